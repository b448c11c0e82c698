"""The one loop that advances and records a station, simulated or hardware.

:class:`StationRecorder` is the only code that advances and samples a
station: ``StationSimulation.run`` (``drake_skill.station.sim.simulation``), the
scripted demonstrator, the Meshcat teleoperation, the rollout runner and the
hardware port's recordings all use it (:func:`record_station` wraps it for a
plain recording without frames), so they share one sampling grid, one
divergence test, one collision reflex and, with perception, the object points
of the ``ObjectSegmenter`` system wired in the diagram (the same points and the
same invalid-frame rule as skill executions: an invalid frame holds the last
valid one).

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

from drake_skill.station.interface import StationInterface


_TERMINATED = SimulatorStatus.ReturnReason.kReachedTerminationCondition
#: A recorder with a segmenter keeps each frame's pixels at most this wide (every k-th pixel): about
#: 20 kB a frame in memory, ~15 kB of it the colour image.
FRAME_WIDTH_PX = 80


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


def advance_station(simulator, station, root_context, t: float, pending: bool = False) -> None:
    """``simulator.AdvanceTo(t)`` (and, with ``pending``, the events due at t) on a diagram
    holding ``station``. A station's monitors stop the simulator by returning
    ``EventStatus.ReachedTermination`` and keep the reason in their state; this raises
    it as the station's typed error (``station.stop_error``: :class:`ReflexError`, on
    the robot also ``StaleStatusError``), outside the simulator. Raises
    :class:`SolverError` when SAP failed to converge, RuntimeError when another system
    ended the simulation."""
    try:
        status = None
        if t > root_context.get_time():
            status = simulator.AdvanceTo(t)
        tripped = status is not None and status.reason() == _TERMINATED
        if pending and not tripped:
            simulator.AdvancePendingEvents()
    except RuntimeError as e:
        if "failed to converge" in str(e):
            time_s = root_context.get_time()
            raise SolverError(f"the contact solver failed to converge at t = {time_s:.3f} s: {e}", time_s) from e
        raise
    if tripped:
        error = station.stop_error(root_context)
        if error is None:     # another system ended the simulation
            raise RuntimeError(f"the simulation ended at t = {status.return_time():.3f} s: "
                               f"{status.FormatMessage()}")
        raise error


def check_joint_state(state, t: float) -> None:
    """Raises :class:`DivergedError` when the station's joint state (14) at t [s] is not
    finite or a joint moves faster than 50 rad/s."""
    if not np.all(np.isfinite(state)) or np.max(np.abs(state[7:])) > 50.0:
        raise DivergedError(
            f"simulation diverged at t = {t:.3f} s (joint state {np.round(state, 3)}); "
            "check the commanded poses and the plant time_step", t)


class StationRecorder:
    """Advances a simulator and samples its station: hand pose, joints, object
    state and peak (filtered) contact force and external joint torques at
    ``record_hz``; with ``frame_hz``, camera frames on the same grid (every
    k-th sample, k = record_hz / frame_hz), the object points, validity and
    X_WO read from ``segmenter`` (an ``ObjectSegmenter`` wired to the
    station's cloud in the same diagram).

    Per frame it also keeps ``frame_force``, the peak of ``force`` over the samples
    since the previous frame (this one included) [N], and, with a segmenter,
    ``pixel_counts`` (pixels of the object's hue in the segmenter's image, the
    object-coloured ones, those its segment kept: ``ObjectSegmenter.eval_pixels``)
    and ``pixels``, that frame's image and masks downscaled to at most
    :data:`FRAME_WIDTH_PX` wide (what a demonstration's three stored frames are
    chosen from).

    The grid is anchored at a frame time (or, without frames, at the current
    time). Drake handles a discrete update due at time t at the start of the
    step *after* t, so at a frame instant the recorder advances to the event's
    exact time and processes the pending events, which refreshes the
    segmenter's memory with the scene at that instant.

    The collision reflex is the station's own system
    (:class:`~drake_skill.station.reflex.ReflexMonitor`, updated at every plant
    step): when it trips, the simulator returns at that instant and the
    recorder raises :class:`ReflexError` from the monitor's state. A sample's
    ``force`` is the monitor's peak filtered force [N] over the interval ending at it,
    its ``torque`` (7) the peak of each filtered |external joint torque| [N m] over
    the same interval (``ReflexMonitor.take_peak`` / ``take_torque_peak``).
    """

    def __init__(self, station: StationInterface, root_context, simulator, record_hz: float = 100.0,
                 frame_hz: float | None = None, segmenter=None):
        self.station = station
        self.simulator = simulator
        self.root_context = root_context
        self.context = station.GetMyContextFromRoot(root_context)
        self.record_hz = float(record_hz)
        self.frame_hz = None if frame_hz is None else float(frame_hz)
        if segmenter is not None and frame_hz is None:
            raise ValueError("a segmenter needs frame_hz (the camera rate)")
        self.k = 1 if frame_hz is None else int(round(record_hz / frame_hz))
        if frame_hz is not None and abs(record_hz / frame_hz - self.k) > 1e-9:
            raise ValueError(f"record_hz = {record_hz} must be an integer multiple of frame_hz = {frame_hz}")
        self.segmenter = segmenter
        if segmenter is not None:
            fps = station.config.camera.fps
            if abs(fps - frame_hz) > 1e-9:
                raise ValueError(f"camera.fps = {fps} Hz: recording perception needs the camera "
                                 f"at frame_hz = {frame_hz} Hz")
            self._seg_context = segmenter.GetMyContextFromRoot(root_context)
            self._frame_stride = max(1, math.ceil(segmenter.config.image_width / FRAME_WIDTH_PX))
        # The same float the camera's periodic events use, so k * period is
        # exactly their event time.
        self._frame_period = None if frame_hz is None else 1.0 / self.frame_hz
        self._ports = {name: station.GetOutputPort(name)
                       for name in ("ee_pose", "panda_state", "object_state")}
        self._monitor = station.reflex_monitor
        self._monitor_context = self._monitor.GetMyMutableContextFromRoot(root_context)
        self.reset()

    def reset(self) -> None:
        self.times, self.X_WE, self.q, self.obj, self.grip, self.force = [], [], [], [], [], []
        self.torque = []
        self.points, self.valid = [], []
        self.frame_force, self.pixel_counts, self.pixels = [], [], []
        self.X_WO_perceived, self.X_WO_frame = None, None
        self._t0 = None
        self._last_peak = 0.0
        self._last_torque_peak = np.zeros(7)
        self._n = 0

    # ------------------------------------------------------------------ grid
    def anchor(self) -> float:
        """Starts the grid at the first frame time at or after now (without
        frames: now); returns it."""
        t = self.root_context.get_time()
        if self._frame_period is None:
            self._frame0, self._t0 = None, t
        else:
            self._frame0 = int(math.ceil(t / self._frame_period - 1e-9))
            self._t0 = self._frame0 * self._frame_period
        return self._t0

    def next_time(self) -> float:
        """Time [s] of the next sample on the grid (nominal)."""
        if self._t0 is None:
            raise ValueError("StationRecorder: call anchor() first")
        if self._frame0 is not None:
            return self._frame0 * self._frame_period + self._n / self.record_hz
        return self._t0 + self._n / self.record_hz

    @property
    def n_samples(self) -> int:
        return self._n

    @property
    def at_frame(self) -> bool:
        """True when the last recorded sample was a frame (a clean end of the grid)."""
        return self._n > 0 and (self._n - 1) % self.k == 0

    # ---------------------------------------------------------------- stepping
    def _advance(self, t: float, pending: bool) -> None:
        """Advances to t (and, with ``pending``, handles the events due at t); raises as
        :func:`advance_station`."""
        advance_station(self.simulator, self.station, self.root_context, t, pending)
        # The peak filtered force and torques over this interval (the reflex monitor's,
        # ReflexMonitor.take_peak / take_torque_peak).
        self._last_peak = self._monitor.take_peak(self._monitor_context)
        self._last_torque_peak = self._monitor.take_torque_peak(self._monitor_context)

    def sample(self, gripper_command: float = math.nan) -> None:
        """Advances to the next grid time and records it (frames included)."""
        if self._t0 is None:
            raise ValueError("StationRecorder.sample called before anchor()")
        i = self._n
        t = self.next_time()
        at_frame = self._frame_period is not None and i % self.k == 0
        if at_frame:
            t = max(t, (self._frame0 + i // self.k) * self._frame_period)
        self._advance(max(t, self.root_context.get_time()), pending=at_frame)
        if at_frame and self.segmenter is not None:
            self._perceive(i // self.k)
        state = self._ports["panda_state"].Eval(self.context)
        check_joint_state(state, t)
        self.times.append(t)
        self.X_WE.append(pose_to_vector(self._ports["ee_pose"].Eval(self.context)))
        self.q.append(state[:7].copy())
        self.obj.append(float(self._ports["object_state"].Eval(self.context)[0]))
        self.grip.append(float(gripper_command))
        self.force.append(float(self._last_peak))
        self.torque.append(self._last_torque_peak)
        if at_frame:
            self.frame_force.append(max(self.force[max(0, i - self.k + 1):]))
        self._n += 1

    def _perceive(self, frame_index: int) -> None:
        seg, ctx = self.segmenter, self._seg_context
        valid = bool(seg.get_valid_output_port().Eval(ctx)[0] > 0.5)
        points = np.asarray(seg.get_object_points_output_port().Eval(ctx), dtype=np.float32)
        if valid and self.X_WO_perceived is None:
            self.X_WO_perceived = pose_to_vector(seg.get_X_WO_output_port().Eval(ctx))
            self.X_WO_frame = frame_index
        self.points.append(points)
        self.valid.append(valid)
        pixels = seg.eval_pixels(ctx)
        self.pixel_counts.append(pixels.counts())
        self.pixels.append(pixels.downscaled(self._frame_stride))

    def record(self, n: int) -> None:
        """Samples n + 1 instants from the anchor (n periods)."""
        for _ in range(n + 1):
            self.sample()

    def run_log(self, X_WO: RigidTransform) -> RunLog:
        return RunLog(np.array(self.times), np.array(self.X_WE).reshape(-1, 7), np.array(self.q).reshape(-1, 7),
                      np.array(self.obj), np.array(self.force), X_WO)


def record_station(simulator, station, root_context, t0: float, n: int, record_hz: float):
    """Advances ``simulator`` from t0 (the current time) over n periods of
    1 / record_hz, sampling the station at each of the n + 1 instants (a
    :class:`StationRecorder` without frames). Returns (times (T,), ee_pose
    (T, 7), q (T, 7), object_state (T,)); raises :class:`DivergedError`,
    :class:`ReflexError` or :class:`SolverError` (see the module docstring).
    """
    if abs(root_context.get_time() - t0) > 1e-9:
        raise ValueError(f"record_station: t0 = {t0} s but the context is at {root_context.get_time()} s")
    recorder = StationRecorder(station, root_context, simulator, record_hz)
    recorder.anchor()
    recorder.record(n)
    return np.array(recorder.times), np.array(recorder.X_WE), np.array(recorder.q), np.array(recorder.obj)
