"""Inference on a fitted Gaussian HMM: log emission densities, log-space forward-backward
(hmmlearn's compiled recursions where present) and Viterbi."""

from __future__ import annotations

import numpy as np
from scipy.special import logsumexp


try:  # hmmlearn's compiled log-space recursions (private module; see _lattices)
    from hmmlearn import _hmmc
    if not all(hasattr(_hmmc, name) for name in ("forward_log", "backward_log")):
        _hmmc = None
except ImportError:  # pragma: no cover - depends on the hmmlearn build
    _hmmc = None


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
