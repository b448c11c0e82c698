"""PomrpReward LeafSystem in a small diagram: same numbers as the numpy POMRP."""

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator, SimulatorStatus
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, TrajectorySource
from pydrake.trajectories import PiecewisePolynomial

from drake_skill.bench.reward import left_to_right_model, sample_demonstrations
from drake_skill.reward.pomrp import fit_pomrp
from drake_skill.reward.systems import NonFiniteGoalData, PomrpReward, PomrpRewardConfig, RewardCapacityError
from drake_skill.station.recording import stop_error

TRUE = left_to_right_model(n_states=4, seed=0)
PERIOD = 0.1


@pytest.fixture(scope="module")
def pomrp():
    X, lengths = sample_demonstrations(TRUE, [50, 60, 45], seed=0)
    return fit_pomrp(X, lengths)


@pytest.fixture(scope="module")
def demo():
    return sample_demonstrations(TRUE, [60], seed=123)[0]  # 6 s of goal data, reaches the goal


def _zoh(values: np.ndarray) -> PiecewisePolynomial:
    """Holds row i over [i * PERIOD, (i + 1) * PERIOD)."""
    values = np.atleast_2d(values)
    times = PERIOD * np.arange(len(values) + 1)
    return PiecewisePolynomial.ZeroOrderHold(times, np.vstack([values, values[-1:]]).T)


def _diagram(pomrp, goal_source, valid=None, config=None):
    builder = DiagramBuilder()
    src = builder.AddSystem(goal_source)
    reward = builder.AddSystem(PomrpReward(pomrp, config))
    builder.Connect(src.get_output_port(), reward.get_goal_data_input_port())
    if valid is not None:
        v = builder.AddSystem(valid)
        builder.Connect(v.get_output_port(), reward.get_valid_input_port())
    diagram = builder.Build()
    return diagram, reward, Simulator(diagram)


def test_ports(pomrp):
    system = PomrpReward(pomrp)
    assert system.GetInputPort("goal_data").size() == 8 and system.GetInputPort("valid").size() == 1
    assert system.GetOutputPort("reward").size() == 1 and system.GetOutputPort("return").size() == 1
    assert system.get_reward_output_port().get_name() == "reward"


def test_trajectory_source_same_return_as_numpy(pomrp, demo):
    diagram, reward, sim = _diagram(pomrp, TrajectorySource(_zoh(demo)))
    root = sim.get_mutable_context()
    sim.AdvanceTo(5.0)
    G = reward.goal_sequence(root)
    # Updates at t = 0, 0.1, ..., 4.9: 50 frames, the ones the source held.
    assert G.shape == (50, 8)
    np.testing.assert_array_equal(G, demo[:50])
    assert reward.smoothed_return(root) == pomrp.episode_return(demo[:50])
    np.testing.assert_array_equal(reward.smoothed_rewards(root), pomrp.rewards(demo[:50]))
    filtered = pomrp.filtered_rewards(demo[:50])
    own = reward.GetMyContextFromRoot(root)
    assert reward.get_return_output_port().Eval(own)[0] == pytest.approx(filtered.sum(), rel=1e-10)
    assert reward.get_reward_output_port().Eval(own)[0] == pytest.approx(filtered[-1], rel=1e-10)
    assert reward.filtered_return(own) == pytest.approx(filtered.sum(), rel=1e-10)
    assert reward.log_likelihood(root) == pytest.approx(pomrp.goal_model.score(demo[:50]), rel=1e-10)
    assert reward.verdict(root) is pomrp.verdict(demo[:50]) is True


def test_reset_restarts_the_sequence(pomrp, demo):
    diagram, reward, sim = _diagram(pomrp, TrajectorySource(_zoh(demo)))
    root = sim.get_mutable_context()
    sim.AdvanceTo(3.0)
    first = reward.smoothed_return(root)
    assert len(reward.goal_sequence(root)) == 30
    diagram.SetDefaultContext(root)
    own = reward.GetMyContextFromRoot(root)
    assert reward.goal_sequence(root).shape == (0, 8)
    assert reward.get_return_output_port().Eval(own)[0] == 0.0
    assert reward.smoothed_return(root) == 0.0 and reward.verdict(root) is False
    root.SetTime(0.0)  # SetDefaultContext leaves the time alone
    sim.Initialize()
    sim.AdvanceTo(3.0)
    assert reward.smoothed_return(root) == first


def test_constant_goal_data_never_succeeds(pomrp):
    start_mean = TRUE[2][0]
    diagram, reward, sim = _diagram(pomrp, ConstantVectorSource(start_mean))
    root = sim.get_mutable_context()
    sim.AdvanceTo(5.0)
    G = reward.goal_sequence(root)
    assert G.shape == (50, 8) and np.all(G == start_mean)
    assert reward.smoothed_return(root) == pomrp.episode_return(G)
    assert reward.verdict(root) is False


def test_invalid_frames_are_skipped(pomrp, demo):
    valid = (np.arange(60) % 3 != 1).astype(float)  # every third frame invalid
    diagram, reward, sim = _diagram(pomrp, TrajectorySource(_zoh(demo)), TrajectorySource(_zoh(valid[:, None])))
    root = sim.get_mutable_context()
    sim.AdvanceTo(5.0)
    kept = demo[:50][valid[:50] > 0.5]
    G = reward.goal_sequence(root)
    assert len(G) == len(kept) == 33
    np.testing.assert_array_equal(G, kept)
    assert reward.smoothed_return(root) == pomrp.episode_return(kept)
    assert reward.filtered_return(root) == pytest.approx(pomrp.filtered_rewards(kept).sum(), rel=1e-10)
    # Each kept frame's online reward, the per-step methods' rewards (computed once, online).
    np.testing.assert_allclose(reward.filtered_rewards(root), pomrp.filtered_rewards(kept), rtol=1e-12, atol=1e-12)
    assert reward.filtered_rewards(root).shape == (33,)


def test_period_is_configurable(pomrp, demo):
    config = PomrpRewardConfig(period=0.2, capacity=100)
    diagram, reward, sim = _diagram(pomrp, TrajectorySource(_zoh(demo)), config=config)
    sim.AdvanceTo(5.0)
    np.testing.assert_array_equal(reward.goal_sequence(sim.get_context()), demo[:50:2])


def test_errors(pomrp, demo):
    # A frame the reward cannot take stops the simulator (ReachedTermination, the reason in
    # state), and stop_error gives it as the typed error, as the station's monitors do.
    diagram, reward, sim = _diagram(pomrp, TrajectorySource(_zoh(demo)), config=PomrpRewardConfig(capacity=10))
    status = sim.AdvanceTo(2.0)
    assert status.reason() == SimulatorStatus.ReturnReason.kReachedTerminationCondition
    assert status.return_time() == pytest.approx(1.0)
    with pytest.raises(RewardCapacityError, match="more than capacity = 10 valid frames at t = 1.000 s"):
        raise stop_error(status, sim.get_context())
    nan = demo.copy()
    nan[3, 0] = np.nan
    diagram, reward, sim = _diagram(pomrp, TrajectorySource(_zoh(nan)))
    assert reward.stop_error(sim.get_context()) is None
    status = sim.AdvanceTo(1.0)
    assert status.return_time() == pytest.approx(0.3)
    assert reward.goal_sequence(sim.get_context()).shape == (3, demo.shape[1])   # frames 0-2 kept
    with pytest.raises(NonFiniteGoalData, match=r"goal_data\[0\] = nan at t = 0.300 s while valid"):
        raise stop_error(status, sim.get_context())
    with pytest.raises(ValueError, match="config.period"):
        PomrpReward(pomrp, PomrpRewardConfig(period=0.0))
