"""Directory writes that cannot mix (issue 12, group 4): an interruption injected at
every file-system step of ``Skill.save(overwrite=True)`` and ``demos record --force``
leaves a folder that loads as wholly the old set or wholly the new one."""

import shutil

import pytest

from drake_skill import fileio
from drake_skill.skill import Skill

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
