"""The object camera: its images and cloud are the crop of the full-frame camera's;
its window holds every place the object can take."""

import numpy as np
import pytest
from pydrake.systems.sensors import CameraInfo
from scipy import ndimage

from drake_skill.station.camera import MARGIN_PX, CropWindow, crop_camera_info, crop_window
from drake_skill.station.config import scenario_for_skill
from drake_skill.station.scripted import scripted_plan
from drake_skill.station.simulation import StationSimulation

HAND_BODIES = ("panda_hand", "panda_leftfinger", "panda_rightfinger")


def _luma(rgb):
    return rgb[..., :3].astype(float) @ np.array([0.299, 0.587, 0.114])


@pytest.mark.parametrize("skill", ["open", "close", "draw"])
def test_cropped_render_equals_the_crop_of_the_full_frame(skill):
    """Box closed (open), box open (close) and the drawer, with the scripted hand in view."""
    sim = StationSimulation(scenario_for_skill(skill))
    station, context = sim.station, sim.station_context()
    window = station.object_camera.window
    X_WO = sim.reset(2)
    sim.set_plan(scripted_plan(skill, X_WO, sim.home_pose()))
    hand_ids = [int(station.plant.GetBodyByName(name).index()) for name in HAND_BODIES]
    port = {name: station.GetOutputPort(name) for name in (
        "color_image", "depth_image", "label_image", "point_cloud",
        "object_color_image", "object_depth_image", "object_label_image", "object_point_cloud")}
    hand_seen = 0
    for t in (0.0, 2.0, 3.5, 5.0):
        if t:
            sim.simulator.AdvanceTo(t)
        full_rgb = port["color_image"].Eval(context).data
        rgb = port["object_color_image"].Eval(context).data
        assert rgb.shape[:2] == window.shape
        labels = port["object_label_image"].Eval(context).data[..., 0]
        # The same pixel grid: labels agree but for a pixel whose centre lies on an edge
        # (float rounding of the shifted projection; measured 0-1 of ~80,000).
        assert np.count_nonzero(labels != window.crop(port["label_image"].Eval(context).data[..., 0])) <= 3
        hand_seen = max(hand_seen, int(np.isin(labels, hand_ids).sum()))
        # Depth: within 1 mm wherever both have a return; the returns themselves agree
        # (a silhouette pixel may flip: measured 0-1 pixels of ~80,000).
        depth, full_depth = port["object_depth_image"].Eval(context).data, window.crop(port["depth_image"].Eval(context).data)
        both = np.isfinite(depth) & np.isfinite(full_depth)
        assert np.count_nonzero(np.isfinite(depth) != np.isfinite(full_depth)) <= 3
        # Within 1 mm at every pixel both label alike; a pixel the two label differently sits
        # on an edge and may see the other surface (measured: 1 pixel, drawer at t = 5 s, 2.9 cm).
        same = both & (labels == window.crop(port["label_image"].Eval(context).data[..., 0]))[..., None]
        assert np.max(np.abs(depth[same] - full_depth[same])) < 1e-3
        assert np.count_nonzero(np.abs(depth[both] - full_depth[both]) >= 1e-3) <= 3
        # The cloud the segmenter reads: the crop of the full-frame cloud, within 1 mm.
        h, w = window.shape
        xyz = port["object_point_cloud"].Eval(context).xyzs().T.reshape(h, w, 3)
        full_xyz = window.crop(port["point_cloud"].Eval(context).xyzs().T.reshape(480, 640, 3))
        ok = np.isfinite(xyz).all(-1) & np.isfinite(full_xyz).all(-1)
        assert ok.sum() > 0.5 * h * w
        # the same edge-pixel rule as the depth above (the cloud is the depth back-projected)
        ok_same = ok & same[..., 0]
        assert np.max(np.abs(xyz[ok_same] - full_xyz[ok_same])) < 1e-3
        assert np.count_nonzero(np.abs(xyz[ok] - full_xyz[ok]).max(-1) >= 1e-3) <= 3
        # Colour: within one grey level off edges. On edges VTK's colour pass
        # anti-aliases (FXAA, a screen-space filter whose edge search reaches across
        # the window's border), so a few edge pixels differ (measured <= 0.15 %).
        diff = np.abs(rgb[..., :3].astype(int) - window.crop(full_rgb)[..., :3].astype(int)).max(-1)
        luma = _luma(full_rgb)
        edge = window.crop(ndimage.maximum_filter(luma, 3) - ndimage.minimum_filter(luma, 3)) >= 4.0
        assert diff[~edge].max() <= 1, f"t = {t}: off-edge colour differs by {diff[~edge].max()}"
        assert np.count_nonzero(diff > 1) <= 0.003 * diff.size
    assert hand_seen > 500, f"the hand was never in the object camera's view ({hand_seen} pixels)"


@pytest.mark.parametrize("skill", ["close", "draw"])
def test_window_holds_the_object_over_its_joint_range_and_pose_noise(skill):
    """The object's pixels in the full frame stay inside the window (with its margin)
    at the ends of the joint range and at randomised poses."""
    sim = StationSimulation(scenario_for_skill(skill))
    station, context = sim.station, sim.station_context()
    window = station.object_camera.window
    ids = [int(station.object_base.index()), int(station.object_joint.child_body().index())]
    lo = float(station.object_joint.position_lower_limits()[0])
    hi = float(station.object_joint.position_upper_limits()[0])
    rows, cols = window.slices()
    closest = np.inf
    for seed in (0, 1, 2, 3):
        sim.reset(seed)
        for q in (lo, 0.5 * (lo + hi), hi):
            station.set_object_joint(sim.context, q)
            labels = station.GetOutputPort("label_image").Eval(context).data[..., 0]
            r, c = np.nonzero(np.isin(labels, ids))
            assert r.size > 1000
            assert r.min() >= rows.start and r.max() < rows.stop and c.min() >= cols.start and c.max() < cols.stop
            closest = min(closest, r.min() - rows.start, rows.stop - 1 - r.max(),
                          c.min() - cols.start, cols.stop - 1 - c.max())
    assert closest >= MARGIN_PX - 2
    # ... and it is tight: some pose reaches within a few pixels of the margin.
    assert closest <= MARGIN_PX + 12


def test_crop_intrinsics_and_window_errors():
    full = CameraInfo(640, 480, 590.0, 600.0, 319.5, 239.5)
    window = CropWindow(200, 150, 200, 150)
    info = crop_camera_info(full, window)
    assert (info.width(), info.height()) == (200, 150)
    assert (info.focal_x(), info.focal_y()) == (590.0, 600.0)
    assert (info.center_x(), info.center_y()) == (119.5, 89.5)
    assert window.shape == (150, 200)
    image = np.arange(480 * 640).reshape(480, 640)
    assert window.crop(image)[0, 0] == image[150, 200] and window.crop(image).shape == (150, 200)
    with pytest.raises(ValueError, match="does not lie inside the 640 x 480 image"):
        crop_camera_info(full, CropWindow(500, 0, 200, 100))
    # Points straight ahead of an identity camera pose project around the principal point.
    from pydrake.math import RigidTransform
    points = np.array([[0.0, 0.0, 1.0], [0.1, 0.05, 1.0]])
    w = crop_window(points, RigidTransform(), full, margin_px=2)
    # u = 319.5 .. 378.5, v = 239.5 .. 269.5: pixels 319..379 and 239..270, 2 more each side.
    assert (w.x0, w.y0, w.x0 + w.width, w.y0 + w.height) == (317, 237, 382, 273)
    # A window off the principal point is grown to hold it (CameraInfo needs it inside).
    w = crop_window(np.array([[0.3, 0.2, 1.0], [0.35, 0.25, 1.0]]), RigidTransform(), full, margin_px=0)
    assert (w.x0, w.y0) == (319, 239) and w.x0 + w.width == 527
    crop_camera_info(full, w)
    with pytest.raises(ValueError, match="behind the camera"):
        crop_window(-points, RigidTransform(), full)
