"""Greedy success of a policy on object poses: held-out evaluation and exploration reports.

What ``drake-skill evaluate`` runs (:func:`evaluate_skill`, :func:`explore_skill`)
and what the learning run (:mod:`drake_skill.learning.loop`) and the
experiment grid measure held-out success with (:func:`evaluate_greedy`).
Success is judged from the simulator's ground truth, never from the learned
reward (docs/method.md section 5: a greedy execution runs the mean, without
exploration).

This module imports no Drake at import time; the pools import it when used.
"""

from __future__ import annotations

import dataclasses as dc
import math
import sys
import time
from collections import Counter
from pathlib import Path
from typing import Any, Callable

import numpy as np

from drake_skill.learning.config import HELD_OUT_SEED0   # the held-out poses' first seed

__all__ = ["CHOICE_SEED0", "HELD_OUT_SEED0", "apply_initial_rule", "best_return_index", "choose_initial_dmp",
           "evaluate_greedy", "evaluate_skill", "evaluation_table", "exploration_table", "explore_skill",
           "results_report", "save_fitted_skill"]


#: First seed of the object poses a skill's initial DMP is chosen on (``initial_dmp: best-return``):
#: below the held-out ones, and a training rollout's pose seed is a 31-bit draw (``pose_seed``).
CHOICE_SEED0 = 800_000


def evaluate_greedy(pool, weights, seeds, progress: Callable | None = None) -> tuple[dict[str, Any], list]:
    """Greedy executions of ``weights`` on the poses of ``seeds``: (report, results).

    report: ``success_rate`` (ground truth), ``successes``, ``verdicts``,
    ``returns``, ``final_object_state``, ``failures`` (reason -> count), ``seeds``.
    """
    seeds = [int(s) for s in seeds]
    results = pool.map([(weights, s) for s in seeds], progress)
    return results_report(seeds, results), results


def results_report(seeds, results) -> dict[str, Any]:
    """JSON-able summary of rollouts on the poses of ``seeds``: ground-truth
    ``success_rate`` and ``successes``, ``verdicts``, ``returns`` (0 for a
    failed rollout), ``final_object_state`` (None where failed), ``failures``
    (reason -> count), per rollout its failure ``reasons`` ("" where it did
    not fail), ``contacts`` (a reflex trip's bodies in contact, ``RolloutResult.contact``;
    None where none tripped) and ``object_poses`` (the object's true placement on the table,
    [x m, y m, yaw rad] in the world frame; None where unknown), and
    ``ik_warnings``."""
    return {
        "seeds": [int(s) for s in seeds],
        "success_rate": float(np.mean([r.success for r in results])) if results else float("nan"),
        "successes": [bool(r.success) for r in results],
        "verdicts": [bool(r.verdict) for r in results],
        "returns": [float(r.dense_return) for r in results],
        "final_object_state": [None if not math.isfinite(r.final_object_state) else float(r.final_object_state)
                               for r in results],
        "failures": dict(Counter(r.reason for r in results if r.failed)),
        "reasons": [str(r.reason) if r.failed else "" for r in results],
        "contacts": [getattr(r, "contact", None) for r in results],
        "object_poses": [_placement(r) for r in results],
        "ik_warnings": int(sum(r.ik_warnings for r in results)),
    }


def _placement(result) -> list[float] | None:
    """[x m, y m, yaw rad] of a rollout's true object pose (``RolloutResult.X_WO_true``), or
    None where it is unknown (not finite)."""
    if not np.all(np.isfinite(result.object_pose_true)):
        return None
    from pydrake.math import RollPitchYaw

    X_WO = result.X_WO_true
    x, y, _ = X_WO.translation()
    return [float(x), float(y), float(RollPitchYaw(X_WO.rotation()).yaw_angle())]


def evaluate_skill(skill_dir, *, poses: int = 10, seed0: int = HELD_OUT_SEED0, station_config=None,
                   rollout_config=None, workers: int = 1, ray_address: str | None = None,
                   all_demos: bool = False, progress: bool = True, keep: Path | None = None) -> dict[str, Any]:
    """Greedy success of a skill (initial or learned) over ``poses`` held-out object poses.

    Executes the skill's policy (its initial DMP, the learned one in a skill
    written by :func:`learn`; with ``all_demos`` each demonstration's DMP:
    its weights, goal and duration)
    on the poses of seeds ``seed0 .. seed0 + poses - 1`` and judges each from
    the simulator's ground truth. Returns a JSON-able report: per policy
    (key = DMP index) the :func:`evaluate_greedy` report, plus the settings.
    With ``keep`` (a folder), each policy's rollouts are kept in
    ``keep/rollouts/evaluation_dmp_I.npz`` (:mod:`~drake_skill.learning.rollout_store`).
    """
    from drake_skill.learning.rollout import RolloutConfig
    from drake_skill.learning.workers import RunnerSpec, make_pool
    from drake_skill.fitted_skill import Skill

    if int(poses) < 1:
        raise ValueError(f"poses: expected at least 1 held-out pose, got {poses}")
    skill = Skill.load(skill_dir)
    station_config = station_config if station_config is not None else skill.station_config()
    rollout_config = (rollout_config or RolloutConfig()).validate()
    seeds = [int(seed0) + i for i in range(int(poses))]
    indices = range(len(skill.dmps)) if all_demos else [skill.initial_index]
    report: dict[str, Any] = {"skill": skill.name, "skill_dir": str(Path(skill_dir)),
                              "object_pose": rollout_config.object_pose, "seeds": seeds,
                              "learned": "learning" in skill.info, "initial_index": skill.initial_index,
                              "policies": {}}
    start = time.perf_counter()
    from tqdm import tqdm

    for index in indices:
        # Each demonstration's DMP whole: its weights with its own goal and
        # duration (a pool per DMP: the runner's DmpSystem is built with them).
        spec = RunnerSpec.create(skill_dir, station_config, rollout_config, dmp_index=index)
        bar = tqdm(total=len(seeds), desc=f"DMP {index}", unit="rollout", disable=not progress,
                   leave=False, file=sys.stderr)
        try:
            with make_pool(spec, workers, ray_address) as pool:
                policy, results = evaluate_greedy(pool, skill.dmps[index].weights, seeds,
                                                  lambda i, r, bar=bar: bar.update(1))
        finally:
            bar.close()
        if keep is not None:
            _keep_rollouts(keep, f"evaluation_dmp_{index}", results, spec)
        policy["initial"] = index == skill.initial_index
        report["policies"][str(index)] = policy
    report["success_rate"] = report["policies"][str(skill.initial_index)]["success_rate"] \
        if str(skill.initial_index) in report["policies"] else None
    report["wall_s"] = round(time.perf_counter() - start, 1)
    return report


def _keep_rollouts(folder, name, results, spec) -> None:
    """``folder/rollouts/NAME.npz`` with what a replay builds its runner from: ``spec``'s fields (the
    ``RunnerSpec`` the rollouts ran on), under the keys of a learn run's ``config.json``."""
    from drake_skill.learning.rollout_store import rollouts_path, save_rollouts

    save_rollouts(rollouts_path(folder, name), results, {"skill_dir": spec.skill_dir, "station": spec.station_yaml,
                                                         "rollout": spec.rollout, "dmp_index": spec.dmp_index})


def best_return_index(mean_returns, default: int) -> int:
    """The DMP with the highest mean learned return; exact ties keep ``default`` (the seeded
    pick) when it is among the best, else the lowest index."""
    means = np.asarray(mean_returns, dtype=float)
    if means.ndim != 1 or means.size == 0 or not np.all(np.isfinite(means)):
        raise ValueError(f"mean_returns: expected finite returns, one per DMP, got {means.tolist()!r}")
    best = np.flatnonzero(means == means.max())
    return int(default) if int(default) in best else int(best[0])


def choose_initial_dmp(skill_dir, *, poses: int | None = None, station_config=None, rollout_config=None,
                       workers: int = 1, ray_address: str | None = None, progress: bool = True) -> dict[str, Any]:
    """Makes the skill in ``skill_dir`` start policy search from its best-imitating demonstration.

    docs/method.md section 5 ("Initial policy"): every demonstration's DMP is
    executed greedily on ``poses`` object poses (default the skill file's
    ``initial_dmp_poses``; seeds ``CHOICE_SEED0 ..``, none a held-out pose)
    and the one with the highest mean learned return R(G) (thesis Eq. 4.5;
    0 for a failed execution) becomes ``initial_index``
    (:func:`best_return_index`). The choice reads the learned reward only;
    the ground truth is recorded beside it, not used. The skill is rewritten
    in one swap with ``info["initial_choice"]`` (this dict: ``rule``,
    ``seeds``, ``mean_returns``, ``successes`` (ground truth, per DMP),
    ``seeded_index``, ``index``, ``executions``), which is returned.
    """
    from drake_skill.fitted_skill import Skill

    skill = Skill.load(skill_dir)
    poses = int(skill.spec.initial_dmp_poses if poses is None else poses)
    report = evaluate_skill(skill_dir, poses=poses, seed0=CHOICE_SEED0, station_config=station_config,
                            rollout_config=rollout_config, workers=workers, ray_address=ray_address,
                            all_demos=True, progress=progress)
    policies = [report["policies"][str(i)] for i in range(len(skill.dmps))]
    means = [float(np.mean(p["returns"])) for p in policies]
    seeded = int(skill.info.get("initial_choice", {}).get("seeded_index", skill.initial_index))
    choice = {"rule": "best-return", "seeds": report["seeds"], "mean_returns": means,
              "successes": [p["successes"] for p in policies], "seeded_index": seeded,
              "index": best_return_index(means, seeded), "executions": poses * len(skill.dmps)}
    dc.replace(skill, initial_index=choice["index"], info={**skill.info, "initial_choice": choice}).save(
        skill_dir, overwrite=True)
    return choice


def _chooses_best_return(skill) -> bool:
    """Whether the skill file's ``initial_dmp`` rule asks for a choice: "best-return" with two
    or more demonstrations (one DMP leaves nothing to choose)."""
    return skill.spec.initial_dmp == "best-return" and len(skill.dmps) >= 2


def _choice_line(choice: dict[str, Any]) -> str:
    returns = ", ".join(f"DMP {i} {r:.1f}" for i, r in enumerate(choice["mean_returns"]))
    return (f"initial DMP: {choice['index']} (best mean learned return over {len(choice['seeds'])} poses: "
            f"{returns}; the seed drew {choice['seeded_index']})")


def apply_initial_rule(skill_dir, *, station_config=None, workers: int = 1, progress: bool = True) -> str | None:
    """The skill file's ``initial_dmp`` rule on a freshly fitted skill: with "best-return",
    :func:`choose_initial_dmp` (a line saying what it chose is returned); with "random" the
    fit's seeded pick stands (None)."""
    from drake_skill.fitted_skill import Skill

    if not _chooses_best_return(Skill.load(skill_dir)):
        return None
    return _choice_line(choose_initial_dmp(skill_dir, station_config=station_config, workers=workers,
                                           progress=progress))


def save_fitted_skill(skill, skill_dir, *, overwrite: bool = False, station_config=None, progress: bool = True,
                      log: Callable[[str], Any] = print):
    """Saves a freshly fitted ``skill`` to ``skill_dir`` and applies its skill file's ``initial_dmp``
    rule (as :func:`apply_initial_rule`, read from ``skill`` in memory; ``log`` gets the line
    saying what it chose). Returns the skill as saved: ``skill`` itself under "random", else the
    rewritten one."""
    from drake_skill.fitted_skill import Skill

    skill.save(skill_dir, overwrite=overwrite)
    if not _chooses_best_return(skill):
        return skill
    log(_choice_line(choose_initial_dmp(skill_dir, station_config=station_config, progress=progress)))
    return Skill.load(skill_dir)


def explore_skill(skill_dir, *, rollouts: int = 20, seed0: int = HELD_OUT_SEED0, station_config=None,
                  rollout_config=None, workers: int = 1, ray_address: str | None = None,
                  progress: bool = True, exploration_scale: float | None = None,
                  keep: Path | None = None, approach_exploration: float = 1.0) -> dict[str, Any]:
    """Exploratory rollouts of a fitted skill: what the first episode of policy search sees.

    Draws ``rollouts`` weight samples ``W ~ N(W_0, exploration_scale * Sigma_b^0)`` per basis
    (PI^2-ES-Cov's first ``ask``, seeded by ``seed0``; ``exploration_scale``
    None: the skill's, as ``learn``) and executes each on
    the pose of seed ``seed0 + i``; ``approach_exploration`` quiets the bases before the
    demonstrations' first contact as ``learn`` does (docs/method.md 5.4). Returns a JSON-able report: the returns
    (learned dense reward; 0 for a failed rollout), their spread (min,
    median, max, standard deviation), ground-truth successes, final object
    states and failures by reason. With ``keep`` (a folder), the rollouts are kept in
    ``keep/rollouts/exploration.npz``.
    """
    from drake_skill.learning.config import valid_approach_exploration, valid_exploration_scale
    from drake_skill.learning.exploration import skill_covariance
    from drake_skill.learning.policy_search import make_policy_search
    from drake_skill.learning.rollout import RolloutConfig
    from drake_skill.learning.workers import RunnerSpec, make_pool
    from drake_skill.fitted_skill import Skill

    if int(rollouts) < 1:
        raise ValueError(f"rollouts: expected at least 1 exploratory rollout, got {rollouts}")
    skill = Skill.load(skill_dir)
    station_config = station_config if station_config is not None else skill.station_config()
    rollout_config = (rollout_config or RolloutConfig()).validate()
    if exploration_scale is None:
        exploration_scale = float(skill.spec.exploration_scale)
    if not valid_exploration_scale(exploration_scale):
        raise ValueError(f"exploration_scale: expected a factor in (0, 100] on Sigma_b^0, got {exploration_scale!r}")
    approach = float(approach_exploration)
    if not valid_approach_exploration(approach):
        raise ValueError(f"approach_exploration (--approach-exploration): expected a factor in (0, 1], got "
                         f"{approach_exploration!r}; give 1 (off) or less")
    samples = make_policy_search("pi2-es-cov", skill.initial_weights,
                                 exploration_scale * skill_covariance(skill, approach),
                                 seed=int(seed0)).ask(int(rollouts))
    seeds = [int(seed0) + i for i in range(int(rollouts))]
    start = time.perf_counter()
    spec = RunnerSpec.create(skill_dir, station_config, rollout_config)
    from tqdm import tqdm
    bar = tqdm(total=len(seeds), desc="exploration", unit="rollout", disable=not progress, leave=False,
               file=sys.stderr)
    try:
        with make_pool(spec, workers, ray_address) as pool:
            results = pool.map([(w, s) for w, s in zip(samples, seeds)], lambda i, r: bar.update(1))
    finally:
        bar.close()
    if keep is not None:
        _keep_rollouts(keep, "exploration", results, spec)
    report = {"skill": skill.name, "skill_dir": str(Path(skill_dir)), "object_pose": rollout_config.object_pose,
              "exploration_scale": float(exploration_scale), "approach_exploration": approach,
              **results_report(seeds, results)}
    returns = np.array(report["returns"])
    report["return_spread"] = {"min": float(returns.min()), "median": float(np.median(returns)),
                               "max": float(returns.max()), "std": float(returns.std())}
    report["wall_s"] = round(time.perf_counter() - start, 1)
    return report


def _final_state_text(finals) -> str:
    """Median (min..max) of the final object states that exist, or "-"."""
    finals = [v for v in finals if v is not None]
    return f"{np.median(finals):.2f} ({min(finals):.2f}..{max(finals):.2f})" if finals else "-"


def _failures_text(failures: dict) -> str:
    return ", ".join(f"{k} {v}" for k, v in sorted(failures.items())) or "-"


def exploration_table(report: dict[str, Any]) -> str:
    """The people's view of :func:`explore_skill`'s report."""
    s = report["return_spread"]
    return "\n".join([
        f"{report['skill']}: {len(report['seeds'])} exploratory rollouts from "
        f"{report['exploration_scale']:g} x Sigma_0 (seeds {report['seeds'][0]}.."
        f"{report['seeds'][-1]}), {report['wall_s']} s",
        f"  return: min {s['min']:.1f}, median {s['median']:.1f}, max {s['max']:.1f}, std {s['std']:.1f}",
        f"  success {report['success_rate'] * 100:.0f}%, "
        f"final state {_final_state_text(report['final_object_state'])}, "
        f"failures {_failures_text(report['failures'])}"])


def evaluation_table(report: dict[str, Any]) -> str:
    """The people's view of :func:`evaluate_skill`'s report."""
    lines = [f"{'policy':<22}{'success':>9}{'verdict':>9}{'mean R':>9}{'final state':>22}  failures"]
    for index, p in report["policies"].items():
        name = f"DMP {index}" + (" (learned)" if p["initial"] and report.get("learned") else
                                 " (initial)" if p["initial"] else "")
        lines.append(f"{name:<22}{p['success_rate'] * 100:>8.0f}%{np.mean(p['verdicts']) * 100:>8.0f}%"
                     f"{np.mean(p['returns']):>9.1f}{_final_state_text(p['final_object_state']):>22}  "
                     f"{_failures_text(p['failures'])}")
    lines.append(f"{report['skill']}: {len(report['seeds'])} held-out poses (seeds {report['seeds'][0]}.."
                 f"{report['seeds'][-1]}), object frame {report['object_pose']}, {report['wall_s']} s")
    return "\n".join(lines)
