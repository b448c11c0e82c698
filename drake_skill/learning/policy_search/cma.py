"""CMA-ES from the ``cma`` package as a baseline, in coordinates whitened by Sigma0."""

from __future__ import annotations

import numpy as np

from drake_skill.learning.policy_search.base import PolicySearch
from drake_skill.learning.policy_search.checks import (_check_float, _check_int, _rng_from_json, _rng_state_json,
                                                       _symmetrise)


class CMAES(PolicySearch):
    """CMA-ES baseline (``cma.CMAEvolutionStrategy``) in whitened coordinates.

    The search runs on ``z`` with ``vec(W) = vec(W0) + L z``, ``L`` the
    block-diagonal Cholesky factor of ``Sigma0`` (one ``L_b`` per basis), so
    CMA-ES starts from ``N(W0, sigma0^2 Sigma0)`` and minimises ``-R``. The
    population size is ``popsize`` or, when ``None``, the ``n`` of the first
    :meth:`ask`; every ask must then use it, and each ask must be followed
    by the :meth:`tell` of its samples. Normal draws come from this object's
    generator (``cma``'s ``randn`` option), not from numpy's global state.

    ``mean`` is the CMA-ES mean mapped back to weights. CMA-ES adapts a full
    covariance over all ``B * D`` weights; ``covariances`` reports its
    per-basis ``D x D`` blocks of ``L C L^T`` (``C`` the covariance shape
    matrix) and ``sigma`` the squared step size, so that
    ``sampling_covariances`` are the blocks of the sampling distribution's
    covariance; :attr:`step_size` is CMA-ES's own sigma.

    State: ``cma`` objects are not serialised (that would need pickling).
    The state keeps the generator's initial state and the returns told per
    episode; restoring replays the same asks and tells, which reproduces
    the run exactly with the same ``cma`` version (checked on the mean and
    the generator state).

    Extra args:
        sigma0: initial CMA-ES step size in whitened coordinates (a standard
            deviation scale: 1 samples from ``Sigma0``).
        popsize: rollouts per episode, or ``None`` for the first ask's ``n``.
    """

    name = "cma-es"

    def __init__(self, mean, covariances, *, n_episodes=None, sigma0=1.0,
                 popsize=None, seed=None):
        super().__init__(mean, covariances, n_episodes=n_episodes, seed=seed)
        try:
            import cma
        except ImportError as error:  # pragma: no cover - depends on env
            raise ImportError(
                "the 'cma-es' method needs the cma package: pip install cma"
            ) from error
        self._cma = cma
        self._sigma0 = _check_float("sigma0", sigma0, positive=True)
        self._popsize = (None if popsize is None else
                         _check_int("popsize", popsize, minimum=2))
        self._initial_rng_state = _rng_state_json(self._rng)
        self._es = None
        self._pending: tuple[np.ndarray, np.ndarray] | None = None
        self._history: list[np.ndarray] = []

    @property
    def step_size(self) -> float:
        """CMA-ES's step size (standard-deviation scale, whitened)."""
        return self._sigma0 if self._es is None else float(self._es.sigma)

    @property
    def popsize(self) -> int | None:
        """Rollouts per episode (``None`` until set by the first ask)."""
        return self._popsize

    @property
    def mean(self) -> np.ndarray:
        if self._es is None:
            return self._initial_mean.copy()
        return self._to_weights(np.asarray(self._es.mean, dtype=float)[None])[0]

    @property
    def covariances(self) -> np.ndarray:
        if self._es is None:
            return self._initial_covariances.copy()
        b, d = self.n_bases, self.n_dims
        scaling = np.broadcast_to(
            np.asarray(self._es.sigma_vec.scaling, dtype=float), (b * d,))
        shape = np.asarray(self._es.C, dtype=float) * np.outer(scaling, scaling)
        blocks = np.stack([shape[i * d:(i + 1) * d, i * d:(i + 1) * d]
                           for i in range(b)])
        lower = self._initial_cholesky
        return _symmetrise(lower @ blocks @ np.swapaxes(lower, 1, 2))

    @property
    def sigma(self) -> float:
        """Squared step size: sampling covariance blocks are ``sigma * Sigma_b``."""
        return self.step_size ** 2

    def _to_weights(self, z: np.ndarray) -> np.ndarray:
        z = z.reshape(len(z), self.n_bases, self.n_dims)
        return self._initial_mean + np.einsum(
            "bij,nbj->nbi", self._initial_cholesky, z)

    def _make_es(self, popsize: int):
        rng = self._rng

        def randn(*shape):
            return rng.standard_normal(shape)

        options = {"popsize": popsize, "randn": randn, "seed": np.nan,
                   "verbose": -9, "verb_disp": 0, "verb_log": 0,
                   "verb_time": False}
        return self._cma.CMAEvolutionStrategy(
            np.zeros(self.n_bases * self.n_dims), self._sigma0, options)

    def _ask(self, n):
        if self._pending is not None:
            raise RuntimeError(
                "cma-es: tell() the samples of the previous ask() before "
                "asking again")
        if self._popsize is None:
            self._popsize = n
        if n != self._popsize:
            raise ValueError(
                f"cma-es samples a fixed population: n must be popsize = "
                f"{self._popsize}; got {n}")
        if self._es is None:
            self._es = self._make_es(self._popsize)
        z = np.asarray(self._es.ask(), dtype=float)
        samples = self._to_weights(z)
        self._pending = (z, samples)
        return samples.copy()

    def _tell(self, samples, results):
        if self._pending is None:
            raise RuntimeError("cma-es: tell() needs the samples of an ask()")
        z, asked = self._pending
        if not np.array_equal(samples, asked):
            raise ValueError(
                "cma-es: samples must be exactly those of the last ask(), in "
                "the same order")
        self._es.tell(list(z), (-results).tolist())
        self._history.append(results.copy())
        self._pending = None

    def _options(self):
        return {**super()._options(), "sigma0": self._sigma0,
                "popsize": 0 if self._popsize is None else self._popsize}

    @classmethod
    def _options_from_state(cls, options):
        options = dict(options)
        if options.get("popsize") in (0, None):
            options["popsize"] = None
        return options

    def _state(self):
        width = self._popsize or 0
        history = (np.stack(self._history) if self._history
                   else np.zeros((0, width)))
        return {"initial_rng_state": self._initial_rng_state,
                "history_returns": history,
                "pending": int(self._pending is not None),
                "mean": self.mean,
                "cma_version": str(self._cma.__version__)}

    def _restore(self, state):
        self._rng = _rng_from_json(state["initial_rng_state"])
        self._initial_rng_state = str(state["initial_rng_state"])
        history = np.asarray(state["history_returns"], dtype=float)
        if history.ndim != 2:
            raise ValueError(
                "cma-es: history_returns must be (episodes, popsize); got "
                f"shape {history.shape}")
        # No reshape: a state saved before the first tell has shape (0, popsize).
        for returns in history:
            self.tell(self.ask(len(returns)), returns)
        if int(state["pending"]):
            self.ask(self._popsize)
        if (self._episode != int(state["episode"])
                or not np.array_equal(self.mean, np.asarray(state["mean"]))
                or _rng_state_json(self._rng) != str(state["rng_state"])):
            raise RuntimeError(
                "cma-es: replaying the saved history did not reproduce the "
                f"saved state (saved with cma {state.get('cma_version')}, "
                f"running cma {self._cma.__version__})")
