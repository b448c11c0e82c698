"""Directory writes that cannot mix (issue 12, group 4): an interruption injected at
every file-system step of ``Skill.save(overwrite=True)`` and ``demos record --force``
leaves a folder that loads as wholly the old set or wholly the new one."""

import errno
import os
import shutil
import stat
from pathlib import Path

import numpy as np
import pytest

from drake_skill import fileio
from drake_skill.fitted_skill import Skill

from test_bad_input import synthetic_skill

_STEPS = ("atomic_write_bytes", "_fsync_tree", "_swap_in", "_remove_tree")


class Interrupted(BaseException):
    """Stands for a kill: nothing after it runs (later file-system steps are skipped)."""


def _inject(monkeypatch, at: int) -> dict:
    """Makes the ``at``-th file-system step (1-based) raise Interrupted; later steps do nothing."""
    state = {"n": 0, "fired": False}
    for name in _STEPS:
        real = getattr(fileio, name)

        def step(*args, _real=real, **kwargs):
            if state["fired"]:
                return None  # the process is gone
            state["n"] += 1
            if state["n"] == at:
                state["fired"] = True
                raise Interrupted()
            return _real(*args, **kwargs)

        monkeypatch.setattr(fileio, name, step)
    return state


def _identity(skill: Skill):
    return skill.config.seed, skill.info["seed"], skill.sigma0[0, 0, 0], skill.pomrp.values.sum()


def test_interrupted_skill_save_leaves_old_or_new(tmp_path, monkeypatch):
    old, new = synthetic_skill(0), synthetic_skill(5)
    reference = tmp_path / "reference"
    old.save(reference)
    want_old = _identity(Skill.load(reference))
    want_new = _identity(new)
    assert want_old[0] != want_new[0]
    outcomes = []
    for at in range(1, 20):
        target = tmp_path / f"case{at}" / "skill"
        shutil.copytree(reference, target)
        with monkeypatch.context() as m:
            state = _inject(m, at)
            try:
                new.save(target, overwrite=True)
                fired = state["fired"]
            except Interrupted:
                fired = True
        got = _identity(Skill.load(target))
        assert got in (want_old, want_new), f"interrupted at step {at}: a mix"
        outcomes.append(got == want_new)
        if not fired:
            break
    # Every step was tried: the last run finished, and both outcomes occurred.
    assert not fired and outcomes[-1] and not outcomes[0]
    assert len(outcomes) >= 5


def test_fallback_swap_without_exchange(tmp_path, monkeypatch):
    """Where renameat2 is unavailable the two-rename swap is used; a stop between them is reported."""
    monkeypatch.setattr(fileio, "_exchange", lambda a, b: False)
    target = tmp_path / "skill"
    synthetic_skill(0).save(target)
    synthetic_skill(5).save(target, overwrite=True)
    assert Skill.load(target).config.seed == 5
    assert sorted(p.name for p in tmp_path.iterdir()) == ["skill"]
    # Simulate the stop between the renames: target renamed aside, new not yet in place.
    aside = tmp_path / ".skill.old-123"
    target.rename(aside)
    with pytest.raises(FileNotFoundError, match=r"an interrupted save left the previous skill in .*\.skill\.old-123"):
        Skill.load(target)


def test_save_refuses_to_replace_without_overwrite(tmp_path):
    target = tmp_path / "skill"
    synthetic_skill(0).save(target)
    with pytest.raises(FileExistsError, match="already holds a skill; pass overwrite=True"):
        synthetic_skill(5).save(target)
    (tmp_path / "file").write_text("x")
    with pytest.raises(NotADirectoryError, match="file: exists and is not a directory"):
        synthetic_skill(5).save(tmp_path / "file")
    assert Skill.load(target).config.seed == 0


# ------------------------------------------------------------------ fileio's own behaviour
# (mutation testing, docs/mutation.md: what the interruption tests above leave unchecked)


def test_exchange_swaps_two_directories_or_names_the_error(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir()
    b.mkdir()
    (a / "from_a").write_text("a")
    (b / "from_b").write_text("b")
    assert fileio._exchange(a, b) is True
    assert [p.name for p in a.iterdir()] == ["from_b"] and [p.name for p in b.iterdir()] == ["from_a"]
    with pytest.raises(OSError, match=r"cannot swap .*a and .*missing: No such file or directory") as err:
        fileio._exchange(a, tmp_path / "missing")
    assert err.value.errno == errno.ENOENT
    assert [p.name for p in a.iterdir()] == ["from_b"]


@pytest.mark.parametrize("code, swapped", [(errno.ENOSYS, False), (errno.EINVAL, False),
                                           (errno.EOPNOTSUPP, False), (errno.EXDEV, None)])
def test_exchange_without_kernel_support_changes_nothing(tmp_path, monkeypatch, code, swapped):
    """renameat2 missing or refused by the file system: False (the caller falls back); other errors raise."""
    import ctypes

    calls = []

    class Libc:
        def renameat2(self, *args):
            calls.append(args)
            return -1

    monkeypatch.setattr(ctypes, "CDLL", lambda name, use_errno=False: Libc())
    monkeypatch.setattr(ctypes, "get_errno", lambda: code)
    a, b = tmp_path / "a", tmp_path / "b"
    if swapped is None:
        with pytest.raises(OSError, match="cannot swap"):
            fileio._exchange(a, b)
    else:
        assert fileio._exchange(a, b) is swapped
    assert calls == [(-100, bytes(a), -100, bytes(b), 2)]  # AT_FDCWD, RENAME_EXCHANGE


def test_exchange_is_not_tried_off_linux_or_without_libc(tmp_path, monkeypatch):
    import ctypes
    import sys

    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir()
    b.mkdir()
    (a / "x").write_text("x")
    with monkeypatch.context() as m:
        m.setattr(sys, "platform", "darwin")
        assert fileio._exchange(a, b) is False

    def no_libc(*args, **kwargs):
        raise OSError("no libc")

    monkeypatch.setattr(ctypes, "CDLL", no_libc)
    assert fileio._exchange(a, b) is False
    assert (a / "x").exists()


def test_staged_directory_exception_discards_the_new_files(tmp_path, monkeypatch):
    target = tmp_path / "out"
    target.mkdir()
    (target / "old").write_text("old")
    with pytest.raises(RuntimeError, match="in the body"):
        with fileio.staged_directory(target, overwrite=True) as tmp:
            (tmp / "new").write_text("new")
            raise RuntimeError("in the body")
    assert not tmp.exists() and [p.name for p in target.iterdir()] == ["old"]

    def failing_swap(new, target):
        raise OSError("swap failed")

    monkeypatch.setattr(fileio, "_swap_in", failing_swap)
    with pytest.raises(OSError, match="swap failed"):
        with fileio.staged_directory(target, overwrite=True) as tmp:
            (tmp / "new").write_text("new")
    assert not tmp.exists() and [p.name for p in target.iterdir()] == ["old"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_staged_directory_refusals_and_new_parents(tmp_path):
    target = tmp_path / "out"
    target.mkdir()
    (target / "old").write_text("old")
    with pytest.raises(FileExistsError, match=r"out: exists and is not empty; pass overwrite"):
        with fileio.staged_directory(target):  # overwrite defaults to False
            pass
    (tmp_path / "file").write_text("x")
    with pytest.raises(NotADirectoryError, match=r"file: exists and is not a directory"):
        with fileio.staged_directory(tmp_path / "file", overwrite=True):
            pass
    deep = tmp_path / "a" / "b" / "c"
    with fileio.staged_directory(deep) as tmp:
        (tmp / "f").write_text("f")
    assert (deep / "f").read_text() == "f"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a", "file", "out"]


def test_fsync_tree_syncs_every_directory(tmp_path, monkeypatch):
    (tmp_path / "d" / "e").mkdir(parents=True)
    (tmp_path / "d" / "f.txt").write_text("x")
    opened = []
    real_open = os.open

    def spy_open(path, flags, *args, **kwargs):
        opened.append(Path(path))
        return real_open(path, flags, *args, **kwargs)

    monkeypatch.setattr(os, "open", spy_open)
    fileio._fsync_tree(tmp_path)
    monkeypatch.undo()
    assert sorted(opened) == sorted([tmp_path, tmp_path / "d", tmp_path / "d" / "e"])


def test_remove_tree_never_raises(tmp_path):
    fileio._remove_tree(tmp_path / "missing")  # best effort: __exit__ must not hide the real error
    (tmp_path / "d" / "e").mkdir(parents=True)
    fileio._remove_tree(tmp_path / "d")
    assert not (tmp_path / "d").exists()


def test_carry_over_keeps_folders_links_and_files(tmp_path, monkeypatch):
    src, dst = tmp_path / "src", tmp_path / "dst"
    (src / "sub").mkdir(parents=True)
    dst.mkdir()
    (src / "sub" / "data.txt").write_text("data")
    os.symlink("data.txt", src / "sub" / "link")
    os.symlink("sub", src / "dirlink")
    (src / "note.txt").write_text("note")
    (src / "skip.txt").write_text("skip")
    fileio.carry_over(src, dst, exclude={"skip.txt"})
    assert sorted(p.name for p in dst.iterdir()) == ["dirlink", "note.txt", "sub"]
    assert (dst / "sub" / "data.txt").read_text() == "data"
    assert os.readlink(dst / "sub" / "link") == "data.txt"  # links inside copied folders stay links
    assert os.readlink(dst / "dirlink") == "sub"  # a link to a folder stays a link, not a copy
    assert (dst / "note.txt").stat().st_ino == (src / "note.txt").stat().st_ino  # hard link
    # Where hard links fail (another file system), the file is copied.
    other = tmp_path / "other"
    other.mkdir()

    def no_link(*args, **kwargs):
        raise OSError(errno.EXDEV, "cross-device link")

    monkeypatch.setattr(os, "link", no_link)
    fileio.carry_over(src, other, exclude={"sub", "dirlink", "skip.txt"})
    assert (other / "note.txt").read_text() == "note"
    assert (other / "note.txt").stat().st_ino != (src / "note.txt").stat().st_ino
    fileio.carry_over(tmp_path / "missing", other)  # no source folder: nothing to carry
    assert sorted(p.name for p in other.iterdir()) == ["note.txt"]


def test_staged_directory_is_a_hidden_sibling_with_the_usual_mode(tmp_path):
    target = tmp_path / "out"
    old = os.umask(0o027)
    try:
        with fileio.staged_directory(target) as tmp:
            assert tmp.parent == tmp_path and tmp.name.startswith(".out.new-")
    finally:
        os.umask(old)
    assert stat.S_IMODE(target.stat().st_mode) == 0o750  # not mkdtemp's private 0700


def test_json_is_indented_with_sorted_keys(tmp_path):
    path = fileio.atomic_write_json(tmp_path / "x.json", {"b": [1, 2], "a": "é"})
    assert path.read_bytes() == '{\n  "a": "\\u00e9",\n  "b": [\n    1,\n    2\n  ]\n}\n'.encode()


def test_atomic_write_bytes_temp_file_mode_and_cleanup(tmp_path, monkeypatch):
    target = tmp_path / "a" / "b" / "x.bin"  # missing parents are made
    renames = []
    real_replace = os.replace

    def spy_replace(src, dst):
        renames.append((Path(src), Path(dst)))
        return real_replace(src, dst)

    old = os.umask(0o022)
    try:
        with monkeypatch.context() as m:
            m.setattr(os, "replace", spy_replace)
            assert fileio.atomic_write_bytes(target, b"data") == target
    finally:
        os.umask(old)
    assert target.read_bytes() == b"data"
    assert stat.S_IMODE(target.stat().st_mode) == 0o644  # not mkstemp's private 0600
    # Written beside the target (same file system: the rename is atomic), hidden, then renamed.
    [(src, dst)] = renames
    assert dst == target and src.parent == target.parent
    assert src.name.startswith(".x.bin.") and src.name.endswith(".tmp")

    def failing_replace(src, dst):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", failing_replace)
    with pytest.raises(OSError, match="disk full"):
        fileio.atomic_write_bytes(target, b"new")
    assert target.read_bytes() == b"data"
    assert [p.name for p in target.parent.iterdir()] == ["x.bin"]  # the temp file is removed


def test_npz_errors_name_the_array_and_the_file(tmp_path):
    with pytest.raises(ValueError, match=r"array 'names' has dtype object; only numeric arrays"):
        fileio.atomic_save_npz(tmp_path / "x.npz", {"ok": np.zeros(2), "names": np.array([{}], dtype=object)})
    assert not (tmp_path / "x.npz").exists()
    with pytest.raises(FileNotFoundError, match=r"missing\.npz: no such file"):
        fileio.load_npz(tmp_path / "missing.npz")


def test_write_figure_png_renders_with_the_given_options(tmp_path):
    import struct

    from matplotlib.figure import Figure

    fig = Figure(figsize=(2.0, 1.0))
    fig.add_subplot().plot([0, 1], [1, 0])
    path = fileio.write_figure_png(fig, tmp_path / "plot.png", dpi=50)
    assert path == tmp_path / "plot.png"
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    assert struct.unpack(">II", data[16:24]) == (100, 50)  # IHDR width, height: 2 x 1 in at 50 dpi
