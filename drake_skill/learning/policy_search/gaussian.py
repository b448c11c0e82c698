"""Gaussian exploration per basis (thesis Eq. 3.24, 5.3), with the Eq. 5.4 schedule or an
adapted covariance (Eq. 3.30-3.31, 5.5), shared by PoWER and the PI^2 family."""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from drake_skill.learning.policy_search.base import PolicySearch
from drake_skill.learning.policy_search.checks import _check_covariances, _check_float, _check_mean, _symmetrise
from drake_skill.learning.policy_search.weighting import rollout_probabilities, sigma_schedule, WEIGHTINGS


class _GaussianSearch(PolicySearch):
    """Samples ``w_b^c = w_b + sqrt(s) L_b z``, ``Sigma_b = L_b L_b^T``."""

    def __init__(self, mean, covariances, *, n_episodes=None, seed=None):
        super().__init__(mean, covariances, n_episodes=n_episodes, seed=seed)
        self._mean = self._initial_mean.copy()
        self._covariances = self._initial_covariances.copy()
        self._cholesky = self._initial_cholesky.copy()

    @property
    def mean(self) -> np.ndarray:
        return self._mean.copy()

    @property
    def covariances(self) -> np.ndarray:
        return self._covariances.copy()

    @property
    def sigma(self) -> float:
        return 1.0

    def _ask(self, n: int) -> np.ndarray:
        z = self._rng.standard_normal((n, self.n_bases, self.n_dims))
        noise = np.einsum("bij,nbj->nbi", self._cholesky, z)
        return self._mean + np.sqrt(self.sigma) * noise

    def _set_covariances(self, covariances: np.ndarray) -> None:
        self._covariances, self._cholesky = _check_covariances(
            covariances, self._initial_mean.shape, name="covariances")

    def _state(self) -> dict[str, Any]:
        return {"mean": self._mean.copy(),
                "covariances": self._covariances.copy()}

    def _restore(self, state: dict[str, Any]) -> None:
        super()._restore(state)
        self._mean = _check_mean(state["mean"])
        self._set_covariances(state["covariances"])


class _ScheduledSearch(_GaussianSearch):
    """Fixed covariances ``Sigma_b^0`` scaled by the Eq. 5.4 schedule.

    Samples ``w_b^c ~ N(w_b, sigma_e Sigma_b^0)`` (thesis Eq. 5.3) with
    ``sigma_e = sigma_schedule(episode, n_episodes, sigma0, decay_start)``.
    """

    def __init__(self, mean, covariances, *, n_episodes=None, sigma0=1.0,
                 decay_start=None, seed=None):
        super().__init__(mean, covariances, n_episodes=n_episodes, seed=seed)
        self._sigma0 = _check_float("sigma0", sigma0, positive=True)
        self._decay_start = (self._n_episodes / 4.0 if decay_start is None
                             else _check_float("decay_start", decay_start,
                                               non_negative=True))

    @property
    def sigma(self) -> float:
        """``sigma_e`` of thesis Eq. 5.4 for the episode about to be sampled."""
        return sigma_schedule(self._episode, self._n_episodes, self._sigma0,
                              self._decay_start)

    def _options(self) -> dict[str, Any]:
        return {**super()._options(), "sigma0": self._sigma0,
                "decay_start": self._decay_start}


class _WeightingMixin:
    """Rollout probabilities (:func:`rollout_probabilities`)."""

    default_weighting: ClassVar[str] = "thesis"
    per_step: ClassVar[bool]

    def _init_weighting(self, weighting: str | None, h: float) -> None:
        weighting = self.default_weighting if weighting is None else weighting
        if weighting not in WEIGHTINGS:
            raise ValueError(
                f"weighting must be one of {WEIGHTINGS}; got {weighting!r}")
        self._weighting = weighting
        self._h = _check_float("h", h, positive=True)

    def _probabilities(self, results: np.ndarray) -> np.ndarray:
        return rollout_probabilities(results, weighting=self._weighting,
                                     h=self._h, per_step=self.per_step)

    def _weighting_options(self) -> dict[str, Any]:
        return {"weighting": self._weighting, "h": self._h}


class _PI2Scheduled(_WeightingMixin, _ScheduledSearch):
    """PI^2 / PI^2-ES mean update with the sigma schedule.

    ``w_b <- sum_c P_c w_b^c`` (thesis Eq. 5.2; Eq. 3.28-3.29 per step), with
    ``P_c`` from :func:`rollout_probabilities`.
    """

    def __init__(self, mean, covariances, *, n_episodes=None, weighting=None,
                 h=10.0, sigma0=1.0, decay_start=None, seed=None):
        super().__init__(mean, covariances, n_episodes=n_episodes,
                         sigma0=sigma0, decay_start=decay_start, seed=seed)
        self._init_weighting(weighting, h)

    def _tell(self, samples, results):
        p = self._probabilities(results)
        self._mean = np.einsum("c,cbd->bd", p, samples)

    def _options(self):
        return {**super()._options(), **self._weighting_options()}


class _PI2Adaptive(_WeightingMixin, _GaussianSearch):
    """PI^2-Cov / PI^2-ES-Cov: mean and covariance updates, eigenvalue floor.

    With ``w_b`` the mean the episode was sampled from::

        w_b'    = sum_c P_c w_b^c                                 (Eq. 5.2)
        Sigma_b = sum_c P_c (w_b^c - w_b)(w_b^c - w_b)^T          (Eq. 5.5)

    (thesis section 5.2; per step, Eq. 3.30-3.31 with the time-averaged
    ``P_c``). No sigma schedule: ``sigma`` is 1.

    Eigenvalue floor: with ``Sigma_b^0 = L_b L_b^T``, every eigenvalue of
    the whitened covariance ``L_b^{-1} Sigma_b L_b^{-T}`` is raised to at
    least ``floor_fraction``, i.e. ``Sigma_b >= floor_fraction * Sigma_b^0``
    in the Loewner order: each direction keeps at least that fraction of its
    initial variance. The floor follows ``Sigma_b^0``'s shape, so it never
    inflates a direction the demonstrations left narrow (a floor on
    ``trace / D`` would, when position and quaternion weights differ in
    scale). Then, if ``min_eigenvalue > 0``, the plain eigenvalues are raised
    to at least ``min_eigenvalue``. Blocks already above the floor are left
    untouched. The floor is what keeps exploration alive when the weighting
    puts nearly all weight on one rollout and the update is rank one
    (docs/method.md section 5).
    """

    def __init__(self, mean, covariances, *, n_episodes=None, weighting=None,
                 h=10.0, floor_fraction=1e-2, min_eigenvalue=0.0, seed=None):
        super().__init__(mean, covariances, n_episodes=n_episodes, seed=seed)
        self._init_weighting(weighting, h)
        self._floor_fraction = _check_float("floor_fraction", floor_fraction,
                                            non_negative=True)
        self._min_eigenvalue = _check_float("min_eigenvalue", min_eigenvalue,
                                            non_negative=True)
        if self._floor_fraction == 0 and self._min_eigenvalue == 0:
            raise ValueError(
                "floor_fraction and min_eigenvalue are both 0: the covariance "
                "update can collapse to a singular matrix; set floor_fraction "
                "> 0 (default 1e-2) or min_eigenvalue > 0")
        if self._floor_fraction > 1:
            raise ValueError(
                f"floor_fraction must be in [0, 1]; got {self._floor_fraction}")

    def _tell(self, samples, results):
        p = self._probabilities(results)
        deviations = samples - self._mean
        self._mean = np.einsum("c,cbd->bd", p, samples)
        covariances = np.einsum("c,cbi,cbj->bij", p, deviations, deviations)
        self._set_covariances(self._floor(covariances))

    def _floor(self, covariances: np.ndarray) -> np.ndarray:
        covariances = _symmetrise(covariances)
        lower = self._initial_cholesky
        if self._floor_fraction > 0:
            left = np.linalg.solve(lower, covariances)           # L^-1 S
            white = _symmetrise(np.linalg.solve(
                lower, np.swapaxes(left, 1, 2)))                 # L^-1 S L^-T
            values, vectors = np.linalg.eigh(white)
            low = values.min(axis=1) < self._floor_fraction
            if low.any():
                values = np.maximum(values[low], self._floor_fraction)
                white = np.einsum("bij,bj,bkj->bik", vectors[low], values,
                                  vectors[low])
                covariances[low] = _symmetrise(
                    lower[low] @ white @ np.swapaxes(lower[low], 1, 2))
        if self._min_eigenvalue > 0:
            values, vectors = np.linalg.eigh(covariances)
            low = values.min(axis=1) < self._min_eigenvalue
            if low.any():
                values = np.maximum(values[low], self._min_eigenvalue)
                covariances[low] = _symmetrise(np.einsum(
                    "bij,bj,bkj->bik", vectors[low], values, vectors[low]))
        return covariances

    def _options(self):
        return {**super()._options(), **self._weighting_options(),
                "floor_fraction": self._floor_fraction,
                "min_eigenvalue": self._min_eigenvalue}
