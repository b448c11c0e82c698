"""The hardware station: the simulated station's ports, backed by a real Panda over LCM.

``build_hardware_station(config)`` returns a :class:`HardwareStation`, a Diagram
exporting the same ports (names and value types) as ``build_station`` (see
``drake_skill.station.sim.builder``), so the systems around the station (DMP,
segmenter, PCAE, reward) and the rollout runner do not know which one they
hold (docs/architecture.md, "One diagram per skill execution"; the pattern of
``MakeHardwareStation`` in the ``manipulation`` course)::

    ee_pose_desired --> [workspace clip] --> [EndEffectorController] --q--> [command encoder] --> LCM PANDA_COMMAND
    gripper_command --> [SchunkWsgCommandSender] --> LCM PANDA_HAND_COMMAND
    LCM PANDA_STATUS --> [PandaStatusReceiver] --> panda_state, ee_pose (forward kinematics), external_torque
                     \\-> [status monitor]: stale status, the robot's own reflex
    LCM camera images --> [LcmImageArrayDecoder] --> color/depth/label_image
                                                         --> [DepthImageToPointCloud] --> point_cloud
                      \\-> [ImageCrop] --> object_*_image --> [DepthImageToPointCloud] --> object_point_cloud

Talking to the drake-franka-driver (``--control_mode=position``):

* Commands are ``lcmt_panda_command`` in position mode, published every
  ``command_period`` and stamped with **wall-clock** ``utime`` [us since the
  epoch]: the driver drops commands older than its ``--expire_sec`` (0.1 s)
  by its own clock. Drake's ``PandaCommandSender`` stamps simulation time,
  which the driver would reject, so :class:`PandaCommandEncoder` builds the
  message instead (same fields, position mode).
* The status is decoded by Drake's ``PandaStatusReceiver``.

Safety lives here, not in the caller's hands:

* The first command is the measured position: ``reset`` waits for a status
  and starts the controller's integrator at the measured joints.
* Commanded hand positions are clipped to the driver's ``workspace``.
* Joint commands come out of the same :class:`EndEffectorController` as in
  simulation: differential IK within Franka's joint position and velocity
  limits, then the rate limiter at the velocity, acceleration and jerk
  limits of ``drake_skill.station.limits``.
* No status for more than ``status_timeout`` (100 ms) stops the station with
  :class:`StaleStatusError`: the check runs every ``STATUS_CHECK_PERIOD``
  (5 ms), and the command published at the instant it fires is the last.
* The reflex: the driver reports the robot's own reflex (``robot_mode`` =
  kReflex), which stops the station; and :meth:`HardwareStation.robot_scene_contact`
  gives the measured external joint torques (the driver's
  ``joint_torque_external``) to the same check that decides the reflex in
  simulation (the recorder's monitor in ``drake_skill.station.recording``,
  on the scenario's ``reflex`` limits).

The station's simulator must run in real time (``realtime`` is True; the
rollout runner paces its simulator by it). Time inside the diagram is the
simulator's; the status age is measured in it.

Plant models are kept only for the forward kinematics of ``ee_pose`` (the
arm) and for Meshcat (arm, hand, table; with ``meshcat``).
There is no ground truth on the robot: ``object_state`` is NaN (a simulated
robot publishes its own on ``ground_truth_channel``) and ``contact_results``
empty; ``object_pose`` is the pose the object was placed
at for the rollout (the human is asked to place it there).
"""

from __future__ import annotations

import time
from typing import Callable

import numpy as np
from drake import (lcmt_image, lcmt_image_array, lcmt_panda_command, lcmt_panda_status, lcmt_schunk_wsg_command,
                   lcmt_scope)
from pydrake.common.value import AbstractValue, Value
from pydrake.lcm import DrakeLcm
from pydrake.manipulation import PandaStatusReceiver, SchunkWsgCommandSender
from pydrake.math import RigidTransform
from pydrake.multibody.plant import ContactResults
from pydrake.systems.framework import Diagram, DiagramBuilder, EventStatus, LeafSystem
from pydrake.systems.lcm import LcmInterfaceSystem, LcmPublisherSystem, LcmSubscriberSystem
from pydrake.systems.primitives import ConstantValueSource, ConstantVectorSource, Multiplexer

from drake_skill.station import recording as _recording
from drake_skill.station.placement import nominal_object_pose, object_parts, random_object_pose
from drake_skill.station.controller import EndEffectorController, make_control_plant
from drake_skill.station.scenario import Scenario, validate_scenario
from drake_skill.station.drivers import PandaLcmDriver, require_panda_driver
from drake_skill.station.reflex import add_reflex_monitor

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


class _ObjectModel:
    """The scenario's object alone in a plant (its perception geometry), for
    sizing the object camera's window as the simulated station does
    (``drake_skill.station.camera.object_swept_points``)."""

    def __init__(self, station_config):
        from pydrake.multibody.parsing import Parser
        from pydrake.multibody.plant import AddMultibodyPlantSceneGraph

        from drake_skill.station.models import add_package_paths

        builder = DiagramBuilder()
        self.plant, self.scene_graph = AddMultibodyPlantSceneGraph(builder, 0.0)
        parser = Parser(self.plant)
        add_package_paths(parser.package_map())
        o = station_config.object
        url = next(d.add_model.file for d in station_config.directives
                   if d.add_model is not None and d.add_model.name == o.model)
        self.object_instance = parser.AddModels(url=url)[0]
        self.object_base, self.object_joint = object_parts(self.plant, self.object_instance, station_config)
        self.plant.Finalize()
        self.config = station_config


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


# --------------------------------------------------------------------------- camera geometry
def camera_geometry(station_config):
    """(CameraInfo, X_WC) of the scenario's camera (Drake's CameraConfig), as the
    simulated station renders it."""
    color, _ = station_config.camera.MakeCameras()
    X_PB = station_config.camera.X_PB.GetDeterministicValue()
    return color.core().intrinsics(), X_PB @ color.core().sensor_pose_in_camera_body()


# --------------------------------------------------------------------------- the station
class HardwareStation(Diagram):
    """The hardware port (see the module docstring for what it does).

    Handles a runner needs: ``config`` (the scenario), ``driver`` (its
    ``PandaLcmDriver``), ``lcm``, ``realtime`` (True), ``ee_controller``;
    :meth:`reset`, :meth:`object_pose`, :meth:`set_reset_hook`.

    Args:
        config: the scenario (``Scenario``); its ``driver`` must be a
            :class:`~drake_skill.station.drivers.PandaLcmDriver` (channels, URL,
            timeouts, workspace).
        lcm: a DrakeLcm to use (default: a new one on ``config.driver.lcm_url``). The
            station owns its LcmInterfaceSystem: it is the one that handles
            the subscriptions of that DrakeLcm.
        meshcat: a ``pydrake.geometry.Meshcat`` to draw the measured arm (and the
            commanded finger opening) in, or None.
        commanding: send position and hand commands (False: only listen,
            e.g. while a person guides the arm for a kinesthetic demonstration).
    """

    realtime = True
    #: The robot has no simulator truth: ``object_state`` is NaN unless a
    #: simulated robot publishes it on ``ground_truth_channel``.
    has_ground_truth = False

    def __init__(self, config: Scenario, lcm: DrakeLcm | None = None, meshcat=None,
                 commanding: bool = True):
        super().__init__()
        self.config = validate_scenario(config)
        self.driver = driver = require_panda_driver(config, "the hardware station")
        self.lcm = lcm if lcm is not None else DrakeLcm(driver.lcm_url)
        self._reset_hook = None
        builder = DiagramBuilder()
        builder.AddNamedSystem("lcm", LcmInterfaceSystem(self.lcm))

        # Status in.
        self._status_sub = builder.AddNamedSystem("status_subscriber", LcmSubscriberSystem.Make(
            driver.status_channel, lcmt_panda_status, self.lcm, use_cpp_serializer=True))
        receiver = builder.AddNamedSystem("status_receiver", PandaStatusReceiver(N_JOINTS))
        builder.Connect(self._status_sub.get_output_port(), receiver.get_input_port())
        self._status_py = builder.AddNamedSystem("status_monitor_subscriber", LcmSubscriberSystem.Make(
            driver.status_channel, lcmt_panda_status, self.lcm))
        self.monitor = builder.AddNamedSystem("status_monitor", StatusMonitor(
            STATUS_CHECK_PERIOD, driver.status_timeout, driver.status_channel))
        builder.Connect(self._status_py.get_output_port(), self.monitor.GetInputPort("status"))
        builder.Connect(receiver.get_torque_external_output_port(), self.monitor.GetInputPort("torque_external"))
        state = builder.AddNamedSystem("panda_state", Multiplexer([N_JOINTS, N_JOINTS]))
        builder.Connect(receiver.get_position_measured_output_port(), state.get_input_port(0))
        builder.Connect(receiver.get_velocity_measured_output_port(), state.get_input_port(1))
        builder.ExportOutput(state.get_output_port(), "panda_state")
        fk = self._forward_kinematics = builder.AddNamedSystem("ee_pose", ForwardKinematics(config.directives))
        builder.Connect(state.get_output_port(), fk.get_input_port())
        builder.ExportOutput(fk.get_output_port(), "ee_pose")
        self._receiver = receiver

        # Hand pose in, joint position commands out.
        ws = driver.workspace
        clip = builder.AddNamedSystem("workspace_clip", WorkspaceClip(ws.lower, ws.upper))
        builder.ExportInput(clip.get_input_port(), "ee_pose_desired")
        controller = builder.AddNamedSystem("ee_controller", EndEffectorController(
            config.controller, config.q_home, directives=config.directives))
        self.ee_controller = controller
        builder.Connect(clip.get_output_port(), controller.GetInputPort("X_WE_desired"))
        q_only = builder.AddNamedSystem("q_commanded", _Selector(2 * N_JOINTS, N_JOINTS))
        builder.Connect(controller.GetOutputPort("panda_state_desired"), q_only.get_input_port())
        encoder = builder.AddNamedSystem("command_encoder", PandaCommandEncoder())
        builder.Connect(q_only.get_output_port(), encoder.get_input_port())
        if commanding:
            publisher = builder.AddNamedSystem("command_publisher", LcmPublisherSystem.Make(
                driver.command_channel, lcmt_panda_command, self.lcm, publish_period=driver.command_period))
            builder.Connect(encoder.get_output_port(), publisher.get_input_port())

        # Gripper.
        hand = builder.AddNamedSystem("hand_command", SchunkWsgCommandSender())
        if meshcat is None:
            builder.ExportInput(hand.GetInputPort("position"), "gripper_command")
        force = builder.AddNamedSystem("hand_force", ConstantVectorSource([driver.hand_force]))
        builder.Connect(force.get_output_port(), hand.GetInputPort("force_limit"))
        if commanding:
            hand_pub = builder.AddNamedSystem("hand_publisher", LcmPublisherSystem.Make(
                driver.hand_command_channel, lcmt_schunk_wsg_command, self.lcm, publish_period=0.1,
                use_cpp_serializer=True))
            builder.Connect(hand.get_output_port(), hand_pub.get_input_port())

        # No ground truth on the robot; a simulated robot publishes its own.
        self._truth_sub = None
        if driver.ground_truth_channel:
            truth_sub = self._truth_sub = builder.AddNamedSystem("ground_truth_subscriber", LcmSubscriberSystem.Make(
                driver.ground_truth_channel, lcmt_scope, self.lcm))
            truth = builder.AddNamedSystem("object_state", GroundTruthDecoder())
            builder.Connect(truth_sub.get_output_port(), truth.get_input_port())
        else:
            truth = builder.AddNamedSystem("object_state", ConstantVectorSource([np.nan]))
        builder.ExportOutput(truth.get_output_port(), "object_state")
        no_contact = builder.AddNamedSystem("contact_results", ConstantValueSource(
            AbstractValue.Make(ContactResults())))
        builder.ExportOutput(no_contact.get_output_port(), "contact_results")
        builder.ExportOutput(receiver.get_torque_external_output_port(), "external_torque")
        # The simulated station's reflex on what the robot measures: the external joint
        # torques (the Panda does not measure the contact force: 0).
        zero_force = builder.AddNamedSystem("robot_scene_contact", ConstantVectorSource([0.0]))
        self.reflex_monitor = add_reflex_monitor(builder, zero_force.get_output_port(),
                                                 receiver.get_torque_external_output_port(),
                                                 self.config.reflex, STATUS_CHECK_PERIOD)
        builder.ExportOutput(controller.GetOutputPort("joint_acceleration_commanded"),
                             "joint_acceleration_commanded")
        self.placed_pose = builder.AddNamedSystem("placed_object_pose", PlacedObjectPose())

        self._camera_sub = None
        self.object_camera = None
        if self.config.enable_camera:
            self._add_camera(builder)
        if meshcat is not None:
            self._add_meshcat(builder, meshcat, receiver.get_position_measured_output_port(),
                              hand.GetInputPort("position"))
        builder.BuildInto(self)
        self.set_name("hardware_station")

    def _add_camera(self, builder) -> None:
        from drake_skill.station.camera import (MARGIN_PX, ObjectCamera, crop_camera_info, crop_window,
                                                export_camera_ports, object_swept_points)

        driver = self.driver
        info, X_WC = camera_geometry(self.config)
        self.camera_info, self._X_WC = info, X_WC
        if driver.camera_source == "realsense":  # pragma: no cover - needs a device
            cam = builder.AddNamedSystem("camera", RealSenseCamera(info.width(), info.height(), 10.0))
            color, depth = cam.GetOutputPort("color_image"), cam.GetOutputPort("depth_image")
            from pydrake.systems.sensors import ImageLabel16I
            label = builder.AddNamedSystem("label_image", ConstantValueSource(
                AbstractValue.Make(ImageLabel16I(info.width(), info.height())))).get_output_port()
        else:
            self._camera_sub = builder.AddNamedSystem("camera_subscriber", LcmSubscriberSystem.Make(
                driver.camera_channel, lcmt_image_array, self.lcm))
            images = builder.AddNamedSystem("camera_images", LcmImageArrayDecoder(info.width(), info.height()))
            builder.Connect(self._camera_sub.get_output_port(), images.get_input_port())
            color, depth, label = (images.GetOutputPort(name) for name in ("color_image", "depth_image",
                                                                           "label_image"))
        export_camera_ports(builder, info, X_WC, color, depth, label)
        # The object camera: the same crop of the frame as the simulated station's.
        window = crop_window(object_swept_points(_ObjectModel(self.config)), X_WC, info, MARGIN_PX)
        crop_info = crop_camera_info(info, window)
        crop = builder.AddNamedSystem("object_crop", ImageCrop(window))
        for name, port in (("color_image", color), ("depth_image", depth), ("label_image", label)):
            builder.Connect(port, crop.GetInputPort(name))
        export_camera_ports(builder, crop_info, X_WC, *(crop.GetOutputPort(f"object_{name}") for name in
                                                        ("color_image", "depth_image", "label_image")),
                            prefix="object_")
        self.object_camera = ObjectCamera(window, crop_info, None)

    def _add_meshcat(self, builder, meshcat, q_port, opening_input) -> None:
        """The arm, hand and table of the scenario in Meshcat, posed by the measured joints."""
        from pydrake.geometry import MeshcatVisualizer, MeshcatVisualizerParams, Role, SceneGraph
        from pydrake.multibody.plant import MultibodyPlant
        from pydrake.systems.primitives import MatrixGain, PassThrough
        from pydrake.systems.rendering import MultibodyPositionToGeometryPose

        from drake_skill.station.controller import add_scenario_instances
        from drake_skill.station.models import add_panda_illustration

        scene_graph = builder.AddNamedSystem("viz_scene_graph", SceneGraph())
        plant = MultibodyPlant(0.0)
        plant.RegisterAsSourceForSceneGraph(scene_graph)
        arm, hand, _ = add_scenario_instances(plant, ("panda", "panda_hand", "table"), self.config.directives)
        add_panda_illustration(plant, scene_graph, (arm, hand))
        plant.Finalize()
        if plant.num_positions() != N_JOINTS + 2:
            raise AssertionError(f"the Meshcat model has {plant.num_positions()} positions, expected 9")
        # The plant lives as long as the station (the pose system keeps a reference).
        self._viz_plant = plant
        # The opening goes both to the hand driver and, halved per finger, to the drawing.
        opening = builder.AddNamedSystem("viz_opening", PassThrough(1))
        builder.ExportInput(opening.get_input_port(), "gripper_command")
        builder.Connect(opening.get_output_port(), opening_input)
        fingers = builder.AddNamedSystem("viz_fingers", MatrixGain(np.array([[0.5], [0.5]])))
        builder.Connect(opening.get_output_port(), fingers.get_input_port())
        q = builder.AddNamedSystem("viz_positions", Multiplexer([N_JOINTS, 2]))
        builder.Connect(q_port, q.get_input_port(0))
        builder.Connect(fingers.get_output_port(), q.get_input_port(1))
        to_pose = builder.AddNamedSystem("viz_poses", MultibodyPositionToGeometryPose(plant))
        builder.Connect(q.get_output_port(), to_pose.get_input_port())
        builder.Connect(to_pose.get_output_port(), scene_graph.get_source_pose_port(plant.get_source_id()))
        MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat,
                                       MeshcatVisualizerParams(role=Role.kIllustration))

    # ------------------------------------------------------------------ object placement
    def nominal_object_pose(self) -> RigidTransform:
        return nominal_object_pose(self.config)

    def random_object_pose(self, seed: int) -> RigidTransform:
        return random_object_pose(self.config, seed)

    def camera_pose(self) -> RigidTransform:
        if not self.config.enable_camera:
            raise ValueError("this station was built with enable_camera = false")
        return self._X_WC

    def set_reset_hook(self, hook: Callable[[int | None, RigidTransform], None] | None) -> None:
        """``hook(seed, X_WO)`` is called by :meth:`reset` before it reads the robot:
        a human places the object at X_WO and confirms (``hardware run`` prompts
        for the Enter key). None: no wait (a simulated robot resets itself)."""
        self._reset_hook = hook

    def hand_pose(self, q) -> RigidTransform:
        """X_WE, the ``ee_pose`` output's value, at joint positions q (7) [rad]."""
        return self._forward_kinematics.pose(np.asarray(q, dtype=float))

    def stop_error(self, context) -> RuntimeError | None:
        """The status monitor's stop (stale status, the robot's own reflex or user stop), else
        the reflex monitor's trip, in ``context`` (a root context), as the typed error; or None."""
        for monitor in (self.monitor, self.reflex_monitor):
            error = monitor.stop_error(monitor.GetMyContextFromRoot(context))
            if error is not None:
                return error
        return None

    def robot_scene_contact(self, context) -> tuple[float, np.ndarray]:
        """(contact force [N], external joint torques (7) [N m]) as the robot measures
        them: the Panda estimates the external joint torques (the driver's
        ``joint_torque_external``) but not the contact force, reported as 0."""
        tau = self.GetOutputPort("external_torque").Eval(self.GetMyContextFromRoot(context))
        return 0.0, np.asarray(tau, dtype=float)

    def object_pose(self, context) -> RigidTransform:
        """The pose the object was placed at for this run (no ground truth on hardware)."""
        return self.placed_pose.get_pose(self.placed_pose.GetMyContextFromRoot(context))

    # ------------------------------------------------------------------ reset
    def _pump_until(self, subscriber, what: str, timeout: float) -> None:
        """Handles LCM until ``subscriber`` receives a new message; StaleStatusError after ``timeout`` s."""
        count = subscriber.WaitForMessage(-1, None, 1e-4)
        deadline = time.monotonic() + timeout
        while True:
            self.lcm.HandleSubscriptions(5)
            if subscriber.WaitForMessage(count, None, 1e-4) > count:
                return
            if time.monotonic() > deadline:
                driver = self.driver
                raise StaleStatusError(
                    f"no {what} within {timeout:.1f} s on LCM {driver.lcm_url or '(default URL)'}: "
                    "is the driver (or drake-skill sim-robot) running with the same URL and channels?")

    def reset(self, context, seed: int | None = None) -> RigidTransform:
        """Prepares a context just set to its defaults for a run on the robot.

        Calls the reset hook (a human places the object at X_WO drawn from
        ``seed``, as the simulated station would place it), waits for a fresh
        status (and camera frame), loads them into ``context``, starts the
        controller at the measured joint positions (the first command holds
        the robot where it is) and the status monitor at the context's time.
        Returns X_WO.
        """
        X_WO = self.nominal_object_pose() if seed is None else self.random_object_pose(seed)
        if self._reset_hook is not None:
            self._reset_hook(seed, X_WO)
        timeout = self.driver.reset_timeout
        self._pump_until(self._status_sub, "robot status", timeout)
        if self._camera_sub is not None:
            self._pump_until(self._camera_sub, "camera image", timeout)
        self.lcm.HandleSubscriptions(0)
        for sub in (self._status_sub, self._status_py, self._camera_sub, self._truth_sub):
            if sub is not None:
                sub.ExecuteForcedEvents(sub.GetMyMutableContextFromRoot(context))
        station_context = self.GetMyContextFromRoot(context)
        q = self.GetOutputPort("panda_state").Eval(station_context)[:N_JOINTS]
        self.ee_controller.set_joint_positions(context, q)
        self.monitor.mark_fresh(self.monitor.GetMyMutableContextFromRoot(context))
        self.reflex_monitor.start(self.reflex_monitor.GetMyMutableContextFromRoot(context))
        self.placed_pose.set_pose(self.placed_pose.GetMyMutableContextFromRoot(context), X_WO)
        return X_WO


class _Selector(LeafSystem):
    """The first ``m`` entries of an ``n``-vector."""

    def __init__(self, n: int, m: int):
        super().__init__()
        self._m = m
        self._u = self.DeclareVectorInputPort("u", n)
        self.DeclareVectorOutputPort("y", m, self._calc_y, {self._u.ticket()})

    def _calc_y(self, context, output):
        output.SetFromVector(self._u.Eval(context)[:self._m])


def build_hardware_station(config: Scenario | None = None, lcm: DrakeLcm | None = None,
                           meshcat=None, commanding: bool = True) -> HardwareStation:
    """Builds the hardware station of the scenario ``config`` (its driver a ``!PandaLcmDriver``;
    default: the Open scene on LCM's default URL); ``drake_skill.station.make.make_station``
    with ``hardware=True`` does the same."""
    config = config if config is not None else Scenario(driver=PandaLcmDriver())
    return HardwareStation(config, lcm=lcm, meshcat=meshcat, commanding=commanding)
