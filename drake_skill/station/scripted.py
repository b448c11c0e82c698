"""Scripted hand motions for Open, Close and Draw, as keyframes in the object frame.

Object frame O (see ``models/``): origin at the centre of the object's bottom
face, x pointing away from the robot (toward the lid hinge / cabinet back),
y along the object's long side, z up. The hand's TCP frame E is the one the
station's ``ee_pose_desired`` port takes. Positions are in metres.

* Open: the hand points along +y_O (along the hinge), opens its fingers and
  slides one of them in from the box's side under the lid's front lip, then
  turns rigidly with the lid about the hinge axis until the lid is past its
  tipping angle (it falls open onto its stay by its weight), and leaves
  sideways.
* Close: the hand points down, hooks the finger behind the lid resting open
  on its stay and flicks it forward: a brisk pull that stops short of the
  tipping angle, so the lid's momentum carries it over and its weight shuts
  it while the hand moves up out of its way. A DMP (10 bases over ~9 s)
  cannot reproduce a 0.2 s flick: it pulls as far but slower, and the lid
  stops near its tipping angle or falls back onto its stay (docs/method.md
  section 6).
* Draw: the hand points down, tilted 20 degrees toward the robot, lowers the
  closed fingers between the drawer front and the handle bar, and pulls along
  -x_O.

Every motion keeps the robot-scene contact force well below the collision
reflex (``drake_skill.station.limits``), as ``tools/check_physics.py`` checks.

``scripted_plan`` maps the keyframes to the world with X_WO and optionally
perturbs timing and path (seeded), as a human demonstrator would.
"""

from __future__ import annotations

import numpy as np
from pydrake.math import RigidTransform, RotationMatrix

from drake_skill.station.pose_source import PosePlan
from drake_skill.station.config import SKILLS

# Hand pointing down (-z_O), fingers spread along y_O: the home orientation.
R_OE_DOWN = RotationMatrix(np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]]))

LID_HINGE_XZ = np.array([0.10, 0.13])   # models/box.sdf
FINGER_HALF_THICKNESS = 0.011
TCP_TO_TIP = 0.009                      # fingertips are 9 mm past the TCP
# Where the fingertip stops under the lid's lip (x in O; the lip spans -0.125..-0.100).
# Open: the hand pointing along +y_O, fingers spread along +x_O, finger
# thickness (x_E) vertical.
OPEN_R_OE = RotationMatrix(np.column_stack([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]))
OPEN_OPENING = 0.08        # finger opening [m]: one finger under the lip, the other in front of the box
FINGER_WIDTH = 0.018       # a finger's extent across the opening direction [m]
OPEN_TIP_Y = -0.11         # fingertip along the lip [m] (the box spans y -0.15..0.15)
OPEN_FINGER_X = -0.1125    # the finger's centre under the lip [m] (the lip spans x -0.125..-0.100)
OPEN_CLEARANCE = 0.004     # the finger slides in this far below the lid's underside [m]
OPEN_PUSH = 0.002          # then presses this far into it as it lifts [m]
OPEN_TURN_TIME = 3.0      # the move from home, turning the hand 120 degrees [s]
OPEN_SWEEP_END = 1.75      # the lid is carried to this angle [rad], past its tipping angle (1.48)
# Close: the hand's lean toward the robot per radian the lid is below 1.4 rad (up to 0.8).
CLOSE_LEAN = 0.8
CLOSE_START = 1.9       # the lid resting on its stay [rad]
CLOSE_RELEASE = 1.64    # the flick stops here [rad], short of the 1.48 rad tipping angle: the lid's momentum carries it over
CLOSE_BEHIND = 0.03     # the approach starts this far behind the lid's face [m]
CLOSE_PUSH = 0.004      # the fingertip path runs this far inside the face [m]
CLOSE_APPROACH = 0.10   # the hand comes down to the lid from this far above [m]
CLOSE_PULL_TIME = 0.2   # the flick's duration, from the stay to CLOSE_RELEASE [s] (0.35 rad in 0.2 s)
CLOSE_RADIUS = 0.19     # the fingertip pulls the lid this far from the hinge [m] (the lid is 0.225 m long)
# Draw: the fingertip's centre between the drawer front (x = -0.16) and the
# handle bar (x = -0.205, radius 8 mm, centre 0.14 m up), 7 mm below the bar.
DRAW_TILT = np.deg2rad(20.0)
DRAW_TIP_X = -0.176
DRAW_TIP_Z = 0.125
DRAW_TRAVEL = 0.16


def _arc(theta, radius):
    """Point on the lid at ``radius`` from the hinge, lid angle theta (x, z in O)."""
    return LID_HINGE_XZ + radius * np.array([-np.cos(theta), np.sin(theta)])


def _xyz(xz):
    return np.array([xz[0], 0.0, xz[1]])


# How far each motion carries the object, at follow_through 0 (the least that
# still succeeds) and 1 (the scripted motion): the lid's angle at the end of the
# Open sweep [rad], the lid's angle where Close's flick stops [rad], the drawer's
# travel [m].
FOLLOW_THROUGH = {"open": (1.58, OPEN_SWEEP_END), "close": (1.68, CLOSE_RELEASE), "draw": (0.12, DRAW_TRAVEL)}


def keyframes(skill: str, follow_through: float = 1.0) -> list[tuple[float, np.ndarray, RotationMatrix, float]]:
    """Keyframes (time [s], p_OE [m], R_OE, finger opening [m]) after a move from home.

    ``follow_through`` in [0, 1] sets how far the motion carries the object
    (``FOLLOW_THROUGH``: 1 is the scripted motion, 0 the least that still
    succeeds: just past the tipping angle or the travel threshold; for
    Close's flick, the earliest stop from which the lid's momentum still
    carries it over), as a person stops pushing once the object looks done.
    """
    if not 0.0 <= follow_through <= 1.0:
        raise ValueError(f"follow_through: expected a fraction in [0, 1], got {follow_through!r}")
    if skill in FOLLOW_THROUGH:
        lo, hi = FOLLOW_THROUGH[skill]
        carry = lo + follow_through * (hi - lo)
    frames = []
    if skill == "open":
        # The hand points along +y_O, level, fingers open and spread along x_O,
        # and slides one finger in from the box's side under the lip (the
        # finger's flat top face under the lid's underside; the other finger
        # passes in front of the box). The hand then turns rigidly with the lid
        # about the hinge axis (a roll of the hand about its own axis, joint 7)
        # until the lid is past its tipping angle, and leaves sideways.
        R0 = OPEN_R_OE
        hinge = _xyz(LID_HINGE_XZ)
        # Finger under the lip: across x -0.1215..-0.1035 (the lip spans
        # -0.125..-0.100), its tip OPEN_TIP_Y along the lip from the box's side.
        tcp_in = np.array([OPEN_FINGER_X - (OPEN_OPENING / 2 + FINGER_WIDTH / 2), OPEN_TIP_Y - TCP_TO_TIP,
                           0.13 - FINGER_HALF_THICKNESS - OPEN_CLEARANCE])
        tcp_touch = tcp_in + [0.0, 0.0, OPEN_CLEARANCE + OPEN_PUSH]
        out = [0.0, -0.09, 0.0]
        w = OPEN_OPENING
        # Turn the hand high beside the box, then down and in.
        # The turn takes OPEN_TURN_TIME: turned faster, the arm swings through
        # the shoulder singularity and the measured path (which the DMP
        # imitates) loops far from the commanded one.
        t0 = OPEN_TURN_TIME
        frames += [(t0, tcp_in + out + [0.0, 0.0, 0.20], R0, w),
                   (t0 + 1.0, tcp_in + out + [0.0, 0.0, 0.06], R0, w),
                   (t0 + 1.7, tcp_in + out, R0, w),
                   (t0 + 2.5, tcp_in, R0, w),
                   (t0 + 3.0, tcp_in, R0, w)]      # a pause, as a person makes before lifting
        for i, theta in enumerate(np.linspace(0.0, carry, 9)):
            R_lid = RotationMatrix.MakeYRotation(theta)
            frames.append((t0 + 3.5 + 0.5 * i, hinge + R_lid @ (tcp_touch - hinge), R_lid @ R0, w))
        last_p, last_R = frames[-1][1], frames[-1][2]
        frames += [(t0 + 8.5, last_p + out, last_R, w),
                   (t0 + 9.5, last_p + out + [-0.05, 0.0, 0.08], last_R, w)]
    elif skill == "close":
        radius, push = CLOSE_RADIUS, CLOSE_PUSH
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
        frames += [(2.5, start + [0.0, 0.0, CLOSE_APPROACH], hand(theta0), 0.0),
                   (3.5, start, hand(theta0), 0.0),
                   (4.0, start, hand(theta0), 0.0)]
        # Flick the lid off its stay: pull briskly and stop short of its
        # tipping angle; its momentum carries it over and its weight shuts it
        # (the hand must not chase and press it). The hand then holds still.
        for i, theta in enumerate(np.linspace(theta0, carry, 5)[1:]):
            frames.append((4.0 + CLOSE_PULL_TIME * (i + 1) / 4, tcp(theta), hand(theta), 0.0))
        frames.append((6.0, tcp(carry), hand(carry), 0.0))
        last = frames[-1][1]
        # Up, out of the falling lid's way, and toward the hinge.
        frames += [(6.5, last + [0.0, 0.0, 0.08], hand(carry), 0.0),
                   (7.5, last + [0.06, 0.0, 0.14], hand(carry), 0.0)]
    elif skill == "draw":
        # Tilted so the fingertips lead toward the drawer front and the hand
        # housing trails toward the robot, clear of the cabinet's top edge
        # (pointing straight down, the housing lands on the cabinet before the
        # fingers are below the handle).
        R = RotationMatrix.MakeYRotation(-DRAW_TILT) @ R_OE_DOWN
        z_E = R.col(2)
        tip = np.array([DRAW_TIP_X, 0.0, DRAW_TIP_Z])
        tcp = tip - TCP_TO_TIP * z_E
        out = tcp - [carry, 0.0, 0.0]
        frames += [(2.5, tcp + [0.0, 0.0, 0.16], R, 0.0),
                   (3.5, tcp, R, 0.0),
                   (4.0, tcp, R, 0.0),
                   (7.0, out, R, 0.0),
                   # lift clear of the handle (never pushing the drawer back), then
                   # away from the robot's base, where the arm can settle
                   (7.8, out + [0.0, 0.0, 0.05], R, 0.0),
                   (8.8, out + [0.10, 0.0, 0.16], R, 0.0)]
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
