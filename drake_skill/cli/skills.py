"""``drake-skill skills``: the shipped skills, or what a skill file defines.

    drake-skill skills                 # a table of the shipped skills
    drake-skill skills FILE_OR_NAME    # one skill file, checked, with its fields
    drake-skill skills FILE_OR_NAME --check-camera [--json]
                                       # does the segment hold the whole object?

``--check-camera`` renders the skill's scenario in simulation with the object's
joint at ``--joints`` values across its limits on ``--poses`` seeded object
poses, and reports the least fraction of the object's visible pixels (the
renderer's label image) that the segment keeps, and where
(drake_skill/skills/camera_check.py). Run it before recording. ``--json``:
``{"skill", "kept_fraction_min", "at_joint", "at_pose": [x, y, yaw], "frames"}``.

A skill is data (docs/skills.md): a YAML file naming its scenario, how many
demonstrations, DMP bases (and columns left unscaled), exploration scale,
which demonstration policy search starts from, gripper opening, success rule
and, optionally, the keyframes the scripted demonstrator plays. Every command
that takes ``--skill`` takes a shipped skill's name or such a file's path.
"""

from __future__ import annotations

import argparse
import json

from drake_skill.cli import options

NAME = "skills"
HELP = "list the shipped skills, or check and show a skill file"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.description = __doc__
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    parser.add_argument("skill", nargs="?", default=None, metavar="SKILL",
                        help="a shipped skill's name or a skill file to check and show (default: list all)")
    parser.add_argument("--check-camera", action="store_true",
                        help="check that the segment keeps the whole object at every joint position")
    parser.add_argument("--json", action="store_true", help="with --check-camera: print one JSON object")
    parser.add_argument("--joints", type=int, default=7, metavar="N",
                        help="with --check-camera: joint positions across the joint's limits (default 7)")
    parser.add_argument("--poses", type=int, default=3, metavar="N",
                        help="with --check-camera: seeded object poses (default 3)")
    parser.add_argument("--seed", type=int, default=0, help="with --check-camera: seed of the first pose")
    options.add_scenario(parser, what="the skill's scenario (with --check-camera)", dest="scenario")


def table(specs) -> str:
    """One row per skill: name, scenario, demonstrations, bases, exploration, the start's rule,
    success rule, keyframes."""
    from drake_skill.station.success import rule_text

    rows = [("skill", "scenario", "demos", "bases", "explore", "start", "success", "keyframes")]
    for s in specs:
        bases = "auto" if s.dmp_bases is None else str(s.dmp_bases)
        rows.append((s.name, s.scenario_path().stem, str(s.demonstrations), bases,
                     f"{s.exploration_scale:g}", s.initial_dmp,
                     rule_text(s.success) + f" after {s.success.settle_time:g} s",
                     str(len(s.keyframes)) if s.keyframes else "- (teleoperate)"))
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    return "\n".join("  ".join(v.ljust(w) for v, w in zip(r, widths)).rstrip() for r in rows)


def run(args: argparse.Namespace) -> int:
    from drake_skill.cli import errors
    from drake_skill.skills import shipped_skills

    if args.check_camera:
        return check_camera(args)
    if args.json:
        raise ValueError("--json: only with --check-camera")
    if args.skill is None:
        specs = shipped_skills()
        print(table(specs))
        for s in specs:
            print(f"  {s.name}: {s.description}")
        return 0
    spec = errors.skill(args.skill, "SKILL")
    print(table([spec]))
    print(f"  {spec.name}: {spec.description}\n  scenario file: {spec.scenario_path()}")
    return 0


def check_camera(args: argparse.Namespace) -> int:
    """``--check-camera``: the table, or one JSON object with ``--json``."""
    from drake_skill.cli import errors
    from drake_skill.skills import camera_check

    if args.skill is None:
        raise ValueError("--check-camera: give a skill (a shipped skill's name or a skill file)")
    if args.joints < 1 or args.poses < 1:
        raise ValueError(f"--joints {args.joints} / --poses {args.poses}: expected at least 1 each")
    spec = errors.skill(args.skill, "SKILL")
    config = errors.scenario(spec, args.scenario, args.scenario_text)
    result = camera_check.check_camera(config, spec.name, args.joints, args.poses, args.seed)
    print(json.dumps(result.summary()) if args.json else camera_check.table(result))
    return 0


def main(argv=None) -> int:
    """``drake-skill skills ARGV...`` (scripts and tests)."""
    from drake_skill.cli.main import command_main
    return command_main(NAME, argv)
