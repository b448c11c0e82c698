"""RolloutRunner: a DMP fitted to a station demonstration, executed in the station."""

import numpy as np
import pytest
from pydrake.common.eigen_geometry import Quaternion
from pydrake.math import RigidTransform

from drake_skill.action.dmp import DmpConfig, fit_dmp
from drake_skill.action.quaternion import make_quaternions_continuous
from drake_skill.demos.format import downsample_action
from drake_skill.learning.rollout import RolloutRunner
from drake_skill.station.scripted import scripted_plan
from drake_skill.station.simulation import StationSimulation, pose_to_vector
from drake_skill.station.config import scenario_for_skill


@pytest.fixture(scope="module")
def draw_setup():
    config = scenario_for_skill("draw")
    config.enable_camera = False
    sim = StationSimulation(config)
    X_WO = sim.reset(5)
    plan = scripted_plan("draw", X_WO, sim.home_pose())
    log = sim.run(plan, plan.duration, record_hz=100)
    assert sim.judge("draw")
    X_OW = X_WO.inverse()
    poses = np.array([pose_to_vector(X_OW @ RigidTransform(Quaternion(p[3:] / np.linalg.norm(p[3:])), p[:3]))
                      for p in log.ee_pose])
    poses[:, 3:] = make_quaternions_continuous(poses[:, 3:])
    _, times, poses = downsample_action(log.times, poses, rate_hz=10)
    dmp_config = DmpConfig(n_basis=30)   # enough bases to thread the finger behind the handle
    dmp = fit_dmp(times, poses, dmp_config)
    runner = RolloutRunner(config, dmp, dmp_config, skill="draw", record_hz=10)
    return dmp, runner, (times, poses)


def test_imitation_follows_the_demonstration(draw_setup):
    dmp, runner, (times, poses) = draw_setup
    result = runner.run(dmp.weights, seed=5)
    # Same object pose as the demonstration: the hand path in O stays near the demo's.
    X_OW = result.X_WO.inverse()
    executed = np.array([(X_OW.multiply(p[:3])) for p in result.ee_pose])
    demo_at = np.array([np.interp(result.times, times, poses[:, i]) for i in range(3)]).T
    error = np.linalg.norm(executed - demo_at, axis=1)
    assert np.median(error) < 0.03, f"median path error {np.median(error):.3f} m"
    assert result.final_object_state > 0.05, "the imitation did not move the drawer at all"


def test_rollouts_are_deterministic_and_weights_matter(draw_setup):
    dmp, runner, _ = draw_setup
    a = runner.run(dmp.weights, seed=9)
    b = runner.run(dmp.weights, seed=9)
    assert np.array_equal(a.ee_pose, b.ee_pose) and a.final_object_state == b.final_object_state
    W = dmp.weights.copy()
    W[:, 0] += 0.5 * np.abs(W[:, 0]).max()          # push the whole x path around
    c = runner.run(W, seed=9)
    assert not np.allclose(a.ee_pose, c.ee_pose, atol=1e-3)
    d = runner.run(dmp.weights, seed=10)
    assert not d.X_WO_true.IsNearlyEqualTo(a.X_WO_true, 1e-6)


def test_runner_rejects_bad_weights(draw_setup):
    dmp, runner, _ = draw_setup
    with pytest.raises(ValueError, match="weights"):
        runner.run(np.zeros((3, 7)), seed=0)
    bad = dmp.weights.copy()
    bad[0, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        runner.run(bad, seed=0)


def test_perceived_object_pose_is_close_to_the_truth(draw_setup):
    dmp, runner, _ = draw_setup
    config = scenario_for_skill("draw")
    perceiving = RolloutRunner(config, dmp, DmpConfig(n_basis=30), skill="draw", object_pose="perceived")
    X_WO = perceiving.reset(dmp.weights, seed=5)
    X_true = perceiving.station.object_pose(perceiving.context)
    assert np.linalg.norm(X_WO.translation() - X_true.translation()) < 0.01
    with pytest.raises(ValueError, match="enable_camera"):
        config.enable_camera = False
        RolloutRunner(config, dmp, DmpConfig(n_basis=30), skill="draw", object_pose="perceived")
