"""Any kept rollout shown again: re-simulated in Meshcat from its weights and seed, or drawn from its
stored joints.

:func:`replay_rollout` reads one rollout of a run's or an evaluation's
``rollouts/NAME.npz`` (:mod:`~drake_skill.learning.rollout_store`), builds
the runner the run used (the skill folder, scenario and rollout settings
from the run's ``config.json`` or the file's own ``meta``), executes the
stored weights on the stored seed's object pose with Meshcat recording
(contact forces drawn by Drake's ``ContactVisualizer``, which the station
adds with a Meshcat), and writes the recording as a standalone HTML page.
The same weights and seed give the same rollout (docs/method.md section 5),
so the page shows what the run saw; :class:`Replayed` says whether the new
path matches the stored one. ``stored=True`` draws the stored joints
instead, without simulating (a robot run's rollouts, which have no
simulator to repeat them).
"""

from __future__ import annotations

import dataclasses as dc
from pathlib import Path
from typing import Any

import numpy as np

from drake_skill.fileio import atomic_write_text, load_json
from drake_skill.learning.rollout_store import load_rollout, rollouts_path, stored_names

__all__ = ["Replayed", "replay_rollout"]

#: The stored path is float32: a re-simulated one matching it differs by less than this [m].
PATH_TOLERANCE_M = 1e-5


@dc.dataclass
class Replayed:
    """What :func:`replay_rollout` did: the page, the stored record and, re-simulated, the new result
    and the largest distance between the new hand path and the stored one [m] (None where none is
    stored or the lengths differ)."""

    html: Path
    stored: dict[str, Any]
    result: Any = None
    path_error_m: float | None = None

    @property
    def same(self) -> bool | None:
        """Whether the re-simulation followed the stored path (None: not re-simulated or nothing stored)."""
        return None if self.path_error_m is None else self.path_error_m <= PATH_TOLERANCE_M


def _setup(folder: Path, record: dict) -> dict:
    """The runner's settings: the file's ``meta`` (an evaluation) or the run's ``config.json``."""
    if "skill_dir" in record["meta"]:
        return record["meta"]
    return load_json(folder / "config.json", "the run folder needs the config.json its learn run wrote")


def find_rollouts(folder, name: str) -> Path:
    """``folder/rollouts/NAME.npz``; a name the folder lacks is a ValueError listing those it has."""
    path = rollouts_path(folder, name)
    if not path.is_file():
        names = stored_names(folder)
        raise ValueError(f"{folder}: no kept rollouts '{name}' (rollouts/{name}.npz); it has "
                         f"{', '.join(names) if names else 'none (a run or evaluation of an older version)'}")
    return path


def replay_rollout(folder, name: str, index: int, out=None, *, stored: bool = False, meshcat=None) -> Replayed:
    """Replays rollout ``index`` of ``folder/rollouts/NAME.npz`` into the HTML page ``out`` (default
    ``folder/replays/NAME_cINDEX.html``): re-simulated from its weights and seed, or with ``stored``
    its stored joints drawn (module docstring). ``meshcat``: a Meshcat to record in (default a new one)."""
    from pydrake.geometry import Meshcat

    folder = Path(folder)
    record = load_rollout(find_rollouts(folder, name), index)
    setup = _setup(folder, record)
    out = Path(out) if out is not None else folder / "replays" / f"{name}_c{int(index)}.html"
    out.parent.mkdir(parents=True, exist_ok=True)
    meshcat = meshcat if meshcat is not None else Meshcat()
    if stored:
        return _draw_stored(record, setup, out, meshcat)
    return _resimulate(record, setup, out, meshcat)


def _draw_stored(record, setup: dict, out: Path, meshcat) -> Replayed:
    from drake_skill.demos.replay import joints_replay_html
    from drake_skill.fitted_skill import Skill
    from drake_skill.station.scenario import load_scenario

    if "joints" not in record:
        raise ValueError("this rollout stored no joints (it failed before it was simulated); nothing to draw")
    # The robot has no true pose: the object is drawn where the perception put it.
    X_WO = record["object_pose_true"] if np.all(np.isfinite(record["object_pose_true"])) else record["object_pose"]
    if not np.all(np.isfinite(X_WO)):
        raise ValueError("this rollout stored no object pose (it failed before perceiving one); nothing to place")
    html = joints_replay_html(load_scenario(data=setup["station"]), X_WO, record["times"], record["joints"],
                              float(Skill.load(setup["skill_dir"]).gripper_opening), record["object_state"], meshcat)
    return Replayed(atomic_write_text(out, html), record)


def _resimulate(record, setup: dict, out: Path, meshcat) -> Replayed:
    """The runner the run used (``RunnerSpec``, as its workers built theirs), with Meshcat."""
    from drake_skill.common import frame_meshcat_camera, recorded_html
    from drake_skill.learning.workers import RunnerSpec

    spec = RunnerSpec(setup["skill_dir"], setup["station"], setup["rollout"], quiet_ik=False,
                      dmp_index=record["meta"].get("dmp_index"))
    runner = spec.build(meshcat)
    frame_meshcat_camera(meshcat, runner.station.random_object_pose(record["seed"]).translation())
    def run():
        result = runner.run(record["weights"], record["seed"])
        # The state at the end or the stop drawn once more: a reflex trips within milliseconds of the
        # first touch, often between two of the visualizers' 32 Hz publishes.
        runner.diagram.ForcedPublish(runner.context)
        return result

    result, html = recorded_html(meshcat, run)
    atomic_write_text(out, html)
    error = None
    if "ee_pose" in record and len(record["ee_pose"]) == len(result.ee_pose):
        error = float(np.max(np.linalg.norm(result.ee_pose[:, :3] - record["ee_pose"][:, :3], axis=1), initial=0.0))
    return Replayed(out, record, result, error)
