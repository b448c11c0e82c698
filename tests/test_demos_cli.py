"""``drake-skill demos list / replay / export / import``: robomimic HDF5 round trip, tables, replays."""

import base64
import json
import re

import h5py
import numpy as np
import pytest

from drake_skill.cli.main import main
from drake_skill.demos.format import MANIFEST, load_demonstrations, save_demonstration, save_demonstrations
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
