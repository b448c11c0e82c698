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
    select the returned mean (guarded: W_0, best greedy, W_E on shared poses)
    held-out greedy success of the selected mean         (after learning)

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

The run is a :class:`LearningRun` (settings, a typed
:class:`~drake_skill.learning.runstate.RunState`, a pool) whose methods are
the steps above: :meth:`~LearningRun.start` or :meth:`~LearningRun.resume`;
per batch :meth:`~LearningRun.ask` (the samples and the due greedy
executions, a :class:`Batch`), :meth:`~LearningRun.evaluate` (their
executions), :meth:`~LearningRun.tell` (records, the update, the next
greedy execution) and :meth:`~LearningRun.checkpoint`; then
:meth:`~LearningRun.select` (docs/method.md 5.1) inside
:meth:`~LearningRun.end`; :func:`learn` drives one from start to end (``drake-skill learn``, the experiment grid's
runs, ``drake-skill hardware run --episodes``).

Artifacts in the output directory (:data:`ARTIFACTS`): ``config.json``
(the settings; ``versions``: the software versions and git commit the run
started with, which a resume does not compare), ``results.jsonl`` (one JSON
object per line: ``held_out``, ``greedy``, ``rollout`` and ``episode``
records, appended at each checkpoint), ``progress.csv`` (one row per
greedy-evaluated episode, appended as each is known; also the
``on_episode`` callback's argument and, with the ``tensorboard`` package
installed, the scalars in ``tensorboard/``; :mod:`~drake_skill.learning.runlog`),
``summary.json``, ``learning_curve.png``, ``report.html`` (the run on one page:
:mod:`~drake_skill.learning.run_report`), ``skill/`` (the learned skill),
``replay_first.html`` / ``replay_last.html`` (Meshcat replays of the first
and last greedy executions), ``rollouts/`` (every rollout's weights, seed,
path and last camera frame, and a failed one's frames up to its stop:
:mod:`~drake_skill.learning.rollout_store`; ``drake-skill replay`` shows
any of them) and ``checkpoint/`` (``search.npz`` + ``state.json``:
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

from drake_skill.common import frame_meshcat_camera, recorded_html
from drake_skill.fileio import atomic_write_json, atomic_write_text, load_json
from drake_skill.learning import selection
from drake_skill.learning.config import REWARDS, LearnConfig
from drake_skill.learning.evaluation import HELD_OUT_SEED0, evaluate_greedy
from drake_skill.learning.rollout_store import rollouts_path, save_rollouts
from drake_skill.learning.run_report import write_run_report
from drake_skill.learning.exploration import SpanExploration, skill_covariance
from drake_skill.learning.plots import plot_learning_curve
from drake_skill.learning.policy_search import PER_STEP_METHODS, make_policy_search
from drake_skill.learning.runlog import RunLog, software_versions
from drake_skill.learning.runstate import (DAMAGED_RUN, RunState, curve_row, episode_rewards, exploration_size,
                                           pose_seed)

__all__ = ["ARTIFACTS", "HELD_OUT_SEED0", "REWARDS", "LearnConfig", "LearnOutcome", "LearningRun", "RunState",
           "episode_rewards", "learn", "pose_seed"]

#: What a learning run writes into its output directory (and ``tensorboard/`` where the
#: ``tensorboard`` package is installed).
ARTIFACTS = ("config.json", "results.jsonl", "progress.csv", "summary.json", "learning_curve.png",
             "return_vs_state.png", "report.html", "skill/",
             "replay_first.html", "replay_last.html", "rollouts/", "checkpoint/")


def exploration_scales_text() -> str:
    """The shipped skills' exploration scales (their skill files) for help texts: "close 1, draw 0.1, open 0.1"."""
    from drake_skill.skills import shipped_skills

    return ", ".join(f"{spec.name} {spec.exploration_scale:g}" for spec in shipped_skills())


#: Greedy executions wait until this many are due and then run beside the next
#: episode's rollouts (all that are left after the last update). One greedy
#: execution beside an even number of rollouts would leave one of two workers
#: idle for a whole rollout every episode; two fill that slot. A constant, not
#: the number of workers, so that the records come out in the same order on
#: any pool.
GREEDY_BATCH = 2


@dc.dataclass
class LearnOutcome:
    """What :func:`learn` returns: the summary (also in ``summary.json``) and paths."""

    summary: dict
    out_dir: Path
    complete: bool
    search: Any = None
    #: The policy the run returns (B x 7): the selected mean (``LearnConfig.select``); None until complete.
    weights: Any = None


@dc.dataclass
class Batch:
    """What :meth:`LearningRun.ask` hands :meth:`~LearningRun.evaluate` and :meth:`~LearningRun.tell`.

    due: the pending greedy executions that run now (their curve rows with ``mean``);
    greedy: their (weights (B, 7), pose seed) tasks; episode: the update these
    rollouts feed (None: no update left, greedy executions only); samples:
    (C, B, 7) weights drawn by the search; seeds: their pose seeds.
    """

    due: list
    greedy: list
    episode: int | None = None
    samples: Any = None
    seeds: list = dc.field(default_factory=list)


class _Replay:
    """Meshcat recordings of greedy executions, saved as standalone HTML."""

    def __init__(self, meshcat, live: bool):
        self.meshcat = meshcat
        self.live = live

    def run(self, runner, weights, seed, path: Path | None):
        if path is None:
            return runner.run(weights, seed)
        frame_meshcat_camera(self.meshcat, runner.station.random_object_pose(seed).translation())
        result, html = recorded_html(self.meshcat, lambda: runner.run(weights, seed), live=self.live)
        atomic_write_text(path, html)
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
        from drake_skill.fitted_skill import Skill

        config = (config or LearnConfig()).validate()
        self.skill_dir, self.out_dir = Path(skill_dir), Path(out_dir)
        self.skill = Skill.load(self.skill_dir)
        if config.exploration_scale is None:       # span: sigma_0 = 1 on the demonstrations' own covariance
            scale = 1.0 if config.exploration == "span" else float(self.skill.spec.exploration_scale)
            config = dc.replace(config, exploration_scale=scale)
        #: The span the search runs in (``exploration: span``, docs/method.md 5.2); None: the weights W.
        self.span = SpanExploration.of_skill(self.skill) if config.exploration == "span" else None
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
                     "replay_last.html", "report.html", "return_vs_state.png"):
            (self.out_dir / name).unlink(missing_ok=True)
        for stale in (self.out_dir / "rollouts").glob("*.npz"):
            stale.unlink()
        atomic_write_json(self.out_dir / "config.json", {**self.run_config, "versions": software_versions()})
        config = self.config
        if self.span is not None:
            start, covariance = self.span.origin_theta(), self.span.initial_covariance()
        else:
            start, covariance = self.skill.initial_weights, skill_covariance(self.skill, config.approach_exploration)
        search = make_policy_search(config.method, start, config.exploration_scale * covariance,
                                    **config.search_options())
        self.state = RunState(search)
        self._open()
        self._log.start([], [], fresh=True)
        self.state.held_out_before = self._held_out("before")
        # Episode 0: the greedy execution before learning is still to run.
        self.state.pending = [{"episode": 0, "mean_return": None, "best_return": None,
                               "exploration": exploration_size(search), "failures": {},
                               "mean": self.weights_of(search.mean).tolist()}]
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
        saved = load_json(self.out_dir / "config.json", DAMAGED_RUN)
        started_with = saved.pop("versions", None)
        from drake_skill.station.scenario import same_station

        if isinstance(saved.get("station"), str) and same_station(saved["station"], self.run_config["station"]):
            saved["station"] = self.run_config["station"]
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
    def weights_of(self, point) -> np.ndarray:
        """The DMP weights W (B, 7) of a point of the search (a batch (S, ...) -> (S, B, 7)): the point
        itself, or with ``exploration: span`` its image W_0 + sum_d theta_d (W_d - W_0)."""
        point = np.asarray(point)
        if self.span is None:
            return point
        return self.span.weights(point)

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
        """One batch: :meth:`ask`, :meth:`evaluate`, :meth:`tell`. Returns whether it ran rollouts;
        the checkpoint is :meth:`checkpoint`'s."""
        batch = self.ask()
        self.tell(batch, self.evaluate(batch))
        return batch.episode is not None

    def ask(self) -> "Batch":
        """What runs next: the next episode's C samples and their pose seeds (while updates remain),
        and the pending greedy executions once :data:`GREEDY_BATCH` are due (all, after the last update)."""
        config, state = self.config, self.state
        search = state.search
        due = state.pending if (not self.rollouts_left or len(state.pending) >= GREEDY_BATCH) else []
        greedy = [(np.asarray(p["mean"]), pose_seed(config.seed, p["episode"], None)) for p in due]
        if not self.rollouts_left:
            return Batch(due, greedy)
        episode = search.episode + 1
        self._exploration_at[episode] = exploration_size(search)
        samples = search.ask(config.rollouts)
        seeds = [pose_seed(config.seed, episode, c) for c in range(config.rollouts)]
        return Batch(due, greedy, episode, samples, seeds)

    def evaluate(self, batch: "Batch") -> list:
        """The batch's executions, greedy ones first: those with a replay or the live view run on the
        viewer, the rest beside the rollouts on the pool."""
        viewed = {}
        for k, (p, (weights, seed)) in enumerate(zip(batch.due, batch.greedy)):
            path = self._greedy_path(p["episode"])
            if self._viewer is not None and (self._meshcat is not None or path is not None):
                viewed[k] = self._replayer.run(self._viewer, weights, seed, path)
        tasks = [t for k, t in enumerate(batch.greedy) if k not in viewed]
        if batch.episode is not None:
            tasks += list(zip(self.weights_of(batch.samples), batch.seeds))
        desc = f"episode {batch.episode}/{self.config.episodes}" if batch.episode is not None else "greedy"
        pooled = iter(self._map(tasks, desc))
        greedy = [viewed[k] if k in viewed else next(pooled) for k in range(len(batch.greedy))]
        return greedy + list(pooled)

    def tell(self, batch: "Batch", results: list) -> None:
        """Records the batch's results: each greedy execution's record and curve row (printed, logged),
        then the rollouts' records, the search's update and the next pending greedy execution."""
        config, state = self.config, self.state
        n = len(batch.due)
        for p, result in zip(batch.due, results[:n]):
            save_rollouts(rollouts_path(self.out_dir, f"greedy_{p['episode']:03d}"), [result])
            g = {"type": "greedy", "episode": p["episode"], **result.summary()}
            state.records.append(g)
            state.candidates[str(p["episode"])] = p["mean"]
            row = {**{k: v for k, v in p.items() if k != "mean"}, "greedy_success": g["success"],
                   "greedy_return": g["dense_return"], "greedy_verdict": g["verdict"]}
            state.curve.append(row)
            state.records.append({"type": "episode", **row})
            _print(_table_row(row), file=self.stream)
            self._log.row(row)
        state.pending = state.pending[n:]
        if batch.episode is None:
            return
        rollouts, episode, search = results[n:], batch.episode, state.search
        save_rollouts(rollouts_path(self.out_dir, f"episode_{episode:03d}"), rollouts)
        search.tell(batch.samples, episode_rewards(rollouts, config.reward, config.method in PER_STEP_METHODS))
        returns = episode_rewards(rollouts, config.reward, False)
        for c, r in enumerate(rollouts):
            state.records.append({"type": "rollout", "episode": episode, "index": c, "reward": float(returns[c]),
                                  "exploration": self._exploration_at[episode], **r.summary()})
        if episode % int(config.greedy_every) == 0 or episode == config.episodes:
            state.pending.append(curve_row(state.records, episode, int(config.greedy_every),
                                           self._exploration_at, self.weights_of(search.mean)))

    def select(self) -> tuple[np.ndarray, dict]:
        """The weights the run returns and the ``select`` record (docs/method.md 5.1,
        :mod:`~drake_skill.learning.selection`): with ``select: last`` the final mean; guarded, the best of
        the start, the best-scoring greedy mean and the final mean on ``select_poses`` shared poses,
        judged by the learned verdict and return alone. Run after the last update."""
        config, state = self.config, self.state
        last = state.search.episode
        if config.select == "last":
            return self.weights_of(state.search.mean), {"type": "select", "rule": "last", "episode": last}
        means = {0: self.skill.initial_weights, last: self.weights_of(state.search.mean)}
        best = selection.best_greedy_episode(r for r in state.records if r["type"] == "greedy")
        if best is not None and str(best) in state.candidates:
            means.setdefault(best, np.asarray(state.candidates[str(best)]))
        seeds = [selection.select_seed(config.seed, k) for k in range(int(config.select_poses))]
        episodes = sorted(means)
        tasks = [(means[e], s) for e in episodes for s in seeds]
        executed = list(self._map(tasks, "selection"))
        save_rollouts(rollouts_path(self.out_dir, "select"), executed)
        results = iter(executed)
        candidates = [selection.Candidate(e, [next(results).summary() for _ in seeds]) for e in episodes]
        chosen = selection.choose(candidates)
        record = {"type": "select", "rule": "guarded", "episode": chosen.episode, "seeds": seeds,
                  "candidates": [c.record() for c in candidates]}
        state.records.append(record)
        _print(f"selected the mean after update {chosen.episode} (" + ", ".join(
            f"update {c.episode}: {c.score[0]}/{len(seeds)} verdicts, mean R {c.score[1]:.1f}" for c in candidates)
            + ")", file=self.stream)
        return means[chosen.episode], record

    def checkpoint(self) -> None:
        """Appends the new records to ``results.jsonl``, then saves the state to ``checkpoint/``."""
        self._flush_records()
        self.state.save(self.checkpoint_dir)

    def _flush_records(self) -> None:
        self._log.records(self.state.records[self._logged:])
        self._logged = len(self.state.records)

    # ------------------------------------------------------------------ the end
    def end(self) -> LearnOutcome:
        """The selected policy (:meth:`select`), its held-out success, the learned skill (``skill/``),
        ``learning_curve.png`` and ``summary.json``."""
        config, state = self.config, self.state
        weights, chosen = self.select()
        held_out_after = self._held_out("after", weights)
        self._flush_records()
        self._save_learned_skill(weights, chosen["episode"])
        plot_learning_curve(state.curve, self.out_dir / "learning_curve.png",
                            title=f"{self.skill.name}: {config.method}, {config.reward} reward")
        curve = state.curve
        summary = {
            "skill": self.skill.name, "method": config.method, "reward": config.reward, "weighting": self.weighting,
            "episodes": config.episodes, "rollouts": config.rollouts, "seed": config.seed,
            "workers": self._pool.n_workers, "curve": curve,
            "greedy_success": [bool(c["greedy_success"]) for c in curve],
            "held_out_before": None if state.held_out_before is None else state.held_out_before["success_rate"],
            "held_out_after": None if held_out_after is None else held_out_after["success_rate"],
            "select": config.select, "selected_episode": chosen["episode"], **self._reward_quality(),
            "failures": dict(sum((Counter(c["failures"]) for c in curve), Counter())),
            "n_rollouts": config.episodes * config.rollouts,
            "n_executions": sum(1 for r in state.records if r["type"] in ("rollout", "greedy"))
            + len(chosen.get("seeds", [])) * len(chosen.get("candidates", [])),
            "wall_s_this_call": round(time.perf_counter() - self._wall_start, 1),
            "artifacts": [a for a in (*ARTIFACTS, "tensorboard/")
                          if (self.out_dir / a.rstrip("/")).exists() or a in ("summary.json", "report.html")],
        }
        atomic_write_json(self.out_dir / "summary.json", summary)
        write_run_report(self.out_dir, state.records, summary)
        return LearnOutcome(summary, self.out_dir, True, state.search, weights)

    def _reward_quality(self) -> dict:
        """``reward_auc``, ``verdict_fpr``, ``verdict_fnr`` (:func:`~drake_skill.learning.reward_quality.
        reward_quality`) and ``reflex_rate`` over the run's rollouts, and ``return_vs_state.png``; on the
        robot, where no execution has a ground-truth object state (NaN), only ``reflex_rate``."""
        from drake_skill.learning.reward_quality import (SUMMARY_KEYS, plot_return_vs_state, reflex_rate,
                                                         reward_quality)

        rollouts = [r for r in self.state.records if r["type"] == "rollout"]
        reflex = {"reflex_rate": reflex_rate(rollouts)}
        executions = (r for r in self.state.records if r["type"] in ("rollout", "greedy"))
        if not any(r.get("final_object_state") is not None for r in executions):
            return reflex
        rule = self.skill.spec.success
        quality = reward_quality(rollouts, rule)
        plot_return_vs_state(rollouts, rule, self.out_dir / "return_vs_state.png",
                             title=f"{self.skill.name}: learned return of the run's rollouts")
        return {**{k: quality[k] for k in SUMMARY_KEYS}, **reflex}

    def _save_learned_skill(self, weights, episode: int) -> None:
        """``skill/``: the initial DMP's weights replaced by ``weights`` (the mean after update ``episode``)."""
        config, skill = self.config, self.skill
        learned = dc.replace(skill, dmps=list(skill.dmps), info=dict(skill.info))
        learned.dmps[skill.initial_index] = dc.replace(skill.initial_dmp, weights=np.asarray(weights))
        learned.info["learning"] = {"method": config.method, "reward": config.reward,
                                    "weighting": self.weighting, "episodes": config.episodes,
                                    "rollouts": config.rollouts, "seed": config.seed, "select": config.select,
                                    "selected_episode": int(episode),
                                    "initial_skill": str(self.skill_dir.resolve())}
        learned.save(self.out_dir / "skill", overwrite=True)

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

    def _held_out(self, phase: str, weights=None) -> dict | None:
        """The greedy success of ``weights`` (default: the current mean) on the held-out poses, as a
        record (None: off)."""
        config = self.config
        if config.held_out <= 0:
            return None
        seeds = [config.held_out_seed0 + i for i in range(config.held_out)]
        b = self._bar(len(seeds), f"held-out poses ({phase})")
        weights = self.weights_of(self.state.search.mean) if weights is None else weights
        try:
            report, results = evaluate_greedy(self._pool, weights, seeds, lambda i, r: b.update(1))
        finally:
            b.close()
        save_rollouts(rollouts_path(self.out_dir, f"held_out_{phase}"), results)
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
    """Nominal object position of a Scenario [m]."""
    o = station_config.object
    return np.array([o.x, o.y, 0.0])
