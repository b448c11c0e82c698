"""The object camera: its images and cloud are the crop of the full-frame camera's;
its window holds every place the object can take."""

import math

import numpy as np
import pytest
from pydrake.geometry import (
    Box,
    ClippingRange,
    ColorRenderCamera,
    GeometryInstance,
    MakeRenderEngineVtk,
    PerceptionProperties,
    RenderCameraCore,
    RenderEngineVtkParams,
    RenderLabel,
    Rgba,
    SceneGraph,
)
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.sensors import CameraInfo
from scipy import ndimage

from drake_skill.station.camera import (
    FXAA_REACH_PX,
    MARGIN_PX,
    CroppedColorCamera,
    CropWindow,
    crop_camera_info,
    crop_window,
)
from drake_skill.skills import scenario_for_skill
from drake_skill.demos.scripted import scripted_plan
from drake_skill.station.sim.simulation import StationSimulation

HAND_BODIES = ("panda_hand", "panda_leftfinger", "panda_rightfinger")


def _luma(rgb):
    return rgb[..., :3].astype(float) @ np.array([0.299, 0.587, 0.114])


@pytest.mark.parametrize("skill", ["open", "close", "draw"])
def test_cropped_render_equals_the_crop_of_the_full_frame(skill):
    """Box closed (open), box open (close) and the drawer, with the scripted hand in view."""
    sim = StationSimulation(scenario_for_skill(skill))
    station, context = sim.station, sim.station_context()
    window = station.object_camera.window
    info = station.camera_info
    # The colour is rendered FXAA_REACH_PX beyond the window, where the image extends.
    assert station.object_camera.color_padding == tuple(min(FXAA_REACH_PX, m) for m in (
        window.x0, window.y0, info.width() - window.x0 - window.width, info.height() - window.y0 - window.height))
    X_WO = sim.reset(2)
    sim.set_plan(scripted_plan(skill, X_WO, sim.home_pose()))
    hand_ids = [int(station.plant.GetBodyByName(name).index()) for name in HAND_BODIES]
    port = {name: station.GetOutputPort(name) for name in (
        "color_image", "depth_image", "label_image", "point_cloud",
        "object_color_image", "object_depth_image", "object_label_image", "object_point_cloud")}
    hand_seen = 0
    for t in (0.0, 2.0, 3.5, 5.0, 6.5):           # Open's hand enters the window after 5 s
        if t:
            sim.simulator.AdvanceTo(t)
        full_rgb = port["color_image"].Eval(context).data
        rgb = port["object_color_image"].Eval(context).data
        assert rgb.shape[:2] == window.shape
        labels = port["object_label_image"].Eval(context).data[..., 0]
        full_labels = window.crop(port["label_image"].Eval(context).data[..., 0])
        # The same pixel grid: labels agree but for a pixel whose centre lies on an edge
        # (float rounding of the shifted projection; measured 0-1 of ~80,000).
        assert np.count_nonzero(labels != full_labels) <= 3
        hand_seen = max(hand_seen, int(np.isin(labels, hand_ids).sum()))
        # Depth: within 1 mm wherever both have a return; the returns themselves agree
        # (a silhouette pixel may flip: measured 0-1 pixels of ~80,000).
        depth = port["object_depth_image"].Eval(context).data
        full_depth = window.crop(port["depth_image"].Eval(context).data)
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
        # Colour: within one grey level off edges. The window's border does not couple
        # (test_color_margin_keeps_fxaa_from_reaching_across_the_border), but the two frusta
        # round differently: a pixel whose centre lies within float rounding of an edge
        # (measured: 8e-5 px, the table's far corner) may rasterise to the other surface, and
        # FXAA then spreads it up to 12 pixels along that edge. (The hand's flange plate sits
        # 0.5 mm below the hand body's face, tools/generate_models.py HAND_BASE_Z: coplanar,
        # either colour showed there by depth rounding.)
        diff = np.abs(rgb[..., :3].astype(int) - window.crop(full_rgb)[..., :3].astype(int)).max(-1)
        luma = _luma(full_rgb)
        edge = window.crop(ndimage.maximum_filter(luma, 3) - ndimage.minimum_filter(luma, 3)) >= 4.0
        assert diff[~edge].max() <= 1, f"t = {t}: off-edge colour differs by {diff[~edge].max()}"
        assert np.count_nonzero(diff > 1) <= 0.003 * diff.size
    assert hand_seen > 500, f"the hand was never in the object camera's view ({hand_seen} pixels)"


def test_color_margin_keeps_fxaa_from_reaching_across_the_border():
    """RenderEngineVtk anti-aliases colour with FXAA, whose edge search reads up to 12 pixels
    along an edge: a crop rendered to its border differs from the full frame's crop where an
    edge crosses the border; rendered FXAA_REACH_PX beyond it, it equals it. The scene: one
    dark slab facing the camera whose upper edge is the image line v = V + u / 8 (a staircase
    FXAA smooths), every pixel centre at least 1/32 px from it, so the two frusta rasterise
    alike."""
    f, depth = 500.0, 2.0
    full = CameraInfo(640, 480, f, f, 319.5, 239.5)
    camera = ColorRenderCamera(RenderCameraCore("vtk", full, ClippingRange(0.1, 10.0), RigidTransform()), False)
    window = CropWindow(200, 150, 240, 180)
    builder = DiagramBuilder()
    scene = builder.AddSystem(SceneGraph())
    scene.AddRenderer("vtk", MakeRenderEngineVtk(RenderEngineVtkParams(backend="EGL")))
    # v = cy + f Y / Z with the edge's Y = Y0 + X / 8 and u = cx + f X / Z.
    V = 200.0 - 3.0 / 32.0                 # pixel centres at (i, j) or (i + 0.5, j + 0.5): >= 1/32 px off
    Y0 = (V - full.center_y() + full.center_x() / 8.0) * depth / f
    R = RotationMatrix.MakeZRotation(math.atan(1.0 / 8.0))
    centre = np.array([0.0, Y0, 0.0]) + R.multiply(np.array([0.0, 2.0, 0.0]))   # 4 m slab below the edge
    slab = GeometryInstance(RigidTransform(R, [centre[0], centre[1], depth + 0.05]), Box(4.0, 4.0, 0.1), "slab")
    props = PerceptionProperties()
    props.AddProperty("phong", "diffuse", Rgba(0.1, 0.1, 0.1, 1.0))
    props.AddProperty("label", "id", RenderLabel(1))
    slab.set_perception_properties(props)
    scene.RegisterAnchoredGeometry(scene.RegisterSource("slab"), slab)
    crops = {reach: builder.AddSystem(CroppedColorCamera(camera, window, scene.world_frame_id(), RigidTransform(),
                                                         reach_px=reach)) for reach in (0, FXAA_REACH_PX)}
    for crop in crops.values():
        builder.Connect(scene.get_query_output_port(), crop.get_input_port())
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    query = scene.get_query_output_port().Eval(scene.GetMyContextFromRoot(context))
    expected = window.crop(query.RenderColorImage(camera, scene.world_frame_id(), RigidTransform()).data)
    assert (expected[..., :3] < 100).any() and (expected[..., :3] > 150).any()      # the edge is in view
    diff = {}
    for reach, crop in crops.items():
        assert crop.padding == (reach,) * 4
        image = crop.get_output_port().Eval(crop.GetMyContextFromRoot(context)).data
        assert image.shape == (window.height, window.width, 4)
        diff[reach] = np.abs(image[..., :3].astype(int) - expected[..., :3].astype(int)).max(-1)
    # Without the margin: the edge's pixels next to the left and right borders differ.
    rows, cols = np.nonzero(diff[0] > 1)
    assert cols.size and set(cols) <= set(range(FXAA_REACH_PX)) | set(range(window.width - FXAA_REACH_PX,
                                                                               window.width))
    # With it: every pixel within one grey level (measured: identical).
    assert diff[FXAA_REACH_PX].max() <= 1


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
