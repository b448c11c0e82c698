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

Modules (as dmpbbo keeps its distributions apart from its updaters):
``weighting`` (schedule, rewards-to-go, rollout probabilities), ``base``
(the ask/tell interface), ``gaussian`` (exploration per basis), ``methods``
(PoWER, the PI^2 family), ``cma`` (the CMA-ES baseline), ``checks`` (argument
checks, state encoding); this module builds them by name.

State: :meth:`PolicySearch.state_dict` returns plain numpy arrays, numbers
and strings only (no pickling), which :meth:`PolicySearch.save` writes to an
``.npz`` file and :func:`load_policy_search` reads back with
``allow_pickle=False``; the restored object continues bit for bit as the
original would have.
"""

from __future__ import annotations

import inspect
from collections.abc import Mapping
from typing import Any

import numpy as np

from drake_skill.learning.policy_search.base import PER_STEP_METHODS, PolicySearch
from drake_skill.learning.policy_search.checks import _plain_state
from drake_skill.learning.policy_search.cma import CMAES
from drake_skill.learning.policy_search.methods import PI2, PI2ES, PI2Cov, PI2ESCov, PoWER
from drake_skill.learning.policy_search.weighting import (WEIGHTINGS, reward_to_go, rollout_probabilities,
                                                          sigma_schedule)


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
    "WEIGHTINGS",
    "load_policy_search",
    "make_policy_search",
    "policy_search_from_state",
    "reward_to_go",
    "rollout_probabilities",
    "sigma_schedule",
]

#: Names accepted by :func:`make_policy_search`.
METHODS = ("power", "pi2", "pi2-cov", "pi2-es", "pi2-es-cov", "cma-es")


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
