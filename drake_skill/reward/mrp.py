"""State values of the goal model's Markov reward process (docs/method.md section 4, thesis ch. 4).

The goal HMM's ``pi`` and ``P`` define a Markov process over its ``k`` hidden
states.  With reward ``r(s) = +1`` for terminal states and 0 otherwise
(Eq. 4.2) it is a finite-horizon MRP whose state values come from Monte Carlo
policy evaluation (thesis 3.3.2, Algorithm 1):

* sample ``n`` state sequences ``s_1..s_L`` from ``pi`` and ``P``, with
  ``L = floor(mean demonstration length)`` (thesis 6.5: ``n = 100``);
* returns along each sequence (Eq. 4.1): ``G_L = r_L``,
  ``G_t = r_t + gamma G_{t+1}``, ``gamma = 0.9``;
* ``v(s)`` = mean of ``G_t`` over every visit to ``s`` (Eq. 4.3), 0 where
  ``s`` is never visited;
* terminal values multiplied by ``c > 1``.  The thesis gives no value for
  ``c``; this project's default is 2.0 (``MrpConfig.terminal_scale``).

:func:`exact_values` is a cross-check the thesis does not have: the value the
Monte Carlo estimate converges to, by dynamic programming on the same
finite-horizon MRP.  Values are unitless (discounted counts of terminal
visits), at most ``c / (1 - gamma)``.
"""

from dataclasses import dataclass

import numpy as np

__all__ = [
    "MrpConfig",
    "terminal_rewards",
    "sample_state_sequences",
    "discounted_returns",
    "monte_carlo_values",
    "exact_values",
    "state_marginals",
    "expected_visit_times",
]


@dataclass
class MrpConfig:
    """Monte Carlo value estimation settings (thesis 6.5; loadable with ``yaml_load_typed``).

    Attributes:
      n_sequences: sampled state sequences ``n`` (thesis: 100).
      gamma: discount factor (thesis: 0.9).
      terminal_scale: ``c > 1`` multiplying terminal values (project choice;
        the thesis gives no value).
      length: sequence length ``L``; 0 = ``floor(mean demonstration length)``.
      random_state: seed of the sampling.
    """

    n_sequences: int = 100
    gamma: float = 0.9
    terminal_scale: float = 2.0
    length: int = 0
    random_state: int = 0


def _check_chain(startprob, transmat):
    pi = np.asarray(startprob, dtype=float)
    P = np.asarray(transmat, dtype=float)
    if pi.ndim != 1 or pi.size == 0:
        raise ValueError(f"startprob: expected shape (k,), got {pi.shape}")
    k = pi.size
    if P.shape != (k, k):
        raise ValueError(f"transmat: expected shape ({k}, {k}) to match startprob, got {P.shape}")
    if not (np.all(np.isfinite(pi)) and np.all(pi >= 0) and abs(pi.sum() - 1) < 1e-6):
        raise ValueError(f"startprob: expected a probability vector, got {pi}")
    if not (np.all(np.isfinite(P)) and np.all(P >= 0) and np.allclose(P.sum(axis=1), 1, atol=1e-6)):
        raise ValueError(f"transmat: expected non-negative rows summing to 1, got row sums {P.sum(axis=1)}")
    return pi, P


def _check_common(k, terminal_states, length, gamma, terminal_scale):
    term = np.asarray(terminal_states, dtype=int).reshape(-1)
    if term.size == 0 or np.any(term < 0) or np.any(term >= k):
        raise ValueError(f"terminal_states: expected a non-empty set of states in [0, {k}), got {term.tolist()}")
    if int(length) < 1:
        raise ValueError(f"length: expected a sequence length >= 1, got {length}")
    if not (0.0 <= gamma <= 1.0):
        raise ValueError(f"gamma: expected a discount in [0, 1], got {gamma}")
    if not terminal_scale > 0:
        raise ValueError(f"terminal_scale: expected c > 0 (thesis: c > 1), got {terminal_scale}")
    return term


def terminal_rewards(n_states: int, terminal_states) -> np.ndarray:
    """Eq. 4.2: ``r(s) = 1`` for ``s`` in ``T``, else 0; ``(k,)``."""
    r = np.zeros(int(n_states))
    r[np.asarray(terminal_states, dtype=int)] = 1.0
    return r


def sample_state_sequences(startprob, transmat, n_sequences: int, length: int, random_state=None) -> np.ndarray:
    """``n`` hidden-state sequences of length ``L`` from ``pi`` and ``P``: ``(n, L)`` ints.

    All sequences advance together by inverse-CDF sampling.  To draw every
    sequence's next state with one ``searchsorted`` call, row ``j`` of the
    cumulative transition matrix is shifted by ``2 j`` and the rows are laid
    end to end (a sorted array); a uniform ``u`` from state ``j`` is looked up
    as ``u + 2 j``.  (Hand-written: numpy's ``Generator.choice`` takes one
    probability vector per call, i.e. one call per sequence and step.)
    """
    pi, P = _check_chain(startprob, transmat)
    rng = np.random.default_rng(random_state)
    n, L = int(n_sequences), int(length)
    if n < 1 or L < 1:
        raise ValueError(f"n_sequences, length: ({n_sequences}, {length}), expected >= 1")
    k = pi.size
    cum_pi = np.cumsum(pi)
    cum_pi[-1] = 1.5  # beyond any u < 1, so rounding never leaves the last bin empty
    cum_P = np.cumsum(P, axis=1)
    cum_P[:, -1] = 1.5
    flat = (cum_P + 2.0 * np.arange(k)[:, None]).ravel()
    u = rng.random((L, n))
    s = np.empty((L, n), dtype=np.intp)
    s[0] = np.searchsorted(cum_pi, u[0], side="right")
    for t in range(1, L):
        prev = s[t - 1]
        s[t] = np.searchsorted(flat, u[t] + 2.0 * prev, side="right") - prev * k
    return np.ascontiguousarray(s.T)


def discounted_returns(rewards: np.ndarray, gamma: float) -> np.ndarray:
    """Eq. 4.1 along the last axis: ``G_L = r_L``, ``G_t = r_t + gamma G_{t+1}``."""
    r = np.ascontiguousarray(np.moveaxis(np.asarray(rewards, dtype=float), -1, 0))  # time first
    G = np.empty_like(r)
    G[-1] = r[-1]
    for t in range(r.shape[0] - 2, -1, -1):
        G[t] = r[t] + gamma * G[t + 1]
    return np.moveaxis(G, 0, -1)


def monte_carlo_values(startprob, transmat, terminal_states, length: int, *, n_sequences: int = 100,
                       gamma: float = 0.9, terminal_scale: float = 2.0, random_state=0) -> np.ndarray:
    """State values by Monte Carlo policy evaluation (Eqs. 4.1-4.3), ``(k,)``.

    Args:
      startprob ``(k,)``, transmat ``(k, k)``: the goal HMM's chain.
      terminal_states: indices of ``T``.
      length: ``L``, the floor of the mean demonstration length (frames).
      n_sequences, gamma, terminal_scale, random_state: see :class:`MrpConfig`.

    ``v(s) = (1 / n_s) sum_i sum_t G^i_t 1(s^i_t = s)``, 0 for never-visited
    states; then ``v(s) *= c`` for ``s`` in ``T``.
    """
    pi, P = _check_chain(startprob, transmat)
    k = pi.size
    term = _check_common(k, terminal_states, length, gamma, terminal_scale)
    S = sample_state_sequences(pi, P, n_sequences, length, random_state)
    r = terminal_rewards(k, term)
    G = discounted_returns(r[S], gamma)
    counts = np.bincount(S.ravel(), minlength=k).astype(float)
    sums = np.bincount(S.ravel(), weights=G.ravel(), minlength=k)
    v = np.divide(sums, counts, out=np.zeros(k), where=counts > 0)
    v[term] *= terminal_scale
    return v


def state_marginals(startprob, transmat, length: int) -> np.ndarray:
    """``p_t(s) = P(s_t = s)`` for ``t = 1..L`` under ``pi`` and ``P``: ``(L, k)``."""
    pi, P = _check_chain(startprob, transmat)
    p = np.empty((int(length), pi.size))
    p[0] = pi
    for t in range(1, int(length)):
        p[t] = p[t - 1] @ P
    return p


def exact_values(startprob, transmat, terminal_states, length: int, *, gamma: float = 0.9,
                 terminal_scale: float = 2.0) -> np.ndarray:
    """The limit of :func:`monte_carlo_values` as ``n -> inf``, by dynamic programming, ``(k,)``.

    Expected return at time ``t`` from state ``s`` (finite horizon ``L``):
    ``u_L = r``, ``u_t = r + gamma P u_{t+1}``.  Monte Carlo averages the
    returns of all visits, so it converges to the visit-weighted mean
    ``v(s) = sum_t p_t(s) u_t(s) / sum_t p_t(s)`` with ``p_t`` from
    :func:`state_marginals` (0 where ``sum_t p_t(s) = 0``), then ``v(T) *= c``.
    """
    pi, P = _check_chain(startprob, transmat)
    k = pi.size
    term = _check_common(k, terminal_states, length, gamma, terminal_scale)
    L = int(length)
    r = terminal_rewards(k, term)
    p = state_marginals(pi, P, L)
    u = np.empty((L, k))
    u[-1] = r
    for t in range(L - 2, -1, -1):
        u[t] = r + gamma * (P @ u[t + 1])
    w = p.sum(axis=0)
    v = np.divide((p * u).sum(axis=0), w, out=np.zeros(k), where=w > 1e-300)
    v[term] *= terminal_scale
    return v


def expected_visit_times(startprob, transmat, length: int) -> np.ndarray:
    """Mean time index (0-based frames) of the visits to each state, ``(k,)``; NaN if never visited."""
    p = state_marginals(startprob, transmat, length)
    w = p.sum(axis=0)
    t = np.arange(p.shape[0], dtype=float)
    return np.divide(t @ p, w, out=np.full(p.shape[1], np.nan), where=w > 1e-300)
