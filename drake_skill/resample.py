"""Resampling of demonstrated poses, e.g. 100 Hz -> 10 Hz (thesis section 6.3).

Plain numpy/scipy, no Drake import. Poses are ``(T, 7)``: xyz (m) +
quaternion (w, x, y, z). Two methods:

- ``"subsample"``: keep every k-th sample, ``k = round(source rate / rate)``
  (the thesis: "sampled uniformly"); the source must be uniformly sampled at
  an integer multiple of the target rate. The last sample is appended when it
  is not already on the subsampled grid (``keep_last``), so the DMP goal is
  the demonstrated final pose.
- ``"interpolate"``: new uniform times ``t0, t0 + 1/rate, ...`` (plus the last
  time with ``keep_last``); positions interpolated linearly, quaternions by
  spherical linear interpolation (``scipy.spatial.transform.Slerp``) between
  the neighbouring samples. Works for irregular source times.

In both cases quaternion signs are made continuous along the result, on the
hemisphere of the first source sample (the DMP treats q as a 4-D vector).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from drake_skill.dmp import validate_demonstration
from drake_skill.quaternion import make_quaternions_continuous

__all__ = ["estimate_rate", "resample_demonstration"]

_METHODS = ("subsample", "interpolate")


def estimate_rate(times) -> float:
    """Sampling rate in Hz from the median step of ``times`` (T >= 2, increasing)."""
    t = np.asarray(times, dtype=float)
    if t.ndim != 1 or t.size < 2:
        raise ValueError(f"times: expected shape (T >= 2,), got {t.shape}")
    step = float(np.median(np.diff(t)))
    if not step > 0:
        raise ValueError(f"times: expected increasing timestamps, median step is {step!r}")
    return 1.0 / step


def resample_demonstration(
    times,
    poses,
    rate_hz: float = 10.0,
    method: str = "subsample",
    *,
    keep_last: bool = True,
    uniform_tolerance: float = 0.05,
) -> tuple[np.ndarray, np.ndarray]:
    """Resamples one demonstration to ``rate_hz``; returns ``(times (T',), poses (T', 7))``.

    ``times``: (T,) s, strictly increasing; ``poses``: (T, 7). For
    ``"subsample"`` every source step must be within ``uniform_tolerance``
    (relative) of the median step and the source rate must be an integer
    multiple of ``rate_hz`` (within the same tolerance); otherwise ValueError.
    """
    t, y = validate_demonstration(times, poses, name="demonstration")
    if not (isinstance(rate_hz, (int, float)) and math.isfinite(rate_hz) and rate_hz > 0):
        raise ValueError(f"rate_hz: expected a finite rate > 0 Hz, got {rate_hz!r}")
    if method not in _METHODS:
        raise ValueError(f"method: expected one of {_METHODS}, got {method!r}")
    y[:, 3:] = make_quaternions_continuous(y[:, 3:])

    if method == "subsample":
        src = estimate_rate(t)
        step = np.diff(t)
        med = 1.0 / src
        if np.any(np.abs(step - med) > uniform_tolerance * med):
            k = int(np.argmax(np.abs(step - med)))
            raise ValueError(
                f"times: subsampling needs uniform timestamps; step {k} is {float(step[k]):.6g} s, median {med:.6g} s "
                f"(use method='interpolate')"
            )
        ratio = src / rate_hz
        k = int(round(ratio))
        if k < 1 or abs(ratio - k) > uniform_tolerance:
            raise ValueError(
                f"rate_hz: source rate {src:.6g} Hz is not an integer multiple of {rate_hz!r} Hz "
                f"(use method='interpolate')"
            )
        idx = np.arange(0, t.size, k)
        if keep_last and idx[-1] != t.size - 1:
            idx = np.append(idx, t.size - 1)
        return t[idx].copy(), y[idx].copy()

    new_t = t[0] + np.arange(int(math.floor((t[-1] - t[0]) * rate_hz + 1e-9)) + 1) / rate_hz
    if keep_last and t[-1] - new_t[-1] > 1e-9 / rate_hz:
        new_t = np.append(new_t, t[-1])
    new_t = np.minimum(new_t, t[-1])
    pos = np.stack([np.interp(new_t, t, y[:, i]) for i in range(3)], axis=1)
    # scipy uses scalar-last quaternions (x, y, z, w).
    rot = Rotation.from_quat(y[:, [4, 5, 6, 3]])
    q_xyzw = Slerp(t, rot)(new_t).as_quat()
    q = make_quaternions_continuous(q_xyzw[:, [3, 0, 1, 2]], reference=y[0, 3:])
    return new_t, np.concatenate([pos, q], axis=1)
