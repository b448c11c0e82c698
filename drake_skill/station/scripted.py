"""Scripted hand motions for Open, Close and Draw, as keyframes in the object frame.

Object frame O (see ``models/``): origin at the centre of the object's bottom
face, x pointing away from the robot (toward the lid hinge / cabinet back),
y along the object's long side, z up. The hand's TCP frame E is the one the
station's ``ee_pose_desired`` port takes. Positions are in metres.

* Open: the hand points along +x_O, slides its closed fingertips under the
  lid's front lip and sweeps them up along the lid's arc about the hinge,
  pushing the lid past vertical.
* Close: the hand points down, hooks the finger behind the open lid's outer
  face and sweeps it forward and down along the arc until the lid is shut.
* Draw: the hand points down, lowers the closed fingers between the drawer
  front and the handle bar, and pulls along -x_O.

``scripted_plan`` maps the keyframes to the world with X_WO and optionally
perturbs timing and path (seeded), as a human demonstrator would.
"""

from __future__ import annotations

import numpy as np
from pydrake.math import RigidTransform, RotationMatrix

from drake_skill.station.pose_source import PosePlan
from drake_skill.station.config import SKILLS

# Hand pointing forward along +x_O and pitched 60 degrees down, fingers spread
# along y_O. (Pointing level, the Panda runs into joint 6's lower limit while
# lifting the lid.)
OPEN_PITCH = np.deg2rad(60.0)
# Both orientations keep y_E = -y_O, as at the home posture, so reaching them
# from home is a rotation about y alone.
R_OE_FORWARD = RotationMatrix.MakeYRotation(OPEN_PITCH) @ RotationMatrix(
    np.array([[0.0, 0.0, 1.0], [0.0, -1.0, 0.0], [1.0, 0.0, 0.0]]))
# Hand pointing down (-z_O), fingers spread along y_O: the home orientation.
R_OE_DOWN = RotationMatrix(np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]]))

LID_HINGE_XZ = np.array([0.10, 0.13])   # models/box.sdf
FINGER_HALF_THICKNESS = 0.011
TCP_TO_TIP = 0.009                      # fingertips are 9 mm past the TCP
# Where the fingertip stops under the lid's lip (x in O; the lip spans -0.125..-0.100).
UNDER_LIP_X = -0.109
UNDER_LIP_Z = 0.116
# Close: the hand's lean toward the robot per radian the lid is below 1.4 rad (up to 0.8).
CLOSE_LEAN = 0.8


def _arc(theta, radius):
    """Point on the lid at ``radius`` from the hinge, lid angle theta (x, z in O)."""
    return LID_HINGE_XZ + radius * np.array([-np.cos(theta), np.sin(theta)])


def _xyz(xz):
    return np.array([xz[0], 0.0, xz[1]])


def keyframes(skill: str) -> list[tuple[float, np.ndarray, RotationMatrix, float]]:
    """Keyframes (time [s], p_OE [m], R_OE, finger opening [m]) after a move from home."""
    frames = []
    if skill == "open":
        R = R_OE_FORWARD
        # Finger's upper front edge sits 1 cm inside the lid's underside as it sweeps.
        z_E, x_E = R.col(2), R.col(0)
        tip_offset = (TCP_TO_TIP * z_E + FINGER_HALF_THICKNESS * x_E)[[0, 2]]  # TCP -> tip's upper edge
        radius, push = LID_HINGE_XZ[0] - UNDER_LIP_X, 0.004
        under_lip = _xyz(np.array([UNDER_LIP_X, UNDER_LIP_Z]) - tip_offset)
        # Turn the hand at height first: descending while turning folds the
        # elbow into joint 4's limit.
        # Down in front of the box, then in under the lip (a diagonal approach
        # would cross the lip).
        frames += [(1.5, under_lip + [-0.05, 0.0, 0.16], R, 0.0),
                   (2.5, under_lip + [-0.05, 0.0, 0.0], R, 0.0),
                   (3.5, under_lip, R, 0.0),
                   (4.0, under_lip, R, 0.0)]    # a pause, as a person makes before lifting
        for i, theta in enumerate(np.linspace(0.0, 1.85, 9)[1:]):
            contact = _arc(theta, radius) + push * np.array([np.sin(theta), np.cos(theta)])
            frames.append((4.0 + 0.5 * (i + 1), _xyz(contact - tip_offset), R, 0.0))
        last = frames[-1][1]
        # Leave upward first, then back: retreating straight back drags the lid.
        frames += [(8.5, last + [0.0, 0.0, 0.06], R, 0.0),
                   (9.5, last + [-0.15, 0.0, 0.08], R, 0.0)]
    elif skill == "close":
        radius, push = 0.19, 0.004
        theta0 = 1.75

        def hand(theta):
            # Below ~80 degrees the hand leans toward the robot, so its body
            # stays clear of the lid's rising front part (pointing straight
            # down, the hand body jams on the lid below ~60 degrees).
            return RotationMatrix.MakeYRotation(CLOSE_LEAN * min(max(1.4 - theta, 0.0), 0.8)) @ R_OE_DOWN

        def tcp(theta):
            n = np.array([np.sin(theta), np.cos(theta)])         # lid's outer normal (x, z)
            face = _arc(theta, radius) + 0.02 * n               # point on the outer face
            tip = face + n * (FINGER_HALF_THICKNESS * abs(n[0]) - push)
            z_E = hand(theta).col(2)
            return _xyz(tip) - TCP_TO_TIP * z_E

        start = tcp(theta0) + [0.03, 0.0, 0.0]
        frames += [(2.5, start + [0.0, 0.0, 0.10], hand(theta0), 0.0),
                   (3.5, start, hand(theta0), 0.0),
                   (4.0, start, hand(theta0), 0.0)]
        for i, theta in enumerate(np.linspace(theta0, -0.05, 10)[1:]):
            frames.append((4.0 + 0.5 * (i + 1), tcp(theta), hand(theta), 0.0))
        last = frames[-1][1]
        # leave up and toward the hinge: lifting straight up can catch the lip
        frames += [(9.5, last + [0.06, 0.0, 0.12], hand(0.0), 0.0)]
    elif skill == "draw":
        R = R_OE_DOWN
        gap_x, tip_z = -0.173, 0.115
        frames += [(2.5, np.array([gap_x, 0.0, 0.30]), R, 0.0),
                   (3.5, np.array([gap_x, 0.0, tip_z + TCP_TO_TIP]), R, 0.0),
                   (4.0, np.array([gap_x, 0.0, tip_z + TCP_TO_TIP]), R, 0.0),
                   (7.0, np.array([gap_x - 0.19, 0.0, tip_z + TCP_TO_TIP]), R, 0.0),
                   # lift clear of the handle (never pushing the drawer back), then
                   # away from the robot's base, where the arm can settle
                   (8.0, np.array([gap_x - 0.20, 0.0, 0.22]), R, 0.0),
                   (8.8, np.array([gap_x - 0.14, 0.0, 0.32]), R, 0.0)]
    else:
        raise ValueError(f"skill {skill!r}: expected one of {', '.join(SKILLS)}")
    return frames


def scripted_plan(skill: str, X_WO: RigidTransform, X_WE_home: RigidTransform,
                  rng: np.random.Generator | None = None, time_scale_range: float = 0.0,
                  path_noise: float = 0.0) -> PosePlan:
    """The keyframes of ``skill`` mapped to the world by X_WO, starting from the home pose.

    With ``rng``: every segment's duration is scaled by a factor drawn from
    [1 - time_scale_range, 1 + time_scale_range] and every via point is moved
    by Gaussian noise of standard deviation ``path_noise`` [m].
    """
    frames = keyframes(skill)
    times, poses, grip = [0.0], [X_WE_home], [0.0]
    t_prev_key, t = 0.0, 0.0
    for t_key, p_OE, R_OE, opening in frames:
        dt = t_key - t_prev_key
        t_prev_key = t_key
        if rng is not None and time_scale_range > 0:
            dt *= rng.uniform(1 - time_scale_range, 1 + time_scale_range)
        if rng is not None and path_noise > 0:
            p_OE = p_OE + rng.normal(0.0, path_noise, size=3)
        t += dt
        times.append(t)
        poses.append(X_WO @ RigidTransform(R_OE, p_OE))
        grip.append(opening)
    return PosePlan.from_poses(times, poses, grip)
