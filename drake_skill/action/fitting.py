"""How well a DMP reproduces its demonstration, and the number of bases chosen from that.

Plain numpy, no Drake (docs/method.md section 2.2). The DMP itself is
``drake_skill.action.dmp``; this module measures a fit and chooses B:

- **fit error** (:func:`fit_errors`): the DMP integrated alone from the
  demonstration's start, at the demonstration's own times, against the
  demonstration's positions::

      e(t) = | y_dmp(t)[:3] - y_demo(t)[:3] |          [mm]

  reported as ``max_t e``, ``sqrt(mean_t e^2)`` (RMS) and ``max e`` over the
  samples *near contact*;
- **near contact** (:func:`drake_skill.action.metrics.contact_mask`): the
  samples where the object's joint moves, ``|ds/dt| > CONTACT_FRACTION *
  max |ds/dt|``, widened by ``CONTACT_DILATE_S`` on either side (the hand
  touches the object a little before the joint starts to move and after it
  stops);
- **B from a tolerance** (:func:`choose_n_basis`): the smallest B of
  :data:`BASIS_LADDER` (up to a cap and the number of samples) whose fits of
  every demonstration meet :class:`FitTolerance` (2 mm max near contact,
  3 mm RMS by default). The fit error falls with B once the data start at
  rest (docs/method.md section 2.2 has the measured table); it is not
  strictly monotone, so the ladder is walked upward rather than bisected.
"""

# No ``from __future__ import annotations``: yaml_load_typed reads the field types.
import dataclasses as dc
import math
from typing import Sequence

import numpy as np

from drake_skill.action.dmp import Dmp, DmpConfig, integrate
# The one near-contact rule, shared with drake-skill bench imitation.
from drake_skill.action.metrics import CONTACT_DILATE_S, CONTACT_FRACTION, contact_mask, position_errors_mm

__all__ = ["BASIS_LADDER", "CONTACT_DILATE_S", "CONTACT_FRACTION", "BasisChoice", "FitError",
           "FitTolerance", "Refinement", "choose_n_basis", "contact_mask", "fit_errors", "refine_for_tracking"]

#: The numbers of bases tried, in order (section 2.2); capped by ``FitTolerance.max_bases``.
BASIS_LADDER = (10, 15, 20, 25, 30, 40, 50, 60, 70, 85, 100)


@dc.dataclass
class FitTolerance:
    """How closely the integrated DMP must follow its demonstration (section 2.2).

    contact_max_mm: largest position error near contact [mm].
    rms_mm: RMS position error over the whole demonstration [mm].
    max_bases: the most bases tried (also capped by the samples of the shortest demonstration).
    """

    contact_max_mm: float = 2.0
    rms_mm: float = 3.0
    max_bases: int = 100

    def validate(self) -> "FitTolerance":
        """Raises ValueError naming the first bad field; returns self."""
        for name in ("contact_max_mm", "rms_mm"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"FitTolerance.{name}: expected a finite value > 0 mm, got {v!r}")
        if not (isinstance(self.max_bases, int) and 2 <= self.max_bases):
            raise ValueError(f"FitTolerance.max_bases: expected an integer >= 2, got {self.max_bases!r}")
        return self

    def met_by(self, error: "FitError") -> bool:
        return error.rms_mm <= self.rms_mm and error.contact_max_mm <= self.contact_max_mm


@dc.dataclass(frozen=True)
class FitError:
    """Position error of one fitted DMP against its demonstration [mm] (module docstring)."""

    max_mm: float
    rms_mm: float
    contact_max_mm: float
    #: Samples near contact (0: the demonstration never moves the object).
    contact_samples: int

    def as_dict(self) -> dict:
        return {"fit_max_mm": round(self.max_mm, 3), "fit_rms_mm": round(self.rms_mm, 3),
                "fit_contact_max_mm": round(self.contact_max_mm, 3), "contact_samples": self.contact_samples}


@dc.dataclass
class BasisChoice:
    """Result of :func:`choose_n_basis`: the chosen B, each demonstration's error at it, and
    whether it meets the tolerance."""

    n_basis: int
    errors: list
    met: bool
    #: (B, worst FitError) for every B tried, in order.
    tried: list


def fit_errors(dmp: Dmp, config: DmpConfig, times, poses, mask=None) -> FitError:
    """Fit error of ``dmp`` against the demonstration ``(times (T,) s, poses (T, 7))`` (module docstring).

    ``mask``: (T,) bool samples near contact (:func:`contact_mask`), or None.
    """
    t = np.asarray(times, dtype=float)
    path = integrate(dmp, config, times=t - t[0])
    worst, rms = position_errors_mm(path, poses)
    m = np.zeros(t.size, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    contact = position_errors_mm(path, poses, m)[0] if m.any() else 0.0
    return FitError(max_mm=worst, rms_mm=rms, contact_max_mm=contact, contact_samples=int(m.sum()))


def _worst(errors: Sequence[FitError]) -> FitError:
    return FitError(max_mm=max(e.max_mm for e in errors), rms_mm=max(e.rms_mm for e in errors),
                    contact_max_mm=max(e.contact_max_mm for e in errors),
                    contact_samples=min(e.contact_samples for e in errors))


def choose_n_basis(fit, demonstrations: Sequence[tuple], masks: Sequence, tolerance: FitTolerance,
                   ladder: Sequence[int] = BASIS_LADDER) -> BasisChoice:
    """The smallest B of ``ladder`` whose fits of every demonstration meet ``tolerance``.

    ``fit(n_basis) -> (dmps, config)`` fits all demonstrations with B bases
    (the caller's fit, e.g. ``fit_demonstrations`` with that ``n_basis``);
    ``demonstrations``: ``(times (T,), poses (T, 7))`` per demonstration, as
    fitted; ``masks``: (T,) near-contact samples of each. B is capped by
    ``tolerance.max_bases`` and by the samples of the shortest demonstration.
    When no B meets the tolerance, the one with the smallest worst error
    (near contact, then RMS) is returned with ``met = False``: the caller
    says so with the best error reached.
    """
    tolerance.validate()
    cap = min(int(tolerance.max_bases), min(len(t) for t, _ in demonstrations))
    candidates = [b for b in ladder if b <= cap] or [cap]
    tried, best = [], None
    for n in candidates:
        dmps, config = fit(n)
        errors = [fit_errors(d, config, t, p, m) for d, (t, p), m in zip(dmps, demonstrations, masks)]
        worst = _worst(errors)
        tried.append((n, worst))
        if best is None or (worst.contact_max_mm, worst.rms_mm) < (best[1].contact_max_mm, best[1].rms_mm):
            best = (n, worst, errors)
        if tolerance.met_by(worst):
            return BasisChoice(n_basis=n, errors=errors, met=True, tried=tried)
    return BasisChoice(n_basis=best[0], errors=best[2], met=False, tried=tried)


@dc.dataclass
class Refinement:
    """Result of :func:`refine_for_tracking`.

    dmp: the DMP to execute (the refined one, or the plain fit when refining did not help);
    errors_mm: RMS position error of the executed path against the target after each
      execution (index 0: the plain fit) [mm];
    kept_plain: True when no refinement beat the plain fit (it diverged or did not help).
    """

    dmp: Dmp
    errors_mm: list
    kept_plain: bool


def refine_for_tracking(fit, execute, times, target, iterations: int = 1, gain: float = 1.0) -> Refinement:
    """Refits a DMP so that the *executed* path, not the commanded one, follows ``target``.

    An imitation copies the station's lag and load offset onto the measured
    path a demonstration already holds (docs/method.md section 2.3). One step
    of iterative learning control on the whole path removes it::

        c_0 = target,   c_{k+1} = c_k + gain (target - m_k),   m_k = execute(fit(c_k))

    ``fit(poses (T, 7)) -> Dmp`` fits the commanded path on ``times`` (T,) s;
    ``execute(dmp) -> (T, 7)`` runs it (the simulated station, or a model of
    it) and returns the measured path on the same times; ``target`` (T, 7) is
    the demonstration's recorded path. Quaternions of a corrected command are
    renormalised. The refinement whose executed path is closest to the target
    (RMS of the position error) is returned; when none beats the plain fit,
    the plain fit is kept and ``kept_plain`` says so.
    """
    if not (isinstance(iterations, int) and iterations >= 0):
        raise ValueError(f"iterations: expected an integer >= 0, got {iterations!r}")
    if not (math.isfinite(gain) and 0 < gain <= 2):
        raise ValueError(f"gain: expected a value in (0, 2], got {gain!r}")
    target = np.asarray(target, dtype=float)
    command = target.copy()
    dmps, errors = [fit(command)], []
    for k in range(iterations + 1):
        measured = np.asarray(execute(dmps[-1]), dtype=float)
        if not np.all(np.isfinite(measured)):
            errors.append(math.inf)   # the execution failed: no correction from it
            break
        errors.append(position_errors_mm(measured, target)[1])
        if k == iterations:
            break
        command = command + gain * (target - measured)
        command[:, 3:] /= np.linalg.norm(command[:, 3:], axis=1, keepdims=True)
        dmps.append(fit(command))
    best = int(np.argmin(errors))
    return Refinement(dmp=dmps[best], errors_mm=errors, kept_plain=best == 0)
