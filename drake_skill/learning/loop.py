"""The learning run: policy search on the learned reward, with greedy and held-out evaluation.

docs/method.md section 5, docs/architecture.md "The outer loop"::

    search = make_policy_search(method, W0, Sigma0, seed=seed)
    held-out greedy success of W0 over N poses           (before learning)
    greedy execution of W0                               (episode 0)
    for e in 1..E:
        samples = search.ask(C)                          # (C, B, 7)
        results = pool.map(samples, pose seeds of episode e)
        search.tell(samples, returns or per-step rewards)
        greedy execution of search.mean                  (episode e)
        checkpoint
    held-out greedy success of the final mean            (after learning)

The greedy executions run two at a time beside the next episode's rollouts
(:data:`GREEDY_BATCH`), which changes no number, only when they run.

Returns (docs/method.md sections 4-5): ``reward="dense"`` uses the POMRP
return R(G) (thesis Eq. 4.5) for the black-box methods and the filtered
per-step rewards for :data:`~drake_skill.learning.policy_search.PER_STEP_METHODS`;
``reward="sparse"`` the goal model's verdict (1 or 0; per step: at the last
step). A failed rollout counts with reward 0 and is reported with its reason.

Seeds: the policy search draws from ``seed``; rollout ``c`` of episode ``e``
and the greedy execution after update ``e`` place the object at poses drawn
from seeds derived from ``(seed, e, c)`` (:func:`pose_seed`); the held-out
poses are the seeds ``held_out_seed0 + i`` (the same for every run, none of
them a demonstration's or a training rollout's in practice).

Artifacts in the output directory (:data:`ARTIFACTS`), all written
atomically: ``config.json``, ``results.jsonl`` (one JSON object per line:
``held_out``, ``greedy``, ``rollout`` and ``episode`` records),
``summary.json``, ``learning_curve.png``, ``skill/`` (the learned skill),
``replay_first.html`` / ``replay_last.html`` (Meshcat replays of the first
and last greedy executions) and ``checkpoint/`` (``search.npz`` + ``state.json``,
written after every episode; :func:`learn` with ``resume=True`` continues
from it to the result an uninterrupted run gives).

This module imports no Drake at import time; the pools and the Meshcat
replays import it when used.
"""

from __future__ import annotations

import dataclasses as dc
import json
import math
import sys
import time
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

from drake_skill.fileio import atomic_save_npz, atomic_write_json, atomic_write_text, load_npz
from drake_skill.learning.evaluation import HELD_OUT_SEED0, evaluate_greedy
from drake_skill.learning.plots import plot_learning_curve
from drake_skill.learning.policy_search import METHODS, PER_STEP_METHODS, make_policy_search, policy_search_from_state

__all__ = ["ARTIFACTS", "HELD_OUT_SEED0", "LearnConfig", "LearnOutcome", "episode_rewards", "frame_meshcat_camera",
           "learn", "pose_seed"]

#: What a learning run writes into its output directory.
ARTIFACTS = ("config.json", "results.jsonl", "summary.json", "learning_curve.png", "skill/",
             "replay_first.html", "replay_last.html", "checkpoint/")

REWARDS = ("dense", "sparse")

#: sigma_0 (thesis Eq. 5.3) per skill: the default of ``LearnConfig.exploration_scale``
#: and ``explore_skill``. Open explores at a tenth of Sigma_0, Close at the
#: thesis' 1 (docs/method.md section 5, "Initial exploration scale").
EXPLORATION_SCALES = {"open": 0.1, "close": 1.0, "draw": 0.1}


def default_exploration_scale(skill: str) -> float:
    """sigma_0 of thesis Eq. 5.3 for ``skill`` (``EXPLORATION_SCALES``)."""
    if skill not in EXPLORATION_SCALES:
        raise ValueError(f"skill {skill!r}: no default exploration scale; expected one of "
                         f"{', '.join(EXPLORATION_SCALES)} or give exploration_scale")
    return EXPLORATION_SCALES[skill]


def exploration_scales_text() -> str:
    """``EXPLORATION_SCALES`` for help texts: "open 0.1, close 1, draw 0.1"."""
    return ", ".join(f"{skill} {scale:g}" for skill, scale in EXPLORATION_SCALES.items())


def _valid_exploration_scale(value) -> bool:
    """An exploration scale is a finite factor in (0, 100] on Sigma_b^0."""
    return math.isfinite(value) and 0 < value <= 100


def _block_row(records, episode: int, every: int, exploration_at: dict, mean) -> dict:
    """The curve row of update ``episode``: its rollouts and those of the updates since the last greedy one.

    With a greedy execution after every update (``every`` = 1) the block is
    the episode's own rollouts; PoWER's 30 x 1 with one every 6 sums 6 of them.
    """
    first = ((episode - 1) // every) * every + 1
    block = [r for r in records if r["type"] == "rollout" and first <= r["episode"] <= episode]
    returns = [r["reward"] for r in block]
    return {"episode": episode, "mean_return": float(np.mean(returns)), "best_return": float(np.max(returns)),
            "exploration": exploration_at[first],
            "failures": dict(Counter(r["reason"] for r in block if r["failed"])),
            "rollout_successes": int(sum(r["success"] for r in block)),
            "ik_warnings": int(sum(r["ik_warnings"] for r in block)), "mean": np.asarray(mean).tolist()}


_CHECKPOINT_FORMAT = 2

#: Greedy executions wait until this many are due and then run beside the next
#: episode's rollouts (all that are left after the last update). One greedy
#: execution beside an even number of rollouts would leave one of two workers
#: idle for a whole rollout every episode; two fill that slot. A constant, not
#: the number of workers, so that the records come out in the same order on
#: any pool.
GREEDY_BATCH = 2


@dc.dataclass
class LearnConfig:
    """What decides a learning run's numbers (saved in ``config.json``; resume checks it).

    method: one of ``policy_search.METHODS`` (default PI^2-ES-Cov, thesis 5.2).
    reward: "dense" (POMRP return / per-step rewards) or "sparse" (verdict).
    weighting: "" (the method's default: "thesis" for PI^2-ES(-Cov), "range"
      for PI^2(-Cov)), "thesis" (Eq. 5.1) or "range"; only the PI^2 family.
    episodes, rollouts: E updates of C rollouts (thesis budget 5 x 6).
    seed: policy search and pose seeds.
    held_out: greedy success over this many held-out poses before and after
      learning (0: off); held_out_seed0: their first seed.
    greedy_every: a greedy execution before learning and after every
      ``greedy_every``-th update and the last (thesis 7.1: 1, PoWER's 30 x 1
      runs every 6). Greedy executions do not touch the search: the curve's
      other points are the same whatever this is.
    exploration_scale: sigma_0 of thesis Eq. 5.3: the first episode samples
      ``w_b ~ N(w_b, exploration_scale * Sigma_b^0)`` (every method starts
      from that covariance; the covariance floor follows it). None: the
      skill's (``EXPLORATION_SCALES``; ``learn`` saves the value it used).
      The thesis sets it to 1 (docs/method.md section 5).
    """

    method: str = "pi2-es-cov"
    reward: str = "dense"
    weighting: str = ""
    episodes: int = 5
    rollouts: int = 6
    seed: int = 0
    held_out: int = 10
    held_out_seed0: int = HELD_OUT_SEED0
    exploration_scale: float | None = None
    greedy_every: int = 1

    def validate(self) -> "LearnConfig":
        def bad(field, value, expected):
            raise ValueError(f"learn config field '{field}' = {value!r}: expected {expected}")

        if self.method not in METHODS:
            bad("method", self.method, f"one of {', '.join(METHODS)}")
        if self.reward not in REWARDS:
            bad("reward", self.reward, "'dense' or 'sparse'")
        if self.weighting not in ("", "thesis", "range"):
            bad("weighting", self.weighting, "'' (method default), 'thesis' or 'range'")
        if self.weighting and self.method in ("power", "cma-es"):
            bad("weighting", self.weighting, f"'' for {self.method} (it has no rollout weighting)")
        if int(self.episodes) < 1:
            bad("episodes", self.episodes, "at least 1")
        min_rollouts = 2 if self.method == "cma-es" else 1
        if int(self.rollouts) < min_rollouts:
            bad("rollouts", self.rollouts, f"at least {min_rollouts} per episode for {self.method}")
        if int(self.greedy_every) < 1:
            bad("greedy_every", self.greedy_every, "at least 1 (a greedy execution after every n-th update)")
        if int(self.held_out) < 0:
            bad("held_out", self.held_out, "0 (off) or a number of poses")
        if self.exploration_scale is not None and not _valid_exploration_scale(self.exploration_scale):
            bad("exploration_scale", self.exploration_scale, "a factor in (0, 100] on Sigma_b^0")
        return self

    def search_options(self) -> dict[str, Any]:
        options: dict[str, Any] = {"n_episodes": int(self.episodes), "seed": int(self.seed)}
        if self.weighting:
            options["weighting"] = self.weighting
        return options


def pose_seed(run_seed: int, episode: int, index: int | None = None) -> int:
    """Object-pose seed of rollout ``index`` of episode ``episode`` (1-based), or,
    with ``index=None``, of the greedy execution after that episode's update
    (episode 0: before learning). A 31-bit integer from ``numpy.random.SeedSequence``."""
    key = [int(run_seed), int(episode), 0 if index is None else 1, 0 if index is None else int(index)]
    return int(np.random.SeedSequence(key).generate_state(1)[0] >> 1)


def episode_rewards(results, reward: str, per_step: bool) -> np.ndarray:
    """What ``tell`` takes from an episode's results: returns ``(C,)`` or per-step ``(C, T)``.

    dense: R(G) (Eq. 4.5) / the filtered per-step rewards (zero-padded to the
    longest rollout); sparse: the verdict as 1/0 (per step: at the last step).
    Failed rollouts count 0.
    """
    if not per_step:
        if reward == "dense":
            return np.array([0.0 if r.failed else float(r.dense_return) for r in results])
        return np.array([0.0 if r.failed else float(r.verdict) for r in results])
    length = max([len(r.filtered_rewards) for r in results] + [1])
    out = np.zeros((len(results), length))
    for i, r in enumerate(results):
        if r.failed:
            continue
        if reward == "dense":
            out[i, :len(r.filtered_rewards)] = r.filtered_rewards
        else:
            out[i, -1] = float(r.verdict)
    return out


def exploration_size(search) -> float:
    """RMS standard deviation of the sampling distribution: sqrt(mean_b trace(s Sigma_b) / D)."""
    cov = search.sampling_covariances
    return float(np.sqrt(np.mean(np.trace(cov, axis1=1, axis2=2)) / cov.shape[-1]))


def frame_meshcat_camera(meshcat, object_xyz) -> None:
    """Points Meshcat's camera at the robot and the object (robot base at the world origin)."""
    target = 0.5 * np.asarray(object_xyz, dtype=float) + np.array([0.0, 0.0, 0.25])   # between base and object
    meshcat.SetCameraPose(target + np.array([0.9, -1.3, 0.55]), target)


@dc.dataclass
class LearnOutcome:
    """What :func:`learn` returns: the summary (also in ``summary.json``) and paths."""

    summary: dict
    out_dir: Path
    complete: bool
    search: Any = None


class _Replay:
    """Meshcat recordings of greedy executions, saved as standalone HTML."""

    def __init__(self, meshcat, live: bool):
        self.meshcat = meshcat
        self.live = live

    def run(self, runner, weights, seed, path: Path | None):
        if path is None:
            return runner.run(weights, seed)
        frame_meshcat_camera(self.meshcat, runner.station.random_object_pose(seed).translation())
        self.meshcat.StartRecording(frames_per_second=32.0, set_visualizations_while_recording=self.live)
        try:
            result = runner.run(weights, seed)
        finally:
            self.meshcat.StopRecording()
        self.meshcat.PublishRecording()
        atomic_write_text(path, self.meshcat.StaticHtml())
        self.meshcat.DeleteRecording()
        return result


def _jsonl(records) -> str:
    return "".join(json.dumps(r, sort_keys=True) + "\n" for r in records)


def _print(*args, file=None):
    print(*args, file=file or sys.stdout, flush=True)


def _table_header() -> str:
    return (f"{'episode':>7}  {'greedy':>7}  {'greedy R':>8}  {'mean R':>8}  {'best R':>8}  "
            f"{'explore':>8}  {'fail':>4}  failures")


def _table_row(row: dict) -> str:
    fmt = lambda v: f"{v:8.1f}" if v is not None else f"{'-':>8}"  # noqa: E731
    failures = ", ".join(f"{k} {v}" for k, v in sorted(row.get("failures", {}).items())) or "-"
    n_fail = sum(row.get("failures", {}).values())
    return (f"{row['episode']:>7}  {'success' if row['greedy_success'] else 'failure':>7}  "
            f"{fmt(row['greedy_return'])}  {fmt(row.get('mean_return'))}  {fmt(row.get('best_return'))}  "
            f"{row['exploration']:8.4f}  {n_fail:>4}  {failures}")


def learn(skill_dir, out_dir, config: LearnConfig | None = None, *, station_config=None,
          rollout_config=None, workers: int = 1, ray_address: str | None = None, use_ray: bool = False,
          resume: bool = False, force: bool = False, meshcat=None, replay: bool = True,
          progress: bool = True, stop_after: int | None = None, log=None, runner=None) -> LearnOutcome:
    """Runs (or resumes) a learning run of the skill in ``skill_dir``; see the module docstring.

    station_config: the scenario (default ``scenario_for_skill``); rollout_config:
    :class:`~drake_skill.learning.rollout.RolloutConfig`; workers / ray_address /
    use_ray: where rollouts run (:func:`~drake_skill.learning.workers.make_pool`;
    they do not change the numbers); meshcat: watch live (greedy executions
    run in this process then); replay: write the HTML replays; stop_after:
    return after this many episodes in this call (checkpointed; ``resume``
    continues); log: a text stream for the tables (default stdout); runner: a
    built RolloutRunner to run every rollout on (``workers`` = 1; e.g. on the
    hardware station, ``drake-skill hardware run --episodes``).
    """
    from pydrake.common.yaml import yaml_dump_typed

    from drake_skill.learning.rollout import RolloutConfig
    from drake_skill.learning.workers import RunnerSpec, make_pool
    from drake_skill.skill import Skill
    from drake_skill.station.config import scenario_for_skill

    config = (config or LearnConfig()).validate()
    out_dir = Path(out_dir)
    skill_dir = Path(skill_dir)
    skill = Skill.load(skill_dir)
    if config.exploration_scale is None:
        config = dc.replace(config, exploration_scale=default_exploration_scale(skill.name))
    station_config = station_config if station_config is not None else scenario_for_skill(skill.name)
    rollout_config = (rollout_config or RolloutConfig()).validate()
    run_config = {"learn": dc.asdict(config), "skill": skill.name, "skill_dir": str(skill_dir.resolve()),
                  "station": yaml_dump_typed(station_config), "rollout": dc.asdict(rollout_config)}
    checkpoint = out_dir / "checkpoint"
    stream = log or sys.stdout

    # ----------------------------------------------------------- fresh or resumed
    if resume:
        if not (checkpoint / "state.json").is_file():
            raise FileNotFoundError(f"{checkpoint}: no checkpoint to resume (state.json missing); "
                                    "run without --resume to start")
        state = json.loads((checkpoint / "state.json").read_text())
        saved = json.loads((out_dir / "config.json").read_text())
        if saved != run_config:
            changed = sorted(k for k in set(saved) | set(run_config) if saved.get(k) != run_config.get(k))
            raise ValueError(f"{out_dir}: --resume with different settings than the run it continues "
                             f"({', '.join(changed)} differ); use the same options or another --out")
        search = policy_search_from_state(load_npz(checkpoint / "search.npz"))
        records, curve = state["records"], state["curve"]
        held_out_before, pending = state.get("held_out_before"), state.get("pending")
        if state.get("format", 1) == 1:         # one greedy execution pending, of the current mean
            pending = [] if pending is None else [{**pending, "mean": search.mean.tolist()}]
        _print(f"resuming {out_dir} after episode {search.episode} of {config.episodes}", file=stream)
    else:
        if (checkpoint / "state.json").exists() and not force:
            raise FileExistsError(f"{out_dir} holds a learning run (checkpoint/); pass --resume to continue "
                                  "it, --force to start over, or choose another --out")
        out_dir.mkdir(parents=True, exist_ok=True)
        for name in ("results.jsonl", "summary.json", "learning_curve.png", "replay_first.html",
                     "replay_last.html"):
            (out_dir / name).unlink(missing_ok=True)
        atomic_write_json(out_dir / "config.json", run_config)
        search = make_policy_search(config.method, skill.initial_weights,
                                    config.exploration_scale * skill.sigma0, **config.search_options())
        records, curve, held_out_before, pending = [], [], None, []
    per_step = config.method in PER_STEP_METHODS
    weighting = search.state_dict().get("option_weighting")   # the method's default when not given
    weighting = None if weighting is None else str(weighting)

    # ----------------------------------------------------------- pools and replays
    spec = RunnerSpec.create(skill_dir, station_config, rollout_config)
    viewer = None
    live = meshcat is not None
    if live or replay:
        from pydrake.geometry import Meshcat

        view_meshcat = meshcat if live else Meshcat()
        if not live:
            view_meshcat.Delete()
        viewer = spec.build(meshcat=view_meshcat)
        replayer = _Replay(view_meshcat, live)
        if live:
            frame_meshcat_camera(view_meshcat, station_config_object_xyz(station_config))
    local_runner = viewer if (live and int(workers) == 1 and not (use_ray or ray_address)) else None
    if runner is not None:                 # a given runner (the hardware station's): rollouts run on it
        local_runner = runner
    pool = make_pool(spec, workers, ray_address, use_ray, runner=local_runner)
    wall_start = time.perf_counter()

    def bar(total, desc):
        from tqdm import tqdm
        return tqdm(total=total, desc=desc, unit="rollout", disable=not progress, leave=False, file=sys.stderr)

    def greedy_path(episode: int) -> Path | None:
        if replay and episode == 0:
            return out_dir / "replay_first.html"
        if replay and episode == config.episodes:
            return out_dir / "replay_last.html"
        return None

    def held_out(phase: str) -> dict | None:
        if config.held_out <= 0:
            return None
        seeds = [config.held_out_seed0 + i for i in range(config.held_out)]
        b = bar(len(seeds), f"held-out poses ({phase})")
        try:
            report, _ = evaluate_greedy(pool, search.mean, seeds, lambda i, r: b.update(1))
        finally:
            b.close()
        record = {"type": "held_out", "phase": phase, "episode": search.episode, **report}
        records.append(record)
        _print(f"held-out greedy success {phase} learning: {report['success_rate'] * 100:.0f} % of "
               f"{len(seeds)} poses", file=stream)
        return record

    def save_checkpoint() -> None:
        state = search.state_dict()
        atomic_save_npz(checkpoint / "search.npz", {k: np.asarray(v) for k, v in state.items()})
        atomic_write_json(checkpoint / "state.json", {
            "format": _CHECKPOINT_FORMAT, "episode": search.episode, "records": records, "curve": curve,
            "held_out_before": held_out_before, "pending": pending})
        atomic_write_text(out_dir / "results.jsonl", _jsonl(records))

    try:
        if not resume:
            held_out_before = held_out("before")
            # Episode 0: the greedy execution before learning is still to run.
            pending = [{"episode": 0, "mean_return": None, "best_return": None,
                        "exploration": exploration_size(search), "failures": {},
                        "mean": search.mean.tolist()}]
            save_checkpoint()
            _print(f"{skill.name}: {config.method}, {config.reward} reward, weighting {weighting or '-'}, "
                   f"{config.episodes} episodes x {config.rollouts} rollouts, {pool.n_workers} worker(s)",
                   file=stream)
        _print(_table_header(), file=stream)
        for row in curve:
            _print(_table_row(row), file=stream)
        ran = 0
        exploration_at = {r["episode"]: r["exploration"] for r in records if "exploration" in r and r["type"] == "rollout"}
        # Each batch: an episode's rollouts, and beside them the greedy
        # executions of earlier updates once GREEDY_BATCH of them are due
        # (pending; each needs only its update's mean, kept with it). A
        # checkpoint follows every batch.
        while pending or search.episode < config.episodes:
            rollouts_now = search.episode < config.episodes
            if rollouts_now and stop_after is not None and ran >= stop_after:
                return LearnOutcome({"interrupted_after_episode": search.episode}, out_dir, False, search)
            due = pending if (not rollouts_now or len(pending) >= GREEDY_BATCH) else []
            tasks, greedy_results = [], []
            for p in due:
                g_seed, path = pose_seed(config.seed, p["episode"], None), greedy_path(p["episode"])
                if viewer is not None and (live or path is not None):
                    greedy_results.append(replayer.run(viewer, np.asarray(p["mean"]), g_seed, path))
                else:
                    greedy_results.append(None)
                    tasks.append((np.asarray(p["mean"]), g_seed))
            n_pooled = len(tasks)
            if rollouts_now:
                episode = search.episode + 1
                exploration_at[episode] = exploration_size(search)
                samples = search.ask(config.rollouts)
                seeds = [pose_seed(config.seed, episode, c) for c in range(config.rollouts)]
                tasks += list(zip(samples, seeds))
            desc = f"episode {search.episode + 1}/{config.episodes}" if rollouts_now else "greedy"
            results = []
            if tasks:
                b = bar(len(tasks), desc)
                try:
                    results = pool.map(tasks, lambda i, r: b.update(1))
                finally:
                    b.close()
            pooled, results = iter(results[:n_pooled]), results[n_pooled:]
            for p, greedy_result in zip(due, greedy_results):
                greedy_result = greedy_result if greedy_result is not None else next(pooled)
                g = {"type": "greedy", "episode": p["episode"], **greedy_result.summary()}
                records.append(g)
                row = {**{k: v for k, v in p.items() if k != "mean"}, "greedy_success": g["success"],
                       "greedy_return": g["dense_return"], "greedy_verdict": g["verdict"]}
                curve.append(row)
                records.append({"type": "episode", **row})
                _print(_table_row(row), file=stream)
            pending = pending[len(due):]
            if rollouts_now:
                values = episode_rewards(results, config.reward, per_step)
                search.tell(samples, values)
                returns = episode_rewards(results, config.reward, False)
                for c, r in enumerate(results):
                    records.append({"type": "rollout", "episode": episode, "index": c,
                                    "reward": float(returns[c]), "exploration": exploration_at[episode],
                                    **r.summary()})
                if episode % int(config.greedy_every) == 0 or episode == config.episodes:
                    pending.append(_block_row(records, episode, int(config.greedy_every), exploration_at,
                                              search.mean))
                ran += 1
            save_checkpoint()

        held_out_after = held_out("after")
        atomic_write_text(out_dir / "results.jsonl", _jsonl(records))
        # The learned skill: the initial DMP's weights replaced by the final mean.
        learned = dc.replace(skill, dmps=list(skill.dmps), info=dict(skill.info))
        learned.dmps[skill.initial_index] = dc.replace(skill.initial_dmp, weights=search.mean)
        learned.info["learning"] = {"method": config.method, "reward": config.reward,
                                    "weighting": weighting, "episodes": config.episodes,
                                    "rollouts": config.rollouts, "seed": config.seed,
                                    "initial_skill": str(skill_dir.resolve())}
        learned.save(out_dir / "skill", overwrite=True)
        plot_learning_curve(curve, out_dir / "learning_curve.png",
                            title=f"{skill.name}: {config.method}, {config.reward} reward")
        summary = {
            "skill": skill.name, "method": config.method, "reward": config.reward, "weighting": weighting,
            "episodes": config.episodes, "rollouts": config.rollouts, "seed": config.seed,
            "workers": pool.n_workers, "curve": curve,
            "greedy_success": [bool(c["greedy_success"]) for c in curve],
            "held_out_before": None if held_out_before is None else held_out_before["success_rate"],
            "held_out_after": None if held_out_after is None else held_out_after["success_rate"],
            "failures": dict(sum((Counter(c["failures"]) for c in curve), Counter())),
            "n_rollouts": config.episodes * config.rollouts,
            "wall_s_this_call": round(time.perf_counter() - wall_start, 1),
            "artifacts": [a for a in ARTIFACTS if (out_dir / a.rstrip("/")).exists() or a == "summary.json"],
        }
        atomic_write_json(out_dir / "summary.json", summary)
        return LearnOutcome(summary, out_dir, True, search)
    finally:
        pool.close()


def station_config_object_xyz(station_config) -> np.ndarray:
    """Nominal object position of a StationConfig [m]."""
    o = station_config.object
    return np.array([o.x, o.y, 0.0])
