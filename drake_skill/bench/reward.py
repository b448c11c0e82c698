"""Benchmark of the learned reward (goal HMM -> MRP -> POMRP).

``drake-skill bench reward [--json]`` / ``python tools/bench_reward.py [--json]``.

Measures, on synthetic 8-D goal data from a known left-to-right HMM:

- ``reward_ms``: dense rewards ``h`` (Eq. 4.4) and return ``R`` (Eq. 4.5) of
  a 50-frame sequence, :meth:`Pomrp.reward_and_return`, on a goal model with
  8 states and full covariances (the largest typical model; median).
  Required: at most 1 ms;
- ``reward_fitted_ms``: the same on the model fitted to the demonstrations;
- ``hmmlearn_predict_proba_ms``: hmmlearn's ``predict_proba`` on the same
  8-state model and sequence (what the hand-written forward-backward replaces);
- ``filter_step_us``: one streaming log-space filter update (per 10 Hz frame);
- ``verdict_ms``: the Viterbi success verdict of the 50-frame sequence;
- ``fit_s``: fitting the goal model (default config: k = 2..8, diag and full,
  4 restarts) on 3 demonstrations of 45-60 frames, then the MRP values;
- ``n_states``, ``covariance_type``: what the fit chose (true k = 4).
"""

from __future__ import annotations

import argparse
import json
import statistics
import time

import numpy as np

from drake_skill.reward.goal_model import GoalHMM
from drake_skill.reward.pomrp import Pomrp, fit_pomrp


def left_to_right_model(n_states: int = 4, n_features: int = 8, stay: float = 0.88, std: float = 0.08,
                        seed: int = 0):
    """A known left-to-right Gaussian HMM: ``(startprob, transmat, means, covars (k, d, d))``.

    Means are a random walk of 0.6-long steps (goal-data scale ~0.1-1); each
    state stays with probability ``stay``; the last state is absorbing.
    """
    rng = np.random.default_rng(seed)
    steps = rng.standard_normal((n_states, n_features))
    steps *= 0.6 / np.linalg.norm(steps, axis=1, keepdims=True)
    means = np.cumsum(steps, axis=0)
    P = np.diag(np.full(n_states, stay)) + np.diag(np.full(n_states - 1, 1 - stay), 1)
    P[-1, -1] = 1.0
    start = np.eye(n_states)[0]
    covars = np.broadcast_to(std**2 * np.eye(n_features), (n_states, n_features, n_features)).copy()
    return start, P, means, covars


def sample_demonstrations(model, lengths, seed: int = 0, reach_end: bool = True):
    """Samples sequences ``(X (N, d), lengths)``; with ``reach_end`` each ends in the last state."""
    start, P, means, covars = model
    k, d = means.shape
    rng = np.random.default_rng(seed)
    chol = np.linalg.cholesky(covars)
    out = []
    for n in lengths:
        while True:
            s = np.empty(n, dtype=int)
            s[0] = rng.choice(k, p=start)
            for t in range(1, n):
                s[t] = rng.choice(k, p=P[s[t - 1]])
            if not reach_end or s[-1] == k - 1:
                break
        noise = np.einsum("tde,te->td", chol[s], rng.standard_normal((n, d)))
        out.append(means[s] + noise)
    return np.vstack(out), [int(n) for n in lengths]


def _model_from_parameters(model) -> Pomrp:
    start, P, means, covars = model
    k = len(start)
    arrays = {"startprob": start, "transmat": P, "means": means, "covars": covars,
              "terminal_states": np.array([k - 1]), "lengths": np.array([50]),
              "loglik_per_step": np.array([0.0])}
    hmm = GoalHMM.from_arrays(arrays, {"covariance_type": "full"})
    return Pomrp(hmm, np.linspace(0.5, 10.0, k))


def _median_ms(fn, repeats: int) -> float:
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e3 * statistics.median(times)


def run(repeats: int = 200, fit: bool = True) -> dict:
    """Runs all measurements; returns the result dict (keys in the module docstring)."""
    big = left_to_right_model(n_states=8, stay=0.85, seed=1)
    G, _ = sample_demonstrations(big, [50], seed=1)
    pomrp8 = _model_from_parameters(big)
    result = {"reward_ms": _median_ms(lambda: pomrp8.reward_and_return(G), repeats),
              "n_frames": int(len(G)), "n_features": int(G.shape[1]), "bench_states": 8}

    from hmmlearn.hmm import GaussianHMM

    ref = GaussianHMM(n_components=8, covariance_type="full", init_params="")
    ref.startprob_, ref.transmat_, ref.means_, ref.covars_ = big
    result["hmmlearn_predict_proba_ms"] = _median_ms(lambda: ref.predict_proba(G), max(10, repeats // 10))

    state = {"lb": np.zeros(8), "t": 0}

    def step():
        state["lb"], _, _ = pomrp8.filter_update(state["lb"], G[state["t"] % len(G)], first=state["t"] == 0)
        state["t"] += 1

    result["filter_step_us"] = 1e3 * _median_ms(step, repeats)
    result["verdict_ms"] = _median_ms(lambda: pomrp8.verdict(G), max(10, repeats // 4))
    if fit:
        true4 = left_to_right_model(n_states=4, seed=0)
        X, lengths = sample_demonstrations(true4, [50, 60, 45], seed=0)
        t0 = time.perf_counter()
        fitted = fit_pomrp(X, lengths)
        result["fit_s"] = time.perf_counter() - t0
        result["n_states"] = fitted.n_states
        result["covariance_type"] = fitted.goal_model.covariance_type_
        result["reward_fitted_ms"] = _median_ms(lambda: fitted.reward_and_return(G), repeats)
    return result


def _print_table(r: dict) -> None:
    rows = [
        (f"reward + return, {r['n_frames']} frames, k=8 full (need <= 1 ms)", f"{r['reward_ms']:.3f} ms"),
        ("  hmmlearn predict_proba, same model and sequence", f"{r['hmmlearn_predict_proba_ms']:.3f} ms"),
        ("streaming filter update, one frame", f"{r['filter_step_us']:.1f} us"),
        ("Viterbi verdict, same sequence", f"{r['verdict_ms']:.3f} ms"),
    ]
    if "fit_s" in r:
        rows += [
            ("fit goal model + MRP values (3 demos, k=2..8, diag/full)", f"{r['fit_s']:.2f} s"),
            ("  chosen (true: 4 states)", f"{r['n_states']} states, {r['covariance_type']}"),
            ("reward + return on the fitted model", f"{r['reward_fitted_ms']:.3f} ms"),
        ]
    width = max(len(a) for a, _ in rows)
    for a, b in rows:
        print(f"{a:<{width}}  {b}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="drake-skill bench reward", description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--repeats", type=int, default=200, help="timing repeats")
    parser.add_argument("--no-fit", action="store_true", help="skip the goal-model fit")
    args = parser.parse_args(argv)
    if args.repeats < 1:
        parser.error("--repeats must be >= 1")
    result = run(args.repeats, fit=not args.no_fit)
    if args.json:
        print(json.dumps(result))
    else:
        _print_table(result)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
