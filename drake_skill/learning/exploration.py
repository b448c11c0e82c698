"""Exploration in the span of the demonstrations: what policy search varies (docs/method.md 5.2).

The thesis samples every basis's weights w_b independently around the mean,
from Sigma_b^0 (Eq. 5.3): noise that no demonstration shows, uncorrelated
from one basis to the next. Measured on Open (3 demonstrations, 100 bases,
200 samples): at the moment the finger sits under the lid's lip, the shipped
Sigma_b^0 x 0.1 moves the hand 8.5 / 8.2 mm (median; 90th percentile 19 /
20 mm) across and up, directions the three demonstrations agree on within
2-5 mm, and 3 of 8 such rollouts pushed the hand into the box and tripped
the collision reflex (30 N); the demonstrations differ there along the lip
(x, up to 31 mm), which is safe.

``exploration: span`` (:class:`SpanExploration`) searches instead over the
coordinates theta (k = N - 1 of them, N demonstrations) of the affine span
of the demonstrations' DMP weights through the initial one::

    W(theta) = W_0 + sum_d theta_d (W_d - W_0),   d over the other demonstrations

so every sample is a blend or an extrapolation of what was demonstrated,
with the bases varying together as they do between demonstrations. At the
same overall size of motion (median largest deviation 54 mm) the hand moves
3.4 / 4.0 mm across and up under the lip (90th percentile 8.5 / 10 mm). The
search's initial covariance is the demonstrations' own in these coordinates
(W_0 at 0, W_d at the unit vectors), times the exploration scale (default 1,
thesis Eq. 5.3's sigma_0). The cost: nothing outside the span can be
learned. A skill whose success lies further along the demonstrated change
(further open, further pushed: "at least as far as I showed") is inside it;
a correction none of the demonstrations shows is not.

``approach_exploration`` (:func:`approach_covariance`, docs/method.md 5.4)
keeps the basis search but scales Sigma_b^0 by a factor for every basis
that moves the hand before the demonstrations first touch the object:
where they agree to the millimetre, the samples stay on the demonstrated
approach, and the search explores what happens in contact and after.
"""

from __future__ import annotations

import numpy as np

__all__ = ["APPROACH_MARGIN_S", "EXPLORATIONS", "SpanExploration", "approach_covariance", "first_contact_time",
           "skill_covariance"]

#: ``LearnConfig.exploration``: "basis" (thesis Eq. 5.3: Sigma_b^0 per basis) or "span" (this module).
EXPLORATIONS = ("basis", "span")


#: ``LearnConfig.approach_exploration`` quiets the bases centred up to this long after the
#: demonstrations' first contact [s]: the contact mask starts CONTACT_DILATE_S (0.2 s) before the
#: object moves, and a basis moves the hand for about its own width (0.1-0.2 s) after its centre.
APPROACH_MARGIN_S = 0.4


def first_contact_time(skill) -> float | None:
    """When the demonstrations first touch the object, on the initial DMP's clock [s]: the start of
    the earliest demonstration's contact mask (``drake_skill.action.metrics.contact_mask``: the
    object moving, widened by 0.2 s), recovered from the fit's ``DmpConfig.start_join`` (that start
    as a fraction of the duration, times ``START_JOIN_FRACTION``). None when the fit has none (no
    demonstration moved the object, or the thesis fit)."""
    from drake_skill.fitted_skill import START_JOIN_FRACTION

    join = float(getattr(skill.config.dmp, "start_join", 0.0) or 0.0)
    if join <= 0.0:
        return None
    return join / START_JOIN_FRACTION * float(skill.dmps[skill.initial_index].tau)


def approach_covariance(sigma0, tau: float, first_contact: float | None, factor: float,
                        margin: float = APPROACH_MARGIN_S) -> np.ndarray:
    """Sigma_b^0 (B, d, d) with every basis centred at or before ``first_contact + margin`` [s]
    scaled by ``factor`` (docs/method.md 5.4); the centres lie at t_b = b tau / (B - 1) [s]
    (``drake_skill.action.dmp.basis_centres_widths``: equally spaced in time over [0, tau]).

    The hand's position at time t integrates the forcing term of every earlier basis (the
    transformation system's spring, sqrt(K) / tau ~ 1 rad/s, forgets slowly), so the whole
    approach is quieted, not only the bases at the touch. ``first_contact`` None or ``factor`` 1:
    Sigma_b^0 unchanged.
    """
    sigma0 = np.asarray(sigma0, dtype=float)
    if first_contact is None or factor == 1.0:
        return sigma0.copy()
    centres = np.linspace(0.0, float(tau), sigma0.shape[0])
    scale = np.where(centres <= float(first_contact) + float(margin), float(factor), 1.0)
    return sigma0 * scale[:, None, None]


def skill_covariance(skill, approach_exploration: float = 1.0) -> np.ndarray:
    """A fitted skill's Sigma_b^0 as the basis search starts from it: :func:`approach_covariance`
    on its initial DMP's clock and first contact (``learn`` and ``evaluate --explore`` alike)."""
    return approach_covariance(skill.sigma0, skill.dmps[skill.initial_index].tau, first_contact_time(skill),
                               approach_exploration)


class SpanExploration:
    """The map theta (1, k) -> W (B, D) onto the demonstrations' span, and its initial covariance.

    directions: (k, B, D) = W_d - W_0 for every demonstration d but the initial one.
    """

    def __init__(self, initial_weights, other_weights, ridge: float = 1e-3):
        self.origin = np.asarray(initial_weights, dtype=float)
        other_weights = list(other_weights)
        if not other_weights:
            raise ValueError("exploration span: needs at least 2 demonstrations (one DMP each); this skill has 1; "
                             "use exploration basis, or record another demonstration")
        self.directions = np.stack([np.asarray(w, dtype=float) - self.origin for w in other_weights])
        self.ridge = float(ridge)

    @classmethod
    def of_skill(cls, skill) -> "SpanExploration":
        """The span of a fitted :class:`~drake_skill.fitted_skill.Skill`'s DMPs through its initial one."""
        others = [d.weights for i, d in enumerate(skill.dmps) if i != skill.initial_index]
        return cls(skill.initial_weights, others)

    @property
    def dim(self) -> int:
        return int(self.directions.shape[0])

    def origin_theta(self) -> np.ndarray:
        """theta of W_0: zeros (1, k)."""
        return np.zeros((1, self.dim))

    def initial_covariance(self) -> np.ndarray:
        """(1, k, k): the sample covariance (ddof 1) of the demonstrations' coordinates (0 and the unit
        vectors) plus ``ridge`` I, so that it is positive definite."""
        points = np.vstack([np.zeros(self.dim), np.eye(self.dim)])
        cov = np.atleast_2d(np.cov(points, rowvar=False, ddof=1)) + self.ridge * np.eye(self.dim)
        return cov[None]

    def weights(self, theta) -> np.ndarray:
        """W (B, D) of theta (1, k), or (S, B, D) of a batch (S, 1, k)."""
        theta = np.asarray(theta, dtype=float)
        flat = theta.reshape(-1, self.dim)
        out = self.origin + np.einsum("sk,kbd->sbd", flat, self.directions)
        return out[0] if theta.ndim == 2 else out
