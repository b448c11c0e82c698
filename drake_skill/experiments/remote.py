"""Grid tasks on Ray with no shared file system: a task carries what it needs, its result brings back
what it made, and only the driver writes under ``--out``.

A Ray worker may run on a node that cannot see the driver's ``--out``
(most cloud clusters have no shared file system). So, on Ray:

- the fitted skills travel through Ray's object store: the driver packs
  each skill folder (:func:`pack_folder`: relative path -> bytes) and puts
  the set once (:data:`SkillFiles`); a worker writes a skill into its own
  temporary folder the first time a task needs it (:func:`_skill_copy`, keyed by
  the bytes' digest) and builds its runner from there;
- a task (:class:`RemoteTask`) holds no path under ``--out``: the grid
  task with its path emptied and the digest of its skill;
- the worker runs the task into a temporary folder (the task's
  ``execute``, :func:`~drake_skill.experiments.grid.execute_task`: the same
  code the process pool runs), writes the driver's skill folder into the run's
  ``config.json`` where the worker's copy was, and returns the folder's
  files with the summary (:func:`execute_remote`);
- the driver stores them (:func:`store_result`): a run's files into its
  ``.run_RRR.partial`` folder, renamed to ``run_RRR`` when complete (as the
  process pool's runs), a held-out-before record into its file.

A run cut off mid-way on Ray starts again from its beginning (its
checkpoint was on the worker); a run is minutes, and the same seed gives
the same run, so the table is the same.
"""

from __future__ import annotations

import atexit
import dataclasses as dc
import hashlib
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any, Callable

from drake_skill.fileio import atomic_write_bytes, atomic_write_json, load_json, pack_folder, unpack_folder
from drake_skill.learning.runstate import DAMAGED_RUN

__all__ = ["RemoteTask", "execute_remote", "remote_tasks", "store_result"]

#: digest -> the files of one skill folder (``pack_folder``).
SkillFiles = dict[str, dict[str, bytes]]


def _digest(files: dict[str, bytes]) -> str:
    h = hashlib.sha256()
    for name, data in files.items():
        h.update(name.encode() + b"\0" + hashlib.sha256(data).digest())
    return h.hexdigest()[:16]


@dc.dataclass(frozen=True)
class RemoteTask:
    """A grid task as sent to a Ray worker: ``task`` with its ``path`` emptied and its spec's skill
    folder kept only as the label written into the run's ``config.json``; ``skill``: the digest of
    the skill's files in the shared :data:`SkillFiles`; ``execute``: what runs it
    (``grid.execute_task``, a module-level function: it travels by name)."""

    task: Any
    skill: str
    execute: Callable[[Any], dict]


def remote_tasks(tasks, execute: Callable[[Any], dict]) -> tuple[list[RemoteTask], SkillFiles]:
    """The tasks as :class:`RemoteTask` run by ``execute`` (same order) and the skills' files they name."""
    files: SkillFiles = {}
    keys: dict[str, str] = {}
    remote = []
    for task in tasks:
        folder = task.spec.skill_dir
        if folder not in keys:
            packed = pack_folder(folder)
            keys[folder] = _digest(packed)
            files[keys[folder]] = packed
        remote.append(RemoteTask(dc.replace(task, path=""), keys[folder], execute))
    return remote, files


_COPIES: dict[str, Path] = {}


def _skill_copy(key: str, skills: SkillFiles) -> Path:
    """This worker's copy of skill ``key`` (written once per worker process, removed when the
    process exits normally; a killed worker leaves it to the node's temporary-file cleanup)."""
    if key not in _COPIES or not (_COPIES[key] / "skill.json").is_file():
        folder = Path(tempfile.mkdtemp(prefix=f"drake_skill_{key}_"))
        atexit.register(shutil.rmtree, folder, True)
        _COPIES[key] = unpack_folder(skills[key], folder)
    return _COPIES[key]


def execute_remote(remote: RemoteTask, skills: SkillFiles) -> dict[str, Any]:
    """Runs ``remote`` in a temporary folder of this worker; returns ``{"summary", "files"}`` (the
    run folder's files, or for a held-out-before task ``{"": the record's JSON bytes}``)."""
    task = remote.task
    label = task.spec.skill_dir
    spec = dc.replace(task.spec, skill_dir=str(_skill_copy(remote.skill, skills)))
    with tempfile.TemporaryDirectory(prefix="drake_skill_task_") as tmp:
        target = Path(tmp) / ("run" if task.kind == "run" else "held_out_before.json")
        summary = remote.execute(dc.replace(task, spec=spec, path=str(target)))
        if task.kind != "run":
            return {"summary": summary, "files": {"": target.read_bytes()}}
        _relabel(target / "config.json", label)
        return {"summary": summary, "files": pack_folder(target)}


def _relabel(config_json: Path, skill_dir: str) -> None:
    """The run's ``config.json`` names the driver's skill folder, as a run on the driver's disk does."""
    atomic_write_json(config_json, {**load_json(config_json, DAMAGED_RUN), "skill_dir": skill_dir})


def store_result(task, payload: dict[str, Any], partial: Path | None = None) -> dict[str, Any]:
    """Stores a remote task's files under the driver's ``--out`` (module docstring): a run's through
    ``partial`` (its ``.run_RRR.partial`` folder); returns its summary."""
    files = payload["files"]
    if task.kind != "run":
        atomic_write_bytes(task.path, files[""])
        return payload["summary"]
    final = Path(task.path)
    shutil.rmtree(partial, ignore_errors=True)
    unpack_folder(files, partial)
    final.parent.mkdir(parents=True, exist_ok=True)
    os.rename(partial, final)
    return payload["summary"]
