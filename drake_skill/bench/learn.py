"""Benchmark of the main job: wall time of the default learning run on 1 worker and on the default.

``drake-skill bench learn [--json]`` / ``python tools/bench_learn.py [--json]``.

The default learning run of ``drake-skill learn`` (Open, PI^2-ES-Cov, dense
reward, 5 episodes x 6 rollouts and 6 greedy executions, 36 executions in all; the
held-out evaluation off, and the Meshcat replays unless ``--replay``), run twice from the same
fitted skill and seed: on 1 worker (the rollouts in this process) and on the
default number of worker processes of ``drake-skill learn``
(``drake_skill.learning.workers.default_workers``: one per CPU the process
may use). The wall time of each covers the whole run, worker start-up
(each worker builds its diagram) included. The skill is fitted first from the
scripted demonstrations (not timed) and cached under ``--cache``
(default ``results/bench_learn/``); ``--skill-dir`` uses a given one.

JSON keys: ``wall_s_1_worker``, ``wall_s_default``, ``default_workers``,
``rollouts_per_s_1_worker`` and ``rollouts_per_s_default`` (executions, rollouts and greedy
ones, per wall-clock second), ``speedup`` (1-worker / default wall time), ``replay`` (whether the Meshcat replays
were recorded: off unless ``--replay``), ``identical`` (both runs gave the same
greedy returns and final weights), ``n_rollouts``, ``skill``. The issue
required at most 180 s with 2 workers and a speedup of at least 1.6 on a
2-core machine.
"""

from __future__ import annotations

import argparse
import io
import json
import tempfile
import time
from pathlib import Path

DEFAULT_CACHE = Path("results") / "bench_learn"
WALL_2_MAX_S = 180.0
SPEEDUP_MIN = 1.6


def fitted_skill_dir(skill: str, cache: Path, progress: bool = False) -> Path:
    """The skill fitted from the scripted demonstrations (thesis counts, seed 0), cached."""
    directory = Path(cache) / f"skill_{skill}"
    if (directory / "skill.json").is_file():
        return directory
    from drake_skill.demos.demonstrator import ScriptedDemonstrator
    from drake_skill.fitted_skill import default_skill_config, fit_skill

    demos = ScriptedDemonstrator(skill).record_many(progress=progress)
    fit_skill(demos, default_skill_config(skill)).save(directory, overwrite=True)
    return directory


def timed_run(skill_dir: Path, workers: int, episodes: int, rollouts: int, seed: int, out: Path,
              replay: bool = False):
    """(wall s, outcome) of one learning run without held-out evaluation (and, by default, replays)."""
    from drake_skill.learning.loop import LearnConfig, learn

    config = LearnConfig(episodes=episodes, rollouts=rollouts, seed=seed, held_out=0)
    start = time.perf_counter()
    outcome = learn(skill_dir, out, config, workers=workers, replay=replay, progress=False, force=True,
                    log=io.StringIO())
    return time.perf_counter() - start, outcome


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="drake-skill bench learn", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--skill", default="open", metavar="SKILL")
    parser.add_argument("--skill-dir", type=Path, help="a fitted skill (default: fitted and cached)")
    parser.add_argument("--episodes", type=int, default=5)
    parser.add_argument("--rollouts", type=int, default=6)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--cache", type=Path, default=DEFAULT_CACHE, help="where the fitted skill is cached")
    parser.add_argument("--replay", action="store_true",
                        help="also record the Meshcat replays (first and last greedy execution, run in "
                             "this process)")
    args = parser.parse_args(argv)

    import numpy as np

    from drake_skill.learning.workers import default_workers

    skill_dir = args.skill_dir or fitted_skill_dir(args.skill, args.cache, progress=not args.json)
    workers = default_workers()
    with tempfile.TemporaryDirectory(prefix="bench_learn_") as tmp:
        wall_1, one = timed_run(skill_dir, 1, args.episodes, args.rollouts, args.seed, Path(tmp) / "w1",
                                args.replay)
        wall_2, two = timed_run(skill_dir, workers, args.episodes, args.rollouts, args.seed, Path(tmp) / "wn",
                                args.replay)
    identical = bool(np.array_equal(one.search.mean, two.search.mean)
                     and one.summary["curve"] == two.summary["curve"])
    executions = args.episodes * args.rollouts + args.episodes + 1
    result = {"wall_s_1_worker": round(wall_1, 1), "wall_s_default": round(wall_2, 1),
              "default_workers": workers, "rollouts_per_s_1_worker": round(executions / wall_1, 4),
              "rollouts_per_s_default": round(executions / wall_2, 4),
              "speedup": round(wall_1 / wall_2, 3), "identical": identical,
              "n_rollouts": args.episodes * args.rollouts, "n_greedy": args.episodes + 1,
              "skill": one.summary["skill"], "replay": bool(args.replay)}
    if args.json:
        print(json.dumps(result))
    else:
        print(f"learning run: {result['skill']}, {args.episodes} episodes x {args.rollouts} rollouts + "
              f"{args.episodes + 1} greedy executions (held-out evaluation off)")
        print(f"  1 worker   {wall_1:8.1f} s  {result['rollouts_per_s_1_worker']:.3f} executions/s")
        print(f"  {workers} workers  {wall_2:8.1f} s  {result['rollouts_per_s_default']:.3f} executions/s "
              f"(the default; 2 workers required <= {WALL_2_MAX_S:.0f} s)")
        print(f"  speedup    {result['speedup']:8.2f}    (required >= {SPEEDUP_MIN})")
        print(f"  identical results: {identical}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
