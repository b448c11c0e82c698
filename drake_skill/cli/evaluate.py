"""``drake-skill evaluate``: greedy success of a skill over held-out object poses.

    drake-skill evaluate --skill-dir DIR [--poses 10] [--seed0 900000] [--workers N]
                         [--ground-truth-pose] [--all-demos | --explore N] [--out FILE] [--json]

Executes the skill's policy without exploration (a fitted skill's initial
DMP, i.e. plain imitation; a skill written by ``drake-skill learn``, the
learned DMP; with ``--all-demos`` every demonstration's DMP, each with its
own goal and duration) on ``--poses`` object poses drawn from the seeds
``seed0, seed0 + 1, ...`` (the held-out poses ``drake-skill learn``
reports, none a demonstration's) and judges each from the simulator's
ground truth (docs/method.md section 5). The object frame comes from the
segmenter's estimate on the camera's first frame, or from the ground truth
with ``--ground-truth-pose``.

Prints a table (success rate, the goal model's verdicts, mean learned
return, final lid angle / drawer travel, failures) and writes the report as
JSON to ``--out`` (default ``DIR/evaluation.json``; per rollout its seed,
object placement, outcome and failure reason); ``--json`` prints that JSON
object instead of the table. Beside it, the same name with ``.png``: where
on the table each policy succeeded and failed (one panel per DMP), which
shows the band of object placements a plain imitation succeeds in. In the
report's folder, ``rollouts/evaluation_dmp_I.npz`` keeps each rollout's
weights, seed, path and last camera frame (a failed one's frames up to its
stop): ``drake-skill replay FOLDER --evaluation I --index C`` replays one.

With ``--explore N`` it runs instead the N exploratory rollouts policy
search's first episode would run (weights sampled from N(W_0, Sigma_b^0),
seeded by --seed0, one pose each) and reports the spread of their learned
returns, their successes and final object states (default out
``DIR/exploration.json``, and ``exploration.png``): whether the learned
reward gives policy search something to climb (rollouts kept in
``rollouts/exploration.npz``; ``drake-skill replay FOLDER --exploration --index C``).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from drake_skill.cli import options

NAME = "evaluate"
HELP = "greedy success of a skill over held-out object poses (table + JSON)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from drake_skill.learning.workers import default_workers

    from drake_skill.learning.evaluation import HELD_OUT_SEED0
    from drake_skill.learning.loop import exploration_scales_text

    parser.description = __doc__
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    parser.add_argument("--skill-dir", type=Path, required=True,
                        help="a fitted skill's folder (drake-skill fit / learn)")
    parser.add_argument("--poses", type=int, default=10, help="held-out object poses (default 10)")
    parser.add_argument("--seed0", type=int, default=HELD_OUT_SEED0,
                        help=f"seed of the first pose (default {HELD_OUT_SEED0}, as drake-skill learn)")
    parser.add_argument("--workers", type=int, default=None,
                        help="rollout worker processes (default: one per CPU this process may use, "
                             f"{default_workers()} here)")
    parser.add_argument("--ray-address", default=None, type=options.ray_address,
                        help="run on Ray actors of this cluster")
    options.add_ground_truth_pose(parser)
    parser.add_argument("--all-demos", action="store_true",
                        help="evaluate every demonstration's DMP (its weights, goal and duration): "
                             "plain imitation of each demonstration")
    parser.add_argument("--explore", type=int, default=0, metavar="N",
                        help="instead: N exploratory rollouts sampled from the skill's Sigma_0 (policy "
                             "search's first episode); reports the spread of their learned returns")
    parser.add_argument("--exploration-scale", type=float, default=None, metavar="S",
                        help=f"with --explore: sample from S x Sigma_0 (default: the skill's, as "
                             f"drake-skill learn: {exploration_scales_text()})")
    parser.add_argument("--approach-exploration", type=float, default=1.0, metavar="F",
                        help="with --explore: Sigma_0 x F on the bases before the demonstrations' first contact, "
                             "as drake-skill learn (default 1: off; docs/method.md 5.4)")
    options.add_scenario(parser, "--station-config", what="the skill's scenario")
    parser.add_argument("--out", type=Path, default=None,
                        help="JSON report (default SKILL/evaluation.json); the placement plot goes beside it "
                             "with the suffix .png")
    parser.add_argument("--json", action="store_true", help="print the JSON report instead of the table")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    from drake_skill.fileio import atomic_write_json
    from drake_skill.learning.evaluation import evaluate_skill, evaluation_table
    from drake_skill.learning.plots import plot_outcomes_by_placement
    from drake_skill.fitted_skill import Skill
    from drake_skill.inputs import scenario

    if args.poses < 1:
        raise ValueError(f"--poses must be at least 1, got {args.poses}")
    if args.workers is None:
        from drake_skill.learning.workers import default_workers

        args.workers = default_workers()
    if args.workers < 1:
        raise ValueError(f"--workers must be at least 1, got {args.workers}")
    if not args.skill_dir.is_dir():
        raise NotADirectoryError(f"--skill-dir {args.skill_dir}: not a folder; give a skill folder "
                                 "(drake-skill fit --out / drake-skill learn --out .../skill)")
    if args.explore < 0:
        raise ValueError(f"--explore must be a number of rollouts >= 1, got {args.explore}")
    station = scenario(Skill.load(args.skill_dir).station_config(), args.station_config, args.scenario_text)
    rollout_config = options.rollout_config(args)
    if args.explore:
        from drake_skill.learning.evaluation import exploration_table, explore_skill

        report = explore_skill(args.skill_dir, rollouts=args.explore, seed0=args.seed0, station_config=station,
                               rollout_config=rollout_config, workers=args.workers,
                               ray_address=args.ray_address, progress=not (args.quiet or args.json),
                               exploration_scale=args.exploration_scale, keep=_keep_dir(args, "exploration.json"),
                               approach_exploration=args.approach_exploration)
        out = args.out if args.out is not None else args.skill_dir / "exploration.json"
        atomic_write_json(out, report)
        plot = plot_outcomes_by_placement(report, _plot_path(out))
        print(json.dumps(report, sort_keys=True) if args.json else exploration_table(report))
        if not args.json:
            print(f"wrote {out} and {plot}")
        return 0
    report = evaluate_skill(
        args.skill_dir, poses=args.poses, seed0=args.seed0, station_config=station,
        rollout_config=rollout_config, workers=args.workers, ray_address=args.ray_address, all_demos=args.all_demos,
        progress=not (args.quiet or args.json), keep=_keep_dir(args, "evaluation.json"))
    out = args.out if args.out is not None else args.skill_dir / "evaluation.json"
    atomic_write_json(out, report)
    plot = plot_outcomes_by_placement(report, _plot_path(out))
    if args.json:
        print(json.dumps(report, sort_keys=True))
    else:
        print(evaluation_table(report))
        print(f"wrote {out} and {plot}")
    return 0


def _keep_dir(args, default_name: str) -> Path:
    """The folder of the JSON report (``--out`` or the skill's): its ``rollouts/`` keeps the rollouts
    (``drake-skill replay FOLDER --evaluation I --index C`` shows one)."""
    return (args.out if args.out is not None else args.skill_dir / default_name).parent


def _plot_path(out: Path) -> Path:
    """The placement plot's path beside the JSON report ``out`` (never ``out`` itself)."""
    return out.with_suffix(".png") if out.suffix != ".png" else out.with_name(out.name + ".png")


def main(argv=None) -> int:
    """``drake-skill evaluate ARGV...`` (scripts and tests): errors as one line, exit status 2."""
    from drake_skill.cli.main import command_main

    return command_main(NAME, argv)
