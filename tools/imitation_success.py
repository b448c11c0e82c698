#!/usr/bin/env python3
"""Greedy success of a fitted skill's initial DMP (plain imitation) over randomised object poses.

    python tools/imitation_success.py SKILL_DIR [--poses 20] [--seed0 1000] [--perceived] [--all-demos]

Executes the skill's initial policy (the DMP of the demonstration chosen by
the skill's seed; ``--all-demos``: each demonstration's DMP) in the simulated
station on ``--poses`` object poses drawn from seeds ``seed0, seed0 + 1, ...``
(none of them a demonstration's), judges each from the simulator's ground
truth and prints the success rate. The object frame comes from the
simulator's ground truth, or with ``--perceived`` from the segmenter's estimate
on the camera's first frame (slower: the camera renders every frame).
Writes ``imitation.json`` into SKILL_DIR.
"""

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("skill_dir", type=Path)
    parser.add_argument("--poses", type=int, default=20)
    parser.add_argument("--seed0", type=int, default=1000)
    parser.add_argument("--perceived", action="store_true")
    parser.add_argument("--all-demos", action="store_true")
    args = parser.parse_args(argv)

    from tqdm import tqdm

    from drake_skill.fileio import atomic_write_json
    from drake_skill.learning.rollout import RolloutRunner
    from drake_skill.skill import Skill
    from drake_skill.station.config import scenario_for_skill

    skill = Skill.load(args.skill_dir)
    config = scenario_for_skill(skill.name)
    config.enable_camera = args.perceived
    runner = RolloutRunner(config, skill.initial_dmp, skill.config.dmp, skill=skill.name,
                           object_pose="perceived" if args.perceived else "ground_truth")
    indices = range(len(skill.dmps)) if args.all_demos else [skill.initial_index]
    report = {"skill": skill.name, "object_pose": "perceived" if args.perceived else "ground_truth",
              "seeds": [args.seed0 + i for i in range(args.poses)], "policies": {}}
    start = time.perf_counter()
    for index in indices:
        finals, successes = [], []
        for seed in tqdm(report["seeds"], desc=f"DMP of demonstration {index}", unit="rollout"):
            result = runner.run(skill.dmps[index].weights, seed)
            finals.append(result.final_object_state)
            successes.append(result.success)
        report["policies"][str(index)] = {"success_rate": float(np.mean(successes)),
                                          "final_object_state": finals,
                                          "initial": index == skill.initial_index}
        print(f"demonstration {index}{' (initial policy)' if index == skill.initial_index else ''}: "
              f"success {np.mean(successes) * 100:.0f} % over {args.poses} poses; final object state "
              f"median {np.median(finals):.2f}, range {min(finals):.2f}..{max(finals):.2f}")
    report["wall_s"] = round(time.perf_counter() - start, 1)
    atomic_write_json(args.skill_dir / "imitation.json", report)
    print(f"wrote {args.skill_dir / 'imitation.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
