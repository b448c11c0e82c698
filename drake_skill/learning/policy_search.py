"""Policy search over DMP weights behind one ask/tell interface.

Plain numpy (plus the ``cma`` package for the CMA-ES baseline), no Drake
import. docs/method.md section 5 / thesis sections 3.4 and 5.2.

The policy parameters are the DMP weights ``theta = W``, shape ``(B, D)``
(B bases, D controlled dimensions; D = 7 for the end-effector pose).
Exploration adds Gaussian noise per basis, with one ``D x D`` covariance per
basis (``covariances: (B, D, D)``)::

    w_b^c ~ N(w_b, s Sigma_b)          (thesis Eq. 3.24, 5.3, 5.6)

where ``s`` is the exploration scale (:attr:`PolicySearch.sigma`): the
Eq. 5.4 schedule for PoWER, PI^2 and PI^2-ES, 1 for the methods that adapt
``Sigma_b`` (PI^2-Cov, PI^2-ES-Cov). Usage::

    search = make_policy_search("pi2-es-cov", W0, Sigma0, seed=0)
    for _ in range(search.n_episodes):
        samples = search.ask(6)                 # (C, B, D)
        results = [run_skill(w) for w in samples]
        search.tell(samples, results)           # (C,) returns, or (C, T)
    W = search.mean                             # greedy weights, (B, D)

``results`` are returns, one per rollout, shape ``(C,)``, for the black-box
methods, and per-step rewards ``(C, T)`` for :data:`PER_STEP_METHODS`.
Higher is better everywhere (thesis Eq. 3.27 writes PI^2 with costs and
``exp(-G / lambda)``; with rewards the sign flips). An *episode* is one
:meth:`PolicySearch.tell`.

Methods (names for :func:`make_policy_search`):

- ``"power"``: black-box PoWER (thesis section 3.4.1, Eq. 3.25-3.26;
  Kormushev et al. 2010); keeps every rollout seen and moves to the
  return-weighted mean of the best ``r`` of them.
- ``"pi2"``: PI^2 (thesis section 3.4.2, Eq. 3.27-3.29).
- ``"pi2-cov"``: PI^2 with the covariance update of Stulp and Sigaud 2012
  (thesis section 3.4.3, Eq. 3.30-3.31).
- ``"pi2-es"``: black-box PI^2-ES (thesis section 5.2, Eq. 5.1-5.4).
- ``"pi2-es-cov"``: PI^2-ES with the Eq. 5.5 covariance update (thesis
  section 5.2).
- ``"cma-es"``: CMA-ES from the ``cma`` package as a baseline, searching in
  coordinates whitened by ``Sigma0``.

Per-step simplification (``"pi2"``, ``"pi2-cov"``): a rollout's parameters
are perturbed once and held for the whole rollout, as in the PI^2 variant
with constant exploration of Stulp and Sigaud. Every basis weight is treated
as active at every time step: the per-step estimates of Eq. 3.28 are not
weighted by the basis activations and there is no projection of the noise
onto the basis. The time average of Eq. 3.29 then reduces to one weight per
rollout, ``P_c = sum_t (T - t) P_{t,c} / sum_t (T - t)``.

State: :meth:`PolicySearch.state_dict` returns plain numpy arrays, numbers
and strings only (no pickling), which :meth:`PolicySearch.save` writes to an
``.npz`` file and :func:`load_policy_search` reads back with
``allow_pickle=False``; the restored object continues bit for bit as the
original would have.
"""

from __future__ import annotations

import abc
import inspect
import json
import numbers
from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np

__all__ = [
    "CMAES",
    "METHODS",
    "PER_STEP_METHODS",
    "PI2",
    "PI2Cov",
    "PI2ES",
    "PI2ESCov",
    "PoWER",
    "PolicySearch",
    "load_policy_search",
    "make_policy_search",
    "policy_search_from_state",
    "reward_to_go",
    "rollout_probabilities",
    "sigma_schedule",
]

#: Names accepted by :func:`make_policy_search`.
METHODS = ("power", "pi2", "pi2-cov", "pi2-es", "pi2-es-cov", "cma-es")

#: Methods whose :meth:`PolicySearch.tell` takes per-step rewards ``(C, T)``;
#: the others take one return per rollout ``(C,)``.
PER_STEP_METHODS = frozenset({"pi2", "pi2-cov"})

#: Weightings of rollouts into probabilities (:func:`rollout_probabilities`).
WEIGHTINGS = ("thesis", "range")

_STATE_FORMAT = 1
_OPTION_PREFIX = "option_"


# --------------------------------------------------------------------------
# Building blocks (pure functions)
# --------------------------------------------------------------------------


def sigma_schedule(
    episode: int,
    n_episodes: int,
    sigma0: float = 1.0,
    decay_start: float | None = None,
) -> float:
    """Exploration scale of thesis Eq. 5.4 for a 0-based episode index.

    ::

        sigma_e = sigma0                              for e <= U
        sigma_e = sigma0 (1 - (e - U) / (E - U))      otherwise

    with ``U = decay_start`` (default ``E / 4``, thesis section 6). ``e`` is
    the 0-based index of the episode being sampled (the number of updates
    done so far), so the last episode of the budget, ``e = E - 1``, samples
    with ``sigma0 / (E - U) > 0`` rather than zero: with the 1-based index
    the last episode would sample only the mean and its update would be
    void. Past the budget (``e >= E``) the value of ``e = E - 1`` is kept, so
    the scale never reaches zero or goes negative. The scale multiplies the
    covariance (``N(w_b, sigma_e Sigma_b^0)``, thesis Eq. 5.3), not the
    standard deviation.
    """
    episode = _check_int("episode", episode, minimum=0)
    n_episodes = _check_int("n_episodes", n_episodes, minimum=1)
    sigma0 = _check_float("sigma0", sigma0, positive=True)
    u = n_episodes / 4.0 if decay_start is None else _check_float(
        "decay_start", decay_start, non_negative=True)
    e = min(episode, n_episodes - 1)
    if e <= u:
        return sigma0
    return sigma0 * (1.0 - (e - u) / (n_episodes - u))


def reward_to_go(rewards: np.ndarray) -> np.ndarray:
    """Undiscounted reward-to-go ``G_{t,c} = sum_{j >= t} r_{j,c}``.

    Thesis Eq. 3.19 with ``gamma = 1``. ``rewards: (C, T)`` -> ``(C, T)``.
    """
    rewards = np.asarray(rewards, dtype=float)
    return np.flip(np.cumsum(np.flip(rewards, axis=-1), axis=-1), axis=-1)


def rollout_probabilities(
    results: np.ndarray,
    *,
    weighting: str = "thesis",
    h: float = 10.0,
    per_step: bool = False,
) -> np.ndarray:
    """Probability of each rollout of an episode, ``(C,)`` summing to 1.

    Black box (``per_step=False``, ``results`` = returns ``R: (C,)``):

    - ``weighting="thesis"``: ``P_c = exp(R_c / C) / sum_c' exp(R_c' / C)``
      (thesis Eq. 5.1 as printed; ``C`` = rollouts in the episode). It
      depends on the scale of the returns: returns in the hundreds put
      nearly all weight on the best rollout, returns below one give nearly
      uniform weights.
    - ``weighting="range"``: ``P_c ∝ exp(h (R_c - min R) / (max R - min R))``
      (the usual PI^2 normalisation, scale free); uniform when all returns
      are equal.

    Per step (``per_step=True``, ``results`` = per-step rewards ``(C, T)``):
    the same weighting is applied at every step ``t`` to the reward-to-go
    ``G_{t,c}`` (:func:`reward_to_go`; thesis Eq. 3.27, with lambda taken
    from the range of ``G_{., t}`` for ``"range"``), and the per-step
    probabilities are averaged over time with weights ``T - t`` for the
    0-based ``t = 0 .. T-1`` (thesis Eq. 3.29; every step, the last one
    included, gets a positive weight). With the parameters held constant
    over a rollout, averaging the per-step estimates
    ``theta^t = sum_c P_{t,c} theta_c`` (Eq. 3.28) is the same as weighting
    the rollouts with these averaged probabilities.
    """
    if weighting not in WEIGHTINGS:
        raise ValueError(
            f"weighting must be one of {WEIGHTINGS}; got {weighting!r}")
    h = _check_float("h", h, positive=True)
    values = np.asarray(results, dtype=float)
    if per_step:
        if values.ndim != 2:
            raise ValueError(
                f"per-step results must have shape (C, T); got {values.shape}")
        values = reward_to_go(values)
    elif values.ndim != 1:
        raise ValueError(f"returns must have shape (C,); got {values.shape}")
    n = values.shape[0]
    if weighting == "thesis":
        exponent = values / n
    else:
        low = values.min(axis=0)
        span = values.max(axis=0) - low
        safe = np.where(span > 0, span, 1.0)
        exponent = np.where(span > 0, h * (values - low) / safe, 0.0)
    exponent = exponent - exponent.max(axis=0)
    p = np.exp(exponent)
    p /= p.sum(axis=0)
    if per_step:
        n_steps = values.shape[1]
        time_weights = np.arange(n_steps, 0, -1, dtype=float)  # T - t
        p = p @ time_weights / time_weights.sum()
    return p


# --------------------------------------------------------------------------
# Base class
# --------------------------------------------------------------------------


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


# --------------------------------------------------------------------------
# Gaussian exploration around a mean, block-diagonal covariance
# --------------------------------------------------------------------------


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


# --------------------------------------------------------------------------
# The methods
# --------------------------------------------------------------------------


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


# --------------------------------------------------------------------------
# Factory and state I/O
# --------------------------------------------------------------------------

_CLASSES: dict[str, type[PolicySearch]] = {
    cls.name: cls for cls in (PoWER, PI2, PI2Cov, PI2ES, PI2ESCov, CMAES)}


def make_policy_search(name: str, mean: np.ndarray, covariances: np.ndarray,
                       **options: Any) -> PolicySearch:
    """Build a policy search by name (one of :data:`METHODS`).

    ``mean: (B, D)``, ``covariances: (B, D, D)``; ``options`` are the
    method's keyword arguments (all take ``n_episodes`` and ``seed``; see
    each class for the others).
    """
    try:
        cls = _CLASSES[name]
    except (KeyError, TypeError):
        raise ValueError(
            f"unknown policy-search method {name!r}; choose one of "
            f"{', '.join(METHODS)}") from None
    accepted = [p for p in inspect.signature(cls.__init__).parameters
                if p not in ("self", "mean", "covariances")]
    unknown = sorted(set(options) - set(accepted))
    if unknown:
        raise TypeError(
            f"{name!r} does not take option(s) {', '.join(unknown)}; its "
            f"options are {', '.join(accepted)}")
    return cls(mean, covariances, **options)


def policy_search_from_state(state: Mapping[str, Any]) -> PolicySearch:
    """Rebuild any method's object from its :meth:`PolicySearch.state_dict`."""
    state = _plain_state(state)
    name = state.get("method")
    if name not in _CLASSES:
        raise ValueError(
            f"state names unknown method {name!r}; expected one of "
            f"{', '.join(METHODS)}")
    return _CLASSES[name].from_state_dict(state)


def load_policy_search(path) -> PolicySearch:
    """Read an object written by :meth:`PolicySearch.save` (no pickling)."""
    with np.load(path, allow_pickle=False) as data:
        state = {key: data[key] for key in data.files}
    return policy_search_from_state(state)


# --------------------------------------------------------------------------
# Helpers
# --------------------------------------------------------------------------


def _check_int(name: str, value, *, minimum: int) -> int:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{name} must be an integer >= {minimum}; got {value!r}")
    if value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}; got {value}")
    return int(value)


def _check_float(name: str, value, *, positive: bool = False,
                 non_negative: bool = False) -> float:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} must be a real number; got {value!r}")
    value = float(value)
    if not np.isfinite(value):
        raise ValueError(f"{name} must be finite; got {value}")
    if positive and value <= 0:
        raise ValueError(f"{name} must be > 0; got {value}")
    if non_negative and value < 0:
        raise ValueError(f"{name} must be >= 0; got {value}")
    return value


def _check_mean(mean) -> np.ndarray:
    mean = np.array(mean, dtype=float)
    if mean.ndim != 2 or 0 in mean.shape:
        raise ValueError(
            f"mean must be the DMP weights W of shape (B, D) (B bases, D "
            f"dimensions, both >= 1); got shape {mean.shape}")
    if not np.isfinite(mean).all():
        raise ValueError("mean contains NaN or inf")
    return mean


def _check_covariances(covariances, mean_shape, *, name: str):
    """Validate ``(B, D, D)`` SPD covariances; return them and their Cholesky."""
    covariances = np.array(covariances, dtype=float)
    b, d = mean_shape
    if covariances.shape != (b, d, d):
        raise ValueError(
            f"{name} must have shape (B, D, D) = ({b}, {d}, {d}), one D x D "
            f"covariance per basis of the mean; got {covariances.shape}")
    if not np.isfinite(covariances).all():
        raise ValueError(f"{name} contains NaN or inf")
    asymmetry = np.abs(covariances - np.swapaxes(covariances, 1, 2)).max(axis=(1, 2))
    scale = np.abs(covariances).max(axis=(1, 2))
    bad = asymmetry > 1e-8 * scale
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ValueError(
            f"{name}[{i}] is not symmetric (max |S - S^T| = {asymmetry[i]:.3g}); "
            "pass 0.5 * (S + S^T)")
    covariances = _symmetrise(covariances)
    try:
        cholesky = np.linalg.cholesky(covariances)
    except np.linalg.LinAlgError:
        smallest = np.linalg.eigvalsh(covariances).min(axis=1)
        i = int(np.argmin(smallest))
        raise ValueError(
            f"{name}[{i}] is not positive definite (smallest eigenvalue "
            f"{smallest[i]:.3g}); regularise it, e.g. S + eps * I") from None
    return covariances, cholesky


def _symmetrise(matrices: np.ndarray) -> np.ndarray:
    return 0.5 * (matrices + np.swapaxes(matrices, -1, -2))


def _make_rng(seed) -> np.random.Generator:
    if isinstance(seed, np.random.Generator):
        return seed
    if seed is None or (isinstance(seed, numbers.Integral)
                        and not isinstance(seed, (bool, np.bool_))):
        return np.random.default_rng(seed)
    raise TypeError(
        f"seed must be an int, None or a numpy.random.Generator; got {seed!r}")


def _rng_state_json(rng: np.random.Generator) -> str:
    def encode(value):
        if isinstance(value, np.ndarray):
            return {"__ndarray__": value.tolist(), "dtype": str(value.dtype)}
        if isinstance(value, np.generic):
            return value.item()
        raise TypeError(f"cannot encode {type(value).__name__}")

    return json.dumps(rng.bit_generator.state, default=encode, sort_keys=True)


def _rng_from_json(text) -> np.random.Generator:
    def decode(obj):
        if "__ndarray__" in obj:
            return np.array(obj["__ndarray__"], dtype=obj["dtype"])
        return obj

    state = json.loads(str(text), object_hook=decode)
    name = state.get("bit_generator")
    bit_generator_type = getattr(np.random, str(name), None)
    if not (isinstance(bit_generator_type, type)
            and issubclass(bit_generator_type, np.random.BitGenerator)):
        raise ValueError(f"rng_state names unknown bit generator {name!r}")
    bit_generator = bit_generator_type()
    bit_generator.state = state
    return np.random.Generator(bit_generator)


def _plain_state(state: Mapping[str, Any]) -> dict[str, Any]:
    """0-d arrays (as ``np.load`` gives them) to Python scalars/strings."""
    if not isinstance(state, Mapping):
        raise TypeError(f"state must be a mapping; got {type(state).__name__}")
    plain = {}
    for key, value in state.items():
        if isinstance(value, np.ndarray) and value.ndim == 0:
            value = value.item()
        elif isinstance(value, np.generic):
            value = value.item()
        plain[str(key)] = value
    return plain
