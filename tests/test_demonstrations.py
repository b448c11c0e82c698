"""Demonstration files: exact round trip, validation errors naming file and field, corrupt files refused."""

import json
import re
import zipfile

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw

from drake_skill.demos.format import (
    SCHEMA_VERSION,
    Demonstration,
    DemonstrationError,
    demo_path,
    downsample_action,
    first_move,
    load_demonstration,
    load_demonstrations,
    object_frame_poses,
    save_demonstration,
    snapshot_frames,
)


def _vec(X):
    return np.r_[X.translation(), X.rotation().ToQuaternion().wxyz()]


def make_demo(seed=0, perception=True, skill="open", n=121) -> Demonstration:
    """A valid synthetic demonstration: n samples at 100 Hz, every 10th at 10 Hz; schema 2's fields
    (with perception, the segment's counts and 3 pictures of 6 x 8 pixels; touching from sample 5)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 100.0
    X_WO = RigidTransform(RollPitchYaw(0, 0, 0.05), [0.6, 0.01, 0.0])
    X_WE = [RigidTransform(RollPitchYaw(np.pi, 0.1 * s, 0.2 * s), [0.4 + 0.1 * s, 0.05 * s, 0.4 - 0.2 * s])
            for s in np.linspace(0, 1, n)]
    X_OE_raw = object_frame_poses(_vec(X_WO), np.array([_vec(X) for X in X_WE]))
    idx, t10, X_OE = downsample_action(t, X_OE_raw)
    m = idx.size
    extra = {}
    if perception:
        extra = dict(object_points=rng.normal(size=(m, 2048, 3)).astype(np.float32),
                     perception_valid=rng.uniform(size=m) > 0.1,
                     X_WO_start=_vec(X_WO) + np.r_[0.002, -0.001, 0, 0, 0, 0, 0])
    extra.update(_schema2(seed, m, perception))
    return Demonstration(
        skill=skill, seed=seed, success=True, final_object_state=1.6,
        times_100hz=t, X_OE_100hz=X_OE_raw, q_100hz=rng.normal(size=(n, 7)),
        gripper_100hz=np.zeros(n), object_state_100hz=np.linspace(0, 1.6, n),
        times=t10, X_OE=X_OE, X_WO_true=_vec(X_WO),
        metadata={"source": "test", "variation": {"pause_s": 0.25}}, **extra)


def _schema2(seed: int, m: int, perception: bool) -> dict:
    """Schema 2's fields for m samples (their own generator: make_demo's other arrays keep their values)."""
    rng = np.random.default_rng([seed, 2])
    fields = dict(peak_force=np.where(np.arange(m) >= 5, rng.uniform(0.6, 3.0, m), 0.0))
    if perception:
        coloured = rng.integers(5000, 6000, m)
        fields.update(pixels_hue=coloured + rng.integers(0, 20, m), pixels_coloured=coloured,
                      pixels_kept=coloured - rng.integers(0, 100, m), snapshot_index=np.array([0, 5, m - 1]),
                      snapshot_rgb=rng.integers(0, 256, (3, 6, 8, 3), dtype=np.uint8),
                      snapshot_segment=rng.integers(0, 4, (3, 6, 8), dtype=np.uint8))
    return fields


SCHEMA2_FIELDS = ("peak_force", "pixels_hue", "pixels_coloured", "pixels_kept", "snapshot_index", "snapshot_rgb",
                  "snapshot_segment")


def _assert_same(a: Demonstration, b: Demonstration):
    for f in ("skill", "seed", "success", "final_object_state", "metadata"):
        assert getattr(a, f) == getattr(b, f), f
    for f in ("times_100hz", "X_OE_100hz", "q_100hz", "gripper_100hz", "object_state_100hz",
              "times", "X_OE", "X_WO_true", "X_WO_start", "object_points", "perception_valid") + SCHEMA2_FIELDS:
        x, y = getattr(a, f), getattr(b, f)
        if x is None:
            assert y is None, f
            continue
        assert x.dtype == y.dtype and x.shape == y.shape, f
        assert np.array_equal(x, y), f


@pytest.mark.parametrize("perception", [True, False])
def test_round_trip_is_exact(tmp_path, perception):
    demo = make_demo(perception=perception)
    path = save_demonstration(demo, demo_path(tmp_path, 0))
    assert path.name == "demo_000.npz"
    back = load_demonstration(path)
    _assert_same(demo, back)
    assert back.path == str(path) and demo.path is None
    assert back.has_perception is perception
    assert back.n_samples == 13 and back.duration == pytest.approx(1.2)
    # Readable with plain numpy, no pickle; metadata is JSON with units and frames.
    with np.load(path, allow_pickle=False) as data:
        meta = json.loads(data["metadata"].item())
        assert data["object_points"].shape == (13, 2048, 3) if perception else "object_points" not in data
    assert meta["schema_version"] == SCHEMA_VERSION
    assert meta["units"]["X_OE"].startswith("m") and "object frame" in meta["frames"]["X_OE"]
    assert meta["rates_hz"] == {"action_raw": 100.0, "action": 10.0, "perception": 10.0}


def test_existing_file_is_not_overwritten_without_force(tmp_path):
    path = save_demonstration(make_demo(seed=1), tmp_path / "demo_000.npz")
    before = path.read_bytes()
    with pytest.raises(FileExistsError, match="demo_000.npz exists"):
        save_demonstration(make_demo(seed=2), path)
    assert path.read_bytes() == before
    save_demonstration(make_demo(seed=2), path, force=True)
    assert load_demonstration(path).seed == 2


def test_invalid_demo_is_refused_before_writing(tmp_path):
    demo = make_demo()
    demo.X_OE[3, 0] = np.nan
    path = tmp_path / "demo_000.npz"
    with pytest.raises(DemonstrationError, match=r"demo_000.npz: field 'X_OE' contains NaN .*index \(3, 0\)"):
        save_demonstration(demo, path)
    assert not path.exists()


def _write_arrays(path, arrays):
    np.savez(path, **arrays)
    return path


@pytest.mark.parametrize("mutate,field,message", [
    (lambda a: a.update(X_OE_100hz=a["X_OE_100hz"][:, :6]), "X_OE_100hz", r"shape \(121, 6\); expected \(121, 7\)"),
    (lambda a: a["q_100hz"].__setitem__((5, 2), np.inf), "q_100hz", "NaN or inf"),
    (lambda a: a["X_OE"].__setitem__((2, 3), 2.0), "X_OE", "quaternion of norm .* at sample 2"),
    (lambda a: a["times"].__setitem__(4, a["times"][3]), "times", r"not strictly increasing \(t\[3\]"),
    (lambda a: a.update(times=a["times"][:9], X_OE=a["X_OE"][:9], object_points=a["object_points"][:9],
                        perception_valid=a["perception_valid"][:9]), "times", "9 samples; expected at least 10"),
    (lambda a: a.update(object_points=a["object_points"].astype(np.float64)), "object_points", "float32"),
    (lambda a: a.update(skill=np.array("juggle it")), "skill", "'juggle it'; expected a skill's name"),
    (lambda a: a.pop("X_WO_true"), "X_WO_true", "is missing"),
    (lambda a: a.pop("perception_valid"), "perception_valid", "is missing"),
    # issue 12, group 3: the cloud size, degenerate clouds marked valid, X_OE vs X_OE_100hz
    (lambda a: a.update(object_points=a["object_points"][:, :1000]), "object_points",
     r"shape \(13, 1000, 3\).*expected \(13, 2048, 3\) float32"),
    (lambda a: (a["object_points"].__setitem__(4, 0.0), a["perception_valid"].__setitem__(4, True)),
     "object_points", r"frame 4 is marked valid but its cloud is degenerate .*mark it invalid"),
    (lambda a: (a["object_points"].__setitem__((6, slice(None), slice(0, 2)), 0.3),
                a["perception_valid"].__setitem__(6, True)),
     "object_points", r"frame 6 is marked valid but its cloud is degenerate"),
    (lambda a: a["X_OE"].__setitem__((5, 0), a["X_OE"][5, 0] + 0.01), "X_OE",
     r"sample 5 \(0\.500 s\) differs from X_OE_100hz at the same instant \(position by 0\.01 m\)"),
    (lambda a: a["times"].__setitem__(3, a["times"][3] + 0.004), "times",
     r"sample 3 \(0\.304000 s\) is not one of the times_100hz instants"),
])
def test_loader_names_file_and_field(tmp_path, mutate, field, message):
    arrays = make_demo().to_arrays()
    mutate(arrays)
    path = _write_arrays(tmp_path / "demo_007.npz", arrays)
    with pytest.raises(DemonstrationError) as err:
        load_demonstration(path)
    text = str(err.value)
    assert text.startswith(f"{path}: field '{field}'"), text
    assert re.search(message, text), text


def test_wrong_schema_version_is_refused(tmp_path):
    arrays = make_demo().to_arrays()
    meta = json.loads(arrays["metadata"].item())
    meta["schema_version"] = SCHEMA_VERSION + 1
    arrays["metadata"] = np.array(json.dumps(meta))
    path = _write_arrays(tmp_path / "demo_000.npz", arrays)
    with pytest.raises(DemonstrationError, match=rf"demo_000.npz: field 'metadata.schema_version' is "
                                                 rf"{SCHEMA_VERSION + 1}; this drake-skill reads versions 1, 2$"):
        load_demonstration(path)
    meta["schema_version"] = 2.0      # a number that equals a version is not one
    arrays["metadata"] = np.array(json.dumps(meta))
    _write_arrays(path, arrays)
    with pytest.raises(DemonstrationError, match=r"'metadata.schema_version' is 2.0; this drake-skill reads versions"):
        load_demonstration(path)


@pytest.mark.parametrize("perception", [True, False])
def test_a_schema_1_file_still_loads(tmp_path, perception):
    """A file written before schema 2 (no peak_force, pixels_* or snapshot_*) loads unchanged; schema-2
    arrays in a version-1 file are not read; saved again, it is a schema-2 file without them."""
    demo = make_demo(perception=perception)
    arrays = {k: v for k, v in demo.to_arrays().items() if k not in SCHEMA2_FIELDS}
    meta = json.loads(arrays["metadata"].item())
    meta["schema_version"] = 1
    arrays["metadata"] = np.array(json.dumps(meta))
    path = _write_arrays(tmp_path / "demo_000.npz", arrays)
    old = load_demonstration(path)
    assert not old.has_segment and all(getattr(old, f) is None for f in SCHEMA2_FIELDS)
    for f in ("times_100hz", "X_OE_100hz", "q_100hz", "times", "X_OE", "object_points", "perception_valid"):
        assert np.array_equal(getattr(old, f), getattr(demo, f), equal_nan=False) or getattr(demo, f) is None, f
    _write_arrays(path, dict(arrays, peak_force=np.full(13, -1.0)))      # ignored in version 1
    assert load_demonstration(path).peak_force is None
    again = load_demonstration(save_demonstration(old, tmp_path / "demo_001.npz"))
    assert again.peak_force is None and not again.has_segment
    with np.load(tmp_path / "demo_001.npz", allow_pickle=False) as data:
        assert json.loads(data["metadata"].item())["schema_version"] == 2 and "peak_force" not in data


def test_schema_2_fields_round_trip_and_mean_what_they_say(tmp_path):
    demo = make_demo()
    back = load_demonstration(save_demonstration(demo, tmp_path / "demo_000.npz"))
    assert back.has_segment and back.snapshot_index.tolist() == [0, 5, 12] and back.snapshot_rgb.shape == (3, 6, 8, 3)
    assert np.all(back.pixels_kept <= back.pixels_coloured) and np.all(back.pixels_coloured <= back.pixels_hue)
    assert np.all(back.peak_force >= 0)
    assert back.peak_force.dtype == np.float64 and back.pixels_kept.dtype == np.int64
    no_camera = make_demo(perception=False)
    assert no_camera.peak_force.shape == (13,) and not no_camera.has_segment


def test_snapshot_frames_first_contact_else_first_move_else_middle():
    force, still = np.r_[0.0, 0.0, 0.4, 0.7, 2.0, 0.0], np.zeros(6)
    assert [k.tolist() for k in snapshot_frames(force, still)[0:1]] == [[0, 3, 5]]
    assert snapshot_frames(force, still)[1] == ["start", "first contact", "end"]
    moving = np.r_[0.0, 0.0, 0.0, 0.01, 0.5, 1.0]         # 1 % of the travel is not a move, 50 % is
    index, labels = snapshot_frames(np.zeros(6), moving)
    assert index.tolist() == [0, 4, 5] and labels[1] == "object first moves" and first_move(moving) == 4
    index, labels = snapshot_frames(np.zeros(7), np.r_[0.0, 1e-9, 0.0, 2e-4, 0, 0, 0])   # noise: no move
    assert index.tolist() == [0, 3, 6] and labels[1] == "middle" and first_move(np.zeros(7)) is None
    assert first_move(np.r_[1.0, 1.0, 0.5]) == 2         # travel either way


def test_foreign_npz_is_refused(tmp_path):
    path = _write_arrays(tmp_path / "demo_000.npz", {"x": np.arange(3)})
    with pytest.raises(DemonstrationError, match="demo_000.npz: field 'metadata' is missing; not a drake-skill"):
        load_demonstration(path)


def test_truncated_and_garbage_files_are_refused(tmp_path):
    good = save_demonstration(make_demo(), tmp_path / "good.npz").read_bytes()
    truncated = tmp_path / "demo_000.npz"
    truncated.write_bytes(good[: len(good) // 2])
    with pytest.raises(ValueError, match=r"demo_000.npz: not a readable numpy .npz archive"):
        load_demonstration(truncated)
    garbage = tmp_path / "demo_001.npz"
    garbage.write_bytes(np.random.default_rng(0).bytes(5000))
    with pytest.raises(ValueError, match=r"demo_001.npz: not a readable numpy .npz archive"):
        load_demonstration(garbage)
    # A flipped byte inside a member: the zip CRC check catches it.
    flipped = bytearray(good)
    with zipfile.ZipFile(tmp_path / "good.npz") as z:
        info = z.getinfo("X_OE_100hz.npy")
    flipped[info.header_offset + 30 + len(info.filename) + 200] ^= 0xFF
    bad = tmp_path / "demo_002.npz"
    bad.write_bytes(bytes(flipped))
    with pytest.raises(ValueError, match=r"demo_002.npz"):
        load_demonstration(bad)


def test_pickled_object_arrays_are_never_loaded(tmp_path):
    arrays = make_demo().to_arrays()
    arrays["metadata"] = np.array([{"schema": "x"}], dtype=object)
    path = tmp_path / "demo_000.npz"
    np.savez(path, **arrays)
    with pytest.raises(ValueError, match="demo_000.npz: not a readable numpy .npz archive.*allow_pickle"):
        load_demonstration(path)


def test_load_demonstrations_sorted_and_checked(tmp_path):
    for i in (2, 0, 1):
        save_demonstration(make_demo(seed=10 + i), demo_path(tmp_path, i))
    (tmp_path / "notes.txt").write_text("not a demo")
    demos = load_demonstrations(tmp_path, skill="open")
    assert [d.seed for d in demos] == [10, 11, 12]
    with pytest.raises(DemonstrationError, match=r"demo_000.npz: field 'skill' is 'open'; expected 'close'"):
        load_demonstrations(tmp_path, skill="close")
    (tmp_path / "empty").mkdir()
    with pytest.raises(FileNotFoundError, match="empty: no demo_"):
        load_demonstrations(tmp_path / "empty")


def test_object_frame_poses_match_drake():
    X_WO = RigidTransform(RollPitchYaw(0.1, -0.2, 0.7), [0.5, 0.1, 0.02])
    X_WE = [RigidTransform(RollPitchYaw(2.0, 0.3, -1.0 + 0.5 * k), [0.3, -0.2 + 0.1 * k, 0.4]) for k in range(4)]
    ours = object_frame_poses(_vec(X_WO), np.array([_vec(X) for X in X_WE]))
    for k, X in enumerate(X_WE):
        expected = X_WO.inverse() @ X
        np.testing.assert_allclose(ours[k, :3], expected.translation(), atol=1e-12)
        q = expected.rotation().ToQuaternion().wxyz()
        assert abs(abs(ours[k, 3:] @ q) - 1.0) < 1e-12
    assert np.all(np.sum(ours[1:, 3:] * ours[:-1, 3:], axis=1) > 0)   # continuous signs


def test_downsample_action_takes_every_tenth_and_the_last():
    t = np.arange(106) / 100.0
    X = np.tile(np.r_[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0], (106, 1))
    X[:, 0] = t
    idx, t10, X10 = downsample_action(t, X)
    assert idx.tolist() == [0, 10, 20, 30, 40, 50, 60, 70, 80, 90, 100, 105]
    np.testing.assert_array_equal(t10, t[idx])
    np.testing.assert_array_equal(X10[:, 0], t[idx])


def test_degenerate_cloud_is_fine_when_marked_invalid(tmp_path):
    demo = make_demo()
    demo.object_points[4] = 0.0
    demo.perception_valid[4] = False
    save_demonstration(demo, tmp_path / "demo_000.npz")
    assert not load_demonstration(tmp_path / "demo_000.npz").perception_valid[4]


def test_quaternion_sign_of_x_oe_may_differ_from_the_raw_pose():
    demo = make_demo()
    demo.X_OE[3, 3:] *= -1.0  # q and -q are the same orientation
    demo.validate()


def test_demonstrations_too_short_for_the_goal_model_name_the_file(tmp_path):
    from drake_skill.fitted_skill import SkillConfig, fit_skill

    demos = [make_demo(0), make_demo(1)]
    for i, d in enumerate(demos):
        d.path = str(tmp_path / f"demo_{i:03d}.npz")
    config = SkillConfig(skill="open")
    config.pomrp.goal_model.n_states_min = 20
    with pytest.raises(ValueError, match=r"demo_000\.npz: 13 frames at 10 Hz, fewer than the goal model's "
                                         r"smallest state count \(pomrp\.goal_model\.n_states_min = 20\)"):
        fit_skill(demos, config)
    config = SkillConfig(skill="open", dmp_data="10hz")  # 20 DMP bases for 13 samples at 10 Hz
    with pytest.raises(ValueError, match=r"demo_000\.npz: 13 samples, fewer than the 20 DMP bases"):
        fit_skill(demos, config)
    config = SkillConfig(skill="open")   # the 100 Hz data: 121 samples
    config.dmp.n_basis = 200
    with pytest.raises(ValueError, match=r"demo_000\.npz: 121 samples, fewer than the 200 DMP bases"):
        fit_skill(demos, config)


# ------------------------------------------------------------- sets of demonstrations
def test_set_is_written_as_one_unit_with_a_manifest(tmp_path):
    from drake_skill.demos.format import MANIFEST, save_demonstrations

    out = tmp_path / "open"
    out.mkdir()
    (out / "notes.txt").write_text("kept")
    paths = save_demonstrations([make_demo(0), make_demo(1)], out)
    assert [p.name for p in paths] == ["demo_000.npz", "demo_001.npz"]
    assert json.loads((out / MANIFEST).read_text())["files"].keys() == {"demo_000.npz", "demo_001.npz"}
    assert (out / "notes.txt").read_text() == "kept"
    assert [d.seed for d in load_demonstrations(out)] == [0, 1]
    with pytest.raises(FileExistsError, match=r"already holds 2 demonstration file\(s\) .*pass --force"):
        save_demonstrations([make_demo(5)], out)
    save_demonstrations([make_demo(5)], out, force=True)  # fewer than before: no stale demo_001
    assert [d.seed for d in load_demonstrations(out)] == [5] and (out / "notes.txt").exists()
    # A mixed folder is detected: a file of another recording dropped in.
    save_demonstration(make_demo(9), out / "demo_001.npz")
    with pytest.raises(DemonstrationError, match=r"do not match demos\.json .*not listed \['demo_001\.npz'\]"):
        load_demonstrations(out)
    (out / "demo_001.npz").unlink()
    save_demonstration(make_demo(9), out / "demo_000.npz", force=True)
    with pytest.raises(DemonstrationError, match=r"demo_000\.npz: contents differ from the checksum"):
        load_demonstrations(out)
    (out / "f").write_text("x")
    with pytest.raises(NotADirectoryError, match="exists and is not a folder"):
        save_demonstrations([make_demo(0)], out / "f")


def test_interrupted_record_force_leaves_old_or_new(tmp_path, monkeypatch):
    """An interruption at every file-system step of ``demos record --force``'s write
    (save_demonstrations) leaves the old set or the new one."""
    from drake_skill import fileio
    from drake_skill.demos.format import save_demonstrations

    class Interrupted(BaseException):
        pass

    old = [make_demo(0), make_demo(1), make_demo(2)]
    new = [make_demo(10), make_demo(11)]
    reference = tmp_path / "reference"
    save_demonstrations(old, reference)
    steps = ("atomic_write_bytes", "_fsync_tree", "_swap_in", "_remove_tree", "carry_over")
    outcomes = []
    for at in range(1, 30):
        import shutil
        target = tmp_path / f"case{at}"
        shutil.copytree(reference, target)
        state = {"n": 0, "fired": False}
        with monkeypatch.context() as m:
            for name in steps:
                real = getattr(fileio, name)

                def step(*args, _real=real, _state=state, _at=at, **kwargs):
                    if _state["fired"]:
                        return None
                    _state["n"] += 1
                    if _state["n"] == _at:
                        _state["fired"] = True
                        raise Interrupted()
                    return _real(*args, **kwargs)
                m.setattr(fileio, name, step)
            try:
                save_demonstrations(new, target, force=True)
            except Interrupted:
                pass
        seeds = [d.seed for d in load_demonstrations(target)]
        assert seeds in ([0, 1, 2], [10, 11]), f"step {at}: {seeds}"
        outcomes.append(seeds == [10, 11])
        if not state["fired"]:
            break
    assert not state["fired"] and outcomes[-1] and not outcomes[0] and len(outcomes) >= 5


def test_append_adds_the_next_file_and_updates_the_manifest(tmp_path):
    """``hardware record-demo``'s write: the folder still loads as one set afterwards."""
    from drake_skill.demos.format import MANIFEST, append_demonstration, save_demonstrations

    out = tmp_path / "open"
    save_demonstrations([make_demo(0), make_demo(1)], out, extra=lambda tmp: (tmp / "demos.png").write_bytes(b"x"))
    (out / "notes.txt").write_text("kept")
    path = append_demonstration(make_demo(7, perception=False), out)
    assert path == out / "demo_002.npz"
    assert sorted(json.loads((out / MANIFEST).read_text())["files"]) == ["demo_000.npz", "demo_001.npz",
                                                                         "demo_002.npz"]
    assert [d.seed for d in load_demonstrations(out, skill="open")] == [0, 1, 7]
    assert (out / "notes.txt").read_text() == "kept" and not (out / "demos.png").exists()   # stale plot dropped
    # Into a new folder, and into one assembled by hand (no manifest): both load afterwards.
    assert append_demonstration(make_demo(3), tmp_path / "new") == tmp_path / "new" / "demo_000.npz"
    assert [d.seed for d in load_demonstrations(tmp_path / "new")] == [3]
    by_hand = tmp_path / "by_hand"
    save_demonstration(make_demo(4), by_hand / "demo_000.npz")
    save_demonstration(make_demo(5), by_hand / "demo_003.npz")
    assert append_demonstration(make_demo(6), by_hand).name == "demo_004.npz"   # after the highest index
    assert [d.seed for d in load_demonstrations(by_hand)] == [4, 5, 6]
    # A folder that does not load as a set, or holds another skill, is refused untouched.
    with pytest.raises(DemonstrationError, match=r"demo_000\.npz: field 'skill' is 'open', but the demonstration "
                                                 r"to add is 'close'; record it into a folder of its own skill"):
        append_demonstration(make_demo(8, skill="close"), out)
    save_demonstration(make_demo(9), out / "demo_005.npz")
    with pytest.raises(DemonstrationError, match=r"do not match demos\.json .*not listed \['demo_005\.npz'\]"):
        append_demonstration(make_demo(10), out)
    assert not (out / "demo_006.npz").exists()


def test_interrupted_append_leaves_old_or_new(tmp_path, monkeypatch):
    """An interruption at every file-system step of append_demonstration leaves a loadable
    folder with the old set or the new one."""
    import shutil

    from drake_skill import fileio
    from drake_skill.demos.format import append_demonstration, save_demonstrations

    class Interrupted(BaseException):
        pass

    reference = tmp_path / "reference"
    save_demonstrations([make_demo(0, perception=False), make_demo(1, perception=False)], reference)
    steps = ("atomic_write_bytes", "_fsync_tree", "_swap_in", "_remove_tree", "carry_over")
    outcomes = []
    for at in range(1, 30):
        target = tmp_path / f"case{at}"
        shutil.copytree(reference, target)
        state = {"n": 0, "fired": False}
        with monkeypatch.context() as m:
            for name in steps:
                real = getattr(fileio, name)

                def step(*args, _real=real, _state=state, _at=at, **kwargs):
                    if not _state["fired"]:
                        _state["n"] += 1
                        if _state["n"] == _at:
                            _state["fired"] = True
                            raise Interrupted()
                    return _real(*args, **kwargs)
                m.setattr(fileio, name, step)
            try:
                append_demonstration(make_demo(2, perception=False), target)
            except Interrupted:
                pass
        seeds = [d.seed for d in load_demonstrations(target)]
        assert seeds in ([0, 1], [0, 1, 2]), f"step {at}: {seeds}"
        outcomes.append(seeds == [0, 1, 2])
        if not state["fired"]:
            break
    assert not state["fired"] and outcomes[-1] and not outcomes[0] and len(outcomes) >= 4


# ------------------------------------------------------------- mutation testing (docs/mutation.md)
def test_fields_of_other_dtypes_are_named():
    demo = make_demo(perception=False)
    demo.q_100hz = np.zeros((121, 7), dtype=np.int64)
    with pytest.raises(DemonstrationError, match=r"^demonstration: field 'q_100hz' has dtype int64; "
                                                 r"expected a floating-point array$"):
        demo.validate()
    demo = make_demo(perception=False)
    demo.gripper_100hz = [0.0] * 121
    with pytest.raises(DemonstrationError, match=r"^here: field 'gripper_100hz' has dtype list; expected a floating"):
        demo.validate("here")
    demo = make_demo(perception=False)
    demo.times = np.arange(13)
    with pytest.raises(DemonstrationError, match=r"^demonstration: field 'times' has dtype int64; expected a floating"):
        demo.validate()


def test_10hz_times_match_raw_instants_up_to_rounding():
    """times need not be bit-identical to times_100hz (another computation of the same instants)."""
    demo = make_demo(perception=False)
    for k, eps in [(0, 1e-12), (5, 1e-12), (6, -1e-12), (12, 1e-12), (12, -1e-12)]:
        d = make_demo(perception=False)
        d.times[k] += eps
        d.validate()
    demo.times[4] += 0.005  # half-way between two raw instants
    with pytest.raises(DemonstrationError, match=r"^demonstration: field 'times' sample 4 \(0\.405000 s\) is not one "
                                                 r"of the times_100hz instants; expected the 10 Hz times to be a "
                                                 r"subset of the raw ones \(downsample_action\)$"):
        demo.validate()


@pytest.mark.parametrize("field, value, message", [
    ("seed", np.array([1, 2]), r"has shape \(2,\) dtype int64; expected a scalar of kind 'iu'"),
    ("seed", np.array(1.5), r"has shape \(\) dtype float64; expected a scalar of kind 'iu'"),
    ("success", np.array(1), r"has shape \(\) dtype int64; expected a scalar of kind 'b'"),
])
def test_scalar_fields_are_checked_on_load(tmp_path, field, value, message):
    arrays = make_demo(perception=False).to_arrays()
    arrays[field] = value
    path = _write_arrays(tmp_path / "demo_000.npz", arrays)
    with pytest.raises(DemonstrationError, match=rf"^{re.escape(str(path))}: field '{field}' {message}$"):
        load_demonstration(path)


def test_file_and_folder_errors_say_what_to_do(tmp_path):
    path = save_demonstration(make_demo(perception=False), tmp_path / "demo_000.npz")
    with pytest.raises(FileExistsError, match=r"demo_000.npz exists; refusing to overwrite a recorded demonstration "
                                              r"\(pass force=True / --force to replace it\)$"):
        save_demonstration(make_demo(perception=False), path)
    with pytest.raises(FileNotFoundError, match=r"^.*missing: no such directory$"):
        load_demonstrations(tmp_path / "missing")
    from drake_skill.demos.format import append_demonstration

    with pytest.raises(NotADirectoryError, match=r"demo_000.npz: exists and is not a folder; choose a folder"):
        append_demonstration(make_demo(perception=False), path)


def test_manifest_contents_and_mismatch_messages(tmp_path):
    from drake_skill.demos.format import MANIFEST, append_demonstration, save_demonstrations
    from drake_skill.fileio import file_sha256

    out = tmp_path / "open"
    save_demonstrations([make_demo(0, perception=False), make_demo(1, perception=False)], out)
    manifest = json.loads((out / MANIFEST).read_text())
    assert manifest == {"schema": "drake-skill-demonstration-set",
                        "files": {p.name: file_sha256(p) for p in sorted(out.glob("demo_*.npz"))}}
    seen = []
    append_demonstration(make_demo(2, perception=False), out,
                         extra=lambda tmp: seen.extend(sorted(p.name for p in tmp.iterdir())))
    assert seen == ["demo_000.npz", "demo_001.npz", "demo_002.npz"]  # extra sees the whole new set
    manifest = json.loads((out / MANIFEST).read_text())
    assert manifest["schema"] == "drake-skill-demonstration-set" and len(manifest["files"]) == 3
    save_demonstration(make_demo(7, perception=False), out / "demo_001.npz", force=True)
    with pytest.raises(DemonstrationError, match=r"demo_001\.npz: contents differ from the checksum in .*demos\.json; "
                                                 r"the folder mixes recordings\. Record the set again "
                                                 r"\(demos record --force\)$"):
        load_demonstrations(out)
    (out / "demo_001.npz").unlink()
    with pytest.raises(DemonstrationError, match=r"do not match demos\.json \(missing \['demo_001\.npz'\], not listed "
                                                 r"\[\]\); the folder mixes recordings\. Record the set again "
                                                 r"\(demos record --force\)$"):
        load_demonstrations(out)
    (out / MANIFEST).write_text("not json")
    with pytest.raises(DemonstrationError, match=r"demos\.json: not a drake-skill demonstration list \(.*\); delete it "
                                                 r"if the folder was assembled by hand$"):
        load_demonstrations(out)


def test_set_errors_name_the_files(tmp_path):
    from drake_skill.demos.format import append_demonstration, save_demonstrations

    out = tmp_path / "open"
    for i in range(4):
        save_demonstration(make_demo(i, perception=False), demo_path(out, i))
    with pytest.raises(FileExistsError, match=r"holds 4 demonstration file\(s\) \(demo_000\.npz, demo_001\.npz, "
                                              r"demo_002\.npz, \.\.\.\); pass --force to replace them or choose "
                                              r"another --out$"):
        save_demonstrations([make_demo(9, perception=False)], out)
    demo_path(out, 3).unlink()
    with pytest.raises(FileExistsError, match=r"\(demo_000\.npz, demo_001\.npz, demo_002\.npz\); pass --force"):
        save_demonstrations([make_demo(9, perception=False)], out)
    bad = make_demo(9, perception=False)
    bad.X_OE[2, 0] = np.nan
    with pytest.raises(DemonstrationError, match=r"open/demo_001\.npz: field 'X_OE' contains NaN"):
        save_demonstrations([make_demo(8, perception=False), bad], out, force=True)
    with pytest.raises(DemonstrationError, match=r"open/demo_003\.npz: field 'X_OE' contains NaN"):
        append_demonstration(bad, out)


def test_a_stale_plot_is_not_carried_into_a_new_set(tmp_path):
    from drake_skill.demos.format import save_demonstrations

    out = tmp_path / "open"
    save_demonstrations([make_demo(0, perception=False)], out, extra=lambda tmp: (tmp / "demos.png").write_bytes(b"x"))
    assert (out / "demos.png").read_bytes() == b"x"
    save_demonstrations([make_demo(1, perception=False)], out, force=True)
    assert sorted(p.name for p in out.iterdir()) == ["demo_000.npz", "demos.json"]


def _set(**fields):
    return lambda d: [setattr(d, k, v) for k, v in fields.items()]


def _set_item(field, index, value):
    return lambda d: getattr(d, field).__setitem__(index, value)


@pytest.mark.parametrize("change, message", [
    (_set(skill=""), r"field 'skill' is ''; expected a skill's name \(letters, digits, '_', '-'\)"),
    (_set(skill=3), r"field 'skill' is 3; expected a skill's name"),
    (_set(seed=True), r"field 'seed' is True; expected an integer"),
    (_set(seed=1.0), r"field 'seed' is 1\.0; expected an integer"),
    (_set(success=1), r"field 'success' is 1; expected a bool"),
    (_set(final_object_state=float("nan")), r"field 'final_object_state' is nan; expected a finite number"),
    (lambda d: setattr(d, "times_100hz", d.times_100hz[:, None]),
     r"field 'times_100hz' has shape \(121, 1\); expected \(T,\)"),
    (_set_item("times", 4, 0.3), r"field 'times' is not strictly increasing \(t\[3\] = 0\.3 s, t\[4\] = 0\.3 s\)"),
    (lambda d: setattr(d, "q_100hz", d.q_100hz[:, :6]), r"field 'q_100hz' has shape \(121, 6\); expected \(121, 7\)"),
    (_set(gripper_100hz=np.zeros(120)), r"field 'gripper_100hz' has shape \(120,\); expected \(121,\)"),
    (_set(gripper_100hz=np.zeros(121, dtype=int)), r"field 'gripper_100hz' has dtype int64; expected a floating"),
    (_set(object_state_100hz=np.zeros(120)), r"field 'object_state_100hz' has shape \(120,\); expected \(121,\)"),
    (_set(object_state_100hz=np.zeros(121, dtype=int)), r"field 'object_state_100hz' has dtype int64; expected a"),
    (_set_item("times", 0, -0.01), r"field 'times' spans -0\.010\.\.1\.200 s, outside times_100hz 0\.000\.\.1\.200 s"),
    (_set_item("times", 12, 1.21), r"field 'times' spans 0\.000\.\.1\.210 s, outside times_100hz 0\.000\.\.1\.200 s"),
    (_set_item("X_WO_true", 3, 2.0), r"field 'X_WO_true' has a quaternion of norm 2\.\d+ at sample 0; "
                                     r"expected unit norm within 0\.001"),
    (_set(perception_valid=None), r"field 'perception_valid' is missing while X_WO_start, object_points is present; "
                                  r"perception fields come together"),
    (_set(perception_valid=None, object_points=None), r"field 'object_points' is missing while X_WO_start is present"),
    (_set_item("X_WO_start", 3, 2.0), r"field 'X_WO_start' has a quaternion of norm"),
    (lambda d: setattr(d, "object_points", d.object_points[:, :, :2].copy()),
     r"field 'object_points' has shape \(13, 2048, 2\) dtype float32; expected \(13, 2048, 3\) float32 \(2048 "
     r"points per frame, docs/method\.md section 3\)"),
    (lambda d: setattr(d, "object_points", d.object_points[:12]), r"field 'object_points' has shape \(12, 2048, 3\)"),
    (_set(object_points=[[0.0]]), r"field 'object_points' has shape None dtype None; expected \(13, 2048, 3\)"),
    (_set_item("object_points", (2, 5, 1), np.inf), r"field 'object_points' contains NaN or inf$"),
    (_set(perception_valid=np.ones(13)), r"field 'perception_valid' has shape \(13,\) dtype float64; "
                                         r"expected \(13,\) bool"),
    (_set(perception_valid=np.ones(12, dtype=bool)), r"field 'perception_valid' has shape \(12,\) dtype bool"),
    (_set(perception_valid=[True] * 13), r"field 'perception_valid' has shape None dtype None; expected \(13,\) bool"),
    # schema 2
    (_set_item("peak_force", 3, -0.5), r"field 'peak_force' has a negative force at sample 3$"),
    (_set(peak_force=np.zeros(12)), r"field 'peak_force' has shape \(12,\); expected \(13,\)"),
    (_set(snapshot_rgb=None), r"field 'snapshot_rgb' is missing while pixels_hue, pixels_coloured, pixels_kept, "
                              r"snapshot_index, snapshot_segment is present; the segment's counts and pictures come "
                              r"together$"),
    (_set(object_points=None, perception_valid=None, X_WO_start=None),
     r"field 'pixels_hue' is present without the perception fields"),
    (_set(pixels_coloured=np.ones(13)), r"field 'pixels_coloured' has shape \(13,\) dtype float64; expected \(13,\) "
                                        r"integers$"),
    (_set_item("pixels_kept", 4, -1), r"field 'pixels_kept' has a negative count at sample 4$"),
    (_set_item("pixels_kept", 7, 10**6),
     r"field 'pixels_kept' is 1000000 at sample 7, more than pixels_coloured \(\d+\); kept pixels are "
     r"object-coloured, and those are of the object's hue$"),
    (_set_item("pixels_hue", 2, 10), r"field 'pixels_coloured' is \d+ at sample 2, more than pixels_hue \(10\)"),
    (_set(snapshot_index=np.array([0, 5, 11])),
     r"field 'snapshot_index' is \[0, 5, 11\]; expected 3 integers \[0, first contact, 12\] \(10 Hz samples: "
     r"start, first contact, end\)$"),
    (_set(snapshot_index=np.array([0, 13, 12])), r"field 'snapshot_index' is \[0, 13, 12\]"),
    (_set(snapshot_index=np.zeros((3, 2), dtype=int)), r"field 'snapshot_index' is \(3, 2\); expected"),
    (_set(snapshot_rgb=np.zeros((3, 6, 8), dtype=np.uint8)), r"field 'snapshot_rgb' has shape \(3, 6, 8\) dtype "
                                                             r"uint8; expected \(3, h, w, 3\) uint8$"),
    (_set(snapshot_segment=np.zeros((3, 6, 8), dtype=bool)), r"field 'snapshot_segment' has shape \(3, 6, 8\) "
                                                             r"dtype bool; expected \(3, 6, 8\) uint8 like"),
    (_set_item("snapshot_segment", (1, 2, 3), 4), r"field 'snapshot_segment' holds the value 4; expected 0 \(not of "
                                                  r"the object's hue\), 1 \(of its hue, not object-coloured\), 2 "
                                                  r"\(object-coloured, dropped\) or 3 \(kept\)$"),
])
def test_each_invalid_field_is_named(change, message):
    demo = make_demo()
    change(demo)
    with pytest.raises(DemonstrationError, match=rf"^somewhere: {message}"):
        demo.validate("somewhere")


def test_the_fewest_samples_are_valid():
    demo = make_demo(perception=False, n=91)  # 91 raw samples, 10 at 10 Hz
    assert demo.validate().n_samples == 10


def test_clouds_flat_along_one_axis_are_valid_and_the_degenerate_frame_is_named():
    demo = make_demo()
    demo.object_points[3, :, 2] = 0.0  # a flat cloud (a lid seen from above): two wide axes are enough
    demo.perception_valid[3] = True
    demo.validate()
    demo.object_points[6, :, :2] = 0.3
    demo.object_points[6, :, 2] = np.linspace(0.0, 0.123456, 2048)
    demo.perception_valid[6] = True
    with pytest.raises(DemonstrationError, match=r"^demonstration: field 'object_points' frame 6 is marked valid "
                                                 r"but its cloud is degenerate \(bounding box \[0\.0, 0\.0, "
                                                 r"0\.123499\d*\] m; expected at least 0\.005 m along two axes\)"):
        demo.validate()


def test_metadata_must_be_json():
    demo = make_demo(perception=False)
    demo.metadata = {"when": object()}
    with pytest.raises(DemonstrationError, match=r"^demonstration: field 'metadata' is not JSON-serialisable \("):
        demo.validate()


def test_downsample_action_rates():
    t = np.arange(30) / 10.0
    X = np.tile([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0], (30, 1))
    idx, t10, _ = downsample_action(t, X)  # already at 10 Hz: every sample
    assert idx.tolist() == list(range(30)) and np.array_equal(t10, t)
    for rate in (25.0, 5.0):
        with pytest.raises(ValueError, match=rf"^times_100hz: rate {rate:.3f} Hz is not an integer multiple of "
                                             r"10\.0 Hz$"):
            downsample_action(np.arange(30) / rate, X)
    # Integer input (whole seconds, 1 Hz -> 0.5 Hz) comes back as floats.
    idx, t_half, X_half = downsample_action(list(range(5)), [[0, 0, 0, 1, 0, 0, 0]] * 5, rate_hz=0.5)
    assert idx.tolist() == [0, 2, 4] and t_half.dtype == np.float64 and X_half.dtype == np.float64


def test_object_frame_poses_normalise_and_start_with_positive_w():
    X_WO = np.r_[0.5, 0.1, 0.0, 1.0, 0.0, 0.0, 0.0]
    c, s = np.cos(0.3), np.sin(0.3)
    q = np.array([c, -s, 0.0, 0.0])  # about -x; its first sample is given as -q (the same rotation)
    X_WE = np.array([np.r_[0.6, 0.1, 0.2, -q], np.r_[0.7, 0.1, 0.2, 3.0 * q]])  # second not unit
    ours = object_frame_poses(np.r_[X_WO[:3], 2.0 * X_WO[3:]], X_WE)  # a non-unit object quaternion too
    np.testing.assert_allclose(ours[:, :3], [[0.1, 0.0, 0.2], [0.2, 0.0, 0.2]], atol=1e-12)
    np.testing.assert_allclose(ours[:, 3:], [q, q], atol=1e-12)
    np.testing.assert_allclose(object_frame_poses(X_WO, X_WE[1:])[:, 3:], [q], atol=1e-12)  # w > 0 is kept


def test_load_errors_of_the_metadata_and_scalars(tmp_path):
    def write(name, **changes):
        arrays = make_demo(perception=False).to_arrays()
        for k, v in changes.items():
            if v is None:
                arrays.pop(k)
            else:
                arrays[k] = v
        return _write_arrays(tmp_path / name, arrays)

    cases = [
        (write("a.npz", metadata=np.array(["{}", "{}"])),
         r"field 'metadata' has shape \(2,\) dtype <U2; expected a JSON string$"),
        (write("b.npz", metadata=np.array(5)), r"field 'metadata' has shape \(\) dtype int64; expected a JSON string$"),
        (write("c.npz", metadata=np.array("{not json")), r"field 'metadata' is not valid JSON \("),
        (write("d.npz", metadata=np.array("[1]")),
         r"field 'metadata' names schema None; expected 'drake-skill-demonstration'$"),
        (write("e.npz", metadata=np.array('{"schema": "other"}')),
         r"field 'metadata' names schema 'other'; expected 'drake-skill-demonstration'$"),
        (write("f.npz", skill=np.array(3)),
         r"field 'skill' has shape \(\) dtype int64; expected a scalar of kind 'U'$"),
        (write("g.npz", final_object_state=np.array(1)),
         r"field 'final_object_state' has shape \(\) dtype int64; expected a scalar of kind 'f'$"),
        (write("h.npz", seed=np.array(1.0)), r"field 'seed' has shape \(\) dtype float64; expected a scalar of kind"),
        (write("i.npz", success=np.array(1.0)), r"field 'success' has shape \(\) dtype float64; expected a scalar"),
        (write("j.npz", X_OE=None), r"field 'X_OE' is missing$"),
    ]
    for path, message in cases:
        with pytest.raises(DemonstrationError, match=rf"^{re.escape(str(path))}: {message}"):
            load_demonstration(path)
    np.savez(tmp_path / "empty.npz")
    with pytest.raises(DemonstrationError, match=r"field 'metadata' is missing; not a drake-skill demonstration file "
                                                 r"\(fields: none\)$"):
        load_demonstration(tmp_path / "empty.npz")
    _write_arrays(tmp_path / "foreign.npz", {"y": np.zeros(1), "x": np.zeros(1)})
    with pytest.raises(DemonstrationError, match=r"\(fields: x, y\)$"):
        load_demonstration(tmp_path / "foreign.npz")


def test_metadata_without_has_perception_means_no_camera(tmp_path):
    arrays = make_demo(perception=False).to_arrays()
    meta = json.loads(arrays["metadata"].item())
    del meta["has_perception"]
    arrays["metadata"] = np.array(json.dumps(meta))
    path = _write_arrays(tmp_path / "demo_000.npz", arrays)
    assert not load_demonstration(path).has_perception
