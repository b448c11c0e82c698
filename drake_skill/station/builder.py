"""The simulated station: Panda, table, one articulated object and a Kinect-like camera.

``build_station(config)`` returns a :class:`Station`, a Diagram whose exported
ports are the contract every other system of drake-skill talks to. The
hardware station (``drake_skill.hardware``) exports the very same names, as
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

Physics choices (documented here because they decide what a skill must do):

* The plant is discrete (SAP) with point contact.
* The Panda's joints are driven by SAP's implicit PD controllers (joint
  impedance), with gravity disabled on the arm: the real Panda's controller
  compensates gravity internally, so the commanded impedance acts alone.
* Gravity is disabled on the object too, and its joints are damped: the lid
  and drawer stay wherever they were left, as a stiff friction hinge would
  hold them, so a skill succeeds only by moving them through contact.
* The object's base is a free body placed at the (randomised) pose and
  locked there: it does not slide when pushed.
"""

from __future__ import annotations

import numpy as np
from pydrake.geometry import (
    ClippingRange,
    ColorRenderCamera,
    DepthRange,
    DepthRenderCamera,
    MakeRenderEngineVtk,
    MeshcatVisualizer,
    MeshcatVisualizerParams,
    RenderCameraCore,
    RenderEngineVtkParams,
    Role,
)
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
from pydrake.multibody.tree import PdControllerGains
from pydrake.perception import BaseField, DepthImageToPointCloud
from pydrake.systems.framework import Diagram, DiagramBuilder, LeafSystem
from pydrake.systems.primitives import ConstantValueSource, MatrixGain
from pydrake.systems.sensors import CameraInfo, PixelType, RgbdSensor
from pydrake.common.value import AbstractValue, Value

from drake_skill.common import look_at
from drake_skill.station.controller import X_FLANGE_HAND, X_HAND_TCP, EndEffectorController
from drake_skill.station.models import add_package_paths, model_url
from drake_skill.station.config import StationConfig, validate_station_config

RENDERER = "vtk"

# Per object kind: SDF file, base body, articulated joint, body whose frame is O.
_OBJECTS = {
    "box": ("box.sdf", "box_base", "lid_hinge"),
    "drawer": ("drawer.sdf", "cabinet", "drawer_slide"),
}


def kinect_camera_info(camera) -> CameraInfo:
    """Pinhole intrinsics from the horizontal and vertical fields of view."""
    fx = camera.width / 2 / np.tan(np.deg2rad(camera.fov_x_deg) / 2)
    fy = camera.height / 2 / np.tan(np.deg2rad(camera.fov_y_deg) / 2)
    return CameraInfo(camera.width, camera.height, fx, fy,
                      camera.width / 2 - 0.5, camera.height / 2 - 0.5)


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


class Station(Diagram):
    """The simulated station (see the module docstring for its ports).

    Besides the ports it keeps handles a runner needs between rollouts:
    ``plant``, ``scene_graph``, ``config``, ``object_base`` (the locked free
    body) and ``object_joint`` (lid hinge or drawer slide).
    """

    def __init__(self, config: StationConfig, meshcat=None):
        super().__init__()
        self.config = validate_station_config(config)
        builder = DiagramBuilder()
        plant_config = MultibodyPlantConfig(
            time_step=config.time_step, contact_model="point",
            discrete_contact_approximation="sap")
        plant, scene_graph = AddMultibodyPlant(plant_config, builder)
        self.plant, self.scene_graph = plant, scene_graph
        parser = Parser(plant)
        add_package_paths(parser.package_map())

        arm = parser.AddModels(url=model_url("panda_arm.sdf"))[0]
        hand = parser.AddModels(url=model_url("panda_hand.sdf"))[0]
        table = parser.AddModels(url=model_url("table.sdf"))[0]
        sdf, base_name, joint_name = _OBJECTS[config.object.kind]
        obj = parser.AddModels(url=model_url(sdf))[0]
        plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("panda_link0", arm))
        plant.WeldFrames(plant.GetFrameByName("panda_link8", arm),
                         plant.GetFrameByName("panda_hand", hand), X_FLANGE_HAND)
        plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("table_top", table))
        for instance in (arm, hand, obj):
            plant.set_gravity_enabled(instance, False)
        self.panda, self.hand, self.object_instance = arm, hand, obj
        self.object_base = plant.GetBodyByName(base_name, obj)
        self.object_joint = plant.GetJointByName(joint_name, obj)
        plant.SetDefaultFloatingBaseBodyPose(self.object_base, self.nominal_object_pose())

        ctrl = config.controller
        for i in range(7):
            actuator = plant.GetJointActuatorByName(f"panda_joint{i + 1}", arm)
            actuator.set_controller_gains(PdControllerGains(p=ctrl.kp[i], d=ctrl.kd[i]))
        for side in ("left", "right"):
            actuator = plant.GetJointActuatorByName(f"panda_finger_joint_{side}", hand)
            actuator.set_controller_gains(PdControllerGains(p=ctrl.finger_kp, d=ctrl.finger_kd))
        plant.Finalize()

        q_home = np.asarray(config.q_home, dtype=float)
        plant.SetDefaultPositions(arm, q_home)
        plant.SetDefaultPositions(hand, [config.gripper_home / 2] * 2)
        self._set_default_object_joint(config.object.initial_joint)

        # Robot-internal collisions cannot happen with the IK limits in force;
        # filtering them saves contact queries every step.
        from pydrake.geometry import CollisionFilterDeclaration, GeometrySet
        robot_geoms = []
        for instance in (arm, hand):
            for body_index in plant.GetBodyIndices(instance):
                robot_geoms += plant.GetCollisionGeometriesForBody(plant.get_body(body_index))
        scene_graph.collision_filter_manager().Apply(
            CollisionFilterDeclaration().ExcludeWithin(GeometrySet(robot_geoms)))

        # Hand pose in, joint impedance set points out.
        controller = builder.AddNamedSystem("ee_controller", EndEffectorController(ctrl, q_home))
        self.ee_controller = controller
        builder.Connect(controller.GetOutputPort("panda_state_desired"),
                        plant.get_desired_state_input_port(arm))
        builder.ExportInput(controller.GetInputPort("X_WE_desired"), "ee_pose_desired")
        # Opening w -> each finger at w/2, zero velocity.
        gripper = builder.AddNamedSystem("gripper", MatrixGain(np.array([[0.5], [0.5], [0.0], [0.0]])))
        builder.Connect(gripper.get_output_port(), plant.get_desired_state_input_port(hand))
        builder.ExportInput(gripper.get_input_port(), "gripper_command")

        # Measured outputs.
        builder.ExportOutput(plant.get_state_output_port(arm), "panda_state")
        hand_body = plant.GetBodyByName("panda_hand", hand)
        ee = builder.AddNamedSystem("ee_pose", _FramePose(hand_body.index(), X_HAND_TCP))
        builder.Connect(plant.get_body_poses_output_port(), ee.get_input_port())
        builder.ExportOutput(ee.get_output_port(), "ee_pose")
        selector = plant.MakeStateSelectorMatrix([self.object_joint.index()])[:1]
        object_state = builder.AddNamedSystem("object_state", MatrixGain(selector))
        builder.Connect(plant.get_state_output_port(), object_state.get_input_port())
        builder.ExportOutput(object_state.get_output_port(), "object_state")
        builder.ExportOutput(plant.get_contact_results_output_port(), "contact_results")

        if config.enable_camera:
            self._add_camera(builder)
        if meshcat is not None:
            MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat,
                                           MeshcatVisualizerParams(role=Role.kIllustration))
        builder.BuildInto(self)
        self.set_name("station")

    # ------------------------------------------------------------------ camera
    def _add_camera(self, builder) -> None:
        cam = self.config.camera
        self.scene_graph.AddRenderer(RENDERER, MakeRenderEngineVtk(RenderEngineVtkParams(backend="EGL")))
        info = kinect_camera_info(cam)
        core = RenderCameraCore(RENDERER, info, ClippingRange(0.05, cam.depth_max + 1.0), RigidTransform())
        color = ColorRenderCamera(core, show_window=False)
        depth = DepthRenderCamera(core, DepthRange(cam.depth_min, cam.depth_max))
        world_id = self.plant.GetBodyFrameIdOrThrow(self.plant.world_body().index())
        self._X_WC = RigidTransform(look_at(cam.position, cam.target))
        sensor = builder.AddNamedSystem("camera", RgbdSensor(world_id, self._X_WC, color, depth))
        builder.Connect(self.scene_graph.get_query_output_port(), sensor.query_object_input_port())
        # Rendering is on demand: an image or the cloud is rendered when a
        # consumer evaluates it, once per state (the sensor caches it), so the
        # camera costs nothing between the frames the perception systems sample
        # at camera.fps. (Holding the images in a ZeroOrderHold instead cost
        # ~10 ms per frame in state copies; Drake's RgbdSensorDiscrete would also
        # render a 16-bit depth image.)
        to_cloud = builder.AddNamedSystem("depth_to_cloud", DepthImageToPointCloud(
            info, PixelType.kDepth32F, 1.0, BaseField.kXYZs | BaseField.kRGBs))
        builder.Connect(sensor.depth_image_32F_output_port(), to_cloud.depth_image_input_port())
        builder.Connect(sensor.color_image_output_port(), to_cloud.color_image_input_port())
        # The camera is fixed in the world: a constant pose keeps the cloud's
        # cache independent of the robot's state.
        camera_pose = builder.AddNamedSystem("camera_pose", ConstantValueSource(AbstractValue.Make(self._X_WC)))
        builder.Connect(camera_pose.get_output_port(), to_cloud.camera_pose_input_port())
        builder.ExportOutput(to_cloud.point_cloud_output_port(), "point_cloud")
        builder.ExportOutput(sensor.color_image_output_port(), "color_image")
        builder.ExportOutput(sensor.depth_image_32F_output_port(), "depth_image")
        # The label image is ground truth for tests and data generation.
        builder.ExportOutput(sensor.label_image_output_port(), "label_image")
        self.camera_info = info

    def camera_pose(self) -> RigidTransform:
        """X_WC of the camera (Drake camera convention)."""
        if not self.config.enable_camera:
            raise ValueError("this station was built with enable_camera = false")
        return self._X_WC

    # ------------------------------------------------------------------ object
    def nominal_object_pose(self) -> RigidTransform:
        o = self.config.object
        return RigidTransform(RollPitchYaw(0.0, 0.0, o.yaw), [o.x, o.y, 0.0])

    def random_object_pose(self, seed: int) -> RigidTransform:
        """The nominal pose perturbed uniformly by the configured translation and yaw noise."""
        o = self.config.object
        rng = np.random.default_rng(seed)
        dx, dy = rng.uniform(-o.randomize_xy, o.randomize_xy, size=2)
        dyaw = rng.uniform(-o.randomize_yaw, o.randomize_yaw)
        return RigidTransform(RollPitchYaw(0.0, 0.0, o.yaw + dyaw), [o.x + dx, o.y + dy, 0.0])

    def _set_default_object_joint(self, value: float) -> None:
        if self.config.object.kind == "box":
            self.object_joint.set_default_angle(value)
        else:
            self.object_joint.set_default_translation(value)

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
        """Sets the lid angle [rad] or drawer travel [m] in ``context``."""
        plant_context = self.plant.GetMyMutableContextFromRoot(context)
        if self.config.object.kind == "box":
            self.object_joint.set_angle(plant_context, value)
        else:
            self.object_joint.set_translation(plant_context, value)

    def reset(self, context, seed: int | None = None) -> RigidTransform:
        """Prepares a context that was just set to its defaults (``SetDefaultContext``)
        for a run: places the object at the pose drawn from ``seed`` (the nominal
        pose when ``seed`` is None), locks it, and starts the hand controller at
        the home joint positions. ``context`` is this station's or a root context
        containing it. Returns X_WO.
        """
        X_WO = self.nominal_object_pose() if seed is None else self.random_object_pose(seed)
        self.set_object_pose(context, X_WO)
        self.ee_controller.set_joint_positions(context, self.config.q_home)
        return X_WO


def build_station(config: StationConfig | None = None, meshcat=None) -> Station:
    """Builds the simulated station described by ``config`` (defaults: the Open scenario)."""
    return Station(config if config is not None else StationConfig(), meshcat=meshcat)
