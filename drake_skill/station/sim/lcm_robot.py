"""A simulated Panda that speaks the drake-franka-driver's LCM protocol.

The simulated station (``drake_skill.station.sim.builder``, its driver a
``!JointSetpointDriver``: joint impedance set points in) behind Drake's driver-side systems::

    LCM PANDA_COMMAND --> [PandaCommandReceiver] --> [driver checks] --> [q, v] --> Station (plant, object, camera)
    Station --> [PandaStatusSender] --> LCM PANDA_STATUS
    LCM PANDA_HAND_COMMAND --> [SchunkWsgCommandReceiver] --> gripper_command
    Station colour/depth/label images --> [ImageToLcmImageArrayT] --> LCM camera channel

The driver checks (:class:`DriverChecks`) are the drake-franka-driver's in
position mode: a command must expect position control with 7 joint
positions and no velocities or torques (else the driver exits; here the
checks stop the simulator and :meth:`SimRobot.stop` or :meth:`SimRobot.run`
raises :class:`DriverProtocolError`), and a command whose wall-clock ``utime`` is
more than ``expire_sec`` (0.1 s) away from the wall clock is dropped, the
last accepted position held. Status goes out every plant step with
Drake's ``PandaStatusSender`` (it stamps simulation time, which the hardware
station does not read); the external joint torque reported is the
station's ``external_torque`` (the contact forces' generalized force on the
arm), as the driver reports the robot's estimate.

Run it in its own thread (:meth:`SimRobot.start`, real time) or process
(``drake-skill sim-robot``); with the camera on, the thread that runs it
must be the only one that evaluates its images (the renderer's EGL context
lives in one thread). The ground truth stays here:
:meth:`SimRobot.object_state` and :meth:`SimRobot.judge`.
"""

from __future__ import annotations

import copy
import threading
import time

import numpy as np
from drake import (lcmt_image_array, lcmt_panda_command, lcmt_panda_status, lcmt_schunk_wsg_command,
                   lcmt_scope)
from pydrake.common.value import AbstractValue
from pydrake.lcm import DrakeLcm
from pydrake.manipulation import (PandaCommandReceiver, PandaControlMode, PandaStatusSender,
                                  SchunkWsgCommandReceiver)
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, EventStatus, LeafSystem
from pydrake.systems.lcm import LcmInterfaceSystem, LcmPublisherSystem, LcmSubscriberSystem
from pydrake.systems.primitives import ConstantVectorSource, Demultiplexer, StateInterpolatorWithDiscreteDerivative
from pydrake.systems.sensors import ImageToLcmImageArrayT

from drake_skill.station.scenario import Scenario, validate_scenario
from drake_skill.station.drivers import JointSetpointDriver, PandaLcmDriver, require_panda_driver
from drake_skill.station.make import make_station
from drake_skill.station.recording import advance_station
from drake_skill.station.success import judge_success

N_JOINTS = 7


class DriverProtocolError(RuntimeError):
    """A command the drake-franka-driver would refuse (it throws on these)."""


class DriverChecks(LeafSystem):
    """The driver's acceptance of position commands.

    Inputs: ``command`` (Python ``lcmt_panda_command``), ``position`` (7, the
    PandaCommandReceiver's output), ``position_measured`` (7). Output
    ``position`` (7): the last accepted command. Discrete state [held q (7),
    accepted count, dropped count, last utime, refused: control mode,
    positions, velocities, torques (-1 while none was refused)]. Every
    ``period`` s the latest message is checked: a ``utime`` more than
    ``expire_sec`` from the wall clock [us] is dropped; a wrong control mode
    or sizes, which the driver refuses by exiting, stop the simulator
    (``EventStatus.ReachedTermination``, the command kept in state;
    :meth:`stop_error` gives the DriverProtocolError). At initialization the
    measured position is held (the driver starts at the robot's position).
    """

    _ACCEPTED, _DROPPED, _UTIME, _REFUSED, _SIZE = N_JOINTS, N_JOINTS + 1, N_JOINTS + 2, N_JOINTS + 3, N_JOINTS + 7

    def __init__(self, period: float, expire_sec: float = 0.1):
        super().__init__()
        self._expire_us = float(expire_sec) * 1e6
        self._msg = self.DeclareAbstractInputPort("command", AbstractValue.Make(lcmt_panda_command()))
        self._q = self.DeclareVectorInputPort("position", N_JOINTS)
        self._q_meas = self.DeclareVectorInputPort("position_measured", N_JOINTS)
        self._state = self.DeclareDiscreteState(self._SIZE)
        self.DeclareInitializationDiscreteUpdateEvent(self._latch)
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._check)
        self.DeclareVectorOutputPort("position", N_JOINTS, self._calc_position, {self.xd_ticket()})

    def counts(self, context) -> tuple[int, int]:
        """(accepted, dropped) distinct commands so far in ``context``."""
        x = context.get_discrete_state(self._state).get_value()
        return int(x[self._ACCEPTED]), int(x[self._DROPPED])

    def stop_error(self, context) -> DriverProtocolError | None:
        """The command the driver refused in ``context``, as a DriverProtocolError, or None."""
        mode, n_q, n_v, n_tau = context.get_discrete_state(self._state).get_value()[self._REFUSED:].astype(int)
        if mode < 0:
            return None
        return DriverProtocolError(
            f"command refused: control_mode_expected {mode}, {n_q} positions, {n_v} velocities, "
            f"{n_tau} torques (expected position mode with {N_JOINTS} positions)")

    def _latch(self, context, discrete_state):
        x = np.zeros(self._SIZE)
        x[:N_JOINTS] = self._q_meas.Eval(context)
        x[self._UTIME] = float(self._msg.Eval(context).utime)   # a message from before the reset is old
        x[self._REFUSED:] = -1.0
        discrete_state.set_value(self._state, x)

    def _check(self, context, discrete_state):
        msg = self._msg.Eval(context)
        x = context.get_discrete_state(self._state).get_value().copy()
        if msg.utime == 0 or float(msg.utime) == x[self._UTIME]:
            return EventStatus.DidNothing()
        x[self._UTIME] = float(msg.utime)
        if (msg.control_mode_expected != lcmt_panda_status.CONTROL_MODE_POSITION
                or msg.num_joint_position != N_JOINTS or msg.num_joint_velocity or msg.num_joint_torque):
            x[self._REFUSED:] = [msg.control_mode_expected, msg.num_joint_position, msg.num_joint_velocity,
                                 msg.num_joint_torque]
            discrete_state.set_value(self._state, x)
            return EventStatus.ReachedTermination(self, "the driver refused a command (see stop_error)")
        if abs(time.time() * 1e6 - msg.utime) > self._expire_us:
            x[self._DROPPED] += 1                       # expired: dropped, position held
        else:
            x[:N_JOINTS] = self._q.Eval(context)
            x[self._ACCEPTED] += 1
        discrete_state.set_value(self._state, x)
        return EventStatus.Succeeded()

    def _calc_position(self, context, output):
        output.SetFromVector(context.get_discrete_state(self._state).get_value()[:N_JOINTS])


class GroundTruthEncoder(LeafSystem):
    """``object_state`` [1] in, ``lcmt_scope`` (utime = simulation time [us]) out."""

    def __init__(self):
        super().__init__()
        self._x = self.DeclareVectorInputPort("object_state", 1)
        self.DeclareAbstractOutputPort("lcmt_scope", lambda: AbstractValue.Make(lcmt_scope()),
                                       self._calc_message, {self._x.ticket(), self.time_ticket()})

    def _calc_message(self, context, output):
        msg = lcmt_scope()
        msg.utime = int(context.get_time() * 1e6)
        msg.size = 1
        msg.value = [float(self._x.Eval(context)[0])]
        output.set_value(msg)


#: The station input that carries the joint set points [q, v] (14) in the simulated robot
#: (its scenario's driver is a ``!JointSetpointDriver``).
JOINT_COMMAND_PORT = "panda_state_desired"


class SimRobot:
    """The simulated station behind the driver's LCM protocol, on its own simulator.

    Args:
        config: the scenario (``Scenario``); its ``driver``, a
            ``!PandaLcmDriver``, gives the channels and the URL. The robot's own
            station is the scenario with a ``!JointSetpointDriver``.
        lcm: a DrakeLcm to use (default: a new one on ``config.driver.lcm_url``).
        pump: add an LcmInterfaceSystem to handle ``lcm``'s subscriptions.
            With the hardware station in the same process on the same
            (``memq://``) DrakeLcm, pass False: one DrakeLcm must be handled
            by one thread, and the hardware station's does it (messages reach
            this diagram's subscribers from that thread; publishing is
            thread-safe). Do not add a Python handler with
            ``DrakeLcm.Subscribe`` to that DrakeLcm while this robot runs in
            its thread: pydrake makes the handler's bytes without holding the
            GIL, which corrupts the heap when another thread runs Python;
            an LcmSubscriberSystem (its serializer is called with the GIL)
            is safe.
        expire_sec: the driver's ``--expire_sec``.
        guide: ``guide(X_WO, X_WE_home, seed) -> PosePlan``: instead of following commands, the arm
            is moved through that plan by an end-effector controller of its
            own: a person guiding the compliant arm, for recording
            kinesthetic demonstrations (``drake-skill sim-robot --guide``
            passes a skill's scripted, human-like demonstration,
            ``drake_skill.demos.demonstrator.humanlike_plan``).
    """

    def __init__(self, config: Scenario | None = None, lcm: DrakeLcm | None = None,
                 pump: bool = True, meshcat=None, expire_sec: float = 0.1, guide=None):
        config = config if config is not None else Scenario(driver=PandaLcmDriver())
        self.config = validate_scenario(config)
        self.driver = driver = require_panda_driver(config, "the simulated robot")
        self.lcm = lcm if lcm is not None else DrakeLcm(driver.lcm_url)
        # The reflex is the driver side's: the hardware station's monitor decides it from the
        # external torques this robot reports (as on the Panda); its own station's monitor
        # would stop this simulation instead and leave the driver without status.
        station_config = copy.deepcopy(config)
        station_config.reflex.enabled = False
        station_config.driver = JointSetpointDriver()
        step = float(station_config.time_step)
        builder = DiagramBuilder()
        self.station = builder.AddNamedSystem("station", make_station(station_config, meshcat=meshcat))
        if pump:
            builder.AddNamedSystem("lcm", LcmInterfaceSystem(self.lcm))
        split = builder.AddNamedSystem("state_split", Demultiplexer([N_JOINTS, N_JOINTS]))
        builder.Connect(self.station.GetOutputPort("panda_state"), split.get_input_port())

        # Commands in.
        sub = builder.AddNamedSystem("command_subscriber", LcmSubscriberSystem.Make(
            driver.command_channel, lcmt_panda_command, self.lcm, use_cpp_serializer=True))
        receiver = builder.AddNamedSystem("command_receiver", PandaCommandReceiver(
            N_JOINTS, PandaControlMode.kPosition))
        builder.Connect(sub.get_output_port(), receiver.get_message_input_port())
        builder.Connect(split.get_output_port(0), receiver.get_position_measured_input_port())
        sub_py = builder.AddNamedSystem("command_check_subscriber", LcmSubscriberSystem.Make(
            driver.command_channel, lcmt_panda_command, self.lcm))
        self.checks = builder.AddNamedSystem("driver_checks", DriverChecks(step, expire_sec))
        builder.Connect(sub_py.get_output_port(), self.checks.GetInputPort("command"))
        builder.Connect(receiver.get_commanded_position_output_port(), self.checks.GetInputPort("position"))
        builder.Connect(split.get_output_port(0), self.checks.GetInputPort("position_measured"))
        self._interp = builder.AddNamedSystem("desired_state", StateInterpolatorWithDiscreteDerivative(
            N_JOINTS, step, suppress_initial_transient=True))
        builder.Connect(self.checks.GetOutputPort("position"), self._interp.get_input_port())
        self.guide, self._guide_source, self._guide_controller = guide, None, None
        if guide is None:
            builder.Connect(self._interp.get_output_port(), self.station.GetInputPort(JOINT_COMMAND_PORT))
        else:
            from drake_skill.station.controller import EndEffectorController
            from drake_skill.station.pose_source import PoseTrajectorySource

            self._guide_source = builder.AddNamedSystem("guide_plan", PoseTrajectorySource())
            self._guide_controller = builder.AddNamedSystem("guide_controller", EndEffectorController(
                station_config.controller, station_config.q_home, directives=station_config.directives))
            builder.Connect(self._guide_source.GetOutputPort("X_WE_desired"),
                            self._guide_controller.GetInputPort("X_WE_desired"))
            builder.Connect(self._guide_controller.GetOutputPort("panda_state_desired"),
                            self.station.GetInputPort(JOINT_COMMAND_PORT))
            builder.Connect(self._guide_source.GetOutputPort("gripper_command"),
                            self.station.GetInputPort("gripper_command"))

        # Status out.
        sender = builder.AddNamedSystem("status_sender", PandaStatusSender(N_JOINTS))
        zeros = builder.AddNamedSystem("zeros", ConstantVectorSource(np.zeros(N_JOINTS)))
        builder.Connect(self.checks.GetOutputPort("position"), sender.get_position_commanded_input_port())
        builder.Connect(split.get_output_port(0), sender.get_position_measured_input_port())
        builder.Connect(split.get_output_port(1), sender.get_velocity_measured_input_port())
        for port in (sender.get_velocity_commanded_input_port(), sender.get_acceleration_commanded_input_port(),
                     sender.get_torque_commanded_input_port(), sender.get_torque_measured_input_port()):
            builder.Connect(zeros.get_output_port(), port)
        if self.station.HasOutputPort("external_torque"):
            builder.Connect(self.station.GetOutputPort("external_torque"), sender.get_torque_external_input_port())
        else:
            builder.Connect(zeros.get_output_port(), sender.get_torque_external_input_port())
        status_pub = builder.AddNamedSystem("status_publisher", LcmPublisherSystem.Make(
            driver.status_channel, lcmt_panda_status, self.lcm, publish_period=step,
            use_cpp_serializer=True))
        builder.Connect(sender.get_output_port(), status_pub.get_input_port())

        # The hand.
        hand_sub = builder.AddNamedSystem("hand_subscriber", LcmSubscriberSystem.Make(
            driver.hand_command_channel, lcmt_schunk_wsg_command, self.lcm, use_cpp_serializer=True))
        hand = builder.AddNamedSystem("hand_receiver", SchunkWsgCommandReceiver(
            station_config.gripper_home, driver.hand_force))
        builder.Connect(hand_sub.get_output_port(), hand.get_input_port())
        if guide is None:
            builder.Connect(hand.GetOutputPort("position"), self.station.GetInputPort("gripper_command"))

        # The ground truth, for the hardware station's object_state.
        if driver.ground_truth_channel:
            truth = builder.AddNamedSystem("ground_truth_encoder", GroundTruthEncoder())
            builder.Connect(self.station.GetOutputPort("object_state"), truth.get_input_port())
            truth_pub = builder.AddNamedSystem("ground_truth_publisher", LcmPublisherSystem.Make(
                driver.ground_truth_channel, lcmt_scope, self.lcm, publish_period=0.01))
            builder.Connect(truth.get_output_port(), truth_pub.get_input_port())

        # The camera.
        if self.station.HasOutputPort("color_image"):
            images = builder.AddNamedSystem("camera_encoder", ImageToLcmImageArrayT("color", "depth", "label"))
            for name in ("color", "depth", "label"):
                builder.Connect(self.station.GetOutputPort(f"{name}_image"), images.GetInputPort(name))
            camera_pub = builder.AddNamedSystem("camera_publisher", LcmPublisherSystem.Make(
                driver.camera_channel, lcmt_image_array, self.lcm,
                publish_period=1.0 / float(station_config.camera.fps), use_cpp_serializer=True))
            builder.Connect(images.image_array_t_msg_output_port(), camera_pub.get_input_port())

        self.diagram = builder.Build()
        # The context (with the camera's renderer, an EGL context that
        # renders in the thread that made it) is created by the thread that
        # runs the simulator: see _prepare.
        self.context = None
        self.simulator = None
        self._thread = None
        self._stop = threading.Event()
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self.X_WO = None

    # ------------------------------------------------------------------ runs
    def _prepare(self, seed: int | None) -> None:
        """In the running thread: context (made once), defaults, object pose from ``seed``."""
        if self.context is None:
            self.context = self.diagram.CreateDefaultContext()
            self.simulator = Simulator(self.diagram, self.context)
            self.simulator.set_target_realtime_rate(1.0)
        self.diagram.SetDefaultContext(self.context)
        self.context.SetTime(0.0)
        self.X_WO = self.station.reset(self.context, seed)
        self._interp.set_initial_position(self._interp.GetMyMutableContextFromRoot(self.context),
                                          self.station.config.q_home)
        if self.guide is not None:
            home = self.station.GetOutputPort("ee_pose").Eval(self.station_context())
            plan = self.guide(self.X_WO, home, 0 if seed is None else int(seed))
            self._guide_source.set_plan(self._guide_source.GetMyMutableContextFromRoot(self.context), plan)
            self._guide_controller.set_joint_positions(self.context, self.station.config.q_home)
            self.guide_duration = plan.duration
        self.simulator.Initialize()

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def start(self, seed: int | None = None, timeout: float = 60.0) -> None:
        """Resets (arm at home, at rest; object at the pose drawn from ``seed``) and runs
        the simulator in real time in a background thread until :meth:`stop`.
        Returns once the robot runs (its first status is on its way)."""
        if self.running:
            raise RuntimeError("SimRobot already running: call stop() first")
        self._stop.clear()
        self._ready.clear()
        self._error = None
        self._thread = threading.Thread(target=self._loop, args=(seed,), name="sim-robot", daemon=True)
        self._thread.start()
        if not self._ready.wait(timeout) or self._error is not None:
            self.stop()
            raise RuntimeError("the simulated robot did not start")

    def _loop(self, seed) -> None:
        try:
            self._prepare(seed)
            self._ready.set()
            while not self._stop.is_set():
                self._advance(self.context.get_time() + 0.02)
        except BaseException as error:   # reported by stop()
            self._error = error
            self._ready.set()

    def run(self, duration: float, seed: int | None = None) -> None:
        """Resets to ``seed`` and runs in real time in this thread for ``duration`` s (inf: until interrupted)."""
        self._prepare(seed)
        while self.context.get_time() < duration:
            self._advance(min(self.context.get_time() + 0.1, float(duration)))

    def _advance(self, t: float) -> None:
        """``recording.advance_station`` to t: a system that stopped the simulator (the driver
        checks on a refused command) raises its typed error here."""
        advance_station(self.simulator, self.station, self.context, t)

    def stop(self) -> None:
        """Stops the background thread (status and camera stop); re-raises its error."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=10.0)
            self._thread = None
        if self._error is not None:
            error, self._error = self._error, None
            raise error

    # ------------------------------------------------------------------ ground truth
    def time(self) -> float:
        return self.context.get_time()

    def station_context(self):
        return self.station.GetMyContextFromRoot(self.context)

    def object_state(self) -> float:
        """Lid angle [rad] or drawer travel [m] now (read when stopped; renders nothing)."""
        return float(self.station.GetOutputPort("object_state").Eval(self.station_context())[0])

    def judge(self) -> bool:
        """Ground-truth success (the scenario's rule, its skill's) for the object state now."""
        return judge_success(self.object_state(), self.station.config.success)

    def command_counts(self) -> tuple[int, int]:
        """(accepted, dropped-as-expired) commands since the last reset."""
        return self.checks.counts(self.checks.GetMyContextFromRoot(self.context))
