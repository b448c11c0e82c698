"""The simulated station: Panda, table, one articulated object and a Kinect-like camera.

``make_station(scenario)`` (``drake_skill.station.make``) returns a :class:`Station`, a Diagram whose exported
ports are the contract every other system of drake-skill talks to. The
hardware station (``drake_skill.station.hardware.station``) exports the same names, as
``MakeHardwareStation`` does in the ``manipulation`` course repository:

inputs
    ``ee_pose_desired``  RigidTransform X_WE, world pose of the hand's TCP frame E
    ``gripper_command``  [1] finger opening [m]
outputs
    ``point_cloud``      PointCloud (world frame, xyz + rgb; 640 x 480 organised,
                         NaN/inf where there is no return)
    ``color_image``, ``depth_image`` (32F, m), ``label_image``
                         rendered on demand: the perception systems sample them
                         at ``camera.fps`` (10 Hz), the Kinect's rate in the thesis
    ``panda_state``      [14] joint positions [rad] and velocities [rad/s]
    ``ee_pose``          RigidTransform X_WE measured
    ``object_state``     [1] lid angle [rad] or drawer travel [m]: ground truth,
                         simulation only, used to judge success, never to reward.

Physics choices (documented here because they decide what a skill must do;
the values are the scenario's, ``drake_skill.station.scenario``):

* The plant is discrete (SAP) with point contact; every surface's friction,
  stiffness and dissipation are set from ``config.contact``.
* The Panda's joints are driven by SAP's implicit PD controllers (joint
  impedance) around the rate-limited command of the end-effector controller.
  Gravity acts on the arm and hand, and a feed-forward torque tau_g(q)
  (``InverseDynamics`` in gravity-compensation mode on an arm + hand model)
  cancels it, as the real Panda's controller does internally; SAP clamps
  PD + feed-forward to each joint's effort limit, so the torque gravity needs
  counts against it.
* Gravity acts on the object's moving part (``object.gravity``); its hinge or
  slide has light viscous damping and Coulomb friction (an implicit PD
  actuator with zero stiffness whose force is clamped to the friction).
* The object's base is a free body placed at the (randomised) pose and
  locked there: it does not slide when pushed (the collision reflex keeps
  the pushes below what a real box would slide at).
"""

from __future__ import annotations

import dataclasses as dc

import numpy as np
from pydrake.geometry import (
    AddContactMaterial,
    CollisionFilterDeclaration,
    GeometrySet,
    MakeRenderEngineVtk,
    MeshcatVisualizer,
    MeshcatVisualizerParams,
    ProximityProperties,
    RenderEngineVtkParams,
    Role,
    RoleAssign,
)
from pydrake.math import RigidTransform
from pydrake.multibody.meshcat import ContactVisualizer, ContactVisualizerParams
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlant, CoulombFriction, MultibodyPlant
from pydrake.multibody.tree import BodyIndex, PdControllerGains
from pydrake.systems.controllers import InverseDynamics
from pydrake.systems.framework import Diagram, DiagramBuilder, LeafSystem
from pydrake.systems.primitives import (ConstantVectorSource, Demultiplexer, MatrixGain,
                                        Multiplexer, PassThrough)
from pydrake.systems.sensors import RgbdSensor
from pydrake.common.value import Value

from drake_skill.station.controller import X_HAND_TCP, EndEffectorController, add_arm_and_hand, make_finger_limiter
from drake_skill.station.models import add_package_paths, add_panda_illustration, process_directives
from drake_skill.station.scenario import Scenario, validate_scenario
from drake_skill.station.drivers import JointSetpointDriver
from drake_skill.station.placement import nominal_object_pose, object_parts, random_object_pose
from drake_skill.station.reflex import RobotSceneContactForce, add_reflex_monitor, robot_scene_pairs

#: Meshcat's contact force arrows: newtons per metre of arrow (a 50 N push draws 25 cm).
CONTACT_N_PER_M = 200.0

# The robot's and the table's collision geometries get these ContactConfig
# surfaces (body name, geometry name fragment, "" for any of the body's
# geometries, surface); panda_link* -> arm; every geometry of the object's
# model -> object.
_SURFACES = (
    ("panda_leftfinger", "", "finger_pads"), ("panda_rightfinger", "", "finger_pads"),
    ("panda_hand", "", "hand_housing"), ("table_top", "", "table"),
)


def make_gravity_plant(directives=None) -> MultibodyPlant:
    """Arm + hand (9 DoF: joints 1..7, fingers) of ``directives`` (the scenario's; default the
    robot's own), as the station has them, for gravity compensation."""
    plant = MultibodyPlant(time_step=0.0)
    add_arm_and_hand(plant, directives)
    plant.Finalize()
    return plant


class _FramePose(LeafSystem):
    """Output ``X_WE``: the TCP pose from the plant's body poses."""

    def __init__(self, body_index, X_BE: RigidTransform):
        super().__init__()
        self._body_index = int(body_index)
        self._X_BE = X_BE
        self._poses = self.DeclareAbstractInputPort("body_poses", Value([RigidTransform()]))
        self.DeclareAbstractOutputPort("X_WE", lambda: Value(RigidTransform()), self._calc_pose,
                                       {self.all_input_ports_ticket()})

    def _calc_pose(self, context, output):
        X_WB = self._poses.Eval(context)[self._body_index]
        output.set_value(X_WB @ self._X_BE)


@dc.dataclass
class ScenePlant:
    """What :func:`add_scene_plant` added: the plant, its SceneGraph, the model
    instances, the object's locked base body and articulated joint, and the
    indices of the robot's bodies."""

    plant: MultibodyPlant
    scene_graph: object
    panda: object
    hand: object
    object_instance: object
    object_base: object
    object_joint: object
    robot_bodies: set


def add_gravity_compensation(builder: DiagramBuilder, scene: "ScenePlant", directives=None) -> MultibodyPlant:
    """Wires tau_g(q) of arm + hand (Drake's ``InverseDynamics`` in gravity-compensation mode on
    :func:`make_gravity_plant` of ``directives``) into the arm's and the hand's actuation inputs
    of ``scene``'s plant, as feed-forward. Returns the gravity plant (the system keeps a
    reference to it; so must the caller)."""
    plant, arm, hand = scene.plant, scene.panda, scene.hand
    gravity_plant = make_gravity_plant(directives)
    gravity = builder.AddNamedSystem("gravity_compensation", InverseDynamics(
        gravity_plant, InverseDynamics.InverseDynamicsMode.kGravityCompensation))
    mux = builder.AddNamedSystem("arm_hand_state", Multiplexer([14, 4]))
    builder.Connect(plant.get_state_output_port(arm), mux.get_input_port(0))
    builder.Connect(plant.get_state_output_port(hand), mux.get_input_port(1))
    order = list(range(7)) + [14, 15] + list(range(7, 14)) + [16, 17]   # -> [q_arm, q_f, v_arm, v_f]
    reorder = builder.AddNamedSystem("arm_hand_state_order", MatrixGain(np.eye(18)[order]))
    builder.Connect(mux.get_output_port(), reorder.get_input_port())
    builder.Connect(reorder.get_output_port(), gravity.get_input_port_estimated_state())
    split = builder.AddNamedSystem("gravity_split", Demultiplexer([7, 2]))
    builder.Connect(gravity.get_output_port_generalized_force(), split.get_input_port())
    builder.Connect(split.get_output_port(0), plant.get_actuation_input_port(arm))
    builder.Connect(split.get_output_port(1), plant.get_actuation_input_port(hand))
    return gravity_plant


def add_scene_plant(builder: DiagramBuilder, config: Scenario) -> ScenePlant:
    """Adds the scenario's MultibodyPlant (``config.plant``) and SceneGraph to ``builder``:
    Panda + hand + table + object, every surface's contact parameters, the
    joints' PD gains (SAP's implicit joint impedance), the object joint's
    damping and Coulomb friction, the defaults (``q_home``, the gripper's home
    opening, the object at its nominal pose and initial joint value), the
    robot's self-collisions filtered. Finalised; nothing is connected.

    The station adds its controllers around it; ``drake-skill bench rollout``'s
    bare plant holds its actuators at the home positions with nothing else.
    """
    plant, scene_graph = AddMultibodyPlant(config.plant, builder)
    parser = Parser(plant)
    add_package_paths(parser.package_map())
    process_directives(config.directives, plant, parser)
    arm, hand = plant.GetModelInstanceByName("panda"), plant.GetModelInstanceByName("panda_hand")
    add_panda_illustration(plant, scene_graph, (arm, hand))  # Meshcat only: Franka's meshes
    obj = plant.GetModelInstanceByName(config.object.model)
    object_base, object_joint = object_parts(plant, obj, config)
    plant.set_gravity_enabled(obj, bool(config.object.gravity))
    plant.SetDefaultFloatingBaseBodyPose(object_base, nominal_object_pose(config))
    object_joint.set_default_damping(config.object.joint_damping)
    _set_contact_properties(plant, scene_graph, config.contact, obj)

    ctrl = config.controller
    for i in range(7):
        actuator = plant.GetJointActuatorByName(f"panda_joint{i + 1}", arm)
        actuator.set_controller_gains(PdControllerGains(p=ctrl.kp[i], d=ctrl.kd[i]))
    for side in ("left", "right"):
        actuator = plant.GetJointActuatorByName(f"panda_finger_joint_{side}", hand)
        actuator.set_controller_gains(PdControllerGains(p=ctrl.finger_kp, d=ctrl.finger_kd))
    # Coulomb friction of the object's joint: zero stiffness, damping
    # joint_friction_gain, force clamped to joint_friction (SAP's PD clamp).
    friction = plant.AddJointActuator(f"{object_joint.name()}_friction", object_joint,
                                      effort_limit=max(config.object.joint_friction, 1e-9))
    friction.set_controller_gains(PdControllerGains(p=0.0, d=config.object.joint_friction_gain))
    plant.Finalize()

    plant.SetDefaultPositions(arm, np.asarray(config.q_home, dtype=float))
    plant.SetDefaultPositions(hand, [config.gripper_home / 2] * 2)
    object_joint.set_default_positions([config.object.initial_joint])

    # Robot-internal collisions cannot happen with the IK limits in force
    # (and the model has no overlapping robot geometry at q_home, tested);
    # filtering them saves contact queries every step.
    robot_bodies = {int(b) for instance in (arm, hand) for b in plant.GetBodyIndices(instance)}
    robot_geoms = []
    for body_index in sorted(robot_bodies):
        robot_geoms += plant.GetCollisionGeometriesForBody(plant.get_body(BodyIndex(body_index)))
    scene_graph.collision_filter_manager().Apply(
        CollisionFilterDeclaration().ExcludeWithin(GeometrySet(robot_geoms)))
    return ScenePlant(plant, scene_graph, arm, hand, obj, object_base, object_joint, robot_bodies)


def _set_contact_properties(plant, scene_graph, contact, obj) -> None:
    """Replaces every collision geometry's proximity properties with its surface's (``contact``)."""
    inspector = scene_graph.model_inspector()
    for body_index in range(plant.num_bodies()):
        body = plant.get_body(BodyIndex(body_index))
        for gid in plant.GetCollisionGeometriesForBody(body):
            name = inspector.GetName(gid)
            surface = ("object" if body.model_instance() == obj else
                       "arm" if body.name().startswith("panda_link") else None)
            for body_name, fragment, candidate in _SURFACES if surface is None else ():
                if body.name() == body_name and fragment in name:
                    surface = candidate
                    break
            if surface is None:
                raise ValueError(f"scenario field 'directives': the collision geometry {name} of body "
                                 f"{body.name()} is neither the robot's, the table's nor the object's; "
                                 "add only the robot, the table and the object (object.model)")
            s = getattr(contact, surface)
            props = ProximityProperties()
            AddContactMaterial(point_stiffness=s.stiffness, friction=CoulombFriction(s.friction, s.friction),
                               properties=props)
            props.AddProperty("material", "relaxation_time", s.relaxation_time)
            scene_graph.AssignRole(plant.get_source_id(), gid, props, RoleAssign.kReplace)


class Station(Diagram):
    """The simulated station (see the module docstring for its ports).

    Besides the ports it keeps handles a runner needs between rollouts:
    ``plant``, ``scene_graph``, ``config``, ``object_base`` (the locked free
    body), ``object_joint`` (lid hinge or drawer slide), ``ee_controller``,
    ``gripper`` (the finger rate limiter) and ``robot_bodies`` (indices).
    It satisfies :class:`drake_skill.station.interface.StationInterface`.
    """

    #: A simulation runs as fast as it can (the hardware station's is True).
    realtime = False

    def __init__(self, config: Scenario, meshcat=None):
        super().__init__()
        self.config = validate_scenario(config)
        self.object_camera = None      # the cropped object camera, with the camera on
        builder = DiagramBuilder()
        scene = add_scene_plant(builder, config)
        plant, scene_graph = scene.plant, scene.scene_graph
        self.plant, self.scene_graph = plant, scene_graph
        arm, hand, obj = scene.panda, scene.hand, scene.object_instance
        self.panda, self.hand, self.object_instance = arm, hand, obj
        self.object_base, self.object_joint = scene.object_base, scene.object_joint
        self.robot_bodies = scene.robot_bodies

        self.ee_controller = self._add_arm_driver(builder, scene)
        # Opening w -> each finger at w/2, at most the hand's finger speed.
        gripper = builder.AddNamedSystem("gripper", make_finger_limiter(
            config.controller, config.time_step, config.gripper_home))
        self.gripper = gripper
        builder.Connect(gripper.GetOutputPort("finger_state_desired"), plant.get_desired_state_input_port(hand))
        builder.ExportInput(gripper.GetInputPort("opening"), "gripper_command")
        self._gravity_plant = add_gravity_compensation(builder, scene, config.directives)
        # The object's friction actuator: zero set point (velocity 0), no feed-forward.
        hold = builder.AddNamedSystem("object_friction_setpoint", ConstantVectorSource(np.zeros(2)))
        builder.Connect(hold.get_output_port(), plant.get_desired_state_input_port(obj))
        zero = builder.AddNamedSystem("object_actuation", ConstantVectorSource(np.zeros(1)))
        builder.Connect(zero.get_output_port(), plant.get_actuation_input_port(obj))

        # Measured outputs.
        builder.ExportOutput(plant.get_state_output_port(arm), "panda_state")
        hand_body = plant.GetBodyByName("panda_hand", hand)
        self._hand_body = hand_body
        ee = builder.AddNamedSystem("ee_pose", _FramePose(hand_body.index(), X_HAND_TCP))
        builder.Connect(plant.get_body_poses_output_port(), ee.get_input_port())
        builder.ExportOutput(ee.get_output_port(), "ee_pose")
        selector = plant.MakeStateSelectorMatrix([self.object_joint.index()])[:1]
        object_state = builder.AddNamedSystem("object_state", MatrixGain(selector))
        builder.Connect(plant.get_state_output_port(), object_state.get_input_port())
        builder.ExportOutput(object_state.get_output_port(), "object_state")
        builder.ExportOutput(plant.get_contact_results_output_port(), "contact_results")
        builder.ExportOutput(plant.get_generalized_contact_forces_output_port(arm), "external_torque")
        # The collision reflex, updated at every plant step (the contact results change only then).
        contact_force = builder.AddNamedSystem("robot_scene_contact", RobotSceneContactForce(self.robot_bodies))
        builder.Connect(plant.get_contact_results_output_port(), contact_force.get_input_port())
        self.reflex_monitor = add_reflex_monitor(builder, contact_force.get_output_port(),
                                                 plant.get_generalized_contact_forces_output_port(arm),
                                                 config.reflex, config.time_step)
        if self.ee_controller is not None and self.ee_controller.force_limit is not None:
            builder.Connect(self.reflex_monitor.GetOutputPort("filtered"),
                            self.ee_controller.GetInputPort("reflex_state"))

        if config.enable_camera:
            self._add_camera(builder)
        if meshcat is not None:
            MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat,
                                           MeshcatVisualizerParams(role=Role.kIllustration))
            # Contact forces as arrows, 1 m per CONTACT_N_PER_M (the reflex trips at tens of N).
            ContactVisualizer.AddToBuilder(builder, plant, meshcat,
                                           ContactVisualizerParams(newtons_per_meter=CONTACT_N_PER_M))
        builder.BuildInto(self)
        self.set_name("station")
        self._kinematics = None

    def _add_arm_driver(self, builder, scene) -> EndEffectorController | None:
        """The scenario's ``driver`` between the command input and the arm's joint impedance
        (``drake_skill.station.drivers``); returns the end-effector controller, or None.

        ``!JointSetpointDriver``: input ``panda_state_desired`` [q (7), v (7)] straight to the
        arm's PD set points. Otherwise (``!EndEffectorDriver``, ``!PandaLcmDriver``: the IK runs
        on drake-skill's side on the robot too): input ``ee_pose_desired``, differential IK and
        the rate limiter, and output ``joint_acceleration_commanded``.
        """
        config = self.config
        desired = scene.plant.get_desired_state_input_port(scene.panda)
        if isinstance(config.driver, JointSetpointDriver):
            set_points = builder.AddNamedSystem("panda_state_desired", PassThrough(14))
            builder.Connect(set_points.get_output_port(), desired)
            builder.ExportInput(set_points.get_input_port(), "panda_state_desired")
            return None
        controller = builder.AddNamedSystem("ee_controller", EndEffectorController(
            config.controller, np.asarray(config.q_home, dtype=float), config.time_step, config.directives,
            reflex=config.reflex))
        builder.Connect(controller.GetOutputPort("panda_state_desired"), desired)
        # The IK's integrator starts where the arm is, in an initialization event.
        builder.Connect(scene.plant.get_state_output_port(scene.panda), controller.GetInputPort("robot_state"))
        builder.ExportInput(controller.GetInputPort("X_WE_desired"), "ee_pose_desired")
        builder.ExportOutput(controller.GetOutputPort("joint_acceleration_commanded"),
                             "joint_acceleration_commanded")
        return controller

    def hand_pose(self, q) -> RigidTransform:
        """X_WE, the ``ee_pose`` output's value, at arm joint positions q (7) [rad] (the
        hand's pose depends on nothing else): the loggers record q and not the pose."""
        if self._kinematics is None:
            # Scratch memory for the kinematics, not run state: every call writes q first.
            self._kinematics = self.plant.CreateDefaultContext()
        self.plant.SetPositions(self._kinematics, self.panda, np.asarray(q, dtype=float))
        return self.plant.EvalBodyPoseInWorld(self._kinematics, self._hand_body) @ X_HAND_TCP

    def stop_error(self, context) -> RuntimeError | None:
        """The reflex monitor's trip in ``context`` (a root context) as a ReflexError, or None."""
        return self.reflex_monitor.stop_error(self.reflex_monitor.GetMyContextFromRoot(context))

    def robot_scene_contact(self, context) -> tuple[float, np.ndarray]:
        """(sum of the robot-scene contact force magnitudes [N], external joint
        torques of joints 1..7 [N m]) at the state in ``context`` (a root context
        containing this station): the reflex monitor's inputs."""
        monitor = self.reflex_monitor
        ctx = monitor.GetMyContextFromRoot(context)
        force = float(monitor.GetInputPort("contact_force").Eval(ctx)[0])
        return force, np.asarray(monitor.GetInputPort("external_torque").Eval(ctx), dtype=float)

    def contact_report(self, context) -> dict:
        """What touches the robot at the state in ``context``: ``{"pairs": [[robot body, other body,
        force_N], ...] (strongest first, summed over the contact points of a pair), "point": [x, y, z]
        (W, m) of the strongest contact point or None}``; what a reflex trip's record keeps."""
        station_context = self.GetMyContextFromRoot(context)
        results = self.GetOutputPort("contact_results").Eval(station_context)
        points = robot_scene_pairs(self.plant, results, self.robot_bodies)
        summed = {}
        for p in points:
            summed[(p["a"], p["b"])] = summed.get((p["a"], p["b"]), 0.0) + p["force_N"]
        pairs = sorted(([a, b, round(f, 3)] for (a, b), f in summed.items()), key=lambda row: -row[2])
        return {"pairs": pairs, "point": [round(v, 4) for v in points[0]["point"]] if points else None}

    # ------------------------------------------------------------------ camera
    def _add_camera(self, builder) -> None:
        cam = self.config.camera        # Drake's CameraConfig: intrinsics, clipping, depth range, X_PB
        renderer = cam.renderer_class if isinstance(cam.renderer_class, RenderEngineVtkParams) \
            else RenderEngineVtkParams(backend="EGL")
        # The cameras render a scene of their own (drake_skill/station/camera.py): the
        # plant's SceneGraph then carries no renderer to update at every step.
        from drake_skill.station.camera import add_object_camera, add_render_scene, export_camera_ports
        self.render_scene = add_render_scene(builder, self, cam.renderer_name, MakeRenderEngineVtk(renderer))
        color, depth = cam.MakeCameras()
        info = color.core().intrinsics()
        world_id = self.plant.GetBodyFrameIdOrThrow(self.plant.world_body().index())
        self._X_WC = cam.X_PB.GetDeterministicValue()
        sensor = builder.AddNamedSystem("camera", RgbdSensor(world_id, self._X_WC, color, depth))
        builder.Connect(self.render_scene.get_query_output_port(), sensor.query_object_input_port())
        # Rendering is on demand: an image or the cloud is rendered when a
        # consumer evaluates it, once per state (the sensor caches it), so the
        # camera costs nothing between the frames the perception systems sample
        # at camera.fps. (Holding the images in a ZeroOrderHold instead cost
        # ~10 ms per frame in state copies; Drake's RgbdSensorDiscrete would also
        # render a 16-bit depth image.)
        export_camera_ports(builder, info, self._X_WC, sensor.color_image_output_port(),
                            sensor.depth_image_32F_output_port(), sensor.label_image_output_port())
        self.camera_info = info
        # The perception systems read the crop of this camera where the object can
        # appear (object_point_cloud etc.; drake_skill/station/camera.py).
        self.object_camera = add_object_camera(builder, self, color, depth, world_id, self._X_WC)
        for extra in self.config.cameras:     # for people and tools: rendered on demand, read by nothing
            color, depth = extra.MakeCameras()
            sensor = builder.AddNamedSystem(f"camera_{extra.name}", RgbdSensor(
                world_id, extra.X_PB.GetDeterministicValue(), color, depth))
            builder.Connect(self.render_scene.get_query_output_port(), sensor.query_object_input_port())
            builder.ExportOutput(sensor.color_image_output_port(), f"{extra.name}_color_image")
            builder.ExportOutput(sensor.depth_image_32F_output_port(), f"{extra.name}_depth_image")
            builder.ExportOutput(sensor.label_image_output_port(), f"{extra.name}_label_image")

    def camera_pose(self) -> RigidTransform:
        """X_WC of the camera (Drake camera convention)."""
        if not self.config.enable_camera:
            raise ValueError("this station was built with enable_camera = false")
        return self._X_WC

    # ------------------------------------------------------------------ object
    def nominal_object_pose(self) -> RigidTransform:
        return nominal_object_pose(self.config)

    def random_object_pose(self, seed: int) -> RigidTransform:
        """The nominal pose perturbed uniformly by the configured translation and yaw noise."""
        return random_object_pose(self.config, seed)

    def set_object_pose(self, context, X_WO: RigidTransform) -> None:
        """Places the object's base frame O at X_WO and locks it there."""
        plant_context = self.plant.GetMyMutableContextFromRoot(context)
        self.plant.SetFreeBodyPose(plant_context, self.object_base, X_WO)
        self.object_base.Lock(plant_context)

    def object_pose(self, context) -> RigidTransform:
        """Ground-truth X_WO (simulation only)."""
        plant_context = self.plant.GetMyContextFromRoot(context)
        return self.plant.EvalBodyPoseInWorld(plant_context, self.object_base)

    def set_object_joint(self, context, value: float) -> None:
        """Sets the object's joint (a lid's angle [rad], a drawer's travel [m]) in ``context``."""
        plant_context = self.plant.GetMyMutableContextFromRoot(context)
        positions = self.plant.GetPositions(plant_context).copy()
        positions[self.object_joint.position_start()] = value
        self.plant.SetPositions(plant_context, positions)

    def reset(self, context, seed: int | None = None) -> RigidTransform:
        """Places the object at the pose drawn from ``seed`` (the nominal pose when ``seed``
        is None) and locks it, in a context just set to its defaults at t = 0
        (``SetDefaultContext``): a run's reset is that, then ``Initialize``. Everything
        else starts from its declared default: the arm and fingers at home, the IK
        integrator and both rate limiters at rest there, the reflex filter at rest.
        ``context`` is this station's or a root context containing it. Returns X_WO.
        """
        X_WO = self.nominal_object_pose() if seed is None else self.random_object_pose(seed)
        self.set_object_pose(context, X_WO)
        return X_WO
