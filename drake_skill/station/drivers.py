"""The arm's driver: a scenario field, as ``model_drivers`` is in Drake's ``hardware_sim``.

(No ``from __future__ import annotations`` here: yaml_load_typed reads the
field types at run time.)

The scenario's ``driver`` (``drake_skill.station.scenario.Scenario.driver``)
says what sits between the station's command input and the arm; the station
factory (:func:`drake_skill.station.make.make_station`) dispatches on its
type, as the ``manipulation`` repository's ``MakeHardwareStation`` dispatches
on ``IiwaDriver`` / ``InverseDynamicsDriver``. In YAML a driver is tagged
with its class name; an untagged one is an :class:`EndEffectorDriver`::

    driver: !PandaLcmDriver {lcm_url: "udpm://239.255.76.67:7667?ttl=0"}

- :class:`EndEffectorDriver` (the default): input ``ee_pose_desired``, the
  hand's TCP pose; differential IK and the rate limiter (the scenario's
  ``controller``) command the simulated arm's joint impedance.
- :class:`JointSetpointDriver`: input ``panda_state_desired``, joint set
  points [q (7), v (7)] that the simulated arm's joint impedance tracks
  directly; the simulated robot behind the Panda driver's LCM protocol
  (``drake_skill.station.sim.lcm_robot.SimRobot``) uses it.
- :class:`PandaLcmDriver`: the real Panda through the drake-franka-driver's
  LCM messages. With ``hardware=True`` the factory builds the hardware
  station on it; in simulation it drives the arm as :class:`EndEffectorDriver`
  does (the IK and the rate limiter run on drake-skill's side on the robot
  too), so one scenario file serves both.
"""

import dataclasses as dc
import functools
import math
import typing

from drake_skill import typed_yaml

__all__ = ["CAMERA_SOURCES", "DRIVER_TYPES", "EndEffectorDriver", "JointSetpointDriver", "PandaLcmDriver",
           "WorkspaceConfig", "driver_tag", "require_panda_driver",
           "validate_driver"]

CAMERA_SOURCES = ("lcm", "realsense")


@dc.dataclass
class EndEffectorDriver:
    """The hand pose in (``ee_pose_desired``, X_WE): differential IK and the 1 kHz rate
    limiter of the scenario's ``controller`` drive the simulated arm."""


@dc.dataclass
class JointSetpointDriver:
    """Joint set points in (``panda_state_desired``: q (7) [rad], v (7) [rad/s]), tracked
    by the simulated arm's joint impedance (the scenario's ``controller.kp``/``kd``)."""


@dc.dataclass
class WorkspaceConfig:
    """The box (world frame W, metres) the commanded hand position p_WE is clipped to on the robot.

    lower, upper: [x, y, z] corners. The defaults enclose the table's working
    area in front of the Panda with the hand above the table top (z = 0).
    """

    lower: typing.List[float] = dc.field(default_factory=lambda: [0.20, -0.45, 0.02])
    upper: typing.List[float] = dc.field(default_factory=lambda: [0.85, 0.45, 0.75])


@dc.dataclass
class PandaLcmDriver:
    """The real Panda behind the drake-franka-driver (``--control_mode=position``) over LCM.

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
      station with ``StaleStatusError``.
    reset_timeout: how long ``reset`` waits for the first status [s].
    hand_force: grasp force limit sent with every hand command [N].
    workspace: the box commanded hand positions are clipped to.
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


#: The scenario field's options, in the order YAML tries them (untagged: the first).
DRIVER_TYPES = (EndEffectorDriver, JointSetpointDriver, PandaLcmDriver)


def driver_tag(driver) -> str:
    """The YAML tag of a driver, e.g. ``!PandaLcmDriver``."""
    return f"!{type(driver).__name__}"


def require_panda_driver(config, who: str, where: str = "") -> PandaLcmDriver:
    """The ``!PandaLcmDriver`` of the scenario ``config``; else the one-line ValueError that
    names the field and the fix. who: what needs it ("the robot"); where: the scenario's file."""
    if not isinstance(config.driver, PandaLcmDriver):
        raise ValueError(f"scenario{f' ({where})' if where else ''}: field 'driver' = "
                         f"{driver_tag(config.driver)}: {who} speaks the Panda driver's LCM protocol; give the "
                         "scenario driver: !PandaLcmDriver {...} (tagged; its keys: lcm_url, channels, timeouts)")
    return config.driver


def validate_driver(driver, diff_ik_period: float, what: str = "scenario") -> None:
    """Raises the one-line ValueError of a ``driver`` field that cannot work.

    diff_ik_period: the scenario's ``controller.diff_ik_period`` [s]; a robot's
    status may not go stale for less than one IK period.
    """
    bad = functools.partial(typed_yaml.bad, what)
    if not isinstance(driver, DRIVER_TYPES):
        bad("driver", driver, "one of " + ", ".join(f"!{t.__name__}" for t in DRIVER_TYPES))
    if not isinstance(driver, PandaLcmDriver):
        return
    for name in ("status_channel", "command_channel", "hand_command_channel", "camera_channel"):
        if not getattr(driver, name):
            bad(f"driver.{name}", getattr(driver, name), "a non-empty LCM channel name")
    if driver.camera_source not in CAMERA_SOURCES:
        bad("driver.camera_source", driver.camera_source, f"one of {', '.join(CAMERA_SOURCES)}")
    if not 1e-3 <= driver.command_period <= 0.05:
        bad("driver.command_period", driver.command_period, "a period in [0.001, 0.05] s")
    if not (math.isfinite(driver.status_timeout) and driver.status_timeout >= 2 * driver.command_period):
        bad("driver.status_timeout", driver.status_timeout,
            f"a finite timeout of at least two command periods ({2 * driver.command_period} s)")
    if diff_ik_period > driver.status_timeout:
        bad("driver.status_timeout", driver.status_timeout,
            f"at least controller.diff_ik_period ({diff_ik_period} s)")
    if not driver.reset_timeout > 0:
        bad("driver.reset_timeout", driver.reset_timeout, "a positive time [s]")
    if not 0 <= driver.hand_force <= 70:
        bad("driver.hand_force", driver.hand_force, "a force in [0, 70] N (the Franka Hand's range)")
    ws = driver.workspace
    if len(ws.lower) != 3 or len(ws.upper) != 3:
        bad("driver.workspace.lower/upper", (ws.lower, ws.upper), "3 coordinates each [m]")
    if not all(lo < hi for lo, hi in zip(ws.lower, ws.upper)):
        bad("driver.workspace.lower/upper", (ws.lower, ws.upper), "lower < upper on every axis")
