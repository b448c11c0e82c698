"""``drake-skill demos list / replay / export / import``: robomimic HDF5 round trip, tables, replays."""

import base64
import json
import re
import sys

import h5py
import numpy as np
import pytest

from drake_skill.cli.main import main
from drake_skill.demos.format import (MANIFEST, DemonstrationError, load_demonstrations, save_demonstration,
                                      save_demonstrations)
from test_demonstrations import _assert_same, make_demo


@pytest.fixture
def demo_dir(tmp_path):
    out = tmp_path / "open"
    save_demonstrations([make_demo(0), make_demo(1, perception=False), make_demo(2, n=151)], out)
    return out


def test_export_then_import_gives_the_same_arrays_bit_for_bit(tmp_path, demo_dir, capsys):
    originals = load_demonstrations(demo_dir)
    assert main(["demos", "export", "--format", "robomimic", str(demo_dir), str(tmp_path / "open.hdf5")]) == 0
    assert f"wrote {tmp_path / 'open.hdf5'}: 3 demonstration(s), 42 samples" in capsys.readouterr().out
    assert main(["demos", "import", str(tmp_path / "open.hdf5"), str(tmp_path / "back")]) == 0
    imported = load_demonstrations(tmp_path / "back", skill="open")     # the normal loader, manifest included
    assert (tmp_path / "back" / MANIFEST).is_file() and len(imported) == 3
    for a, b in zip(originals, imported):
        _assert_same(a, b)      # every array: dtype, shape and values equal; scalars and metadata equal


def test_export_has_robomimics_layout(tmp_path, demo_dir):
    originals = load_demonstrations(demo_dir)
    assert main(["demos", "export", str(demo_dir), str(tmp_path / "open.hdf5")]) == 0
    with h5py.File(tmp_path / "open.hdf5", "r") as f:
        data = f["data"]
        assert sorted(data) == ["demo_0", "demo_1", "demo_2"]
        assert data.attrs["total"] == sum(d.n_samples for d in originals) == 13 + 13 + 16
        env = json.loads(data.attrs["env_args"])
        assert env["env_name"] == "drake-skill-open" and env["env_kwargs"]["skill"] == "open"
        assert env["env_kwargs"]["scenario"] == "box_closed"      # drake_skill/skills/open.yaml names it
        for i, d in enumerate(originals):
            g = data[f"demo_{i}"]
            n = d.n_samples
            assert g.attrs["num_samples"] == n
            obs = g["obs"]
            idx = np.arange(0, d.times_100hz.size, 10)      # the 10 Hz samples of a 100 Hz recording
            np.testing.assert_array_equal(obs["joint_positions"][()], d.q_100hz[idx])
            np.testing.assert_array_equal(obs["hand_pose"][()], d.X_OE)
            np.testing.assert_array_equal(obs["gripper_opening"][()], d.gripper_100hz[idx, None])
            np.testing.assert_array_equal(obs["object_state"][()], d.object_state_100hz[idx, None])
            assert ("object_points" in obs) == d.has_perception
            if d.has_perception:
                np.testing.assert_array_equal(obs["object_points"][()], d.object_points)
                assert obs["object_points"].dtype == np.float32
            # Schema 2: per-sample columns in obs, the three pictures beside the 100 Hz data.
            np.testing.assert_array_equal(obs["peak_force"][()], d.peak_force[:, None])
            assert ("pixels_hue" in obs) == ("snapshot_rgb" in g["drake_skill"]) == d.has_perception
            if d.has_perception:
                np.testing.assert_array_equal(obs["pixels_kept"][()], d.pixels_kept[:, None])
                np.testing.assert_array_equal(obs["pixels_hue"][()], d.pixels_hue[:, None])
                assert obs["pixels_coloured"].dtype == np.int64 and obs["pixels_coloured"].shape == (n, 1)
                np.testing.assert_array_equal(g["drake_skill/snapshot_segment"][()], d.snapshot_segment)
            # Actions: the next sample's hand pose (the last repeats its own) and the gripper command.
            act = g["actions"][()]
            assert act.shape == (n, 8)
            np.testing.assert_array_equal(act[:-1, :7], d.X_OE[1:])
            np.testing.assert_array_equal(act[-1, :7], d.X_OE[-1])
            np.testing.assert_array_equal(act[:, 7], d.gripper_100hz[idx])
            np.testing.assert_array_equal(g["dones"][()], np.r_[np.zeros(n - 1), 1])
            np.testing.assert_array_equal(g["rewards"][()], np.r_[np.zeros(n - 1), 1.0])   # all succeeded


def test_export_and_import_errors_are_one_line(tmp_path, demo_dir, capsys):
    target = tmp_path / "open.hdf5"
    target.write_text("x")
    assert main(["demos", "export", str(demo_dir), str(target)]) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"drake-skill: error: OUT.hdf5 {target}: exists; pass --force to replace it or choose another file"
    assert main(["demos", "import", str(target), str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"drake-skill: error: {target}: not a readable HDF5 file") and "\n" not in err
    assert err.endswith("export it again with 'drake-skill demos export DIR OUT.hdf5'")
    with h5py.File(tmp_path / "empty.hdf5", "w") as f:        # an HDF5 file of another kind
        f.create_group("mask")
    assert main(["demos", "import", str(tmp_path / "empty.hdf5"), str(tmp_path / "x")]) == 2
    assert capsys.readouterr().err.strip().endswith(
        "group 'data' is missing; not a robomimic dataset: import a file written by 'drake-skill demos export "
        "DIR OUT.hdf5'")
    with h5py.File(tmp_path / "other.hdf5", "w") as f:        # a robomimic file from elsewhere
        f.create_group("data/demo_0/obs")
    assert main(["demos", "import", str(tmp_path / "other.hdf5"), str(tmp_path / "x")]) == 2
    assert "data/demo_0: group 'drake_skill' is missing; only datasets written by 'drake-skill demos export'" \
        in capsys.readouterr().err
    assert not (tmp_path / "x").exists()
    # Importing over existing demonstrations needs --force.
    assert main(["demos", "export", "--force", str(demo_dir), str(target)]) == 0
    assert main(["demos", "import", str(target), str(demo_dir)]) == 2
    assert "already holds 3 demonstration file(s); pass --force" in capsys.readouterr().err
    assert main(["demos", "import", "--force", str(target), str(demo_dir)]) == 0


def test_list_prints_a_row_per_demonstration(demo_dir, capsys):
    assert main(["demos", "list", str(demo_dir)]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[0].split()[:3] == ["#", "file", "skill"]
    assert lines[1].split() == ["0", "demo_000.npz", "open", "1.20", "121", "/", "13", "11/13", "yes", "test"]
    assert lines[2].split()[7:] == ["-", "yes", "test"] and lines[3].split()[3] == "1.50"
    assert lines[-1] == f"3 demonstration(s) in {demo_dir}"
    # A folder that does not load as a set: listed, with the reason, and exit status 1.
    save_demonstration(make_demo(9, skill="close"), demo_dir / "demo_003.npz")
    assert main(["demos", "list", str(demo_dir)]) == 1
    captured = capsys.readouterr()
    assert "demo_003.npz  close" in captured.out and "does not load as one set" in captured.out
    assert "do not match demos.json" in captured.err and "mixes skills (close, open)" in captured.err


def test_replay_writes_a_meshcat_page_per_demonstration(tmp_path):
    out = tmp_path / "open"
    save_demonstrations([make_demo(0, perception=False), make_demo(1, perception=False)], out)
    assert main(["demos", "replay", str(out)]) == 0
    pages = sorted((tmp_path / "open_replay").iterdir())            # beside the folder by default
    assert [p.name for p in pages] == ["demo_000.html", "demo_001.html"]
    animations = []
    for page in pages:
        text = page.read_text()
        assert text.startswith("<!DOCTYPE html>")
        # Meshcat's page replays msgpack commands embedded as base64 data URIs.
        commands = [base64.b64decode(m) for m in re.findall(r'base64,([A-Za-z0-9+/=]+)"', text)]
        (animation,) = [c for c in commands if b"set_animation" in c]
        assert b"panda_link7" in animation and b"box_lid" in animation      # the arm and the object move
        animations.append(animation)
    assert animations[0] != animations[1]           # each page plays its own joint positions


# ----------------------------------------------------------------------------- drake_skill.demos.robomimic directly
def _export(tmp_path, demos, name="set"):
    from drake_skill.demos.robomimic import export_robomimic

    save_demonstrations(demos, tmp_path / name)
    return export_robomimic(tmp_path / name, tmp_path / f"{name}.hdf5")


def test_export_attributes_rewards_and_perception_by_hand(tmp_path):
    failed = make_demo(3, perception=False)
    failed.success = False
    failed.final_object_state = 0.25
    path, demos = _export(tmp_path, [make_demo(0), failed])
    assert path == tmp_path / "set.hdf5" and [d.seed for d in demos] == [0, 3]
    with h5py.File(path, "r") as f:
        assert json.loads(f["data"].attrs["env_args"]) == {
            "env_name": "drake-skill-open", "type": "drake-skill",
            "env_kwargs": {"skill": "open", "rate_hz": 10.0, "scenario": "box_closed",
                           "action": "X_OE of the next sample (m, quaternion wxyz) and the gripper opening (m)"}}
        assert f["data"].attrs["env_args"].startswith('{"env_kwargs": {"action": ')       # sorted keys
        with_points, without = f["data/demo_0"], f["data/demo_1"]
        points = with_points["obs/object_points"]
        assert (points.compression, points.compression_opts) == ("gzip", 4)
        np.testing.assert_array_equal(with_points["obs/object_points_valid"][()], demos[0].perception_valid)
        np.testing.assert_array_equal(with_points["drake_skill/X_WO_start"][()], demos[0].X_WO_start)
        assert "object_points" not in without["obs"] and "X_WO_start" not in without["drake_skill"]
        np.testing.assert_array_equal(without["rewards"][()], np.zeros(failed.n_samples))
        assert without["dones"].dtype == np.int64 and without["rewards"].dtype == np.float64
        raw = without["drake_skill"].attrs
        assert (raw["skill"], raw["seed"], raw["success"], raw["final_object_state"]) == ("open", 3, False, 0.25)
        assert raw["seed"].dtype == np.int64 and type(raw["final_object_state"]) in (float, np.float64)
        assert raw["metadata"] == '{"source": "test", "variation": {"pause_s": 0.25}}'
        assert raw["source_file"] == "demo_001.npz"
        for name in ("times_100hz", "X_OE_100hz", "q_100hz", "gripper_100hz", "object_state_100hz", "times",
                     "X_WO_true"):
            np.testing.assert_array_equal(without[f"drake_skill/{name}"][()], getattr(demos[1], name))


def test_actions_and_sample_indices_by_hand():
    from drake_skill.demos.robomimic import _sample_indices, actions

    demo = make_demo(0, perception=False, n=31)              # 10 Hz samples at 0, 0.1, 0.2, 0.3 s
    demo.gripper_100hz = np.arange(31) / 1000.0
    np.testing.assert_array_equal(_sample_indices(demo), [0, 10, 20, 30])
    act = actions(demo)
    np.testing.assert_array_equal(act[:, :7], demo.X_OE[[1, 2, 3, 3]])
    np.testing.assert_array_equal(act[:, 7], [0.0, 0.01, 0.02, 0.03])
    # Times off the raw ones by up to 1e-9 still find them; more is an error.
    demo.times = demo.times + np.r_[0.0, 0.9e-9, -0.9e-9, 0.0]
    np.testing.assert_array_equal(_sample_indices(demo), [0, 10, 20, 30])
    demo.times[1] += 2e-9
    demo.path = "here.npz"
    with pytest.raises(DemonstrationError) as e:
        _sample_indices(demo)
    assert str(e.value) == "here.npz: field 'times' is not a subset of times_100hz"


def test_export_refuses_two_skills_and_names_no_scenario_for_a_users_skill(tmp_path):
    from drake_skill.demos.robomimic import export_robomimic

    save_demonstrations([make_demo(0, perception=False), make_demo(1, perception=False, skill="close")],
                        tmp_path / "mixed")
    with pytest.raises(DemonstrationError) as e:
        export_robomimic(tmp_path / "mixed", tmp_path / "mixed.hdf5")
    assert str(e.value) == (f"{tmp_path / 'mixed'}: holds demonstrations of close, open; a robomimic dataset is "
                            "one task: export one skill's folder")
    path, _ = _export(tmp_path, [make_demo(0, perception=False, skill="my_skill")], "mine")
    with h5py.File(path, "r") as f:
        kwargs = json.loads(f["data"].attrs["env_args"])["env_kwargs"]
    assert "scenario" not in kwargs and kwargs["skill"] == "my_skill"


def test_read_orders_demos_by_number_and_names_what_is_missing(tmp_path):
    from drake_skill.demos.robomimic import import_robomimic, read_robomimic

    path, demos = _export(tmp_path, [make_demo(i, perception=False) for i in range(3)])
    with h5py.File(path, "a") as f:
        f["data"].move("demo_1", "demo_10")
        f.create_group("data/mask")                           # robomimic's filter keys: not a demo
        f.create_group("data/demo_x")
    assert [d.seed for d in read_robomimic(str(path))] == [0, 2, 1]          # demo_10 after demo_2
    paths, imported = import_robomimic(path, tmp_path / "back")
    assert [p.name for p in paths] == ["demo_000.npz", "demo_001.npz", "demo_002.npz"]
    assert [d.seed for d in imported] == [0, 2, 1]
    assert imported[0].path == f"{path}:/data/demo_0"
    with pytest.raises(FileNotFoundError) as e:
        read_robomimic(tmp_path / "none.hdf5")
    assert str(e.value) == f"{tmp_path / 'none.hdf5'}: no such file"

    def damaged(edit):
        target = tmp_path / "damaged.hdf5"
        target.write_bytes(path.read_bytes())
        with h5py.File(target, "a") as f:
            edit(f)
        with pytest.raises(DemonstrationError) as e:
            read_robomimic(target)
        return str(e.value).replace(str(target), "F")

    assert damaged(lambda f: [f["data"].pop(n) for n in list(f["data"])]) == (
        "F: 'data' has no demo_N groups; nothing to import: export a folder that holds demonstrations "
        "('drake-skill demos list DIR' shows them)")
    assert damaged(lambda f: f["data/demo_10/drake_skill"].attrs.pop("seed")) == \
        "F:/data/demo_10/drake_skill: attribute 'seed' is missing"
    assert damaged(lambda f: f["data/demo_0/drake_skill"].attrs.__setitem__("metadata", "{x")).startswith(
        "F:/data/demo_0/drake_skill: attribute 'metadata' is not JSON (")
    assert damaged(lambda f: f["data/demo_0/drake_skill"].pop("q_100hz")) == (
        "F:/data/demo_0: '/data/demo_0/drake_skill/q_100hz' is missing; not a dataset written by "
        "'drake-skill demos export --format robomimic'")
    assert damaged(lambda f: f["data/demo_0/obs"].pop("hand_pose")) == (
        "F:/data/demo_0: '/data/demo_0/obs/hand_pose' is missing; not a dataset written by "
        "'drake-skill demos export --format robomimic'")
    assert damaged(lambda f: f["data/demo_0"].pop("obs")) == (
        "F:/data/demo_0: '/data/demo_0/hand_pose' is missing; not a dataset written by "
        "'drake-skill demos export --format robomimic'")
    assert damaged(lambda f: f["data/demo_0"].pop("drake_skill")) == (
        "F:/data/demo_0: group 'drake_skill' is missing; only datasets written by 'drake-skill demos export' can be "
        "imported (they carry the 100 Hz data)")
    # A demonstration the file holds but that is invalid is named by its place in the file.
    assert damaged(lambda f: f["data/demo_10/drake_skill"].attrs.__setitem__("skill", "")).startswith(
        "F:/data/demo_10")


def test_read_of_perception_and_damaged_bytes(tmp_path):
    from drake_skill.demos.robomimic import read_robomimic

    path, demos = _export(tmp_path, [make_demo(0)])
    back, = read_robomimic(path)
    _assert_same(demos[0], back)
    target = tmp_path / "damaged.hdf5"
    target.write_bytes(path.read_bytes())
    with h5py.File(target, "a") as f:
        f["data/demo_0/drake_skill"].pop("X_WO_start")
    with pytest.raises(DemonstrationError) as e:
        read_robomimic(target)
    assert str(e.value) == (f"{target}:/data/demo_0: '/data/demo_0/drake_skill/X_WO_start' is missing; not a "
                            "dataset written by 'drake-skill demos export --format robomimic'")
    target.write_bytes(path.read_bytes())
    with h5py.File(target, "a") as f:
        f["data/demo_0/obs"].pop("object_points_valid")
    with pytest.raises(DemonstrationError) as e:
        read_robomimic(target)
    assert str(e.value).startswith(f"{target}:/data/demo_0: '/data/demo_0/obs/object_points_valid' is missing")
    target.write_bytes(path.read_bytes())
    with h5py.File(target, "a") as f:                 # a value h5py reads but that is no number
        f["data/demo_0/drake_skill"].attrs["final_object_state"] = "abc"
    with pytest.raises(ValueError) as e:
        read_robomimic(target)
    assert str(e.value) == (f"{target}: damaged HDF5 (ValueError: could not convert string to float: 'abc'); "
                            "export it again with 'drake-skill demos export DIR OUT.hdf5'")


def test_robomimic_edges_found_by_mutation(tmp_path, monkeypatch):
    from drake_skill.demos import robomimic

    # Metadata is written with sorted keys, whatever order the demonstration holds them in.
    demo = make_demo(0, perception=False)
    demo.metadata = {"z": 1, "a": {"y": 2, "b": 3}}
    path, _ = _export(tmp_path, [demo])
    with h5py.File(path, "r") as f:
        assert f["data/demo_0/drake_skill"].attrs["metadata"] == '{"a": {"b": 3, "y": 2}, "z": 1}'
    # Importing over existing demonstrations needs force.
    with pytest.raises(FileExistsError, match="pass --force"):
        robomimic.import_robomimic(path, tmp_path / "set")
    # 10 Hz times past the last raw one are the named error, not an IndexError.
    late = make_demo(0, perception=False, n=31)
    late.times = late.times + np.r_[0.0, 0.0, 0.0, 0.005]
    late.path = "late.npz"
    with pytest.raises(DemonstrationError, match="late.npz: field 'times' is not a subset of times_100hz"):
        robomimic._sample_indices(late)
    # A file h5py cannot open: its reason in one line, as h5py gives it.
    text = tmp_path / "text.hdf5"
    text.write_text("x")
    with pytest.raises(ValueError) as e:
        robomimic.read_robomimic(text)
    assert str(e.value).startswith(f"{text}: not a readable HDF5 file (Unable to synchronously open file (file "
                                   "signature not found)): a file cut short or of another format")
    # Without h5py: the named ImportError.
    monkeypatch.setitem(sys.modules, "h5py", None)
    with pytest.raises(ImportError) as e:
        robomimic._h5py()
    assert str(e.value) == "the robomimic format needs h5py: pip install 'h5py>=3.10'"


def test_a_schema_1_demonstration_goes_through_robomimic_without_the_new_fields(tmp_path):
    import dataclasses as dc

    from drake_skill.demos.robomimic import read_robomimic
    from test_demonstrations import SCHEMA2_FIELDS

    old = dc.replace(make_demo(0), **dict.fromkeys(SCHEMA2_FIELDS))
    path, demos = _export(tmp_path, [old])
    with h5py.File(path, "r") as f:
        assert not {"peak_force", "pixels_hue", "pixels_coloured", "pixels_kept"} & set(f["data/demo_0/obs"])
        assert "snapshot_rgb" not in f["data/demo_0/drake_skill"]
    back, = read_robomimic(path)
    _assert_same(old, back)
