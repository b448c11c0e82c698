"""Goal model: a Gaussian-emission HMM over a skill's goal data (docs/method.md section 4).

The goal data of a demonstration is a sequence ``G = g_1..g_T`` of PCA features
of the object's point cloud, ``G: (T, d)`` with ``d = 8`` in the project
(unitless, scale ~0.1-1), sampled at 10 Hz.  The goal model is the HMM
``lambda = {pi, P, mu_i, Sigma_i}`` of thesis section 3.2 trained by
Baum-Welch (Eqs. 3.10-3.18) on all demonstrations of a skill, with the number
of states ``k`` chosen by an information criterion (thesis 6.5: AIC; BIC as an
option) and the terminal states ``T`` = the final states of the
demonstrations (thesis chapter 4).

Baum-Welch itself is hmmlearn's.  What this module adds is what hmmlearn does
not do safely with 2-3 short sequences:

* deterministic initialisation (hmmlearn's own random init is seed-fragile
  and can produce NaN start probabilities): restart 0 splits every
  demonstration at its ``k - 1`` least-squares change points and refines the
  split by left-to-right segmental k-means; odd restarts use seeded k-means
  clusters ordered by mean time, even ones random time segments refined the
  same way.  Transitions start left-to-right biased (stay probability from
  the segment durations) and the start probability sits on the first state.
  Equal time cuts were tried first and stuck EM in poor optima: demonstrations
  spend most of their frames in the final sub-goal;
* a real regulariser in every M-step: ``covars_prior = eps*I`` with the shape
  hmmlearn expects for the covariance type (a scalar prior is broadcast to
  *every entry* of a full matrix, and ``min_covar`` is only used at init);
  ``eps = covar_reg * mean per-dimension variance of all frames``, so it
  scales with the data (:func:`regulariser_scale`: 1 for goal data that never changes);
* convergence read from ``monitor_.history`` (hmmlearn's ``converged`` is also
  true when the iteration budget runs out or the likelihood drops);
* several seeded restarts per candidate ``(k, covariance type)``; the best
  converged restart by log-likelihood wins and its index is recorded;
* runs where a state explains too few frames to estimate its covariance are
  marked degenerate and lose to every proper candidate (see :meth:`GoalHMM.fit`);
* BLAS limited to one thread during the fit (tiny matrices; thread hand-offs
  on a busy machine made hmmlearn's triangular solves several times slower).

Inference (log emission densities, log-space forward-backward, Viterbi) runs
on the fitted parameters here; see :func:`forward_backward` for why.

hmmlearn private API used (pin ``hmmlearn>=0.3,<0.4``): only
``hmmlearn._hmmc.forward_log`` / ``backward_log``, the compiled log-space
recursions behind its public ``score_samples``: the public API returns only
the smoothed posteriors, and the online reward needs the *filtered* ones
(the forward lattice) at every frame of every rollout, where the numpy
recursion is a few times slower. A numpy fallback is used when they are
absent, and tests/test_goal_model.py pins them: the compiled lattices equal
the plain numpy recursion, and the smoothed posteriors and log-likelihood
equal hmmlearn's public ``score_samples``. Covariances are read through the
public ``covars_`` (:func:`_full_covars`).
"""

import logging
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.special import logsumexp
from threadpoolctl import threadpool_limits

try:  # hmmlearn's compiled log-space recursions (private module; see _lattices)
    from hmmlearn import _hmmc
    if not all(hasattr(_hmmc, name) for name in ("forward_log", "backward_log")):
        _hmmc = None
except ImportError:  # pragma: no cover - depends on the hmmlearn build
    _hmmc = None

__all__ = [
    "GoalModelConfig",
    "GoalHMM",
    "COVARIANCE_TYPES",
    "CRITERIA",
    "check_sequences",
    "n_free_parameters",
    "gaussian_log_density",
    "forward_backward",
    "forward_log",
    "viterbi",
]

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


def _precision_cholesky(covars: np.ndarray):
    """For full covariances ``(k, d, d)``: ``U`` with ``Sigma^-1 = U U^T`` and the log normaliser.

    Returns ``(U: (k, d, d), log_norm: (k,))`` where
    ``log N(x; mu, Sigma) = log_norm - 0.5 |(x - mu) U|^2``.
    """
    k, d, _ = covars.shape
    L = np.linalg.cholesky(covars)  # Sigma = L L^T
    eye = np.broadcast_to(np.eye(d), (k, d, d))
    Linv = np.linalg.solve(L, eye)  # (k, d, d)
    U = np.swapaxes(Linv, 1, 2)  # Sigma^-1 = Linv^T Linv = U U^T
    log_det = 2.0 * np.log(np.diagonal(L, axis1=1, axis2=2)).sum(axis=1)
    log_norm = -0.5 * (d * np.log(2.0 * np.pi) + log_det)
    return U, log_norm


def gaussian_log_density(X: np.ndarray, means: np.ndarray, prec_chol: np.ndarray,
                         log_norm: np.ndarray) -> np.ndarray:
    """Log emission densities ``log z_i(g_t)`` (thesis 3.2), ``(T, k)``.

    ``X: (T, d)``, ``means: (k, d)``, ``prec_chol: (k, d, d)`` and
    ``log_norm: (k,)`` from the covariances (see ``_precision_cholesky``).
    """
    diff = X[:, None, :] - means[None, :, :]  # (T, k, d)
    y = np.einsum("tkd,kde->tke", diff, prec_chol)
    return log_norm[None, :] - 0.5 * np.einsum("tke,tke->tk", y, y)


def forward_log(log_b: np.ndarray, log_startprob: np.ndarray, log_transmat: np.ndarray):
    """Log-space forward pass (Eq. 3.10), ``(log alpha (T, k), log P(G))``.

    The plain reference recursion with ``scipy.special.logsumexp`` (tests
    compare :func:`forward_backward` against it).  ``log alpha`` is
    unnormalised (joint with g_1..g_t).
    """
    T, k = log_b.shape
    la = np.empty((T, k))
    la[0] = log_startprob + log_b[0]
    for t in range(1, T):
        la[t] = logsumexp(la[t - 1][:, None] + log_transmat, axis=0) + log_b[t]
    return la, float(logsumexp(la[-1]))


def _backward_log(log_b: np.ndarray, log_transmat: np.ndarray) -> np.ndarray:
    T, k = log_b.shape
    lb = np.zeros((T, k))
    for t in range(T - 2, -1, -1):
        lb[t] = logsumexp(log_transmat + (log_b[t + 1] + lb[t + 1])[None, :], axis=1)
    return lb


def _forward_log_np(log_b: np.ndarray, log_startprob: np.ndarray, log_transmat: np.ndarray) -> np.ndarray:
    """Log-space forward lattice ``log alpha (T, k)`` in plain numpy (fallback of :func:`_lattices`).

    Each step is ``log sum_i exp(log alpha_{t-1}(i) + log P_ij)`` with the
    maximum over ``i`` factored out per column, so no entry underflows.
    """
    T, k = log_b.shape
    la = np.empty((T, k))
    la[0] = log_startprob + log_b[0]
    for t in range(1, T):
        M = la[t - 1][:, None] + log_transmat
        m = M.max(axis=0)
        finite = np.isfinite(m)
        safe = np.where(finite, m, 0.0)
        with np.errstate(divide="ignore"):
            la[t] = np.where(finite, safe + np.log(np.exp(M - safe).sum(axis=0)), -np.inf) + log_b[t]
    return la


def _backward_log_np(log_b: np.ndarray, log_transmat: np.ndarray) -> np.ndarray:
    T, k = log_b.shape
    lb = np.zeros((T, k))
    for t in range(T - 2, -1, -1):
        M = log_transmat + (log_b[t + 1] + lb[t + 1])[None, :]
        m = M.max(axis=1)
        finite = np.isfinite(m)
        safe = np.where(finite, m, 0.0)
        with np.errstate(divide="ignore"):
            lb[t] = np.where(finite, safe + np.log(np.exp(M - safe[:, None]).sum(axis=1)), -np.inf)
    return lb


def _lattices(log_b: np.ndarray, startprob: np.ndarray, transmat: np.ndarray, smooth: bool):
    """``(log alpha (T, k), log beta (T, k) or None)``, exact in log space.

    hmmlearn's compiled log-space recursions (``hmmlearn._hmmc``, a private
    module of hmmlearn 0.3.x, hence the pin ``hmmlearn>=0.3,<0.4``) when
    available, else the numpy versions above (same numbers, a few times slower).
    """
    log_b = np.ascontiguousarray(log_b, dtype=float)
    pi = np.ascontiguousarray(startprob, dtype=float)
    P = np.ascontiguousarray(transmat, dtype=float)
    if _hmmc is not None:
        with np.errstate(divide="ignore"):
            _, la = _hmmc.forward_log(pi, P, log_b)
            lb = _hmmc.backward_log(pi, P, log_b) if smooth else None
        return la, lb
    with np.errstate(divide="ignore"):
        log_pi, log_P = np.log(pi), np.log(P)
    return _forward_log_np(log_b, log_pi, log_P), (_backward_log_np(log_b, log_P) if smooth else None)


def _normalise_rows(log_p: np.ndarray) -> np.ndarray:
    """``exp(log_p)`` with every row scaled to sum to one (log-sum-exp per row)."""
    m = log_p.max(axis=1, keepdims=True)
    p = np.exp(log_p - m)
    p /= p.sum(axis=1, keepdims=True)
    return p


def forward_backward(log_b: np.ndarray, startprob: np.ndarray, transmat: np.ndarray,
                     *, smooth: bool = True):
    """Filtered and smoothed state posteriors of one sequence (Eqs. 3.10-3.13).

    Args:
      log_b: ``(T, k)`` log emission densities ``log z_i(g_t)``.
      startprob: ``(k,)`` prior ``pi``; transmat: ``(k, k)`` ``P_ij``.
      smooth: also run the backward pass.

    Returns ``(filtered (T, k), smoothed (T, k) or None, log P(G))`` where
    ``filtered[t] = P(s_t | g_1..g_t)`` and ``smoothed[t] = P(s_t | G)``.

    Both passes run in log space (Eqs. 3.10 and 3.12 with log-sum-exp), so
    they stay exact when transitions are zero and emission log-densities
    differ by hundreds or thousands of nats: a probability-space (Rabiner
    scaled) recursion loses states whose probability underflows and can
    overflow in the backward pass (docs/method.md section 4).  The filtered
    posteriors equal those of the streaming filter
    (:meth:`drake_skill.reward.pomrp.Pomrp.filter_update`).

    Hand-written rather than hmmlearn's ``predict_proba`` because the
    per-step online reward needs the *filtered* posterior, which hmmlearn's
    public API does not return, and one pass here gives filtered, smoothed
    and ``log P(G)`` together without hmmlearn's per-call validation and
    density recomputation.
    """
    log_b = np.asarray(log_b, dtype=float)
    if log_b.ndim != 2 or log_b.shape[0] == 0:
        raise ValueError(f"log_b: expected shape (T >= 1, k), got {log_b.shape}")
    la, lb = _lattices(log_b, startprob, transmat, smooth)
    log_lik = float(logsumexp(la[-1]))
    if not np.isfinite(log_lik):
        raise ValueError("forward_backward: the sequence has probability zero under the chain "
                         "(no state sequence allowed by startprob/transmat explains it)")
    filtered = _normalise_rows(la)
    if not smooth:
        return filtered, None, log_lik
    return filtered, _normalise_rows(la + lb), log_lik


def viterbi(log_b: np.ndarray, startprob: np.ndarray, transmat: np.ndarray):
    """Most likely state path (Viterbi, log space): ``(path int (T,), log prob)``."""
    T, k = log_b.shape
    with np.errstate(divide="ignore"):
        log_pi, log_P = np.log(startprob), np.log(transmat)
    delta = log_pi + log_b[0]
    back = np.empty((T, k), dtype=int)
    for t in range(1, T):
        cand = delta[:, None] + log_P  # (from, to)
        back[t] = np.argmax(cand, axis=0)
        delta = cand[back[t], np.arange(k)] + log_b[t]
    path = np.empty(T, dtype=int)
    path[-1] = int(np.argmax(delta))
    for t in range(T - 1, 0, -1):
        path[t - 1] = back[t, path[t]]
    return path, float(delta[path[-1]])


def _change_point_labels(s: np.ndarray, k: int) -> np.ndarray:
    """Least-squares split of one sequence ``s: (n, d)`` into ``k`` contiguous segments.

    Exact dynamic programme over change points (``O(k n^2)``), the classic
    piecewise-constant segmentation; returns each frame's segment index.
    Unlike equal time cuts it does not put several segments on the long
    stretch a demonstration spends in its final sub-goal.
    """
    n = len(s)
    c1 = np.vstack([np.zeros(s.shape[1]), np.cumsum(s, axis=0)])  # (n + 1, d)
    c2 = np.r_[0.0, np.cumsum((s * s).sum(axis=1))]  # (n + 1,)
    i = np.arange(n + 1)[:, None]
    j = np.arange(n + 1)[None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        seg = c1[None, :, :] - c1[:, None, :]
        cost = (c2[None, :] - c2[:, None]) - (seg * seg).sum(axis=2) / (j - i)
    cost[j <= i] = np.inf  # cost[i, j]: SSE of frames i..j-1
    F = cost[0].copy()  # best cost of frames 0..j-1 in m + 1 segments
    arg = np.zeros((k, n + 1), dtype=int)
    for m in range(1, k):
        total = F[:, None] + cost  # (i, j)
        arg[m] = np.argmin(total, axis=0)
        F = total[arg[m], np.arange(n + 1)]
    labels = np.empty(n, dtype=int)
    end = n
    for m in range(k - 1, -1, -1):
        start = arg[m, end] if m > 0 else 0
        labels[start:end] = m
        end = start
    return labels


def _segmental_kmeans(segs: list[np.ndarray], labels: list[np.ndarray], k: int,
                      n_rounds: int = 10) -> np.ndarray:
    """Left-to-right segmental k-means: the initial state labels of all frames.

    Alternates (a) state means from the frames of each label and (b) the
    least-squares split of every demonstration into states 0..k-1 in order
    (a Viterbi alignment on a strict left-to-right chain with squared
    Euclidean costs; each demonstration may end before state k-1).  A few
    rounds put the means on the sub-goals the demonstrations share, which
    starts Baum-Welch far closer to the optimum than equal time cuts alone.
    """
    labels = [lab.copy() for lab in labels]
    X = np.concatenate(segs)
    for _ in range(n_rounds):
        lab = np.concatenate(labels)
        means = np.array([X[lab == j].mean(axis=0) if np.any(lab == j) else X.mean(axis=0)
                          for j in range(k)])
        changed = False
        for i, s in enumerate(segs):
            cost = ((s[:, None, :] - means[None, :, :]) ** 2).sum(axis=2)  # (n, k)
            n = len(s)
            D = np.full((n, k), np.inf)
            came_from_prev = np.zeros((n, k), dtype=bool)
            D[0, 0] = cost[0, 0]
            for t in range(1, n):
                stay, move = D[t - 1], np.r_[np.inf, D[t - 1, :-1]]
                came_from_prev[t] = move < stay
                D[t] = np.minimum(stay, move) + cost[t]
            path = np.empty(n, dtype=int)
            path[-1] = int(np.argmin(D[-1]))
            for t in range(n - 1, 0, -1):
                path[t - 1] = path[t] - 1 if came_from_prev[t, path[t]] else path[t]
            if not np.array_equal(path, labels[i]):
                labels[i] = path
                changed = True
        if not changed:
            break
    return np.concatenate(labels)


def _full_covars(model) -> np.ndarray:
    """A fitted hmmlearn GaussianHMM's covariances as full matrices ``(k, d, d)``.

    hmmlearn's public ``covars_`` property (full matrices for every
    covariance type), with one correction: hmmlearn 0.3's spherical M-step
    stores ``(k, d)`` equal variances where its property expects ``(k,)``,
    so the property returns ``(k d, d, d)``: each state's ``d`` matrices are
    averaged back into one (they are equal; the mean is also right for the
    ``(k,)`` storage of an unfitted model, where there is one per state).
    """
    k, d = model.n_components, model.means_.shape[1]
    c = np.asarray(model.covars_, dtype=float)
    if model.covariance_type == "spherical" and c.shape[0] != k:
        c = c.reshape(k, -1, d, d).mean(axis=1)
    return np.array(c, dtype=float).reshape(k, d, d)


def _split(lengths: np.ndarray) -> list[slice]:
    ends = np.cumsum(lengths)
    return [slice(int(e - n), int(e)) for e, n in zip(ends, lengths)]


class GoalHMM:
    """Gaussian-emission HMM goal model with state count chosen by AIC/BIC.

    scikit-learn style: the constructor takes hyper-parameters only (those of
    :class:`GoalModelConfig`), :meth:`fit` learns, fitted attributes end in
    ``_``:

    * ``n_states_`` (k), ``n_features_in_`` (d), ``covariance_type_``,
      ``restart_`` (index of the winning restart), ``converged_``, ``n_iter_``;
    * ``startprob_ (k,)``, ``transmat_ (k, k)``, ``means_ (k, d)``,
      ``covars_ (k, d, d)`` (always full matrices, whatever the type);
    * ``terminal_states_`` (sorted int array): the Viterbi final states of the
      demonstrations (the same rule the success verdict uses, so every
      demonstration passes its own verdict);
    * ``lengths_`` demonstration lengths, ``log_likelihood_`` total (nats),
      ``loglik_per_step_ (n_demos,)`` each demonstration's
      ``log P(G) / T`` in nats per frame (the range the verdict may check);
    * ``criterion_table_``: one dict per candidate (k, covariance_type,
      n_params, log_likelihood, aic, bic, restart, converged, n_iter, status
      "ok" / "degenerate" / "failed"), JSON-able.

    ``converged`` means EM stopped on the tolerance before the iteration
    budget with no likelihood drop beyond rounding (read from
    ``monitor_.history``).  Per candidate, non-degenerate then converged
    restarts are preferred, then the highest log-likelihood.
    """

    def __init__(self, n_states_min: int = 2, n_states_max: int = 8, criterion: str = "aic",
                 covariance_types=("diag", "full"), n_restarts: int = 4, n_iter: int = 100,
                 tol: float = 1e-3, covar_reg: float = 1e-3, random_state: int = 0):
        self.n_states_min = n_states_min
        self.n_states_max = n_states_max
        self.criterion = criterion
        self.covariance_types = covariance_types
        self.n_restarts = n_restarts
        self.n_iter = n_iter
        self.tol = tol
        self.covar_reg = covar_reg
        self.random_state = random_state

    @classmethod
    def from_config(cls, config: GoalModelConfig) -> "GoalHMM":
        return cls(**{f: getattr(config, f) for f in GoalModelConfig.__dataclass_fields__})

    def get_params(self) -> dict[str, Any]:
        return {
            "n_states_min": int(self.n_states_min),
            "n_states_max": int(self.n_states_max),
            "criterion": str(self.criterion),
            "covariance_types": [str(c) for c in self.covariance_types],
            "n_restarts": int(self.n_restarts),
            "n_iter": int(self.n_iter),
            "tol": float(self.tol),
            "covar_reg": float(self.covar_reg),
            "random_state": int(self.random_state),
        }

    # ------------------------------------------------------------------ fit
    def _check_params(self):
        if self.criterion not in CRITERIA:
            raise ValueError(f"criterion: {self.criterion!r}, expected one of {CRITERIA}")
        cts = list(self.covariance_types)
        if not cts or any(c not in COVARIANCE_TYPES for c in cts):
            raise ValueError(f"covariance_types: {cts!r}, expected a non-empty subset of {COVARIANCE_TYPES}")
        if not (1 <= int(self.n_states_min) <= int(self.n_states_max)):
            raise ValueError(
                f"n_states_min, n_states_max: ({self.n_states_min}, {self.n_states_max}), "
                "expected 1 <= n_states_min <= n_states_max")
        if int(self.n_restarts) < 1 or int(self.n_iter) < 1:
            raise ValueError(f"n_restarts, n_iter: ({self.n_restarts}, {self.n_iter}), expected >= 1")
        if not (self.tol > 0 and self.covar_reg > 0):
            raise ValueError(f"tol, covar_reg: ({self.tol}, {self.covar_reg}), expected > 0")

    def fit(self, X, lengths=None) -> "GoalHMM":
        """Fits the goal model on all demonstrations of a skill.

        Args:
          X: ``(N, d)`` goal data of every demonstration stacked in time.
          lengths: frames per demonstration (sum ``N``); ``None`` = one.

        Every candidate ``k`` in ``[n_states_min, min(n_states_max, shortest
        demonstration)]`` and covariance type is fitted with ``n_restarts``
        Baum-Welch runs; the candidate with the smallest criterion
        ``AIC = -2 log L + 2 p`` (or ``BIC = -2 log L + p log N``, ``N``
        frames) wins, with ``p`` from :func:`n_free_parameters`.

        A run is *degenerate* when some state explains fewer frames (summed
        smoothed posteriors) than its covariance needs: ``d + 1`` for full,
        2 for diag/spherical.  Such a state's density is bounded only by the
        regulariser, so its likelihood (and AIC) is spuriously good; with
        2-3 demonstrations this otherwise makes AIC pick many full-covariance
        states.  Degenerate candidates are chosen only if nothing else fits.

        Raises ValueError on bad input, including a demonstration shorter
        than ``n_states_min``.
        """
        self._check_params()
        X, lengths = check_sequences(X, lengths)
        k_min, k_max = int(self.n_states_min), int(self.n_states_max)
        if lengths.min() < k_min:
            i = int(np.argmin(lengths))
            raise ValueError(
                f"lengths: demonstration {i} has {int(lengths[i])} frames, fewer than the smallest "
                f"state count n_states_min={k_min}; expected every demonstration to have >= {k_min} frames")
        k_max = min(k_max, int(lengths.min()))
        N, d = X.shape
        eps = float(self.covar_reg) * regulariser_scale(X)

        table = []
        best = None
        # Single-threaded BLAS: these matrices are tiny, and thread hand-offs on a
        # busy machine made hmmlearn's per-state triangular solves ~5x slower.
        with threadpool_limits(limits=1):
            candidates = [(k, ct) for k in range(k_min, k_max + 1) for ct in self.covariance_types]
            runs = [self._fit_candidate(X, lengths, k, ct, eps) for k, ct in candidates]
        for (k, ct), run in zip(candidates, runs):
            p = n_free_parameters(k, d, ct)
            row = {"k": k, "covariance_type": ct, "n_params": p}
            if run is None:
                row.update(status="failed", log_likelihood=None, aic=None, bic=None,
                           restart=None, converged=False, n_iter=None)
                table.append(row)
                continue
            ll = run["log_likelihood"]
            row.update(status="degenerate" if run["degenerate"] else "ok", log_likelihood=ll,
                       aic=float(-2 * ll + 2 * p), bic=float(-2 * ll + p * np.log(N)),
                       restart=run["restart"], converged=run["converged"], n_iter=run["n_iter"])
            table.append(row)
            # Candidates whose states all explain enough frames come first.
            key = (run["degenerate"], row[self.criterion])
            if best is None or key < best[0]:
                best = (key, run, row)
        if best is None:
            raise RuntimeError("GoalHMM.fit: every Baum-Welch run produced non-finite parameters")
        _, run, row = best
        self.criterion_table_ = table
        self.n_states_ = int(row["k"])
        self.n_features_in_ = d
        self.covariance_type_ = row["covariance_type"]
        self.restart_ = int(run["restart"])
        self.converged_ = bool(run["converged"])
        self.n_iter_ = int(run["n_iter"])
        self.startprob_ = run["startprob"]
        self.transmat_ = run["transmat"]
        self.means_ = run["means"]
        self.covars_ = run["covars"]
        self.lengths_ = lengths.copy()
        self._prepare()
        per_step, finals = [], []
        for sl in _split(lengths):
            log_b = self.log_emission(X[sl])
            _, _, ll = forward_backward(log_b, self.startprob_, self.transmat_, smooth=False)
            per_step.append(ll / (sl.stop - sl.start))
            finals.append(viterbi(log_b, self.startprob_, self.transmat_)[0][-1])
        self.loglik_per_step_ = np.array(per_step)
        self.log_likelihood_ = float(np.dot(self.loglik_per_step_, lengths))
        self.terminal_states_ = np.unique(np.array(finals, dtype=int))
        return self

    def _inits(self, X, lengths, k, ct_index, eps):
        """Yields ``(restart, startprob, transmat, means, covars_full)`` initialisations."""
        segs = [X[sl] for sl in _split(lengths)]
        d = X.shape[1]
        glob_var = np.diag(np.var(X, axis=0) + eps)
        for r in range(int(self.n_restarts)):
            rng = np.random.default_rng([int(self.random_state), k, ct_index, r])
            if r % 2 == 0:
                # Time segments, each demonstration's least-squares change points
                # for r = 0 and random (Dirichlet) ones later, then refined by
                # left-to-right segmental k-means.
                labels = []
                for s in segs:
                    if r == 0:
                        labels.append(_change_point_labels(s, k))
                        continue
                    n = len(s)
                    frac = rng.dirichlet(np.full(k, 2.0))
                    cuts = np.round(np.cumsum(frac)[:-1] * n).astype(int)
                    lab = np.searchsorted(cuts, np.arange(n), side="right")
                    labels.append(np.minimum(lab, k - 1))
                lab = _segmental_kmeans(segs, labels, k)
            else:
                from sklearn.cluster import KMeans

                km = KMeans(n_clusters=k, n_init=1, random_state=int(rng.integers(2**31 - 1)))
                raw = km.fit_predict(X)
                # Order clusters by the mean relative time of their frames.
                rel_t = np.concatenate([np.linspace(0.0, 1.0, n) for n in lengths])
                order = np.argsort([rel_t[raw == j].mean() if np.any(raw == j) else 2.0 for j in range(k)])
                rank = np.empty(k, dtype=int)
                rank[order] = np.arange(k)
                lab = rank[raw]
            means = np.empty((k, d))
            covs = np.empty((k, d, d))
            durations = np.empty(k)
            m0 = d + 2.0  # pseudo-frames of the global diagonal covariance
            for j in range(k):
                pts = X[lab == j]
                n_j = len(pts)
                if n_j == 0:
                    pts = X[rng.integers(len(X), size=1)]
                    n_j = 1
                means[j] = pts.mean(axis=0)
                S = np.cov(pts.T, bias=True) if n_j > 1 else np.zeros((d, d))
                covs[j] = (n_j * np.atleast_2d(S) + m0 * glob_var / k) / (n_j + m0) + eps * np.eye(d)
                durations[j] = max(n_j / len(lengths), 1.0)
            stay = np.clip(1.0 - 1.0 / durations, 0.5, 0.98)
            trans = np.full((k, k), _INIT_LEAK / max(k - 1, 1))
            for j in range(k):
                if j + 1 < k:
                    trans[j, j] = stay[j] * (1 - _INIT_LEAK)
                    trans[j, j + 1] = (1 - stay[j]) * (1 - _INIT_LEAK)
                else:
                    trans[j, j] = 1 - _INIT_LEAK
            if k == 1:
                trans[:] = 1.0
            trans /= trans.sum(axis=1, keepdims=True)
            start = np.full(k, _INIT_LEAK / max(k - 1, 1))
            start[0] = 1.0 - _INIT_LEAK if k > 1 else 1.0
            start /= start.sum()
            yield r, start, trans, means, covs

    def _fit_candidate(self, X, lengths, k, ct, eps):
        """Runs the restarts of one ``(k, covariance type)``; returns the best run or None."""
        from hmmlearn.hmm import GaussianHMM

        d = X.shape[1]
        ct_index = COVARIANCE_TYPES.index(ct)
        prior = {
            "spherical": np.full((k, d), eps),  # its M-step works on (k, d) variances
            "diag": np.full((k, d), eps),
            "full": np.broadcast_to(eps * np.eye(d), (k, d, d)).copy(),
            "tied": eps * np.eye(d),
        }[ct]
        best = None
        hmm_log = logging.getLogger("hmmlearn")
        old_level = hmm_log.level
        hmm_log.setLevel(logging.ERROR)  # we read the likelihood drops from history ourselves
        try:
            for r, start, trans, means, covs in self._inits(X, lengths, k, ct_index, eps):
                model = GaussianHMM(
                    n_components=k, covariance_type=ct, min_covar=eps,
                    # Tiny pull toward the data mean so a state that loses all its
                    # frames gets a finite mean instead of 0/0 = NaN.
                    means_prior=np.broadcast_to(X.mean(axis=0), (k, d)).copy(), means_weight=1e-8,
                    covars_prior=prior,
                    # Full/tied divide by (covars_weight - d) + occupancy: keep it > 0.
                    covars_weight=(d + 1e-8) if ct in ("full", "tied") else 1.0,
                    n_iter=int(self.n_iter), tol=float(self.tol), init_params="", params="stmc",
                    random_state=int(self.random_state), implementation="log")
                model.startprob_ = start
                model.transmat_ = trans
                model.means_ = means
                model.covars_ = {
                    "spherical": np.array([np.trace(c) / d for c in covs]),
                    "diag": np.array([np.diag(c) for c in covs]),
                    "full": covs,
                    "tied": covs.mean(axis=0),
                }[ct]
                try:
                    with np.errstate(all="ignore"):
                        model.fit(X, lengths)
                except (ValueError, np.linalg.LinAlgError):
                    continue
                run = self._validate_run(model, X, lengths, r)
                if run is None:
                    continue
                key = (not run["degenerate"], run["converged"], run["log_likelihood"])
                if best is None or key > (not best["degenerate"], best["converged"], best["log_likelihood"]):
                    best = run
        finally:
            hmm_log.setLevel(old_level)
        return best

    def _validate_run(self, model, X, lengths, r):
        """Checks one EM run; returns its parameters and diagnostics or None if unusable."""
        start = np.asarray(model.startprob_, dtype=float).copy()
        trans = np.asarray(model.transmat_, dtype=float).copy()
        means = np.asarray(model.means_, dtype=float).copy()
        covars = _full_covars(model)
        if not all(np.all(np.isfinite(a)) for a in (start, trans, means, covars)):
            return None
        # A state that received no frames keeps an all-zero row: make it absorbing.
        dead = trans.sum(axis=1) <= 0
        trans[dead] = np.eye(len(trans))[dead]
        trans /= trans.sum(axis=1, keepdims=True)
        start /= start.sum()
        try:
            U, log_norm = _precision_cholesky(covars)
        except np.linalg.LinAlgError:
            return None
        ll = 0.0
        occupancy = np.zeros(len(start))
        for sl in _split(lengths):
            log_b = gaussian_log_density(X[sl], means, U, log_norm)
            _, gamma, ll_seq = forward_backward(log_b, start, trans)
            ll += ll_seq
            occupancy += gamma.sum(axis=0)
        if not np.isfinite(ll):
            return None
        # A state's covariance must be estimable from the frames it explains
        # (d + 1 for a full matrix, 2 for a variance); below that only the
        # regulariser bounds its density and the likelihood is spuriously high.
        d = means.shape[1]
        need = {"full": d + 1.0, "diag": 2.0, "spherical": 2.0, "tied": 0.0}[model.covariance_type]
        degenerate = bool(occupancy.min() < need)
        hist = np.array(model.monitor_.history, dtype=float)
        n_it = len(hist)
        # Converged = stopped by the tolerance (not by the budget) with no real drop.
        deltas = np.diff(hist)
        drop_tol = 1e-8 * max(1.0, abs(hist[-1])) if n_it else 0.0
        converged = bool(
            n_it >= 2 and n_it < int(self.n_iter)
            and np.all(deltas >= -drop_tol) and deltas[-1] < float(self.tol))
        return {"restart": r, "startprob": start, "transmat": trans, "means": means,
                "covars": covars, "log_likelihood": float(ll), "converged": converged, "n_iter": n_it,
                "degenerate": degenerate, "min_occupancy": float(occupancy.min())}

    # ------------------------------------------------------------ inference
    def _prepare(self):
        """Caches the precision Cholesky factors used by every density evaluation."""
        self._prec_chol, self._log_norm = _precision_cholesky(self.covars_)

    def _check_fitted(self):
        if not hasattr(self, "means_"):
            raise RuntimeError("GoalHMM: not fitted; call fit() or from_arrays() first")

    def log_emission(self, G) -> np.ndarray:
        """``log z_i(g_t)`` for one sequence ``G: (T, d)`` -> ``(T, k)``."""
        self._check_fitted()
        G, _ = check_sequences(G, name="G", n_features=self.n_features_in_)
        return gaussian_log_density(G, self.means_, self._prec_chol, self._log_norm)

    def filtered_posteriors(self, G) -> np.ndarray:
        """``P(s_t | g_1..g_t)``, ``(T, k)``, for one sequence ``G: (T, d)``."""
        return forward_backward(self.log_emission(G), self.startprob_, self.transmat_, smooth=False)[0]

    def predict_proba(self, G) -> np.ndarray:
        """Smoothed posteriors ``P(s_t | G)`` (Eq. 3.13), ``(T, k)``, for one sequence."""
        return forward_backward(self.log_emission(G), self.startprob_, self.transmat_)[1]

    def score(self, X, lengths=None) -> float:
        """Total log-likelihood ``sum log P(G | lambda)`` (Eq. 3.11) in nats."""
        self._check_fitted()
        X, lengths = check_sequences(X, lengths, n_features=self.n_features_in_)
        total = 0.0
        for sl in _split(lengths):
            log_b = gaussian_log_density(X[sl], self.means_, self._prec_chol, self._log_norm)
            total += forward_backward(log_b, self.startprob_, self.transmat_, smooth=False)[2]
        return float(total)

    def decode(self, G) -> np.ndarray:
        """Viterbi state path of one sequence ``G: (T, d)`` -> ``(T,)`` ints."""
        return viterbi(self.log_emission(G), self.startprob_, self.transmat_)[0]

    def sample(self, n_frames: int, random_state=None):
        """Samples ``(G (n, d), states (n,))`` from the fitted model (for tests and demos)."""
        self._check_fitted()
        rng = np.random.default_rng(random_state)
        k, d = self.n_states_, self.n_features_in_
        states = np.empty(n_frames, dtype=int)
        s = rng.choice(k, p=self.startprob_)
        L = np.linalg.cholesky(self.covars_)
        G = np.empty((n_frames, d))
        for t in range(n_frames):
            states[t] = s
            G[t] = self.means_[s] + L[s] @ rng.standard_normal(d)
            s = rng.choice(k, p=self.transmat_[s])
        return G, states

    # ------------------------------------------------------------ save/load
    _ARRAYS = ("startprob_", "transmat_", "means_", "covars_", "terminal_states_", "lengths_",
               "loglik_per_step_")

    def to_arrays(self) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """``(arrays, metadata)``: numeric arrays for npz and JSON-able metadata (no pickle)."""
        self._check_fitted()
        arrays = {name.rstrip("_"): np.asarray(getattr(self, name)) for name in self._ARRAYS}
        meta = {
            "params": self.get_params(),
            "n_states": self.n_states_,
            "n_features": self.n_features_in_,
            "covariance_type": self.covariance_type_,
            "restart": self.restart_,
            "converged": self.converged_,
            "n_iter": self.n_iter_,
            "log_likelihood": self.log_likelihood_,
            "criterion_table": self.criterion_table_,
        }
        return arrays, meta

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray], metadata: dict[str, Any],
                    prefix: str = "") -> "GoalHMM":
        """Rebuilds a fitted model from :meth:`to_arrays` output, validated as strictly as a fit.

        Raises ValueError naming the array (with ``prefix``, e.g. the key in a
        skill's ``arrays.npz``) when an array is missing, has the wrong shape,
        is not finite, a probability vector or stochastic row does not sum to
        one, a covariance is not symmetric positive definite, a terminal state
        does not exist, or the metadata disagree with the arrays.
        """
        missing = [prefix + n.rstrip("_") for n in cls._ARRAYS if n.rstrip("_") not in arrays]
        if missing:
            raise ValueError(f"missing array(s) {missing}")
        try:
            self = cls(**metadata.get("params", {}))
        except TypeError as e:
            raise ValueError(f"goal-model metadata 'params': {e}") from e
        for name in cls._ARRAYS:
            value = np.array(arrays[name.rstrip("_")])
            if value.dtype.kind not in "fiub":
                raise ValueError(f"{prefix}{name.rstrip('_')}: dtype {value.dtype}, expected numbers")
            setattr(self, name, value.astype(float) if name not in ("terminal_states_", "lengths_") else value)
        _validate_fitted_arrays(self, prefix)
        k, d = self.means_.shape
        for key, actual in (("n_states", k), ("n_features", d)):
            if key in metadata and int(metadata[key]) != actual:
                raise ValueError(f"goal-model metadata '{key}' = {metadata[key]} disagrees with "
                                 f"{prefix}means of shape {self.means_.shape}")
        self.n_states_, self.n_features_in_ = k, d
        self.covariance_type_ = str(metadata.get("covariance_type", "full"))
        if self.covariance_type_ not in COVARIANCE_TYPES:
            raise ValueError(f"goal-model metadata 'covariance_type' = {self.covariance_type_!r}, "
                             f"expected one of {COVARIANCE_TYPES}")
        self.restart_ = int(metadata.get("restart", 0))
        self.converged_ = bool(metadata.get("converged", True))
        self.n_iter_ = int(metadata.get("n_iter", 0))
        self.log_likelihood_ = float(metadata.get("log_likelihood", np.nan))
        self.criterion_table_ = list(metadata.get("criterion_table", []))
        self._prepare()
        return self


def _validate_fitted_arrays(hmm: "GoalHMM", prefix: str) -> None:
    """Checks a fitted model's arrays (see :meth:`GoalHMM.from_arrays`); casts the integer ones."""
    def fail(name, message):
        raise ValueError(f"{prefix}{name}: {message}")

    means = hmm.means_
    if means.ndim != 2 or means.shape[0] < 1 or means.shape[1] < 1:
        fail("means", f"shape {means.shape}, expected (k, d) with k, d >= 1")
    k, d = means.shape
    shapes = {"startprob": (hmm.startprob_, (k,)), "transmat": (hmm.transmat_, (k, k)),
              "covars": (hmm.covars_, (k, d, d))}
    for name, (value, shape) in shapes.items():
        if value.shape != shape:
            fail(name, f"shape {value.shape}, expected {shape} for {k} states of {d} features "
                 f"(means {means.shape})")
    for name, value in (("means", means), ("startprob", hmm.startprob_), ("transmat", hmm.transmat_),
                        ("covars", hmm.covars_), ("loglik_per_step", hmm.loglik_per_step_)):
        if not np.all(np.isfinite(value)):
            fail(name, "contains NaN or inf")
    tol = 1e-6
    if np.any(hmm.startprob_ < 0) or abs(hmm.startprob_.sum() - 1.0) > tol:
        fail("startprob", f"not a probability vector (sum {hmm.startprob_.sum():.6g}, min "
             f"{hmm.startprob_.min():.3g}); expected non-negative entries summing to 1")
    rows = hmm.transmat_.sum(axis=1)
    if np.any(hmm.transmat_ < 0) or np.any(np.abs(rows - 1.0) > tol):
        i = int(np.argmax(np.abs(rows - 1.0) + (hmm.transmat_ < 0).any(axis=1)))
        fail("transmat", f"row {i} sums to {rows[i]:.6g} (min entry {hmm.transmat_[i].min():.3g}); "
             "expected non-negative rows summing to 1")
    C = hmm.covars_
    if not np.allclose(C, np.swapaxes(C, 1, 2), rtol=1e-9, atol=1e-12):
        fail("covars", "not symmetric")
    try:
        np.linalg.cholesky(C)
    except np.linalg.LinAlgError:
        fail("covars", "a covariance is not positive definite")
    term = np.asarray(hmm.terminal_states_)
    if term.ndim != 1 or term.size == 0 or np.any(term != np.round(term)):
        fail("terminal_states", f"{term.tolist()}, expected a non-empty list of state indices")
    term = term.astype(int)
    if np.any(term < 0) or np.any(term >= k) or len(np.unique(term)) != term.size:
        fail("terminal_states", f"{term.tolist()}, expected distinct states in [0, {k})")
    lengths = np.asarray(hmm.lengths_)
    if lengths.ndim != 1 or lengths.size == 0 or np.any(lengths != np.round(lengths)) or np.any(lengths < 1):
        fail("lengths", f"{lengths.tolist()}, expected demonstration frame counts >= 1")
    if hmm.loglik_per_step_.shape != lengths.shape:
        fail("loglik_per_step", f"shape {hmm.loglik_per_step_.shape}, expected one value per "
             f"demonstration {lengths.shape}")
    hmm.terminal_states_ = np.sort(term)
    hmm.lengths_ = lengths.astype(int)
