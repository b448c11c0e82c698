"""Station configuration: dataclasses loadable from YAML with ``yaml_load_typed``.

(No ``from __future__ import annotations`` here: yaml_load_typed reads the
field types at run time.)

A scenario names the plant (Drake's ``MultibodyPlantConfig``), the object on
the table and its joint physics, the contact parameters of every surface, the
camera (Drake's ``CameraConfig``), the controller, the collision reflex and
the success rule; code never hard-codes them. The scenes of the shipped
skills are YAML files in ``drake_skill/station/scenarios/``, and a skill file
names its scene (:func:`drake_skill.skills.scenario_for_skill` gives a skill's scene with the
skill's success rule); a user's own file loads with :func:`load_scenario`. Units are SI (m, rad, s, kg, N).
``load_scenario`` turns every problem into a ``ValueError`` that names
the offending field.
"""


import copy
import dataclasses as dc
import functools
import math
import typing
from pathlib import Path

import numpy as np
from pydrake.common.schema import Transform
from pydrake.common.yaml import yaml_dump_typed, yaml_load_typed
from pydrake.geometry import RenderEngineVtkParams
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import ModelDirective, ModelDirectives
from pydrake.multibody.plant import MultibodyPlantConfig
from pydrake.multibody.tree import ModelInstanceIndex
from pydrake.systems.sensors import CameraConfig

from drake_skill import typed_yaml
from drake_skill.common import look_at
from drake_skill.typed_yaml import load_typed
from drake_skill.perception.segmentation import CLUSTER_RULES, VALUE_MIN
from drake_skill.station import limits, models
from drake_skill.station.drivers import EndEffectorDriver, JointSetpointDriver, PandaLcmDriver, validate_driver
from drake_skill.station.models import model_url

#: The model instances every station's directives must add (the object's is named in ``object.model``).
ROBOT_MODELS = ("panda", "panda_hand", "table")
#: The Panda with its hand: the one definition of the robot (models/panda_robot.dmd.yaml).
ROBOT_FILE = model_url(models.ROBOT_FILE)
#: ``ROBOT_FILE`` and the table top welded at the world origin: the one definition of the
#: workcell (models/workcell.dmd.yaml).
WORKCELL_FILE = model_url(models.WORKCELL_FILE)
#: The robot and the table as Drake model directives (``ProcessModelDirectives``): one
#: ``add_directives`` of ``WORKCELL_FILE``. A scenario's ``directives`` add the object.
ROBOT_DIRECTIVES = f"""
- add_directives: {{file: "{WORKCELL_FILE}"}}
"""
SCENARIO_DIR = Path(__file__).resolve().parent / "scenarios"
#: The camera's pose: 1.3 m in front and 0.7 m to the right of the robot's base, 0.8 m up.
CAMERA_POSITION = (1.30, -0.70, 0.80)
CAMERA_TARGET = (0.52, 0.0, 0.06)


@dc.dataclass
class ColourConfig:
    """The object's colour as the segmenter finds it (HSV; docs/method.md section 3).

    hue_min_deg, hue_max_deg: hue range [deg, 0..360); min > max wraps through 0 (reds).
    saturation_min, value_min: lower bounds in [0, 1]; value_min's default is the
      segmenter's (``segmentation.VALUE_MIN``, low: a shaded face keeps its colour).
    cluster_rule: which colour regions are the object: "all_regions" (every one
      but specks) or "largest" (thesis 3.6; with value_min 0.15, the rule before issue 50).
    """

    hue_min_deg: float = 200.0
    hue_max_deg: float = 250.0
    saturation_min: float = 0.45
    value_min: float = VALUE_MIN
    cluster_rule: str = "all_regions"


@dc.dataclass
class ObjectConfig:
    """The articulated object on the table: which model it is, its joint physics,
    how its pose is randomised and how the camera finds it.

    model: the name of the object's model instance in ``directives``.
    base_body: its body that rests on the table (a free body, placed and
      locked at the drawn pose); its frame is the object frame O.
    joint: its one articulated joint (revolute or prismatic), the one the
      station's ``object_state`` reports and success rules read.
    x, y, yaw: nominal pose of the object's base frame O on the table [m, rad].
    initial_joint: the joint's position at the start of a run [rad or m].
    randomize_xy: half-width of the uniform translation noise per axis [m].
    randomize_yaw: half-width of the uniform yaw noise [rad].
    gravity: gravity acts on the object (its base is locked to the table).
    joint_damping: viscous damping of the joint [N m s/rad or N s/m].
    joint_friction: Coulomb friction of the joint [N m or N], modelled
      as SAP's implicit PD constraint with zero stiffness, damping
      ``joint_friction_gain`` and its force clamped to ``joint_friction``: the
      regularised Coulomb law tau = -clamp(d v, -tau_c, tau_c).
    joint_friction_gain: the regularisation's slope d [N m s/rad or N s/m];
      |v| above tau_c / d slides at the full friction.
    colour: the object's colour range, which the segmenter keeps.
    footprint_heights: ``[low, high]`` heights above the table [m] of the
      points whose outline gives the object's frame (the segmenter's
      footprint band, docs/method.md section 3): a horizontal slice of the
      object whose outline is that of its base and that neither the moving
      part nor anything standing proud of the base crosses. Empty: the
      segmenter's default band (the box's base, below its lid).
    """

    model: str = "box"
    base_body: str = "box_base"
    joint: str = "lid_hinge"
    x: float = 0.55
    y: float = 0.0
    yaw: float = 0.0
    initial_joint: float = 0.0
    randomize_xy: float = 0.02
    randomize_yaw: float = 0.08
    gravity: bool = True
    joint_damping: float = 0.005
    joint_friction: float = 0.01
    joint_friction_gain: float = 1.0
    colour: ColourConfig = dc.field(default_factory=ColourConfig)
    footprint_heights: typing.List[float] = dc.field(default_factory=list)


@dc.dataclass
class SurfaceConfig:
    """Point-contact parameters of one surface (Drake's proximity properties).

    friction: Coulomb coefficient (static = dynamic; SAP uses the dynamic one).
      Drake combines two surfaces' coefficients as 2 mu_a mu_b / (mu_a + mu_b).
    stiffness: point-contact stiffness [N/m] (Drake combines two in series).
    relaxation_time: SAP's linear dissipation time scale [s].
    """

    friction: float = 0.5
    stiffness: float = 1e5
    relaxation_time: float = 0.01


def _surface(friction, stiffness=1e5, relaxation_time=0.01):
    return dc.field(default_factory=lambda: SurfaceConfig(friction, stiffness, relaxation_time))


@dc.dataclass
class ContactConfig:
    """Contact parameters per surface. Values: rubber-padded fingers on painted
    wood or plastic mu ~ 1, the hand's plastic housing and the arm's painted
    links mu ~ 0.3, the painted box, lid, drawer and handle mu ~ 0.5, the wooden
    table mu ~ 0.6. Stiffness 1e5 N/m per surface (5e4 N/m for two in series)
    keeps a 30 N push to 0.6 mm of penetration. ``object``: every collision
    geometry of the object's model."""

    finger_pads: SurfaceConfig = _surface(1.0)
    hand_housing: SurfaceConfig = _surface(0.3)
    arm: SurfaceConfig = _surface(0.3)
    object: SurfaceConfig = _surface(0.5)
    table: SurfaceConfig = _surface(0.6)


def default_camera() -> CameraConfig:
    """A Microsoft Kinect v1 (the thesis' camera): 640 x 480 pixels, 57 x 43 degrees
    field of view, depth 0.5-4 m, 10 Hz (the thesis samples perception at 10 Hz,
    docs/method.md section 1), fixed in the world looking at the table."""
    camera = CameraConfig()
    camera.name = "kinect"
    camera.width, camera.height, camera.fps = 640, 480, 10.0
    camera.focal = CameraConfig.FovDegrees(x=57.0, y=43.0)
    camera.clipping_near, camera.clipping_far = 0.05, 5.0
    camera.z_near, camera.z_far = 0.5, 4.0
    camera.X_PB = Transform(RigidTransform(look_at(CAMERA_POSITION, CAMERA_TARGET)))
    camera.renderer_name = "vtk"
    camera.renderer_class = RenderEngineVtkParams(backend="EGL")
    camera.rgb, camera.depth, camera.label = True, True, True
    return camera


def robot_directives() -> list:
    """``ROBOT_DIRECTIVES`` as ``ModelDirective`` objects."""
    return yaml_load_typed(schema=_Directives, data="directives:" + ROBOT_DIRECTIVES).directives


def box_directives() -> list:
    """The workcell (the robot and the table) and the shipped lidded box (the default scenario's models)."""
    box = yaml_load_typed(schema=_Directives, data="""directives:
- add_model: {name: box, file: "package://drake_skill_models/box.sdf"}
""").directives
    return robot_directives() + box


@dc.dataclass
class _Directives:
    directives: typing.List[ModelDirective] = dc.field(default_factory=list)


def default_plant() -> MultibodyPlantConfig:
    """Discrete plant with SAP (the implicit PD actuators and the friction need it), point contact."""
    return MultibodyPlantConfig(time_step=0.002, contact_model="point",
                                discrete_contact_approximation="sap")


@dc.dataclass
class ForceLimitConfig:
    """The hand yields before the collision reflex trips (``drake_skill.station.force_limit``).

    enabled: off, the commanded hand pose passes unchanged (the thesis's
      station, and every run stored before this option existed).
    start: the fraction of the reflex's limits (its filtered contact force
      against ``reflex.contact_force_max``, each external joint torque against
      ``reflex.external_torque_max``) where the hand starts to yield.
    gain: the hand's yielding speed per unit of that fraction above ``start``
      [m/s] (1: at 80 % of the limit with start 0.6 the hand backs off at 0.2 m/s;
      a hand pressed into a closed lid at 3 cm/s then holds 19 N).
    relax_time: time constant of the return to the commanded pose once the
      measured load is below ``start`` [s].
    max_offset: the largest distance the hand yields from the commanded pose [m].
    """

    enabled: bool = False
    start: float = 0.6
    gain: float = 1.0
    relax_time: float = 1.0
    max_offset: float = 0.05


@dc.dataclass
class ControllerConfig:
    """End-effector controller (differential IK), rate limiter and joint impedance gains.

    diff_ik_period: integration period of differential IK [s].
    velocity_scale: fraction of the Panda's joint velocity limits IK may use.
    ee_speed_max: Cartesian speed limit of the hand [m/s].
    limiter_period: period of the joint rate limiter [s] (libfranka's: 1 ms).
    limiter_bandwidth: natural frequency [rad/s] of the limiter's critically
      damped tracking of the IK's joint positions.
    kp, kd: joint stiffness [N m/rad] and damping [N m s/rad] of the impedance
      controller (SAP implicit PD on each actuator), joints 1..7; defaults are
      libfranka's joint impedance example (``examples/joint_impedance_control``
      uses 600, 600, 600, 600, 250, 150, 50 and 50, 50, 50, 20, 20, 20, 10).
    finger_kp, finger_kd: the same for the two prismatic fingers [N/m, N s/m].
    joint_centering_gain: pull of the redundant joint motion toward q_home
      [1/s] (differential IK's secondary objective).
    force_limit: :class:`ForceLimitConfig` (off by default).
    """

    diff_ik_period: float = 0.01
    velocity_scale: float = 0.8
    ee_speed_max: float = 0.6
    limiter_period: float = 0.001
    limiter_bandwidth: float = 40.0
    kp: list[float] = dc.field(default_factory=lambda: [600.0, 600.0, 600.0, 600.0, 250.0, 150.0, 50.0])
    kd: list[float] = dc.field(default_factory=lambda: [50.0, 50.0, 50.0, 20.0, 20.0, 20.0, 10.0])
    finger_kp: float = 2000.0
    finger_kd: float = 40.0
    joint_centering_gain: float = 1.0
    force_limit: ForceLimitConfig = dc.field(default_factory=ForceLimitConfig)


@dc.dataclass
class ReflexConfig:
    """The Panda's collision reflex (defaults and sources: ``drake_skill.station.limits``).

    enabled: crossing a limit ends the run with ``ReflexError``.
    contact_force_max: limit on the sum of the robot-scene contact force magnitudes [N].
    external_torque_max: limit on each joint's external torque (the contact
      forces' generalized force on joints 1..7) [N m].
    filter_time: both are compared after a first-order low-pass filter of
      this time constant [s], as the robot compares its filtered estimates
      (a contact impulse over one plant step is not a sustained force).
    """

    enabled: bool = True
    filter_time: float = 0.01
    contact_force_max: float = limits.REFLEX_FORCE_N
    external_torque_max: list[float] = dc.field(default_factory=lambda: limits.REFLEX_TORQUE_NM.tolist())


@dc.dataclass
class SuccessConfig:
    """The ground-truth success rule on the object's joint (simulation only, never a reward).

    A skill file's ``success`` (docs/skills.md); the station takes it from the
    skill. Read at the end of a settle phase of ``settle_time`` s in which the
    hand holds still away from the object (no robot-object contact in it).
    joint: the object's joint the rule reads (the station's ``object_state``);
      "" only in a scenario read without a skill, whose runs have no verdict.
    above: the joint's final position must be at least this [rad or m], or
    below: at most this (exactly one of the two).
    settle_time: length of the settle phase [s].
    """

    joint: str = ""
    above: typing.Optional[float] = None
    below: typing.Optional[float] = None
    settle_time: float = 1.0


@dc.dataclass
class Scenario:
    """Everything ``make_station`` needs: the station's models, object, cameras, controller, reflex,
    success rule and the arm's driver.

    plant: Drake's MultibodyPlantConfig (time step, contact model, SAP...).
    directives: the models, as Drake model directives (``ProcessModelDirectives``;
      the manipulation course's ``Scenario`` does the same): ``ROBOT_DIRECTIVES`` (the
      ``add_directives`` of ``WORKCELL_FILE``: model instances ``panda``, ``panda_hand``,
      ``table``; a list that adds and welds them itself works alike) and the object's
      ``add_model`` (``package://drake_skill_models/...`` for the shipped
      models; ``file:///...`` or a path relative to the scenario file for yours).
    q_home: the Panda's initial joint positions [rad].
    gripper_home: initial finger opening (distance between fingers) [m].
    enable_camera: add the cameras (``camera`` and ``cameras``) and the point cloud.
    camera: the camera perception reads (Drake's CameraConfig, a Kinect by
      default, named ``kinect``): its images, its cloud and the object crop.
    cameras: more cameras (Drake's CameraConfig, fixed in the world, the same
      renderer), for people and tools: each exports ``<name>_color_image``,
      ``<name>_depth_image`` and ``<name>_label_image``; nothing reads them.
    driver: what drives the arm (``drake_skill.station.drivers``): an
      ``!EndEffectorDriver`` (the default: hand pose in), a
      ``!JointSetpointDriver`` (joint set points in, the LCM sim robot's) or
      a ``!PandaLcmDriver`` (the real Panda over LCM: its channels, URL,
      timeouts and workspace; the hardware station's).
    """

    plant: MultibodyPlantConfig = dc.field(default_factory=default_plant)
    directives: typing.List[ModelDirective] = dc.field(default_factory=lambda: box_directives())
    q_home: list[float] = dc.field(
        default_factory=lambda: [0.0, -0.6, 0.0, -2.4, 0.0, 1.8, 0.785])
    gripper_home: float = 0.0
    enable_camera: bool = True
    object: ObjectConfig = dc.field(default_factory=ObjectConfig)
    contact: ContactConfig = dc.field(default_factory=ContactConfig)
    camera: CameraConfig = dc.field(default_factory=default_camera)
    cameras: typing.List[CameraConfig] = dc.field(default_factory=list)
    controller: ControllerConfig = dc.field(default_factory=ControllerConfig)
    reflex: ReflexConfig = dc.field(default_factory=ReflexConfig)
    success: SuccessConfig = dc.field(default_factory=SuccessConfig)
    driver: typing.Union[EndEffectorDriver, JointSetpointDriver, PandaLcmDriver] = dc.field(
        default_factory=EndEffectorDriver)

    @property
    def time_step(self) -> float:
        """The plant's discrete step [s] (``plant.time_step``)."""
        return self.plant.time_step


# ----------------------------------------------------------------------------- validation
_bad = functools.partial(typed_yaml.bad, "scenario")


def _number(field, value, lo=-math.inf, hi=math.inf, lo_open=False, hi_open=False, what="a number"):
    """Checks lo <= value <= hi (open ends where asked) and finiteness."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        _bad(field, value, what)
    ok = math.isfinite(v) and (v > lo if lo_open else v >= lo) and (v < hi if hi_open else v <= hi)
    if not ok:
        lo_s = "(" if lo_open else "["
        hi_s = ")" if hi_open else "]"
        _bad(field, value, f"{what} in {lo_s}{lo}, {hi}{hi_s}")
    return v


def _vector(field, values, n, lo=-math.inf, hi=math.inf, lo_open=False, what="numbers"):
    if len(values) != n:
        _bad(field, values, f"{n} {what}")
    for i, v in enumerate(values):
        _number(f"{field}[{i}]", v, lo, hi, lo_open=lo_open, what=what)


def validate_scenario(config: Scenario) -> Scenario:
    """Raises ValueError naming the field of ``config`` that cannot work; returns it."""
    if not isinstance(config, Scenario):
        raise ValueError(f"config must be a Scenario, got {type(config).__name__}")
    plant = config.plant
    _number("plant.time_step", plant.time_step, 1e-4, 0.01, what="a plant step [s]")
    if plant.discrete_contact_approximation != "sap":
        _bad("plant.discrete_contact_approximation", plant.discrete_contact_approximation,
             "'sap' (the implicit PD actuators and the joint friction need SAP)")
    if plant.contact_model not in ("point", "hydroelastic", "hydroelastic_with_fallback"):
        _bad("plant.contact_model", plant.contact_model, "point, hydroelastic or hydroelastic_with_fallback")
    _number("plant.penetration_allowance", plant.penetration_allowance, 0, 0.1, lo_open=True, what="a length [m]")
    _number("plant.stiction_tolerance", plant.stiction_tolerance, 0, 1, lo_open=True, what="a speed [m/s]")
    _number("plant.sap_near_rigid_threshold", plant.sap_near_rigid_threshold, 0, 10, what="a threshold")
    _vector("q_home", config.q_home, 7, what="finite joint angles [rad]")
    for i, q in enumerate(config.q_home):
        _number(f"q_home[{i}]", q, limits.Q_MIN[i], limits.Q_MAX[i], what="a joint angle within Franka's limits [rad]")
    _number("gripper_home", config.gripper_home, 0.0, 2 * limits.FINGER_MAX, what="a finger opening [m]")

    _validate_directives(config)
    obj = config.object
    for name in ("x", "y", "yaw"):
        _number(f"object.{name}", getattr(obj, name), what="a finite pose coordinate")
    reach = math.hypot(obj.x, obj.y)
    if not 0.35 <= reach <= 0.80:
        _bad("object.x/object.y", (obj.x, obj.y),
             "an object 0.35..0.80 m from the robot's base (the Panda's reach for these skills)")
    _number("object.randomize_xy", obj.randomize_xy, 0.0, 0.1, what="a noise half-width [m]")
    _number("object.randomize_yaw", obj.randomize_yaw, 0.0, math.pi / 4, what="a noise half-width [rad]")
    _number("object.initial_joint", obj.initial_joint, what="a joint position (checked against the "
            "model's joint limits when the station is built)")
    c = obj.colour
    for name in ("hue_min_deg", "hue_max_deg"):
        _number(f"object.colour.{name}", getattr(c, name), 0.0, 360.0, what="a hue [deg]")
    for name in ("saturation_min", "value_min"):
        _number(f"object.colour.{name}", getattr(c, name), 0.0, 1.0, hi_open=True,
                what="a lower bound in [0, 1) (1 or more keeps no pixel: an empty colour range)")
    if c.hue_min_deg == c.hue_max_deg:
        _bad("object.colour.hue_min_deg/hue_max_deg", (c.hue_min_deg, c.hue_max_deg),
             "a hue range that holds the object's colour (min < max, or min > max to wrap through 0)")
    if c.cluster_rule not in CLUSTER_RULES:
        _bad("object.colour.cluster_rule", c.cluster_rule, " or ".join(repr(r) for r in CLUSTER_RULES))
    _number("object.joint_damping", obj.joint_damping, 0.0, 100.0, what="a damping")
    _number("object.joint_friction", obj.joint_friction, 0.0, 100.0, what="a friction force/torque")
    _number("object.joint_friction_gain", obj.joint_friction_gain, 0.0, 1e4, lo_open=True, what="a gain")
    if obj.footprint_heights:
        band = obj.footprint_heights
        if len(band) != 2 or not all(math.isfinite(v) for v in band) or not 0.0 <= band[0] < band[1]:
            _bad("object.footprint_heights", band,
                 "[] (the segmenter's default) or [low, high] heights above the table, 0 <= low < high [m]")

    for f in dc.fields(ContactConfig):
        s = getattr(config.contact, f.name)
        _number(f"contact.{f.name}.friction", s.friction, 0.0, 3.0, lo_open=True, what="a friction coefficient")
        _number(f"contact.{f.name}.stiffness", s.stiffness, 0.0, 1e9, lo_open=True, what="a stiffness [N/m]")
        _number(f"contact.{f.name}.relaxation_time", s.relaxation_time, 0.0, 1.0, what="a time [s]")

    names = [config.camera.name]
    for i, extra in enumerate(config.cameras):
        if extra.name in names:
            _bad(f"cameras[{i}].name", extra.name, f"a name of its own (taken: {', '.join(names)})")
        names.append(extra.name)
        if extra.renderer_name != config.camera.renderer_name:
            _bad(f"cameras[{i}].renderer_name", extra.renderer_name,
                 f"'{config.camera.renderer_name}', the perception camera's (the station has one renderer)")
        _validate_camera(extra, f"cameras[{i}]")
    _validate_camera(config.camera, "camera")

    ctrl = config.controller
    _vector("controller.kp", ctrl.kp, 7, 0.0, 1e5, lo_open=True, what="positive stiffnesses [N m/rad]")
    _vector("controller.kd", ctrl.kd, 7, 0.0, 1e4, what="non-negative dampings [N m s/rad]")
    _number("controller.finger_kp", ctrl.finger_kp, 0.0, 1e6, lo_open=True, what="a stiffness [N/m]")
    _number("controller.finger_kd", ctrl.finger_kd, 0.0, 1e4, what="a damping [N s/m]")
    _number("controller.velocity_scale", ctrl.velocity_scale, 0.0, 1.0, lo_open=True, what="a fraction")
    _number("controller.ee_speed_max", ctrl.ee_speed_max, 0.0, 2.0, lo_open=True, what="a speed [m/s]")
    _number("controller.joint_centering_gain", ctrl.joint_centering_gain, 0.0, 100.0, what="a gain [1/s]")
    fl = ctrl.force_limit
    _number("controller.force_limit.start", fl.start, 0.0, 1.0, lo_open=True, what="a fraction of the reflex's limits")
    _number("controller.force_limit.gain", fl.gain, 0.0, 10.0, lo_open=True, what="a speed per fraction [m/s]")
    _number("controller.force_limit.relax_time", fl.relax_time, 0.0, 100.0, lo_open=True, what="a time [s]")
    _number("controller.force_limit.max_offset", fl.max_offset, 0.0, 0.5, lo_open=True, what="a distance [m]")
    _number("controller.diff_ik_period", ctrl.diff_ik_period, max(config.time_step, 1e-3), 0.1,
            what="a period at least the plant step [s]")
    _number("controller.limiter_period", ctrl.limiter_period, 1e-4, ctrl.diff_ik_period, what="a period [s]")
    _number("controller.limiter_bandwidth", ctrl.limiter_bandwidth, 0.0, 0.5 / ctrl.limiter_period,
            lo_open=True, what="a bandwidth [rad/s] below half the limiter rate")
    # The limiters step at the plant's rate, k limiter periods per plant step (RateLimiter).
    steps = config.time_step / ctrl.limiter_period
    if abs(steps - round(steps)) > 1e-9 * steps or round(steps) < 1:
        _bad("controller.limiter_period", ctrl.limiter_period,
             f"a period that divides plant.time_step = {config.time_step} s (e.g. 0.001)")
    validate_driver(config.driver, ctrl.diff_ik_period)

    ref = config.reflex
    _number("reflex.contact_force_max", ref.contact_force_max, 0.0, 1e4, lo_open=True, what="a force [N]")
    _number("reflex.filter_time", ref.filter_time, 0.0, 1.0, what="a time constant [s]")
    _vector("reflex.external_torque_max", ref.external_torque_max, 7, 0.0, 1e3, lo_open=True,
            what="positive torques [N m]")

    if config.success.joint:
        validate_success(config.success, "success")
        if config.success.joint != config.object.joint:
            _bad("success.joint", config.success.joint, f"the object's joint, object.joint = '{config.object.joint}'")
    return config


def _validate_camera(cam: CameraConfig, field: str) -> None:
    """Raises ValueError naming the field of a camera that cannot work."""
    if not (16 <= cam.width <= 4096 and 16 <= cam.height <= 4096):
        _bad(f"{field}.width/height", (cam.width, cam.height), "16..4096 pixels each")
    if isinstance(cam.focal, CameraConfig.FovDegrees):
        for name in ("x", "y"):
            value = getattr(cam.focal, name)
            if value is not None:
                _number(f"{field}.focal.{name}", value, 1.0, 170.0, what="a field of view [deg]")
    else:
        for name in ("x", "y"):
            value = getattr(cam.focal, name)
            if value is not None:
                _number(f"{field}.focal.{name}", value, 0.0, 1e5, lo_open=True, what="a focal length [pixels]")
    _number(f"{field}.fps", cam.fps, 0.1, 120.0, what="a frame rate [Hz]")
    _number(f"{field}.z_near", cam.z_near, 0.0, math.inf, lo_open=True, what="a depth [m]")
    _number(f"{field}.z_far", cam.z_far, cam.z_near, math.inf, lo_open=True, what="a depth beyond z_near [m]")
    _number(f"{field}.clipping_near", cam.clipping_near, 0.0, cam.z_near, lo_open=True,
            what="a clipping distance up to z_near [m]")
    _number(f"{field}.clipping_far", cam.clipping_far, cam.z_far, math.inf, what="a clipping distance beyond z_far [m]")
    X = np.asarray(cam.X_PB.GetDeterministicValue().GetAsMatrix4())
    if not np.all(np.isfinite(X)):
        _bad(f"{field}.X_PB", X[:3, 3].tolist(), "a finite pose")
    if cam.X_PB.base_frame not in (None, "", "world", "WorldBody"):
        _bad(f"{field}.X_PB.base_frame", cam.X_PB.base_frame, "the world (the camera is fixed)")


def load_scenario(path: str | Path | None = None, *, data: str | None = None, overrides=(),
                  defaults: Scenario | None = None) -> Scenario:
    """The scenario of a YAML file (``path``) or string (``data``), laid over ``defaults`` (else
    the built-in :class:`Scenario`), then each YAML text of ``overrides`` in turn, validated once:
    the layering of the ``manipulation`` repository's ``LoadScenario(filename, scenario_text)``.
    A command's flags reach the scenario as overrides (``--scenario-text``, ``--no-camera`` as
    ``enable_camera: false``). With neither ``path`` nor ``data``, ``defaults`` alone is layered.

    Keys left out keep their defaults; an unknown key (a typo), a value of the wrong type or one
    that cannot work is a one-line ValueError naming the file (or the override) and the field.
    """
    if path is None and data is None:
        config = copy.deepcopy(defaults) if defaults is not None else Scenario()
        where = "defaults"
    else:
        config = load_typed(Scenario, what="scenario", path=path, data=data, defaults=defaults)
        where = f"{path}" if path is not None else "YAML"
    if path is not None:
        _resolve_relative_files(config, Path(path).parent)
    for text in overrides:
        where += f" + override {text!r}"
        config = load_typed(Scenario, what="scenario", data=text, defaults=config, where=where)
    try:
        return validate_scenario(config)
    except ValueError as e:
        raise ValueError(f"scenario ({where}): {e}") from e


def _resolve_relative_files(config: Scenario, base: Path) -> None:
    """A user's model or directives file named relative to the scenario file, made absolute."""
    for d in config.directives:
        if d.add_model is not None and "://" not in d.add_model.file:
            d.add_model.file = "file://" + str((base / d.add_model.file).resolve())
        if d.add_directives is not None and "://" not in d.add_directives.file:
            d.add_directives.file = "file://" + str((base / d.add_directives.file).resolve())


def dump_scenario(config: Scenario) -> str:
    """The YAML text of ``config`` (every field written)."""
    return yaml_dump_typed(config)


def same_station(a: str, b: str) -> bool:
    """Whether two dumped station configs describe the same station: equal text, or equal with every
    ``add_directives`` of a shipped file written out, those it includes too (a run stored before the
    robot moved into ``ROBOT_FILE`` wrote its directives in full, one stored before the table moved
    into ``WORKCELL_FILE`` wrote ``ROBOT_FILE``'s ``add_directives`` and the table's two lines).
    A text today's :class:`Scenario` cannot read (one stored by older code, before the models
    became directives) describes a station other than any it can."""
    if a == b:
        return True
    try:
        return _inlined(a) == _inlined(b)
    except (RuntimeError, ValueError):        # a field today's schema does not know
        return False


def _inlined(text: str) -> str:
    from drake_skill.station.models import model_url, url_path
    from pydrake.multibody.parsing import LoadModelDirectives

    def flat(directives) -> list:
        out = []
        for d in directives:
            if d.add_directives is not None and d.add_directives.file.startswith(model_url("")) \
                    and not d.add_directives.model_namespace:
                out += flat(LoadModelDirectives(str(url_path(d.add_directives.file))).directives)
            else:
                out.append(d)
        return out

    config = yaml_load_typed(schema=Scenario, data=text, defaults=Scenario())
    config.directives = flat(config.directives)
    return yaml_dump_typed(config)


def object_joint_name(config: Scenario) -> str:
    """The name of the scenario's object joint (the one ``object_state`` reports)."""
    return config.object.joint


def _validate_directives(config: Scenario) -> None:
    """Every ``add_model`` file exists; processed, the directives add the robot's model instances and
    the object's (an included ``add_directives`` file counts)."""
    from drake_skill.station.placement import object_parts

    for i, d in enumerate(config.directives):
        if d.add_directives is not None:
            _check_file(f"directives[{i}].add_directives.file", d.add_directives.file, "directives")
        if d.add_model is not None:
            _check_file(f"directives[{i}].add_model.file", d.add_model.file, "model")
    plant = _directives_plant(_directives_key(config.directives))
    added = sorted(plant.GetModelInstanceName(ModelInstanceIndex(i)) for i in range(2, plant.num_model_instances()))
    for name in ROBOT_MODELS:
        if name not in added:
            _bad("directives", added, f"the robot's models ({', '.join(ROBOT_MODELS)}): start the list with the "
                 f"workcell's directives (drake_skill/station/scenario.py ROBOT_DIRECTIVES: add_directives "
                 f"{WORKCELL_FILE}, the robot and the table)")
    obj = config.object
    if obj.model not in added:
        _bad("object.model", obj.model, f"the name of a model the directives add ({', '.join(added)})")
    for field in ("base_body", "joint"):
        if not getattr(obj, field):
            _bad(f"object.{field}", getattr(obj, field), f"the name of the object model's {field.replace('_', ' ')}")
    object_parts(plant, plant.GetModelInstanceByName(obj.model), config)


def _check_file(field: str, url: str, what: str) -> None:
    """A directive's file URL names an existing local file (``station.models.url_path``)."""
    from drake_skill.station.models import PACKAGE_NAME, url_path

    path = url_path(url)
    if path is None:
        _bad(field, url, f"package://{PACKAGE_NAME}/<file>, file:///<absolute path>, or a path relative to the "
             "scenario file")
    if not path.is_file():
        _bad(field, url, f"an existing {what} file ({path} does not exist)")


def _directives_key(directives) -> tuple:
    """The directives' text and the modification times of the user's model and directive files (``file://``):
    a scenario whose files did not change is parsed once per process."""
    urls = [d.add_model.file if d.add_model is not None else d.add_directives.file
            if d.add_directives is not None else "" for d in directives]
    files = [url[len("file://"):] for url in urls if url.startswith("file://")]
    return yaml_dump_typed(ModelDirectives(directives=list(directives))), \
        tuple(Path(f).stat().st_mtime_ns for f in files)


@functools.lru_cache(maxsize=16)
def _directives_plant(key: tuple):
    """Every directive processed on a scratch plant (~0.1 s; the station processes the same list),
    so a frame no model has or a model Drake cannot parse is found where the scenario file
    loads, and ``load_scenario`` names the file. Read-only for its callers."""
    from pydrake.common.yaml import yaml_load_typed as load
    from pydrake.multibody.parsing import Parser
    from pydrake.multibody.plant import MultibodyPlant

    from drake_skill.station.models import add_package_paths, process_directives

    plant = MultibodyPlant(0.0)
    parser = Parser(plant)
    add_package_paths(parser.package_map())
    process_directives(load(schema=ModelDirectives, data=key[0]).directives, plant, parser)
    return plant


def validate_success(rule: SuccessConfig, field: str = "success", what: str = "scenario") -> SuccessConfig:
    """Raises ValueError naming the field of a success rule that cannot work (``what``: the
    configuration it is in); returns it."""
    _bad = functools.partial(typed_yaml.bad, what)
    if not rule.joint:
        _bad(f"{field}.joint", rule.joint, "the name of the object's joint the rule reads")
    if (rule.above is None) == (rule.below is None):
        _bad(f"{field}.above/below", (rule.above, rule.below),
             "exactly one of 'above' (success at or above it) and 'below' (at or below it)")
    value = rule.above if rule.above is not None else rule.below
    if not math.isfinite(float(value)):
        _bad(f"{field}.{'above' if rule.above is not None else 'below'}", value, "a finite joint position [rad or m]")
    if not (math.isfinite(float(rule.settle_time)) and 0.0 <= rule.settle_time <= 60.0):
        _bad(f"{field}.settle_time", rule.settle_time, "a duration in [0, 60] s")
    return rule
