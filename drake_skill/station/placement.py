"""Where the scenario's object is: its parts in a plant and its pose on the table.

Shared by the simulated and the hardware station (the hardware station places a
model of the object for its camera window and draws the same poses for the
operator to set up): the object's base body and joint checked against the
scenario, the nominal pose X_WO and the seeded random poses around it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from pydrake.math import RigidTransform, RollPitchYaw

if TYPE_CHECKING:   # annotations only: station.config validates a scenario with object_parts
    from drake_skill.station.scenario import Scenario


def nominal_object_pose(config: Scenario) -> RigidTransform:
    """X_WO of the object's base at the scenario's nominal place on the table."""
    o = config.object
    return RigidTransform(RollPitchYaw(0.0, 0.0, o.yaw), [o.x, o.y, 0.0])


def random_object_pose(config: Scenario, seed: int) -> RigidTransform:
    """The nominal pose perturbed uniformly, from ``seed`` alone: x and y by up to
    ``object.randomize_xy`` [m] each, the yaw by up to ``object.randomize_yaw`` [rad]."""
    o = config.object
    rng = np.random.default_rng(seed)
    dx, dy = rng.uniform(-o.randomize_xy, o.randomize_xy, size=2)
    dyaw = rng.uniform(-o.randomize_yaw, o.randomize_yaw)
    return RigidTransform(RollPitchYaw(0.0, 0.0, o.yaw + dyaw), [o.x + dx, o.y + dy, 0.0])


def object_parts(plant, obj, config: Scenario):
    """The object model's base body and its one articulated joint (``object.base_body``,
    ``object.joint``); a name the model lacks, a joint with other than one position,
    or an initial position outside the joint's limits is a ValueError naming the field."""
    o = config.object
    bodies = [plant.get_body(b).name() for b in plant.GetBodyIndices(obj)]
    if o.base_body not in bodies:
        raise ValueError(f"scenario field 'object.base_body' = {o.base_body!r}: the model "
                         f"'{o.model}' has no such body; expected one of {', '.join(bodies)}")
    joints = [plant.get_joint(j).name() for j in plant.GetJointIndices(obj)]
    if o.joint not in joints:
        raise ValueError(f"scenario field 'object.joint' = {o.joint!r}: the model '{o.model}' has no "
                         f"such joint; expected one of {', '.join(joints) or '(none)'}")
    joint = plant.GetJointByName(o.joint, obj)
    if joint.num_positions() != 1:
        raise ValueError(f"scenario field 'object.joint' = {o.joint!r}: a {joint.type_name()} joint of "
                         f"{joint.num_positions()} positions; expected a revolute or prismatic joint")
    lo, hi = float(joint.position_lower_limits()[0]), float(joint.position_upper_limits()[0])
    if not lo - 1e-9 <= o.initial_joint <= hi + 1e-9:
        raise ValueError(f"scenario field 'object.initial_joint' = {o.initial_joint!r}: expected a "
                         f"position within the joint's limits [{lo}, {hi}]")
    return plant.GetBodyByName(o.base_body, obj), joint
