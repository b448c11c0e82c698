"""Learned rewards: the goal HMM as a POMRP (docs/method.md section 4, thesis ch. 4).

For an execution's goal data ``G = g_1..g_T`` (``G: (T, d)``, 10 Hz frames):

* dense per-step reward, Eq. 4.4: ``h(G, t) = sum_s v(s) P(s_t = s | G)``
  with the smoothed (forward-backward) posterior;
* return, Eq. 4.5: ``R(G) = sum_t h(G, t)``, the black-box objective;
* the reward available online at ``t`` (for per-step methods, PI^2 and
  PI^2-Cov): ``sum_s v(s) P(s_t = s | g_1..g_t)`` from the filtered posterior,
  and a one-frame log-space filter update for streaming use;
* sparse verdict: success iff the final state of the Viterbi path is
  terminal (the authors' rule); optionally also the per-frame log-likelihood
  ``log P(G) / T`` must lie within the demonstrations' range widened by a
  margin (:class:`VerdictConfig`);
* off-model guard (a deliberate extension of the thesis, docs/method.md
  section 4, "Observations the goal model cannot explain";
  :class:`OffModelConfig`): each frame's log-likelihood
  ``l_t = max_j log N(g_t; x_j, S)`` (nats) against the demonstration
  frames ``x_j``, with ``S`` the covariance of all demonstration frames (the
  spread the demonstrations covered; the per-state covariances, fitted on two
  or three demonstrations, are far too tight to judge a new object pose), is
  compared with the range the demonstrations show against each other:
  ``l_lo`` = the ``quantile`` (5 %) of every demonstration frame's ``l``
  against the *other* demonstrations' frames.  The dense reward of frame
  ``t`` is multiplied by ``w_t = min(1, exp(l_t - (l_lo - margin)))`` (1 on
  everything as close to the demonstrations as they are to each other, the
  likelihood ratio below), and the verdict also requires the final frame to
  be explained (``l_T >= l_lo - margin``).  ``OffModelConfig(enabled=False)``
  is the thesis's plain form.

* progress reward (``PomrpConfig.reward = "progress"``; docs/method.md section
  4.4, an extension): the potential ``Phi_t = w_t p_t``, with
  ``p_t = (g_t - s) . (e - s) / |e - s|^2`` the progress along the demonstrated
  change (``s``, ``e``: the demonstrations' mean first and last frames, so a
  demonstration's start is at 0 and their average end at 1), gives the per-step
  reward ``h_t = c (Phi_t - Phi_(t-1))`` (``h_1 = 0``; ``c`` =
  ``ProgressConfig.scale``) and the return ``R(G) = max(0, sum_t h_t) =
  c max(0, Phi_T - Phi_1)``: how far the execution moved the object along the
  change the demonstrations showed, from where it started. The verdict:
  ``p_T - p_1 >= (1 - tolerance) x`` the least demonstration's own, and the
  final frame explained. The goal HMM still filters the belief.

Values ``v`` come from :mod:`drake_skill.reward.mrp`; rewards are unitless
(value per frame), returns are sums over frames.
"""

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.special import logsumexp

from drake_skill.reward.goal_model import (
    GoalHMM,
    GoalModelConfig,
    check_sequences,
    forward_backward,
    gaussian_log_density,
    regulariser_scale,
    viterbi,
)
from drake_skill.reward.goal_model.inference import _precision_cholesky
from drake_skill.reward.mrp import MrpConfig, monte_carlo_values

__all__ = ["VerdictConfig", "OffModelConfig", "ProgressConfig", "PomrpConfig", "Pomrp", "fit_pomrp",
           "REWARDS"]

#: What a POMRP's dense reward is: "states" (thesis Eq. 4.4, the MRP values of the
#: belief) or "progress" (along the demonstrated change; docs/method.md section 4.4).
REWARDS = ("states", "progress")


@dataclass
class VerdictConfig:
    """The goal model's success rule (docs/method.md section 4, "Sparse reward").

    Attributes:
      require_likelihood: also require ``log P(G) / T`` (nats per frame) to be
        within ``[min - margin, max + margin]`` of the demonstrations' values
        recorded at fit time.  Off by default (the authors' rule only).
      loglik_margin: the margin in nats per frame.
    """

    require_likelihood: bool = False
    loglik_margin: float = 2.0


@dataclass
class OffModelConfig:
    """The off-model guard on rewards and verdict (docs/method.md section 4; not in the thesis).

    Attributes:
      enabled: weight each frame's dense reward by how well the goal model
        explains it and require an explained final frame for success; False
        gives the thesis's plain Eqs. 4.4-4.5 and verdict.
      margin: nats per frame below ``l_lo`` that still count as explained
        (weight 1).  A project choice: 10 nats is a likelihood ratio of e^-10;
        with ``l_t`` a Gaussian log-density it lets the squared Mahalanobis
        distance (under ``S``) to the nearest demonstration frame exceed the
        demonstrations' own by 20.
      quantile: which quantile of the demonstrations' leave-one-demonstration-out
        ``l`` is ``l_lo`` (0 = the minimum; 0.05 ignores the few transit frames
        where one demonstration moves faster than another).
      covar_reg: ridge added to ``S``, relative to its mean variance (keeps a
        direction the demonstrations never moved in from making ``S`` singular).
    """

    enabled: bool = True
    margin: float = 10.0
    quantile: float = 0.05
    covar_reg: float = 1e-3


@dataclass
class ProgressConfig:
    """The progress reward (docs/method.md section 4.4; not in the thesis).

    Attributes:
      scale: ``c``, the return of an execution that moves the object as far as
        the demonstrations do on average (unitless; of the order of the
        thesis reward's demonstration returns, so that Eq. 5.1's weighting
        ``exp(R / C)`` keeps its sharpness).
      tolerance: the verdict calls an execution a success when its progress
        reaches ``1 - tolerance`` of the least demonstration's (0.05: measured
        in docs/method.md section 4.4).
    """

    scale: float = 1000.0
    tolerance: float = 0.05


@dataclass
class PomrpConfig:
    """Everything :func:`fit_pomrp` needs (loadable with ``yaml_load_typed``).

    reward: "states" (thesis Eq. 4.4-4.5 and the Viterbi verdict) or "progress"
      (:class:`ProgressConfig`; docs/method.md section 4.4).
    """

    goal_model: GoalModelConfig = field(default_factory=GoalModelConfig)
    mrp: MrpConfig = field(default_factory=MrpConfig)
    verdict: VerdictConfig = field(default_factory=VerdictConfig)
    off_model: OffModelConfig = field(default_factory=OffModelConfig)
    reward: str = "states"
    progress: ProgressConfig = field(default_factory=ProgressConfig)


class Pomrp:
    """The goal HMM plus MRP state values: dense rewards, returns and the verdict.

    Args:
      goal_model: a fitted :class:`GoalHMM` (``k`` states, ``d`` features).
      values: ``v (k,)`` state values (:func:`drake_skill.reward.mrp.monte_carlo_values`).
      verdict: :class:`VerdictConfig`.
      info: JSON-able provenance saved with the model (``fit_pomrp`` records
        the MRP settings and horizon ``L`` there).
      off_model: :class:`OffModelConfig` (default: enabled when
        ``frame_loglik_range`` is given, the plain form otherwise).
      frame_loglik_range: ``(min, max)`` of ``l_t`` over the demonstration
        frames (nats); required when the guard is enabled.
      data_covar: ``S (d, d)``, the regularised covariance of all
        demonstration frames; references: ``(N, d)`` the demonstration frames
        ``x_j`` (:func:`fit_pomrp` computes all three).
      reward: "states" or "progress" (:data:`REWARDS`); progress: its
        :class:`ProgressConfig`; progress_line: ``(2, d)`` the demonstrations'
        mean first and last frames ``s``, ``e``; progress_least: the least
        demonstration's own progress ``p_T - p_1`` (both from :func:`fit_pomrp`,
        required for "progress").
    """

    def __init__(self, goal_model: GoalHMM, values, verdict: VerdictConfig | None = None,
                 info: dict[str, Any] | None = None, off_model: OffModelConfig | None = None,
                 frame_loglik_range=None, data_covar=None, references=None, reward: str = "states",
                 progress: ProgressConfig | None = None, progress_line=None, progress_least: float | None = None):
        goal_model._check_fitted()
        v = np.asarray(values, dtype=float)
        k = goal_model.n_states_
        if v.shape != (k,) or not np.all(np.isfinite(v)):
            raise ValueError(f"values: expected {k} finite state values, got shape {v.shape}: {v}")
        self.goal_model = goal_model
        self.values = v
        self.verdict_config = verdict if verdict is not None else VerdictConfig()
        self.info = dict(info or {})  # JSON-able provenance, e.g. the MRP settings
        if not self.verdict_config.loglik_margin >= 0:
            raise ValueError(f"verdict.loglik_margin: expected >= 0, got {self.verdict_config.loglik_margin}")
        if off_model is None:  # the guard needs the demonstrations' range
            off_model = OffModelConfig(enabled=frame_loglik_range is not None)
        self.off_model_config = off_model
        if not (np.isfinite(self.off_model_config.margin) and self.off_model_config.margin >= 0):
            raise ValueError(f"off_model.margin: expected a finite value >= 0 nats, got {self.off_model_config.margin}")
        if frame_loglik_range is not None:
            r = np.asarray(frame_loglik_range, dtype=float)
            if r.shape != (2,) or not np.all(np.isfinite(r)) or r[0] > r[1]:
                raise ValueError(f"frame_loglik_range: expected finite (min, max) nats, got {r}")
            frame_loglik_range = (float(r[0]), float(r[1]))
        if self.off_model_config.enabled and (frame_loglik_range is None or data_covar is None
                                              or references is None):
            raise ValueError("frame_loglik_range, data_covar, references: required with off_model.enabled "
                             "(the demonstrations' l range, frame covariance and frames, recorded by "
                             "fit_pomrp); refit, or pass OffModelConfig(enabled=False) for the thesis's "
                             "plain rewards")
        self.frame_loglik_range = frame_loglik_range
        self.data_covar = None
        if data_covar is not None:
            d = goal_model.n_features_in_
            S = np.asarray(data_covar, dtype=float)
            if S.shape != (d, d) or not np.all(np.isfinite(S)) or not np.allclose(S, S.T):
                raise ValueError(f"data_covar: expected a finite symmetric ({d}, {d}) covariance, got shape {S.shape}")
            try:
                self._om_prec, self._om_log_norm = _precision_cholesky(np.broadcast_to(S, (1, d, d)).copy())
            except np.linalg.LinAlgError as e:
                raise ValueError("data_covar: not positive definite") from e
            self.data_covar = S
        self.references = None
        if references is not None:
            R = np.asarray(references, dtype=float)
            if R.ndim != 2 or R.shape[1] != goal_model.n_features_in_ or len(R) == 0 or not np.all(np.isfinite(R)):
                raise ValueError(f"references: expected finite demonstration frames (N, "
                                 f"{goal_model.n_features_in_}), got shape {R.shape}")
            self.references = R
            if self.data_covar is not None:
                self._om_ref = R @ self._om_prec[0]  # whitened: |(g - x) U|^2 = squared Mahalanobis
        self._init_progress(reward, progress, progress_line, progress_least)
        # Parameters cached once: the reward path must stay well under 1 ms.
        self._startprob = goal_model.startprob_
        self._transmat = goal_model.transmat_
        with np.errstate(divide="ignore"):
            self._log_startprob = np.log(goal_model.startprob_)
            self._log_transmat = np.log(goal_model.transmat_)

    # --------------------------------------------------------------- basics
    @property
    def n_states(self) -> int:
        return self.goal_model.n_states_

    @property
    def n_features(self) -> int:
        return self.goal_model.n_features_in_

    @property
    def terminal_states(self) -> np.ndarray:
        return self.goal_model.terminal_states_

    @property
    def loglik_range(self) -> tuple[float, float]:
        """Accepted ``log P(G) / T`` (nats per frame): demonstrations' min/max -/+ margin."""
        ll = self.goal_model.loglik_per_step_
        m = float(self.verdict_config.loglik_margin)
        return float(ll.min()) - m, float(ll.max()) + m

    def _log_b(self, G) -> np.ndarray:
        return self.goal_model.log_emission(G)

    @property
    def explained_floor(self) -> float:
        """``l_lo - margin`` (nats): frames with ``l_t`` at or above it are explained; -inf when off."""
        if not self.off_model_config.enabled:
            return -np.inf
        return self.frame_loglik_range[0] - float(self.off_model_config.margin)

    def frame_loglik(self, G) -> np.ndarray:
        """``l_t = max_j log N(g_t; x_j, S)`` (nats), ``(T,)``, for checked ``G: (T, d)``."""
        if self.data_covar is None or self.references is None:
            raise ValueError("frame_loglik: this reward has no data_covar/references (saved before the "
                             "off-model guard)")
        return _nearest_loglik(np.asarray(G, dtype=float) @ self._om_prec[0], self._om_ref,
                               float(self._om_log_norm[0]))

    def explained_weights(self, G) -> np.ndarray:
        """``w_t = min(1, exp(l_t - (l_lo - margin)))`` for checked ``G: (T, d)``; all ones when off."""
        if not self.off_model_config.enabled:
            return np.ones(len(G))
        return np.exp(np.minimum(0.0, self.frame_loglik(G) - self.explained_floor))

    def _init_progress(self, reward, progress, line, least) -> None:
        if reward not in REWARDS:
            raise ValueError(f"reward: {reward!r}; expected one of {', '.join(REWARDS)}")
        self.reward_kind = reward
        self.progress_config = progress if progress is not None else ProgressConfig()
        c = self.progress_config
        if not (np.isfinite(c.scale) and c.scale > 0) or not 0.0 <= c.tolerance < 1.0:
            raise ValueError(f"progress: expected scale > 0 and tolerance in [0, 1), got {c}")
        self.progress_line = None if line is None or least is None else np.asarray(line, dtype=float)
        self.progress_least = None if self.progress_line is None else float(least)
        if self.progress_line is None:
            if reward == "progress":
                raise ValueError("progress_line, progress_least: required with reward 'progress' "
                                 "(the demonstrations' mean first and last frames; fit_pomrp records them)")
            return
        d = self.goal_model.n_features_in_
        if self.progress_line.shape != (2, d) or not np.all(np.isfinite(self.progress_line)):
            raise ValueError(f"progress_line: expected finite (2, {d}) first and last frames, "
                             f"got shape {self.progress_line.shape}")
        change = self.progress_line[1] - self.progress_line[0]
        if not float(change @ change) > 0 or not np.isfinite(self.progress_least):
            raise ValueError("progress_line: the demonstrations end where they start in goal space (the "
                             "camera saw no change of the object); progress cannot be measured")
        self._progress_axis = change / float(change @ change)

    def progress(self, G) -> np.ndarray:
        """``p_t = (g_t - s) . (e - s) / |e - s|^2`` (T,): 0 at the demonstrations' mean first frame,
        1 at their mean last frame, for ``G: (T, d)``."""
        if self.progress_line is None:
            raise ValueError("progress: this reward has no progress line (fitted before it existed); refit")
        return self._progress_of(self._checked(G))

    def _progress_of(self, G: np.ndarray) -> np.ndarray:
        """:meth:`progress` of checked goal data."""
        return (G - self.progress_line[0]) @ self._progress_axis

    def _progress_rewards(self, G: np.ndarray) -> np.ndarray:
        """``h_t = c (Phi_t - Phi_(t-1))``, ``h_1 = 0``, with ``Phi_t = w_t p_t``, for checked ``G``."""
        phi = self._progress_of(G) * self.explained_weights(G)
        return float(self.progress_config.scale) * np.diff(phi, prepend=phi[0])

    def _checked(self, G) -> np.ndarray:
        return check_sequences(G, name="G", n_features=self.n_features)[0]

    # -------------------------------------------------------------- rewards
    def posteriors(self, G):
        """``(filtered (T, k), smoothed (T, k), log P(G))`` for ``G: (T, d)``."""
        return forward_backward(self._log_b(G), self._startprob, self._transmat)

    def reward_and_return(self, G) -> tuple[np.ndarray, float]:
        """Dense rewards ``h (T,)`` (Eq. 4.4, times the off-model weight ``w_t``) and return ``R`` (Eq. 4.5);
        with the progress reward, ``h_t = c (Phi_t - Phi_(t-1))`` and ``R = max(0, sum_t h_t)``."""
        G = self._checked(G)
        if self.reward_kind == "progress":
            h = self._progress_rewards(G)
            return h, max(0.0, float(h.sum()))
        _, smoothed, _ = forward_backward(self._log_b(G), self._startprob, self._transmat)
        h = (smoothed @ self.values) * self.explained_weights(G)
        return h, float(h.sum())

    def rewards(self, G) -> np.ndarray:
        """Eq. 4.4: ``h(G, t) = w_t sum_s v(s) P(s_t = s | G)``, ``(T,)`` (``w_t = 1`` in the plain form)."""
        return self.reward_and_return(G)[0]

    def episode_return(self, G) -> float:
        """Eq. 4.5: ``R(G) = sum_t h(G, t)``."""
        return self.reward_and_return(G)[1]

    def filtered_rewards(self, G) -> np.ndarray:
        """Reward available online at each ``t``: ``sum_s v(s) P(s_t = s | g_1..g_t)``, ``(T,)`` (the
        progress reward's ``h_t`` needs no smoothing: the same as :meth:`rewards`)."""
        G = self._checked(G)
        if self.reward_kind == "progress":
            return self._progress_rewards(G)
        filtered, _, _ = forward_backward(self._log_b(G), self._startprob, self._transmat, smooth=False)
        return (filtered @ self.values) * self.explained_weights(G)

    # ------------------------------------------------------------ streaming
    def log_emission_frame(self, g) -> np.ndarray:
        """``log z_i(g)`` of one frame ``g: (d,)`` -> ``(k,)``."""
        g = np.asarray(g, dtype=float)
        if g.shape != (self.n_features,):
            raise ValueError(f"g: expected one frame of shape ({self.n_features},), got {g.shape}")
        if not np.all(np.isfinite(g)):
            raise ValueError(f"g: non-finite goal data {g}")
        gm = self.goal_model
        return gaussian_log_density(g[None, :], gm.means_, gm._prec_chol, gm._log_norm)[0]

    def filter_update(self, log_belief, g, first: bool, previous=None):
        """One step of the forward filter in log space (Eq. 3.10, normalised).

        Args:
          log_belief: ``(k,)`` ``log P(s_{t-1} | g_1..g_{t-1})`` (ignored if ``first``).
          g: ``(d,)`` the new frame ``g_t``.
          first: ``g`` is the first frame (use ``pi`` instead of ``P``).

        Returns ``(log P(s_t | g_1..g_t) (k,), log P(g_t | g_1..g_{t-1}), reward_t)``;
        the second summed over ``t`` is ``log P(G)``, the third is the
        filtered reward ``w_t v . P(s_t | g_1..g_t)`` (the same as
        :meth:`filtered_rewards` at ``t``). With the progress reward the third is
        ``c (Phi(g) - Phi(previous))`` (0 on the first frame), ``previous`` the
        frame before ``g`` (required then).
        """
        log_b = self.log_emission_frame(g)
        if first:
            la = self._log_startprob + log_b
        else:
            lb = np.asarray(log_belief, dtype=float)
            la = logsumexp(lb[:, None] + self._log_transmat, axis=0) + log_b
        c = float(logsumexp(la))
        la = la - c
        if self.reward_kind == "progress":
            if first:
                return la, c, 0.0
            if previous is None:
                raise ValueError("filter_update: the progress reward needs the previous frame")
            pair = self._checked(np.vstack([np.asarray(previous, dtype=float), np.asarray(g, dtype=float)]))
            return la, c, float(self._progress_rewards(pair)[1])
        w = float(self.explained_weights(np.asarray(g, dtype=float)[None, :])[0])
        return la, c, float(np.exp(la) @ self.values) * w

    # -------------------------------------------------------------- verdict
    def verdict_details(self, G) -> dict[str, Any]:
        """The success rule's ingredients for ``G: (T, d)``.

        Keys: ``final_state`` (Viterbi), ``terminal`` (final state in ``T``),
        ``loglik_per_step`` (nats per frame), ``loglik_in_range``,
        ``final_frame_loglik`` (``l_T``, nats), ``final_frame_explained``
        (``l_T >= l_lo - margin``; True when the guard is off), ``success``; with the
        progress reward also ``progress`` (``p_T - p_1``) and ``progress_needed``.
        """
        G = self._checked(G)
        log_b = self._log_b(G)
        path, _ = viterbi(log_b, self._startprob, self._transmat)
        _, _, ll = forward_backward(log_b, self._startprob, self._transmat, smooth=False)
        per_step = ll / len(log_b)
        lo, hi = self.loglik_range
        terminal = bool(np.isin(path[-1], self.terminal_states))
        in_range = bool(lo <= per_step <= hi)
        final_ll = float(self.frame_loglik(G[-1:])[0]) if self.references is not None else np.nan
        explained = bool(not self.off_model_config.enabled or final_ll >= self.explained_floor)
        likely = in_range or not self.verdict_config.require_likelihood
        details = {"final_state": int(path[-1]), "terminal": terminal, "loglik_per_step": float(per_step),
                   "loglik_in_range": in_range, "final_frame_loglik": final_ll,
                   "final_frame_explained": explained}
        if self.reward_kind == "progress":
            p = self._progress_of(G)
            details["progress"] = float(p[-1] - p[0])
            details["progress_needed"] = (1.0 - float(self.progress_config.tolerance)) * self.progress_least
            return {**details, "success": bool(details["progress"] >= details["progress_needed"]
                                               and explained and likely)}
        return {**details, "success": bool(terminal and explained and likely)}

    def verdict(self, G) -> bool:
        """Sparse success: Viterbi final state terminal (with the progress reward: progress
        ``p_T - p_1`` at least ``1 - tolerance`` of the least demonstration's), final frame
        explained (guard on) and, if configured, likelihood in range."""
        return self.verdict_details(G)["success"]

    # ------------------------------------------------------------ save/load
    def to_arrays(self) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """``(arrays, metadata)`` for npz + JSON; goal-model arrays are prefixed ``hmm_``."""
        arrays, meta = self.goal_model.to_arrays()
        out = {f"hmm_{k}": v for k, v in arrays.items()}
        out["values"] = self.values.copy()
        if self.frame_loglik_range is not None:
            out["frame_loglik_range"] = np.array(self.frame_loglik_range)
        if self.data_covar is not None:
            out["data_covar"] = self.data_covar.copy()
        if self.references is not None:
            out["references"] = self.references.copy()
        meta = {"hmm": meta, "info": self.info, "verdict": {
            "require_likelihood": bool(self.verdict_config.require_likelihood),
            "loglik_margin": float(self.verdict_config.loglik_margin)},
            "off_model": dataclasses.asdict(self.off_model_config),
            "reward": self.reward_kind, "progress": dataclasses.asdict(self.progress_config)}
        if self.progress_line is not None:
            out["progress_line"] = self.progress_line.copy()
            meta["progress_least"] = self.progress_least
        return out, meta

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray], metadata: dict[str, Any],
                    prefix: str = "") -> "Pomrp":
        """Inverse of :meth:`to_arrays`; ``prefix`` names the arrays in error messages.

        Metadata without ``off_model`` (written before the guard existed) load
        with the guard off: the demonstrations' ``l_t`` range was not recorded;
        without ``reward``, with the thesis's state reward.
        """
        if "values" not in arrays:
            raise ValueError(f"missing array '{prefix}values'")
        hmm = GoalHMM.from_arrays({k[4:]: v for k, v in arrays.items() if k.startswith("hmm_")},
                                  metadata.get("hmm", {}), prefix=prefix + "hmm_")
        values = np.asarray(arrays["values"])
        if values.shape != (hmm.n_states_,) or not np.all(np.isfinite(values)):
            raise ValueError(f"{prefix}values: expected {hmm.n_states_} finite state values, got shape "
                             f"{values.shape}")
        try:
            verdict = VerdictConfig(**metadata.get("verdict", {}))
            off_model = OffModelConfig(**metadata.get("off_model", {"enabled": False}))
            progress = ProgressConfig(**metadata.get("progress", {}))
        except TypeError as e:
            raise ValueError(f"POMRP metadata: {e}") from e
        return cls(hmm, values, verdict, metadata.get("info", {}), off_model,
                   arrays.get("frame_loglik_range"), arrays.get("data_covar"), arrays.get("references"),
                   reward=metadata.get("reward", "states"), progress=progress,
                   progress_line=arrays.get("progress_line"), progress_least=metadata.get("progress_least"))


def fit_pomrp(X, lengths=None, config: PomrpConfig | None = None) -> Pomrp:
    """Fits the goal model on the demonstrations and values its states (thesis ch. 4, 6.5).

    ``X: (N, d)`` all demonstrations' goal data stacked, ``lengths`` their
    frame counts.  ``L = floor(mean demonstration length)`` unless
    ``config.mrp.length`` is set.
    """
    config = config if config is not None else PomrpConfig()
    if config.reward not in REWARDS:
        raise ValueError(f"reward: {config.reward!r}; expected one of {', '.join(REWARDS)}")
    hmm = GoalHMM.from_config(config.goal_model).fit(X, lengths)
    mc = config.mrp
    L = int(mc.length) if mc.length > 0 else int(np.floor(hmm.lengths_.mean()))
    v = monte_carlo_values(hmm.startprob_, hmm.transmat_, hmm.terminal_states_, L,
                           n_sequences=mc.n_sequences, gamma=mc.gamma,
                           terminal_scale=mc.terminal_scale, random_state=mc.random_state)
    info = {"mrp": dataclasses.asdict(mc), "mrp_length": L}
    X, lengths = check_sequences(X, lengths)
    om = config.off_model
    if not (np.isfinite(om.covar_reg) and om.covar_reg > 0):
        raise ValueError(f"off_model.covar_reg: expected a finite value > 0, got {om.covar_reg}")
    if not 0.0 <= om.quantile < 1.0:
        raise ValueError(f"off_model.quantile: expected a value in [0, 1), got {om.quantile}")
    S = np.atleast_2d(np.cov(X.T, bias=True))
    S = S + float(om.covar_reg) * regulariser_scale(X) * np.eye(len(S))
    U, log_norm = _precision_cholesky(S[None])
    Y = X @ U[0]
    # Each demonstration's frames against the other demonstrations' (a single
    # demonstration: against the state means).
    parts = []
    ends = np.cumsum(lengths)
    for end, n in zip(ends, lengths):
        own = np.zeros(len(X), bool)
        own[end - n:end] = True
        others = Y[~own] if len(lengths) > 1 else hmm.means_ @ U[0]
        parts.append(_nearest_loglik(Y[own], others, float(log_norm[0])))
    l_loo = np.concatenate(parts)
    l_range = (float(np.quantile(l_loo, om.quantile)), float(l_loo.max()))
    line, least = _progress_line(X, lengths)
    if line is None and config.reward == "progress":
        raise ValueError("reward 'progress': the demonstrations end where they start in goal space (the camera "
                         "saw no change of the object); check the camera with 'drake-skill skills --check-camera'")
    return Pomrp(hmm, v, config.verdict, info, om, l_range, S, X, reward=config.reward,
                 progress=config.progress, progress_line=line, progress_least=least)


def _progress_line(X: np.ndarray, lengths: np.ndarray) -> tuple[np.ndarray | None, float | None]:
    """The demonstrations' mean first and last frames ``(2, d)`` and the least demonstration's own
    progress ``p_T - p_1`` along them; (None, None) when they end where they start."""
    ends = np.cumsum(lengths)
    first, last = X[ends - lengths], X[ends - 1]
    line = np.vstack([first.mean(axis=0), last.mean(axis=0)])
    change = line[1] - line[0]
    if not float(change @ change) > 1e-12 * max(1.0, float((line * line).sum())):
        return None, None
    own = (last - first) @ change / float(change @ change)
    return line, float(own.min())


def _nearest_loglik(Y: np.ndarray, R: np.ndarray, log_norm: float) -> np.ndarray:
    """``log_norm - 0.5 min_j |y_t - r_j|^2`` for whitened frames ``Y (T, d)`` and references ``R (N, d)``."""
    d2 = (Y * Y).sum(axis=1)[:, None] + (R * R).sum(axis=1)[None, :] - 2.0 * (Y @ R.T)
    return log_norm - 0.5 * np.maximum(d2.min(axis=1), 0.0)
