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

# Hand pointing forward along +x_O, fingers spread along y_O, pitched down by
# OPEN_PITCH. (Pointing level, the Panda runs into joint 6's lower limit while
# lifting the lid.) It keeps y_E = -y_O, as at the home posture, so reaching
# it from home is a rotation about y alone.
OPEN_PITCH = np.deg2rad(60.0)
R_OE_FORWARD_LEVEL = RotationMatrix(np.array([[0.0, 0.0, 1.0], [0.0, -1.0, 0.0], [1.0, 0.0, 0.0]]))
R_OE_FORWARD = RotationMatrix.MakeYRotation(OPEN_PITCH) @ R_OE_FORWARD_LEVEL
# Hand pointing down (-z_O), fingers spread along y_O: the home orientation.
R_OE_DOWN = RotationMatrix(np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]]))

LID_HINGE_XZ = np.array([0.10, 0.13])   # models/box.sdf
FINGER_HALF_THICKNESS = 0.011
TCP_TO_TIP = 0.009                      # fingertips are 9 mm past the TCP
# Where the fingertip stops under the lid's lip (x in O; the lip spans -0.125..-0.100).
# Open: the lip's front-bottom edge is LIP_RADIUS from the hinge (models/box.sdf).
LIP_RADIUS = 0.225
OPEN_FACE_CONTACT = 0.006   # the face touches the lip edge this far behind the tip [m]
OPEN_CLEARANCE = 0.005      # the approach stops this far short of the lip edge [m]
OPEN_PUSH = 0.003           # the sweep presses the face this far into the edge [m]
OPEN_SWEEP_END = 1.75       # the sweep pushes the lid to this angle [rad], past its tipping angle
# Close: the hand's lean toward the robot per radian the lid is below 1.4 rad (up to 0.8).
CLOSE_LEAN = 0.8
CLOSE_START = 1.9       # the lid resting on its stay [rad]
CLOSE_RELEASE = 1.2     # pulled this far (past the 1.48 rad tipping angle), the lid falls shut
CLOSE_BEHIND = 0.03     # the approach starts this far behind the lid's face [m]
CLOSE_PUSH = 0.004      # the fingertip path runs this far inside the face [m]
# Draw: the fingertip's centre between the drawer front (x = -0.16) and the
# handle bar (x = -0.205, radius 8 mm, centre 0.14 m up), 7 mm below the bar.
DRAW_TILT = np.deg2rad(20.0)
DRAW_TIP_X = -0.176
DRAW_TIP_Z = 0.125
DRAW_TRAVEL = 0.19


def _arc(theta, radius):
    """Point on the lid at ``radius`` from the hinge, lid angle theta (x, z in O)."""
    return LID_HINGE_XZ + radius * np.array([-np.cos(theta), np.sin(theta)])


def _xyz(xz):
    return np.array([xz[0], 0.0, xz[1]])


def keyframes(skill: str) -> list[tuple[float, np.ndarray, RotationMatrix, float]]:
    """Keyframes (time [s], p_OE [m], R_OE, finger opening [m]) after a move from home."""
    frames = []
    if skill == "open":
        R = RotationMatrix.MakeYRotation(OPEN_PITCH) @ R_OE_FORWARD_LEVEL
        z_E, x_E = R.col(2), R.col(0)
        # The finger's upper face (normal x_E) rises behind its tip at the
        # hand's pitch, so it meets the lip's front-bottom edge before the tip
        # can get under the lip: the face lifts the lid by that edge. The
        # contact sits OPEN_FACE_CONTACT behind the tip's upper corner.
        face_back = -z_E[[0, 2]]
        normal = x_E[[0, 2]]
        tip_offset = (TCP_TO_TIP * z_E + FINGER_HALF_THICKNESS * x_E)[[0, 2]]  # TCP -> tip's upper corner

        def tcp(theta, push):
            corner = _arc(theta, LIP_RADIUS) - OPEN_FACE_CONTACT * face_back + push * normal
            return _xyz(corner - tip_offset)

        start = tcp(0.0, -OPEN_CLEARANCE)
        # Turn the hand at height first (descending while turning folds the
        # elbow into joint 4's limit), then down in front of the lip and in.
        frames += [(1.5, start + [-0.05, 0.0, 0.16], R, 0.0),
                   (2.5, start + [-0.05, 0.0, 0.0], R, 0.0),
                   (3.5, start, R, 0.0),
                   (4.0, start, R, 0.0)]    # a pause, as a person makes before lifting
        for i, theta in enumerate(np.linspace(0.0, OPEN_SWEEP_END, 9)):
            frames.append((4.5 + 0.5 * i, tcp(theta, OPEN_PUSH), R, 0.0))
        last = frames[-1][1]
        # Leave upward first, then back: retreating straight back drags the lid.
        frames += [(9.0, last + [0.0, 0.0, 0.06], R, 0.0),
                   (10.0, last + [-0.15, 0.0, 0.08], R, 0.0)]
    elif skill == "close":
        radius, push = 0.19, CLOSE_PUSH
        theta0 = CLOSE_START

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

        start = tcp(theta0) + [CLOSE_BEHIND, 0.0, 0.0]
        frames += [(2.5, start + [0.0, 0.0, 0.10], hand(theta0), 0.0),
                   (3.5, start, hand(theta0), 0.0),
                   (4.0, start, hand(theta0), 0.0)]
        # Pull the lid off its stay and over its tipping angle; past it, its
        # weight shuts it (the hand must not chase and press it).
        for i, theta in enumerate(np.linspace(theta0, CLOSE_RELEASE, 5)[1:]):
            frames.append((4.0 + 0.5 * (i + 1), tcp(theta), hand(theta), 0.0))
        last = frames[-1][1]
        # Up, out of the falling lid's way, and toward the hinge.
        frames += [(6.5, last + [0.0, 0.0, 0.08], hand(CLOSE_RELEASE), 0.0),
                   (7.5, last + [0.06, 0.0, 0.14], hand(CLOSE_RELEASE), 0.0)]
    elif skill == "draw":
        # Tilted so the fingertips lead toward the drawer front and the hand
        # housing trails toward the robot, clear of the cabinet's top edge
        # (pointing straight down, the housing lands on the cabinet before the
        # fingers are below the handle).
        R = RotationMatrix.MakeYRotation(-DRAW_TILT) @ R_OE_DOWN
        z_E = R.col(2)
        tip = np.array([DRAW_TIP_X, 0.0, DRAW_TIP_Z])
        tcp = tip - TCP_TO_TIP * z_E
        out = tcp - [DRAW_TRAVEL, 0.0, 0.0]
        frames += [(2.5, tcp + [0.0, 0.0, 0.16], R, 0.0),
                   (3.5, tcp, R, 0.0),
                   (4.0, tcp, R, 0.0),
                   (7.0, out, R, 0.0),
                   # lift clear of the handle (never pushing the drawer back), then
                   # away from the robot's base, where the arm can settle
                   (8.0, out + [-0.01, 0.0, 0.10], R, 0.0),
                   (8.8, out + [0.05, 0.0, 0.20], R, 0.0)]
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
