#!/usr/bin/env python3
"""Greedy success of a fitted skill's initial DMP (plain imitation) over held-out object poses.

    python tools/imitation_success.py SKILL_DIR [--all-demos] [--poses 10] [--seed0 900000]
                                      [--ground-truth-pose] [--workers 1] [--json]

A thin wrapper over ``drake-skill evaluate`` (``drake_skill.learning.loop.evaluate_skill``)
with the settings issue 10's imitation figures are reported in: the
skill's initial policy (``--all-demos``: every demonstration's DMP, each
with its own goal and duration) on the 10 held-out object poses that
``drake-skill learn`` reports (seeds 900000, 900001, ...), the object frame
from the segmenter's estimate on the camera's first frame (or the ground
truth with ``--ground-truth-pose``), judged from the simulator's ground
truth. Writes ``imitation.json`` into SKILL_DIR. Equivalent to::

    drake-skill evaluate --skill SKILL_DIR [--all-demos] --out SKILL_DIR/imitation.json
"""

import argparse
import sys
from pathlib import Path


def main(argv=None) -> int:
    from drake_skill.learning.loop import HELD_OUT_SEED0

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("skill_dir", type=Path, help="a fitted skill folder (drake-skill fit)")
    parser.add_argument("--all-demos", action="store_true", help="every demonstration's DMP, not only the initial one")
    parser.add_argument("--poses", type=int, default=10, help="held-out object poses (default 10)")
    parser.add_argument("--seed0", type=int, default=HELD_OUT_SEED0,
                        help=f"seed of the first pose (default {HELD_OUT_SEED0}, as drake-skill learn)")
    parser.add_argument("--ground-truth-pose", action="store_true",
                        help="the object frame from the simulator, not from the segmenter")
    parser.add_argument("--perceived", action="store_true", help=argparse.SUPPRESS)   # accepted from older scripts: now the default
    parser.add_argument("--workers", type=int, default=1, help="rollout worker processes")
    parser.add_argument("--json", action="store_true", help="print the report as JSON instead of the table")
    args = parser.parse_args(argv)
    if args.perceived and args.ground_truth_pose:
        parser.error("--perceived and --ground-truth-pose contradict each other (the perceived frame is the default)")

    from drake_skill.cli.main import command_main

    argv = ["--skill", str(args.skill_dir), "--poses", str(args.poses), "--seed0", str(args.seed0),
            "--workers", str(args.workers), "--out", str(args.skill_dir / "imitation.json")]
    for flag in ("ground_truth_pose", "all_demos", "json"):
        if getattr(args, flag):
            argv.append("--" + flag.replace("_", "-"))
    return command_main("evaluate", argv)


if __name__ == "__main__":
    sys.exit(main())
