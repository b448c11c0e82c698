"""How closely an action model reproduces its demonstration: plain numpy, no Drake.

The figures of ``drake-skill bench imitation`` (docs/method.md section 2): a
demonstration's recorded hand path (``Demonstration.X_OE_100hz``, the
*measured* pose of the hand in the object frame O, 100 Hz), the DMP fitted to
it integrated alone (:func:`drake_skill.action.dmp.integrate`), and its
imitation in the simulated station (:class:`drake_skill.learning.imitation.Imitation`:
the measured hand path and the DMP's commanded path, on the same 100 Hz grid).

Poses are (T, 7) arrays ``[x, y, z, qw, qx, qy, qz]`` (m + unit quaternion);
every error here is on the position (the first three columns) only, as a
Euclidean distance, reported in millimetres. Paths compared sample by sample
share a uniform time grid starting at 0 (the demonstration's ``times_100hz``):
no time alignment, except in :func:`lag_ms`, which measures it.

Near contact: the samples where the demonstrated object moves
(:func:`contact_mask`), the part of the path where a millimetre decides whether
the object follows, or the collision reflex trips.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage

from drake_skill.action.dmp import Dmp, DmpConfig, integrate

__all__ = ["CONTACT_FRACTION", "CONTACT_DILATE_S", "position_errors_mm", "contact_mask", "fit_error",
           "tracking_error", "total_error", "lag_ms", "contact_shift_mm", "nan_max"]

#: A sample is near contact where |d(object state)/dt| exceeds this fraction of its peak ...
CONTACT_FRACTION = 0.02
#: ... dilated by this many seconds on either side [s].
CONTACT_DILATE_S = 0.2
#: A joint that moves less than this over a demonstration was not moved by it
#: [rad or m, the joint's unit]: no sample is near contact.
OBJECT_MOTION_MIN = 1e-3
#: Largest time shift :func:`lag_ms` considers, either way [s].
MAX_LAG_S = 0.5


def _positions(X, name: str) -> np.ndarray:
    p = np.asarray(X, dtype=float)
    if p.ndim != 2 or p.shape[1] < 3:
        raise ValueError(f"{name}: expected poses of shape (T, 7) (or positions (T, 3)), got {p.shape}")
    return p[:, :3]


def position_errors_mm(X_a, X_b, mask=None) -> tuple[float, float]:
    """(max, RMS) of the position distance |p_a(t_k) - p_b(t_k)| in mm.

    ``X_a``, ``X_b``: (T, 7) poses (or (T, 3) positions) on the same grid;
    when their lengths differ, the common first ``min(T_a, T_b)`` samples are
    compared. ``mask``: (T,) bool selecting samples (over the common length).
    No sample selected: (nan, nan).
    """
    a, b = _positions(X_a, "X_a"), _positions(X_b, "X_b")
    n = min(len(a), len(b))
    d = np.linalg.norm(a[:n] - b[:n], axis=1)
    if mask is not None:
        d = d[np.asarray(mask, dtype=bool)[:n]]
    if d.size == 0:
        return math.nan, math.nan
    return float(1e3 * d.max()), float(1e3 * np.sqrt(np.mean(d * d)))


def contact_mask(times, object_state, fraction: float = CONTACT_FRACTION,
                 dilate_s: float = CONTACT_DILATE_S) -> np.ndarray:
    """(T,) bool: the samples "near contact", where the demonstrated object moves.

    ``times`` (T,) s, ``object_state`` (T,) the object's joint (rad or m).
    A sample is in the mask where ``|d state / dt|`` (``numpy.gradient``) is
    above ``fraction`` (default 2 %) of its peak over the demonstration; the
    mask is then dilated by ``dilate_s`` (default 0.2 s) on either side, to
    take in the touch before the part moves and the release after (the
    rule the fit's near-contact tolerance uses). An object that never
    moves, less than ``OBJECT_MOTION_MIN`` over the demonstration (its
    joint jiggling as the hand passes), gives an empty mask.
    """
    t = np.asarray(times, dtype=float)
    s = np.asarray(object_state, dtype=float)
    if t.ndim != 1 or s.shape != t.shape or t.size < 2:
        raise ValueError(f"times / object_state: expected two (T,) arrays, T >= 2, got {t.shape} and {s.shape}")
    if not np.all(np.isfinite(s)) or np.ptp(s) < OBJECT_MOTION_MIN:
        return np.zeros(t.size, dtype=bool)
    speed = np.abs(np.gradient(s, t))
    peak = float(speed.max())
    if peak < 1e-9:
        return np.zeros(t.size, dtype=bool)
    moving = speed > fraction * peak
    dt = float(np.median(np.diff(t)))
    k = max(0, int(round(dilate_s / dt)))
    if k == 0:
        return moving
    # Dilation: a sample is kept when a moving sample lies within k of it (any length of array).
    return ndimage.maximum_filter1d(moving.astype(np.uint8), size=2 * k + 1, mode="constant") > 0


def fit_error(dmp: Dmp, config: DmpConfig, times, X_OE) -> tuple[float, float]:
    """(max, RMS) in mm of the DMP integrated alone against the demonstration's path.

    ``dmp`` integrated from its own ``y0`` (``integrate``, ``config`` the
    skill's DmpConfig with its scaled columns) at ``times - times[0]`` (s),
    against ``X_OE`` (T, 7), the demonstration's recorded path at ``times``
    (``Demonstration.times_100hz``, ``X_OE_100hz``). Position only.
    """
    t = np.asarray(times, dtype=float)
    return position_errors_mm(integrate(dmp, config, t - t[0]), X_OE)


def tracking_error(X_measured, X_commanded) -> tuple[float, float]:
    """(max, RMS) in mm of the imitation's measured hand path against the DMP's commanded path.

    Both (N, 7) in the object frame at the same instants (the whole
    imitation, settle phase included): the controller's lag and the load's sag.
    """
    return position_errors_mm(X_measured, X_commanded)


def total_error(X_imitation, X_demo, mask=None) -> dict:
    """The imitation's measured path against the demonstration's recorded path, mm.

    ``X_imitation`` (N, 7) and ``X_demo`` (T, 7) on the same grid from t = 0,
    compared sample by sample with no time alignment over the common length
    (the demonstration's, unless the imitation stopped early). ``mask``: (T,)
    the near-contact samples (:func:`contact_mask`). Returns
    ``{"total_max_mm", "total_rms_mm", "contact_max_mm"}`` (``contact_max_mm``
    nan without a mask or with an empty one).
    """
    worst, rms = position_errors_mm(X_imitation, X_demo)
    contact = math.nan if mask is None else position_errors_mm(X_imitation, X_demo, mask)[0]
    return {"total_max_mm": worst, "total_rms_mm": rms, "contact_max_mm": contact}


def _shift_costs(p: np.ndarray, d: np.ndarray, m: int) -> np.ndarray:
    """Mean squared distance between p(t_i + s) and d(t_i), i = 0..T-1, for s = -m..m samples.

    p is extended at both ends by holding its first and last samples (the hand
    at rest before the start and after a run that stopped early)."""
    n = len(d)
    head = np.repeat(p[:1], m, axis=0)
    tail = np.repeat(p[-1:], max(0, n + m - len(p)), axis=0)
    padded = np.concatenate([head, p[:n + m], tail])   # padded[m + i] = p[i]
    return np.array([np.mean(np.sum((padded[m + s:m + s + n] - d) ** 2, axis=1)) for s in range(-m, m + 1)])


def lag_ms(X_imitation, X_demo, dt: float, max_lag_s: float = MAX_LAG_S) -> float:
    """The time shift [ms] that best aligns the imitation's measured path with the demonstration's.

    Least squares over shifts on the grid: the shift ``L`` minimising
    ``mean_i |p_imitation(t_i + L) - p_demo(t_i)|^2`` over the
    demonstration's samples t_i (``dt`` [s] apart), for ``|L| <= max_lag_s``,
    refined below a sample by the parabola through the best shift's cost and
    its two neighbours'. Positive: the imitation runs behind the
    demonstration (it reaches each point ``L`` later). Position only; the
    imitation is held at its first sample before t = 0 and at its last after
    its end. A demonstration that never moves gives 0.
    """
    p, d = _positions(X_imitation, "X_imitation"), _positions(X_demo, "X_demo")
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"dt: expected the grid's step > 0 s, got {dt!r}")
    if len(p) == 0 or len(d) < 3:
        raise ValueError(f"X_imitation / X_demo: expected samples to compare, got {len(p)} and {len(d)}")
    m = max(1, int(round(max_lag_s / dt)))
    costs = _shift_costs(p, d, m)
    k = int(np.argmin(costs))
    if np.ptp(costs) <= 1e-30:
        return 0.0
    offset = 0.0
    if 0 < k < len(costs) - 1:
        c0, c1, c2 = costs[k - 1], costs[k], costs[k + 1]
        curvature = c0 - 2.0 * c1 + c2
        if curvature > 0:
            offset = 0.5 * (c0 - c2) / curvature
    return float(1e3 * (k - m + offset) * dt)


def contact_shift_mm(dmp: Dmp, config: DmpConfig, times, mask, shift_m: float = 0.05,
                     axes=(0, 1)) -> float:
    """How far the near-contact part of the DMP's path moves when its start moves [mm].

    The DMP is integrated alone (``integrate``, ``config`` the skill's
    DmpConfig with its scaled columns) from ``y0`` and from ``y0 +- shift_m``
    (default 5 cm) along each of ``axes`` of the object frame (default x and
    y: where the hand's start moves when the object's pose on the table
    changes), with the same goal and duration, at ``times - times[0]`` (s).
    Returns the largest distance between a shifted and the unshifted path
    over the samples of ``mask`` ((T,) bool, :func:`contact_mask`) and the
    shifts. A column kept out of the amplitude scaling moves by
    ``shift (1 + w t) exp(-w t)``, w = sqrt(K) / tau for the default
    critically damped K, D: the start's offset decaying (or, with
    ``DmpConfig.start_join``, fading out within that fraction of tau, after
    which it is 0); a scaled column's shape stretches by ``(g - y0') / (g - y0)``. nan
    for an empty mask.
    """
    t = np.asarray(times, dtype=float)
    mask = np.asarray(mask, dtype=bool)
    if mask.shape != t.shape:
        raise ValueError(f"mask: expected shape {t.shape} (one flag per time), got {mask.shape}")
    if not mask.any():
        return math.nan
    rel = t - t[0]
    base = integrate(dmp, config, rel)[mask, :3]
    worst = 0.0
    for axis in axes:
        for sign in (-1.0, 1.0):
            y0 = dmp.y0.copy()
            y0[int(axis)] += sign * shift_m
            moved = integrate(dmp.with_start(y0), config, rel)[mask, :3]
            worst = max(worst, float(np.linalg.norm(moved - base, axis=1).max()))
    return 1e3 * worst


def nan_max(values):
    """The largest of ``values`` ignoring nan and None; None when there is none."""
    finite = [float(v) for v in values if v is not None and math.isfinite(float(v))]
    return max(finite) if finite else None
