"""What a run records, by Drake's loggers in the diagram.

:class:`StationLoggers` adds ``VectorLogSink`` systems (``LogVectorOutput``)
on a station's outputs: the joint state, the object state and the reflex
monitor's state, at the end of every simulator step. All three are computed
in C++ (a Python output evaluated at every step would cost more than the
plant: 60 ms per simulated second with the hand pose logged); the hand pose
X_WE of a sample is the station's ``hand_pose`` of its joint positions, the
value its ``ee_pose`` output has then. The
simulator ends a step at every event time, and a step's end sees the state
after every event before it; so the sample of a grid time t is the first
step end at or after t, the state ``Simulator.AdvanceTo(t)`` leaves (events
due at t still pending). (A periodic publish at 1 / record_hz would be
cheaper, but its times k * period round differently from the plant's
k * time_step: where they fall an ulp apart, it would see the plant's update
at that instant, where they coincide, not.) The logs live in the Context:
resetting a run clears them (:meth:`StationLoggers.clear`), so the diagram
holds no per-run value of its own.

:meth:`StationLoggers.read` returns :class:`StationRecords`: the samples on
the grid ``k / record_hz``, k = 0..n, and per sample the peak filtered
contact force over the interval ending at it [N].
"""

from __future__ import annotations

import dataclasses as dc

import numpy as np
from pydrake.systems.primitives import LogVectorOutput

from drake_skill.station.recording import pose_to_vector

__all__ = ["StationLoggers", "StationRecords"]


@dc.dataclass
class StationRecords:
    """times (T,) [s]; ee_pose (T, 7) X_WE as xyz + wxyz; state (T, 14) joint positions
    [rad] and velocities [rad/s]; object_state (T,) lid angle [rad] or drawer travel [m];
    contact_force (T,) peak filtered robot-scene contact force [N] over the interval
    ending at each sample."""

    times: np.ndarray
    ee_pose: np.ndarray
    state: np.ndarray
    object_state: np.ndarray
    contact_force: np.ndarray


class StationLoggers:
    """The loggers of a station's run (module docstring), added to ``builder`` beside
    ``station`` (any station with the simulated station's ports)."""

    def __init__(self, builder, station, record_hz: float):
        self.station = station
        self.record_hz = float(record_hz)
        ports = {"state": station.GetOutputPort("panda_state"),
                 "object_state": station.GetOutputPort("object_state"),
                 "reflex": station.GetOutputPort("reflex_state")}
        # Publish period 0: at the end of every simulator step (module docstring).
        self._sinks = {name: LogVectorOutput(port, builder, 0.0) for name, port in ports.items()}

    def _log(self, sink, root_context):
        return sink.FindMutableLog(root_context)     # the log within the root context

    def clear(self, root_context) -> None:
        """Empties every log (a run's reset)."""
        for sink in self._sinks.values():
            self._log(sink, root_context).Clear()

    def read(self, root_context, n: int) -> StationRecords:
        """The samples of the grid k / record_hz, k = 0..n, that the run reached (a run
        stopped early has fewer), from the step logs (module docstring)."""
        logs = {name: self._log(sink, root_context) for name, sink in self._sinks.items()}
        times = logs["state"].sample_times()
        grid = np.arange(n + 1) / self.record_hz
        grid = grid[grid <= times[-1]] if len(times) else grid[:0]
        rows = np.searchsorted(times, grid, side="left")     # first step end at or after t_k
        data = {name: log.data()[:, rows].T for name, log in logs.items()}
        force = _interval_peaks(times, logs["reflex"].data()[0], rows)
        poses = np.array([pose_to_vector(self.station.hand_pose(q[:7])) for q in data["state"]]).reshape(-1, 7)
        return StationRecords(grid, poses, data["state"], data["object_state"][:, 0], force)


def _interval_peaks(times: np.ndarray, values: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """Per sample row r_k, the largest of ``values`` over rows r_(k-1)..r_k (the value at
    the interval's start and after every step of it; for k = 0, row r_0 alone)."""
    starts = np.r_[rows[:1], rows[:-1]]
    return np.array([float(values[a:b + 1].max()) for a, b in zip(starts, rows)])
