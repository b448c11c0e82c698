"""A learning run's settings (``LearnConfig``), loadable with ``yaml_load_typed``.

(No ``from __future__ import annotations`` here: yaml_load_typed reads the
field types at run time; ``drake-skill learn --config`` holds one.)
"""

import dataclasses as dc
import functools
import math
import typing
from typing import Any

from drake_skill import typed_yaml
from drake_skill.learning.policy_search import METHODS
from drake_skill.learning.exploration import EXPLORATIONS
from drake_skill.learning.selection import SELECT_RULES

__all__ = ["LearnConfig", "REWARDS"]

REWARDS = ("dense", "sparse")


#: Seed of the first held-out pose (drake_skill.learning.evaluation): far from the
#: learning rollouts' seeds, so no held-out pose is a learning pose.
HELD_OUT_SEED0 = 900_000


def valid_exploration_scale(value) -> bool:
    """An exploration scale is a finite factor in (0, 100] on Sigma_b^0."""
    return math.isfinite(value) and 0 < value <= 100


def valid_approach_exploration(value) -> bool:
    """An approach exploration factor is a finite factor in (0, 1] on Sigma_b^0 (docs/method.md 5.4)."""
    return math.isfinite(value) and 0 < value <= 1



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
    select: which mean the run returns (docs/method.md 5.1,
      :mod:`~drake_skill.learning.selection`): "guarded" (default: the start,
      the best-scoring greedy mean or the last, whichever scores best by the
      learned verdict and return on ``select_poses`` shared poses) or "last"
      (the thesis's final mean; the chapter-7 grid).
    select_poses: object poses each guarded candidate runs on (>= 1).
    exploration: what the search varies (docs/method.md 5.2,
      :mod:`~drake_skill.learning.exploration`): "basis" (thesis Eq. 5.3:
      every basis's weights around the mean, from Sigma_b^0) or "span" (blends
      and extrapolations of the demonstrations' DMPs; ``exploration_scale``
      then defaults to 1).
    approach_exploration: a factor in (0, 1] on Sigma_b^0 of the bases that move the hand
      before the demonstrations' first contact (docs/method.md 5.4,
      :func:`~drake_skill.learning.exploration.approach_covariance`); 1 (the default, the
      thesis's): none quieted. Only with ``exploration`` "basis".
    """

    method: str = "pi2-es-cov"
    reward: str = "dense"
    weighting: str = ""
    episodes: int = 5
    rollouts: int = 6
    seed: int = 0
    held_out: int = 10
    held_out_seed0: int = HELD_OUT_SEED0
    exploration_scale: typing.Optional[float] = None
    greedy_every: int = 1
    select: str = "guarded"
    select_poses: int = 3
    exploration: str = "basis"
    approach_exploration: float = 1.0

    def validate(self) -> "LearnConfig":
        bad = functools.partial(typed_yaml.bad, "learn config")

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
        if self.select not in SELECT_RULES:
            bad("select", self.select, "'guarded' (never return a policy that scores below the start) or 'last'")
        if self.exploration not in EXPLORATIONS:
            bad("exploration", self.exploration, "'basis' (thesis Eq. 5.3) or 'span' (the demonstrations' span)")
        if not valid_approach_exploration(float(self.approach_exploration)):
            bad("approach_exploration", self.approach_exploration, "a factor in (0, 1] on Sigma_b^0 (1: off)")
        if float(self.approach_exploration) != 1.0 and self.exploration != "basis":
            bad("approach_exploration", self.approach_exploration,
                "1 with exploration span (the span has no bases to quiet), or exploration basis")
        if int(self.select_poses) < 1:
            bad("select_poses", self.select_poses, "at least 1 object pose per candidate")
        if int(self.held_out) < 0:
            bad("held_out", self.held_out, "0 (off) or a number of poses")
        if self.exploration_scale is not None and not valid_exploration_scale(self.exploration_scale):
            bad("exploration_scale", self.exploration_scale, "a factor in (0, 100] on Sigma_b^0")
        return self

    def search_options(self) -> dict[str, Any]:
        options: dict[str, Any] = {"n_episodes": int(self.episodes), "seed": int(self.seed)}
        if self.weighting:
            options["weighting"] = self.weighting
        return options
