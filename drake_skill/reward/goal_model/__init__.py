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

Modules: ``config`` (hyper-parameters, checks), ``inference`` (densities,
forward-backward, Viterbi), ``initialisation`` (change points, segmental
k-means), ``hmm`` (:class:`GoalHMM`: fit with model selection, inference on
new sequences, I/O).

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

from __future__ import annotations

from drake_skill.reward.goal_model.config import (COVARIANCE_TYPES, CRITERIA, GoalModelConfig, check_sequences,
                                                  n_free_parameters, regulariser_scale)
from drake_skill.reward.goal_model.hmm import GoalHMM
from drake_skill.reward.goal_model.inference import forward_backward, forward_log, gaussian_log_density, viterbi

__all__ = [
    "GoalModelConfig",
    "GoalHMM",
    "COVARIANCE_TYPES",
    "CRITERIA",
    "check_sequences",
    "n_free_parameters",
    "regulariser_scale",
    "gaussian_log_density",
    "forward_backward",
    "forward_log",
    "viterbi",
]
