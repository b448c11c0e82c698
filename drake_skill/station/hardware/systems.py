"""The hardware station's systems: the Panda driver's LCM messages in and out, the checks
that stop it, and the small converters it is wired from (``station.HardwareStation``).

Each is a LeafSystem with named ports; the station (``drake_skill.station.hardware.station``)
only wires them. Talking to the drake-franka-driver: commands are ``lcmt_panda_command`` in
position mode stamped with the wall clock (:class:`PandaCommandEncoder`; Drake's
``PandaCommandSender`` stamps simulation time, which the driver would drop); the status is
decoded by Drake's ``PandaStatusReceiver`` and watched by :class:`StatusMonitor`, which stops
the simulator (``EventStatus.ReachedTermination``, its reason kept in state) on a stale status,
the robot's own reflex or its user stop.
"""

from __future__ import annotations

import time
from typing import Callable

import numpy as np
from drake import lcmt_image, lcmt_image_array, lcmt_panda_command, lcmt_panda_status, lcmt_scope
from pydrake.common.value import AbstractValue, Value
from pydrake.math import RigidTransform
from pydrake.systems.framework import EventStatus, LeafSystem

from drake_skill.station import recording as _recording
from drake_skill.station.controller import make_control_plant

N_JOINTS = 7
#: Period of the status monitor's checks [s]: a stale status is caught at
#: most this long after ``status_timeout``.
STATUS_CHECK_PERIOD = 0.005


class StaleStatusError(RuntimeError):
    """The robot's status stopped arriving: the station stopped commanding.

    ``last_seen`` and ``detected_at``: the station's times [s] of the last new
    status and of the check that found it stale (None where not known).
    """

    reason = "stale_status"

    def __init__(self, message: str, last_seen: float | None = None, detected_at: float | None = None):
        super().__init__(message)
        self.last_seen, self.detected_at = last_seen, detected_at


#: The collision reflex's error, the simulated station's.
ReflexError = _recording.ReflexError


def wall_clock_utime() -> int:
    """Microseconds since the epoch (the driver's ``std::chrono::system_clock``)."""
    return int(time.time() * 1e6)


def clip_to_workspace(p_WE, lower, upper) -> np.ndarray:
    """p_WE (3,) [m] clipped to the box [lower, upper] (world frame)."""
    return np.clip(np.asarray(p_WE, dtype=float), lower, upper)


# --------------------------------------------------------------------------- leaf systems
class WorkspaceClip(LeafSystem):
    """``X_WE`` in, ``X_WE_clipped`` out: the translation clipped to the workspace box,
    the rotation unchanged."""

    def __init__(self, lower, upper):
        super().__init__()
        self._lower, self._upper = np.asarray(lower, float), np.asarray(upper, float)
        self._in = self.DeclareAbstractInputPort("X_WE", Value(RigidTransform()))
        self.DeclareAbstractOutputPort("X_WE_clipped", lambda: Value(RigidTransform()), self._calc_clipped,
                                       {self._in.ticket()})

    def _calc_clipped(self, context, output):
        X = self._in.Eval(context)
        output.set_value(RigidTransform(X.rotation(), clip_to_workspace(X.translation(), self._lower,
                                                                        self._upper)))


class PandaCommandEncoder(LeafSystem):
    """Joint positions ``q`` (7) in, ``lcmt_panda_command`` (position mode) out,
    stamped with the wall clock (:func:`wall_clock_utime`): the message of
    Drake's ``PandaCommandSender`` in position mode, except for ``utime``."""

    def __init__(self, clock: Callable[[], int] = wall_clock_utime):
        super().__init__()
        self._clock = clock
        self._q = self.DeclareVectorInputPort("position", N_JOINTS)
        self.DeclareAbstractOutputPort("lcmt_panda_command", lambda: AbstractValue.Make(lcmt_panda_command()),
                                       self._calc_message, {self._q.ticket(), self.time_ticket()})

    def _calc_message(self, context, output):
        msg = lcmt_panda_command()
        msg.utime = self._clock()
        msg.control_mode_expected = lcmt_panda_status.CONTROL_MODE_POSITION
        msg.num_joint_position = N_JOINTS
        msg.joint_position = [float(v) for v in self._q.Eval(context)]
        msg.num_joint_velocity = msg.num_joint_torque = 0
        msg.joint_velocity, msg.joint_torque = [], []
        output.set_value(msg)


#: StatusMonitor's stop codes, kept in its state (0: running).
STOP_STALE, STOP_ROBOT_REFLEX, STOP_USER_STOPPED = 1, 2, 3


class StatusMonitor(LeafSystem):
    """Watches the status messages; stops the simulator before a command goes out on a bad one.

    Input ``status`` (Python ``lcmt_panda_status``), ``torque_external`` (7) [N m].
    Discrete state [utime of the last new status, context time it was seen,
    stop code, time of the stop]. Every ``period`` s: a status with a new
    ``utime`` refreshes the state; a status older than ``timeout`` s
    (:data:`STOP_STALE`), or one whose ``robot_mode`` is kReflex or kUserStopped
    (the robot stopped itself), stops the run: the check keeps the reason in
    the state and returns ``EventStatus.ReachedTermination``, so the
    simulator's step ends at the instant of the check and no command goes out
    after it. The stop holds until :meth:`mark_fresh` (a run's reset).
    :meth:`stop_error` turns the state into the typed error
    (:class:`StaleStatusError`, :class:`ReflexError`), which
    ``station.recording.advance_station`` raises outside the simulator. (The
    reflex limits on the external torque are checked where the simulated
    station's are, by the reflex monitor on
    :meth:`HardwareStation.robot_scene_contact`.)
    """

    def __init__(self, period: float, timeout: float, channel: str = "PANDA_STATUS"):
        super().__init__()
        self._timeout, self._channel = float(timeout), channel
        self._status = self.DeclareAbstractInputPort("status", AbstractValue.Make(lcmt_panda_status()))
        self._tau = self.DeclareVectorInputPort("torque_external", N_JOINTS)
        self._state = self.DeclareDiscreteState(4)   # [last utime, time seen, stop code, stop time]
        self._stop_tau = self.DeclareDiscreteState(N_JOINTS)   # external torque at a robot stop [N m]
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._check)

    def mark_fresh(self, context) -> None:
        """Records the status now in ``context`` as seen at the context's time; clears a stop."""
        msg = self._status.Eval(context)
        context.get_mutable_discrete_state(self._state).SetFromVector([float(msg.utime), context.get_time(), 0, 0])

    def last_seen(self, context) -> float:
        """Context time [s] the last new status was seen at."""
        return float(context.get_discrete_state(self._state).get_value()[1])

    def stop_error(self, context) -> RuntimeError | None:
        """The typed error of the stop the state holds, or None while running."""
        _, seen, code, t = context.get_discrete_state(self._state).get_value()
        if code == STOP_STALE:
            return StaleStatusError(
                f"no status from the robot on LCM channel {self._channel!r} for {(t - seen) * 1e3:.0f} ms "
                f"(limit {self._timeout * 1e3:.0f} ms, last at t = {seen:.3f} s, now t = {t:.3f} s): "
                "stopped commanding. Check that the driver runs, its --lcm_url and channels, and the network",
                last_seen=seen, detected_at=t)
        if code in (STOP_ROBOT_REFLEX, STOP_USER_STOPPED):
            what = "robot reflex" if code == STOP_ROBOT_REFLEX else "robot user stop"
            return ReflexError(t, 0.0, context.get_discrete_state(self._stop_tau).get_value().copy(), what)
        return None

    def _check(self, context, discrete_state):
        msg = self._status.Eval(context)
        last_utime, seen, code, _ = context.get_discrete_state(self._state).get_value()
        t = context.get_time()
        if code:                                     # a stop holds until the next reset
            return EventStatus.ReachedTermination(self, "the station stopped")
        if msg.num_joints and float(msg.utime) != last_utime:
            last_utime, seen = float(msg.utime), t
        if t - seen > self._timeout:
            code = STOP_STALE
        elif msg.num_joints and msg.robot_mode in (lcmt_panda_status.kReflex, lcmt_panda_status.kUserStopped):
            code = STOP_ROBOT_REFLEX if msg.robot_mode == lcmt_panda_status.kReflex else STOP_USER_STOPPED
            discrete_state.set_value(self._stop_tau, np.asarray(self._tau.Eval(context), dtype=float))
        discrete_state.set_value(self._state, np.array([last_utime, seen, code, t if code else 0.0]))
        if code:
            return EventStatus.ReachedTermination(self, "stale status" if code == STOP_STALE else "robot stop")
        return EventStatus.Succeeded()


class ForwardKinematics(LeafSystem):
    """``panda_state`` (14) in, ``X_WE`` out: the TCP pose of the kinematic arm model of
    ``directives`` (the scenario's; default the robot's own)."""

    def __init__(self, directives=None):
        super().__init__()
        self._plant = make_control_plant(directives)
        self._frame = self._plant.GetFrameByName("ee")
        # Scratch memory for the kinematics, not run state: every evaluation
        # writes all positions before reading.
        self._plant_context = self._plant.CreateDefaultContext()
        self._state = self.DeclareVectorInputPort("panda_state", 2 * N_JOINTS)
        self.DeclareAbstractOutputPort("X_WE", lambda: Value(RigidTransform()), self._calc_pose,
                                       {self._state.ticket()})

    def pose(self, q) -> RigidTransform:
        """X_WE at joint positions q (7) [rad]."""
        self._plant.SetPositions(self._plant_context, q)
        return self._plant.CalcRelativeTransform(self._plant_context, self._plant.world_frame(), self._frame)

    def _calc_pose(self, context, output):
        output.set_value(self.pose(self._state.Eval(context)[:N_JOINTS]))


class GroundTruthDecoder(LeafSystem):
    """``lcmt_scope`` in, ``object_state`` [1] out: its first value, NaN before any message."""

    def __init__(self):
        super().__init__()
        self._msg = self.DeclareAbstractInputPort("message", AbstractValue.Make(lcmt_scope()))
        self.DeclareVectorOutputPort("object_state", 1, self._calc_state, {self._msg.ticket()})

    def _calc_state(self, context, output):
        msg = self._msg.Eval(context)
        output.SetFromVector([float(msg.value[0]) if msg.size > 0 else np.nan])


class LcmImageArrayDecoder(LeafSystem):
    """``lcmt_image_array`` (Python) in; ``color_image`` (RGBA8), ``depth_image``
    (32F, m) and ``label_image`` (16I) out, each of ``width`` x ``height``.

    Drake's ``LcmImageArrayToImages`` (pydrake 1.51.1) fills only the first
    quarter of a 32-bit depth image it decodes (the rest is zero: measured on
    a round trip through ``ImageToLcmImageArrayT``), so the images are
    decoded here with numpy (uncompressed or zlib). Before any message, or
    for an image the message lacks: colour and label zero, depth +inf (no
    return).
    """

    _FORMATS = {  # pixel_format -> (output, channels, dtype)
        lcmt_image.PIXEL_FORMAT_RGBA: ("color_image", 4, np.uint8),
        lcmt_image.PIXEL_FORMAT_DEPTH: ("depth_image", 1, np.float32),
        lcmt_image.PIXEL_FORMAT_LABEL: ("label_image", 1, np.int16),
    }

    def __init__(self, width: int, height: int):
        super().__init__()
        from pydrake.systems.sensors import ImageDepth32F, ImageLabel16I, ImageRgba8U

        self._w, self._h = int(width), int(height)
        self._types = {"color_image": ImageRgba8U, "depth_image": ImageDepth32F, "label_image": ImageLabel16I}
        self._msg = self.DeclareAbstractInputPort("image_array", AbstractValue.Make(lcmt_image_array()))
        for name, kind in self._types.items():
            self.DeclareAbstractOutputPort(
                name, lambda kind=kind: Value(kind(self._w, self._h)),
                lambda context, output, name=name: self._calc_image(context, output, name),
                {self._msg.ticket()})

    def _calc_image(self, context, output, name):
        import zlib

        image = self._types[name](self._w, self._h)
        data = image.mutable_data
        data[:] = np.inf if name == "depth_image" else 0
        for im in self._msg.Eval(context).images:
            target = self._FORMATS.get(im.pixel_format)
            if target is None or target[0] != name:
                continue
            _, channels, dtype = target
            if (im.width, im.height) != (self._w, self._h):
                raise ValueError(f"camera image {name} is {im.width} x {im.height}, the station's camera "
                                 f"is {self._w} x {self._h}: set the scenario's camera width/height")
            raw = zlib.decompress(bytes(im.data)) if im.compression_method == lcmt_image.COMPRESSION_METHOD_ZLIB \
                else bytes(im.data)
            rows = np.frombuffer(raw, dtype=np.uint8).reshape(im.height, im.row_stride)
            pixels = rows[:, :self._w * channels * np.dtype(dtype).itemsize].copy().view(dtype)
            data[:] = pixels.reshape(self._h, self._w, channels)
        output.set_value(image)


class ImageCrop(LeafSystem):
    """Colour, depth and label images in; their crop to ``window`` (a
    :class:`~drake_skill.station.camera.CropWindow`) out: the object camera's
    images, cut from the full frame instead of rendered."""

    def __init__(self, window):
        super().__init__()
        from pydrake.systems.sensors import ImageDepth32F, ImageLabel16I, ImageRgba8U

        self._window = window
        w, h = window.width, window.height
        for name, kind in (("color_image", ImageRgba8U), ("depth_image", ImageDepth32F),
                           ("label_image", ImageLabel16I)):
            port = self.DeclareAbstractInputPort(name, Value(kind(w, h)))
            self.DeclareAbstractOutputPort(
                f"object_{name}", lambda kind=kind: Value(kind(w, h)),
                lambda context, output, port=port, kind=kind: self._calc_crop(context, output, port, kind),
                {port.ticket()})

    def _calc_crop(self, context, output, port, kind):
        image = kind(self._window.width, self._window.height)
        image.mutable_data[:] = self._window.crop(port.Eval(context).data)
        output.set_value(image)


class PlacedObjectPose(LeafSystem):
    """Holds, as an abstract parameter, the pose the object was placed at for this run."""

    def __init__(self):
        super().__init__()
        self._index = self.DeclareAbstractParameter(AbstractValue.Make(RigidTransform()))

    def set_pose(self, context, X_WO: RigidTransform) -> None:
        context.get_mutable_abstract_parameter(self._index).set_value(X_WO)

    def get_pose(self, context) -> RigidTransform:
        return context.get_abstract_parameter(self._index).get_value()


class RealSenseCamera(LeafSystem):  # pragma: no cover - needs a device
    """Colour (RGBA8) and depth (32F, m) images from a RealSense through ``pyrealsense2``.

    The optional extra ``pip install pyrealsense2``; frames are polled at
    ``fps`` and held in abstract state. The depth stream is aligned to the
    colour stream, so the camera's intrinsics are the colour stream's.
    """

    def __init__(self, width: int, height: int, fps: float):
        super().__init__()
        try:
            import pyrealsense2 as rs
        except ImportError as e:
            raise ValueError("camera_source = 'realsense' needs pyrealsense2: pip install pyrealsense2 "
                             "(or camera_source = 'lcm')") from e
        from pydrake.systems.sensors import ImageDepth32F, ImageRgba8U

        self._rs = rs
        self._pipeline = rs.pipeline()
        cfg = rs.config()
        rate = int(round(min(fps, 30)))
        cfg.enable_stream(rs.stream.color, width, height, rs.format.rgba8, 30)
        cfg.enable_stream(rs.stream.depth, width, height, rs.format.z16, 30)
        profile = self._pipeline.start(cfg)
        self._depth_scale = profile.get_device().first_depth_sensor().get_depth_scale()
        self._align = rs.align(rs.stream.color)
        self._color = self.DeclareAbstractState(AbstractValue.Make(ImageRgba8U(width, height)))
        self._depth = self.DeclareAbstractState(AbstractValue.Make(ImageDepth32F(width, height)))
        self.DeclarePeriodicUnrestrictedUpdateEvent(1.0 / rate, 0.0, self._poll)
        self.DeclareStateOutputPort("color_image", self._color)
        self.DeclareStateOutputPort("depth_image", self._depth)

    def _poll(self, context, state):
        from pydrake.systems.sensors import ImageDepth32F, ImageRgba8U

        frames = self._align.process(self._pipeline.wait_for_frames())
        color = np.asanyarray(frames.get_color_frame().get_data())
        depth = np.asanyarray(frames.get_depth_frame().get_data()).astype(np.float32) * self._depth_scale
        depth[depth == 0] = np.inf   # no return
        h, w = depth.shape
        image_c, image_d = ImageRgba8U(w, h), ImageDepth32F(w, h)
        image_c.mutable_data[:] = color.reshape(h, w, 4)
        image_d.mutable_data[:] = depth.reshape(h, w, 1)
        state.get_mutable_abstract_state(int(self._color)).set_value(image_c)
        state.get_mutable_abstract_state(int(self._depth)).set_value(image_d)



class Selector(LeafSystem):
    """The first ``m`` entries of an ``n``-vector."""

    def __init__(self, n: int, m: int):
        super().__init__()
        self._m = m
        self._u = self.DeclareVectorInputPort("u", n)
        self.DeclareVectorOutputPort("y", m, self._calc_y, {self._u.ticket()})

    def _calc_y(self, context, output):
        output.SetFromVector(self._u.Eval(context)[:self._m])
