"""Demonstrations as a robomimic dataset: one HDF5 file, written and read with h5py.

robomimic's layout (robomimic.github.io, "Datasets > Overview > Dataset
Structure"): a group ``data`` with the attributes ``total`` (samples in all
demonstrations) and ``env_args`` (a JSON object: ``env_name``, ``type``,
``env_kwargs``), and per demonstration a group ``data/demo_N`` with the
attribute ``num_samples``, the datasets ``actions``, ``rewards``, ``dones``
and a group ``obs`` of per-sample observations. drake-skill writes one
robomimic sample per 10 Hz sample of a demonstration (the rate of its action
data and of its camera frames; docs/method.md section 1), T10 of them:

===============================  ==============  ==================================
``obs/joint_positions``          (T10, 7) f64    measured Panda joints [rad]
``obs/gripper_opening``          (T10, 1) f64    commanded finger opening [m]
``obs/hand_pose``                (T10, 7) f64    X_OE: measured hand pose in the
                                                 object frame [m, quaternion wxyz]
``obs/object_state``             (T10, 1) f64    lid angle [rad] / drawer travel [m]
                                                 (simulator or sensor ground truth)
``obs/object_points``            (T10, N, 3) f32 segmented object cloud in W [m]
``obs/object_points_valid``      (T10,) bool     the segmentation found the object
``obs/peak_force``               (T10, 1) f64    peak contact force since the
                                                 previous sample [N] (schema 2)
``obs/pixels_hue``               (T10, 1) i64    pixels of the object's hue in the
                                                 camera image (schema 2)
``obs/pixels_coloured``          (T10, 1) i64    of those, object-coloured
``obs/pixels_kept``              (T10, 1) i64    of those, kept by the segment
``actions``                      (T10, 8) f64    [X_OE of the next sample (7),
                                                 gripper opening (1)]
``rewards``, ``dones``           (T10,) f64/i64  1 at the last sample (reward only
                                                 when the demonstration succeeded)
===============================  ==============  ==================================

The demonstration format records the *measured* hand pose, not a commanded
one, so the action at sample t is the hand pose reached at sample t + 1 (an
absolute pose target, as the DMP's output X_OE is), the last sample's
repeating its own pose; the gripper's is its command. The object-cloud keys
are absent for demonstrations recorded without a camera, the schema-2 keys for
demonstrations that lack those fields (``drake_skill.demos.format``).

So that ``demos import`` gives back the very arrays of the ``.npz`` files,
bit for bit, each ``demo_N`` also holds a group ``drake_skill`` with the
fields robomimic's samples leave out (the 100 Hz raw streams, the sample
times, the object poses, schema 2's three pictures ``snapshot_index``,
``snapshot_rgb`` and ``snapshot_segment``) and attributes ``skill``, ``seed``, ``success``,
``final_object_state``, ``metadata`` (JSON) and ``source_file``. robomimic
reads only the keys it is configured with and ignores the group.

``env_args`` names the skill and (for a shipped skill) its scenario; robomimic has no environment
wrapper for the Drake station, so train with rollouts off (``experiment.rollout.enabled
= false``) or evaluate with ``drake-skill evaluate``.
"""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np

from drake_skill.demos.format import Demonstration, DemonstrationError, load_demonstrations, save_demonstrations
from drake_skill.fileio import atomic_write_bytes

__all__ = ["FORMATS", "export_robomimic", "import_robomimic", "read_robomimic"]

FORMATS = ("robomimic",)
#: The Demonstration arrays kept in data/demo_N/drake_skill (the rest are read from obs).
_RAW = ("times_100hz", "X_OE_100hz", "q_100hz", "gripper_100hz", "object_state_100hz", "times", "X_WO_true")
#: Schema 2's per-sample fields, kept in obs as (T10, 1) columns.
_COLUMNS = ("peak_force", "pixels_hue", "pixels_coloured", "pixels_kept")
#: Schema 2's pictures, kept in data/demo_N/drake_skill.
_SNAPSHOTS = ("snapshot_index", "snapshot_rgb", "snapshot_segment")


def _h5py():
    try:
        import h5py
    except ImportError as e:  # pragma: no cover - h5py is a dependency
        raise ImportError("the robomimic format needs h5py: pip install 'h5py>=3.10'") from e
    return h5py


def _sample_indices(demo: Demonstration) -> np.ndarray:
    """The raw (100 Hz) index of each 10 Hz sample (``times`` is a subset of ``times_100hz``)."""
    idx = np.clip(np.searchsorted(demo.times_100hz, demo.times - 1e-9), 0, demo.times_100hz.size - 1)
    if np.any(np.abs(demo.times_100hz[idx] - demo.times) > 1e-9):
        raise DemonstrationError(f"{demo.path}: field 'times' is not a subset of times_100hz")
    return idx


def actions(demo: Demonstration) -> np.ndarray:
    """``(T10, 8)``: the next sample's hand pose X_OE (the last repeats its own) and the gripper command."""
    idx = _sample_indices(demo)
    nxt = np.append(np.arange(1, demo.n_samples), demo.n_samples - 1)
    return np.concatenate([demo.X_OE[nxt], demo.gripper_100hz[idx, None]], axis=1)


def export_robomimic(directory, out_path) -> tuple[Path, list[Demonstration]]:
    """Writes the demonstrations of ``directory`` to the HDF5 file ``out_path`` (atomically).

    Returns the path written and the demonstrations (in file order: ``demo_000.npz``
    becomes ``data/demo_0``).
    """
    h5py = _h5py()
    demos = load_demonstrations(directory)
    skills = sorted({d.skill for d in demos})
    if len(skills) != 1:
        raise DemonstrationError(f"{directory}: holds demonstrations of {', '.join(skills)}; a robomimic "
                                 "dataset is one task: export one skill's folder")
    skill = skills[0]
    env_kwargs = {"skill": skill, "rate_hz": 10.0,
                  "action": "X_OE of the next sample (m, quaternion wxyz) and the gripper opening (m)"}
    try:        # a shipped skill names its scenario (drake_skill/skills/<name>.yaml)
        from drake_skill.skills import load_skill
        env_kwargs["scenario"] = load_skill(skill).scenario
    except (ValueError, OSError):
        pass    # a skill from a file of the user's: the name is all the demonstrations record
    buf = io.BytesIO()          # built in memory, then written in one atomic replace
    with h5py.File(buf, "w") as f:
        data = f.create_group("data")
        data.attrs["total"] = int(sum(d.n_samples for d in demos))
        data.attrs["env_args"] = json.dumps({"env_name": f"drake-skill-{skill}", "type": "drake-skill",
                                             "env_kwargs": env_kwargs}, sort_keys=True)
        for i, d in enumerate(demos):
            g = data.create_group(f"demo_{i}")
            g.attrs["num_samples"] = d.n_samples
            idx = _sample_indices(d)
            obs = g.create_group("obs")
            obs["joint_positions"] = d.q_100hz[idx]
            obs["gripper_opening"] = d.gripper_100hz[idx, None]
            obs["hand_pose"] = d.X_OE
            obs["object_state"] = d.object_state_100hz[idx, None]
            if d.has_perception:
                obs.create_dataset("object_points", data=d.object_points, compression="gzip", compression_opts=4)
                obs["object_points_valid"] = d.perception_valid
            for name in _COLUMNS:
                if getattr(d, name) is not None:
                    obs[name] = getattr(d, name)[:, None]
            g["actions"] = actions(d)
            done = np.zeros(d.n_samples, dtype=np.int64)
            done[-1] = 1
            g["dones"] = done
            g["rewards"] = done.astype(np.float64) * float(d.success)
            raw = g.create_group("drake_skill")
            for name in _RAW:
                raw[name] = getattr(d, name)
            if d.has_perception:
                raw["X_WO_start"] = d.X_WO_start
            if d.has_segment:
                for name in _SNAPSHOTS:
                    raw[name] = getattr(d, name)
            raw.attrs["skill"] = d.skill
            raw.attrs["seed"] = np.int64(d.seed)
            raw.attrs["success"] = bool(d.success)
            raw.attrs["final_object_state"] = float(d.final_object_state)
            raw.attrs["metadata"] = json.dumps(d.metadata, sort_keys=True)
            raw.attrs["source_file"] = Path(d.path).name if d.path else ""
    return atomic_write_bytes(out_path, buf.getvalue()), demos


def _get(where: str, group, name: str):
    if name not in group:
        raise DemonstrationError(f"{where}: '{group.name}/{name}' is missing; not a dataset written by "
                                 "'drake-skill demos export --format robomimic'")
    return group[name][()]


def read_robomimic(path) -> list[Demonstration]:
    """The demonstrations of a robomimic HDF5 file written by :func:`export_robomimic`, validated."""
    h5py = _h5py()
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    try:
        f = h5py.File(path, "r")
    except OSError as e:
        raise ValueError(f"{path}: not a readable HDF5 file ({' '.join(str(e).split())}): a file cut short or "
                         "of another format; export it again with 'drake-skill demos export DIR OUT.hdf5'") from None
    try:
        with f:
            return _read_demos(f, path)
    except DemonstrationError:
        raise
    except (OSError, RuntimeError, KeyError, TypeError, ValueError, IndexError) as e:   # h5py on damaged bytes
        raise ValueError(f"{path}: damaged HDF5 ({type(e).__name__}: {' '.join(str(e).split())[:200]}); export "
                         "it again with 'drake-skill demos export DIR OUT.hdf5'") from None


def _read_demos(f, path: Path) -> list[Demonstration]:
    """The demonstrations of the open robomimic file ``f`` (``path`` names it in errors)."""
    demos = []
    if "data" not in f:
        raise DemonstrationError(f"{path}: group 'data' is missing; not a robomimic dataset: import a file "
                                 "written by 'drake-skill demos export DIR OUT.hdf5'")
    names = [n for n in f["data"] if n.startswith("demo_") and n[5:].isdigit()]
    if not names:
        raise DemonstrationError(f"{path}: 'data' has no demo_N groups; nothing to import: export a folder "
                                 "that holds demonstrations ('drake-skill demos list DIR' shows them)")
    for name in sorted(names, key=lambda n: int(n[5:])):
        g = f["data"][name]
        where = f"{path}:/data/{name}"
        if "drake_skill" not in g:
            raise DemonstrationError(f"{where}: group 'drake_skill' is missing; only datasets written by "
                                     "'drake-skill demos export' can be imported (they carry the 100 Hz data)")
        raw = g["drake_skill"]
        obs = g["obs"] if "obs" in g else {}
        names = ("skill", "seed", "success", "final_object_state", "metadata")
        missing = [k for k in names if k not in raw.attrs]
        if missing:     # (h5py's KeyError names no attribute: "Unable to ... open attribute (...)")
            raise DemonstrationError(f"{where}/drake_skill: attribute {missing[0]!r} is missing")
        attrs = {k: raw.attrs[k] for k in names}
        try:
            metadata = json.loads(attrs["metadata"])
        except (TypeError, json.JSONDecodeError) as e:
            raise DemonstrationError(f"{where}/drake_skill: attribute 'metadata' is not JSON ({e})") from e
        perception = {}
        if "object_points" in obs:
            perception = dict(object_points=_get(where, g["obs"], "object_points"),
                              perception_valid=_get(where, g["obs"], "object_points_valid"),
                              X_WO_start=_get(where, raw, "X_WO_start"))
        schema2 = {name: np.reshape(_get(where, g["obs"], name), -1) for name in _COLUMNS if name in obs}
        if "pixels_hue" in obs:
            schema2.update({name: _get(where, raw, name) for name in _SNAPSHOTS})
        demo = Demonstration(
            skill=str(attrs["skill"]), seed=int(attrs["seed"]), success=bool(attrs["success"]),
            final_object_state=float(attrs["final_object_state"]),
            X_OE=_get(where, g["obs"] if "obs" in g else g, "hand_pose"),
            **{n: _get(where, raw, n) for n in _RAW}, **perception, **schema2, metadata=metadata, path=where)
        demos.append(demo.validate(where))
    return demos


def import_robomimic(path, directory, force: bool = False) -> tuple[list[Path], list[Demonstration]]:
    """Reads ``path`` and writes its demonstrations to ``directory`` as a set (``demos.json``)."""
    demos = read_robomimic(path)
    return save_demonstrations(demos, directory, force=force), demos
