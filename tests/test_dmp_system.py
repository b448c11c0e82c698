"""Tests of DmpSystem in a Drake diagram: equality with the numpy integration, parameters, latching, caching."""

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

import drake_skill.action.systems as dmp_system_module
from drake_skill.bench.dmp import synthetic_demonstration
from drake_skill.action.dmp import DmpConfig, fit_dmp, integrate, phase
from drake_skill.action.systems import DmpSystem
from drake_skill.action.quaternion import quaternion_distance

CFG = DmpConfig(n_basis=10)
X_WO_1 = RigidTransform(RollPitchYaw(0.1, -0.2, 0.3), [0.5, 0.1, 0.7])
X_WO_2 = RigidTransform(RollPitchYaw(0.0, 0.0, 1.2), [0.4, -0.3, 0.72])


@pytest.fixture(scope="module")
def dmp():
    return fit_dmp(*synthetic_demonstration(duration=2.0, rate_hz=20.0), CFG)


def _build(dmp, config=CFG):
    """Diagram with the DMP's X_WO input exported, so tests can fix it."""
    builder = DiagramBuilder()
    system = builder.AddSystem(DmpSystem(dmp, config))
    builder.ExportInput(system.get_X_WO_input_port(), "X_WO")
    diagram = builder.Build()
    simulator = Simulator(diagram)
    return diagram, system, simulator


def _pose_in_object_frame(system, context, X_WO):
    """Output X_WE_desired expressed back in O, as a 7-vector (xyz, wxyz)."""
    X_OE = X_WO.inverse() @ system.get_X_WE_desired_output_port().Eval(context)
    q = X_OE.rotation().ToQuaternion()
    return np.r_[X_OE.translation(), q.w(), q.x(), q.y(), q.z()]


def _simulate(system, simulator, times, X_WO):
    context = system.GetMyContextFromRoot(simulator.get_context())
    out = []
    for t in times:
        simulator.AdvanceTo(t)
        out.append(_pose_in_object_frame(system, context, X_WO))
    return np.array(out)


def _assert_poses_close(actual, expected, atol):
    np.testing.assert_allclose(actual[:, :3], expected[:, :3], atol=atol)
    assert quaternion_distance(actual[:, 3:], expected[:, 3:]).max() < atol


def test_ports_and_no_direct_feedthrough(dmp):
    system = DmpSystem(dmp, CFG)
    assert system.get_input_port(0).get_name() == "X_WO"
    assert [system.get_output_port(i).get_name() for i in range(2)] == ["X_WE_desired", "phase"]
    assert not system.HasAnyDirectFeedthrough()
    assert system.num_numeric_parameter_groups() == 5   # weights, y0, goal, tau, y0_demo
    assert system.get_weights(system.CreateDefaultContext()).shape == (10, 7)


def test_simulated_output_equals_numpy_integration(dmp):
    diagram, system, simulator = _build(dmp)
    diagram.get_input_port().FixValue(simulator.get_mutable_context(), X_WO_1)
    simulator.Initialize()
    times = np.array([0.0, 0.05, 0.3, 0.7251, 1.0, 1.5, 2.0])
    actual = _simulate(system, simulator, times, X_WO_1)
    _assert_poses_close(actual, integrate(dmp, CFG, times), atol=1e-6)
    context = system.GetMyContextFromRoot(simulator.get_context())
    assert system.get_phase_output_port().Eval(context)[0] == pytest.approx(0.01)
    # after the duration the final pose is held
    held = _simulate(system, simulator, [2.5, 3.0], X_WO_1)
    _assert_poses_close(held, np.tile(integrate(dmp, CFG, [dmp.tau]), (2, 1)), atol=1e-12)
    assert system.get_phase_output_port().Eval(context)[0] == pytest.approx(phase(3.0, dmp.tau, CFG.alpha_x))


def test_weights_changed_in_reset_context_change_output_without_rebuild(dmp):
    diagram, system, simulator = _build(dmp)
    root = simulator.get_mutable_context()
    diagram.get_input_port().FixValue(root, X_WO_1)
    times = np.array([0.0, 0.5, 1.0, 1.5])
    simulator.Initialize()
    first = _simulate(system, simulator, times, X_WO_1)

    rng = np.random.default_rng(0)
    w_new = dmp.weights + rng.normal(0.0, 20.0, dmp.weights.shape)  # |w| ~ 100
    diagram.SetDefaultContext(root)  # what a rollout does: reset, then write the sample
    root.SetTime(0.0)
    system.set_weights(system.GetMyMutableContextFromRoot(root), w_new)
    simulator.Initialize()
    second = _simulate(system, simulator, times, X_WO_1)
    expected = integrate(dmp, CFG, times, weights=w_new)
    _assert_poses_close(second, expected, atol=1e-6)
    assert np.abs(second[1:, :3] - first[1:, :3]).max() > 1e-3

    # a plain reset restores the default weights and the first trajectory
    diagram.SetDefaultContext(root)
    root.SetTime(0.0)
    simulator.Initialize()
    _assert_poses_close(_simulate(system, simulator, times, X_WO_1), first, atol=1e-12)


def test_object_pose_is_latched_at_initialization(dmp):
    diagram, system, simulator = _build(dmp)
    root = simulator.get_mutable_context()
    port = diagram.get_input_port()
    port.FixValue(root, X_WO_1)
    simulator.Initialize()
    simulator.AdvanceTo(0.5)
    port.FixValue(root, X_WO_2)  # the object moves during the execution: ignored
    context = system.GetMyContextFromRoot(root)
    expected_O = integrate(dmp, CFG, [0.5, 1.0])
    _assert_poses_close(_simulate(system, simulator, [0.5, 1.0], X_WO_1), expected_O, atol=1e-6)
    # reset to defaults + initialize re-latches the current input
    diagram.SetDefaultContext(root)
    root.SetTime(0.0)
    simulator.Initialize()
    assert system.get_latched_X_WO(context).IsNearlyEqualTo(X_WO_2, 1e-12)
    _assert_poses_close(_simulate(system, simulator, [0.5, 1.0], X_WO_2), expected_O, atol=1e-6)


def test_start_goal_and_duration_parameters(dmp):
    diagram, system, simulator = _build(dmp)
    root = simulator.get_mutable_context()
    diagram.get_input_port().FixValue(root, RigidTransform())
    context = system.GetMyMutableContextFromRoot(root)
    goal = dmp.goal.copy()
    goal[:3] += [0.05, -0.02, 0.03]
    system.set_start_goal(context, dmp.y0, goal)
    system.set_duration(context, 3.0)
    simulator.Initialize()
    times = np.array([0.0, 1.0, 3.0, 3.5])
    expected = integrate(system.get_dmp(context), CFG, np.minimum(times, 3.0))
    _assert_poses_close(_simulate(system, simulator, times, RigidTransform()), expected, atol=1e-6)
    assert np.linalg.norm(expected[-1, :3] - goal[:3]) < 2e-3
    with pytest.raises(ValueError, match="tau: expected a finite duration > 0 s"):
        system.set_duration(context, -1.0)
    with pytest.raises(ValueError, match=r"goal: quaternion .* has norm 2"):
        system.set_start_goal(context, dmp.y0, np.r_[goal[:3], 2.0, 0, 0, 0])
    with pytest.raises(ValueError, match=r"weights: expected shape \(10, 7\) or \(70,\), got \(10, 6\)"):
        system.set_weights(context, np.zeros((10, 6)))
    with pytest.raises(ValueError, match=r"dmp.weights: shape \(10, 7\) does not fit config.quaternion='ude'"):
        DmpSystem(dmp, DmpConfig(n_basis=10, quaternion="ude"))


def test_trajectory_is_computed_once_per_parameter_change(dmp, monkeypatch):
    calls = []

    def counting_integrate(*args, **kwargs):
        calls.append(1)
        return integrate(*args, **kwargs)

    monkeypatch.setattr(dmp_system_module, "integrate", counting_integrate)
    diagram, system, simulator = _build(dmp)
    root = simulator.get_mutable_context()
    diagram.get_input_port().FixValue(root, X_WO_1)
    simulator.Initialize()
    _simulate(system, simulator, np.linspace(0.0, 2.0, 21), X_WO_1)
    assert len(calls) == 1
    system.set_weights(system.GetMyMutableContextFromRoot(root), dmp.weights * 1.1)
    _simulate(system, simulator, [2.1, 2.2], X_WO_1)
    assert len(calls) == 2


def test_unconnected_input_latches_identity_and_ude_variant():
    times, poses = synthetic_demonstration(duration=1.0, rate_hz=20.0)
    cfg = DmpConfig(n_basis=8, quaternion="ude", dt=0.005)
    dmp = fit_dmp(times, poses, cfg)
    system = DmpSystem(dmp, cfg)
    simulator = Simulator(system)
    simulator.Initialize()
    context = simulator.get_context()
    assert system.get_latched_X_WO(context).IsExactlyIdentity()
    simulator.AdvanceTo(0.4)
    actual = _pose_in_object_frame(system, context, RigidTransform())
    _assert_poses_close(actual[None], integrate(dmp, cfg, [0.4]), atol=1e-6)
