"""Configuration of the hardware port: the LCM side of the Panda driver, safety, camera.

(No ``from __future__ import annotations`` here: yaml_load_typed reads the
field types at run time.)

A :class:`HardwareConfig` wraps the :class:`~drake_skill.station.config.StationConfig`
of the scenario (controller, camera intrinsics and pose, object placement,
success thresholds are the simulated station's) and adds what only the real
robot has: LCM channels and URL, the workspace box, the stale-status
timeout and the camera source. ``load_hardware_config`` turns every problem
into a ``ValueError`` naming the field.
"""

import dataclasses as dc
import functools
import math
from pathlib import Path


from drake_skill import configs
from drake_skill.configs import load_typed
from drake_skill.station.config import StationConfig, validate_station_config

CAMERA_SOURCES = ("lcm", "realsense")


@dc.dataclass
class WorkspaceConfig:
    """The box (world frame W, metres) the commanded hand position p_WE is clipped to.

    lower, upper: [x, y, z] corners. The defaults enclose the table's working
    area in front of the Panda with the hand above the table top (z = 0).
    """

    lower: list[float] = dc.field(default_factory=lambda: [0.20, -0.45, 0.02])
    upper: list[float] = dc.field(default_factory=lambda: [0.85, 0.45, 0.75])


@dc.dataclass
class HardwareConfig:
    """Everything ``build_hardware_station`` needs.

    lcm_url: LCM URL ("" = LCM's default, udpm://239.255.76.67:7667?ttl=0);
      ``memq://`` for a robot simulated in the same process.
    status_channel, command_channel: the drake-franka-driver's channels
      (its ``--lcm_status_channel`` / ``--lcm_command_channel``).
    hand_command_channel: the Franka Hand driver's command channel
      (``lcmt_schunk_wsg_command``).
    camera_channel: ``lcmt_image_array`` (colour, 32-bit depth, optional
      label image) published by the camera driver or the simulated robot.
    ground_truth_channel: ``lcmt_scope`` with the object state (lid angle
      [rad] / drawer travel [m]) that ``drake-skill sim-robot`` publishes;
      the hardware station's ``object_state`` reads it (NaN when nothing is
      published there, as with a real robot). "" turns it off.
    camera_source: "lcm" (images over ``camera_channel``) or "realsense"
      (a RealSense device through ``pyrealsense2``, an optional extra).
    command_period: period of the position commands sent to the driver [s]
      (the driver's control loop runs at 1 kHz, the controller's rate limiter too).
    status_timeout: no status message for longer than this [s] stops the
      station with :class:`~drake_skill.station.hardware.StaleStatusError`.
    reset_timeout: how long ``reset`` waits for the first status [s].
    hand_force: grasp force limit sent with every hand command [N].
    workspace: the box commanded hand positions are clipped to.
    station: the scenario; its controller, camera (enable_camera switches
      the camera ports on), object placement and success thresholds apply.
    """

    lcm_url: str = ""
    status_channel: str = "PANDA_STATUS"
    command_channel: str = "PANDA_COMMAND"
    hand_command_channel: str = "PANDA_HAND_COMMAND"
    camera_channel: str = "DRAKE_RGBD_CAMERA_IMAGES"
    ground_truth_channel: str = "SIM_OBJECT_STATE"
    camera_source: str = "lcm"
    command_period: float = 0.001
    status_timeout: float = 0.1
    reset_timeout: float = 2.0
    hand_force: float = 20.0
    workspace: WorkspaceConfig = dc.field(default_factory=WorkspaceConfig)
    station: StationConfig = dc.field(default_factory=StationConfig)


def validate_hardware_config(config: HardwareConfig) -> HardwareConfig:
    """Raises ValueError naming the field of ``config`` that cannot work; returns it."""
    bad = functools.partial(configs.bad, "hardware config")

    if not isinstance(config, HardwareConfig):
        raise ValueError(f"config must be a HardwareConfig, got {type(config).__name__}")
    for name in ("status_channel", "command_channel", "hand_command_channel", "camera_channel"):
        if not getattr(config, name):
            bad(name, getattr(config, name), "a non-empty LCM channel name")
    if config.camera_source not in CAMERA_SOURCES:
        bad("camera_source", config.camera_source, f"one of {', '.join(CAMERA_SOURCES)}")
    if not 1e-3 <= config.command_period <= 0.05:
        bad("command_period", config.command_period, "a period in [0.001, 0.05] s")
    if not (math.isfinite(config.status_timeout) and config.status_timeout >= 2 * config.command_period):
        bad("status_timeout", config.status_timeout,
            f"a finite timeout of at least two command periods ({2 * config.command_period} s)")
    if not config.reset_timeout > 0:
        bad("reset_timeout", config.reset_timeout, "a positive time [s]")
    if not 0 <= config.hand_force <= 70:
        bad("hand_force", config.hand_force, "a force in [0, 70] N (the Franka Hand's range)")
    ws = config.workspace
    if len(ws.lower) != 3 or len(ws.upper) != 3:
        bad("workspace.lower/upper", (ws.lower, ws.upper), "3 coordinates each [m]")
    if not all(lo < hi for lo, hi in zip(ws.lower, ws.upper)):
        bad("workspace.lower/upper", (ws.lower, ws.upper), "lower < upper on every axis")
    validate_station_config(config.station)
    if config.station.controller.diff_ik_period > config.status_timeout:
        bad("station.controller.diff_ik_period", config.station.controller.diff_ik_period,
            "at most status_timeout")
    return config


def load_hardware_config(path: str | Path | None = None, *, data: str | None = None,
                         defaults: HardwareConfig | None = None) -> HardwareConfig:
    """A HardwareConfig from a YAML file or string (missing keys keep their defaults)."""
    config = load_typed(HardwareConfig, what="hardware config", path=path, data=data, defaults=defaults)
    return validate_hardware_config(config)
