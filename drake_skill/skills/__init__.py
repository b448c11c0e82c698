"""Skills as data: a skill file names everything that makes a skill (docs/skills.md).

A skill is whatever its demonstrations show (thesis chapter 3); what the
library needs to know about it beyond them is data, in a YAML file loaded
with ``yaml_load_typed`` into :class:`SkillSpec`::

    name: open                          # what commands and results call it
    scenario: open                      # a shipped scenario, or a YAML path relative to this file
    demonstrations: 3                   # the thesis's count (section 6.2)
    # dmp_bases: 20                     # optional: fixes B; left out, fit chooses it (docs/method.md 2.2)
    exploration_scale: 0.1              # sigma_0 of thesis Eq. 5.3 (docs/method.md section 5)
    success: {joint: lid_hinge, above: 1.7, settle_time: 1.0}
    keyframes:                          # optional: the scripted demonstrator's motion
      - {t: 3.0, gripper: 0.08, pose: {translation: [...], rotation: !Rpy {deg: [...]}}}

The shipped skills (Open, Close and Draw of the thesis) are files in this
folder; :func:`load_skill` takes a shipped skill's name or a path to a
user's file, and every command that takes ``--skill`` goes through it.
"""

from __future__ import annotations

from drake_skill.skills.spec import (Keyframe, SkillSpec, keyframes, load_skill, scenario_for_skill,
                                     shipped_skill_names, shipped_skills)

__all__ = ["Keyframe", "SkillSpec", "keyframes", "load_skill", "scenario_for_skill", "shipped_skill_names",
           "shipped_skills"]
