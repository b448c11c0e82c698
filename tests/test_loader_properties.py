"""Every loader, fed a damaged copy of a valid file, loads it or fails as one line naming the file
(issue 47 item 2): Hypothesis draws truncations, byte flips, numbers turned into words and key
typos, with fixed seeds (``derandomize``). A failure must be a ValueError or OSError (what
``drake-skill`` prints as ``drake-skill: error: ...``, exit 2), never another exception (a
traceback), and the damaged file is left byte for byte as it was.

Loaders and cases (``EXAMPLES`` each): skill file, scenario, learn config (through the CLI),
demonstration npz, robomimic HDF5, checkpoint (state.json + search.npz), experiment table.csv,
a run's summary.json.
"""

import contextlib
import io
import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

REPO = Path(__file__).resolve().parent.parent
EXAMPLES = 25
SETTINGS = settings(max_examples=EXAMPLES, derandomize=True, deadline=None, database=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


@st.composite
def damaged(draw, data: bytes, text: bool):
    """``data`` with one damage: cut short, one byte changed, (text) a number made a word or a key misspelt."""
    numbers = list(re.finditer(rb"(?<![\w.\-])\d+(?:\.\d+)?(?![\w.])", data)) if text else []
    keys = list(re.finditer(rb'(?m)^[ \t-]*"?([A-Za-z_]+)"?:', data)) if text else []
    kinds = ["truncate", "flip"] + (["number"] if numbers else []) + (["key"] if keys else [])
    kind = draw(st.sampled_from(kinds))
    if kind == "truncate":
        return data[:draw(st.integers(0, len(data) - 1))]
    if kind == "flip":
        k, value = draw(st.integers(0, len(data) - 1)), draw(st.integers(0, 255))
        return data[:k] + bytes([value]) + data[k + 1:]
    if kind == "number":
        m = draw(st.sampled_from(numbers))
        return data[:m.start()] + draw(st.sampled_from([b"three", b"yes", b"[]", b"{}", b"''"])) + data[m.end():]
    m = draw(st.sampled_from(keys))
    key = m.group(1)
    i = draw(st.integers(0, len(key) - 1))
    typo = key[:i] + key[i + 1:] if len(key) > 1 and draw(st.booleans()) else key[:i] + b"x" + key[i:]
    return data[:m.start(1)] + typo + data[m.end(1):]


def _check(load, path: Path, data: bytes) -> None:
    """Writes ``data`` to ``path``, loads it; a failure must be one clean line naming the file."""
    path.write_bytes(data)
    try:
        load(path)
    except (ValueError, OSError) as e:
        message = str(e)
        assert message and path.name in message, f"{type(e).__name__} names no file: {message}"
    assert path.read_bytes() == data


# ----------------------------------------------------------------------------- text files
SKILL = (REPO / "drake_skill" / "skills" / "open.yaml").read_bytes()
SCENARIO = (REPO / "drake_skill" / "station" / "scenarios" / "box_closed.yaml").read_bytes()
LEARN = b"""skill: open
learn:
  method: pi2-es-cov
  reward: dense
  episodes: 5
  rollouts: 6
  seed: 0
  held_out: 10
workers: 1
"""


@SETTINGS
@given(data=damaged(SKILL, text=True))
def test_a_damaged_skill_file(tmp_path, data):
    from drake_skill.skills import load_skill

    _check(load_skill, tmp_path / "open.yaml", data)


@SETTINGS
@given(data=damaged(SCENARIO, text=True))
def test_a_damaged_scenario(tmp_path, data):
    from drake_skill.inputs import scenario

    _check(lambda p: scenario("open", p), tmp_path / "scene.yaml", data)


@SETTINGS
@given(data=damaged(LEARN, text=True))
def test_a_damaged_learn_config(tmp_path, data):
    from drake_skill.cli.learn_config import LearnFile
    from drake_skill.typed_yaml import load_typed

    _check(lambda p: load_typed(LearnFile, what="--config", path=p).learn.validate(), tmp_path / "learn.yaml", data)


@settings(SETTINGS, max_examples=4)
@given(data=damaged(LEARN, text=True))
def test_a_damaged_learn_config_through_the_command(tmp_path, data):
    """The command itself: exit 0, or 2 with one line (a few examples: each loads a skill)."""
    from drake_skill.cli.main import main

    path = tmp_path / "learn.yaml"
    path.write_bytes(data)
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        code = main(["learn", "--config", str(path), "--print-config"])
    assert code == 0 or (code == 2 and err.getvalue().startswith("drake-skill: error: ")
                         and err.getvalue().count("\n") == 1), (code, err.getvalue())
    assert path.read_bytes() == data


# ----------------------------------------------------------------------------- data files
@pytest.fixture(scope="module")
def valid_files(tmp_path_factory):
    """A demonstration npz, its robomimic export, a checkpoint, a table.csv and a summary.json."""
    from learning_support import shared_skill

    from drake_skill.demos.robomimic import export_robomimic
    from drake_skill.learning.loop import RunState
    from drake_skill.learning.policy_search import make_policy_search

    root = tmp_path_factory.mktemp("valid")
    demos = shared_skill(tmp_path_factory)["demos_dir"]
    one = root / "one_demo"
    one.mkdir()
    shutil.copy(demos / "demo_000.npz", one / "demo_000.npz")
    export_robomimic(one, root / "demos.hdf5")
    search = make_policy_search("pi2-es-cov", np.zeros((3, 7)), np.tile(np.eye(7), (3, 1, 1)), n_episodes=2, seed=0)
    RunState(search, [{"type": "rollout", "episode": 0}], [{"episode": 0}], [], None).save(root / "checkpoint")
    grid = REPO / "docs" / "results" / "experiment"
    lines = (grid / "table.csv").read_bytes().splitlines(keepends=True)
    summary = next(grid.glob("*/*/*/run_*/summary.json")).read_bytes()
    (root / "table.csv").write_bytes(b"".join(lines[:40]))
    (root / "summary.json").write_bytes(summary)
    return _Files({"npz": one / "demo_000.npz", "hdf5": root / "demos.hdf5",
                   "state": root / "checkpoint" / "state.json", "search": root / "checkpoint" / "search.npz",
                   "table": root / "table.csv", "summary": root / "summary.json"})


class _Files(dict):
    """{kind: path} of the valid files; ``[kind]`` reads the bytes. A short repr: Hypothesis prints
    the arguments of a failing example."""

    def __getitem__(self, kind):
        return dict.__getitem__(self, kind).read_bytes()

    def __repr__(self):
        return "valid_files"


@SETTINGS
@given(damage=st.data())
def test_a_damaged_demonstration(tmp_path, valid_files, damage):
    from drake_skill.demos.format import load_demonstration

    _check(load_demonstration, tmp_path / "demo_000.npz", damage.draw(damaged(valid_files["npz"], text=False)))


@SETTINGS
@given(damage=st.data())
def test_a_damaged_robomimic_file(tmp_path, valid_files, damage):
    from drake_skill.demos.robomimic import read_robomimic

    _check(read_robomimic, tmp_path / "demos.hdf5", damage.draw(damaged(valid_files["hdf5"], text=False)))


@SETTINGS
@given(damage=st.data(), which=st.sampled_from(["state", "search"]))
def test_a_damaged_checkpoint(tmp_path, valid_files, damage, which):
    from drake_skill.learning.loop import RunState

    checkpoint = tmp_path / "checkpoint"
    checkpoint.mkdir(exist_ok=True)
    (checkpoint / "state.json").write_bytes(valid_files["state"])
    (checkpoint / "search.npz").write_bytes(valid_files["search"])
    name = "state.json" if which == "state" else "search.npz"
    _check(lambda _: RunState.load(checkpoint), checkpoint / name,
           damage.draw(damaged(valid_files[which], text=which == "state")))


@SETTINGS
@given(damage=st.data())
def test_a_damaged_experiment_table(tmp_path, valid_files, damage):
    from drake_skill.experiments.table import read_table

    _check(read_table, tmp_path / "table.csv", damage.draw(damaged(valid_files["table"], text=False)))


@SETTINGS
@given(damage=st.data())
def test_a_damaged_run_summary(tmp_path, valid_files, damage):
    from drake_skill.experiments.table import stored_runs

    run = tmp_path / "grid" / "open" / "pi2" / "dense" / "run_000"
    run.mkdir(parents=True, exist_ok=True)
    _check(lambda _: stored_runs(tmp_path / "grid"), run / "summary.json",
           damage.draw(damaged(valid_files["summary"], text=True)))


def test_the_valid_files_load(tmp_path, valid_files):
    """The starting points are valid, so every damage above starts from a file that loads."""
    from drake_skill.demos.format import load_demonstration
    from drake_skill.demos.robomimic import read_robomimic
    from drake_skill.experiments.table import read_table
    from drake_skill.learning.loop import RunState

    for name, data in (("demo_000.npz", "npz"), ("demos.hdf5", "hdf5"), ("table.csv", "table")):
        (tmp_path / name).write_bytes(valid_files[data])
    assert load_demonstration(tmp_path / "demo_000.npz").skill == "close"
    assert read_robomimic(tmp_path / "demos.hdf5")[0].skill == "close"
    assert len(read_table(tmp_path / "table.csv")) == 39
    (tmp_path / "checkpoint").mkdir()
    (tmp_path / "checkpoint" / "state.json").write_bytes(valid_files["state"])
    (tmp_path / "checkpoint" / "search.npz").write_bytes(valid_files["search"])
    assert RunState.load(tmp_path / "checkpoint").search.mean.shape == (3, 7)
    assert json.loads(valid_files["summary"])["skill"] in ("open", "close", "draw")
