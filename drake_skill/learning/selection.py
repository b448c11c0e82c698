"""Which policy a learning run returns: the guard against ending worse than the start.

docs/method.md section 5.1. Policy search moves the mean W on the learned
reward alone, and a few rollouts per update are a noisy estimate of it; a
run can end on a mean worse than the one it started from (issue 45: Open's
imitation succeeds on 10 of 10 held-out poses and a run ended at 4). The
thesis returns the last mean (``select: last``, the chapter-7 reproduction).
``select: guarded`` (the default) chooses among

* W_0, the start (the skill's initial DMP);
* W_e*, the mean whose greedy execution during the run scored best
  (:func:`score`; the latest among equals, so W_E when nothing beat it);
* W_E, the last mean,

by running each greedy on the same ``select_poses`` object poses (seeds
:func:`select_seed`, none a training or held-out pose) and keeping the one
with the best score. A score uses only what a real robot has: the learned
goal model's verdict and the dense return R(G) (thesis Eq. 4.5), never the
simulator's ground truth::

    score(W) = (number of executions with verdict success and no failure,
                mean R(G) over the executions, a failed one counting 0)

compared lexicographically; among equal scores the later mean wins, so a
run whose learning changed nothing measurable returns the start only when
the start scores strictly better.
"""

from __future__ import annotations

import dataclasses as dc

import numpy as np

__all__ = ["SELECT_RULES", "Candidate", "best_greedy_episode", "choose", "score", "select_seed"]

#: ``LearnConfig.select``: "guarded" (this module) or "last" (the thesis: the final mean).
SELECT_RULES = ("guarded", "last")


def select_seed(run_seed: int, index: int) -> int:
    """Object-pose seed of selection pose ``index`` of run ``run_seed``: a 31-bit integer from
    ``numpy.random.SeedSequence`` on a key no rollout's or greedy execution's seed uses
    (:func:`~drake_skill.learning.loop.pose_seed` keys have four entries, these five)."""
    key = [int(run_seed), 0, 2, 0, int(index)]
    return int(np.random.SeedSequence(key).generate_state(1)[0] >> 1)


def score(summaries) -> tuple[int, float]:
    """(verdict successes without failure, mean dense return with failures as 0) of executions
    given as ``RolloutResult.summary()`` dicts (or records holding the same keys)."""
    summaries = list(summaries)
    if not summaries:
        return (0, float("-inf"))
    wins = sum(1 for s in summaries if s["verdict"] and not s["failed"])
    returns = [0.0 if s["failed"] else float(s["dense_return"]) for s in summaries]
    return (int(wins), float(np.mean(returns)))


def best_greedy_episode(greedy_records) -> int | None:
    """The episode (>= 1) whose greedy execution scores best, the latest among equals; None
    when there is none after an update."""
    learned = [r for r in greedy_records if int(r["episode"]) >= 1]
    if not learned:
        return None
    return int(max(learned, key=lambda r: (score([r]), int(r["episode"])))["episode"])


#: What a candidate's record keeps of each execution (``RolloutResult.summary()`` keys; the ground
#: truth ``success`` and ``final_object_state`` for the report only, never for the choice).
EXECUTION_KEYS = ("seed", "failed", "reason", "verdict", "dense_return", "success", "final_object_state")


@dc.dataclass
class Candidate:
    """A mean W considered for return: the update it follows (0: the start) and its executions
    on the selection poses (``RolloutResult.summary()`` dicts)."""

    episode: int
    executions: list

    def __post_init__(self):
        self.executions = [{k: s[k] for k in EXECUTION_KEYS} for s in self.executions]

    @property
    def score(self) -> tuple[int, float]:
        return score(self.executions)

    def record(self) -> dict:
        wins, mean_return = self.score
        return {"episode": int(self.episode), "verdict_successes": wins, "mean_return": mean_return,
                "executions": self.executions}


def choose(candidates: list[Candidate]) -> Candidate:
    """The candidate with the best :func:`score`; among equal scores the one after the most updates."""
    if not candidates:
        raise ValueError("choose: no candidate policy to select from")
    return max(candidates, key=lambda c: (c.score, c.episode))
