"""Unit-quaternion helpers on numpy arrays (no Drake import).

Convention: Hamilton quaternions stored scalar-first, ``q = (w, x, y, z)``,
the same order as Drake's ``Quaternion`` and as the 7-D poses of the action
data (docs/method.md section 2: xyz + quaternion w, x, y, z). Every function works
on arrays of shape ``(..., 4)`` and broadcasts over the leading axes.

Hand-written rather than ``scipy.spatial.transform.Rotation`` because the
action model needs (a) scalar-first storage without copies, (b) the sign of a
quaternion preserved (``Rotation`` may canonicalise it, while the DMP treats
``q`` as a 4-D vector whose sign matters), and (c) batched maps inside the
Ude et al. integration loop with no object construction per step.

Maps used by the Ude et al. 2014 orientation DMP (see ``drake_skill.action.dmp``):

- ``quat_log(q)``: unit quaternion -> 3-vector ``theta/2 * axis`` (half the
  rotation vector), so ``2 * quat_log(q)`` is the rotation vector in rad;
- ``quat_exp(v)``: inverse map, 3-vector -> unit quaternion.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "as_quaternions",
    "quat_normalize",
    "quat_conjugate",
    "quat_multiply",
    "quat_log",
    "quat_exp",
    "quaternion_distance",
    "rotation_angle",
    "make_quaternions_continuous",
]

#: Largest accepted deviation of an input quaternion's norm from 1.
UNIT_NORM_TOLERANCE = 1e-2


def as_quaternions(q, name: str = "q", tol: float = UNIT_NORM_TOLERANCE) -> np.ndarray:
    """Validates ``q`` (shape ``(..., 4)``, finite, norm within ``tol`` of 1).

    Returns a float64 copy normalised to exactly unit norm. Raises ValueError
    naming ``name`` otherwise.
    """
    q = np.array(q, dtype=float, copy=True)
    if q.ndim < 1 or q.shape[-1] != 4:
        raise ValueError(f"{name}: expected shape (..., 4) quaternions (w, x, y, z), got shape {q.shape}")
    if not np.all(np.isfinite(q)):
        raise ValueError(f"{name}: contains NaN or inf (shape {q.shape})")
    norm = np.linalg.norm(q, axis=-1)
    bad = np.abs(norm - 1.0) > tol
    if np.any(bad):
        idx = np.argwhere(bad)[0]
        raise ValueError(
            f"{name}: quaternion at index {tuple(int(i) for i in idx)} has norm {float(norm[tuple(idx)]):.6g}; "
            f"expected unit norm within {tol}"
        )
    return q / norm[..., None]


def quat_normalize(q: np.ndarray) -> np.ndarray:
    """Returns ``q / |q|`` along the last axis (shape ``(..., 4)``)."""
    q = np.asarray(q, dtype=float)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def quat_to_rotation_matrix(q) -> np.ndarray:
    """Rotation matrix R (3, 3) of a unit quaternion ``(w, x, y, z)`` (normalised first)."""
    w, x, y, z = quat_normalize(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def quat_conjugate(q: np.ndarray) -> np.ndarray:
    """Returns the conjugate ``(w, -x, -y, -z)``; the inverse for unit ``q``."""
    q = np.asarray(q, dtype=float)
    out = -q
    out[..., 0] = q[..., 0]
    return out


def quat_multiply(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Hamilton product ``p * q`` of arrays of shape ``(..., 4)`` (broadcast)."""
    p = np.asarray(p, dtype=float)
    q = np.asarray(q, dtype=float)
    pw, px, py, pz = np.moveaxis(p, -1, 0)
    qw, qx, qy, qz = np.moveaxis(q, -1, 0)
    return np.stack(
        [
            pw * qw - px * qx - py * qy - pz * qz,
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
        ],
        axis=-1,
    )


def quat_log(q: np.ndarray) -> np.ndarray:
    """Logarithm of a unit quaternion, ``(..., 4) -> (..., 3)``.

    ``log(q) = atan2(|v|, w) * v / |v|`` with ``q = (w, v)`` (Ude et al. 2014,
    Eq. 19), i.e. half the rotation angle times the axis; ``0`` for ``v = 0``.
    """
    q = np.asarray(q, dtype=float)
    w = q[..., 0]
    v = q[..., 1:]
    nv = np.linalg.norm(v, axis=-1)
    # atan2 is accurate for every angle; sinc-like ratio handled at nv -> 0.
    ang = np.arctan2(nv, w)
    safe = nv > 1e-12
    scale = np.where(safe, ang / np.where(safe, nv, 1.0), 1.0 / np.where(np.abs(w) > 0, w, 1.0))
    return v * scale[..., None]


def quat_exp(r: np.ndarray) -> np.ndarray:
    """Exponential map ``(..., 3) -> (..., 4)``: ``(cos|r|, sin|r| r/|r|)``.

    Inverse of :func:`quat_log` for ``|r| < pi`` (Ude et al. 2014, Eq. 18).
    """
    r = np.asarray(r, dtype=float)
    n = np.linalg.norm(r, axis=-1)
    # sin(n)/n with its Taylor series near 0 to avoid 0/0.
    sinc = np.where(n > 1e-8, np.sin(n) / np.where(n > 1e-8, n, 1.0), 1.0 - n * n / 6.0)
    return np.concatenate([np.cos(n)[..., None], r * sinc[..., None]], axis=-1)


def quaternion_distance(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Sign-invariant Euclidean distance ``min(|p - q|, |p + q|)`` (shape ``(...)``).

    ``q`` and ``-q`` are the same rotation, so both signs are compared. For
    small errors the rotation angle is about twice this distance.
    """
    p = np.asarray(p, dtype=float)
    q = np.asarray(q, dtype=float)
    return np.minimum(np.linalg.norm(p - q, axis=-1), np.linalg.norm(p + q, axis=-1))


def rotation_angle(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Angle (rad, in ``[0, pi]``) of the rotation taking ``q`` to ``p``.

    ``2 * |log(p * conj(q))|`` with the shorter of the two signs.
    """
    d = quat_multiply(quat_normalize(p), quat_conjugate(quat_normalize(q)))
    d = np.where(d[..., :1] < 0.0, -d, d)
    return 2.0 * np.linalg.norm(quat_log(d), axis=-1)


def make_quaternions_continuous(q, reference: np.ndarray | None = None) -> np.ndarray:
    """Flips signs so that consecutive quaternions have a non-negative dot product.

    ``q``: ``(T, 4)``. If ``reference`` (shape ``(4,)``) is given, the first
    sample is first put on the reference's hemisphere (dot >= 0), which is how
    several demonstrations are made consistent with one another (docs/method.md
    section 2). Returns a new array; rotations are unchanged since ``q`` and
    ``-q`` represent the same orientation.
    """
    q = np.array(q, dtype=float, copy=True)
    if q.ndim != 2 or q.shape[1] != 4:
        raise ValueError(f"q: expected shape (T, 4), got {q.shape}")
    if q.shape[0] == 0:
        return q
    if reference is not None:
        reference = np.asarray(reference, dtype=float)
        if reference.shape != (4,):
            raise ValueError(f"reference: expected shape (4,), got {reference.shape}")
        if np.dot(q[0], reference) < 0.0:
            q[0] = -q[0]
    # Sign of each step relative to the previous *raw* sample; the cumulative
    # product turns the per-step flips into absolute signs.
    dots = np.einsum("ij,ij->i", q[1:], q[:-1])
    step = np.where(dots < 0.0, -1.0, 1.0)
    signs = np.concatenate([[1.0], np.cumprod(step)])
    return q * signs[:, None]
