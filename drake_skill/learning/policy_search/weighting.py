"""The building blocks: the exploration schedule (thesis Eq. 5.4), rewards-to-go and the
weighting of rollouts into probabilities (thesis Eq. 3.27, 5.1)."""

from __future__ import annotations

import numpy as np

from drake_skill.learning.policy_search.checks import _check_float, _check_int


#: Weightings of rollouts into probabilities (:func:`rollout_probabilities`).
WEIGHTINGS = ("thesis", "range")


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
