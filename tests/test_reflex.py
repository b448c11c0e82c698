"""The collision reflex monitor (drake_skill.station.reflex): filter, trip, termination."""

import math
import types

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator, SimulatorStatus
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from drake_skill.station.scenario import ReflexConfig
from drake_skill.station.reflex import ReflexMonitor, reflex_filter_step


def _simulate(force: float, tau, enabled: bool = True, until: float = 0.5):
    reflex = ReflexConfig(enabled=enabled, contact_force_max=30.0, filter_time=0.01,
                          external_torque_max=[30.0, 30.0, 27.0, 27.0, 24.0, 21.0, 18.0])
    builder = DiagramBuilder()
    monitor = builder.AddSystem(ReflexMonitor(reflex, 0.002))
    builder.Connect(builder.AddSystem(ConstantVectorSource([force])).get_output_port(),
                    monitor.GetInputPort("contact_force"))
    builder.Connect(builder.AddSystem(ConstantVectorSource(np.asarray(tau, float))).get_output_port(),
                    monitor.GetInputPort("external_torque"))
    diagram = builder.Build()
    simulator = Simulator(diagram)
    context = monitor.GetMyMutableContextFromRoot(simulator.get_mutable_context())
    monitor.start(context)
    status = simulator.AdvanceTo(until)
    return status, monitor, context


def test_a_steady_force_over_the_limit_stops_the_simulator_once_the_filter_passes_it():
    status, monitor, context = _simulate(40.0, np.zeros(7))
    assert status.reason() == SimulatorStatus.ReturnReason.kReachedTerminationCondition
    trip = monitor.trip(context)
    assert trip.cause == "force"
    # f_hat(t) = 40 (1 - exp(-t / 0.01)) passes 30 N at t = 0.01 ln 4 = 13.9 ms: the first 2 ms update after it.
    assert trip.time_s == pytest.approx(0.014, abs=1e-9)
    assert trip.force_N == pytest.approx(40.0 * (1 - math.exp(-0.014 / 0.01)), rel=1e-9)
    assert status.return_time() == pytest.approx(0.014, abs=1e-9)


def test_a_joint_torque_over_its_limit_names_the_joint_and_a_force_under_it_runs_on():
    tau = np.zeros(7)
    tau[2] = -35.0                                  # joint 3's limit is 27 N m
    status, monitor, context = _simulate(10.0, tau)
    assert monitor.trip(context).cause == "torque joint 3"
    status, monitor, context = _simulate(25.0, np.full(7, 10.0))
    assert status.reason() == SimulatorStatus.ReturnReason.kReachedBoundaryTime
    assert monitor.trip(context) is None
    filtered = monitor.GetOutputPort("filtered").Eval(context)
    assert filtered[0] == pytest.approx(25.0, rel=1e-6) and filtered[-1] == pytest.approx(25.0, rel=1e-6)


def test_a_disabled_reflex_filters_and_keeps_the_peak_but_never_stops():
    status, monitor, context = _simulate(100.0, np.full(7, 100.0), enabled=False)
    assert status.reason() == SimulatorStatus.ReturnReason.kReachedBoundaryTime
    assert monitor.GetOutputPort("filtered").Eval(context)[9] == pytest.approx(100.0, rel=1e-6)


def test_the_filter_is_first_order_in_the_time_since_its_last_update():
    params = np.r_[1.0, 30.0, 0.01, np.full(7, 30.0)]
    x = np.zeros(10)
    x, trip = reflex_filter_step(x, 10.0, np.ones(7), 0.004, params)
    assert x[0] == pytest.approx(10.0 * (1 - math.exp(-0.4)), rel=1e-12) and trip is None
    # Two updates at 2 ms on the same input equal one at 4 ms.
    y = np.zeros(10)
    for t in (0.002, 0.004):
        y, _ = reflex_filter_step(y, 10.0, np.ones(7), t, params)
    assert y[:8] == pytest.approx(x[:8], rel=1e-12)


# ----------------------------------------------------------------------------- the filter step's edges, by hand
PARAMS = np.r_[1.0, 30.0, 0.01, [30.0, 30.0, 27.0, 27.0, 24.0, 21.0, 18.0]]


def test_filter_step_edges_by_hand():
    x0 = np.r_[5.0, np.full(7, 2.0), 0.1, 6.0]
    # No filter (time constant 0): the input itself; the peak only rises.
    no_filter = PARAMS.copy()
    no_filter[2] = 0.0
    x, trip = reflex_filter_step(x0, 4.0, np.arange(7.0), 0.2, no_filter)
    np.testing.assert_array_equal(x, np.r_[4.0, np.arange(7.0), 0.2, 6.0])
    assert trip is None and x0[0] == 5.0               # the caller's state is not changed
    # A time before the last update: dt = 0, nothing moves but the time.
    x, _ = reflex_filter_step(x0, 100.0, np.full(7, 9.0), 0.05, PARAMS)
    np.testing.assert_array_equal(x, np.r_[5.0, np.full(7, 2.0), 0.05, 6.0])
    # One step of dt = 10 ms = T_f: alpha = 1 - 1/e; the peak follows f_hat up.
    x, _ = reflex_filter_step(x0, 25.0, np.r_[-12.0, np.full(6, 2.0)], 0.11, PARAMS)
    alpha = 1 - math.exp(-1.0)
    assert x[0] == pytest.approx(5.0 + alpha * 20.0, rel=1e-14) and x[-1] == x[0]
    assert x[1] == pytest.approx(2.0 - alpha * 14.0, rel=1e-14)
    np.testing.assert_array_equal(x[2:8], 2.0)
    assert x[8] == 0.11


def test_trip_thresholds_are_strict_and_name_the_first_joint_over():
    x0 = np.zeros(10)
    p = PARAMS.copy()
    p[2] = 0.0                                          # f_hat, tau_hat = the inputs
    at_limits = p[3:].copy()
    assert reflex_filter_step(x0, 30.0, at_limits, 0.1, p)[1] is None
    assert reflex_filter_step(x0, 30.0, -at_limits, 0.1, p)[1] is None
    x, trip = reflex_filter_step(x0, 30.0 + 1e-9, at_limits, 0.1, p)
    assert trip == (0.1, 30.0 + 1e-9, trip.torque_Nm, "force")
    np.testing.assert_array_equal(trip.torque_Nm, at_limits)
    x[1:8] = 0.0
    np.testing.assert_array_equal(trip.torque_Nm, at_limits)   # a copy, not a view of the state
    tau = at_limits.copy()
    tau[4] = -24.5                                      # joints 5 and 7 over, 5 is named
    tau[6] = 19.0
    trip = reflex_filter_step(x0, 1.0, tau, 0.3, p)[1]
    assert trip.cause == "torque joint 5" and trip.time_s == 0.3 and trip.force_N == 1.0
    assert reflex_filter_step(x0, 40.0, tau, 0.3, p)[1].cause == "force"        # the force first
    tau = np.zeros(7)
    tau[0] = 31.0
    assert reflex_filter_step(x0, 0.0, tau, 0.3, p)[1].cause == "torque joint 1"
    assert reflex_filter_step(x0, 30.0, tau, 0.3, p)[1].cause == "torque joint 1"   # the force at its limit
    # A state of ints (a list) is taken as floats, not truncated.
    x, _ = reflex_filter_step([0] * 10, 2.5, [1] * 7, 0.1, p)
    assert x[0] == 2.5 and x[-1] == 2.5
    # Enabled is params[0] >= 0.5.
    p[0] = 0.5
    assert reflex_filter_step(x0, 40.0, tau, 0.3, p)[1] is not None
    p[0] = 0.49
    x, trip = reflex_filter_step(x0, 40.0, tau, 0.3, p)
    assert trip is None and x[0] == 40.0 and x[-1] == 40.0


def test_monitor_checks_its_torque_limits_and_keeps_its_state_in_the_context():
    with pytest.raises(ValueError) as e:
        ReflexMonitor(ReflexConfig(external_torque_max=[30.0] * 6), 0.002)
    assert str(e.value) == "reflex.external_torque_max: expected 7 values, got 6"
    tau = np.r_[-20.0, np.zeros(6)]
    status, monitor, context = _simulate(10.0, tau, enabled=False, until=0.3)
    x = monitor.GetOutputPort("filtered").Eval(context)
    assert x[8] == pytest.approx(0.298, abs=1e-12) and x[9] == x[0]      # the last update's time; peak = f_hat
    assert x[0] == pytest.approx(10.0, rel=1e-9) and x[1] == pytest.approx(-20.0, rel=1e-9)
    # One discrete group, the output's [10]: no other per-run value (a peak taken by changing the state).
    assert context.num_discrete_state_groups() == 1
    monitor.start(context)
    np.testing.assert_array_equal(monitor.GetOutputPort("filtered").Eval(context), np.r_[np.zeros(8), 0.3, 0.0])
    assert monitor.trip(context) is None


def test_the_monitor_is_added_named_and_exported():
    from drake_skill.station.reflex import add_reflex_monitor

    builder = DiagramBuilder()
    force = builder.AddSystem(ConstantVectorSource([50.0]))
    tau = builder.AddSystem(ConstantVectorSource(np.zeros(7)))
    monitor = add_reflex_monitor(builder, force.get_output_port(), tau.get_output_port(),
                                 ReflexConfig(contact_force_max=30.0, filter_time=0.0), 0.005)
    assert monitor.get_name() == "reflex"
    diagram = builder.Build()
    simulator = Simulator(diagram)
    context = monitor.GetMyMutableContextFromRoot(simulator.get_mutable_context())
    monitor.start(context)
    status = simulator.AdvanceTo(1.0)
    assert status.reason() == SimulatorStatus.ReturnReason.kReachedTerminationCondition
    assert status.return_time() == pytest.approx(0.0, abs=1e-12)   # the update at 0 already trips
    assert "collision reflex (force)" in status.message() and status.system() is monitor
    out = diagram.GetOutputPort("reflex_state").Eval(simulator.get_context())
    assert out[0] == 50.0


class _Info:
    def __init__(self, a, b, force, point):
        self._a, self._b, self._f, self._p = a, b, np.asarray(force, float), np.asarray(point, float)

    def bodyA_index(self):
        return self._a

    def bodyB_index(self):
        return self._b

    def contact_force(self):
        return self._f

    def contact_point(self):
        return self._p


class _Results:
    def __init__(self, infos):
        self._infos = infos

    def num_point_pair_contacts(self):
        return len(self._infos)

    def point_pair_contact_info(self, i):
        return self._infos[i]


# Robot bodies 1, 2; the rest are the scene. Robot-robot and scene-scene pairs are left out.
CONTACTS = _Results([_Info(1, 7, [3.0, 4.0, 0.0], [0.1, 0.2, 0.3]), _Info(1, 2, [9.0, 0.0, 0.0], [0, 0, 0]),
                     _Info(8, 2, [0.0, 0.0, -12.0], [0.4, 0.5, 0.6]), _Info(7, 8, [50.0, 0, 0], [0, 0, 0])])


def test_robot_scene_contacts_and_pairs_from_contact_results():
    from drake_skill.station.reflex import robot_scene_contacts, robot_scene_pairs

    got = list(robot_scene_contacts(CONTACTS, {1, 2}))
    assert [(a, b) for a, b, _ in got] == [(1, 7), (2, 8)]
    assert got[1][2] is CONTACTS.point_pair_contact_info(2)

    class _Body:
        def __init__(self, i):
            self.i = i

        def model_instance(self):
            return "robot" if self.i < 5 else "scene"

        def name(self):
            return f"body{self.i}"

    class _Plant:
        def get_body(self, index):
            return _Body(int(index))

        def GetModelInstanceName(self, instance):
            return instance

    pairs = robot_scene_pairs(_Plant(), CONTACTS, [np.int64(1), 2])
    assert pairs == [{"a": "robot::body2", "b": "scene::body8", "force_N": 12.0, "point": [0.4, 0.5, 0.6]},
                     {"a": "robot::body1", "b": "scene::body7", "force_N": 5.0, "point": [0.1, 0.2, 0.3]}]
    assert all(type(v) is float for p in pairs for v in [p["force_N"], *p["point"]])


def test_robot_scene_contact_force_sums_the_magnitudes():
    from drake_skill.station.reflex import RobotSceneContactForce

    system = RobotSceneContactForce([1, 2])
    assert system.get_input_port().get_name() == "contact_results"
    assert system.get_output_port().get_name() == "force" and system.get_output_port().size() == 1
    context = system.CreateDefaultContext()
    from pydrake.multibody.plant import ContactResults
    system.get_input_port().FixValue(context, ContactResults())
    assert system.get_output_port().Eval(context)[0] == 0.0          # no contacts
    system._results = types.SimpleNamespace(Eval=lambda ctx: CONTACTS)  # two robot-scene contacts
    context = system.CreateDefaultContext()
    assert system.get_output_port().Eval(context)[0] == 17.0
