#!/usr/bin/env python3
"""Greedy success of a fitted skill's initial DMP (plain imitation) over randomised object poses.

    python tools/imitation_success.py SKILL_DIR [--poses 20] [--seed0 1000] [--perceived] [--all-demos]

A thin wrapper over ``drake-skill evaluate`` (``drake_skill.learning.loop.evaluate_skill``):
executes the skill's initial policy (``--all-demos``: each demonstration's
DMP) on ``--poses`` object poses from seeds ``seed0, seed0 + 1, ...``, judged
from the simulator's ground truth. The object frame is the ground truth, or
with ``--perceived`` the segmenter's estimate on the camera's first frame.
Writes ``imitation.json`` into SKILL_DIR. Equivalent to::

    drake-skill evaluate --skill SKILL_DIR --poses 20 --seed0 1000 --ground-truth-pose --out SKILL_DIR/imitation.json
"""

import argparse
import sys
from pathlib import Path


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("skill_dir", type=Path)
    parser.add_argument("--poses", type=int, default=20)
    parser.add_argument("--seed0", type=int, default=1000)
    parser.add_argument("--perceived", action="store_true")
    parser.add_argument("--all-demos", action="store_true")
    parser.add_argument("--workers", type=int, default=1)
    args = parser.parse_args(argv)

    from drake_skill.cli.main import command_main

    argv = ["--skill", str(args.skill_dir), "--poses", str(args.poses), "--seed0", str(args.seed0),
            "--workers", str(args.workers), "--out", str(args.skill_dir / "imitation.json")]
    if not args.perceived:
        argv.append("--ground-truth-pose")
    if args.all_demos:
        argv.append("--all-demos")
    return command_main("evaluate", argv)


if __name__ == "__main__":
    sys.exit(main())
