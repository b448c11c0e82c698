"""Demonstration files: one ``.npz`` per demonstration, validated on save and load.

Plain numpy, no Drake import. docs/method.md section 1 / thesis section 6.3: a
demonstration gives *action data* (the hand pose in the object frame, recorded
at 100 Hz and sampled uniformly down to 10 Hz) and *perceptual data* (the
camera at 10 Hz; here the segmented object's points, see below).

Frames and units (SI: m, rad, s):

* W: world frame of the station (robot base at the origin, z up).
* O: object frame (see ``drake_skill.demos.scripted``): origin at the centre of the
  object's bottom face, x away from the robot, z up.
* E: the hand's tool centre point (the station's ``ee_pose`` port).
* Poses are 7-vectors ``[x, y, z, qw, qx, qy, qz]``: translation [m] and unit
  quaternion (scalar first, Hamilton), e.g. ``X_OE`` is the pose of E in O.

Fields of :class:`Demonstration` (T raw samples at 100 Hz, T10 at 10 Hz):

=====================  ==============  =========================================
``times_100hz``        (T,) float64    s from the start of the demonstration
``X_OE_100hz``         (T, 7) float64  *measured* hand pose in O
``q_100hz``            (T, 7) float64  measured Panda joint positions [rad]
``gripper_100hz``      (T,) float64    commanded finger opening [m]
``object_state_100hz`` (T,) float64    lid angle [rad] / drawer travel [m]
                                       (simulator ground truth; never a reward)
``times``              (T10,) float64  the 10 Hz sample times (a subset of
                                       ``times_100hz``, last sample kept)
``X_OE``               (T10, 7)        action data at 10 Hz (what a DMP fits)
``X_WO_true``          (7,) float64    ground-truth object pose at the start;
                                       X_OE = X_WO_true^-1 X_WE (simulation)
``X_WO_start``         (7,) float64    *perceived* object pose at the start
                                       (segmented cloud's box centre), or None
``object_points``      (T10, N, 3)     segmented object points in W [m],
                       float32         N = 2048 (docs/method.md section 3), or None
``perception_valid``   (T10,) bool     segmentation found the object, or None
``peak_force``         (T10,) float64  peak filtered robot-scene contact force [N]
                                       over the raw samples since the previous
                                       10 Hz sample (the first: its own), or
                                       None (schema 1); 0 on the robot, which
                                       measures joint torques, not contact force
``pixels_hue``         (T10,) int64    pixels of the object's hue (the colour
                                       test widened: perception.segmentation.
                                       hue_config) in the camera image the
                                       segmenter read, or None
``pixels_coloured``    (T10,) int64    of those, the object-coloured pixels
                                       (the segmenter's colour test), or None
``pixels_kept``        (T10,) int64    of those, the pixels the segment kept,
                                       or None
``snapshot_index``     (3,) int64      the 10 Hz samples shown as pictures: 0
                                       (start), first contact, T10 - 1 (end)
``snapshot_rgb``       (3, h, w, 3)    their camera images, downscaled (every
                       uint8           k-th pixel, w <= 80), or None
``snapshot_segment``   (3, h, w) uint8 per pixel 0: not of the object's hue,
                                       1: of its hue but not object-coloured,
                                       2: object-coloured but dropped by the
                                       segment, 3: kept; or None
``skill``, ``seed``, ``success``, ``final_object_state``
                                       what was demonstrated, the seed that
                                       produced it, the ground-truth verdict
``metadata``           dict            JSON-serialisable extras (source,
                                       demonstrator settings, attempts, ...)
=====================  ==============  =========================================

The camera's full clouds are *not* stored: 640 x 480 = 307,200 points per
frame, 100 frames for a 10 s demonstration, ~370 MB as float32 xyz + rgb.
The segmented object (2048 points per frame, ~8 MB per demonstration) is what
the goal model uses.

Schema 2 adds ``peak_force`` and, with the camera, the segment's pixel counts
and three small pictures (``pixels_*``, ``snapshot_*``): enough to see
afterwards, also for a demonstration recorded on the robot, when the segment
lost the object and why (``drake-skill fit``'s ``fit_report.html`` and its
warnings): without ground truth, the pixels of the object's hue stand for the
object's, those of them that fail the colour test are what the colour range
drops, and object-coloured pixels the segment does not keep are what the
crop, the table removal and the cluster rule drop.
"First contact" is the first 10 Hz sample whose ``peak_force`` exceeds
:data:`CONTACT_FORCE_N` (free motion reads 0 N); without one (no touch, or
the robot) the first at which the object state moved :data:`MOVE_FRACTION`
of its travel (of :data:`MIN_TRAVEL` or more), else the middle sample;
``metadata["snapshot_labels"]`` says which. Their size: 32 bytes per 10 Hz
sample (``peak_force`` and the three counts) and, at w x h pixels, 12 w h
bytes for the pictures; measured on a 14.6 s scripted demonstration of Open
(147 samples, crop 282 x 265 -> 71 x 67 pixels): 4.7 kB + 57 kB = 62 kB,
1.6 % of its 3.9 MB file.

File format (``SCHEMA_VERSION`` = 2; version 1 files, without the schema-2
fields, still load): a numpy ``.npz`` written atomically,
readable with ``np.load(path, allow_pickle=False)``. Every field above is an
array of the same name (``skill`` a 0-d unicode array, ``seed`` int64,
``success`` bool, ``final_object_state`` float64); ``metadata`` is a 0-d
unicode array holding a JSON object with ``schema``, ``schema_version``,
``units``, ``frames``, ``rates_hz`` and the extras. The perception fields are
absent when the demonstration was recorded without a camera
(``metadata["has_perception"]`` is false); each schema-2 group
(``peak_force``; ``pixels_*`` with ``snapshot_*``) is present or absent as a
whole (absent: a demonstration converted from version 1 or imported).
"""

from __future__ import annotations

import dataclasses as dc
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from drake_skill.common import N_POINTS
from drake_skill.fileio import atomic_save_npz, load_npz
from drake_skill.action.quaternion import make_quaternions_continuous, quat_conjugate, quat_multiply

__all__ = [
    "SCHEMA",
    "SCHEMA_VERSION",
    "READ_VERSIONS",
    "CONTACT_FORCE_N",
    "MOVE_FRACTION",
    "MIN_SAMPLES",
    "N_POINTS",
    "Demonstration",
    "DemoSetWriter",
    "DemonstrationError",
    "object_frame_poses",
    "downsample_action",
    "first_move",
    "snapshot_frames",
    "save_demonstration",
    "load_demonstration",
    "load_demonstrations",
    "demo_path",
    "existing_demo_files",
    "save_demonstrations",
    "append_demonstration",
    "check_manifest",
    "MANIFEST",
]

SCHEMA = "drake-skill-demonstration"
SCHEMA_VERSION = 2
#: The versions :func:`load_demonstration` reads (1: before peak_force, pixels_* and snapshot_*).
READ_VERSIONS = (1, 2)
#: A 10 Hz sample whose peak contact force exceeds this [N] touches the object ("first contact"):
#: free motion reads exactly 0 N, a scripted demonstration's first touch 0.5-10 N.
CONTACT_FORCE_N = 0.5
#: The object "moves" once its state is this share of its whole travel away from the start ...
MOVE_FRACTION = 0.02
#: ... of at least this much [rad or m] (less is the simulator's or the sensor's noise: it did not move).
MIN_TRAVEL = 1e-3
#: Fewest 10 Hz samples a demonstration may have (1 s of motion).
MIN_SAMPLES = 10
QUATERNION_TOLERANCE = 1e-3
#: A frame marked valid must have a segmented cloud at least this wide (m) along
#: two axes (the objects are 0.1-0.3 m; a point, a line or all zeros is not a cloud).
MIN_CLOUD_EXTENT_M = 0.005
#: How far X_OE may be from X_OE_100hz at the same instant (m, and quaternion
#: components up to sign): X_OE is a subsample, so only rounding separates them.
SUBSAMPLE_TOLERANCE = 1e-6
#: The file that lists a recorded set of demonstrations (written by save_demonstrations).
MANIFEST = "demos.json"
ACTION_RAW_HZ = 100.0
ACTION_HZ = 10.0

UNITS = {
    "times_100hz": "s", "times": "s", "X_OE_100hz": "m, unit quaternion wxyz",
    "X_OE": "m, unit quaternion wxyz", "q_100hz": "rad", "gripper_100hz": "m",
    "object_state_100hz": "rad (box lid angle) or m (drawer travel)",
    "X_WO_true": "m, unit quaternion wxyz", "X_WO_start": "m, unit quaternion wxyz",
    "object_points": "m", "final_object_state": "rad (box lid angle) or m (drawer travel)",
    "peak_force": "N", "pixels_hue": "pixels", "pixels_coloured": "pixels", "pixels_kept": "pixels",
    "snapshot_segment": "0 not of the object's hue, 1 of its hue, not object-coloured, 2 object-coloured, "
                        "dropped, 3 kept",
}
FRAMES = {
    "X_OE_100hz": "pose of the hand TCP frame E in the object frame O",
    "X_OE": "pose of the hand TCP frame E in the object frame O",
    "X_WO_true": "ground-truth pose of O in the world W at the start (simulation)",
    "X_WO_start": "perceived pose of O in W at the start (segmented cloud's bounding-box centre)",
    "object_points": "segmented object points, world frame W",
}

_RAW = ("times_100hz", "X_OE_100hz", "q_100hz", "gripper_100hz", "object_state_100hz")
_PERCEPTION = ("X_WO_start", "object_points", "perception_valid")
_SCALARS = ("skill", "seed", "success", "final_object_state")
#: Schema 2's camera group (needs the perception fields).
_SEGMENT = ("pixels_hue", "pixels_coloured", "pixels_kept", "snapshot_index", "snapshot_rgb", "snapshot_segment")
_SCHEMA2 = ("peak_force",) + _SEGMENT


class DemonstrationError(ValueError):
    """A demonstration (in memory or on disk) does not satisfy the schema."""


def _fail(where: str, field: str, message: str):
    raise DemonstrationError(f"{where}: field '{field}' {message}")


@dc.dataclass
class Demonstration:
    """One demonstration (see the module docstring for every field's shape, unit and frame)."""

    skill: str
    seed: int
    success: bool
    final_object_state: float
    times_100hz: np.ndarray
    X_OE_100hz: np.ndarray
    q_100hz: np.ndarray
    gripper_100hz: np.ndarray
    object_state_100hz: np.ndarray
    times: np.ndarray
    X_OE: np.ndarray
    X_WO_true: np.ndarray
    X_WO_start: np.ndarray | None = None
    object_points: np.ndarray | None = None
    perception_valid: np.ndarray | None = None
    peak_force: np.ndarray | None = None
    pixels_hue: np.ndarray | None = None
    pixels_coloured: np.ndarray | None = None
    pixels_kept: np.ndarray | None = None
    snapshot_index: np.ndarray | None = None
    snapshot_rgb: np.ndarray | None = None
    snapshot_segment: np.ndarray | None = None
    metadata: dict[str, Any] = dc.field(default_factory=dict)
    #: The file it was loaded from (not stored in the file; None when recorded in memory).
    path: str | None = dc.field(default=None, compare=False)

    @property
    def has_perception(self) -> bool:
        return self.object_points is not None

    @property
    def has_segment(self) -> bool:
        """The segment's pixel counts and pictures are stored (schema 2, recorded with the camera)."""
        return self.pixels_hue is not None

    @property
    def duration(self) -> float:
        """Seconds from the first to the last raw sample."""
        return float(self.times_100hz[-1] - self.times_100hz[0])

    @property
    def n_samples(self) -> int:
        """Number of 10 Hz samples (T10)."""
        return int(self.times.shape[0])

    def validate(self, where: str = "demonstration") -> "Demonstration":
        """Checks every field; raises DemonstrationError naming ``where`` and the field."""
        if not isinstance(self.skill, str) or not self.skill or not all(c.isalnum() or c in "_-" for c in self.skill):
            _fail(where, "skill", f"is {self.skill!r}; expected a skill's name (letters, digits, '_', '-')")
        if isinstance(self.seed, bool) or not isinstance(self.seed, (int, np.integer)):
            _fail(where, "seed", f"is {self.seed!r}; expected an integer")
        if not isinstance(self.success, (bool, np.bool_)):
            _fail(where, "success", f"is {self.success!r}; expected a bool")
        if not math.isfinite(float(self.final_object_state)):
            _fail(where, "final_object_state", f"is {self.final_object_state!r}; expected a finite number")
        t_raw = _times(where, "times_100hz", self.times_100hz, MIN_SAMPLES)
        n = t_raw.shape[0]
        _poses(where, "X_OE_100hz", self.X_OE_100hz, n)
        _array(where, "q_100hz", self.q_100hz, (n, 7))
        _array(where, "gripper_100hz", self.gripper_100hz, (n,))
        _array(where, "object_state_100hz", self.object_state_100hz, (n,))
        t10 = _times(where, "times", self.times, MIN_SAMPLES)
        m = t10.shape[0]
        if t10[0] < t_raw[0] - 1e-9 or t10[-1] > t_raw[-1] + 1e-9:
            _fail(where, "times", f"spans {t10[0]:.3f}..{t10[-1]:.3f} s, outside times_100hz "
                  f"{t_raw[0]:.3f}..{t_raw[-1]:.3f} s")
        _poses(where, "X_OE", self.X_OE, m)
        _subsample_consistent(where, t_raw, self.X_OE_100hz, t10, self.X_OE)
        _poses(where, "X_WO_true", self.X_WO_true, None)
        present = [name for name in _PERCEPTION if getattr(self, name) is not None]
        if present and len(present) != len(_PERCEPTION):
            missing = sorted(set(_PERCEPTION) - set(present))
            _fail(where, missing[0], f"is missing while {', '.join(present)} "
                  "is present; perception fields come together")
        if present:
            _poses(where, "X_WO_start", self.X_WO_start, None)
            pts = self.object_points
            if not isinstance(pts, np.ndarray) or pts.dtype != np.float32 or pts.ndim != 3 \
                    or pts.shape[0] != m or pts.shape[2] != 3 or pts.shape[1] != N_POINTS:
                _fail(where, "object_points", f"has shape {getattr(pts, 'shape', None)} dtype "
                      f"{getattr(pts, 'dtype', None)}; expected ({m}, {N_POINTS}, 3) float32 "
                      f"({N_POINTS} points per frame, docs/method.md section 3)")
            if not np.all(np.isfinite(pts)):
                _fail(where, "object_points", "contains NaN or inf")
            valid = self.perception_valid
            if not isinstance(valid, np.ndarray) or valid.dtype != np.bool_ or valid.shape != (m,):
                _fail(where, "perception_valid", f"has shape {getattr(valid, 'shape', None)} dtype "
                      f"{getattr(valid, 'dtype', None)}; expected ({m},) bool")
            if valid.any():
                extent = np.ptp(pts[valid], axis=1)  # (n_valid, 3) bounding-box sizes, m
                wide = (extent >= MIN_CLOUD_EXTENT_M).sum(axis=1)
                if np.any(wide < 2):
                    k = int(np.flatnonzero(valid)[int(np.argmax(wide < 2))])
                    _fail(where, "object_points", f"frame {k} is marked valid but its cloud is degenerate "
                          f"(bounding box {np.ptp(pts[k], axis=0).round(4).tolist()} m; expected at least "
                          f"{MIN_CLOUD_EXTENT_M} m along two axes); mark it invalid in perception_valid")
        self._validate_schema2(where, m)
        try:
            json.dumps(self.metadata)
        except (TypeError, ValueError) as e:
            _fail(where, "metadata", f"is not JSON-serialisable ({e})")
        return self

    def _validate_schema2(self, where: str, m: int) -> None:
        """Checks ``peak_force`` and the ``pixels_*`` / ``snapshot_*`` group (module docstring)."""
        if self.peak_force is not None and np.any(_array(where, "peak_force", self.peak_force, (m,)) < 0):
            _fail(where, "peak_force", f"has a negative force at sample {int(np.argmax(self.peak_force < 0))}")
        present = [name for name in _SEGMENT if getattr(self, name) is not None]
        if present and len(present) != len(_SEGMENT):
            missing = sorted(set(_SEGMENT) - set(present))
            _fail(where, missing[0], f"is missing while {', '.join(present)} is present; the segment's "
                  "counts and pictures come together")
        if not present:
            return
        if not self.has_perception:
            _fail(where, "pixels_hue", "is present without the perception fields (object_points, ...)")
        names = _SEGMENT[:3]
        counts = [_counts(where, name, getattr(self, name), (m,)) for name in names]
        for j in (1, 2):
            if np.any(counts[j] > counts[j - 1]):
                k = int(np.argmax(counts[j] > counts[j - 1]))
                _fail(where, names[j], f"is {counts[j][k]} at sample {k}, more than {names[j - 1]} "
                      f"({counts[j - 1][k]}); kept pixels are object-coloured, and those are of the object's hue")
        _snapshots(where, self.snapshot_index, self.snapshot_rgb, self.snapshot_segment, m)

    def to_arrays(self) -> dict[str, np.ndarray]:
        """The arrays stored in the ``.npz`` (metadata as a JSON string)."""
        meta = dict(self.metadata)
        meta.update(schema=SCHEMA, schema_version=SCHEMA_VERSION, units=UNITS, frames=FRAMES,
                    rates_hz={"action_raw": ACTION_RAW_HZ, "action": ACTION_HZ,
                              "perception": ACTION_HZ},
                    has_perception=self.has_perception)
        arrays = {
            "metadata": np.array(json.dumps(meta, sort_keys=True)),
            "skill": np.array(str(self.skill)),
            "seed": np.array(int(self.seed), dtype=np.int64),
            "success": np.array(bool(self.success)),
            "final_object_state": np.array(float(self.final_object_state)),
            "times": self.times, "X_OE": self.X_OE, "X_WO_true": self.X_WO_true,
        }
        arrays.update({name: getattr(self, name) for name in _RAW})
        if self.has_perception:
            arrays.update({name: getattr(self, name) for name in _PERCEPTION})
        arrays.update({name: getattr(self, name) for name in _SCHEMA2 if getattr(self, name) is not None})
        return arrays


# ---------------------------------------------------------------- validation
def _array(where, field, value, shape) -> np.ndarray:
    if not isinstance(value, np.ndarray) or value.dtype.kind != "f":
        _fail(where, field, f"has dtype {getattr(value, 'dtype', type(value).__name__)}; "
              "expected a floating-point array")
    if shape is not None and value.shape != shape:
        _fail(where, field, f"has shape {value.shape}; expected {shape}")
    if not np.all(np.isfinite(value)):
        bad = np.argwhere(~np.isfinite(value))[0]
        _fail(where, field, f"contains NaN or inf (first at index {tuple(int(i) for i in bad)})")
    return value


def _times(where, field, value, min_len) -> np.ndarray:
    t = _array(where, field, value, None)
    if t.ndim != 1:
        _fail(where, field, f"has shape {t.shape}; expected (T,)")
    if t.shape[0] < min_len:
        _fail(where, field, f"has {t.shape[0]} samples; expected at least {min_len}")
    steps = np.diff(t)
    if np.any(steps <= 0):
        k = int(np.argmax(steps <= 0))
        _fail(where, field, f"is not strictly increasing (t[{k}] = {t[k]:.6g} s, "
              f"t[{k + 1}] = {t[k + 1]:.6g} s)")
    return t


def _subsample_consistent(where, t_raw, X_raw, t10, X10) -> None:
    """``times`` must be instants of ``times_100hz`` and ``X_OE`` the raw poses there."""
    idx = np.clip(np.searchsorted(t_raw, t10), 0, len(t_raw) - 1)
    prev = np.clip(idx - 1, 0, len(t_raw) - 1)
    idx = np.where(np.abs(t_raw[prev] - t10) < np.abs(t_raw[idx] - t10), prev, idx)
    off = np.abs(t_raw[idx] - t10)
    if np.any(off > 1e-9):
        k = int(np.argmax(off))
        _fail(where, "times", f"sample {k} ({t10[k]:.6f} s) is not one of the times_100hz instants; "
              "expected the 10 Hz times to be a subset of the raw ones (downsample_action)")
    dp = np.abs(X10[:, :3] - X_raw[idx, :3]).max(axis=1)
    dq = 1.0 - np.abs(np.einsum("ti,ti->t", X10[:, 3:], X_raw[idx, 3:]))  # 0 for q or -q
    bad = (dp > SUBSAMPLE_TOLERANCE) | (dq > SUBSAMPLE_TOLERANCE)
    if np.any(bad):
        k = int(np.argmax(bad))
        _fail(where, "X_OE", f"sample {k} ({t10[k]:.3f} s) differs from X_OE_100hz at the same instant "
              f"(position by {dp[k]:.3g} m); X_OE must be X_OE_100hz subsampled (downsample_action)")


def _poses(where, field, value, n) -> np.ndarray:
    shape = (7,) if n is None else (n, 7)
    x = _array(where, field, value, shape)
    norms = np.linalg.norm(x[..., 3:], axis=-1)
    bad = np.abs(norms - 1.0) > QUATERNION_TOLERANCE
    if np.any(bad):
        k = int(np.argmax(np.atleast_1d(bad)))
        _fail(where, field, f"has a quaternion of norm {float(np.atleast_1d(norms)[k]):.6g} at "
              f"sample {k}; expected unit norm within {QUATERNION_TOLERANCE}")
    return x


def _counts(where, field, value, shape) -> np.ndarray:
    if not isinstance(value, np.ndarray) or value.dtype.kind not in "iu" or value.shape != shape:
        _fail(where, field, f"has shape {getattr(value, 'shape', None)} dtype {getattr(value, 'dtype', None)}; "
              f"expected {shape} integers")
    if np.any(value < 0):
        _fail(where, field, f"has a negative count at sample {int(np.argmax(value < 0))}")
    return value


def _snapshots(where, index, rgb, segment, m) -> None:
    """snapshot_index (3,) 0 <= first contact <= m - 1 in order, from 0 to m - 1; rgb (3, h, w, 3) and
    segment (3, h, w) uint8 with values 0-3."""
    if not isinstance(index, np.ndarray) or index.dtype.kind not in "iu" or index.shape != (3,) \
            or index[0] != 0 or index[2] != m - 1 or not 0 <= index[1] <= m - 1:
        shown = index.tolist() if isinstance(index, np.ndarray) and index.size <= 3 else getattr(index, "shape", index)
        _fail(where, "snapshot_index", f"is {shown!r}; expected 3 integers [0, first contact, {m - 1}] "
              "(10 Hz samples: start, first contact, end)")
    if not isinstance(rgb, np.ndarray) or rgb.dtype != np.uint8 or rgb.ndim != 4 or rgb.shape[0] != 3 \
            or rgb.shape[3] != 3 or min(rgb.shape) < 1:
        _fail(where, "snapshot_rgb", f"has shape {getattr(rgb, 'shape', None)} dtype {getattr(rgb, 'dtype', None)}; "
              "expected (3, h, w, 3) uint8")
    if not isinstance(segment, np.ndarray) or segment.dtype != np.uint8 or segment.shape != rgb.shape[:3]:
        _fail(where, "snapshot_segment", f"has shape {getattr(segment, 'shape', None)} dtype "
              f"{getattr(segment, 'dtype', None)}; expected {rgb.shape[:3]} uint8 like snapshot_rgb")
    if segment.max() > 3:
        _fail(where, "snapshot_segment", f"holds the value {int(segment.max())}; expected 0 (not of the object's "
              "hue), 1 (of its hue, not object-coloured), 2 (object-coloured, dropped) or 3 (kept)")


# ---------------------------------------------------------------- pose math
def object_frame_poses(X_WO, X_WE) -> np.ndarray:
    """X_OE = X_WO^-1 X_WE for poses as 7-vectors.

    X_WO: (7,) object pose in W; X_WE: (T, 7) hand poses in W. Returns (T, 7)
    with quaternion signs made continuous along T (starting on the hemisphere
    with qw >= 0).
    """
    X_WO = np.asarray(X_WO, dtype=float)
    X_WE = np.atleast_2d(np.asarray(X_WE, dtype=float))
    q_WO = X_WO[3:] / np.linalg.norm(X_WO[3:])
    q_OW = quat_conjugate(q_WO)
    p = X_WE[:, :3] - X_WO[:3]
    # p_O = R_OW p, i.e. the quaternion product q_OW (0, p) q_WO.
    p_quat = np.concatenate([np.zeros((p.shape[0], 1)), p], axis=1)
    p_O = quat_multiply(quat_multiply(q_OW, p_quat), q_WO)[:, 1:]
    q_OE = quat_multiply(q_OW, X_WE[:, 3:])
    q_OE /= np.linalg.norm(q_OE, axis=1, keepdims=True)
    if q_OE[0, 0] < 0:
        q_OE[0] = -q_OE[0]
    q_OE = make_quaternions_continuous(q_OE)
    return np.concatenate([p_O, q_OE], axis=1)


def downsample_action(times_100hz, X_OE_100hz, rate_hz: float = ACTION_HZ):
    """Uniform subsampling 100 Hz -> ``rate_hz`` (thesis section 6.3), last sample kept.

    Returns (indices (T10,), times (T10,), X_OE (T10, 7)); the indices pick
    the raw samples, so perception frames recorded at the same instants line up.
    """
    t = np.asarray(times_100hz, dtype=float)
    rate = 1.0 / float(np.median(np.diff(t)))
    k = int(round(rate / rate_hz))
    if k < 1 or abs(rate / rate_hz - k) > 0.05:
        raise ValueError(f"times_100hz: rate {rate:.3f} Hz is not an integer multiple of {rate_hz} Hz")
    idx = np.arange(0, t.size, k)
    if idx[-1] != t.size - 1:
        idx = np.append(idx, t.size - 1)
    X = np.asarray(X_OE_100hz, dtype=float)[idx].copy()
    X[:, 3:] = make_quaternions_continuous(X[:, 3:])
    return idx, t[idx].copy(), X


def first_move(object_state) -> int | None:
    """The first sample at which the object state is :data:`MOVE_FRACTION` of its whole travel away
    from the start (None when it never moves, or by less than :data:`MIN_TRAVEL`)."""
    s = np.asarray(object_state, dtype=float)
    away = np.abs(s - s[0])
    if away.max() < MIN_TRAVEL:
        return None
    return int(np.flatnonzero(away > MOVE_FRACTION * away.max())[0])


def snapshot_frames(peak_force, object_state) -> tuple[np.ndarray, list[str]]:
    """The 10 Hz samples stored as pictures, ``[0, first contact, T10 - 1]``, and their labels, from
    each sample's peak contact force [N] and object state (module docstring: the first touch over
    :data:`CONTACT_FORCE_N`, else the object's first move, else the middle)."""
    n = len(peak_force)
    touch = np.flatnonzero(np.asarray(peak_force) > CONTACT_FORCE_N)
    moved = first_move(object_state)
    if touch.size:
        k, label = int(touch[0]), "first contact"
    elif moved is not None:
        k, label = moved, "object first moves"
    else:
        k, label = n // 2, "middle"
    return np.array([0, k, n - 1], dtype=np.int64), ["start", label, "end"]


# ---------------------------------------------------------------- files
def demo_path(directory, index: int) -> Path:
    """``DIR/demo_000.npz`` for index 0, and so on."""
    return Path(directory) / f"demo_{index:03d}.npz"


def save_demonstration(demo: Demonstration, path, force: bool = False) -> Path:
    """Validates ``demo`` and writes it to ``path`` atomically.

    Refuses (FileExistsError) to replace an existing file unless ``force``.
    """
    path = Path(path)
    demo.validate(str(path))
    if path.exists() and not force:
        raise FileExistsError(f"{path} exists; refusing to overwrite a recorded demonstration "
                              "(pass force=True / --force to replace it)")
    return atomic_save_npz(path, demo.to_arrays())


def _scalar(where, data, name, kind):
    value = data[name]
    if value.shape != () or value.dtype.kind not in kind:
        _fail(where, name, f"has shape {value.shape} dtype {value.dtype}; expected a scalar of kind {kind!r}")
    return value.item()


def load_demonstration(path) -> Demonstration:
    """Loads and validates one demonstration file; errors name the file and the field."""
    path = Path(path)
    where = str(path)
    data = load_npz(path)   # FileNotFoundError / ValueError naming the file
    if "metadata" not in data:
        raise DemonstrationError(f"{where}: field 'metadata' is missing; not a drake-skill "
                                 f"demonstration file (fields: {', '.join(sorted(data)) or 'none'})")
    meta_arr = data["metadata"]
    if meta_arr.shape != () or meta_arr.dtype.kind != "U":
        _fail(where, "metadata", f"has shape {meta_arr.shape} dtype {meta_arr.dtype}; expected a JSON string")
    try:
        meta = json.loads(meta_arr.item())
    except json.JSONDecodeError as e:
        _fail(where, "metadata", f"is not valid JSON ({e})")
    if not isinstance(meta, dict) or meta.get("schema") != SCHEMA:
        _fail(where, "metadata", f"names schema {meta.get('schema') if isinstance(meta, dict) else None!r}; "
              f"expected {SCHEMA!r}")
    version = meta.get("schema_version")
    if type(version) is not int or version not in READ_VERSIONS:
        _fail(where, "metadata.schema_version", f"is {version!r}; this drake-skill reads versions "
              f"{', '.join(map(str, READ_VERSIONS))}")
    has_perception = bool(meta.get("has_perception", False))
    required = ("times", "X_OE", "X_WO_true") + _RAW + _SCALARS + (_PERCEPTION if has_perception else ())
    for name in required:
        if name not in data:
            _fail(where, name, "is missing")
    extras = {k: v for k, v in meta.items()
              if k not in ("schema", "schema_version", "units", "frames", "rates_hz", "has_perception")}
    demo = Demonstration(
        skill=_scalar(where, data, "skill", "U"),
        seed=int(_scalar(where, data, "seed", "iu")),
        success=bool(_scalar(where, data, "success", "b")),
        final_object_state=float(_scalar(where, data, "final_object_state", "f")),
        times=data["times"], X_OE=data["X_OE"], X_WO_true=data["X_WO_true"],
        **{name: data[name] for name in _RAW},
        **({name: data[name] for name in _PERCEPTION} if has_perception else {}),
        **{name: data[name] for name in _SCHEMA2 if version >= 2 and name in data},
        metadata=extras, path=where,
    )
    return demo.validate(where)


def load_demonstrations(directory, skill: str | None = None) -> list[Demonstration]:
    """All ``demo_*.npz`` of ``directory``, sorted by file name.

    With ``skill``: every file must be a demonstration of that skill.
    Raises FileNotFoundError if the directory has none.
    """
    directory = Path(directory)
    if not directory.is_dir():
        raise FileNotFoundError(f"{directory}: no such directory")
    paths = sorted(directory.glob("demo_*.npz"))
    if not paths:
        raise FileNotFoundError(f"{directory}: no demo_*.npz files (record some with "
                                f"'drake-skill demos record --out {directory}')")
    check_manifest(directory, paths)
    demos = [load_demonstration(p) for p in paths]
    if skill is not None:
        for p, d in zip(paths, demos):
            if d.skill != skill:
                _fail(str(p), "skill", f"is {d.skill!r}; expected {skill!r} (all demonstrations of {directory})")
    return demos


def existing_demo_files(directory) -> list[Path]:
    """The ``demo_*.npz`` already in ``directory`` (empty if it does not exist)."""
    directory = Path(directory)
    return sorted(directory.glob("demo_*.npz")) if directory.is_dir() else []


# ---------------------------------------------------------------- sets of files
def check_manifest(directory: Path, paths: list[Path]) -> None:
    """With a ``demos.json`` (written by :func:`save_demonstrations`), the folder must hold exactly its files."""
    from drake_skill.fileio import file_sha256

    manifest = directory / MANIFEST
    if not manifest.is_file():
        return  # a folder assembled by hand (save_demonstration one by one)
    try:
        meta = json.loads(manifest.read_text())
        files = dict(meta["files"])
    except (json.JSONDecodeError, UnicodeDecodeError, KeyError, TypeError, ValueError) as e:
        raise DemonstrationError(f"{manifest}: not a drake-skill demonstration list ({e}); delete it "
                                 "if the folder was assembled by hand") from e
    names = sorted(p.name for p in paths)
    if names != sorted(files):
        extra = sorted(set(names) - set(files))
        missing = sorted(set(files) - set(names))
        raise DemonstrationError(
            f"{directory}: the demonstration files do not match {MANIFEST} (missing {missing}, not listed "
            f"{extra}); the folder mixes recordings. Record the set again (demos record --force)")
    for p in paths:
        if file_sha256(p) != files[p.name]:
            raise DemonstrationError(f"{p}: contents differ from the checksum in {manifest}; the folder mixes "
                                     "recordings. Record the set again (demos record --force)")


def save_demonstrations(demos, directory, force: bool = False, extra=None) -> list[Path]:
    """Writes a set of demonstrations to ``directory`` as one unit.

    ``demo_000.npz``, ``demo_001.npz``, ... and ``demos.json`` (their
    SHA-256) are written into a new directory that then replaces
    ``directory`` in one swap (:class:`drake_skill.fileio.staged_directory`):
    an interruption leaves the whole old set or the whole new one. Other
    files already in ``directory`` (not ``demo_*.npz``, ``demos.json`` or
    ``demos.png``) are carried over. ``extra(tmp_dir)``, if given, writes
    more files into the new set (the CLI's ``demos.png``).

    Refuses (FileExistsError) to replace existing demonstrations unless ``force``.
    """
    from drake_skill import fileio

    directory = Path(directory)
    if directory.exists() and not directory.is_dir():
        raise NotADirectoryError(f"{directory}: exists and is not a folder; choose a folder for the demonstrations")
    existing = existing_demo_files(directory)
    if existing and not force:
        raise FileExistsError(
            f"{directory} already holds {len(existing)} demonstration file(s) "
            f"({', '.join(p.name for p in existing[:3])}{', ...' if len(existing) > 3 else ''}); "
            "pass --force to replace them or choose another --out")
    for i, demo in enumerate(demos):
        demo.validate(str(demo_path(directory, i)))
    ours = {MANIFEST, "demos.png"}
    with fileio.staged_directory(directory, overwrite=True) as tmp:
        old_demos = {p.name for p in existing}
        fileio.carry_over(directory, tmp, exclude=ours | old_demos)
        files = {}
        for i, demo in enumerate(demos):
            path = demo_path(tmp, i)
            fileio.atomic_save_npz(path, demo.to_arrays())
            files[path.name] = fileio.file_sha256(path)
        if extra is not None:
            extra(tmp)
        fileio.atomic_write_json(tmp / MANIFEST, {"schema": "drake-skill-demonstration-set", "files": files})
    return [demo_path(directory, i) for i in range(len(demos))]


def append_demonstration(demo: Demonstration, directory, extra=None) -> Path:
    """Adds ``demo`` to the set in ``directory`` as the next ``demo_NNN.npz``, manifest updated.

    The folder is rewritten as one unit like :func:`save_demonstrations`: the
    files already there are hard-linked into a new directory (no copy), the
    new file and a ``demos.json`` listing all of them are written beside
    them, and the new directory replaces the old in one swap. An
    interruption leaves the old set or the new one; the folder loads with
    :func:`load_demonstrations` either way. The index is one past the highest
    existing one. A folder without ``demos.json`` (assembled by hand) gets one.
    ``demos.png`` (a plot of the set written by ``demos record``) is left out
    unless ``extra(tmp_dir)`` writes a new one; ``extra`` sees the whole new set.

    Refuses (DemonstrationError) a folder whose files do not match its
    manifest or hold another skill's demonstrations.
    """
    from drake_skill import fileio

    directory = Path(directory)
    if directory.exists() and not directory.is_dir():
        raise NotADirectoryError(f"{directory}: exists and is not a folder; choose a folder for the demonstrations")
    existing = existing_demo_files(directory)
    if existing:
        check_manifest(directory, existing)
        for p in existing:
            other = load_demonstration(p)
            if other.skill != demo.skill:
                _fail(str(p), "skill", f"is {other.skill!r}, but the demonstration to add is {demo.skill!r}; "
                      "record it into a folder of its own skill (--out)")
    index = 1 + max((int(p.stem.split("_")[1]) for p in existing if p.stem.split("_")[1].isdigit()), default=-1)
    target = demo_path(directory, index)
    demo.validate(str(target))
    with fileio.staged_directory(directory, overwrite=True) as tmp:
        fileio.carry_over(directory, tmp, exclude={MANIFEST, "demos.png"})
        fileio.atomic_save_npz(tmp / target.name, demo.to_arrays())
        files = {p.name: fileio.file_sha256(p) for p in existing_demo_files(tmp)}
        if extra is not None:
            extra(tmp)
        fileio.atomic_write_json(tmp / MANIFEST, {"schema": "drake-skill-demonstration-set", "files": files})
    return target


class DemoSetWriter:
    """Keeps every demonstration as it is finished, so that an interruption loses none.

    For recordings that cannot be repeated at will (a person at the
    teleoperation page or the robot). Each :meth:`add` appends the
    demonstration to the set on disk (:func:`append_demonstration`: one
    swap, manifest updated). Into a folder with no demonstrations they go
    straight there. Replacing a set (``force``) grows the new one in the
    staging folder ``.NAME.recording`` beside it, so the old set stays whole
    until the new one replaces it: at :meth:`finish`, or at
    :meth:`interrupted` once at least one new demonstration is finished.
    A staging folder left by a killed session is refused, never cleared
    (it holds a person's finished demonstrations).
    """

    def __init__(self, directory, force: bool = False):
        self.directory = Path(directory)
        self.demos: list[Demonstration] = []
        existing = existing_demo_files(self.directory)
        if existing and not force:
            raise FileExistsError(f"{self.directory} already holds {len(existing)} demonstration file(s); "
                                  "pass --force to replace them or choose another --out")
        self.staging = self.directory.with_name(f".{self.directory.name}.recording") if existing else None
        if self.staging is not None and self.staging.exists():
            raise FileExistsError(f"{self.staging}: holds the demonstrations of an interrupted session; move them "
                                  f"elsewhere (they load with 'drake-skill demos list {self.staging}') or delete "
                                  "the folder, then record again")

    @property
    def target(self) -> Path:
        """Where the next demonstration is written."""
        return self.directory if self.staging is None else self.staging

    def add(self, demo: Demonstration) -> Path:
        """Writes ``demo`` as the next file of the set being recorded; returns its path."""
        path = append_demonstration(demo, self.target)
        self.demos.append(demo)
        return path

    def finish(self, extra=None) -> list[Path]:
        """The finished set in ``directory`` (replacing an old one as a whole), ``extra(tmp)`` beside it."""
        paths = save_demonstrations(self.demos, self.directory, force=True, extra=extra)
        self._drop_staging()
        return paths

    def interrupted(self) -> str:
        """Keeps every finished demonstration in ``directory``; returns the sentence that says so."""
        n = len(self.demos)
        if self.staging is not None and n == 0:
            self._drop_staging()
            return f"no demonstration was finished; {self.directory} still holds its old set"
        if self.staging is not None:
            save_demonstrations(self.demos, self.directory, force=True)
            self._drop_staging()
            return f"kept the {n} finished demonstration(s) in {self.directory}; they replace the old set"
        return f"kept the {n} finished demonstration(s) in {self.directory}"

    def _drop_staging(self) -> None:
        import shutil

        if self.staging is not None and self.staging.exists():
            shutil.rmtree(self.staging)
