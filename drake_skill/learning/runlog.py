"""What a learning run logs as it goes: ``results.jsonl``, ``progress.csv``, TensorBoard events, versions.

A :class:`~drake_skill.learning.loop.LearningRun` hands :class:`RunLog` its
records and learning-curve rows as they become known:

- ``results.jsonl``: one JSON object per record (``held_out``, ``greedy``,
  ``rollout``, ``episode``), appended at each checkpoint with the records
  made since the last one.
- ``progress.csv``: one row per greedy-evaluated episode
  (:data:`PROGRESS_COLUMNS`, :func:`progress_row`), appended as each row is
  known; the same dict goes to the ``on_episode`` callback.
- ``tensorboard/``: the same rows as scalars ``progress/<column>`` at step
  = episode, when the ``tensorboard`` package is installed
  (``pip install 'drake-skill[tensorboard]'``; written with
  ``torch.utils.tensorboard.SummaryWriter``). Without it the log says so in
  one line and the run goes on.

Resume: the checkpoint is the truth. ``results.jsonl`` and ``progress.csv``
are rewritten (atomically) from the checkpoint's records and curve, which
drops whatever was appended after it (an interrupted batch's records and
rows); the TensorBoard writer starts with ``purge_step`` = the first episode
not in the checkpoint's curve, so TensorBoard hides the events of episodes
logged after it. A resumed run's files then equal an uninterrupted run's.

:func:`software_versions` is what ``config.json`` records under
``"versions"`` (a resume does not compare it).
"""

from __future__ import annotations

import csv
import io
import json
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Callable

from drake_skill.fileio import atomic_write_text, read_csv_rows

__all__ = ["PROGRESS_COLUMNS", "RunLog", "VERSIONED_PACKAGES", "progress_row", "read_progress", "software_versions"]

#: ``progress.csv``'s columns; every one but ``episode`` and ``failure_reasons`` is also a TensorBoard scalar.
#: episode: updates before the greedy execution (0: before learning); rollouts_used:
#: episode x rollouts per episode; greedy_success / greedy_verdict: 1 or 0 (ground truth /
#: the goal model); greedy_return: its learned dense return R(G) (thesis Eq. 4.5); mean_return,
#: best_return, rollout_successes, failures (count), failure_reasons ("reason:count ..."),
#: ik_warnings: of the rollouts since the previous greedy execution (empty at episode 0);
#: exploration: RMS standard deviation of the weight noise they were sampled with.
PROGRESS_COLUMNS = ("episode", "rollouts_used", "greedy_success", "greedy_verdict", "greedy_return",
                    "mean_return", "best_return", "exploration", "rollout_successes", "failures",
                    "failure_reasons", "ik_warnings")

_NOT_SCALARS = ("episode", "failure_reasons")

#: Distributions whose versions ``config.json`` records.
VERSIONED_PACKAGES = ("drake", "torch", "numpy", "hmmlearn", "scikit-learn", "drake-skill")


def progress_row(row: dict, rollouts_per_episode: int) -> dict:
    """The ``progress.csv`` row of a learning-curve row (``LearningRun.state.curve``): flat, numbers or None."""
    failures = row.get("failures") or {}
    has_rollouts = row.get("mean_return") is not None
    return {
        "episode": int(row["episode"]),
        "rollouts_used": int(row["episode"]) * int(rollouts_per_episode),
        "greedy_success": int(bool(row["greedy_success"])),
        "greedy_verdict": int(bool(row["greedy_verdict"])),
        "greedy_return": row["greedy_return"],
        "mean_return": row.get("mean_return"),
        "best_return": row.get("best_return"),
        "exploration": row["exploration"],
        "rollout_successes": row.get("rollout_successes") if has_rollouts else None,
        "failures": int(sum(failures.values())) if has_rollouts else None,
        "failure_reasons": " ".join(f"{k}:{v}" for k, v in sorted(failures.items())),
        "ik_warnings": row.get("ik_warnings") if has_rollouts else None,
    }


def _csv_line(values) -> str:
    buffer = io.StringIO()
    csv.writer(buffer, lineterminator="\n").writerow(
        ["" if v is None else repr(float(v)) if isinstance(v, float) else str(v) for v in values])
    return buffer.getvalue()


def _csv_text(rows) -> str:
    return _csv_line(PROGRESS_COLUMNS) + "".join(_csv_line([r[c] for c in PROGRESS_COLUMNS]) for r in rows)


def _jsonl(records) -> str:
    return "".join(json.dumps(r, sort_keys=True) + "\n" for r in records)


def _append(path: Path, text: str) -> None:
    """Appends ``text`` (whole lines) to ``path``; a crash mid-line is repaired by the next resume."""
    if text:
        with open(path, "a", encoding="utf-8") as f:
            f.write(text)
            f.flush()


def read_progress(path) -> list[dict]:
    """The rows of a ``progress.csv``, typed as :func:`progress_row` makes them (empty cells None)."""
    rows = read_csv_rows(path, PROGRESS_COLUMNS, "a learning run's progress.csv",
                         "summary.json and results.jsonl beside it hold the same curve")
    floats = ("greedy_return", "mean_return", "best_return", "exploration")
    for row in rows:
        for key in PROGRESS_COLUMNS:
            if key == "failure_reasons":
                continue
            row[key] = None if row[key] == "" else float(row[key]) if key in floats else int(row[key])
    return rows


def _git_commit(root: Path) -> tuple[str | None, bool | None]:
    """(commit, has uncommitted changes) of the git checkout whose top folder is ``root``; (None, None) otherwise.

    A package installed into site-packages inside some other repository (a
    virtual environment in a checkout) is not a checkout of drake-skill:
    the repository's top folder must be the one holding the package.
    """
    def git(*args):
        return subprocess.run(["git", "-C", str(root), *args], capture_output=True, text=True, timeout=20)

    try:
        found = git("rev-parse", "--show-toplevel", "HEAD")
        if found.returncode != 0:
            return None, None
        top, commit = found.stdout.splitlines()[:2]
        if Path(top).resolve() != root.resolve():
            return None, None
        status = git("status", "--porcelain", "--untracked-files=no")
        return commit, (bool(status.stdout.strip()) if status.returncode == 0 else None)
    except (OSError, ValueError, subprocess.SubprocessError):
        return None, None


def software_versions() -> dict:
    """Versions of :data:`VERSIONED_PACKAGES` (None where not installed), the python version, and
    ``git_commit`` / ``git_dirty`` of the drake-skill checkout the package runs from (None when
    it is not run from a git checkout)."""
    from importlib import metadata

    import drake_skill

    versions: dict = {}
    for name in VERSIONED_PACKAGES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = None
    versions["python"] = sys.version.split()[0]
    versions["git_commit"], versions["git_dirty"] = _git_commit(Path(drake_skill.__file__).resolve().parent.parent)
    return versions


class RunLog:
    """The appended logs of a learning run in ``out_dir`` (see the module docstring).

    stream: where one-line notes go (the run's log); rollouts_per_episode:
    for ``rollouts_used``; on_episode: called with each :func:`progress_row`
    dict after its row is written.
    """

    def __init__(self, out_dir, stream, rollouts_per_episode: int, on_episode: Callable[[dict], None] | None = None):
        self.out_dir = Path(out_dir)
        self.stream = stream
        self.rollouts_per_episode = int(rollouts_per_episode)
        self.on_episode = on_episode
        self._writer = None

    @property
    def results_path(self) -> Path:
        return self.out_dir / "results.jsonl"

    @property
    def progress_path(self) -> Path:
        return self.out_dir / "progress.csv"

    @property
    def tensorboard_dir(self) -> Path:
        return self.out_dir / "tensorboard"

    def start(self, records, curve, fresh: bool) -> None:
        """Fresh: the logs start empty (an earlier run's ``tensorboard/`` removed). Resumed: the
        logs rewritten from the checkpoint's ``records`` and ``curve``."""
        if fresh:
            shutil.rmtree(self.tensorboard_dir, ignore_errors=True)
        atomic_write_text(self.results_path, _jsonl(records))
        atomic_write_text(self.progress_path,
                          _csv_text([progress_row(c, self.rollouts_per_episode) for c in curve]))
        self._writer = self._tensorboard(purge_step=None if fresh else (curve[-1]["episode"] + 1 if curve else 0))

    def _tensorboard(self, purge_step: int | None):
        try:
            import tensorboard  # noqa: F401  (SummaryWriter needs it; torch alone imports without it)
            from torch.utils.tensorboard import SummaryWriter
        except ImportError:
            print("tensorboard is not installed: no TensorBoard events (pip install 'drake-skill[tensorboard]')",
                  file=self.stream, flush=True)
            return None
        return SummaryWriter(str(self.tensorboard_dir), purge_step=purge_step)

    def records(self, records) -> None:
        """Appends ``records`` to ``results.jsonl``."""
        _append(self.results_path, _jsonl(records))

    def row(self, curve_row: dict) -> dict:
        """Appends a learning-curve row to ``progress.csv`` and TensorBoard, calls ``on_episode``; returns the row."""
        row = progress_row(curve_row, self.rollouts_per_episode)
        _append(self.progress_path, _csv_line([row[c] for c in PROGRESS_COLUMNS]))
        if self._writer is not None:
            for column in PROGRESS_COLUMNS:
                if column not in _NOT_SCALARS and row[column] is not None:
                    self._writer.add_scalar(f"progress/{column}", float(row[column]), global_step=row["episode"])
            self._writer.flush()
        if self.on_episode is not None:
            self.on_episode(dict(row))
        return row

    def close(self) -> None:
        if self._writer is not None:
            self._writer.close()
            self._writer = None
