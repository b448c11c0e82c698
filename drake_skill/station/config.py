"""Station configuration: dataclasses loadable from YAML with ``yaml_load_typed``.

(No ``from __future__ import annotations`` here: yaml_load_typed reads the
field types at run time.)

A scenario file names the object on the table, the camera, the controller and
the success thresholds; code never hard-codes them. Units are SI (m, rad, s).
``load_station_config`` turns every problem into a ``ValueError`` that names
the offending field.
"""


import dataclasses as dc
import math
from pathlib import Path

from pydrake.common.yaml import yaml_load_typed

from drake_skill.common import SKILLS

OBJECT_KINDS = ("box", "drawer")


@dc.dataclass
class ObjectConfig:
    """The articulated object on the table and how its pose is randomised.

    kind: "box" (hinged lid, skills open/close) or "drawer" (skill draw).
    x, y, yaw: nominal pose of the object's base frame O on the table [m, rad].
    initial_joint: lid angle [rad] or drawer travel [m] at the start of a run.
    randomize_xy: half-width of the uniform translation noise per axis [m].
    randomize_yaw: half-width of the uniform yaw noise [rad].
    """

    kind: str = "box"
    x: float = 0.55
    y: float = 0.0
    yaw: float = 0.0
    initial_joint: float = 0.0
    randomize_xy: float = 0.02
    randomize_yaw: float = 0.08


@dc.dataclass
class CameraConfig:
    """An RGB-D camera modelled on the Microsoft Kinect v1.

    640 x 480 pixels, 57 x 43 degrees field of view, 10 Hz (the thesis samples
    perception at 10 Hz, docs/method.md section 1), depth range [depth_min, depth_max] m.
    The camera sits at ``position`` and looks at ``target`` (world frame, m).
    """

    width: int = 640
    height: int = 480
    fov_x_deg: float = 57.0
    fov_y_deg: float = 43.0
    fps: float = 10.0
    depth_min: float = 0.5
    depth_max: float = 4.0
    position: list[float] = dc.field(default_factory=lambda: [1.30, -0.70, 0.80])
    target: list[float] = dc.field(default_factory=lambda: [0.52, 0.0, 0.06])


@dc.dataclass
class ControllerConfig:
    """End-effector controller (differential IK) and joint impedance gains.

    diff_ik_period: integration period of differential IK [s].
    velocity_scale: fraction of the Panda's joint velocity limits IK may use.
    ee_speed_max: Cartesian speed limit of the hand [m/s].
    kp, kd: joint stiffness [N m/rad] and damping [N m s/rad] of the impedance
      controller (SAP implicit PD on each actuator), joints 1..7.
    finger_kp, finger_kd: the same for the two prismatic fingers [N/m, N s/m].
    joint_centering_gain: pull of the redundant joint motion toward q_home
      [1/s] (differential IK's secondary objective).
    """

    diff_ik_period: float = 0.01
    velocity_scale: float = 0.8
    ee_speed_max: float = 0.6
    kp: list[float] = dc.field(default_factory=lambda: [3000.0] * 4 + [1000.0] * 3)
    kd: list[float] = dc.field(default_factory=lambda: [150.0] * 4 + [40.0] * 3)
    finger_kp: float = 2000.0
    finger_kd: float = 40.0
    joint_centering_gain: float = 1.0


@dc.dataclass
class SuccessConfig:
    """Ground-truth success thresholds (simulation only, never a reward).

    open_min: lid angle at the end at least this [rad].
    close_max: lid angle at the end at most this [rad].
    draw_min: drawer travel at the end at least this [m].
    """

    open_min: float = 1.2
    close_max: float = 0.15
    draw_min: float = 0.10


@dc.dataclass
class StationConfig:
    """Everything ``build_station`` needs.

    time_step: MultibodyPlant discrete step (SAP) [s]. 4 ms keeps the
      station with its camera above 3x real time on 2 cores; the scripted
      skills succeed at 2, 3 and 4 ms.
    q_home: the Panda's initial joint positions [rad].
    gripper_home: initial finger opening (distance between fingers) [m].
    enable_camera: add the RGB-D camera and its point cloud.
    """

    time_step: float = 0.004
    q_home: list[float] = dc.field(
        default_factory=lambda: [0.0, -0.6, 0.0, -2.4, 0.0, 1.8, 0.785])
    gripper_home: float = 0.0
    enable_camera: bool = True
    object: ObjectConfig = dc.field(default_factory=ObjectConfig)
    camera: CameraConfig = dc.field(default_factory=CameraConfig)
    controller: ControllerConfig = dc.field(default_factory=ControllerConfig)
    success: SuccessConfig = dc.field(default_factory=SuccessConfig)


def validate_station_config(config: StationConfig) -> StationConfig:
    """Raises ValueError naming the field of ``config`` that cannot work."""
    def bad(field: str, value, expected: str):
        raise ValueError(f"station config field '{field}' = {value!r}: expected {expected}")

    if not isinstance(config, StationConfig):
        raise ValueError(f"config must be a StationConfig, got {type(config).__name__}")
    if not 1e-4 <= config.time_step <= 0.01:
        bad("time_step", config.time_step, "a plant step in [1e-4, 0.01] s")
    if len(config.q_home) != 7 or not all(math.isfinite(q) for q in config.q_home):
        bad("q_home", config.q_home, "7 finite joint angles [rad]")
    if not 0.0 <= config.gripper_home <= 0.08:
        bad("gripper_home", config.gripper_home, "a finger opening in [0, 0.08] m")
    obj = config.object
    if obj.kind not in OBJECT_KINDS:
        bad("object.kind", obj.kind, f"one of {', '.join(OBJECT_KINDS)}")
    if obj.randomize_xy < 0 or obj.randomize_yaw < 0:
        bad("object.randomize_xy/randomize_yaw", (obj.randomize_xy, obj.randomize_yaw),
            "non-negative noise half-widths")
    upper = 2.2 if obj.kind == "box" else 0.22
    if not 0.0 <= obj.initial_joint <= upper:
        bad("object.initial_joint", obj.initial_joint, f"within the joint range [0, {upper}]")
    cam = config.camera
    if not (16 <= cam.width <= 4096 and 16 <= cam.height <= 4096):
        bad("camera.width/height", (cam.width, cam.height), "16..4096 pixels each")
    for name in ("fov_x_deg", "fov_y_deg"):
        if not 1.0 <= getattr(cam, name) <= 170.0:
            bad(f"camera.{name}", getattr(cam, name), "a field of view in [1, 170] degrees")
    if not 0.1 <= cam.fps <= 120:
        bad("camera.fps", cam.fps, "a frame rate in [0.1, 120] Hz")
    if not 0 < cam.depth_min < cam.depth_max:
        bad("camera.depth_min/depth_max", (cam.depth_min, cam.depth_max), "0 < depth_min < depth_max")
    for name in ("position", "target"):
        if len(getattr(cam, name)) != 3:
            bad(f"camera.{name}", getattr(cam, name), "3 coordinates [m]")
    if math.dist(cam.position, cam.target) < 1e-3:
        bad("camera.target", cam.target, "a point away from camera.position")
    ctrl = config.controller
    if len(ctrl.kp) != 7 or len(ctrl.kd) != 7:
        bad("controller.kp/kd", (ctrl.kp, ctrl.kd), "7 gains each")
    if not 0 < ctrl.velocity_scale <= 1:
        bad("controller.velocity_scale", ctrl.velocity_scale, "a fraction in (0, 1]")
    if ctrl.diff_ik_period < config.time_step:
        bad("controller.diff_ik_period", ctrl.diff_ik_period, "at least time_step")
    return config


def load_station_config(path: str | Path | None = None, *, data: str | None = None,
                        defaults: StationConfig | None = None) -> StationConfig:
    """Loads a StationConfig from a YAML file or string, then validates it.

    Keys left out keep their defaults; an unknown key (a typo) is an error that
    names it.
    """
    if (path is None) == (data is None):
        raise ValueError("give exactly one of path= or data=")
    if path is not None:
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"station config {path}: no such file")
    try:
        config = yaml_load_typed(
            schema=StationConfig, filename=str(path) if path is not None else None,
            data=data, defaults=defaults or StationConfig())
    except RuntimeError as e:
        where = f"{path}" if path is not None else "YAML"
        raise ValueError(f"station config ({where}): {e}") from e
    return validate_station_config(config)


def scenario_for_skill(skill: str) -> StationConfig:
    """The default station for a skill: the box closed (open), open (close), or the drawer."""
    if skill not in SKILLS:
        raise ValueError(f"skill {skill!r}: expected one of {', '.join(SKILLS)}")
    config = StationConfig()
    # The box sits further away for Open than for Close: lifting the lip from
    # the front needs the arm stretched, reaching behind the open lid needs it
    # closer (the Panda's joint 4 and 6 limits bound both).
    if skill == "open":
        config.object.x = 0.62
    elif skill == "close":
        config.object.x = 0.52
        config.object.initial_joint = 1.9
    elif skill == "draw":
        config.object.kind = "drawer"
        config.object.x = 0.68
    return config
