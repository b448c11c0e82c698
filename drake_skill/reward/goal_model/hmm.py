"""The goal model: a Gaussian HMM over goal features chosen by an information criterion
(thesis 6.5, Eq. 4.1), its inference and its plain-array I/O."""

from __future__ import annotations

import logging
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from drake_skill.reward.goal_model.config import (_INIT_LEAK, check_sequences, COVARIANCE_TYPES, CRITERIA,
                                                  GoalModelConfig, n_free_parameters, regulariser_scale)
from drake_skill.reward.goal_model.inference import _precision_cholesky, forward_backward, gaussian_log_density, viterbi
from drake_skill.reward.goal_model.initialisation import _change_point_labels, _full_covars, _segmental_kmeans, _split


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
