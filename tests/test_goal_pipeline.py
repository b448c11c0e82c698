"""The perception-to-reward chain on the object camera computes what the full frame did:
demonstration returns and verdicts, a rollout's return against its recorded clouds,
one render and one segmentation per camera frame."""

import numpy as np
import pytest
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from drake_skill.demos.demonstrator import DemonstratorConfig, ScriptedDemonstrator
from drake_skill.perception import systems
from drake_skill.perception.pcae import cloud_in_object_frame
from drake_skill.perception.segmentation import fit_table_plane, process_frame
from drake_skill.reward.systems import add_goal_pipeline
from drake_skill.fitted_skill import default_skill_config, fit_skill
from drake_skill.station.make import make_station
from drake_skill.skills import scenario_for_skill
from drake_skill.station.pose_source import PoseTrajectorySource
from drake_skill.demos.scripted import scripted_plan

DEMO_CONFIG = DemonstratorConfig(seed=0, pause_probability=0.0)


def _full_frame_segmenter(monkeypatch):
    """Wires every segmenter to the full-frame cloud, as before the object camera."""
    original = systems.add_object_segmenter

    def full_frame(builder, station, config=None, name="object_segmenter"):
        return original(builder, station, config or systems.segmenter_config_for_station(station.config), name)

    monkeypatch.setattr(systems, "add_object_segmenter", full_frame)


@pytest.fixture(scope="module")
def demos():
    """Two Close demonstrations, recorded through the object camera and through the full frame."""
    crop = ScriptedDemonstrator("close", DEMO_CONFIG).record_many(2, progress=False)
    with pytest.MonkeyPatch.context() as monkeypatch:
        _full_frame_segmenter(monkeypatch)
        demonstrator = ScriptedDemonstrator("close", DEMO_CONFIG)
        assert demonstrator.sim.segmenter.config.image_width == 640
        full = demonstrator.record_many(2, progress=False)
    return crop, full


@pytest.fixture(scope="module")
def skill(demos):
    """The skill as it was fitted before the object camera (full-frame demonstrations)."""
    return fit_skill(demos[1], default_skill_config("close"))


def test_demonstration_returns_and_verdicts_unchanged(demos, skill):
    crop, full = demos
    assert [d.seed for d in crop] == [d.seed for d in full]
    for i, (a, b) in enumerate(zip(crop, full)):
        assert a.object_points.shape == b.object_points.shape
        np.testing.assert_array_equal(a.perception_valid, b.perception_valid)
        G = skill.goal_data(a.object_points, a.perception_valid, X_WO=a.X_WO_start)
        R, R_full = skill.dense_return(G), skill.info["demo_returns"][i]
        assert abs(R - R_full) <= 0.01 * abs(R_full), f"demo {i}: return {R:.3f} vs full frame {R_full:.3f}"
        assert skill.verdict(G) == skill.info["demo_verdicts"][i]
        # The perceived start pose agrees with the full frame's within a millimetre.
        np.testing.assert_allclose(a.X_WO_start[:3], b.X_WO_start[:3], atol=1e-3)


def test_rollout_return_equals_offline_return_of_its_clouds(skill, monkeypatch):
    """A scripted Close behind the goal pipeline; every camera frame's cloud is recorded
    as the pipeline saw it (after the instant's events) and the return recomputed offline."""
    calls = []
    original = systems.ObjectSegmenter._calc_frame

    def counted(self, context, value):
        calls.append(context.get_time())
        return original(self, context, value)

    monkeypatch.setattr(systems.ObjectSegmenter, "_calc_frame", counted)
    builder = DiagramBuilder()
    station = builder.AddNamedSystem("station", make_station(scenario_for_skill("close")))
    source = builder.AddNamedSystem("plan", PoseTrajectorySource())
    builder.Connect(source.GetOutputPort("X_WE_desired"), station.GetInputPort("ee_pose_desired"))
    builder.Connect(source.GetOutputPort("gripper_command"), station.GetInputPort("gripper_command"))
    pipeline = add_goal_pipeline(builder, station, skill)
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    simulator = Simulator(diagram, context)
    X_WO = station.reset(context, 21)
    station_context = station.GetMyContextFromRoot(context)
    home = station.GetOutputPort("ee_pose").Eval(station_context)
    source.set_plan(source.GetMyMutableContextFromRoot(context), scripted_plan("close", X_WO, home))
    simulator.Initialize()
    cloud_port = station.GetOutputPort(station.object_camera.cloud_port_name)
    clouds, n = [], 60
    for k in range(n + 1):
        simulator.AdvanceTo(0.1 * k)
        simulator.AdvancePendingEvents()
        cloud = cloud_port.Eval(station_context)
        clouds.append((cloud.xyzs().T.copy(), cloud.rgbs().T.copy()))
        if k == 0:      # the table plane is fitted on the first frame's full frame
            full_xyz = station.GetOutputPort("point_cloud").Eval(station_context).xyzs().T.copy()
    # One segmentation per camera frame, shared by the segmenter's memory and the featurizer.
    assert len(calls) == n + 1 and len(set(calls)) == n + 1
    # Offline: the table plane from the first frame, each frame segmented, valid frames
    # encoded; the reward lags the camera by one frame (it reads the featurizer's state).
    config = pipeline.segmenter.config
    shape = station.object_camera.window.shape
    plane = fit_table_plane(full_xyz, config.segmentation, (480, 640), seed=config.seed)
    segmenter = pipeline.segmenter
    np.testing.assert_array_equal(plane, segmenter.table_plane(segmenter.GetMyContextFromRoot(context)))
    encoder, goal, X_WO_first = skill.encoder(), [], None
    for xyz, rgb in clouds[:-1]:
        result = process_frame(xyz, rgb, plane, config.segmentation, shape, n_points=config.n_points, seed=config.seed)
        if result.valid:
            if X_WO_first is None:      # the object frame of the run's first valid frame
                X_WO_first = RigidTransform(RotationMatrix.MakeZRotation(result.box.yaw),
                                            result.box.position).GetAsMatrix4()
            points = cloud_in_object_frame(result.points, X_WO_first)
            goal.append(skill.goal_features.transform(encoder.encode_points(points)))
    G = np.array(goal)
    reward_context = pipeline.reward.GetMyContextFromRoot(context)
    G_online = pipeline.reward.goal_sequence(reward_context)
    assert G_online.shape == G.shape and len(G) >= 55
    np.testing.assert_allclose(G_online, G, rtol=0, atol=1e-6)
    R = pipeline.reward.smoothed_return(reward_context)
    assert R == pytest.approx(skill.dense_return(G), rel=1e-9)
    assert pipeline.reward.verdict(reward_context) == skill.verdict(G)
