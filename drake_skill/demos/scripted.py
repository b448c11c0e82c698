"""The scripted demonstrator's hand motion: a skill file's keyframes mapped to the world.

A skill file's ``keyframes`` (:class:`drake_skill.skills.Keyframe`) give the
hand's TCP frame E in the object frame O (docs/skills.md: O's origin at the
centre of the object's bottom face, x away from the robot, z up), after a
move from home. ``scripted_plan`` maps them to the world with X_WO and
optionally perturbs timing and path (seeded), as a human demonstrator would;
``drake_skill.demos.demonstrator.humanlike_plan`` adds the rest of a person's
variation. The shipped skills' motions keep the robot-scene contact force well
below the collision reflex (``drake_skill.station.limits``), as
``tools/check_physics.py`` checks.
"""

from __future__ import annotations

import numpy as np
from pydrake.math import RigidTransform

from drake_skill.station.pose_source import PosePlan


def scripted_plan(skill, X_WO: RigidTransform, X_WE_home: RigidTransform,
                  rng: np.random.Generator | None = None, time_scale_range: float = 0.0,
                  path_noise: float = 0.0) -> PosePlan:
    """The keyframes of ``skill`` (a name, a skill file or a SkillSpec) mapped to the
    world by X_WO, starting from the home pose.

    With ``rng``: every segment's duration is scaled by a factor drawn from
    [1 - time_scale_range, 1 + time_scale_range] and every via point is moved
    by Gaussian noise of standard deviation ``path_noise`` [m].
    """
    from drake_skill.skills import keyframes, load_skill

    spec = load_skill(skill)
    frames = keyframes(spec)
    if not frames:
        raise ValueError(f"skill {spec.name!r} has no keyframes to script; record its demonstrations by "
                         "teleoperation (drake-skill demos record --interactive) "
                         "or on the robot (drake-skill hardware record-demo)")
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
