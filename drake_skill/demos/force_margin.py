"""A force margin at recording: a demonstration that presses close to the collision reflex gets a warning.

The DMP reproduces a demonstration within millimetres, not exactly, and
exploration adds noise on top: a demonstration that already presses near the
reflex's limit gives imitations and rollouts that trip it (a flap demonstrated
at 22 N of the reflex's 30 N tripped it on 16 of 16 imitations). So a
demonstration whose peak exceeds ``FORCE_MARGIN`` (60 %) of a reflex limit
is named, with the time and the value of its peak, when it is recorded:

* the robot-scene contact force f [N] against ``reflex.contact_force_max``
  (simulation: scripted and interactive demonstrations);
* each joint's external torque |tau_i| [N m] against
  ``reflex.external_torque_max[i]`` (the robot measures only these: on
  ``drake-skill hardware record-demo`` the contact force is 0).

Both are the reflex monitor's filtered values
(``drake_skill.station.reflex``), the peak over each 100 Hz sample's
interval, as the loggers give them (``drake_skill.station.loggers``, from the
logged filter state); a demonstration stores the peak of
each and its time (s from the demonstration's start) in its metadata
(``drake_skill.demos.demonstrator.demonstration_from``).

The scripted demonstrator still rejects a demonstration above its
``max_force_fraction`` (0.8); the warning names the ones it accepts between
the margin and that fraction, and every interactive or kinesthetic one above
the margin. The math is plain numpy (:func:`peaks`, :func:`check_margin`,
:func:`margin_message`); :func:`margin_warnings` applies it to a
Demonstration.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = ["FORCE_MARGIN", "MarginExcess", "peaks", "check_margin", "margin_message", "margin_warnings"]

#: Fraction of a reflex limit above which a demonstration's peak is warned about.
FORCE_MARGIN = 0.6


class MarginExcess(NamedTuple):
    """A peak over the margin: ``peak`` and ``limit`` [N or N m], ``time_s`` [s from the
    demonstration's start], ``fraction`` = peak / limit, ``index`` the column (joint - 1)."""

    peak: float
    time_s: float
    limit: float
    fraction: float
    index: int


def peaks(times, values) -> tuple[np.ndarray, np.ndarray]:
    """The peak of each column of ``values`` and the time of its first occurrence.

    times: (T,) [s]; values: (T,) or (T, J) (magnitudes, e.g. a recording's
    per-sample peak force or |external torque|). Returns (peak (J,), time (J,))
    (J = 1 for (T,)); zeros for T = 0.
    """
    times = np.asarray(times, dtype=float).reshape(-1)
    values = np.abs(np.asarray(values, dtype=float))
    values = values.reshape(values.shape[0], -1) if values.ndim else values.reshape(1, 1)
    if values.shape[0] != times.size:
        raise ValueError(f"peaks: {times.size} times for {values.shape[0]} samples")
    if times.size == 0:
        return np.zeros(values.shape[1]), np.zeros(values.shape[1])
    i = np.argmax(values, axis=0)
    return values[i, np.arange(values.shape[1])], times[i]


def check_margin(peak, time_s, limit, margin: float = FORCE_MARGIN) -> MarginExcess | None:
    """The worst of the peaks over ``margin`` x their limit, or None.

    peak, time_s, limit: scalars or (J,) arrays [N or N m, s, N or N m]; the
    worst is the largest peak / limit. A limit <= 0 or not finite checks nothing.
    """
    peak, time_s, limit = np.broadcast_arrays(*(np.atleast_1d(np.asarray(v, dtype=float))
                                                for v in (peak, time_s, limit)))
    checked = np.isfinite(limit) & (limit > 0) & np.isfinite(peak)
    fraction = np.where(checked, np.abs(peak) / np.where(checked, limit, 1.0), 0.0)
    i = int(np.argmax(fraction))
    if not fraction[i] > margin:
        return None
    return MarginExcess(float(abs(peak[i])), float(time_s[i]), float(limit[i]), float(fraction[i]), i)


def margin_message(name: str, excess: MarginExcess, quantity: str = "contact force", unit: str = "N",
                   margin: float = FORCE_MARGIN) -> str:
    """The one-line warning: the demonstration ``name``, the time, the peak, the limit and what to do."""
    return (f"{name}: {quantity} peaks at {excess.peak:.1f} {unit} at t = {excess.time_s:.2f} s, "
            f"{100 * excess.fraction:.0f} % of the reflex limit {excess.limit:g} {unit} "
            f"(warned above {100 * margin:.0f} %); demonstrate with a lighter touch, or the imitation and "
            f"exploration will trip the reflex at {excess.limit:g} {unit}")


def margin_warnings(demo, reflex, name: str, margin: float = FORCE_MARGIN) -> list[str]:
    """The warnings of a Demonstration (``drake_skill.demos.format``) recorded with
    ``reflex`` (the station's ``ReflexConfig``): one for the contact force, one for the
    joint whose external torque is nearest its limit, each only above ``margin``.

    Reads the metadata ``demonstration_from`` writes (``peak_contact_force_N`` and
    ``_time_s``, ``peak_external_torque_Nm`` (7) and ``_time_s`` (7)); a demonstration
    without them (recorded by an older drake-skill) gets the force check only where
    its peak force is stored, at an unknown time (NaN).
    """
    meta, out = demo.metadata, []
    if "peak_contact_force_N" in meta:
        excess = check_margin(meta["peak_contact_force_N"], meta.get("peak_contact_force_time_s", np.nan),
                              reflex.contact_force_max, margin)
        if excess is not None:
            out.append(margin_message(name, excess, "contact force", "N", margin))
    if "peak_external_torque_Nm" in meta:
        excess = check_margin(meta["peak_external_torque_Nm"], meta["peak_external_torque_time_s"],
                              reflex.external_torque_max, margin)
        if excess is not None:
            out.append(margin_message(name, excess, f"external torque of joint {excess.index + 1}", "N m",
                                      margin))
    return out
