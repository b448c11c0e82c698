"""The loggers of a run (drake_skill.station.loggers) on a stand-in station: no plant, fixed numbers.

The stand-in has the station's three output ports (and a gripper command), each the discrete state
of a counter that a periodic update every 1 ms advances, so that the value a logger sees at each
step end is known; a stand-in segmenter's outputs are the counter's too. (tests/test_rollout.py
checks the same loggers against the ports read after each advance on the real station.)
"""

import types


import numpy as np
import pytest
from pydrake.common.value import AbstractValue, Value
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, EventStatus, LeafSystem

from drake_skill.perception.segmentation import SegmentPixels
from drake_skill.station.loggers import StationLoggers, StationRecords, _interval_peaks, frame_peaks

STEP = 1e-3
# The reflex's f_hat at update k (k = 0 the initial state): not monotonic, so a peak
# over an interval is not its last value.
FORCE = [0.0, 3.0, 1.0, 7.0, 2.0, 2.5, 9.0, 4.0, 0.5, 6.0, 1.5, 8.0, 3.5, 0.25, 5.0, 2.0]


class _Counter(LeafSystem):
    """Discrete state k (one value), advanced every STEP; outputs: ``panda_state`` (14)
    [k, 2k, ..., 14k] / 100, ``object_state`` (2) [k / 10, -1], ``reflex_state`` (10)
    [FORCE[k], k, 0, ...]."""

    def __init__(self):
        super().__init__()
        self._k = self.DeclareDiscreteState(1)
        self.DeclarePeriodicDiscreteUpdateEvent(STEP, 0.0, self._update)
        self.DeclareVectorOutputPort("panda_state", 14, self._state, {self.xd_ticket()})
        self.DeclareVectorOutputPort("object_state", 2, self._object, {self.xd_ticket()})
        self.DeclareVectorOutputPort("reflex_state", 10, self._reflex, {self.xd_ticket()})
        self.DeclareVectorOutputPort("gripper", 1, lambda c, o: o.SetFromVector([self._k_of(c) / 1000.0]),
                                     {self.xd_ticket()})

    def _k_of(self, context) -> int:
        return int(context.get_discrete_state(self._k).get_value()[0])

    def _update(self, context, discrete_state):
        discrete_state.set_value(self._k, [self._k_of(context) + 1.0])
        return EventStatus.Succeeded()

    def _state(self, context, output):
        output.SetFromVector(self._k_of(context) * np.arange(1, 15) / 100.0)

    def _object(self, context, output):
        output.SetFromVector([self._k_of(context) / 10.0, -1.0])

    def _reflex(self, context, output):
        k = self._k_of(context)
        output.SetFromVector(np.r_[FORCE[k % len(FORCE)], k, 0.0, -FORCE[k % len(FORCE)], np.zeros(6)])

    @staticmethod
    def hand_pose(q) -> RigidTransform:
        """X_WE of joint positions q (7): [q0, q1, q2] and a yaw of q3 rad."""
        assert len(q) == 7
        return RigidTransform(RollPitchYaw(0.0, 0.0, q[3]), [q[0], q[1], q[2]])


class _Segmenter(LeafSystem):
    """A stand-in ObjectSegmenter fed the counter's ``panda_state``: valid unless k % 12 == 8;
    object_points (3, 3) all k; X_WO at [k, 0, 0] (held at the last valid k when not valid:
    the outputs are of k alone here, so the test sees which step the log read); pixels a
    4 x 4 image of value k, its masks nested (hue 3 rows, coloured 2, kept 1)."""

    config = types.SimpleNamespace(period_s=0.004, offset_s=0.0, image_width=160)   # stride 2

    def __init__(self):
        super().__init__()
        self._state = self.DeclareVectorInputPort("panda_state", 14)
        k = self._k
        self.valid = self.DeclareVectorOutputPort("valid", 1, lambda c, o: o.SetFromVector([k(c) % 12 != 8]))
        self.points = self.DeclareAbstractOutputPort("object_points", lambda: AbstractValue.Make(np.zeros((3, 3))),
                                                     lambda c, o: o.set_value(np.full((3, 3), float(k(c)))))
        self.X_WO = self.DeclareAbstractOutputPort("X_WO", lambda: Value(RigidTransform()),
                                                   lambda c, o: o.set_value(RigidTransform([k(c), 0.0, 0.0])))
        self.pixels = self.DeclareAbstractOutputPort("pixels", lambda: AbstractValue.Make(object()), self._pixels)

    def _k(self, context) -> int:
        return int(round(self._state.Eval(context)[0] * 100))

    def _pixels(self, context, output):
        rows = np.arange(4)[:, None] * np.ones((1, 4))
        output.set_value(SegmentPixels(np.full((4, 4, 3), self._k(context), np.uint8), rows < 3, rows < 2, rows < 1))

    def get_valid_output_port(self):
        return self.valid

    def get_object_points_output_port(self):
        return self.points

    def get_X_WO_output_port(self):
        return self.X_WO

    def get_pixels_output_port(self):
        return self.pixels


def _run(record_hz: float, until: float):
    builder = DiagramBuilder()
    station = builder.AddSystem(_Counter())
    loggers = StationLoggers(builder, station, record_hz)
    simulator = Simulator(builder.Build())
    simulator.Initialize()
    simulator.AdvanceTo(until)
    return loggers, simulator


def test_interval_peaks_are_the_largest_from_the_previous_row_to_this_one():
    values = np.array([5.0, 1.0, 4.0, 2.0, 9.0, 3.0, 0.0, 6.0])
    np.testing.assert_array_equal(_interval_peaks(np.arange(8.0), values, np.array([1, 3, 4, 7])),
                                  [1.0, 4.0, 9.0, 9.0])
    # A repeated row is that row's value alone; the first sample is row r_0 alone.
    np.testing.assert_array_equal(_interval_peaks(np.arange(8.0), values, np.array([0, 0, 2, 2, 5])),
                                  [5.0, 5.0, 5.0, 4.0, 9.0])
    assert _interval_peaks(np.arange(8.0), values, np.array([], dtype=int)).shape == (0,)


def test_the_loggers_read_the_grid_samples_and_the_interval_peaks():
    loggers, simulator = _run(record_hz=250.0, until=0.012)     # a sample every 4 steps
    assert loggers.record_hz == 250.0 and isinstance(loggers.record_hz, float)
    records = loggers.read(simulator.get_context(), 3)
    assert isinstance(records, StationRecords)
    np.testing.assert_array_equal(records.times, [0.0, 0.004, 0.008, 0.012])
    k = np.array([0, 4, 8, 12])              # the counter at each step end at a grid time
    np.testing.assert_allclose(records.state, k[:, None] * np.arange(1, 15) / 100.0, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(records.object_state, k / 10.0)
    # Peaks of FORCE over k = 0, 0..4, 4..8, 8..12 (both ends included).
    np.testing.assert_array_equal(records.contact_force, [0.0, 7.0, 9.0, 8.0])
    # Asked for fewer samples than the run reached: those, k = 0..n.
    np.testing.assert_array_equal(loggers.read(simulator.get_context(), 2).times, [0.0, 0.004, 0.008])
    assert records.ee_pose.shape == (4, 7)
    for row, kk in zip(records.ee_pose, k):
        q = kk * np.arange(1, 8) / 100.0
        expected = np.r_[q[:3], RollPitchYaw(0.0, 0.0, q[3]).ToQuaternion().wxyz()]
        np.testing.assert_allclose(row, expected, rtol=0, atol=1e-15)


def test_a_run_stopped_early_has_fewer_samples_and_clear_empties_the_logs():
    loggers, simulator = _run(record_hz=500.0, until=0.005)
    context = simulator.get_mutable_context()
    records = loggers.read(context, 10)                 # asked for 0..20 ms, reached 5 ms
    np.testing.assert_array_equal(records.times, [0.0, 0.002, 0.004])
    np.testing.assert_array_equal(records.object_state, [0.0, 0.2, 0.4])
    np.testing.assert_array_equal(records.contact_force, [0.0, 3.0, 7.0])
    # A grid time between step ends takes the first step end after it.
    records = loggers.read(context, 2)
    np.testing.assert_array_equal(records.times, [0.0, 0.002, 0.004])
    loggers.clear(context)
    empty = loggers.read(context, 10)
    for name in ("times", "object_state", "contact_force"):
        assert getattr(empty, name).shape == (0,), name
    assert empty.ee_pose.shape == (0, 7) and empty.state.shape == (0, 14)
    # Logging goes on after a clear (the grid still starts at 0: a run's reset also resets
    # the time; here the grid times before the first step end take that step end).
    simulator.AdvanceTo(0.007)
    again = loggers.read(context, 10)
    np.testing.assert_array_equal(again.times, [0.0, 0.002, 0.004, 0.006])
    np.testing.assert_array_equal(again.object_state, [0.6] * 4)
    np.testing.assert_array_equal(again.contact_force, [FORCE[6]] * 4)


@pytest.mark.parametrize("record_hz", [300.0])
def test_grid_times_between_step_ends_take_the_next_step_end(record_hz):
    loggers, simulator = _run(record_hz=record_hz, until=0.01)
    records = loggers.read(simulator.get_context(), 3)
    np.testing.assert_allclose(records.times, np.arange(4) / record_hz)
    # 1/300 s = 3.33 ms: the step end at 4 ms; 6.67 ms: 7 ms; 10 ms: 10 ms.
    np.testing.assert_array_equal(records.object_state, [0.0, 0.4, 0.7, 1.0])
    np.testing.assert_array_equal(records.contact_force, [0.0, 7.0, 9.0, 6.0])


def test_a_recording_started_later_logs_torques_gripper_and_frames_on_its_grid():
    """start() at a camera frame (t = 4 ms) empties the logs and logs that instant; read(t0) takes
    the grid from there: the gripper command, the interval peaks of each |tau_hat_i| and, every
    k-th sample, the segmenter's frame of the same step end."""
    builder = DiagramBuilder()
    station = builder.AddSystem(_Counter())
    segmenter = builder.AddSystem(_Segmenter())
    builder.Connect(station.GetOutputPort("panda_state"), segmenter.GetInputPort("panda_state"))
    loggers = StationLoggers(builder, station, 500.0, gripper_command=station.GetOutputPort("gripper"),
                             segmenter=segmenter)
    assert loggers.frame_period == 0.004 and loggers.samples_per_frame(500.0) == 2
    with pytest.raises(ValueError, match="record_hz = 300.0 Hz: expected an integer multiple of the camera's 250 Hz"):
        loggers.samples_per_frame(300.0)
    simulator = Simulator(builder.Build())
    context = simulator.get_mutable_context()
    simulator.Initialize()
    simulator.AdvanceTo(0.004)
    assert loggers.start(context) == 0.004
    simulator.AdvanceTo(0.016)
    records = loggers.read(context, 6, t0=0.004)
    np.testing.assert_allclose(records.times, 0.004 + np.arange(7) * 0.002, rtol=0, atol=1e-15)
    k = np.arange(4, 17, 2)                          # the counter at each sample's step end
    np.testing.assert_array_equal(records.object_state, k / 10.0)
    np.testing.assert_array_equal(records.gripper, k / 1000.0)
    # |tau_hat_1| = k rises: its peak is the sample's; |tau_hat_3| = FORCE[k]: the force's peaks.
    np.testing.assert_array_equal(records.external_torque[:, 0], k)
    np.testing.assert_array_equal(records.external_torque[:, 2], records.contact_force)
    np.testing.assert_array_equal(records.contact_force, [2.0, 9.0, 9.0, 6.0, 8.0, 5.0, 5.0])
    assert not records.external_torque[:, [1, 3, 4, 5, 6]].any()
    frames = records.frames
    np.testing.assert_array_equal(frames.index, [0, 2, 4, 6])
    np.testing.assert_allclose(frames.times, [0.004, 0.008, 0.012, 0.016], rtol=0, atol=1e-15)
    kf = k[frames.index]
    np.testing.assert_array_equal(frames.valid, kf % 12 != 8)
    assert frames.first_valid == 0 and frames.points.dtype == np.float32 and frames.points.shape == (4, 3, 3)
    np.testing.assert_array_equal(frames.points[:, 0, 0], kf)
    np.testing.assert_array_equal(frames.X_WO[:, 0], kf)
    np.testing.assert_array_equal(frames.X_WO[:, 3:], np.tile([1.0, 0, 0, 0], (4, 1)))
    np.testing.assert_array_equal(frames.pixel_counts, np.tile([12, 8, 4], (4, 1)))
    assert [p.rgb.shape for p in frames.pixels] == [(2, 2, 3)] * 4                    # every 2nd pixel
    assert [int(p.rgb[0, 0, 0]) for p in frames.pixels] == kf.tolist()
    # The peak force of each frame: its samples since the previous frame.
    np.testing.assert_array_equal(frame_peaks(records.contact_force, frames.index), [2.0, 9.0, 8.0, 5.0])
    # Frames are only at the camera's instants: a grid from 6 ms has none there.
    with pytest.raises(RuntimeError, match=r"no camera frame was logged at t = 0\.006000 s"):
        loggers.read(context, 4, t0=0.006)
    assert loggers.read(context, 4, t0=0.006, frames=False).frames is None
    # A clear empties the frame log too.
    loggers.clear(context)
    assert loggers.frame_log.frames(loggers.frame_log.GetMyContextFromRoot(context)) == ()
