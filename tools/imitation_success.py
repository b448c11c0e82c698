#!/usr/bin/env python3
"""Greedy success of a fitted skill's initial DMP (plain imitation) over held-out object poses.

    python tools/imitation_success.py SKILL_DIR [--all-demos] [--poses 10] [--seed0 900000]
                                      [--ground-truth-pose] [--workers 1] [--json] [...]

``drake-skill evaluate --skill-dir SKILL_DIR --out SKILL_DIR/imitation.json``
under the name issue 10 gives it: every option after SKILL_DIR is
evaluate's, with evaluate's defaults, which are the settings the
imitation figures are reported in (the skill's initial policy, or with
``--all-demos`` every demonstration's DMP with its own goal and duration,
on the 10 held-out object poses ``drake-skill learn`` reports, the object
frame from the segmenter's estimate on the camera's first frame, judged
from the simulator's ground truth). Beside the JSON, ``imitation.png``
shows where on the table each DMP succeeded. ``drake-skill evaluate
--help`` lists the options.
"""

import argparse
import sys
from pathlib import Path


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter,
                                     allow_abbrev=False,
                                     epilog="Every other option is drake-skill evaluate's "
                                            "(drake-skill evaluate --help).")
    parser.add_argument("skill_dir", type=Path, help="a fitted skill folder (drake-skill fit)")
    parser.add_argument("--perceived", action="store_true", help=argparse.SUPPRESS)   # older scripts: now the default
    args, rest = parser.parse_known_args(argv)
    if args.perceived and "--ground-truth-pose" in rest:
        parser.error("--perceived and --ground-truth-pose contradict each other (the perceived frame is the default)")
    if not any(a == "--out" or a.startswith("--out=") for a in rest):
        rest += ["--out", str(args.skill_dir / "imitation.json")]

    from drake_skill.cli.main import command_main

    return command_main("evaluate", ["--skill-dir", str(args.skill_dir), *rest])


if __name__ == "__main__":
    sys.exit(main())
