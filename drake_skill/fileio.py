"""Atomic file writing and safe loading shared by every module that saves results.

Files are written to a temporary sibling and renamed into place, so a crash
never leaves a half-written file and never clobbers what was there before.
Nothing here unpickles: numpy archives load with ``allow_pickle=False``.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Any, Mapping

import numpy as np


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Writes ``data`` to ``path`` atomically (temp file + fsync + rename)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        # mkstemp makes the file private (0600); give it the usual permissions.
        umask = os.umask(0)
        os.umask(umask)
        os.fchmod(fd, 0o666 & ~umask)
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path


def atomic_write_text(path: str | os.PathLike, text: str) -> Path:
    return atomic_write_bytes(path, text.encode("utf-8"))


def atomic_write_json(path: str | os.PathLike, obj: Any) -> Path:
    return atomic_write_text(path, json.dumps(obj, indent=2, sort_keys=True) + "\n")


def atomic_save_npz(path: str | os.PathLike, arrays: Mapping[str, np.ndarray]) -> Path:
    """Saves arrays to an ``.npz`` atomically. Object arrays are refused."""
    import io

    for name, value in arrays.items():
        if np.asarray(value).dtype == object:
            raise ValueError(f"array '{name}' has dtype object; only numeric arrays are saved (no pickle)")
    buf = io.BytesIO()
    np.savez(buf, **{k: np.asarray(v) for k, v in arrays.items()})
    return atomic_write_bytes(path, buf.getvalue())


def load_npz(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Loads an ``.npz`` without pickle; errors name the file."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    try:
        with np.load(path, allow_pickle=False) as data:
            return {k: data[k] for k in data.files}
    except Exception as e:  # zipfile.BadZipFile, ValueError, OSError, ...
        raise ValueError(f"{path}: not a readable numpy .npz archive ({e})") from e


def write_figure_png(fig, path: str | os.PathLike, **savefig_kwargs) -> Path:
    """Renders a matplotlib figure to PNG and writes it to ``path`` atomically.

    ``savefig_kwargs`` go to ``Figure.savefig`` (``dpi``, ``bbox_inches``).
    """
    import io

    buf = io.BytesIO()
    fig.savefig(buf, format="png", **savefig_kwargs)
    return atomic_write_bytes(path, buf.getvalue())
