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


def load_json(path: str | os.PathLike, fix: str) -> Any:
    """The JSON in ``path``; a damaged file (cut short, not UTF-8) is a one-line ValueError that
    names it, where the parse stopped and ``fix`` (what the user can do)."""
    path = Path(path)
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError as e:
        raise ValueError(f"{path}: damaged JSON ({e.msg} at line {e.lineno}, column {e.colno}); {fix}") from None
    except UnicodeDecodeError:
        raise ValueError(f"{path}: damaged JSON (not UTF-8 text); {fix}") from None


def read_csv_rows(path: str | os.PathLike, columns, what: str, fix: str) -> list[dict]:
    """The rows of the CSV file ``path`` (dicts of strings), whose header must be ``columns``.

    Another header is a ValueError saying the file is not ``what`` ("an
    experiment table"); a damaged file (not UTF-8, a stray NUL) is one that
    names it, the parser's reason and ``fix`` (what the user can do).
    """
    import csv

    path = Path(path)
    try:
        with open(path, newline="") as f:
            reader = csv.DictReader(f)
            if tuple(reader.fieldnames or ()) != tuple(columns):
                raise ValueError(f"{path}: not {what} (columns {reader.fieldnames}; "
                                 f"expected {', '.join(columns)})")
            return list(reader)
    except (UnicodeDecodeError, csv.Error) as e:
        raise ValueError(f"{path}: damaged CSV ({e}); {fix}") from None


def atomic_save_npz(path: str | os.PathLike, arrays: Mapping[str, np.ndarray], compressed: bool = False) -> Path:
    """Saves arrays to an ``.npz`` (``compressed``: deflated) atomically. Object arrays are refused."""
    import io

    for name, value in arrays.items():
        if np.asarray(value).dtype == object:
            raise ValueError(f"array '{name}' has dtype object; only numeric arrays are saved (no pickle)")
    buf = io.BytesIO()
    (np.savez_compressed if compressed else np.savez)(buf, **{k: np.asarray(v) for k, v in arrays.items()})
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


def new_figure(figsize, dpi: float = 100):
    """A matplotlib Figure on its own Agg canvas, outside pyplot: library code draws
    on it without switching the caller's backend (a notebook keeps its inline
    plots) or registering it with pyplot (nothing to close)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, dpi=dpi)
    FigureCanvasAgg(fig)
    return fig


def write_figure_png(fig, path: str | os.PathLike, **savefig_kwargs) -> Path:
    """Renders a matplotlib figure to PNG and writes it to ``path`` atomically.

    ``savefig_kwargs`` go to ``Figure.savefig`` (``dpi``, ``bbox_inches``).
    """
    import io

    buf = io.BytesIO()
    fig.savefig(buf, format="png", **savefig_kwargs)
    return atomic_write_bytes(path, buf.getvalue())


def png_data_url(image=None, *, fig=None) -> str:
    """A ``data:image/png;base64,...`` URL of an (h, w, 3) uint8 ``image`` or of a matplotlib ``fig``:
    images inline in a self-contained HTML page (``report.html``, ``fit_report.html``)."""
    import base64
    import io

    buf = io.BytesIO()
    if fig is not None:
        fig.savefig(buf, format="png")
    else:
        import matplotlib.image

        matplotlib.image.imsave(buf, np.asarray(image, dtype=np.uint8), format="png")
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


# ------------------------------------------------------------------ directories
def pack_folder(folder) -> dict[str, bytes]:
    """Every file under ``folder``: {relative POSIX path: bytes}, in sorted order."""
    folder = Path(folder)
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def unpack_folder(files: dict[str, bytes], folder) -> Path:
    """Writes ``files`` (``pack_folder``'s) under ``folder`` (made if missing)."""
    folder = Path(folder)
    for name, data in files.items():
        path = folder / name
        if Path(name).is_absolute() or ".." in Path(name).parts:
            raise ValueError(f"{name}: a packed file's name leaves its folder")
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data)
    return folder


def file_sha256(path: str | os.PathLike) -> str:
    """Hex SHA-256 of a file's bytes."""
    import hashlib

    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _exchange(a: Path, b: Path) -> bool:
    """Atomically swaps two directory entries (Linux ``renameat2(RENAME_EXCHANGE)``).

    Returns False where the call is not available (other systems, old
    kernels, file systems without support); nothing is changed then.
    """
    import ctypes
    import sys

    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        renameat2 = libc.renameat2
    except (OSError, AttributeError):
        return False
    AT_FDCWD, RENAME_EXCHANGE = -100, 2
    rc = renameat2(AT_FDCWD, os.fsencode(a), AT_FDCWD, os.fsencode(b), RENAME_EXCHANGE)
    if rc == 0:
        return True
    err = ctypes.get_errno()
    import errno

    if err in (errno.ENOSYS, errno.EINVAL, errno.ENOTSUP if hasattr(errno, "ENOTSUP") else errno.EINVAL):
        return False
    raise OSError(err, f"cannot swap {a} and {b}: {os.strerror(err)}")


def _swap_in(new: Path, target: Path) -> Path | None:
    """Puts directory ``new`` at ``target``; returns where the old ``target`` went (or None).

    With an existing ``target`` the two are exchanged atomically where the
    system allows it, so ``target`` always names a complete directory (old,
    then new). Elsewhere ``target`` is renamed aside first and there is an
    instant with no ``target`` (never a mix); :func:`interrupted_swap`
    reports it to loaders.
    """
    if not target.exists():
        os.rename(new, target)
        return None
    if _exchange(new, target):
        return new
    aside = target.with_name(f".{target.name}.old-{os.getpid()}")
    os.rename(target, aside)
    os.rename(new, target)
    return aside


def _remove_tree(path: Path) -> None:
    import shutil

    shutil.rmtree(path, ignore_errors=True)


def interrupted_swap(target: str | os.PathLike) -> list[Path]:
    """The aside copies a directory swap interrupted between its two renames left next to ``target``."""
    target = Path(target)
    return sorted(target.parent.glob(f".{target.name}.old-*")) if target.parent.is_dir() else []


def _fsync_tree(path: Path) -> None:
    for p in [*sorted(path.rglob("*")), path]:
        if p.is_dir():
            fd = os.open(p, os.O_RDONLY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)


class staged_directory:
    """Writes a directory's files as one unit: ``with staged_directory(target) as tmp: ...``.

    Files are written into ``tmp``, a new hidden sibling of ``target``; on a
    normal exit ``tmp`` replaces ``target`` in one swap (see :func:`_swap_in`)
    and the old contents are deleted. On an exception (or an interruption)
    ``tmp`` is removed and ``target`` is untouched. So ``target`` holds either
    the whole old set of files or the whole new one, never a mix.

    ``overwrite=False`` refuses (FileExistsError) an existing non-empty ``target``.
    """

    def __init__(self, target: str | os.PathLike, overwrite: bool = False):
        self.target = Path(target)
        self.overwrite = overwrite
        self.tmp: Path | None = None

    def __enter__(self) -> Path:
        t = self.target
        if t.exists() and not t.is_dir():
            raise NotADirectoryError(f"{t}: exists and is not a directory; choose a folder path")
        if t.is_dir() and any(t.iterdir()) and not self.overwrite:
            raise FileExistsError(f"{t}: exists and is not empty; pass overwrite / --force to replace it")
        t.parent.mkdir(parents=True, exist_ok=True)
        self.tmp = Path(tempfile.mkdtemp(prefix=f".{t.name}.new-", dir=t.parent))
        os.chmod(self.tmp, 0o777 & ~_umask())
        return self.tmp

    def __exit__(self, exc_type, exc, tb) -> bool:
        assert self.tmp is not None
        if exc_type is not None:
            _remove_tree(self.tmp)
            return False
        try:
            _fsync_tree(self.tmp)
            old = _swap_in(self.tmp, self.target)
        except BaseException:
            _remove_tree(self.tmp)
            raise
        if old is not None:
            _remove_tree(old)
        return False


def carry_over(source: str | os.PathLike, destination: str | os.PathLike, exclude=()) -> None:
    """Links (or copies) every entry of folder ``source`` not named in ``exclude`` into ``destination``.

    Used to keep a user's unrelated files when a staged directory replaces
    ``source`` (hard links: no data copied, the old files stay intact).
    """
    import shutil

    source, destination = Path(source), Path(destination)
    if not source.is_dir():
        return
    for p in source.iterdir():
        if p.name in exclude:
            continue
        if p.is_dir() and not p.is_symlink():
            shutil.copytree(p, destination / p.name, symlinks=True)
        elif p.is_symlink():
            os.symlink(os.readlink(p), destination / p.name)
        else:
            try:
                os.link(p, destination / p.name)
            except OSError:
                shutil.copy2(p, destination / p.name)


def _umask() -> int:
    umask = os.umask(0)
    os.umask(umask)
    return umask
