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
from typing import Any, Callable

import numpy as np

from drake_skill.fileio import atomic_save_npz, atomic_write_json, atomic_write_text, load_npz
from drake_skill.learning.policy_search import METHODS, PER_STEP_METHODS, make_policy_search, policy_search_from_state

__all__ = ["ARTIFACTS", "HELD_OUT_SEED0", "LearnConfig", "LearnOutcome", "episode_rewards", "evaluate_greedy",
           "evaluate_skill", "evaluation_table",
           "frame_meshcat_camera", "learn", "plot_learning_curve", "pose_seed"]

#: First seed of the held-out object poses (drake-skill evaluate uses the same).
HELD_OUT_SEED0 = 900_000

#: What a learning run writes into its output directory.
ARTIFACTS = ("config.json", "results.jsonl", "summary.json", "learning_curve.png", "skill/",
             "replay_first.html", "replay_last.html", "checkpoint/")

REWARDS = ("dense", "sparse")

def exploration_scales_text() -> str:
    """The shipped skills' exploration scales (their skill files) for help texts: "close 1, draw 0.1, open 0.1"."""
    from drake_skill.skills import shipped_skills

    return ", ".join(f"{spec.name} {spec.exploration_scale:g}" for spec in shipped_skills())


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
      skill file's ``exploration_scale`` (``learn`` saves the value it used).
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
    not fail) and ``object_poses`` (the object's true placement on the table,
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


def exploration_size(search) -> float:
    """RMS standard deviation of the sampling distribution: sqrt(mean_b trace(s Sigma_b) / D)."""
    cov = search.sampling_covariances
    return float(np.sqrt(np.mean(np.trace(cov, axis1=1, axis2=2)) / cov.shape[-1]))


def frame_meshcat_camera(meshcat, object_xyz) -> None:
    """Points Meshcat's camera at the robot and the object (robot base at the world origin)."""
    target = 0.5 * np.asarray(object_xyz, dtype=float) + np.array([0.0, 0.0, 0.25])   # between base and object
    meshcat.SetCameraPose(target + np.array([0.9, -1.3, 0.55]), target)


def plot_learning_curve(curve: list[dict], path, title: str = "") -> Path:
    """Greedy success and returns per episode (0 = before learning) to a PNG."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from drake_skill.fileio import write_figure_png

    episodes = [c["episode"] for c in curve]
    fig, (ax_s, ax_r) = plt.subplots(1, 2, figsize=(10, 3.8))
    ax_s.plot(episodes, [float(c["greedy_success"]) for c in curve], "o-", color="tab:green")
    ax_s.set_ylim(-0.05, 1.05)
    ax_s.set_xlabel("episode (update)")
    ax_s.set_ylabel("greedy success (ground truth)")
    ax_s.set_xticks(episodes)
    ax_r.plot(episodes, [c["greedy_return"] for c in curve], "o-", label="greedy return")
    learned = [c for c in curve if c.get("mean_return") is not None]
    if learned:
        ax_r.plot([c["episode"] for c in learned], [c["mean_return"] for c in learned], "s--", label="mean rollout return")
        ax_r.plot([c["episode"] for c in learned], [c["best_return"] for c in learned], "^:", label="best rollout return")
    ax_r.set_xlabel("episode (update)")
    ax_r.set_ylabel("learned return R(G)")
    ax_r.set_xticks(episodes)
    ax_r.legend(fontsize=8)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    try:
        return write_figure_png(fig, path, dpi=110)
    finally:
        plt.close(fig)


#: Marker and colour per rollout outcome in :func:`plot_outcomes_by_placement`.
_OUTCOME_STYLE = {"success": ("o", "tab:green"), "not achieved": ("o", "tab:orange"),
                  "reflex": ("X", "tab:red")}


def plot_outcomes_by_placement(report: dict[str, Any], path, title: str = "") -> Path:
    """Where on the table each rollout of an :func:`evaluate_skill` or
    :func:`explore_skill` report succeeded, to a PNG: one panel per policy,
    each object placement (x, y [mm], its x axis drawn for the yaw) marked by
    the outcome (success; run to the end without success, labelled with the
    final lid angle [rad] or drawer travel [m]; a failure, by reason).

    Plain imitation of a DMP succeeds in a band of placements around its
    demonstration's (docs/method.md section 6): the plot shows the band.
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from drake_skill.fileio import write_figure_png

    if "policies" in report:
        panels = []
        for index, p in report["policies"].items():
            role = " (learned)" if p["initial"] and report.get("learned") else " (initial)" if p["initial"] else ""
            panels.append((f"DMP {index}{role}", p))
    else:
        panels = [(f"{len(report['seeds'])} exploratory rollouts", report)]
    fig, axes = plt.subplots(1, len(panels), figsize=(4.2 * len(panels), 4.2), squeeze=False)
    placed = np.array([1000.0 * np.asarray(pose[:2]) for _, p in panels
                       for pose in p.get("object_poses", []) if pose is not None]).reshape(-1, 2)
    centre = placed.mean(axis=0) if len(placed) else np.zeros(2)
    half = max(float(np.abs(placed - centre).max()) if len(placed) else 0.0, 10.0) + 12.0
    seen = set()                                   # one legend entry per outcome
    for ax, (name, p) in zip(axes[0], panels):
        for k, pose in enumerate(p.get("object_poses", [])):
            if pose is None:
                continue
            x, y, yaw = 1000.0 * pose[0], 1000.0 * pose[1], pose[2]
            reason = p["reasons"][k]
            outcome = "success" if p["successes"][k] else (reason or "not achieved")
            marker, colour = _OUTCOME_STYLE.get(outcome, ("X", "tab:purple"))
            ax.plot([x, x + 8.0 * np.cos(yaw)], [y, y + 8.0 * np.sin(yaw)], "-", color="0.6", lw=1)
            ax.plot(x, y, marker, color=colour, ms=8, label=None if outcome in seen else outcome)
            seen.add(outcome)
            final = p["final_object_state"][k]
            if outcome == "not achieved" and final is not None:
                final = 0.0 if abs(final) < 5e-3 else final      # no "-0.00" for a lid at rest on its seat
                ax.annotate(f"{final:.2f}", (x, y), textcoords="offset points", xytext=(5, -10), fontsize=7)
        ax.set_title(f"{name}: {p['success_rate'] * 100:.0f} % success", fontsize=10)
        ax.set_xlabel("object x [mm] (away from the robot)")
        ax.set_xlim(centre[0] - half, centre[0] + half)
        ax.set_ylim(centre[1] - half, centre[1] + half)
        ax.set_aspect("equal", adjustable="box")
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("object y [mm]")
    legend = {}                                    # label -> handle, over every panel
    for ax in axes[0]:
        handles, labels = ax.get_legend_handles_labels()
        legend.update(zip(labels, handles))
    rank = list(_OUTCOME_STYLE)                    # success first, failures by reason last
    labels = sorted(legend, key=lambda label: (rank.index(label) if label in rank else len(rank), label))
    fig.legend([legend[label] for label in labels], labels, loc="lower center", ncol=max(1, len(labels)),
               fontsize=8, frameon=False)
    fig.suptitle(title or f"{report['skill']}: outcome by object placement "
                          f"(object frame {report['object_pose']})", fontsize=11)
    fig.tight_layout(rect=(0, 0.07, 1, 1))
    try:
        return write_figure_png(fig, path, dpi=110)
    finally:
        plt.close(fig)


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

    station_config: the scenario (default the skill's, ``Skill.station_config``); rollout_config:
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

    config = (config or LearnConfig()).validate()
    out_dir = Path(out_dir)
    skill_dir = Path(skill_dir)
    skill = Skill.load(skill_dir)
    if config.exploration_scale is None:
        config = dc.replace(config, exploration_scale=float(skill.spec.exploration_scale))
    station_config = station_config if station_config is not None else skill.station_config()
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


def evaluate_skill(skill_dir, *, poses: int = 10, seed0: int = HELD_OUT_SEED0, station_config=None,
                   rollout_config=None, workers: int = 1, ray_address: str | None = None,
                   all_demos: bool = False, progress: bool = True) -> dict[str, Any]:
    """Greedy success of a skill (initial or learned) over ``poses`` held-out object poses.

    Executes the skill's policy (its initial DMP, the learned one in a skill
    written by :func:`learn`; with ``all_demos`` each demonstration's DMP:
    its weights, goal and duration)
    on the poses of seeds ``seed0 .. seed0 + poses - 1`` and judges each from
    the simulator's ground truth. Returns a JSON-able report: per policy
    (key = DMP index) the :func:`evaluate_greedy` report, plus the settings.
    """
    from drake_skill.learning.rollout import RolloutConfig
    from drake_skill.learning.workers import RunnerSpec, make_pool
    from drake_skill.skill import Skill

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
                policy, _ = evaluate_greedy(pool, skill.dmps[index].weights, seeds, lambda i, r: bar.update(1))
        finally:
            bar.close()
        policy["initial"] = index == skill.initial_index
        report["policies"][str(index)] = policy
    report["success_rate"] = report["policies"][str(skill.initial_index)]["success_rate"] \
        if str(skill.initial_index) in report["policies"] else None
    report["wall_s"] = round(time.perf_counter() - start, 1)
    return report


def explore_skill(skill_dir, *, rollouts: int = 20, seed0: int = HELD_OUT_SEED0, station_config=None,
                  rollout_config=None, workers: int = 1, ray_address: str | None = None,
                  progress: bool = True, exploration_scale: float | None = None) -> dict[str, Any]:
    """Exploratory rollouts of a fitted skill: what the first episode of policy search sees.

    Draws ``rollouts`` weight samples ``W ~ N(W_0, exploration_scale * Sigma_b^0)`` per basis
    (PI^2-ES-Cov's first ``ask``, seeded by ``seed0``; ``exploration_scale``
    None: the skill's, as ``learn``) and executes each on
    the pose of seed ``seed0 + i``. Returns a JSON-able report: the returns
    (learned dense reward; 0 for a failed rollout), their spread (min,
    median, max, standard deviation), ground-truth successes, final object
    states and failures by reason.
    """
    from drake_skill.learning.rollout import RolloutConfig
    from drake_skill.learning.workers import RunnerSpec, make_pool
    from drake_skill.skill import Skill

    if int(rollouts) < 1:
        raise ValueError(f"rollouts: expected at least 1 exploratory rollout, got {rollouts}")
    skill = Skill.load(skill_dir)
    station_config = station_config if station_config is not None else skill.station_config()
    rollout_config = (rollout_config or RolloutConfig()).validate()
    if exploration_scale is None:
        exploration_scale = float(skill.spec.exploration_scale)
    if not _valid_exploration_scale(exploration_scale):
        raise ValueError(f"exploration_scale: expected a factor in (0, 100] on Sigma_b^0, got {exploration_scale!r}")
    samples = make_policy_search("pi2-es-cov", skill.initial_weights, exploration_scale * skill.sigma0,
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
    report = {"skill": skill.name, "skill_dir": str(Path(skill_dir)), "object_pose": rollout_config.object_pose,
              "exploration_scale": float(exploration_scale), **results_report(seeds, results)}
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
        f"  success {report['success_rate'] * 100:.0f}%, final state {_final_state_text(report['final_object_state'])}, "
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
