"""ObjectSegmenter in a diagram with the simulated station: truth, determinism, occlusion, bad clouds."""

import math

import numpy as np
import pytest
from pydrake.common.yaml import yaml_load_typed
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.perception import BaseField, Fields, PointCloud
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from drake_skill.perception.systems import (
    ObjectSegmenter,
    ObjectSegmenterConfig,
    add_object_segmenter,
    segmenter_config_for_station,
)
from drake_skill.station.pose_source import PosePlan, PoseTrajectorySource, hold_plan
from drake_skill.perception.segmentation import fit_table_plane
from drake_skill.station.make import make_station
from drake_skill.station.scenario import Scenario
from drake_skill.skills import scenario_for_skill


class Rig:
    """Station + plan source + segmenter in one diagram, reset like StationSimulation."""

    def __init__(self, config: Scenario, segmenter_config: ObjectSegmenterConfig | None = None):
        builder = DiagramBuilder()
        self.station = builder.AddNamedSystem("station", make_station(config))
        self.source = builder.AddNamedSystem("plan", PoseTrajectorySource())
        builder.Connect(self.source.GetOutputPort("X_WE_desired"), self.station.GetInputPort("ee_pose_desired"))
        builder.Connect(self.source.GetOutputPort("gripper_command"), self.station.GetInputPort("gripper_command"))
        self.segmenter = add_object_segmenter(builder, self.station, segmenter_config)
        self.diagram = builder.Build()
        self.context = self.diagram.CreateDefaultContext()
        self.simulator = Simulator(self.diagram, self.context)
        ids = [b.index() for b in (self.station.object_base, self.station.object_joint.child_body())]
        self.object_labels = [int(i) for i in ids]

    def reset(self, seed, plan=None) -> RigidTransform:
        self.diagram.SetDefaultContext(self.context)
        self.context.SetTime(0.0)
        X_WO = self.station.reset(self.context, seed)
        sc = self.station.GetMyContextFromRoot(self.context)
        self.home = self.station.GetOutputPort("ee_pose").Eval(sc)
        self.source.set_plan(self.source.GetMyMutableContextFromRoot(self.context), plan or hold_plan(self.home))
        self.simulator.Initialize()
        self.simulator.AdvanceTo(0.0)        # the camera's first frame
        return X_WO

    @property
    def seg_context(self):
        return self.segmenter.GetMyContextFromRoot(self.context)

    def outputs(self):
        s, c = self.segmenter, self.seg_context
        return (bool(s.get_valid_output_port().Eval(c)[0]), s.get_X_WO_output_port().Eval(c),
                s.get_object_points_output_port().Eval(c).copy(), s.get_bounding_box_output_port().Eval(c).copy())

    def object_mask(self):
        """The object's pixels in the label image of the camera the segmenter reads (the
        object camera's crop)."""
        labels = self.station.GetOutputPort("object_label_image").Eval(self.station.GetMyContextFromRoot(self.context))
        return np.isin(labels.data[:, :, 0], self.object_labels)


def _yaw(X: RigidTransform) -> float:
    return X.rotation().ToRollPitchYaw().yaw_angle()


@pytest.fixture(scope="module")
def close_rig():
    return Rig(scenario_for_skill("close"))       # the box, lid open at 1.9 rad


def test_outputs_match_truth_and_label_image(close_rig):
    rig = close_rig
    segmenter_config = rig.segmenter.config
    assert (segmenter_config.image_height, segmenter_config.image_width) == rig.station.object_camera.window.shape
    for seed in (0, 5):
        X_true = rig.reset(seed)
        valid, X_WO, points, box = rig.outputs()
        assert valid
        # Measured: 1.4-1.6 mm and at most 0.11 degrees (lid open, seeds 0-5).
        assert np.linalg.norm(X_WO.translation() - X_true.translation()) < 0.002
        assert math.degrees(abs(_yaw(X_WO) - _yaw(X_true))) < 0.2
        assert points.shape == (2048, 3) and points.dtype == np.float64
        # Every point inside the reported box (its own yawed frame).
        c, s = math.cos(box[6]), math.sin(box[6])
        local = (points[:, :2] - box[:2]) @ np.array([[c, -s], [s, c]])
        assert np.all(np.abs(local) <= box[3:5] / 2 + 1e-9)
        assert np.all(np.abs(points[:, 2] - box[2]) <= box[5] / 2 + 1e-9)
        assert box[6] == pytest.approx(_yaw(X_WO))
        assert box[5] > 0.3                               # the raised lid reaches 0.32 m
        mask, truth = rig.segmenter.eval_frame(rig.seg_context).segmentation.mask(), rig.object_mask()
        iou = (mask & truth).sum() / (mask | truth).sum()
        assert iou >= 0.98, f"seed {seed}: IoU {iou:.3f}"       # measured 0.988


def test_deterministic_across_resets_and_plane_fitted_once(close_rig):
    rig = close_rig

    def run(seed):
        rig.diagram.SetDefaultContext(rig.context)
        assert rig.segmenter.table_plane(rig.seg_context) is None     # not stored before the first update
        rig.reset(seed)                                               # processes the frame at t = 0
        xyz, _ = _cloud_arrays(rig)          # the plane comes from the full frame
        first_plane = fit_table_plane(xyz, rig.segmenter.config.segmentation, (480, 640),
                                      seed=rig.segmenter.config.seed)
        rig.simulator.AdvanceTo(0.25)
        plane = rig.segmenter.table_plane(rig.seg_context)
        assert np.array_equal(plane, first_plane)       # fitted on the first frame, then kept
        valid, X_WO, points, box = rig.outputs()
        return valid, X_WO.GetAsMatrix4(), points, box

    a, b, c = run(3), run(3), run(4)
    assert a[0] and b[0] and c[0]
    for x, y in zip(a[1:], b[1:]):
        assert np.array_equal(x, y)
    assert not np.allclose(a[2], c[2]) and not np.allclose(a[1], c[1])


def _cloud_arrays(rig, port="point_cloud"):
    cloud = rig.station.GetOutputPort(port).Eval(rig.station.GetMyContextFromRoot(rig.context))
    return cloud.xyzs().T, cloud.rgbs().T


def test_hand_hiding_the_object_clears_the_flag_and_holds_outputs():
    """A camera looking at the box from the side at table height; the hand moves in front
    of the box (it hides about 85 % of it), stays, and goes back home.

    The segment's rule is "largest": the hand cuts the box's visible rest into pieces of at
    most 600-800 pixels, each under min_points. Under the default "all_regions" the pieces
    together (about 1900 object pixels) are a valid, partial object."""
    config = Scenario()
    config.object.colour.cluster_rule = "largest"
    from pydrake.common.schema import Transform
    from drake_skill.common import look_at
    config.camera.X_PB = Transform(RigidTransform(look_at([0.55, -1.15, 0.30], [0.55, 0.0, 0.07])))
    rig = Rig(config)
    rig.reset(0)
    R = RotationMatrix.MakeZRotation(math.pi / 2) @ rig.home.rotation()   # palm toward the camera
    hide, lift = RigidTransform(R, [0.55, -0.55, 0.10]), RigidTransform(R, [0.45, -0.30, 0.30])
    plan = PosePlan.from_poses([0.0, 1.5, 2.3, 3.0, 3.6], [rig.home, hide, hide, lift, rig.home], [0.0] * 5)
    X_true = rig.reset(0, plan)
    log = []
    for k in range(41):                     # 4 s at the camera rate
        if k:
            # To the frame instant and through its events (the plant's step, then the
            # segmenter's update): the outputs are then those of the frame the update saw.
            rig.simulator.AdvanceTo(0.1 * k)
            rig.simulator.AdvancePendingEvents()
        log.append(rig.outputs())
    valid = np.array([v[0] for v in log])
    assert valid[:12].all() and valid[-5:].all(), f"flags {valid.astype(int)}"
    assert not valid[18:23].any(), f"hidden from 1.8 s to 2.2 s, flags {valid.astype(int)}"
    for k in np.flatnonzero(~valid):        # invalid frames repeat the last valid frame's outputs
        last = np.flatnonzero(valid[:k])[-1]
        assert log[k][1].IsExactlyEqualTo(log[last][1])
        assert np.array_equal(log[k][2], log[last][2]) and np.array_equal(log[k][3], log[last][3])
    # Unoccluded before and after. This camera sees one face of the base and the lid's
    # top, so X_WO comes from all points (the lid's 2.5 cm lip shifts x by 1.25 cm).
    for k in (0, 40):
        assert np.linalg.norm(log[k][1].translation() - X_true.translation()) < 0.02
        assert np.linalg.norm(log[k][1].translation() - log[0][1].translation()) < 0.002


def _organised_cloud(xyz, rgb=None) -> PointCloud:
    fields = Fields(BaseField.kXYZs | (BaseField.kRGBs if rgb is not None else BaseField.kNone))
    cloud = PointCloud(xyz.shape[0], fields)
    cloud.mutable_xyzs()[:] = xyz.T
    if rgb is not None:
        cloud.mutable_rgbs()[:] = rgb.T
    return cloud


def test_blank_and_malformed_clouds():
    config = ObjectSegmenterConfig(default_pose=[0.6, 0.1, 0.2])
    segmenter = ObjectSegmenter(config)
    context = segmenter.CreateDefaultContext()
    n = 640 * 480
    blank = _organised_cloud(np.full((n, 3), np.inf, np.float32), np.zeros((n, 3), np.uint8))
    segmenter.get_point_cloud_input_port().FixValue(context, blank)
    assert segmenter.get_valid_output_port().Eval(context)[0] == 0.0
    X = segmenter.get_X_WO_output_port().Eval(context)
    np.testing.assert_allclose(X.translation(), [0.6, 0.1, 0.0])
    assert _yaw(X) == pytest.approx(0.2)
    assert not segmenter.get_object_points_output_port().Eval(context).any()
    assert segmenter.eval_frame(context) is None          # no table, no plane
    segmenter.get_point_cloud_input_port().FixValue(
        context, _organised_cloud(np.zeros((100, 3), np.float32), np.zeros((100, 3), np.uint8)))
    with pytest.raises(ValueError, match=r"point_cloud: 100 points, expected an organised 480x640 cloud"):
        segmenter.get_valid_output_port().Eval(context)
    segmenter.get_point_cloud_input_port().FixValue(context, _organised_cloud(np.zeros((n, 3), np.float32)))
    with pytest.raises(ValueError, match="point_cloud: expected xyz and rgb"):
        segmenter.get_valid_output_port().Eval(context)


def test_configured_plane_and_seeded_resampling(close_rig):
    """A fixed cloud fed to segmenters with a configured table plane and two seeds."""
    close_rig.reset(1)
    xyz, rgb = (a.copy() for a in _cloud_arrays(close_rig))
    cloud = _organised_cloud(xyz, rgb)
    outputs = []
    for seed in (0, 0, 1):
        config = segmenter_config_for_station(close_rig.station.config)
        config.seed, config.table_plane = seed, [0.0, 0.0, 2.0, 0.0]
        segmenter = ObjectSegmenter(config)
        context = segmenter.CreateDefaultContext()
        np.testing.assert_allclose(segmenter.table_plane(context), [0, 0, 1, 0])
        segmenter.get_point_cloud_input_port().FixValue(context, cloud)
        outputs.append((segmenter.get_object_points_output_port().Eval(context).copy(),
                        segmenter.get_bounding_box_output_port().Eval(context).copy()))
    assert np.array_equal(outputs[0][0], outputs[1][0])
    assert not np.array_equal(outputs[0][0], outputs[2][0])
    assert np.array_equal(outputs[0][1], outputs[2][1])      # the seed only changes the sampling


def test_config_yaml_and_errors():
    config = yaml_load_typed(schema=ObjectSegmenterConfig, defaults=ObjectSegmenterConfig(),
                             data="period_s: 0.2\ntable_plane: [0, 0, 1, 0]\nsegmentation: {min_points: 50}\n")
    assert config.period_s == 0.2 and config.segmentation.min_points == 50 and config.table_plane == [0, 0, 1, 0]
    assert config.segmentation.hue_min_deg == 200.0
    station = segmenter_config_for_station(scenario_for_skill("draw"))
    assert station.default_pose == [0.68, 0.0, 0.0] and station.period_s == pytest.approx(0.1)
    for kwargs, field in [({"period_s": 0.0}, "period_s"), ({"table_plane": [0, 0, 1]}, "table_plane"),
                          ({"default_pose": [0, 0]}, "default_pose"), ({"image_width": 0}, "image_width")]:
        with pytest.raises(ValueError, match=f"'{field}"):
            ObjectSegmenter(ObjectSegmenterConfig(**kwargs))


@pytest.mark.parametrize("skill, start, done", [("open", 0.0, 1.9), ("close", 1.9, 0.0), ("draw", 0.0, 0.14)])
def test_segmented_object_follows_its_state(skill, start, done):
    """The shipped scenario's camera sees the object's state change: the lid swung
    from shut to open (or back), the drawer pulled 14 cm, move the segment's
    bounding box by centimetres, while the object frame estimated from the
    footprint stays within 2 mm. (From the shared camera, behind the
    cabinet, the drawer's travel was hidden: the segment stayed the same to
    the micrometre.)"""
    rig = Rig(scenario_for_skill(skill))
    rig.reset(seed=3)
    boxes, frames = [], []
    for value in (start, done):
        rig.station.set_object_joint(rig.context, value)
        valid, X_WO, points, box = rig.outputs()
        assert valid
        boxes.append(box)
        frames.append(X_WO.translation().copy())
    change = np.abs(boxes[1][:6] - boxes[0][:6])
    assert change.max() > 0.05, (skill, boxes)
    assert np.linalg.norm(frames[1] - frames[0]) < 0.002, (skill, frames)
    if skill == "draw":
        # The drawer comes out along -x_O toward the robot: the box grows by about its travel.
        assert boxes[1][3] - boxes[0][3] > 0.10, boxes
