"""PoWER (thesis 3.4.1) and the PI^2 family (thesis 3.4.2-3.4.3, 5.2)."""

from __future__ import annotations

import numpy as np

from drake_skill.learning.policy_search.checks import _check_int
from drake_skill.learning.policy_search.gaussian import _PI2Adaptive, _PI2Scheduled, _ScheduledSearch


class PoWER(_ScheduledSearch):
    """Black-box PoWER (thesis section 3.4.1, Eq. 3.25-3.26).

    Every rollout told is kept (the importance-sampling memory). After each
    episode, with ``k`` over the ``n_best`` (``r``, default 6) rollouts of
    highest return seen so far (ties: the earlier rollout first)::

        theta <- theta + sum_k (theta_k - theta) R_k / sum_k R_k

    i.e. the return-weighted mean of the best ``r`` rollouts. Returns must be
    non-negative (use a transform fixed over the whole run, e.g.
    ``exp(-cost)``); when the best ``r`` returns are all zero, as sparse
    rewards often give early on, the mean is not changed. Exploration:
    ``N(w_b, sigma_e Sigma_b^0)`` with the Eq. 5.4 schedule. Thesis budget:
    one rollout per episode, ``E = 30`` (docs/method.md section 5).

    Extra args:
        n_best: number ``r`` of best rollouts in the update.
        sigma0, decay_start: see :func:`sigma_schedule`.
    """

    name = "power"
    default_n_episodes = 30

    def __init__(self, mean, covariances, *, n_episodes=None, n_best=6,
                 sigma0=1.0, decay_start=None, seed=None):
        super().__init__(mean, covariances, n_episodes=n_episodes,
                         sigma0=sigma0, decay_start=decay_start, seed=seed)
        self._n_best = _check_int("n_best", n_best, minimum=1)
        self._memory_samples = np.zeros((0, self.n_bases, self.n_dims))
        self._memory_returns = np.zeros(0)

    @property
    def memory(self) -> tuple[np.ndarray, np.ndarray]:
        """All rollouts told so far: weights ``(K, B, D)``, returns ``(K,)``."""
        return self._memory_samples.copy(), self._memory_returns.copy()

    def _check_results(self, results, n):
        results = super()._check_results(results, n)
        if (results < 0).any():
            worst = int(np.argmin(results))
            raise ValueError(
                f"PoWER needs non-negative returns; got {float(results[worst])!r} at "
                f"rollout {worst}. Map returns to >= 0 with a transform fixed "
                "for the whole run (e.g. exp(-cost)), not a per-episode shift")
        return results

    def _tell(self, samples, results):
        self._memory_samples = np.concatenate([self._memory_samples, samples])
        self._memory_returns = np.concatenate([self._memory_returns, results])
        best = np.argsort(-self._memory_returns, kind="stable")[:self._n_best]
        returns = self._memory_returns[best]
        total = returns.sum()
        if total <= 0:
            return
        step = np.einsum("k,kbd->bd", returns,
                         self._memory_samples[best] - self._mean) / total
        self._mean = self._mean + step

    def _options(self):
        return {**super()._options(), "n_best": self._n_best}

    def _state(self):
        return {**super()._state(),
                "memory_samples": self._memory_samples.copy(),
                "memory_returns": self._memory_returns.copy()}

    def _restore(self, state):
        super()._restore(state)
        samples = np.asarray(state["memory_samples"], dtype=float).reshape(
            -1, self.n_bases, self.n_dims)
        returns = np.asarray(state["memory_returns"], dtype=float).reshape(-1)
        if len(samples) != len(returns):
            raise ValueError(
                f"memory_samples {samples.shape} and memory_returns "
                f"{returns.shape} disagree on the number of rollouts")
        self._memory_samples, self._memory_returns = samples, returns


class PI2ES(_PI2Scheduled):
    """Black-box PI^2-ES (thesis section 5.2, Eq. 5.1-5.4).

    ``P_c`` from the episode's returns (``weighting="thesis"``: Eq. 5.1,
    ``exp(R_c / C)``; ``"range"``: ``exp(h (R_c - min) / (max - min))``),
    ``w_b <- sum_c P_c w_b^c`` (Eq. 5.2), sampling
    ``N(w_b, sigma_e Sigma_b^0)`` (Eq. 5.3) with the Eq. 5.4 schedule.
    """

    name = "pi2-es"
    default_weighting = "thesis"


class PI2(_PI2Scheduled):
    """PI^2 with per-step rewards (thesis section 3.4.2, Eq. 3.27-3.29).

    ``results`` are per-step rewards ``(C, T)``; ``P_{t,c}`` from the
    reward-to-go at each step (``weighting="range"`` by default: lambda from
    the range of ``G`` at that step), per-step estimates averaged over time
    with weights ``T - t`` (see :func:`rollout_probabilities` and the module
    docstring for the constant-exploration simplification). Sampling
    ``N(w_b, sigma_e Sigma_b^0)`` with the Eq. 5.4 schedule.
    """

    name = "pi2"
    per_step = True
    default_weighting = "range"


class PI2ESCov(_PI2Adaptive):
    """PI^2-ES-Cov (thesis section 5.2, Eq. 5.1, 5.2, 5.5, 5.6).

    PI^2-ES's mean update plus the covariance update
    ``Sigma_b = sum_c P_c (w_b^c - w_b)(w_b^c - w_b)^T`` around the mean the
    episode was sampled from, with an eigenvalue floor; sampling
    ``N(w_b, Sigma_b)``, no sigma schedule. Default weighting ``"thesis"``
    (Eq. 5.1).
    """

    name = "pi2-es-cov"
    default_weighting = "thesis"


class PI2Cov(_PI2Adaptive):
    """PI^2-Cov with per-step rewards (thesis section 3.4.3, Eq. 3.30-3.31).

    PI^2's time-averaged probabilities (default ``weighting="range"``) for
    both the mean and the covariance update (around the mean the episode
    was sampled from), with the eigenvalue floor of PI^2-ES-Cov; no sigma
    schedule.
    """

    name = "pi2-cov"
    per_step = True
    default_weighting = "range"
