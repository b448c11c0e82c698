"""Franka Emika Panda limits: the one definition the simulated station and the hardware port share.

Joint limits are Franka's published values ("Robot and interface
specifications", Franka Control Interface documentation; the same numbers
are in ``libfranka``'s ``rate_limiting.h``): position, velocity,
acceleration, jerk and torque per joint, joints 1..7. Units: rad, rad/s,
rad/s^2, rad/s^3, N m.

The Franka Hand: each finger travels 0..0.04 m; the finger speed limit is
the ``velocity`` of the finger joints in Franka's ``franka_description``
(0.2 m/s), which bounds what ``franka::Gripper::move`` accepts.

Collision reflex (``REFLEX_*``): the real robot stops itself ("cartesian /
joint reflex") when its estimated external wrench or external joint
torques exceed the thresholds set with ``franka::Robot::setCollisionBehavior``.
``libfranka``'s examples (``setDefaultBehavior``) and ``franka_ros``'s
``franka_control`` node set 20 N (x, y, z) and 20, 20, 18, 18, 16, 14, 12 N m
(joints 1..7); labs commonly raise them moderately for contact tasks. The
station uses 30 N on the total robot-scene contact force and 1.5 x the
default joint thresholds on the external joint torques (the torques the
contact forces produce on the joints, as the robot's estimator sees them).
"""

from __future__ import annotations

import numpy as np

Q_MIN = np.array([-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973])
Q_MAX = np.array([2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973])
QD_MAX = np.array([2.1750, 2.1750, 2.1750, 2.1750, 2.6100, 2.6100, 2.6100])
QDD_MAX = np.array([15.0, 7.5, 10.0, 12.5, 15.0, 20.0, 20.0])
QDDD_MAX = np.array([7500.0, 3750.0, 5000.0, 6250.0, 7500.0, 10000.0, 10000.0])
TAU_MAX = np.array([87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0])
DTAU_MAX = 1000.0                     # torque rate [N m/s]

FINGER_MAX = 0.04                     # travel of one finger [m]
FINGER_SPEED_MAX = 0.2                # one finger [m/s]
FINGER_FORCE_MAX = 70.0               # continuous grasp force [N]

#: Defaults of the collision reflex (see the module docstring).
REFLEX_FORCE_N = 30.0
REFLEX_TORQUE_NM = 1.5 * np.array([20.0, 20.0, 18.0, 18.0, 16.0, 14.0, 12.0])
