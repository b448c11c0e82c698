"""Advancing a station, and the typed errors that end a run early.

:func:`advance_station` is how every run advances a station's simulator
(rollouts, demonstrations, teleoperation, the hardware port's recordings):
it turns a monitor's termination into the station's typed error. What a run
records is logged in the diagram (``drake_skill.station.loggers``, the one
recording path); :class:`RunLog` is a plain run's record, and
:func:`check_joint_state` the divergence test applied to every sample
(:func:`advance_and_check`: both, for a loop that advances step by step).

A run ends early with an exception (all ``RuntimeError``): :class:`ReflexError`
(the collision reflex: robot-scene contact force or external joint torque
over ``config.reflex``), :class:`SolverError` (the contact solver did not
converge) or :class:`DivergedError` (non-finite or runaway joint states).
"""

from __future__ import annotations

import dataclasses as dc
import math

import numpy as np
from pydrake.math import RigidTransform
from pydrake.systems.analysis import SimulatorStatus

_TERMINATED = SimulatorStatus.ReturnReason.kReachedTerminationCondition


def pose_to_vector(X: RigidTransform) -> np.ndarray:
    """[x, y, z, qw, qx, qy, qz] of a RigidTransform."""
    return np.r_[X.translation(), X.rotation().ToQuaternion().wxyz()]


def vector_to_pose(v) -> RigidTransform:
    """The RigidTransform of [x, y, z, qw, qx, qy, qz] (the quaternion normalised): ``pose_to_vector``'s inverse."""
    from pydrake.common.eigen_geometry import Quaternion

    v = np.asarray(v, dtype=float)
    return RigidTransform(Quaternion(v[3:] / np.linalg.norm(v[3:])), v[:3])


class DivergedError(RuntimeError):
    """The simulation produced non-finite or runaway states."""

    reason = "diverged"

    def __init__(self, message: str, time_s: float = math.nan):
        super().__init__(message)
        self.time_s = float(time_s)


class ReflexError(RuntimeError):
    """The collision reflex stopped the robot: ``time_s`` [s], ``force_N`` (robot-scene
    contact force at that instant), ``torque_Nm`` (7 external joint torques) and
    ``cause`` ("force" or "torque joint i")."""

    reason = "reflex"

    def __init__(self, time_s: float, force_N: float, torque_Nm, cause: str):
        self.time_s, self.force_N = float(time_s), float(force_N)
        self.torque_Nm = np.asarray(torque_Nm, dtype=float).copy()
        self.cause = cause
        super().__init__(f"collision reflex at t = {self.time_s:.3f} s ({cause}): contact force "
                         f"{self.force_N:.1f} N, external joint torques {np.round(self.torque_Nm, 1).tolist()} N m")


class SolverError(RuntimeError):
    """The plant's contact solver (SAP) failed to converge at ``time_s``."""

    reason = "solver"

    def __init__(self, message: str, time_s: float):
        super().__init__(message)
        self.time_s = float(time_s)


@dc.dataclass
class RunLog:
    """What one run recorded, at ``record_hz``.

    times: (T,) [s]; ee_pose: (T, 7) X_WE as xyz + wxyz; q: (T, 7) joint
    positions [rad]; object_state: (T,) lid angle [rad] or drawer travel [m];
    contact_force: (T,) peak robot-scene contact force [N] over the interval
    ending at each sample; X_WO: the object pose the run started from (ground truth).
    """

    times: np.ndarray
    ee_pose: np.ndarray
    q: np.ndarray
    object_state: np.ndarray
    contact_force: np.ndarray
    X_WO: RigidTransform

    @property
    def final_object_state(self) -> float:
        return float(self.object_state[-1])

    @property
    def peak_force(self) -> float:
        return float(np.max(self.contact_force)) if self.contact_force.size else 0.0


def advance_station(simulator, station, root_context, t: float) -> None:
    """``simulator.AdvanceTo(t)`` on a diagram holding ``station`` (nothing when t is not
    after the context's time). A system that stops the simulator returns
    ``EventStatus.ReachedTermination`` and keeps the reason in its state; this raises it
    as the typed error, outside the simulator (:func:`stop_error`). Raises
    :class:`SolverError` when SAP failed to converge."""
    try:
        status = None
        if t > root_context.get_time():
            status = simulator.AdvanceTo(t)
        tripped = status is not None and status.reason() == _TERMINATED
    except RuntimeError as e:
        # Drake's SAP solver throws an untyped std::runtime_error; its text is the one
        # thing that tells it apart, read here once and turned into a typed error.
        if "failed to converge" in str(e):
            time_s = root_context.get_time()
            raise SolverError(f"the contact solver failed to converge at t = {time_s:.3f} s: {e}", time_s) from e
        raise
    if tripped:
        raise stop_error(status, root_context, station)


def stop_error(status, root_context, station=None) -> RuntimeError:
    """The typed error for a simulator ``status`` that reached termination: the station's, when
    given (``station.stop_error``: :class:`ReflexError`, on the robot also ``StaleStatusError``),
    else that of the system that stopped it (``status.system().stop_error``, e.g. the
    reward's ``NonFiniteGoalData``), else a RuntimeError naming the status."""
    error = None if station is None else station.stop_error(root_context)
    system = status.system()
    if error is None and system is not None and hasattr(system, "stop_error"):
        error = system.stop_error(system.GetMyContextFromRoot(root_context))
    if error is None:
        error = RuntimeError(f"the simulation ended at t = {status.return_time():.3f} s: {status.FormatMessage()}")
    return error


def advance_and_check(simulator, station, root_context, t: float) -> None:
    """One step of an interactive loop (teleoperation, a kinesthetic recording on the robot):
    :func:`advance_station` to t [s], then :func:`check_joint_state` on the state reached, so a
    diverging simulation stops the loop at once rather than when the logs are read."""
    advance_station(simulator, station, root_context, t)
    check_joint_state(station.GetOutputPort("panda_state").Eval(station.GetMyContextFromRoot(root_context)), t)


def check_joint_state(state, t: float) -> None:
    """Raises :class:`DivergedError` when the station's joint state (14) at t [s] is not
    finite or a joint moves faster than 50 rad/s."""
    if not np.all(np.isfinite(state)) or np.max(np.abs(state[7:])) > 50.0:
        raise DivergedError(
            f"simulation diverged at t = {t:.3f} s (joint state {np.round(state, 3)}); "
            "check the commanded poses and the plant time_step", t)
