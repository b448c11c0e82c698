"""How well a skill's learned reward tracks ground-truth success, measured in simulation.

``drake-skill bench reward_quality --skill NAME|FILE | --skill-dir DIR [--rollouts 30]
[--demo-poses 2] [--seed0 900000] [--workers N] [--out DIR] [--ground-truth-pose] [--json]``

Runs, on the simulated station:

- ``--rollouts`` exploratory rollouts around the skill's initial DMP at its
  exploration scale: what policy search's first episode sees (weights
  W ~ N(W_0, sigma_0 Sigma_b^0), thesis Eq. 5.3; object poses of seeds
  seed0, seed0 + 1, ...; ``drake-skill evaluate --explore``);
- every demonstration's DMP imitated (its weights, goal and duration) on
  ``--demo-poses`` object poses each (seeds after the exploratory ones;
  ``drake-skill evaluate --all-demos``; 0: none),

and reports over all of them (drake_skill.learning.reward_quality):

  reward_auc         ROC AUC of the dense return R(G) for ground-truth success,
                     over the rollouts that did not fail (1: every success
                     ranked above every failure; None: one class only)
  verdict_fpr        share of ground-truth failures the goal model's verdict
                     calls a success; verdict_fnr: of successes called a failure
  state_spearman     Spearman rho of R(G) and the final object state, signed
                     toward the rule (x -1 for a 'below' rule): > 0 when the
                     return grows as the object ends nearer success
  rollouts, scored, failed, failed_rate, failures (by reason),
  successes (ground truth), verdict_successes

and the same per source (``by_source``: exploration, imitation), per rollout
its record (``records``), the settings and ``wall_s``. Writes
``reward_quality.json`` (that object) and ``return_vs_state.png`` (the return
against the final object state; colour = ground truth, filled = verdict
success, crosses = failed rollouts) into ``--out`` (default: the skill
folder with --skill-dir; results/reward_quality/NAME with --skill).

With ``--skill`` the skill's scripted demonstrations are recorded into
OUT/demos and fitted into OUT/initial_skill first, as
``drake-skill learn --skill`` does (a fit already there is used again).
Prints a short table, or the JSON object with ``--json``.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
import time
from pathlib import Path

DEFAULT_OUT = Path("results") / "reward_quality"


def _parser() -> argparse.ArgumentParser:
    from drake_skill.learning.config import HELD_OUT_SEED0

    parser = argparse.ArgumentParser(prog="drake-skill bench reward_quality", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--skill", metavar="NAME|FILE",
                        help="a shipped skill's name or a skill file: record and fit its scripted demonstrations")
    parser.add_argument("--skill-dir", type=Path, metavar="DIR", help="a fitted skill's folder (drake-skill fit)")
    parser.add_argument("--rollouts", type=int, default=30, help="exploratory rollouts (default 30)")
    parser.add_argument("--demo-poses", type=int, default=2,
                        help="object poses each demonstration's DMP is imitated on (default 2; 0: none)")
    parser.add_argument("--seed0", type=int, default=HELD_OUT_SEED0,
                        help=f"exploration seed and first object-pose seed (default {HELD_OUT_SEED0})")
    parser.add_argument("--exploration-scale", type=float, default=None, metavar="S",
                        help="explore with S x Sigma_0 (default: the skill's, as drake-skill learn)")
    parser.add_argument("--workers", type=int, default=None, help="rollout worker processes (default: one per CPU)")
    parser.add_argument("--out", type=Path, default=None,
                        help="folder for reward_quality.json and return_vs_state.png (default: the skill "
                             "folder with --skill-dir, results/reward_quality/NAME with --skill)")
    parser.add_argument("--ground-truth-pose", action="store_true",
                        help="object frame from the simulator's ground truth instead of the camera's segmenter")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")
    return parser


def _check(args) -> None:
    """One-line errors for options that cannot work, before any simulation."""
    from drake_skill import inputs

    if (args.skill is None) == (args.skill_dir is None):
        raise ValueError("--skill / --skill-dir: give exactly one (a skill name or file to record and fit, "
                         "or a fitted skill's folder)")
    if args.rollouts < 1:
        raise ValueError(f"--rollouts must be at least 1, got {args.rollouts}")
    if args.demo_poses < 0:
        raise ValueError(f"--demo-poses must be 0 (no imitations) or a number of poses, got {args.demo_poses}")
    if args.workers is not None and args.workers < 1:
        raise ValueError(f"--workers must be at least 1, got {args.workers}")
    if args.skill_dir is not None:
        inputs.input_folder(args.skill_dir, "--skill-dir", "a fitted skill (drake-skill fit --out / learn --out)")
        inputs.input_file(args.skill_dir / "skill.json", "--skill-dir",
                          "a fitted skill's folder, which holds skill.json (drake-skill fit --out)")
    else:
        inputs.skill(args.skill)
    if args.out is not None:
        inputs.output_folder(args.out, "--out", what="reward_quality.json and return_vs_state.png")


def _skill_dir(args) -> tuple[Path, Path]:
    """(fitted skill folder, output folder); with --skill, records and fits first."""
    from drake_skill import inputs
    from drake_skill.workflow.prepare import PrepareConfig, prepare_skill

    if args.skill_dir is not None:
        return args.skill_dir, args.out if args.out is not None else args.skill_dir
    out = args.out if args.out is not None else DEFAULT_OUT / inputs.skill(args.skill).name
    out.mkdir(parents=True, exist_ok=True)
    with contextlib.redirect_stdout(sys.stderr) if args.json else contextlib.nullcontext():
        skill_dir = prepare_skill(PrepareConfig(skill=args.skill, quiet=bool(args.quiet or args.json)), out)
    return skill_dir, out


def measure(skill_dir: Path, *, rollouts: int = 30, demo_poses: int = 2, seed0: int | None = None,
            exploration_scale: float | None = None, workers: int = 1, rollout_config=None,
            progress: bool = True) -> dict:
    """The benchmark's report (keys in the module docstring) for the fitted skill in ``skill_dir``."""
    from drake_skill.learning.config import HELD_OUT_SEED0
    from drake_skill.learning.evaluation import evaluate_skill, explore_skill
    from drake_skill.learning.reward_quality import records_from_report, reward_quality
    from drake_skill.fitted_skill import Skill

    seed0 = HELD_OUT_SEED0 if seed0 is None else int(seed0)
    skill = Skill.load(skill_dir)
    rule = skill.spec.success
    start = time.perf_counter()
    explored = explore_skill(skill_dir, rollouts=rollouts, seed0=seed0, workers=workers,
                             rollout_config=rollout_config, progress=progress,
                             exploration_scale=exploration_scale)
    records = records_from_report(explored, "exploration")
    imitations = []
    if demo_poses > 0:
        imitated = evaluate_skill(skill_dir, poses=demo_poses, seed0=seed0 + rollouts, workers=workers,
                                  rollout_config=rollout_config, all_demos=True, progress=progress)
        for index, policy in imitated["policies"].items():
            imitations += records_from_report(policy, f"demo {index}")
    by_source = {"exploration": reward_quality(records, rule)}
    if imitations:
        by_source["imitation"] = reward_quality(imitations, rule)
    records += imitations
    return {**reward_quality(records, rule), "skill": skill.name, "skill_dir": str(skill_dir),
            "rule": {"joint": rule.joint, "above": rule.above, "below": rule.below},
            "exploration_scale": explored["exploration_scale"], "exploration_rollouts": int(rollouts),
            "demonstrations": len(skill.dmps), "demo_poses": int(demo_poses), "seed0": seed0,
            "object_pose": explored["object_pose"], "by_source": by_source, "records": records,
            "wall_s": round(time.perf_counter() - start, 1)}


def _num(x, fmt: str) -> str:
    return "-" if x is None else format(x, fmt)


def _row(name: str, q: dict) -> str:
    return (f"{name:<12}{q['rollouts']:>9}{q['failed']:>8}{q['successes']:>10}{q['verdict_successes']:>9}"
            f"{_num(q['reward_auc'], '.3f'):>8}{_num(q['verdict_fpr'], '.2f'):>6}{_num(q['verdict_fnr'], '.2f'):>6}"
            f"{_num(q['state_spearman'], '+.2f'):>10}")


def table(report: dict) -> str:
    """The people's view of :func:`measure`'s report."""
    rule = report["rule"]
    side = f">= {rule['above']:g}" if rule["above"] is not None else f"<= {rule['below']:g}"
    failures = ", ".join(f"{k} {v}" for k, v in report["failures"].items()) or "none"
    rate = report["failed_rate"]
    return "\n".join([
        f"{report['skill']}: {report['exploration_rollouts']} exploratory rollouts "
        f"({report['exploration_scale']:g} x Sigma_0) + {report['demonstrations']} demonstrations x "
        f"{report['demo_poses']} poses imitated; rule {rule['joint']} {side}; {report['wall_s']} s",
        f"{'':<12}{'rollouts':>9}{'failed':>8}{'success':>10}{'verdict':>9}{'AUC':>8}{'FPR':>6}{'FNR':>6}"
        f"{'Spearman':>10}",
        *[_row(name, q) for name, q in report["by_source"].items()],
        _row("all", report),
        f"failed rollouts: {failures} ({_num(None if rate is None else 100 * rate, '.0f')} %)"])


def main(argv=None) -> int:
    from drake_skill.fileio import atomic_write_json
    from drake_skill.learning.rollout import RolloutConfig
    from drake_skill.learning.reward_quality import plot_return_vs_state

    args = _parser().parse_args(argv)
    _check(args)
    if args.workers is None:
        from drake_skill.learning.workers import default_workers

        args.workers = default_workers()
    skill_dir, out = _skill_dir(args)
    rollout = RolloutConfig(object_pose="ground_truth" if args.ground_truth_pose else "perceived")
    report = measure(skill_dir, rollouts=args.rollouts, demo_poses=args.demo_poses, seed0=args.seed0,
                     exploration_scale=args.exploration_scale, workers=args.workers,
                     rollout_config=rollout, progress=not (args.quiet or args.json))
    json_path = atomic_write_json(Path(out) / "reward_quality.json", report)
    rule = report["rule"]
    plot = plot_return_vs_state(report["records"], rule, Path(out) / "return_vs_state.png",
                                title=f"{report['skill']}: learned return against the object's final state")
    if args.json:
        print(json.dumps(report, sort_keys=True))
    else:
        print(table(report))
        print(f"wrote {json_path} and {plot}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
