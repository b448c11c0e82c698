"""The collision reflex as a system of the station diagram.

The Panda stops itself when its estimate of the external wrench or of an
external joint torque exceeds a threshold (Franka's collision behaviour; the
thresholds are the scenario's ``reflex``, ``drake_skill.station.limits``
gives their sources). :class:`ReflexMonitor` does the same on the station's
measurements, in simulation and on the robot alike:

    f_hat  <- f_hat  + alpha (f   - f_hat),        alpha = 1 - exp(-dt / T_f)
    tau_hat <- tau_hat + alpha (tau - tau_hat)

a first-order low-pass (time constant ``filter_time`` T_f [s], dt the time
since the last update [s]) of the robot-scene contact force f [N] and the
external joint torques tau [N m]; the reflex trips when f_hat >
``contact_force_max`` or any |tau_hat_i| > ``external_torque_max[i]``.

Every value of a run lives in the Context: the thresholds in a numeric
parameter, the filter, the time of its last update and the peak of f_hat
since the run's start in discrete state, exported as the station's
``reflex_state``. Nothing reads the monitor by changing it: a recording's
per-sample peaks of f_hat and of each |tau_hat_i| are computed from the
logged state (``drake_skill.station.loggers``; ``drake_skill.demos.force_margin``
compares a demonstration's with the thresholds). The update runs every
``period`` s (the plant's step in simulation: the contact results change
only then) and, when the reflex trips, returns a termination status: the
simulator's ``AdvanceTo`` returns at that instant and
``drake_skill.station.recording.advance_station`` raises
:class:`~drake_skill.station.recording.ReflexError` from the state.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from pydrake.systems.framework import BasicVector, EventStatus, LeafSystem

__all__ = ["FILTERED_FORCE", "FILTERED_TORQUE", "REFLEX_STATE_SIZE", "ReflexMonitor", "ReflexTrip",
           "RobotSceneContactForce", "add_reflex_monitor", "reflex_filter_step"]

N_JOINTS = 7
# Discrete state layout: [f_hat, tau_hat (7), time of the last update, peak f_hat].
_F, _TAU, _T, _PEAK = 0, slice(1, 1 + N_JOINTS), 1 + N_JOINTS, 2 + N_JOINTS
_STATE_SIZE = 3 + N_JOINTS
#: The ``reflex_state`` layout for readers of the station's port: its size, the filtered
#: contact force's index and the filtered external torques' slice.
REFLEX_STATE_SIZE, FILTERED_FORCE, FILTERED_TORQUE = _STATE_SIZE, _F, _TAU
# Parameter layout: [enabled, contact_force_max, filter_time, external_torque_max (7)].
_PARAM_SIZE = 3 + N_JOINTS


class ReflexTrip(NamedTuple):
    """Why the reflex tripped: ``time_s`` [s], filtered ``force_N`` and ``torque_Nm`` (7), and
    ``cause`` ("force" or "torque joint i", i from 1)."""

    time_s: float
    force_N: float
    torque_Nm: np.ndarray
    cause: str


def reflex_filter_step(x: np.ndarray, force: float, tau, now: float, params: np.ndarray):
    """One update of the module docstring's filter and test.

    x: the state [f_hat, tau_hat (7), t_last, peak]; force [N]; tau (7) [N m];
    now [s]; params: [enabled, contact_force_max, filter_time, tau_max (7)].
    Returns (next state, :class:`ReflexTrip` or None).
    """
    x_next, trip = _filter_step(np.asarray(x, dtype=float).tolist(), float(force),
                                np.asarray(tau, dtype=float).tolist(), float(now),
                                np.asarray(params, dtype=float).tolist())
    return np.array(x_next), trip


def _filter_step(x: list, force: float, tau: list, now: float, params: list):
    """:func:`reflex_filter_step` on Python floats: the same IEEE operations in the same order as
    the vector form, so the same floats; element by element because it runs at every plant
    step, where numpy's per-call overhead on 10 numbers cost more than the filter (32 ms per
    simulated second of a rollout, against 12 here)."""
    filter_time = params[2]
    dt = max(now - x[_T], 0.0)
    alpha = 1.0 if filter_time <= 0 else 1.0 - math.exp(-dt / filter_time)
    f = x[_F] + alpha * (force - x[_F])
    x_tau = x[_TAU]
    taus = [t_hat + alpha * (t - t_hat) for t_hat, t in zip(x_tau, tau)]
    x_next = [f, *taus, now, max(x[_PEAK], f)]
    if params[0] < 0.5:
        return x_next, None
    over = [abs(t) > limit for t, limit in zip(taus, params[3:])]
    if f > params[1] or any(over):
        cause = "force" if f > params[1] else f"torque joint {over.index(True) + 1}"
        return x_next, ReflexTrip(now, f, np.array(taus), cause)
    return x_next, None


class ReflexMonitor(LeafSystem):
    """Inputs ``contact_force`` [1] (robot-scene contact force [N]) and ``external_torque``
    [7] [N m]; output ``filtered`` [10]: the state [f_hat, tau_hat (7), time of the last
    update [s], peak f_hat since the run's start] (a state output port: no Python per
    evaluation). The module docstring gives the filter; ``reflex`` is the scenario's
    ``ReflexConfig`` (the parameter's defaults), ``period`` the update's [s].
    """

    def __init__(self, reflex, period: float):
        super().__init__()
        params = np.r_[float(bool(reflex.enabled)), float(reflex.contact_force_max), float(reflex.filter_time),
                       np.asarray(reflex.external_torque_max, dtype=float)]
        if params.shape != (_PARAM_SIZE,):
            raise ValueError(f"reflex.external_torque_max: expected {N_JOINTS} values, got {params.size - 3}")
        self._params = self.DeclareNumericParameter(BasicVector(params))
        self._force = self.DeclareVectorInputPort("contact_force", 1)
        self._tau = self.DeclareVectorInputPort("external_torque", N_JOINTS)
        self._state = self.DeclareDiscreteState(_STATE_SIZE)
        self.DeclarePeriodicDiscreteUpdateEvent(float(period), 0.0, self._update)
        self.DeclareStateOutputPort("filtered", self._state)

    def start(self, context) -> None:
        """Starts the filter at rest at the context's time (a run's reset)."""
        x = np.zeros(_STATE_SIZE)
        x[_T] = context.get_time()
        context.get_mutable_discrete_state(self._state).SetFromVector(x)

    def stop_error(self, context):
        """The trip the state shows as the typed error (``station.recording.ReflexError``), or None."""
        from drake_skill.station.recording import ReflexError

        trip = self.trip(context)
        return None if trip is None else ReflexError(*trip)

    def trip(self, context) -> ReflexTrip | None:
        """The trip the state shows (None when the filter is within the thresholds)."""
        x = context.get_discrete_state(self._state).get_value()
        params = context.get_numeric_parameter(self._params).get_value()
        _, trip = reflex_filter_step(x, x[_F], x[_TAU], x[_T], params)
        return trip

    def _update(self, context, discrete_state):
        # Python floats, not numpy: this runs at every plant step (see _filter_step).
        x = context.get_discrete_state(self._state).get_value().tolist()
        params = context.get_numeric_parameter(self._params).get_value().tolist()
        x_next, trip = _filter_step(x, float(self._force.Eval(context)[0]), self._tau.Eval(context).tolist(),
                                    context.get_time(), params)
        discrete_state.set_value(self._state, x_next)
        if trip is not None:
            return EventStatus.ReachedTermination(self, f"collision reflex ({trip.cause})")
        return EventStatus.Succeeded()


class RobotSceneContactForce(LeafSystem):
    """Input ``contact_results`` (the plant's); output ``force`` [1]: the sum of the
    contact force magnitudes [N] of the point contacts between a robot body
    (``robot_bodies``, body indices) and anything else."""

    def __init__(self, robot_bodies):
        super().__init__()
        from pydrake.multibody.plant import ContactResults
        from pydrake.common.value import AbstractValue

        self._robot = frozenset(int(b) for b in robot_bodies)
        self._results = self.DeclareAbstractInputPort("contact_results", AbstractValue.Make(ContactResults()))
        self.DeclareVectorOutputPort("force", 1, self._calc, {self._results.ticket()})

    def _calc(self, context, output):
        results = self._results.Eval(context)
        force = 0.0
        for _, _, info in robot_scene_contacts(results, self._robot):
            force += float(np.linalg.norm(info.contact_force()))
        output.SetAtIndex(0, force)


def robot_scene_contacts(results, robot):
    """``(robot body index, other body index, PointPairContactInfo)`` of every point contact in
    ``results`` (a ContactResults) between a body in ``robot`` (a set of body indices as ints) and
    anything else, in ``results``' order: what :class:`RobotSceneContactForce` sums and a reflex
    trip's record names."""
    for i in range(results.num_point_pair_contacts()):
        info = results.point_pair_contact_info(i)
        a, b = int(info.bodyA_index()), int(info.bodyB_index())
        if (a in robot) != (b in robot):
            yield (a, b, info) if a in robot else (b, a, info)


def robot_scene_pairs(plant, results, robot_bodies) -> list[dict]:
    """The robot-scene point contacts in ``results`` (a ContactResults of ``plant``), strongest first:
    ``{"a": "model::body" (the robot's), "b": "model::body", "force_N": |f|, "point": [x, y, z] (W, m)}``."""
    from pydrake.multibody.tree import BodyIndex

    def name(index) -> str:
        body = plant.get_body(BodyIndex(index))
        return f"{plant.GetModelInstanceName(body.model_instance())}::{body.name()}"

    robot = frozenset(int(b) for b in robot_bodies)
    pairs = [{"a": name(a), "b": name(b), "force_N": float(np.linalg.norm(info.contact_force())),
              "point": [float(v) for v in info.contact_point()]}
             for a, b, info in robot_scene_contacts(results, robot)]
    return sorted(pairs, key=lambda p: -p["force_N"])


def add_reflex_monitor(builder, contact_force_port, external_torque_port, reflex, period: float) -> ReflexMonitor:
    """Adds a :class:`ReflexMonitor` named "reflex" fed by the two ports and exports its
    ``filtered`` output as ``reflex_state`` (the station contract); returns it."""
    monitor = builder.AddNamedSystem("reflex", ReflexMonitor(reflex, period))
    builder.Connect(contact_force_port, monitor.GetInputPort("contact_force"))
    builder.Connect(external_torque_port, monitor.GetInputPort("external_torque"))
    builder.ExportOutput(monitor.GetOutputPort("filtered"), "reflex_state")
    return monitor
