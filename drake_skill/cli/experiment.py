"""``drake-skill experiment``: the thesis's simulation study as a resumable grid of learning runs.

    drake-skill experiment run [--skills open close] [--methods power pi2 pi2-cov pi2-es pi2-es-cov cma-es]
                               [--rewards dense sparse] [--runs 20] [--episodes 5] [--rollouts 6]
                               [--held-out 10] [--seed0 0] [--workers N] [--ray | --ray-address ADDR]
                               [--out results/experiment]
    drake-skill experiment report OUT [--table FILE] [--report-dir DIR]
    drake-skill experiment generalization [--skills ...] [--runs 5] [--workers N] [--exploration basis|span]
                                          [--scenario FILE] [--out docs/results/generalization]

``run``: for each skill the scripted demonstrations are recorded and the
skill fitted once (``OUT/SKILL/initial_skill``, reused when there); its
held-out success before learning is measured once; then every cell (skill,
method, reward) gets ``--runs`` learning runs (seeds ``seed0 + r``), each one
call of ``drake-skill learn``'s loop with one worker inside, several runs at
a time on worker processes (default one per CPU) or on Ray. Budgets: E x C
(default 5 x 6) with a greedy execution before learning and after every
update; PoWER E*C x 1 with a greedy execution every C updates (thesis 7.1).

Each run is stored the moment it ends (``OUT/SKILL/METHOD/REWARD/run_RRR/``
with ``summary.json``, renamed into place whole); a second invocation skips
stored runs, resumes interrupted ones from their checkpoint and adds runs
when ``--runs`` is raised; a run whose worker process died is retried
(3 attempts). ``OUT/table.csv`` is rewritten from the stored runs at the end:
one row per run x greedy execution (skill, method, reward, run, episode,
rollouts_used, success, return, held_out_after, held_out_before).

``report``: from the table alone (no simulation), ``SKILL_methods.png``
(per method, dense against sparse: mean greedy success +/- sd against
episode), ``SKILL_dense.png`` (every method, dense reward) and
``results.md`` (success per episode, area under the curve, the thesis's
three claims marked holds / does not hold / cannot tell with their numbers).

``generalization``: every shipped skill (or --skills) learned with
``drake-skill learn``'s defaults (PI^2-ES-Cov, dense reward, 5 x 6 rollouts,
tolerance fit, guarded selection, 10 held-out poses), --runs seeds each, as
a grid (resumable the same way); then, from the stored runs alone,
``table.csv`` (a row per skill and seed), ``summary.json``, per skill
``SKILL_held_out.png`` and ``SKILL_return_vs_state.png``, and ``README.md``
with the criteria of issue 45 marked (drake_skill.experiments.generalization).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from drake_skill.cli import options

NAME = "experiment"
HELP = "the thesis's simulation study: a resumable grid of learning runs (run) and its results (report)"

DEFAULT_OUT = Path("results") / "experiment"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.description = __doc__
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    actions = parser.add_subparsers(dest="action", metavar="ACTION", title="actions")
    actions.required = True
    _add_run_arguments(actions.add_parser(
        "run", help="run the grid's runs not stored yet, then write OUT/table.csv",
        description="Runs the grid (resumable); see 'drake-skill experiment --help'."))
    report_p = actions.add_parser("report", help="figures and results.md from OUT/table.csv (no simulation)",
                                  description="Figures and results.md from a grid's table alone.")
    report_p.add_argument("out", type=Path, help="the grid folder (holding table.csv)")
    report_p.add_argument("--table", type=Path, default=None, help="the table (default OUT/table.csv)")
    report_p.add_argument("--report-dir", type=Path, default=None, help="where to write (default OUT)")
    general = actions.add_parser(
        "generalization", help="every skill learned with learn's defaults, N seeds each (resumable), and its report",
        description="Learning on every skill with drake-skill learn's defaults; see 'drake-skill experiment --help'.")
    general.add_argument("--skills", nargs="+", default=None, metavar="SKILL",
                         help="shipped skills' names or skill files (default: every shipped skill)")
    general.add_argument("--runs", type=int, default=5, help="seeds per skill (default 5)")
    general.add_argument("--workers", type=int, default=None, help="runs at a time (default: one per CPU)")
    general.add_argument("--exploration", choices=("basis", "span"), default="basis",
                         help="what each run's search varies, as learn --exploration (default basis; span "
                              "writes the same study for the demonstrations' span, docs/method.md 5.2)")
    general.add_argument("--approach-exploration", type=float, default=1.0, metavar="F",
                         help="as learn --approach-exploration: Sigma_0 x F on the bases before the "
                              "demonstrations' first contact (default 1: off; docs/method.md 5.4)")
    general.add_argument("--scenario", dest="station_config", type=Path, default=None, metavar="FILE",
                         help="scenario YAML over each skill's scenario, as learn --scenario (e.g. "
                              "'controller: {force_limit: {enabled: true}}'; stored with the runs)")
    general.add_argument("--out", type=Path, default=Path("docs") / "results" / "generalization",
                         help="the study's folder (default docs/results/generalization)")
    general.add_argument("--report-only", action="store_true", help="rewrite the report from the stored runs only")
    general.add_argument("--quiet", action="store_true", help="no progress bar")
    for action in actions.choices.values():      # 'experiment run --verbose' as 'experiment --verbose run'
        action.add_argument("--verbose", action="store_true", default=argparse.SUPPRESS,
                            help="print tracebacks of errors and every differential-IK warning")


def _add_run_arguments(run_p: argparse.ArgumentParser) -> None:
    from drake_skill.skills import shipped_skill_names
    from drake_skill.experiments.grid import DEFAULT_RUNS
    from drake_skill.learning.loop import REWARDS
    from drake_skill.learning.policy_search import METHODS
    from drake_skill.learning.workers import default_workers

    grid = run_p.add_argument_group("grid")
    grid.add_argument("--skills", nargs="+", default=["open", "close"], metavar="SKILL",
                      help=f"shipped skills' names (some of {', '.join(shipped_skill_names())}) or skill files "
                           "(default open close: the thesis's simulation study)")
    grid.add_argument("--methods", nargs="+", default=list(METHODS), metavar="METHOD",
                      help=f"some of {', '.join(METHODS)} (default all)")
    grid.add_argument("--rewards", nargs="+", default=list(REWARDS), metavar="REWARD",
                      help="dense and/or sparse (default both)")
    grid.add_argument("--runs", type=int, default=DEFAULT_RUNS,
                      help=f"runs per cell (default {DEFAULT_RUNS}); raise it later to add runs")
    budget = run_p.add_argument_group("every run")
    budget.add_argument("--episodes", type=int, default=5, help="updates E (default 5; PoWER: E*C of 1 rollout)")
    budget.add_argument("--rollouts", type=int, default=6, help="rollouts per update C (default 6)")
    budget.add_argument("--held-out", type=int, default=10,
                        help="held-out object poses for success before (once per skill) and after (default 10)")
    budget.add_argument("--seed0", type=int, default=0, help="seed of run 0 (run r: seed0 + r; default 0)")
    budget.add_argument("--skill-dir", type=Path, default=None,
                        help="start from this fitted skill instead of recording and fitting (one skill)")
    budget.add_argument("--scenario", "--station-config", dest="station_config", type=Path, metavar="FILE",
                        help="scenario YAML over each skill's scenario (Scenario)")
    options.add_ground_truth_pose(budget)
    where = run_p.add_argument_group("where")
    where.add_argument("--workers", type=int, default=None,
                       help=f"runs at a time (default: one per CPU this process may use, {default_workers()} here)")
    where.add_argument("--ray", action="store_true", help="run on a local Ray (needs pip install ray)")
    where.add_argument("--ray-address", default=None, type=options.ray_address,
                       help="run on this Ray cluster ('auto', 'ray://host:port'; OUT on a shared path)")
    where.add_argument("--out", type=Path, default=DEFAULT_OUT, help=f"grid folder (default {DEFAULT_OUT})")
    where.add_argument("--keep-skills", action="store_true",
                       help="keep each run's learned skill/ folder (7 MB each; the weights are in checkpoint/)")
    where.add_argument("--quiet", action="store_true", help="no progress bar")
    where.add_argument("--fit", choices=("thesis", "tolerance"), default="thesis",
                       help="how each skill is fitted: 'thesis' (default, the committed grid's: 10 Hz data, "
                            "Table 6.1's bases) or 'tolerance' (docs/method.md section 2.2); kept in grid.json, "
                            "so a resumed grid never mixes fits")


def _run(args) -> int:
    from drake_skill.cli import errors, options
    from drake_skill.experiments.grid import GridConfig, run_grid

    errors.output_folder(args.out, "--out", what="the experiment grid")
    if args.skill_dir is not None:
        errors.input_folder(args.skill_dir, "--skill-dir", "a fitted skill (drake-skill fit)")
    config = GridConfig(skills=tuple(args.skills), methods=tuple(args.methods), rewards=tuple(args.rewards),
                        runs=args.runs, episodes=args.episodes, rollouts=args.rollouts, held_out=args.held_out,
                        seed0=args.seed0, keep_skills=args.keep_skills, fit=args.fit)
    rollout = options.rollout_config(args)
    outcome = run_grid(args.out, config, skill_dir=args.skill_dir, station_yaml=args.station_config,
                       rollout_config=rollout, workers=args.workers, use_ray=args.ray,
                       ray_address=args.ray_address, progress=not args.quiet, quiet=args.quiet)
    print(f"{outcome.ran} run(s) finished in {outcome.wall_s:.0f} s on {outcome.workers} worker(s); "
          f"{outcome.stored} stored in {args.out}; table {outcome.table}")
    for name, error in outcome.failed:
        print(f"not finished: {name}: {error}")
    if outcome.failed:
        print("run the same command again to retry them")
    return 1 if outcome.failed else 0


def _report(args) -> int:
    from drake_skill.cli import errors
    from drake_skill.experiments.report import write_report

    table = args.table if args.table is not None else args.out / "table.csv"
    errors.input_file(table, "--table" if args.table is not None else "OUT",
                      "the table of a grid (OUT/table.csv, written by 'drake-skill experiment run')")
    written = write_report(table, args.report_dir if args.report_dir is not None else args.out)
    print(f"wrote {', '.join(str(p) for p in written)}")
    return 0


def _generalization(args) -> int:
    from drake_skill.cli import errors
    from drake_skill.experiments.generalization import generalization_config, write_report
    from drake_skill.experiments.grid import run_grid
    from drake_skill.learning.rollout import RolloutConfig

    errors.output_folder(args.out, "--out", what="the generalization study")
    failed = []
    if not args.report_only:
        if args.station_config is not None:
            from drake_skill.inputs import input_file
            input_file(args.station_config, "--scenario",
                       "a station scenario YAML file (see drake_skill/station/scenarios/)")
        config = generalization_config(args.skills, args.runs, args.exploration, args.approach_exploration)
        outcome = run_grid(args.out, config, rollout_config=RolloutConfig(), workers=args.workers,
                           station_yaml=args.station_config, progress=not args.quiet, quiet=args.quiet)
        print(f"{outcome.ran} run(s) finished in {outcome.wall_s:.0f} s on {outcome.workers} worker(s); "
              f"{outcome.stored} stored in {args.out}")
        failed = outcome.failed
        for name, error in failed:
            print(f"not finished: {name}: {error}")
    written = write_report(args.out)
    print(f"wrote {', '.join(str(p) for p in written)}")
    return 1 if failed else 0


def run(args: argparse.Namespace) -> int:
    if args.action == "generalization":
        return _generalization(args)
    return _run(args) if args.action == "run" else _report(args)


def main(argv=None) -> int:
    """``drake-skill experiment ARGV...`` (scripts and tests): errors as one line, exit status 2."""
    from drake_skill.cli.main import command_main

    return command_main(NAME, argv)
