"""The ask/tell interface every method shares, its checks and its state I/O."""

from __future__ import annotations

import abc
from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np

from drake_skill.learning.policy_search.checks import (_check_covariances, _check_int, _check_mean, _make_rng,
                                                       _OPTION_PREFIX, _plain_state, _rng_from_json, _rng_state_json,
                                                       _STATE_FORMAT)


#: Methods whose :meth:`PolicySearch.tell` takes per-step rewards ``(C, T)``;
#: the others take one return per rollout ``(C,)``.
PER_STEP_METHODS = frozenset({"pi2", "pi2-cov"})


class PolicySearch(abc.ABC):
    """Ask/tell policy search over DMP weights ``W: (B, D)``.

    Args:
        mean: initial weights ``W0: (B, D)``, the mean of the exploration
            distribution (docs/method.md section 5).
        covariances: initial exploration covariances ``Sigma0: (B, D, D)``,
            one symmetric positive-definite ``D x D`` matrix per basis (the
            covariance of the per-demonstration DMP weights, thesis
            section 5.2; regularise it, e.g. ``+ eps * I``, when there are
            fewer demonstrations than dimensions).
        n_episodes: episode budget ``E`` (thesis section 6: 5 for the PI^2
            family, 30 for PoWER, the class default); it sets the sigma
            schedule of the methods that use one and is informative
            otherwise.
        seed: ``int``, ``None`` (fresh entropy) or a
            ``numpy.random.Generator``, which is then used as is and should
            be dedicated to this object. Given an ``int``, every ``ask`` is
            deterministic.
    """

    #: Name for :func:`make_policy_search`.
    name: ClassVar[str] = ""
    #: Whether :meth:`tell` takes per-step rewards ``(C, T)``.
    per_step: ClassVar[bool] = False
    #: Episode budget of thesis section 6.
    default_n_episodes: ClassVar[int] = 5

    def __init__(
        self,
        mean: np.ndarray,
        covariances: np.ndarray,
        *,
        n_episodes: int | None = None,
        seed: int | np.random.Generator | None = None,
    ) -> None:
        self._initial_mean = _check_mean(mean)
        self._initial_covariances, self._initial_cholesky = _check_covariances(
            covariances, self._initial_mean.shape, name="covariances")
        self._n_episodes = (self.default_n_episodes if n_episodes is None else
                            _check_int("n_episodes", n_episodes, minimum=1))
        self._rng = _make_rng(seed)
        self._episode = 0

    # -- read-only views ------------------------------------------------

    @property
    def n_bases(self) -> int:
        """Number of bases B."""
        return self._initial_mean.shape[0]

    @property
    def n_dims(self) -> int:
        """Number of controlled dimensions D."""
        return self._initial_mean.shape[1]

    @property
    def n_episodes(self) -> int:
        """Episode budget E."""
        return self._n_episodes

    @property
    def episode(self) -> int:
        """Number of episodes told so far (0-based index of the next one)."""
        return self._episode

    @property
    @abc.abstractmethod
    def mean(self) -> np.ndarray:
        """Current mean weights ``W: (B, D)``, the greedy policy (a copy)."""

    @property
    @abc.abstractmethod
    def covariances(self) -> np.ndarray:
        """Exploration covariances ``Sigma_b: (B, D, D)`` (a copy).

        The next :meth:`ask` samples from ``N(w_b, sigma * Sigma_b)``.
        """

    @property
    @abc.abstractmethod
    def sigma(self) -> float:
        """Scale ``s`` of the next :meth:`ask`: ``N(w_b, s Sigma_b)``."""

    @property
    def sampling_covariances(self) -> np.ndarray:
        """Covariances the next :meth:`ask` samples from: ``sigma * Sigma_b``.

        Shape ``(B, D, D)``.
        """
        return self.sigma * self.covariances

    # -- ask / tell -----------------------------------------------------

    def ask(self, n: int) -> np.ndarray:
        """Sample ``n`` rollouts' weights, ``(n, B, D)``.

        Deterministic given the seed and the history of calls.
        """
        n = _check_int("n", n, minimum=1)
        return self._ask(n)

    def tell(self, samples: np.ndarray, results: np.ndarray) -> None:
        """Update the search distribution from one episode.

        Args:
            samples: the rollouts' weights ``(C, B, D)``, as returned by
                :meth:`ask`.
            results: returns ``(C,)`` for black-box methods, per-step
                rewards ``(C, T)`` for :data:`PER_STEP_METHODS`; finite,
                higher is better. A failed rollout counts with return 0
                (docs/method.md section 5).
        """
        samples = self._check_samples(samples)
        results = self._check_results(results, samples.shape[0])
        self._tell(samples, results)
        self._episode += 1

    @abc.abstractmethod
    def _ask(self, n: int) -> np.ndarray:
        ...

    @abc.abstractmethod
    def _tell(self, samples: np.ndarray, results: np.ndarray) -> None:
        ...

    # -- state ------------------------------------------------------------

    def state_dict(self) -> dict[str, Any]:
        """Full state as a dict of numpy arrays, numbers and strings.

        Keys: ``method``, ``format``, ``initial_mean``,
        ``initial_covariances``, ``episode``, ``rng_state`` (the bit
        generator's state as a JSON string), ``option_<name>`` for each
        hyper-parameter, and the method's own entries (``mean``,
        ``covariances``, PoWER's rollout memory, CMA-ES's history). No entry
        needs pickling; ``np.savez`` stores it as is.
        """
        state: dict[str, Any] = {
            "format": _STATE_FORMAT,
            "method": self.name,
            "initial_mean": self._initial_mean.copy(),
            "initial_covariances": self._initial_covariances.copy(),
            "episode": self._episode,
            "rng_state": _rng_state_json(self._rng),
        }
        for key, value in self._options().items():
            state[_OPTION_PREFIX + key] = value
        state.update(self._state())
        return state

    @classmethod
    def from_state_dict(cls, state: Mapping[str, Any]) -> PolicySearch:
        """Rebuild an object from :meth:`state_dict` (or a loaded ``.npz``)."""
        state = _plain_state(state)
        method = state.get("method")
        if method != cls.name:
            raise ValueError(
                f"state is for method {method!r}, not {cls.name!r}; use "
                "policy_search_from_state() to dispatch on the method")
        if state.get("format") != _STATE_FORMAT:
            raise ValueError(
                f"state format {state.get('format')!r} is not supported "
                f"(expected {_STATE_FORMAT})")
        options = {key[len(_OPTION_PREFIX):]: value
                   for key, value in state.items()
                   if key.startswith(_OPTION_PREFIX)}
        obj = cls(state["initial_mean"], state["initial_covariances"],
                  **cls._options_from_state(options))
        obj._restore(state)
        return obj

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        """Replace this object's whole state (hyper-parameters included)."""
        restored = type(self).from_state_dict(state)
        self.__dict__.clear()
        self.__dict__.update(restored.__dict__)

    def save(self, path) -> None:
        """Write :meth:`state_dict` to an ``.npz`` file (``np.savez``)."""
        np.savez(path, **self.state_dict())

    def _options(self) -> dict[str, Any]:
        return {"n_episodes": self._n_episodes}

    @classmethod
    def _options_from_state(cls, options: dict[str, Any]) -> dict[str, Any]:
        return options

    def _state(self) -> dict[str, Any]:
        return {}

    def _restore(self, state: dict[str, Any]) -> None:
        self._episode = int(state["episode"])
        self._rng = _rng_from_json(state["rng_state"])

    # -- validation -------------------------------------------------------

    def _check_samples(self, samples: np.ndarray) -> np.ndarray:
        samples = np.array(samples, dtype=float)
        expected = (self.n_bases, self.n_dims)
        if samples.ndim != 3 or samples.shape[1:] != expected or not len(samples):
            raise ValueError(
                f"samples must have shape (C, B, D) = (C, {expected[0]}, "
                f"{expected[1]}) with C >= 1, as returned by ask(); got "
                f"{samples.shape}")
        bad = ~np.isfinite(samples).all(axis=(1, 2))
        if bad.any():
            raise ValueError(
                f"samples contain NaN or inf (rollouts {np.flatnonzero(bad).tolist()})")
        return samples

    def _check_results(self, results: np.ndarray, n: int) -> np.ndarray:
        results = np.array(results, dtype=float)
        if self.per_step:
            if results.ndim != 2 or results.shape[0] != n or results.shape[1] < 1:
                raise ValueError(
                    f"results must be per-step rewards of shape (C, T) = "
                    f"({n}, T) with T >= 1 for {self.name!r}; got "
                    f"{results.shape}")
        elif results.shape != (n,):
            hint = (" (sum per-step rewards over time for a black-box method)"
                    if results.ndim == 2 and results.shape[0] == n else "")
            raise ValueError(
                f"results must be one return per rollout, shape ({n},), for "
                f"{self.name!r}; got {results.shape}{hint}")
        bad = ~np.isfinite(results.reshape(n, -1)).all(axis=1)
        if bad.any():
            raise ValueError(
                f"results contain NaN or inf (rollouts "
                f"{np.flatnonzero(bad).tolist()}); count a failed rollout with "
                "return 0 (docs/method.md section 5)")
        return results
