"""Benchmark of scaling: rollouts per second on 1..N workers, on worker processes and on Ray.

``drake-skill bench scale [--json] [--max-workers N] [--rollouts-per-worker K] [--backends pool ray]``

A skill is fitted once from scripted demonstrations and cached (as ``bench
rollout``). For each backend and each worker count n = 1..N, a pool of n
workers is started (:class:`~drake_skill.learning.workers.ProcessPool`, also
for n = 1, so that every count pays the same inter-process cost; or
:class:`~drake_skill.learning.workers.RayPool` on a local ``ray.init`` of n
CPUs), every worker builds its runner and executes one untimed rollout, then
n * K rollouts of the skill's initial weights on distinct object poses are
timed as one ``map``:

- ``rollouts_per_s`` = n * K / wall time of the map;
- ``efficiency`` = speedup / workers = rollouts_per_s(n) / (n * rollouts_per_s(1)).

Output: ``{"pool": {"1": {"rollouts_per_s": x, "efficiency": 1.0, "wall_s": t}, "2": ...}, "ray": {...},
"cpus": c, "machine": ...}``. Run it when nothing else computes: the figures
are only as good as the machine is quiet (``load_average`` says how quiet it
was).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

__all__ = ["main", "run"]


def _pool(backend: str, spec, n: int):
    from drake_skill.learning.workers import ProcessPool, RayPool

    return ProcessPool(spec, n) if backend == "pool" else RayPool(spec, n)


def _measure(backend: str, spec, weights, n: int, per_worker: int) -> float:
    """Rollouts per second of ``n`` workers over ``n * per_worker`` rollouts (after one untimed each)."""
    with _pool(backend, spec, n) as pool:
        pool.map([(weights, 10_000 + i) for i in range(n)])              # build the runners, warm up
        tasks = [(weights, i) for i in range(n * per_worker)]
        start = time.perf_counter()
        results = pool.map(tasks)
        wall = time.perf_counter() - start
    failed = [r.reason for r in results if r.failed and r.reason == "error"]
    if failed:
        raise RuntimeError(f"bench scale: {len(failed)} rollouts failed on {backend} with {n} workers")
    return len(tasks) / wall


def run(skill_name: str = "open", max_workers: int | None = None, per_worker: int = 2,
        backends=("pool", "ray"), cache: Path | None = None) -> dict:
    """The figures of the module docstring."""
    from drake_skill.bench.rollout import DEFAULT_CACHE, fitted_skill
    from drake_skill.learning.rollout import RolloutConfig
    from drake_skill.learning.workers import RunnerSpec, default_workers

    cache = Path(cache) if cache is not None else DEFAULT_CACHE
    skill = fitted_skill(skill_name, 0, cache)
    spec = RunnerSpec.create(cache / f"skill_{skill_name}_seed0", skill.station_config(), RolloutConfig())
    max_workers = int(max_workers) if max_workers else default_workers()
    out: dict = {"skill": skill_name, "rollouts_per_worker": int(per_worker), "cpus": default_workers(),
                 "machine": f"{platform.machine()}, {os.cpu_count()} logical CPUs, {platform.node()}"}
    for backend in backends:
        rates = {}
        for n in range(1, max_workers + 1):
            rates[n] = _measure(backend, spec, skill.initial_weights, n, per_worker)
        out[backend] = {str(n): {"rollouts_per_s": round(r, 4), "efficiency": round(r / (n * rates[1]), 3)}
                        for n, r in rates.items()}
    out["load_average"] = [round(v, 2) for v in os.getloadavg()]
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="drake-skill bench scale", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--skill", default="open", metavar="SKILL")
    parser.add_argument("--max-workers", type=int, default=None, metavar="N",
                        help="measure 1..N workers (default: one per CPU this process may use)")
    parser.add_argument("--rollouts-per-worker", type=int, default=2, metavar="K",
                        help="timed rollouts per worker (default 2)")
    parser.add_argument("--backends", nargs="+", choices=("pool", "ray"), default=["pool", "ray"])
    parser.add_argument("--cache", type=Path, default=None, help="where the fitted skill is kept "
                        "(default results/bench_rollout, shared with bench rollout)")
    args = parser.parse_args(argv)
    if args.max_workers is not None and args.max_workers < 1:
        raise ValueError(f"--max-workers {args.max_workers}: expected at least 1")
    if args.rollouts_per_worker < 1:
        raise ValueError(f"--rollouts-per-worker {args.rollouts_per_worker}: expected at least 1")
    result = run(args.skill, args.max_workers, args.rollouts_per_worker, args.backends, args.cache)
    if args.json:
        print(json.dumps(result))
        return 0
    print(f"{args.skill}: {args.rollouts_per_worker} timed rollouts per worker; {result['machine']} "
          f"(load {result['load_average'][0]:.2f})")
    for backend in args.backends:
        for n, figures in result[backend].items():
            print(f"  {backend:4s} {n:>3} workers: {figures['rollouts_per_s']:7.3f} rollouts/s, "
                  f"efficiency {figures['efficiency']:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
