"""Post-hoc ablation beside the grid (code of ab8d2dc): Close, PI^2-ES, sparse reward, with the
per-step methods' range weighting instead of Eq. 5.1; plus a check that the same script with the
default weighting reproduces the grid's stored run 0. Each finished run is stored as it ends.

    git worktree add /tmp/grid ab8d2dc
    cd /tmp/grid && PYTHONPATH=/tmp/grid /path/to/repo/.venv/bin/python \
        /path/to/repo/docs/results/weighting/run_ablation.py pi2-es
"""
import dataclasses as dc
import json
import sys
from pathlib import Path
from drake_skill.experiments.grid import GridConfig, GridTask, _runner_specs, execute_task, run_dir

OUT = Path(__file__).resolve().parent
GRID = OUT.parent / 'experiment'
config = GridConfig(skills=('close',), methods=('pi2-es',), rewards=('sparse',), runs=10).validate()
specs = _runner_specs(GRID, config, None, None, None, True)
plan = [("check-thesis", "pi2-es", 0, "")] + [("range", m, r, "range") for r in range(7) for m in sys.argv[1:]]
for label, method, run, weighting in plan:
    path = OUT / "close" / method / f"sparse-{label}" / f"run_{run:03d}"
    if (path / "summary.json").is_file():
        continue
    learn = dc.asdict(config.learn_config(method, "sparse", run))
    if weighting:
        learn["weighting"] = weighting
    task = GridTask("run", "close", specs["close"], str(path), method, "sparse", run, learn, held_out=10)
    s = execute_task(task)
    print(label, method, run, "greedy", [int(c["greedy_success"]) for c in s["curve"]], "after", s["held_out_after"],
          "weighting", s["weighting"], "wall", s["wall_s"], flush=True)
    if label == "check-thesis":
        stored = json.loads((run_dir(GRID, "close", method, "sparse", run) / "summary.json").read_text())
        successes = [[c["greedy_success"] for c in summary["curve"]] for summary in (stored, s)]
        print("reproduces the grid's run:", successes[0] == successes[1],
              stored["held_out_after"] == s["held_out_after"], flush=True)
