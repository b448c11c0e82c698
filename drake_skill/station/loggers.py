"""What a run records: loggers in the diagram, the one recording path.

Every recording of a station reads its samples here: a rollout
(``drake_skill.learning.rollout``), a scripted demonstration
(``StationSimulation.record``, ``drake_skill.demos.demonstrator``), a
teleoperated one (``drake_skill.demos.teleop``) and a kinesthetic one on the
robot (``drake-skill hardware record-demo``). The loggers are systems of the
diagram and keep what they log in the Context, so the diagram holds no per-run
value of its own: a run starts by emptying them (:meth:`StationLoggers.start`
or :meth:`~StationLoggers.clear`), advances the simulator (in one
``AdvanceTo``, or step by step from an interactive loop: the logs do not
care), and reads them (:meth:`StationLoggers.read`). Nothing is sampled from
Python between steps, and no system's state is changed to read it.

:class:`StationLoggers` adds ``VectorLogSink`` systems (``LogVectorOutput``)
on a station's outputs: the joint state, the object state and the reflex
monitor's state (and, when given, the gripper command the station is fed), at
the end of every simulator step. All are computed in C++ (a Python output
evaluated at every step would cost more than the plant); the hand pose X_WE
of a sample is the station's ``hand_pose`` of its joint positions, the value
its ``ee_pose`` output has then. The simulator ends a step at every event
time, and a step's end sees the state after every event before it; so the
sample of a grid time t is the first step end at or after t, the state
``Simulator.AdvanceTo(t)`` leaves (events due at t still pending). (A periodic
publish at 1 / record_hz would be cheaper, but its times k * period round
differently from the plant's k * time_step: where they fall an ulp apart, it
would see the plant's update at that instant, where they coincide, not.)

Per sample, the peak over the interval ending at it of the filtered contact
force [N] and of each filtered |external joint torque| [N m] are computed
from the logged reflex state (its f_hat and tau_hat after every update), so
reading a peak changes nothing in the monitor.

With an ``ObjectSegmenter`` (``segmenter``), a :class:`FrameLog` logs its
outputs at every camera frame: validity, object points, X_WO, and the
frame's pixel counts and pixels (``pixels``, downscaled to at most
:data:`FRAME_WIDTH_PX` wide). It is a periodic publish at the segmenter's
own period and offset, so it sees the step end at the frame instant, the same
state as the vector logs' sample there (a run's every sample of instant t is
the scene at t). A publish cannot change state, so it appends to a value kept
in a cache entry of the Context that nothing invalidates: the way Drake's own
``VectorLogSink`` keeps its log (not abstract state: an unrestricted update
would copy the whole log into the update's scratch state at every frame, and
its event at t runs at the start of the step after t, so a run's last frame
would need the events due at its end processed). The segmenter updates its
memory at the start of the next step, after the plant's step at t: on an
invalid frame its held outputs (the last valid frame's) are those of that
update, one plant step after the valid frame this log recorded.
"""

from __future__ import annotations

import dataclasses as dc
import math
from typing import NamedTuple

import numpy as np
from pydrake.common.value import AbstractValue, Value
from pydrake.math import RigidTransform
from pydrake.systems.framework import LeafSystem, ValueProducer
from pydrake.systems.primitives import LogVectorOutput

from drake_skill.station.recording import check_joint_state, pose_to_vector

__all__ = ["FRAME_WIDTH_PX", "FrameLog", "FrameRecords", "StationLoggers", "StationRecords", "frame_peaks"]

#: A frame log keeps each frame's pixels at most this wide (every k-th pixel): about
#: 20 kB a frame in memory, ~15 kB of it the colour image.
FRAME_WIDTH_PX = 80
#: Tolerance [s] between a grid time and the camera event it stands for (their floats may
#: differ in the last bits: t0 + k / record_hz against Drake's j * period).
_TIME_TOL = 1e-9


class _Frame(NamedTuple):
    time: float
    valid: bool
    points: np.ndarray        # (N, 3) float32
    X_WO: np.ndarray          # (7,) xyz + wxyz
    counts: tuple             # (hue, coloured, kept) pixels
    pixels: object            # SegmentPixels, downscaled


class FrameLog(LeafSystem):
    """Logs an ``ObjectSegmenter``'s outputs at each camera frame (module docstring).

    Inputs ``valid`` [1], ``object_points`` (abstract (N, 3) array [m], world),
    ``X_WO`` (abstract RigidTransform) and ``pixels`` (abstract
    ``SegmentPixels``); a periodic publish every ``period`` s from ``offset``
    (the segmenter's) and a forced publish append one frame to the log in the
    Context, the pixels downscaled by ``stride`` (every stride-th pixel).
    """

    def __init__(self, period: float, offset: float = 0.0, stride: int = 1):
        super().__init__()
        if not (math.isfinite(period) and period > 0):
            raise ValueError(f"period: expected a positive frame period [s], got {period}")
        self.period, self.offset, self.stride = float(period), float(offset), max(1, int(stride))
        self._valid = self.DeclareVectorInputPort("valid", 1)
        self._points = self.DeclareAbstractInputPort("object_points", AbstractValue.Make(np.zeros((0, 3))))
        self._X_WO = self.DeclareAbstractInputPort("X_WO", Value(RigidTransform()))
        self._pixels = self.DeclareAbstractInputPort("pixels", AbstractValue.Make(object()))
        # The log: a list in a cache entry that nothing invalidates (VectorLogSink's way).
        self._log = self.DeclareCacheEntry(
            "frames", ValueProducer(allocate=lambda: AbstractValue.Make([]), calc=lambda context, value: None),
            {self.nothing_ticket()})
        self.DeclarePeriodicPublishEvent(self.period, self.offset, self._log_frame)
        self.DeclareForcedPublishEvent(self._log_frame)

    def _frames(self, context) -> list:
        return self._log.get_mutable_cache_entry_value(context).GetMutableValueOrThrow()

    def frames(self, context) -> tuple:
        """The frames logged in ``context`` (this system's), oldest first."""
        return tuple(self._frames(context))

    def clear(self, context) -> None:
        self._frames(context).clear()

    def _log_frame(self, context):
        pixels = self._pixels.Eval(context)
        self._frames(context).append(_Frame(
            context.get_time(), bool(self._valid.Eval(context)[0] > 0.5),
            np.asarray(self._points.Eval(context), dtype=np.float32).copy(),
            pose_to_vector(self._X_WO.Eval(context)), pixels.counts(), pixels.downscaled(self.stride)))


@dc.dataclass
class FrameRecords:
    """The camera frames of a recording, one per ``samples_per_frame``-th sample.

    index (F,): the sample of each frame; times (F,) [s]; valid (F,) bool: the
    segmentation found the object; points (F, N, 3) float32 [m] (world; an invalid
    frame holds the segmenter's last valid one); X_WO (F, 7) the perceived object
    pose, xyz + wxyz; pixel_counts (F, 3): pixels of the object's hue, object-coloured
    and kept by the segment; pixels: F ``SegmentPixels`` downscaled to at most
    :data:`FRAME_WIDTH_PX` wide.
    """

    index: np.ndarray
    times: np.ndarray
    valid: np.ndarray
    points: np.ndarray
    X_WO: np.ndarray
    pixel_counts: np.ndarray
    pixels: list

    @property
    def first_valid(self) -> int | None:
        """The first valid frame (None if none was)."""
        valid = np.flatnonzero(self.valid)
        return int(valid[0]) if valid.size else None


@dc.dataclass
class StationRecords:
    """times (T,) [s]; ee_pose (T, 7) X_WE as xyz + wxyz; state (T, 14) joint positions
    [rad] and velocities [rad/s]; object_state (T,) lid angle [rad] or drawer travel [m];
    contact_force (T,) peak filtered robot-scene contact force [N] and external_torque
    (T, 7) peak filtered |external joint torque| [N m] over the interval ending at each
    sample; gripper (T,) the gripper command [m] (NaN when not logged); frames: the camera
    frames (None without a frame log)."""

    times: np.ndarray
    ee_pose: np.ndarray
    state: np.ndarray
    object_state: np.ndarray
    contact_force: np.ndarray
    external_torque: np.ndarray
    gripper: np.ndarray
    frames: FrameRecords | None = None

    def check_joint_states(self) -> None:
        """Raises ``DivergedError`` at the first sample whose joint state is not finite or
        whose joints move faster than 50 rad/s (``recording.check_joint_state``)."""
        for t, state in zip(self.times, self.state):
            check_joint_state(state, t)


class StationLoggers:
    """The loggers of a station's run (module docstring), added to ``builder`` beside
    ``station`` (any station with the simulated station's ports).

    record_hz: the grid :meth:`read` samples by default [Hz]; gripper_command: the output
    port feeding the station's ``gripper_command`` input, to log it (optional);
    segmenter: an ``ObjectSegmenter`` in the same diagram, to log its frames
    (:class:`FrameLog`, at the segmenter's period, which must divide 1 / record_hz
    into a whole number of samples).
    """

    def __init__(self, builder, station, record_hz: float, *, gripper_command=None, segmenter=None):
        self.station = station
        self.record_hz = float(record_hz)
        ports = {"state": station.GetOutputPort("panda_state"),
                 "object_state": station.GetOutputPort("object_state"),
                 "reflex": station.GetOutputPort("reflex_state")}
        if gripper_command is not None:
            ports["gripper"] = gripper_command
        # Publish period 0: at the end of every simulator step (module docstring).
        self._sinks = {name: LogVectorOutput(port, builder, 0.0) for name, port in ports.items()}
        self.frame_log: FrameLog | None = None
        if segmenter is not None:
            config = segmenter.config
            stride = max(1, math.ceil(config.image_width / FRAME_WIDTH_PX))
            self.frame_log = builder.AddNamedSystem("frame_log", FrameLog(config.period_s, config.offset_s, stride))
            for name, port in (("valid", segmenter.get_valid_output_port()),
                               ("object_points", segmenter.get_object_points_output_port()),
                               ("X_WO", segmenter.get_X_WO_output_port()),
                               ("pixels", segmenter.get_pixels_output_port())):
                builder.Connect(port, self.frame_log.GetInputPort(name))
            self.samples_per_frame(self.record_hz)     # a rate that cannot work fails here

    @property
    def frame_period(self) -> float | None:
        """The camera frames' period [s] (None without a frame log)."""
        return None if self.frame_log is None else self.frame_log.period

    def samples_per_frame(self, record_hz: float) -> int:
        """record_hz * frame period, checked to be a whole number."""
        k = record_hz * self.frame_period
        if round(k) < 1 or abs(k - round(k)) > 1e-9:
            raise ValueError(f"record_hz = {record_hz} Hz: expected an integer multiple of the camera's "
                             f"{1.0 / self.frame_period:g} Hz")
        return int(round(k))

    def grid(self, n: int, t0: float = 0.0, record_hz: float | None = None, frames: bool = True) -> np.ndarray:
        """The times [s] of samples 0..n from t0: t0 + i / record_hz, except that with a frame
        log (and ``frames``) every ``samples_per_frame``-th sample is at its camera frame's
        event time, Drake's offset + j * period, where that is later by at most a rounding
        (the two floats may differ in the last bit; a run that ends on a frame must reach
        its event)."""
        hz = self.record_hz if record_hz is None else float(record_hz)
        times = t0 + np.arange(n + 1) / hz
        if frames and self.frame_log is not None:
            k, log = self.samples_per_frame(hz), self.frame_log
            j0 = round((t0 - log.offset) / log.period)
            i = np.arange(0, n + 1, k)
            event = log.offset + (j0 + i // k) * log.period
            times[i] = np.where(np.abs(event - times[i]) <= _TIME_TOL, np.maximum(times[i], event), times[i])
        return times

    def _log(self, sink, root_context):
        return sink.FindMutableLog(root_context)     # the log within the root context

    def clear(self, root_context) -> None:
        """Empties every log (a run's reset, before ``Simulator.Initialize`` logs its start)."""
        for sink in self._sinks.values():
            self._log(sink, root_context).Clear()
        if self.frame_log is not None:
            self.frame_log.clear(self.frame_log.GetMyContextFromRoot(root_context))

    def start(self, root_context) -> float:
        """Starts a recording now: empties every log, then logs the current instant as its
        first sample (and frame): the state ``AdvanceTo`` left, the values the step end
        logged. A recording with frames starts at a camera frame instant. Returns the
        time [s]."""
        self.clear(root_context)
        for sink in self._sinks.values():
            sink.ForcedPublish(sink.GetMyContextFromRoot(root_context))
        if self.frame_log is not None:
            self.frame_log.ForcedPublish(self.frame_log.GetMyContextFromRoot(root_context))
        return root_context.get_time()

    def read(self, root_context, n: int, t0: float = 0.0, record_hz: float | None = None,
             frames: bool = True) -> StationRecords:
        """The samples of the grid t0 + k / record_hz, k = 0..n (:meth:`grid`), that the run
        reached (a run stopped early has fewer), from the step logs (module docstring); with
        a frame log and ``frames``, the frames of every ``samples_per_frame``-th sample from
        k = 0 (RuntimeError when one is missing: t0 was not a camera frame instant)."""
        hz = self.record_hz if record_hz is None else float(record_hz)
        logs = {name: self._log(sink, root_context) for name, sink in self._sinks.items()}
        times = logs["state"].sample_times()
        grid = self.grid(n, t0, hz, frames)
        grid = grid[grid <= times[-1]] if len(times) else grid[:0]
        rows = np.searchsorted(times, grid, side="left")     # first step end at or after t_k
        data = {name: log.data()[:, rows].T for name, log in logs.items()}
        reflex = logs["reflex"].data()
        force = _interval_peaks(times, reflex[0], rows)
        torque = np.stack([_interval_peaks(times, np.abs(reflex[1 + i]), rows) for i in range(7)], axis=-1)
        poses = np.array([pose_to_vector(self.station.hand_pose(q[:7])) for q in data["state"]]).reshape(-1, 7)
        gripper = data["gripper"][:, 0] if "gripper" in data else np.full(len(grid), np.nan)
        logged = None
        if frames and self.frame_log is not None:
            logged = self._read_frames(root_context, grid, hz)
        return StationRecords(grid, poses, data["state"], data["object_state"][:, 0], force,
                              torque.reshape(-1, 7), gripper, logged)

    def _read_frames(self, root_context, grid: np.ndarray, record_hz: float) -> FrameRecords:
        """The logged frame at each k-th grid time (k = samples_per_frame): the first logged at it."""
        k = self.samples_per_frame(record_hz)
        logged = self.frame_log.frames(self.frame_log.GetMyContextFromRoot(root_context))
        times = np.array([f.time for f in logged])
        index = np.arange(0, len(grid), k)
        picked = []
        for t in grid[index]:
            i = int(np.searchsorted(times, t - _TIME_TOL, side="left"))
            if i == len(times) or abs(times[i] - t) > _TIME_TOL:
                raise RuntimeError(f"no camera frame was logged at t = {t:.6f} s: a recording with "
                                   f"frames starts at a camera frame instant (every {self.frame_period} s)")
            picked.append(logged[i])
        n_points = picked[0].points.shape[0] if picked else 0
        return FrameRecords(
            index, np.array([f.time for f in picked]), np.array([f.valid for f in picked], dtype=bool),
            np.array([f.points for f in picked], dtype=np.float32).reshape(-1, n_points, 3),
            np.array([f.X_WO for f in picked]).reshape(-1, 7),
            np.array([f.counts for f in picked], dtype=np.int64).reshape(-1, 3), [f.pixels for f in picked])


def _interval_peaks(times: np.ndarray, values: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """Per sample row r_k, the largest of ``values`` over rows r_(k-1)..r_k (the value at
    the interval's start and after every step of it; for k = 0, row r_0 alone)."""
    starts = np.r_[rows[:1], rows[:-1]]
    return np.array([float(values[a:b + 1].max()) for a, b in zip(starts, rows)])


def frame_peaks(values: np.ndarray, index: np.ndarray) -> np.ndarray:
    """Per frame sample ``index[j]``, the largest of ``values`` (T,) over the samples since the
    previous frame, this one included (for j = 0, index[0] alone)."""
    values = np.asarray(values, dtype=float)
    starts = np.r_[index[:1], np.asarray(index[:-1]) + 1]
    return np.array([float(values[a:b + 1].max()) for a, b in zip(starts, index)])
