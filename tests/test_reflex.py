"""The collision reflex monitor (drake_skill.station.reflex): filter, trip, termination."""

import math

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator, SimulatorStatus
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from drake_skill.station.config import ReflexConfig
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
    assert monitor.take_peak(context) == pytest.approx(100.0, rel=1e-6)


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
