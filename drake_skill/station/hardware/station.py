"""The hardware station: the simulated station's ports, backed by a real Panda over LCM.

``make_station(scenario, hardware=True)`` (``drake_skill.station.make``) returns a
:class:`HardwareStation`, a Diagram exporting the same ports (names and value types) as the
simulated station (see
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
  simulation (the reflex monitor, ``drake_skill.station.reflex``,
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
from drake import (lcmt_image_array, lcmt_panda_command, lcmt_panda_status, lcmt_schunk_wsg_command,
                   lcmt_scope)
from pydrake.common.value import AbstractValue
from pydrake.lcm import DrakeLcm
from pydrake.manipulation import PandaStatusReceiver, SchunkWsgCommandSender
from pydrake.math import RigidTransform
from pydrake.multibody.plant import ContactResults
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.lcm import LcmInterfaceSystem, LcmPublisherSystem, LcmSubscriberSystem
from pydrake.systems.primitives import ConstantValueSource, ConstantVectorSource, Multiplexer

from drake_skill.station.placement import nominal_object_pose, object_parts, random_object_pose
from drake_skill.station.controller import EndEffectorController
from drake_skill.station.scenario import Scenario, validate_scenario
from drake_skill.station.drivers import require_panda_driver
from drake_skill.station.reflex import add_reflex_monitor
from drake_skill.station.hardware.systems import (  # noqa: F401 (the station's errors and systems, re-exported)
    N_JOINTS, STATUS_CHECK_PERIOD, ForwardKinematics, GroundTruthDecoder, ImageCrop, LcmImageArrayDecoder,
    PandaCommandEncoder, PlacedObjectPose, RealSenseCamera, ReflexError, Selector, StaleStatusError, StatusMonitor,
    WorkspaceClip, clip_to_workspace, wall_clock_utime)

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
            config.controller, config.q_home, directives=config.directives, reflex=config.reflex))
        self.ee_controller = controller
        builder.Connect(clip.get_output_port(), controller.GetInputPort("X_WE_desired"))
        q_only = builder.AddNamedSystem("q_commanded", Selector(2 * N_JOINTS, N_JOINTS))
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
        if controller.force_limit is not None:   # the hand yields on the torques the robot measures
            builder.Connect(self.reflex_monitor.GetOutputPort("filtered"), controller.GetInputPort("reflex_state"))
            builder.Connect(state.get_output_port(), controller.GetInputPort("robot_state"))
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
