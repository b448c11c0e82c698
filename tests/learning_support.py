"""A small fitted skill shared by the learning tests (built once per pytest session).

Two scripted Close demonstrations recorded with a 160 x 120 camera (the
segmenter, PCAE and reward see the same scene at a sixteenth of the pixels),
fitted with the thesis' settings, and the DMPs' duration shortened to
``TAU`` s so that a rollout simulates ``TAU`` + ``SETTLE`` s. The folder
lives under pytest's session temp root (the run's, under pytest-xdist), guarded
by a file lock, so every test module of a session reuses the same skill.
"""

from __future__ import annotations

import dataclasses as dc
import fcntl
import os

TAU = 2.0
SETTLE = 0.3


def small_station(skill: str = "close"):
    from drake_skill.skills import scenario_for_skill

    config = scenario_for_skill(skill)
    config.camera.width, config.camera.height = 160, 120
    return config


def rollout_config(**changes):
    from drake_skill.learning.rollout import RolloutConfig

    return dc.replace(RolloutConfig(settle_time=SETTLE), **changes)


def shared_skill(tmp_path_factory) -> dict:
    """``{"skill_dir", "demos_dir", "station_yaml", "station"}`` of the shared test skill."""
    from pydrake.common.yaml import yaml_dump_typed

    base = tmp_path_factory.getbasetemp()
    # Under pytest-xdist every worker has a temp root of its own below the run's: share the run's.
    root = (base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base) / "learning_close_skill"
    root.mkdir(exist_ok=True)
    station = small_station("close")
    paths = {"skill_dir": root / "skill", "demos_dir": root / "demos", "station_yaml": root / "station.yaml",
             "station": station}
    with open(root / ".lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not (root / "skill" / "skill.json").is_file():
            from drake_skill.demos.demonstrator import DemonstratorConfig, ScriptedDemonstrator
            from drake_skill.demos.format import demo_path, save_demonstration
            from drake_skill.fitted_skill import default_skill_config, fit_skill

            demos = ScriptedDemonstrator("close", DemonstratorConfig(pause_probability=0.0, settle_time=0.3),
                                         station_config=small_station("close")).record_many(progress=False)
            for i, demo in enumerate(demos):
                save_demonstration(demo, demo_path(root / "demos", i), force=True)
            skill = fit_skill(demos, default_skill_config("close", fit="thesis"))
            fast = dc.replace(skill, dmps=[dc.replace(d, tau=TAU) for d in skill.dmps])
            fast.save(root / "skill", overwrite=True)
            (root / "station.yaml").write_text(yaml_dump_typed(station))
    return paths
