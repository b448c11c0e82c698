"""The goal model's hyper-parameters and the checks and counts its fit shares.

No ``from __future__ import annotations`` here: ``yaml_load_typed`` reads
:class:`GoalModelConfig`'s annotations as types, not strings."""

from dataclasses import dataclass, field

import numpy as np


COVARIANCE_TYPES = ("spherical", "diag", "full", "tied")
CRITERIA = ("aic", "bic")

# Probability mass spread over non-left-to-right entries of the initial
# transition matrix and start vector, so EM can still move mass there.
_INIT_LEAK = 0.02


@dataclass
class GoalModelConfig:
    """Hyper-parameters of :class:`GoalHMM` (loadable with ``yaml_load_typed``).

    Attributes:
      n_states_min, n_states_max: range of state counts ``k`` tried (inclusive).
      criterion: "aic" (thesis 6.5, default) or "bic".
      covariance_types: hmmlearn covariance types tried; the criterion picks
        one together with ``k``.
      n_restarts: EM runs per candidate ``(k, covariance type)``; restart 0 is
        the deterministic change-point init, the others are seeded.
      n_iter: Baum-Welch iteration budget per run.
      tol: convergence threshold on the gain of total log-likelihood (nats).
      covar_reg: M-step covariance regulariser, relative to the mean
        per-dimension variance of the training frames (docs/method.md
        section 4: with 2-3 demonstrations a state's frames are few and
        nearly alike, so this sets how far a new execution may differ from
        them and still be in the state).
      random_state: seed of every random restart.
    """

    n_states_min: int = 2
    n_states_max: int = 8
    criterion: str = "aic"
    covariance_types: list[str] = field(default_factory=lambda: ["diag", "full"])
    n_restarts: int = 4
    n_iter: int = 100
    tol: float = 1e-3
    covar_reg: float = 0.03
    random_state: int = 0


def check_sequences(X, lengths=None, *, name: str = "X", n_features: int | None = None):
    """Validates stacked sequences; returns ``(X float (N, d), lengths int (n,))``.

    ``X: (N, d)`` is all sequences stacked in time; ``lengths`` (``None`` = one
    sequence) gives each sequence's frame count and must sum to ``N``.
    """
    X = np.asarray(X, dtype=float)
    if X.ndim != 2:
        raise ValueError(f"{name}: expected a 2-D array (frames, features), got shape {X.shape}")
    if X.shape[0] == 0:
        raise ValueError(f"{name}: empty sequence (shape {X.shape}); expected at least one frame")
    if n_features is not None and X.shape[1] != n_features:
        raise ValueError(f"{name}: expected {n_features} features per frame, got shape {X.shape}")
    if not np.all(np.isfinite(X)):
        bad = np.argwhere(~np.isfinite(X))[0]
        raise ValueError(f"{name}: non-finite value {X[tuple(bad)]} at frame {bad[0]}, feature {bad[1]}")
    if lengths is None:
        lengths = np.array([X.shape[0]], dtype=int)
    else:
        raw = np.asarray(lengths)
        if raw.ndim != 1 or raw.size == 0 or not np.all(np.isfinite(raw)) or np.any(raw != np.round(raw)):
            raise ValueError(f"lengths: expected a non-empty 1-D list of integers, got {lengths!r}")
        lengths = raw.astype(int)
        if np.any(lengths < 1):
            raise ValueError(f"lengths: every sequence needs at least one frame, got {lengths.tolist()}")
        if lengths.sum() != X.shape[0]:
            raise ValueError(
                f"lengths: sum {int(lengths.sum())} does not match the {X.shape[0]} frames of {name}")
    return X, lengths


def n_free_parameters(n_states: int, n_features: int, covariance_type: str) -> int:
    """Free parameters of a Gaussian HMM, as counted by AIC/BIC.

    ``(k - 1)`` start + ``k (k - 1)`` transition + ``k d`` mean parameters, plus
    covariances: spherical ``k``, diag ``k d``, full ``k d (d + 1) / 2``,
    tied ``d (d + 1) / 2``.
    """
    k, d = int(n_states), int(n_features)
    cov = {
        "spherical": k,
        "diag": k * d,
        "full": k * d * (d + 1) // 2,
        "tied": d * (d + 1) // 2,
    }
    if covariance_type not in cov:
        raise ValueError(f"covariance_type: {covariance_type!r}, expected one of {COVARIANCE_TYPES}")
    return (k - 1) + k * (k - 1) + k * d + cov[covariance_type]


def regulariser_scale(X: np.ndarray) -> float:
    """The scale of the covariance regularisers: the mean per-feature variance of ``X (N, d)`` (goal
    units squared), or 1 when that variance is zero *or at the rounding level of the data*.

    Goal data that never changes has variance 0 only if its value is a binary fraction: a constant
    0.3 has a computed variance of about 1e-33, which would make the regulariser vanish and the
    Gaussian densities overflow.  A variance below ``16 (machine eps * max |x|)^2`` (a spread of
    four units in the last place) is indistinguishable from that rounding, so it counts as zero.
    """
    var = float(X.var(axis=0).mean())
    rounding = 16.0 * (np.finfo(float).eps * float(np.abs(X).max(initial=0.0))) ** 2
    return var if var > rounding else 1.0
