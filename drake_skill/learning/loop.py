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

The run is a :class:`LearningRun` (settings, a :class:`RunState`, a pool)
whose methods are the steps above: :meth:`~LearningRun.start` or
:meth:`~LearningRun.resume`, :meth:`~LearningRun.batch` (an episode's
rollouts and update, with the due greedy executions),
:meth:`~LearningRun.checkpoint`, :meth:`~LearningRun.end`; :func:`learn`
drives one from start to end (``drake-skill learn``, the experiment grid's
runs, ``drake-skill hardware run --episodes``).

Artifacts in the output directory (:data:`ARTIFACTS`): ``config.json``
(the settings; ``versions``: the software versions and git commit the run
started with, which a resume does not compare), ``results.jsonl`` (one JSON
object per line: ``held_out``, ``greedy``, ``rollout`` and ``episode``
records, appended at each checkpoint), ``progress.csv`` (one row per
greedy-evaluated episode, appended as each is known; also the
``on_episode`` callback's argument and, with the ``tensorboard`` package
installed, the scalars in ``tensorboard/``; :mod:`~drake_skill.learning.runlog`),
``summary.json``, ``learning_curve.png``, ``skill/`` (the learned skill),
``replay_first.html`` / ``replay_last.html`` (Meshcat replays of the first
and last greedy executions) and ``checkpoint/`` (``search.npz`` + ``state.json``:
the :class:`RunState`, written after every batch; :func:`learn` with
``resume=True`` continues from it to the result an uninterrupted run gives,
and cuts the appended logs back to it first, so that they hold no record or
row twice). Every file but the appended logs is written atomically.

This module imports no Drake at import time; the pools and the Meshcat
replays import it when used.
"""

from __future__ import annotations

import dataclasses as dc
import sys
import time
from collections import Counter
from pathlib import Path
from typing import Any, Callable

import numpy as np

from drake_skill.common import frame_meshcat_camera
from drake_skill.fileio import atomic_save_npz, atomic_write_json, atomic_write_text, load_json, load_npz
from drake_skill.learning.config import REWARDS, LearnConfig
from drake_skill.learning.evaluation import HELD_OUT_SEED0, evaluate_greedy
from drake_skill.learning.plots import plot_learning_curve
from drake_skill.learning.policy_search import PER_STEP_METHODS, make_policy_search, policy_search_from_state
from drake_skill.learning.runlog import RunLog, software_versions

#: What to do with a run whose checkpoint or config.json is damaged (a copy cut short).
_DAMAGED_RUN = "the run cannot be resumed from it: start over with --force, or delete the run folder"

__all__ = ["ARTIFACTS", "HELD_OUT_SEED0", "REWARDS", "LearnConfig", "LearnOutcome", "LearningRun", "RunState",
           "episode_rewards", "learn", "pose_seed"]

#: What a learning run writes into its output directory (and ``tensorboard/`` where the
#: ``tensorboard`` package is installed).
ARTIFACTS = ("config.json", "results.jsonl", "progress.csv", "summary.json", "learning_curve.png", "skill/",
             "replay_first.html", "replay_last.html", "checkpoint/")


def exploration_scales_text() -> str:
    """The shipped skills' exploration scales (their skill files) for help texts: "close 1, draw 0.1, open 0.1"."""
    from drake_skill.skills import shipped_skills

    return ", ".join(f"{spec.name} {spec.exploration_scale:g}" for spec in shipped_skills())


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


@dc.dataclass
class RunState:
    """A learning run between two batches: what ``checkpoint/`` saves and a resume loads.

    search: the policy search (``search.npz``: its ``state_dict``, arrays
      only; ``search.episode`` updates done, ``search.mean`` W: (B, 7)).
    records: every record so far, in order (``results.jsonl``'s lines).
    curve: the learning-curve rows so far, one per greedy execution run.
    pending: greedy executions still to run, in episode order: each its
      curve row without the greedy result, and ``mean``, the weights W
      (B x 7, nested lists) it executes (its update's mean).
    held_out_before: the held-out record before learning (None: off).
    """

    search: Any
    records: list = dc.field(default_factory=list)
    curve: list = dc.field(default_factory=list)
    pending: list = dc.field(default_factory=list)
    held_out_before: dict | None = None

    def save(self, checkpoint: Path) -> None:
        """``checkpoint/search.npz`` and ``checkpoint/state.json``, each written atomically."""
        atomic_save_npz(checkpoint / "search.npz", {k: np.asarray(v) for k, v in self.search.state_dict().items()})
        atomic_write_json(checkpoint / "state.json", {
            "format": _CHECKPOINT_FORMAT, "episode": self.search.episode, "records": self.records,
            "curve": self.curve, "held_out_before": self.held_out_before, "pending": self.pending})

    @classmethod
    def load(cls, checkpoint: Path) -> "RunState":
        """The state :meth:`save` wrote (format 1: one pending greedy execution, of the current mean)."""
        state = load_json(checkpoint / "state.json", _DAMAGED_RUN)
        try:
            search = policy_search_from_state(load_npz(checkpoint / "search.npz"))
        except (KeyError, TypeError, IndexError, AttributeError) as e:   # arrays of another shape or kind
            raise ValueError(f"{checkpoint / 'search.npz'}: damaged checkpoint ({type(e).__name__}: {e}); "
                             f"{_DAMAGED_RUN}") from None
        try:
            pending = state.get("pending")
            if state.get("format", 1) == 1:
                pending = [] if pending is None else [{**pending, "mean": search.mean.tolist()}]
            records, curve = state["records"], state["curve"]
            if not (isinstance(records, list) and isinstance(curve, list) and isinstance(pending, list)):
                raise TypeError("records, curve and pending must be lists")
        except (KeyError, TypeError, AttributeError) as e:
            raise ValueError(f"{checkpoint / 'state.json'}: damaged checkpoint ({type(e).__name__}: {e}); "
                             f"{_DAMAGED_RUN}") from None
        return cls(search, records, curve, pending, state.get("held_out_before"))


class LearningRun:
    """One learning run into ``out_dir``: its settings, its :class:`RunState`, the pool it runs on.

    The steps (what :func:`learn` does with them)::

        run = LearningRun(skill_dir, out_dir, config, ...)   # settings only
        run.start(force) or run.resume()  # files, pool, held-out before (start)
        while not run.finished:
            run.batch()                   # an episode's rollouts + due greedy executions
            run.checkpoint()              # checkpoint/ and the appended logs
        outcome = run.end()               # held-out after, learned skill, plot, summary
        run.close()                       # the pool (also as a context manager)

    The arguments are :func:`learn`'s. ``state`` is None until started or
    resumed; the numbers depend on ``config`` alone (and the skill, station
    and rollout settings), not on the pool or on where a run was resumed.
    """

    def __init__(self, skill_dir, out_dir, config: LearnConfig | None = None, *, station_config=None,
                 rollout_config=None, workers: int = 1, ray_address: str | None = None, use_ray: bool = False,
                 meshcat=None, replay: bool = True, progress: bool = True, log=None, runner=None,
                 on_episode: Callable[[dict], None] | None = None):
        from pydrake.common.yaml import yaml_dump_typed

        from drake_skill.learning.rollout import RolloutConfig
        from drake_skill.skill import Skill

        config = (config or LearnConfig()).validate()
        self.skill_dir, self.out_dir = Path(skill_dir), Path(out_dir)
        self.skill = Skill.load(self.skill_dir)
        if config.exploration_scale is None:
            config = dc.replace(config, exploration_scale=float(self.skill.spec.exploration_scale))
        self.config = config
        self.station_config = station_config if station_config is not None else self.skill.station_config()
        self.rollout_config = (rollout_config or RolloutConfig()).validate()
        #: config.json without "versions": what a resume must find unchanged.
        self.run_config = {"learn": dc.asdict(config), "skill": self.skill.name,
                           "skill_dir": str(self.skill_dir.resolve()),
                           "station": yaml_dump_typed(self.station_config), "rollout": dc.asdict(self.rollout_config)}
        self.checkpoint_dir = self.out_dir / "checkpoint"
        self.stream = log or sys.stdout
        self.state: RunState | None = None
        self._pool_options = dict(workers=workers, ray_address=ray_address, use_ray=use_ray, runner=runner)
        self._meshcat, self._replay, self._progress = meshcat, replay, progress
        self._pool = self._viewer = self._replayer = None
        self._log = RunLog(self.out_dir, self.stream, config.rollouts, on_episode)
        self._logged = 0                      # records already in results.jsonl
        self._exploration_at: dict[int, float] = {}
        self._wall_start = time.perf_counter()

    # ------------------------------------------------------------------ start / resume
    def start(self, force: bool = False) -> RunState:
        """A fresh run: ``config.json`` (with ``versions``), the initial search, the held-out success
        before learning, the greedy execution of W_0 pending, the first checkpoint."""
        if (self.checkpoint_dir / "state.json").exists() and not force:
            raise FileExistsError(f"{self.out_dir} holds a learning run (checkpoint/); pass --resume to continue "
                                  "it, --force to start over, or choose another --out")
        self.out_dir.mkdir(parents=True, exist_ok=True)
        for name in ("results.jsonl", "progress.csv", "summary.json", "learning_curve.png", "replay_first.html",
                     "replay_last.html"):
            (self.out_dir / name).unlink(missing_ok=True)
        atomic_write_json(self.out_dir / "config.json", {**self.run_config, "versions": software_versions()})
        config = self.config
        search = make_policy_search(config.method, self.skill.initial_weights,
                                    config.exploration_scale * self.skill.sigma0, **config.search_options())
        self.state = RunState(search)
        self._open()
        self._log.start([], [], fresh=True)
        self.state.held_out_before = self._held_out("before")
        # Episode 0: the greedy execution before learning is still to run.
        self.state.pending = [{"episode": 0, "mean_return": None, "best_return": None,
                               "exploration": exploration_size(search), "failures": {},
                               "mean": search.mean.tolist()}]
        self.checkpoint()
        _print(f"{self.skill.name}: {config.method}, {config.reward} reward, weighting {self.weighting or '-'}, "
               f"{config.episodes} episodes x {config.rollouts} rollouts, {self._pool.n_workers} worker(s)",
               file=self.stream)
        self._print_table()
        return self.state

    def resume(self) -> RunState:
        """The run in ``out_dir`` from its checkpoint; refuses other settings. The logs are cut back
        to the checkpoint (:mod:`~drake_skill.learning.runlog`)."""
        if not (self.checkpoint_dir / "state.json").is_file():
            raise FileNotFoundError(f"{self.checkpoint_dir}: no checkpoint to resume (state.json missing); "
                                    "run without --resume to start")
        saved = load_json(self.out_dir / "config.json", _DAMAGED_RUN)
        started_with = saved.pop("versions", None)
        if saved != self.run_config:
            changed = sorted(k for k in set(saved) | set(self.run_config) if saved.get(k) != self.run_config.get(k))
            raise ValueError(f"{self.out_dir}: --resume with different settings than the run it continues "
                             f"({', '.join(changed)} differ); use the same options or another --out")
        self.state = RunState.load(self.checkpoint_dir)
        _print(f"resuming {self.out_dir} after episode {self.state.search.episode} of {self.config.episodes}",
               file=self.stream)
        if started_with is not None:
            now = software_versions()
            changed = [f"{k} {started_with.get(k)} -> {now[k]}" for k in now if started_with.get(k) != now[k]]
            if changed:
                _print(f"note: the run started with other software ({', '.join(changed)}); config.json keeps "
                       "the versions it started with", file=self.stream)
        self._open()
        self._log.start(self.state.records, self.state.curve, fresh=False)
        self._logged = len(self.state.records)
        self._print_table()
        return self.state

    def _open(self) -> None:
        """The replay viewer and the pool (:func:`~drake_skill.learning.workers.make_pool`)."""
        from drake_skill.learning.workers import RunnerSpec, make_pool

        spec = RunnerSpec.create(self.skill_dir, self.station_config, self.rollout_config)
        live = self._meshcat is not None
        if live or self._replay:
            from pydrake.geometry import Meshcat

            view_meshcat = self._meshcat if live else Meshcat()
            if not live:
                view_meshcat.Delete()
            self._viewer = spec.build(meshcat=view_meshcat)
            self._replayer = _Replay(view_meshcat, live)
            if live:
                frame_meshcat_camera(view_meshcat, station_config_object_xyz(self.station_config))
        options = self._pool_options
        local_runner = self._viewer if (live and int(options["workers"]) == 1
                                        and not (options["use_ray"] or options["ray_address"])) else None
        if options["runner"] is not None:      # a given runner (the hardware station's): rollouts run on it
            local_runner = options["runner"]
        self._pool = make_pool(spec, options["workers"], options["ray_address"], options["use_ray"],
                               runner=local_runner)
        self._exploration_at = {r["episode"]: r["exploration"] for r in self.state.records
                                if "exploration" in r and r["type"] == "rollout"}
        self._wall_start = time.perf_counter()

    def close(self) -> None:
        """Closes the pool and the logs (idempotent)."""
        if self._pool is not None:
            self._pool.close()
            self._pool = None
        self._log.close()

    def __enter__(self) -> "LearningRun":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # ------------------------------------------------------------------ the batches
    @property
    def weighting(self) -> str | None:
        """The rollout weighting the search uses (the method's default when not given; None: none)."""
        weighting = self.state.search.state_dict().get("option_weighting")
        return None if weighting is None else str(weighting)

    @property
    def rollouts_left(self) -> bool:
        """Whether updates remain (``search.episode`` < episodes)."""
        return self.state.search.episode < self.config.episodes

    @property
    def finished(self) -> bool:
        """No update and no greedy execution left: :meth:`end` is next."""
        return not self.state.pending and not self.rollouts_left

    def batch(self) -> bool:
        """One batch: the next episode's C rollouts and its update (while updates remain), with the
        pending greedy executions beside them once :data:`GREEDY_BATCH` are due (all, after the last
        update). Returns whether it ran rollouts. Records, curve rows and the progress log follow;
        the checkpoint is :meth:`checkpoint`'s."""
        config, state = self.config, self.state
        search = state.search
        rollouts_now = self.rollouts_left
        due = state.pending if (not rollouts_now or len(state.pending) >= GREEDY_BATCH) else []
        tasks, greedy_results = [], []
        for p in due:
            g_seed, path = pose_seed(config.seed, p["episode"], None), self._greedy_path(p["episode"])
            if self._viewer is not None and (self._meshcat is not None or path is not None):
                greedy_results.append(self._replayer.run(self._viewer, np.asarray(p["mean"]), g_seed, path))
            else:
                greedy_results.append(None)
                tasks.append((np.asarray(p["mean"]), g_seed))
        n_pooled = len(tasks)
        if rollouts_now:
            episode = search.episode + 1
            self._exploration_at[episode] = exploration_size(search)
            samples = search.ask(config.rollouts)
            seeds = [pose_seed(config.seed, episode, c) for c in range(config.rollouts)]
            tasks += list(zip(samples, seeds))
        results = self._map(tasks, f"episode {search.episode + 1}/{config.episodes}" if rollouts_now else "greedy")
        pooled, results = iter(results[:n_pooled]), results[n_pooled:]
        for p, greedy_result in zip(due, greedy_results):
            greedy_result = greedy_result if greedy_result is not None else next(pooled)
            g = {"type": "greedy", "episode": p["episode"], **greedy_result.summary()}
            state.records.append(g)
            row = {**{k: v for k, v in p.items() if k != "mean"}, "greedy_success": g["success"],
                   "greedy_return": g["dense_return"], "greedy_verdict": g["verdict"]}
            state.curve.append(row)
            state.records.append({"type": "episode", **row})
            _print(_table_row(row), file=self.stream)
            self._log.row(row)
        state.pending = state.pending[len(due):]
        if rollouts_now:
            search.tell(samples, episode_rewards(results, config.reward, config.method in PER_STEP_METHODS))
            returns = episode_rewards(results, config.reward, False)
            for c, r in enumerate(results):
                state.records.append({"type": "rollout", "episode": episode, "index": c,
                                      "reward": float(returns[c]), "exploration": self._exploration_at[episode],
                                      **r.summary()})
            if episode % int(config.greedy_every) == 0 or episode == config.episodes:
                state.pending.append(_block_row(state.records, episode, int(config.greedy_every),
                                                self._exploration_at, search.mean))
        return rollouts_now

    def checkpoint(self) -> None:
        """Appends the new records to ``results.jsonl``, then saves the state to ``checkpoint/``."""
        self._flush_records()
        self.state.save(self.checkpoint_dir)

    def _flush_records(self) -> None:
        self._log.records(self.state.records[self._logged:])
        self._logged = len(self.state.records)

    # ------------------------------------------------------------------ the end
    def end(self) -> LearnOutcome:
        """Held-out success after learning, the learned skill (``skill/``), ``learning_curve.png`` and
        ``summary.json``."""
        config, state, skill = self.config, self.state, self.skill
        held_out_after = self._held_out("after")
        self._flush_records()
        # The learned skill: the initial DMP's weights replaced by the final mean.
        learned = dc.replace(skill, dmps=list(skill.dmps), info=dict(skill.info))
        learned.dmps[skill.initial_index] = dc.replace(skill.initial_dmp, weights=state.search.mean)
        learned.info["learning"] = {"method": config.method, "reward": config.reward,
                                    "weighting": self.weighting, "episodes": config.episodes,
                                    "rollouts": config.rollouts, "seed": config.seed,
                                    "initial_skill": str(self.skill_dir.resolve())}
        learned.save(self.out_dir / "skill", overwrite=True)
        plot_learning_curve(state.curve, self.out_dir / "learning_curve.png",
                            title=f"{skill.name}: {config.method}, {config.reward} reward")
        curve = state.curve
        summary = {
            "skill": skill.name, "method": config.method, "reward": config.reward, "weighting": self.weighting,
            "episodes": config.episodes, "rollouts": config.rollouts, "seed": config.seed,
            "workers": self._pool.n_workers, "curve": curve,
            "greedy_success": [bool(c["greedy_success"]) for c in curve],
            "held_out_before": None if state.held_out_before is None else state.held_out_before["success_rate"],
            "held_out_after": None if held_out_after is None else held_out_after["success_rate"],
            "failures": dict(sum((Counter(c["failures"]) for c in curve), Counter())),
            "n_rollouts": config.episodes * config.rollouts,
            "wall_s_this_call": round(time.perf_counter() - self._wall_start, 1),
            "artifacts": [a for a in (*ARTIFACTS, "tensorboard/")
                          if (self.out_dir / a.rstrip("/")).exists() or a == "summary.json"],
        }
        atomic_write_json(self.out_dir / "summary.json", summary)
        return LearnOutcome(summary, self.out_dir, True, state.search)

    def interrupted(self) -> LearnOutcome:
        """The outcome of a run stopped after a checkpoint (``resume`` continues it)."""
        return LearnOutcome({"interrupted_after_episode": self.state.search.episode}, self.out_dir, False,
                            self.state.search)

    # ------------------------------------------------------------------ helpers
    def _bar(self, total: int, desc: str):
        from tqdm import tqdm
        return tqdm(total=total, desc=desc, unit="rollout", disable=not self._progress, leave=False, file=sys.stderr)

    def _map(self, tasks, desc: str) -> list:
        """``pool.map`` of (weights, seed) tasks with a progress bar."""
        if not tasks:
            return []
        b = self._bar(len(tasks), desc)
        try:
            return self._pool.map(tasks, lambda i, r: b.update(1))
        finally:
            b.close()

    def _greedy_path(self, episode: int) -> Path | None:
        """Where the replay of the greedy execution after update ``episode`` goes (first and last only)."""
        if self._replay and episode == 0:
            return self.out_dir / "replay_first.html"
        if self._replay and episode == self.config.episodes:
            return self.out_dir / "replay_last.html"
        return None

    def _held_out(self, phase: str) -> dict | None:
        """The greedy success of the current mean on the held-out poses, as a record (None: off)."""
        config = self.config
        if config.held_out <= 0:
            return None
        seeds = [config.held_out_seed0 + i for i in range(config.held_out)]
        b = self._bar(len(seeds), f"held-out poses ({phase})")
        try:
            report, _ = evaluate_greedy(self._pool, self.state.search.mean, seeds, lambda i, r: b.update(1))
        finally:
            b.close()
        record = {"type": "held_out", "phase": phase, "episode": self.state.search.episode, **report}
        self.state.records.append(record)
        _print(f"held-out greedy success {phase} learning: {report['success_rate'] * 100:.0f} % of "
               f"{len(seeds)} poses", file=self.stream)
        return record

    def _print_table(self) -> None:
        _print(_table_header(), file=self.stream)
        for row in self.state.curve:
            _print(_table_row(row), file=self.stream)


def learn(skill_dir, out_dir, config: LearnConfig | None = None, *, station_config=None,
          rollout_config=None, workers: int = 1, ray_address: str | None = None, use_ray: bool = False,
          resume: bool = False, force: bool = False, meshcat=None, replay: bool = True,
          progress: bool = True, stop_after: int | None = None, log=None, runner=None,
          on_episode: Callable[[dict], None] | None = None) -> LearnOutcome:
    """Runs (or resumes) a learning run of the skill in ``skill_dir``: a :class:`LearningRun`
    driven to its end; see the module docstring.

    station_config: the scenario (default the skill's, ``Skill.station_config``); rollout_config:
    :class:`~drake_skill.learning.rollout.RolloutConfig`; workers / ray_address /
    use_ray: where rollouts run (:func:`~drake_skill.learning.workers.make_pool`;
    they do not change the numbers); meshcat: watch live (greedy executions
    run in this process then); replay: write the HTML replays; stop_after:
    return after this many episodes in this call (checkpointed; ``resume``
    continues); log: a text stream for the tables (default stdout); runner: a
    built RolloutRunner to run every rollout on (``workers`` = 1; e.g. on the
    hardware station, ``drake-skill hardware run --episodes``); on_episode:
    called with each ``progress.csv`` row (a dict,
    :func:`~drake_skill.learning.runlog.progress_row`) after its greedy
    execution, in episode order (after a resume: from the first row not in
    the checkpoint).
    """
    with LearningRun(skill_dir, out_dir, config, station_config=station_config, rollout_config=rollout_config,
                     workers=workers, ray_address=ray_address, use_ray=use_ray, meshcat=meshcat, replay=replay,
                     progress=progress, log=log, runner=runner, on_episode=on_episode) as run:
        if resume:
            run.resume()
        else:
            run.start(force=force)
        batches = 0
        while not run.finished:
            if run.rollouts_left and stop_after is not None and batches >= stop_after:
                return run.interrupted()
            batches += run.batch()
            run.checkpoint()
        return run.end()


def station_config_object_xyz(station_config) -> np.ndarray:
    """Nominal object position of a StationConfig [m]."""
    o = station_config.object
    return np.array([o.x, o.y, 0.0])
