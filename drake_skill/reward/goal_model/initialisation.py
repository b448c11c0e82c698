"""Deterministic initialisation of the HMM's EM runs: change points along each sequence and
segmental k-means, left-to-right."""

from __future__ import annotations

import numpy as np


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
