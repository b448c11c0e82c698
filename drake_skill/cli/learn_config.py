"""The file of ``drake-skill learn --config FILE``: a learning run's settings in one YAML.

(No ``from __future__ import annotations`` here: yaml_load_typed reads the
field types at run time.)

    skill: open                  # a shipped skill's name or a skill file (or skill_dir / demos)
    out: results/learn/open
    workers: 2
    learn: {method: pi2-es-cov, reward: dense, episodes: 5, rollouts: 6, seed: 0, held_out: 10}
    station:                     # overrides of the skill's scenario (Scenario's keys)
      object: {x: 0.62}

Flags given on the command line override the file; ``--print-config`` prints
the effective settings (the station in full) and runs nothing.
"""

import dataclasses as dc

from drake_skill.learning.loop import LearnConfig
from drake_skill.station.scenario import Scenario

__all__ = ["LearnFile"]


@dc.dataclass
class LearnFile:
    """skill / skill_dir / demos: where the skill comes from (as the flags of the same
    names); out: the run's folder; workers: rollout worker processes (0: one per
    CPU); learn: :class:`~drake_skill.learning.loop.LearnConfig`; station: the
    scenario, read over the skill's (keys left out keep the skill's values)."""

    skill: str = ""
    skill_dir: str = ""
    demos: str = ""
    out: str = ""
    workers: int = 0
    learn: LearnConfig = dc.field(default_factory=LearnConfig)
    station: Scenario = dc.field(default_factory=Scenario)
