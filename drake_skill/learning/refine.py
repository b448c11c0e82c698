"""Refinement of a fitted skill's DMPs on the simulated station (docs/method.md section 2.3).

A demonstration stores the *measured* hand path, which lags the
demonstrator's command by 20-30 ms and sags under load. A DMP fitted to it
commands that path, and the station lags and sags once more. The
refinement runs each demonstration's DMP in the skill's scenario on the
demonstration's own object pose (:class:`~drake_skill.learning.imitation.Imitator`)
and refits it to ``demonstration + (demonstration - imitation)``
(:func:`drake_skill.action.fitting.refine_for_tracking`), keeping the plain
fit where the refined one does not follow the demonstration more closely
(a refinement that diverges, or trips the reflex).

It runs at fit time (``drake-skill fit``, ``drake-skill learn`` when it
fits), on the simulated station only; ``SkillConfig.dmp_refine = 0`` (or
``--no-refine``) switches it off. Demonstrations recorded on the robot are
refined against the simulated station too, so what it removes is the
simulated controller's lag, which the rollouts in simulation share.
"""

from __future__ import annotations

import copy

import numpy as np

from drake_skill.action.dmp import fit_dmp
from drake_skill.action.fitting import refine_for_tracking
from drake_skill.action.quaternion import make_quaternions_continuous

__all__ = ["refine_skill", "refinement_lines"]


def _same_hemisphere(path: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """``path`` (T, 7) with each quaternion flipped onto the side of ``reference``'s row (q and -q agree)."""
    out = np.array(path, dtype=float)
    flip = np.einsum("ij,ij->i", out[:, 3:], reference[:, 3:]) < 0
    out[flip, 3:] *= -1.0
    return out


def refine_skill(skill, demos, station_config=None, iterations: int | None = None, progress=None) -> list[dict]:
    """Refines ``skill``'s DMPs in place (one per demonstration, the fit's order); returns a report per DMP.

    ``iterations``: refinement steps (default ``skill.config.dmp_refine``); 0
    or a skill fitted to the 10 Hz data (the thesis's fit) leaves it as it
    is. ``progress(i, n, name)`` is called before each demonstration. The
    report, also stored as ``skill.info["dmp_refinement"]``, holds per
    demonstration the RMS error [mm] of the executed path against the
    demonstration after each execution (plain fit first), whether the plain
    fit was kept, and the imitation's failure reason when one failed.
    Sigma_b^0 is kept: a refinement moves each DMP by its tracking error,
    not by the demonstrations' spread that Sigma_b^0 describes.
    """
    from drake_skill.learning.imitation import Imitator

    iterations = int(skill.config.dmp_refine if iterations is None else iterations)
    if iterations <= 0 or skill.config.dmp_data != "100hz":
        return []
    config = skill.config.dmp
    if station_config is not None:   # the ground-truth object frame: no camera to render
        station_config = copy.deepcopy(station_config)
        station_config.enable_camera = False
    imitator = Imitator(skill, station_config)
    report, dmps = [], []
    for i, (dmp, demo) in enumerate(zip(skill.dmps, demos)):
        name = getattr(demo, "path", None) or f"demo {i}"
        if progress is not None:
            progress(i, len(demos), name)
        t = np.asarray(demo.times_100hz, dtype=float)
        target = np.array(demo.X_OE_100hz, dtype=float)
        target[:, 3:] = make_quaternions_continuous(target[:, 3:], reference=dmp.y0[3:])
        failures = []

        def execute(candidate, demo=demo, target=target, failures=failures):
            imitation = imitator.imitate(candidate, demo)
            if imitation.failed:
                failures.append(imitation.reason)
                return np.full_like(target, np.nan)
            return _same_hemisphere(imitation.X_OE_demo_grid, target)

        result = refine_for_tracking(lambda c, t=t: fit_dmp(t, c, config), execute, t, target, iterations)
        dmps.append(result.dmp)
        report.append({"demo": str(name), "errors_mm": [round(e, 3) for e in result.errors_mm],
                       "kept_plain": bool(result.kept_plain), "failures": failures})
    skill.dmps = dmps
    skill.info["dmp_refinement"] = report
    return report


def refinement_lines(report: list[dict]) -> tuple[list[str], list[str]]:
    """``(lines, warnings)`` for ``drake-skill fit``: each DMP's executed error before and after."""
    lines, warnings = [], []
    for r in report:
        errors = r["errors_mm"]
        if r["kept_plain"]:
            why = f" (the imitation failed: {', '.join(r['failures'])})" if r["failures"] else ""
            warnings.append(f"{r['demo']}: refining its DMP on the simulated station did not bring the imitation "
                            f"closer than the plain fit's {errors[0]:.1f} mm RMS{why}; the plain fit is kept")
        else:
            best = min(errors)
            lines.append(f"  {r['demo']}: imitation {errors[0]:.1f} -> {best:.1f} mm RMS from the demonstration "
                         "after refinement on the simulated station")
    return lines, warnings
