"""A learning run's typed state and the pure functions its steps use (no Drake).

:class:`RunState` is what ``checkpoint/`` holds between two batches of a
:class:`~drake_skill.learning.loop.LearningRun`; :func:`pose_seed` gives every
execution its object pose, :func:`episode_rewards` what ``tell`` takes,
:func:`curve_row` a learning-curve row (docs/method.md section 5).
"""

from __future__ import annotations

import dataclasses as dc
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

from drake_skill.fileio import atomic_save_npz, atomic_write_json, load_json, load_npz
from drake_skill.learning.policy_search import policy_search_from_state

__all__ = ["DAMAGED_RUN", "RunState", "curve_row", "episode_rewards", "exploration_size", "pose_seed"]

#: What to do with a run whose checkpoint or config.json is damaged (a copy cut short).
DAMAGED_RUN = "the run cannot be resumed from it: start over with --force, or delete the run folder"

#: 3: ``candidates`` (the greedy-executed means) added; 2: a list of pending greedy executions.
_CHECKPOINT_FORMAT = 3


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
    Failed rollouts (a reflex trip among them) count 0, the least any
    rollout earns (R(G) >= 0: the MRP values are positive), so every
    weighting ranks a trip last.
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


def curve_row(records, episode: int, every: int, exploration_at: dict, mean) -> dict:
    """The curve row of update ``episode``: its rollouts and those of the updates since the last greedy one.

    With a greedy execution after every update (``every`` = 1) the block is
    the episode's own rollouts; PoWER's 30 x 1 with one every 6 sums 6 of them.
    ``mean``: the weights W (B x 7) the greedy execution will run.
    """
    first = ((episode - 1) // every) * every + 1
    block = [r for r in records if r["type"] == "rollout" and first <= r["episode"] <= episode]
    returns = [r["reward"] for r in block]
    return {"episode": episode, "mean_return": float(np.mean(returns)), "best_return": float(np.max(returns)),
            "exploration": exploration_at[first],
            "failures": dict(Counter(r["reason"] for r in block if r["failed"])),
            "rollout_successes": int(sum(r["success"] for r in block)),
            "ik_warnings": int(sum(r["ik_warnings"] for r in block)), "mean": np.asarray(mean).tolist()}


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
    candidates: the means whose greedy execution ran, by episode (str keys,
      B x 7 nested lists): what the guarded selection chooses among
      (:mod:`~drake_skill.learning.selection`).
    held_out_before: the held-out record before learning (None: off).
    """

    search: Any
    records: list = dc.field(default_factory=list)
    curve: list = dc.field(default_factory=list)
    pending: list = dc.field(default_factory=list)
    held_out_before: dict | None = None
    candidates: dict = dc.field(default_factory=dict)

    def save(self, checkpoint: Path) -> None:
        """``checkpoint/search.npz`` and ``checkpoint/state.json``, each written atomically."""
        atomic_save_npz(checkpoint / "search.npz", {k: np.asarray(v) for k, v in self.search.state_dict().items()})
        atomic_write_json(checkpoint / "state.json", {
            "format": _CHECKPOINT_FORMAT, "episode": self.search.episode, "records": self.records,
            "curve": self.curve, "held_out_before": self.held_out_before, "pending": self.pending,
            "candidates": self.candidates})

    @classmethod
    def load(cls, checkpoint: Path) -> "RunState":
        """The state :meth:`save` wrote (format 1: one pending greedy execution, of the current mean;
        formats 1-2: no candidates kept, the guarded selection then weighs the start and the last mean)."""
        state = load_json(checkpoint / "state.json", DAMAGED_RUN)
        try:
            search = policy_search_from_state(load_npz(checkpoint / "search.npz"))
        except (KeyError, TypeError, IndexError, AttributeError) as e:   # arrays of another shape or kind
            raise ValueError(f"{checkpoint / 'search.npz'}: damaged checkpoint ({type(e).__name__}: {e}); "
                             f"{DAMAGED_RUN}") from None
        try:
            pending = state.get("pending")
            if state.get("format", 1) == 1:
                pending = [] if pending is None else [{**pending, "mean": search.mean.tolist()}]
            records, curve = state["records"], state["curve"]
            candidates = state.get("candidates", {})
            if not (isinstance(records, list) and isinstance(curve, list) and isinstance(pending, list)
                    and isinstance(candidates, dict)):
                raise TypeError("records, curve and pending must be lists, candidates a mapping")
        except (KeyError, TypeError, AttributeError) as e:
            raise ValueError(f"{checkpoint / 'state.json'}: damaged checkpoint ({type(e).__name__}: {e}); "
                             f"{DAMAGED_RUN}") from None
        return cls(search, records, curve, pending, state.get("held_out_before"), candidates)
