"""The one station contract: what the simulated and the hardware station both are.

Everything above the station (the skill's diagram, the rollout runner, the
recorders, the segmenter) talks to a station only through this contract, so
a skill runs unchanged in simulation (:class:`drake_skill.station.sim.builder.Station`)
and on the robot (:class:`drake_skill.station.hardware.station.HardwareStation`);
``tests/test_hardware.py`` checks both against it. Ports (docs/architecture.md):

    inputs   ee_pose_desired      RigidTransform X_WE of the hand's TCP [m]
             gripper_command      [1] finger opening [m]
    outputs  panda_state          [14] joint positions [rad] and velocities [rad/s]
             ee_pose              RigidTransform X_WE, measured
             object_state         [1] the object's joint [rad or m] (NaN on a robot without a sensor)
             reflex_state         [10] the collision reflex's filtered force [N], torques [N m], ...
             point_cloud, color_image, depth_image, label_image, object_point_cloud, ...
                                  the camera's, when ``config.enable_camera``
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

from pydrake.math import RigidTransform

__all__ = ["CAMERA_OUTPUTS", "INPUTS", "OUTPUTS", "StationInterface", "port_signature", "station_ports"]

#: Name -> (Drake port data type, vector size or abstract value type) of every station.
INPUTS = {"ee_pose_desired": ("kAbstractValued", "RigidTransform"), "gripper_command": ("kVectorValued", 1)}
OUTPUTS = {"panda_state": ("kVectorValued", 14), "ee_pose": ("kAbstractValued", "RigidTransform"),
           "object_state": ("kVectorValued", 1), "reflex_state": ("kVectorValued", 10)}
#: ... and of a station with its camera on.
CAMERA_OUTPUTS = {"point_cloud": ("kAbstractValued", "PointCloud"),
                  "object_point_cloud": ("kAbstractValued", "PointCloud")}


@runtime_checkable
class StationInterface(Protocol):
    """A station: a Diagram with the ports above, its scenario, and these methods.

    config: the scenario (``Scenario``); realtime: its simulator must run
    in real time (the robot's); object_camera: the cropped object camera
    (``drake_skill.station.camera.ObjectCamera``) or None without one.
    """

    config: object
    realtime: bool
    object_camera: object

    def hand_pose(self, q) -> RigidTransform:
        """X_WE of the hand's TCP for joint positions q [rad] (the ``ee_pose`` output's value)."""

    def camera_pose(self) -> RigidTransform:
        """X_WC of the camera [m]."""

    def nominal_object_pose(self) -> RigidTransform:
        """The scenario's object pose X_WO [m]."""

    def random_object_pose(self, seed: int) -> RigidTransform:
        """The object pose X_WO drawn from ``seed`` (the scenario's randomisation)."""

    def object_pose(self, context) -> RigidTransform:
        """The object's pose X_WO now (placed or simulated)."""

    def reset(self, context, seed: int | None = None) -> RigidTransform:
        """Home arm, object at the pose of ``seed`` (nominal for None); returns X_WO."""

    def stop_error(self, context) -> RuntimeError | None:
        """Why the station stopped the simulator (its monitors returned
        ``EventStatus.ReachedTermination`` and keep the reason in their state), as the typed
        error (``ReflexError``, ``StaleStatusError``), or None; ``context``: a root context."""


def port_signature(port) -> tuple[str, object]:
    """(data type name, size or abstract value type name) of a Drake port; template
    types read as pydrake prints them (``Image[PixelType.kRgba8U]``)."""
    from pydrake.common import pretty_class_name

    kind = port.get_data_type().name
    if kind == "kAbstractValued":
        return kind, pretty_class_name(type(port.Allocate().get_value()))
    return kind, port.size()


def station_ports(system) -> tuple[dict, dict]:
    """The signatures of a system's input and output ports, by name."""
    ins = {system.get_input_port(i).get_name(): port_signature(system.get_input_port(i))
           for i in range(system.num_input_ports())}
    outs = {system.get_output_port(i).get_name(): port_signature(system.get_output_port(i))
            for i in range(system.num_output_ports())}
    return ins, outs
