"""``drake-skill skills``: the shipped skills, or what a skill file defines.

    drake-skill skills                 # a table of the shipped skills
    drake-skill skills FILE_OR_NAME    # one skill file, checked, with its fields

A skill is data (docs/skills.md): a YAML file naming its scenario, how many
demonstrations, DMP bases (and columns left unscaled), exploration scale,
which demonstration policy search starts from, gripper opening, success rule
and, optionally, the keyframes the scripted demonstrator plays. Every command
that takes ``--skill`` takes a shipped skill's name or such a file's path.
"""

from __future__ import annotations

import argparse

NAME = "skills"
HELP = "list the shipped skills, or check and show a skill file"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.description = __doc__
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    parser.add_argument("skill", nargs="?", default=None, metavar="SKILL",
                        help="a shipped skill's name or a skill file to check and show (default: list all)")


def table(specs) -> str:
    """One row per skill: name, scenario, demonstrations, bases, exploration, the start's rule,
    success rule, keyframes."""
    from drake_skill.station.success import rule_text

    rows = [("skill", "scenario", "demos", "bases", "explore", "start", "success", "keyframes")]
    for s in specs:
        rows.append((s.name, s.scenario_path().stem, str(s.demonstrations), str(s.dmp_bases),
                     f"{s.exploration_scale:g}", s.initial_dmp,
                     rule_text(s.success) + f" after {s.success.settle_time:g} s",
                     str(len(s.keyframes)) if s.keyframes else "- (teleoperate)"))
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    return "\n".join("  ".join(v.ljust(w) for v, w in zip(r, widths)).rstrip() for r in rows)


def run(args: argparse.Namespace) -> int:
    from drake_skill.cli import errors
    from drake_skill.skills import shipped_skills

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


def main(argv=None) -> int:
    """``drake-skill skills ARGV...`` (scripts and tests)."""
    from drake_skill.cli.main import command_main
    return command_main(NAME, argv)
