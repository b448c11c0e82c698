"""POMRP rewards (thesis Eqs. 4.4, 4.5), filtered reward, streaming filter and verdict."""

import json
import warnings

import numpy as np
import pytest
from hmmlearn.hmm import GaussianHMM
from scipy.stats import multivariate_normal
from pydrake.common.yaml import yaml_load_typed

from drake_skill.bench import reward as bench_reward
from drake_skill.bench.reward import left_to_right_model, sample_demonstrations
from drake_skill.fileio import atomic_save_npz, atomic_write_json, load_npz
from drake_skill.reward.mrp import exact_values
from drake_skill.reward.goal_model import GoalHMM, forward_backward
from drake_skill.reward.pomrp import OffModelConfig, Pomrp, PomrpConfig, ProgressConfig, VerdictConfig, fit_pomrp
from goal_model_support import two_state_model_arrays

TRUE = left_to_right_model(n_states=4, seed=0)


def _path_sequence(states, seed):
    """Goal data emitted by the true model along a given state path."""
    _, _, means, covars = TRUE
    rng = np.random.default_rng(seed)
    states = np.asarray(states)
    return means[states] + rng.standard_normal((len(states), means.shape[1])) * np.sqrt(covars[0, 0, 0])


@pytest.fixture(scope="module")
def pomrp():
    X, lengths = sample_demonstrations(TRUE, [50, 60, 45], seed=0)
    return fit_pomrp(X, lengths)


@pytest.fixture(scope="module")
def held_out():
    return [sample_demonstrations(TRUE, [50], seed=100 + i)[0] for i in range(5)]


@pytest.fixture(scope="module")
def stalled():
    # Halfway: reaches the second of four sub-goals and stays; never leaves the start.
    return {"halfway": _path_sequence([0] * 10 + [1] * 40, 1), "start": _path_sequence([0] * 50, 2)}


def test_fitted_values_rise_toward_terminal(pomrp):
    gm = pomrp.goal_model
    assert pomrp.n_states == 4 and len(pomrp.terminal_states) == 1
    order = np.argsort(np.linalg.norm(gm.means_[:, None] - TRUE[2][None], axis=2).argmin(axis=1))
    v = pomrp.values[order]  # values in the order of the true sub-goals
    assert np.all(np.diff(v) > 0)
    assert order[-1] == pomrp.terminal_states[0]
    # MC (n = 100, seeded) near the exact values of the same MRP.
    L = int(np.floor(gm.lengths_.mean()))
    exact = exact_values(gm.startprob_, gm.transmat_, pomrp.terminal_states, L)
    np.testing.assert_allclose(pomrp.values, exact, rtol=0.05)


def test_return_ordering(pomrp, held_out, stalled):
    demo = [pomrp.episode_return(G) for G in held_out]
    half = pomrp.episode_return(stalled["halfway"])
    start = pomrp.episode_return(stalled["start"])
    assert min(demo) > half > start > 0


def test_rewards_are_values_under_smoothed_posteriors(pomrp, held_out):
    gm = pomrp.goal_model
    ref = GaussianHMM(n_components=gm.n_states_, covariance_type="full", init_params="")
    ref.startprob_, ref.transmat_, ref.means_, ref.covars_ = gm.startprob_, gm.transmat_, gm.means_, gm.covars_
    G = held_out[0]
    filtered, smoothed, ll = pomrp.posteriors(G)
    np.testing.assert_allclose(smoothed, ref.predict_proba(G), atol=1e-10)
    assert np.isclose(ll, ref.score(G), rtol=1e-12)
    h, R = pomrp.reward_and_return(G)
    np.testing.assert_allclose(h, ref.predict_proba(G) @ pomrp.values, rtol=1e-9)
    assert np.isclose(R, h.sum()) and np.isclose(pomrp.episode_return(G), R)
    np.testing.assert_array_equal(pomrp.rewards(G), h)


def test_filtered_reward_equals_brute_force_forward(pomrp, held_out):
    # Brute force: for each t, the unnormalised forward recursion of Eq. 3.10
    # restarted on g_1..g_t in plain probability space (no scaling, no logs).
    gm = pomrp.goal_model
    G = held_out[1][:25]
    b = np.exp(gm.log_emission(G))
    expected = []
    for t in range(len(G)):
        alpha = gm.startprob_ * b[0]
        for j in range(1, t + 1):
            alpha = (alpha @ gm.transmat_) * b[j]
        expected.append(alpha @ pomrp.values / alpha.sum())
    np.testing.assert_allclose(pomrp.filtered_rewards(G), expected, rtol=1e-9)
    # Online, the filtered reward never uses frames after t.
    np.testing.assert_allclose(pomrp.filtered_rewards(G[:10]), expected[:10], rtol=1e-9)


def test_streaming_filter_matches_batch(pomrp, held_out, stalled):
    for G in (held_out[2], stalled["halfway"]):
        lb, total, rewards = None, 0.0, []
        for t, g in enumerate(G):
            lb, step_ll, r = pomrp.filter_update(lb, g, first=(t == 0))
            total += step_ll
            rewards.append(r)
        np.testing.assert_allclose(rewards, pomrp.filtered_rewards(G), rtol=1e-9)
        assert np.isclose(total, pomrp.goal_model.score(G), rtol=1e-12)
        assert np.isclose(np.exp(lb).sum(), 1.0)


def test_far_execution_is_finite(pomrp, held_out):
    far = held_out[0] + 30.0  # every density underflows in probability space
    h, R = pomrp.reward_and_return(far)
    assert np.all(np.isfinite(h)) and np.isfinite(R)
    assert np.all(np.isfinite(pomrp.filtered_rewards(far)))


def test_verdict(pomrp, held_out, stalled):
    assert all(pomrp.verdict(G) for G in held_out)
    assert not pomrp.verdict(stalled["halfway"])
    assert not pomrp.verdict(stalled["start"])
    d = pomrp.verdict_details(stalled["halfway"])
    assert not d["terminal"] and d["final_state"] not in pomrp.terminal_states
    # Optional likelihood rule: demonstration-like data stays in range, a
    # sequence that ends at the goal through unseen goal data does not.
    strict = Pomrp(pomrp.goal_model, pomrp.values, VerdictConfig(require_likelihood=True))
    assert all(strict.verdict(G) for G in held_out)
    odd = held_out[0].copy()
    odd[:40] += 0.3  # off every sub-goal for most of the execution
    loose = pomrp.verdict_details(odd)
    assert loose["terminal"] and loose["success"]
    tight = strict.verdict_details(odd)
    assert not tight["loglik_in_range"] and not tight["success"]
    lo, hi = strict.loglik_range
    assert hi - lo == pytest.approx(np.ptp(pomrp.goal_model.loglik_per_step_) + 2 * 2.0)


def test_save_load_round_trip(tmp_path, pomrp, held_out):
    arrays, meta = pomrp.to_arrays()
    atomic_save_npz(tmp_path / "goal.npz", arrays)
    atomic_write_json(tmp_path / "goal.json", meta)
    back = Pomrp.from_arrays(load_npz(tmp_path / "goal.npz"), json.loads((tmp_path / "goal.json").read_text()))
    np.testing.assert_array_equal(back.values, pomrp.values)
    assert back.episode_return(held_out[0]) == pomrp.episode_return(held_out[0])
    assert back.verdict_config == pomrp.verdict_config
    assert back.info == pomrp.info == {"mrp": {"n_sequences": 100, "gamma": 0.9, "terminal_scale": 2.0,
                                               "length": 0, "random_state": 0}, "mrp_length": 51}


def test_config_loads_from_yaml():
    cfg = yaml_load_typed(schema=PomrpConfig, data="""
goal_model: {n_states_max: 5, covariance_types: [diag]}
mrp: {terminal_scale: 3.0}
verdict: {require_likelihood: true, loglik_margin: 1.5}
""")
    assert cfg.goal_model.n_states_max == 5 and cfg.goal_model.covariance_types == ["diag"]
    assert cfg.mrp.terminal_scale == 3.0 and cfg.mrp.n_sequences == 100
    assert cfg.verdict == VerdictConfig(True, 1.5)


def test_bad_input_is_a_clear_error(pomrp, held_out):
    G = held_out[0]
    with pytest.raises(ValueError, match=r"G: expected 8 features per frame, got shape \(50, 3\)"):
        pomrp.episode_return(G[:, :3])
    with pytest.raises(ValueError, match=r"G: expected a 2-D array"):
        pomrp.rewards(G[0])
    bad = G.copy()
    bad[3, 1] = np.inf
    with pytest.raises(ValueError, match="G: non-finite value inf at frame 3, feature 1"):
        pomrp.verdict(bad)
    with pytest.raises(ValueError, match="G: empty sequence"):
        pomrp.filtered_rewards(np.zeros((0, 8)))
    with pytest.raises(ValueError, match=r"g: expected one frame of shape \(8,\)"):
        pomrp.filter_update(None, G[:2], first=True)
    with pytest.raises(ValueError, match=r"values: expected 4 finite state values"):
        Pomrp(pomrp.goal_model, [1.0, 2.0])


def test_bench_reward_json(capsys):
    assert bench_reward.main(["--json", "--no-fit", "--repeats", "5"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert 0 < out["reward_ms"] < 50 and out["n_frames"] == 50 and out["bench_states"] == 8


# ------------------------------------------------- issue 12: finite, robust rewards
from drake_skill.reward.goal_model import forward_log  # noqa: E402
from drake_skill.reward.goal_model.inference import _backward_log  # noqa: E402


def _strict_chain_pomrp():
    """3 states on a line (1-D goal data, means 0, 10, 20, variance 0.01): emission
    log-densities of one frame differ by thousands of nats; strict left-to-right chain."""
    k = 3
    P = np.array([[0.9, 0.1, 0.0], [0.0, 0.9, 0.1], [0.0, 0.0, 1.0]])
    arrays = {"startprob": np.array([1.0, 0.0, 0.0]), "transmat": P, "means": np.array([[0.0], [10.0], [20.0]]),
              "covars": np.full((k, 1, 1), 0.01), "terminal_states": np.array([2]), "lengths": np.array([50]),
              "loglik_per_step": np.array([1.0])}
    hmm = GoalHMM.from_arrays(arrays, {"covariance_type": "full"})
    return Pomrp(hmm, np.array([0.5, 2.0, 20.0]), off_model=OffModelConfig(enabled=False))


def test_reward_of_the_nan_reproducer_is_finite_and_exact():
    pomrp = _strict_chain_pomrp()
    gm = pomrp.goal_model
    for visits in ([0] * 10 + [1] * 10 + [0] * 30, [0] * 10 + [1] * 10 + [2] * 10 + [1] * 10 + [0] * 10):
        G = gm.means_[np.array(visits)]
        h, R = pomrp.reward_and_return(G)
        log_b = gm.log_emission(G)
        with np.errstate(divide="ignore"):
            log_pi, log_P = np.log(gm.startprob_), np.log(gm.transmat_)
        la, _ = forward_log(log_b, log_pi, log_P)
        lg = la + _backward_log(log_b, log_P)
        smoothed = np.exp(lg - lg.max(axis=1, keepdims=True))
        smoothed /= smoothed.sum(axis=1, keepdims=True)
        filtered = np.exp(la - la.max(axis=1, keepdims=True))
        filtered /= filtered.sum(axis=1, keepdims=True)
        assert np.isfinite(R)
        np.testing.assert_allclose(h, smoothed @ pomrp.values, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(pomrp.filtered_rewards(G), filtered @ pomrp.values, rtol=1e-9, atol=1e-12)
        # The batch filtered rewards are the streaming filter's.
        lb, streamed = None, []
        for t, g in enumerate(G):
            lb, _, r = pomrp.filter_update(lb, g, first=(t == 0))
            streamed.append(r)
        np.testing.assert_allclose(streamed, pomrp.filtered_rewards(G), rtol=1e-9, atol=1e-12)


def _noise(seed, like):
    """Goal data far from every state: Gaussian noise at 3x the data's spread."""
    rng = np.random.default_rng(seed)
    return like.mean(axis=0) + 3 * like.std() * rng.standard_normal((50, like.shape[1]))


@pytest.mark.parametrize("seed", range(5))
def test_off_model_data_scores_below_a_stall_and_fails(seed):
    true = left_to_right_model(n_states=4, seed=seed)
    X, lengths = sample_demonstrations(true, [50, 60, 45], seed=seed)
    guarded = fit_pomrp(X, lengths)
    plain = Pomrp(guarded.goal_model, guarded.values, guarded.verdict_config, {}, OffModelConfig(enabled=False),
                  guarded.frame_loglik_range)
    _, _, means, covars = true
    rng = np.random.default_rng(seed)
    half = means[np.r_[[0] * 10, [1] * 40]] + rng.standard_normal((50, means.shape[1])) * np.sqrt(covars[0, 0, 0])
    demo = sample_demonstrations(true, [50], seed=100 + seed)[0]
    noise = _noise(seed, X)
    # Guarded (default): noise earns (almost) nothing and is no success; the
    # stall and the demonstration keep their plain returns within 5 %.
    assert guarded.episode_return(noise) < 0.01 * guarded.episode_return(half)
    assert not guarded.verdict(noise) and not guarded.verdict_details(noise)["final_frame_explained"]
    assert guarded.episode_return(half) == pytest.approx(plain.episode_return(half), rel=0.05)
    assert guarded.episode_return(demo) == pytest.approx(plain.episode_return(demo), rel=1e-6)
    assert guarded.verdict(demo) and not guarded.verdict(half)
    # The thesis's plain form rewards the noise (measured 216-674 against stalls of 103-182).
    assert plain.episode_return(noise) > plain.episode_return(half)


def test_off_model_weight_at_its_boundary(pomrp, held_out):
    """w_t = 1 down to l_lo - margin, then the likelihood ratio; the verdict's cut is the same floor."""
    G = held_out[0]
    floor = pomrp.explained_floor
    assert floor == pytest.approx(pomrp.frame_loglik_range[0] - 10.0)
    # l_t: the nearest demonstration frame's log-density under the demonstrations' frame covariance S.
    gm, S = pomrp.goal_model, pomrp.data_covar
    assert pomrp.references.shape == (155, 8)  # the three demonstrations' frames
    Sinv = np.linalg.inv(S)
    ref = np.array([max(-0.5 * (g - x) @ Sinv @ (g - x) for x in pomrp.references) for g in G])
    ref -= 0.5 * (G.shape[1] * np.log(2 * np.pi) + np.linalg.slogdet(S)[1])
    np.testing.assert_allclose(pomrp.frame_loglik(G), ref, rtol=1e-10)
    assert np.all(ref > floor)
    np.testing.assert_array_equal(pomrp.explained_weights(G), 1.0)
    # Frames pushed away from the data: the weight is the likelihood ratio to the floor.
    rng = np.random.default_rng(0)
    H = G + rng.standard_normal(G.shape) * np.linspace(0.0, 3.0, len(G))[:, None]
    l_H = pomrp.frame_loglik(H)
    w = pomrp.explained_weights(H)
    assert (w == 1.0).any() and (w < 1e-3).any()
    np.testing.assert_allclose(w, np.exp(np.minimum(0.0, l_H - floor)), rtol=1e-12)
    # The verdict's boundary: move the last frame until it falls just below the floor.
    direction = np.ones(G.shape[1]) / np.sqrt(G.shape[1])

    def details(alpha):
        H = G.copy()
        H[-1] = G[-1] + alpha * direction
        return pomrp.verdict_details(H)
    lo, hi = 0.0, 20.0
    assert details(lo)["final_frame_explained"] and not details(hi)["final_frame_explained"]
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if details(mid)["final_frame_explained"] else (lo, mid)
    assert details(lo)["final_frame_loglik"] >= floor > details(hi)["final_frame_loglik"]
    assert details(hi)["final_frame_loglik"] == pytest.approx(floor, abs=1e-6)
    assert not details(hi)["success"]
    plain = Pomrp(gm, pomrp.values, pomrp.verdict_config, {}, OffModelConfig(enabled=False))
    assert plain.verdict_details(G)["final_frame_explained"]


def test_verdict_is_decided_by_the_last_viterbi_frame(pomrp):
    """Reaching the terminal sub-goal on the very last frame is a success; one frame short is not."""
    term = int(pomrp.terminal_states[0])
    for seed in range(3):
        reached = _path_sequence([0] * 10 + [1] * 10 + [2] * 10 + [3], 200 + seed)
        d = pomrp.verdict_details(reached)
        path = pomrp.goal_model.decode(reached)
        assert path[-1] == term and path[-2] != term  # the boundary: only path[-1] is terminal
        assert d["final_state"] == term and d["terminal"] and d["success"]
        short = _path_sequence([0] * 10 + [1] * 10 + [2] * 11, 300 + seed)
        assert pomrp.goal_model.decode(short)[-1] != term and not pomrp.verdict(short)


def _terminal_can_be_left_pomrp():
    """3 states on a line (1-D goal data, means 0, 10, 20): 0 -> 1 -> 2, and the terminal
    state 2 can be left again for 1 (a lid that falls back, a drawer pushed back in)."""
    P = np.array([[0.9, 0.1, 0.0], [0.0, 0.9, 0.1], [0.0, 0.1, 0.9]])
    arrays = {"startprob": np.array([1.0, 0.0, 0.0]), "transmat": P, "means": np.array([[0.0], [10.0], [20.0]]),
              "covars": np.full((3, 1, 1), 0.01), "terminal_states": np.array([2]), "lengths": np.array([50]),
              "loglik_per_step": np.array([1.0])}
    hmm = GoalHMM.from_arrays(arrays, {"covariance_type": "full"})
    return Pomrp(hmm, np.array([0.5, 2.0, 20.0]), off_model=OffModelConfig(enabled=False))


def test_a_path_that_visits_the_terminal_state_and_moves_on_fails():
    """The verdict is where the path ends, not whether it passed through the terminal state."""
    pomrp = _terminal_can_be_left_pomrp()
    means = pomrp.goal_model.means_
    left = means[np.array([0] * 10 + [1] * 10 + [2] * 10 + [1] * 10)]
    assert 2 in pomrp.goal_model.decode(left) and pomrp.goal_model.decode(left)[-1] == 1
    d = pomrp.verdict_details(left)
    assert d["final_state"] == 1 and not d["terminal"] and not d["success"]
    assert not pomrp.verdict(left)
    # Leaving the terminal state and coming back to it is a success; so is staying.
    back = means[np.array([0] * 10 + [1] * 10 + [2] * 10 + [1] * 10 + [2] * 5)]
    stays = means[np.array([0] * 10 + [1] * 10 + [2] * 20)]
    assert pomrp.verdict(back) and pomrp.verdict(stays)


# ------------------------------------------------------------------ mutation testing (docs/mutation.md)
def test_streaming_filter_matches_batch_on_frames_off_the_data(pomrp, held_out):
    """Where the off-model weight w_t < 1, filter_update's reward is still filtered_rewards at t."""
    G = held_out[1]
    H = G + np.random.default_rng(1).standard_normal(G.shape) * np.linspace(0.0, 3.0, len(G))[:, None]
    assert (pomrp.explained_weights(H) < 0.5).any()
    lb, rewards = None, []
    for t, g in enumerate(H):
        lb, _, r = pomrp.filter_update(lb, g, first=(t == 0))
        rewards.append(r)
    np.testing.assert_allclose(rewards, pomrp.filtered_rewards(H), rtol=1e-9, atol=1e-300)
    g = H[0].copy()
    g[2] = np.nan
    with pytest.raises(ValueError, match=r"^g: non-finite goal data \["):
        pomrp.filter_update(None, g, first=True)


def test_metadata_keys_and_a_non_default_verdict_round_trip(pomrp, held_out):
    strict = Pomrp(pomrp.goal_model, pomrp.values, VerdictConfig(require_likelihood=True, loglik_margin=1.5),
                   pomrp.info, pomrp.off_model_config, pomrp.frame_loglik_range, pomrp.data_covar,
                   pomrp.references)
    arrays, meta = strict.to_arrays()
    assert set(meta) == {"hmm", "info", "verdict", "off_model", "reward", "progress"}
    assert meta["hmm"] == pomrp.goal_model.to_arrays()[1]
    back = Pomrp.from_arrays(arrays, json.loads(json.dumps(meta)))
    assert back.verdict_config == VerdictConfig(True, 1.5)
    assert back.verdict_details(held_out[0]) == strict.verdict_details(held_out[0])


def test_from_arrays_metadata_defaults_and_errors(pomrp, held_out):
    arrays, meta = pomrp.to_arrays()
    # Metadata written before the verdict settings and the off-model guard: defaults, guard off.
    old = Pomrp.from_arrays(arrays, {"hmm": meta["hmm"], "info": meta["info"]})
    assert old.verdict_config == VerdictConfig() and not old.off_model_config.enabled
    np.testing.assert_array_equal(old.explained_weights(held_out[0]), 1.0)
    bare = Pomrp.from_arrays(arrays, {})  # no metadata at all: the goal model's defaults (full covariances)
    assert bare.episode_return(held_out[0]) == old.episode_return(held_out[0])
    # The goal model's metadata is read and errors carry the prefix.
    with pytest.raises(ValueError, match=r"^goal-model metadata 'n_states' = 5 disagrees with p/hmm_means of shape "
                                         r"\(4, 8\)$"):
        Pomrp.from_arrays(arrays, dict(meta, hmm=dict(meta["hmm"], n_states=5)), prefix="p/")
    with pytest.raises(ValueError, match=r"^missing array 'values'$"):
        Pomrp.from_arrays({k: v for k, v in arrays.items() if k != "values"}, meta)
    with pytest.raises(ValueError, match=r"^p/values: expected 4 finite state values, got shape \(3,\)$"):
        Pomrp.from_arrays(dict(arrays, values=np.zeros(3)), meta, prefix="p/")
    with pytest.raises(ValueError, match=r"^POMRP metadata: .*unexpected keyword argument 'bogus'"):
        Pomrp.from_arrays(arrays, dict(meta, verdict={"bogus": 1}))


def test_fit_uses_the_configured_mrp_settings():
    import dataclasses

    """A small fit (one candidate model) with every MRP setting changed: the values are those settings'."""
    from drake_skill.reward.goal_model import GoalModelConfig
    from drake_skill.reward.mrp import MrpConfig, monte_carlo_values

    X, lengths = sample_demonstrations(TRUE, [30, 34], seed=3)
    mc = MrpConfig(n_sequences=7, gamma=0.7, terminal_scale=3.0, length=20, random_state=5)
    config = PomrpConfig(goal_model=GoalModelConfig(n_states_min=4, n_states_max=4, covariance_types=["diag"],
                                                    n_restarts=1, n_iter=20), mrp=mc)
    fitted = fit_pomrp(X, lengths, config)
    hmm = fitted.goal_model
    assert hmm.lengths_.tolist() == [30, 34] and fitted.info["mrp_length"] == 20
    expected = monte_carlo_values(hmm.startprob_, hmm.transmat_, hmm.terminal_states_, 20, n_sequences=7,
                                  gamma=0.7, terminal_scale=3.0, random_state=5)
    np.testing.assert_array_equal(fitted.values, expected)
    assert fitted.info == {"mrp": dataclasses.asdict(mc), "mrp_length": 20}
    # The off-model guard's frame covariance: the biased sample covariance plus covar_reg times its mean variance.
    S = np.cov(X.T, bias=True)
    assert np.trace(S) / len(S) < 1.0
    np.testing.assert_allclose(fitted.data_covar, S + config.off_model.covar_reg * np.trace(S) / len(S) * np.eye(8),
                               rtol=1e-12)
    for other in (MrpConfig(n_sequences=7, gamma=0.7, terminal_scale=3.0, length=20, random_state=6),
                  MrpConfig(n_sequences=8, gamma=0.7, terminal_scale=3.0, length=20, random_state=5)):
        assert not np.array_equal(fitted.values, monte_carlo_values(
            hmm.startprob_, hmm.transmat_, hmm.terminal_states_, other.length, n_sequences=other.n_sequences,
            gamma=other.gamma, terminal_scale=other.terminal_scale, random_state=other.random_state))


@pytest.mark.parametrize("field, value, message", [
    ("covar_reg", 0.0, r"off_model\.covar_reg: expected a finite value > 0, got 0\.0$"),
    ("covar_reg", np.inf, r"off_model\.covar_reg: expected a finite value > 0, got inf$"),
    ("quantile", 1.0, r"off_model\.quantile: expected a value in \[0, 1\), got 1\.0$"),
    ("quantile", 1.5, r"off_model\.quantile: expected a value in \[0, 1\), got 1\.5$"),
    ("quantile", 0.0, None),
])
def test_off_model_settings_are_checked_at_fit(field, value, message):
    from drake_skill.reward.goal_model import GoalModelConfig

    X, lengths = sample_demonstrations(TRUE, [30, 34], seed=3)
    config = PomrpConfig(goal_model=GoalModelConfig(n_states_min=4, n_states_max=4, covariance_types=["diag"],
                                                    n_restarts=1, n_iter=20),
                         off_model=OffModelConfig(**{field: value}))
    if message is None:
        assert fit_pomrp(X, lengths, config).off_model_config.quantile == 0.0
    else:
        with pytest.raises(ValueError, match=rf"^{message}"):
            fit_pomrp(X, lengths, config)


def test_off_model_range_is_each_demonstration_against_the_others(pomrp):
    """frame_loglik_range: the log-density of every demonstration frame at its nearest frame of
    the *other* demonstrations (leave one demonstration out), under the data covariance S:
    (quantile, max) of l_t = -0.5 (d log 2 pi + log det S) - 0.5 min_j |y_t - r_j|^2_S."""
    expected = _expected_frame_loglik_range(pomrp.references, pomrp.data_covar, [50, 60, 45],  # the fixture's
                                            pomrp.off_model_config.quantile)
    assert pomrp.frame_loglik_range == pytest.approx(expected, rel=1e-9, abs=1e-9)


def _expected_frame_loglik_range(X, S, lengths, quantile, state_means=None):
    """(quantile, max) of l_t = -0.5 (d log 2 pi + log det S) - 0.5 min_j |x_t - r_j|^2_S over every
    demonstration frame, r_j the frames of the other demonstrations (the state means if there is one)."""
    Sinv = np.linalg.inv(S)
    log_norm = -0.5 * (len(S) * np.log(2 * np.pi) + np.linalg.slogdet(S)[1])
    ends = np.cumsum(lengths)
    l_loo = []
    for end, n in zip(ends, lengths):
        own = np.zeros(len(X), bool)
        own[end - n:end] = True
        refs = X[~own] if state_means is None else state_means
        diff = X[own][:, None, :] - refs[None, :, :]
        d2 = np.einsum("tjd,de,tje->tj", diff, Sinv, diff)
        l_loo.append(log_norm - 0.5 * d2.min(axis=1))
    l_loo = np.concatenate(l_loo)
    return np.quantile(l_loo, quantile), l_loo.max()


def _small_config(n_states=4, **kwargs):
    from drake_skill.reward.goal_model import GoalModelConfig

    return PomrpConfig(goal_model=GoalModelConfig(n_states_min=n_states, n_states_max=n_states,
                                                  covariance_types=["diag"], n_restarts=1, n_iter=20), **kwargs)


@pytest.mark.parametrize("lengths", [[40], [30, 34]])
def test_off_model_range_of_one_and_two_demonstrations(lengths):
    """One demonstration: its frames against the goal model's state means; two: each against the other.
    The verdict settings given reach the fitted reward."""
    X, lengths = sample_demonstrations(TRUE, lengths, seed=3)
    config = _small_config(verdict=VerdictConfig(require_likelihood=True, loglik_margin=0.5))
    fitted = fit_pomrp(X, lengths, config)
    assert fitted.verdict_config == config.verdict
    means = fitted.goal_model.means_ if len(lengths) == 1 else None
    expected = _expected_frame_loglik_range(X, fitted.data_covar, lengths, config.off_model.quantile, means)
    assert fitted.frame_loglik_range == pytest.approx(expected, rel=1e-9, abs=1e-9)


def test_off_model_covariance_of_constant_goal_data():
    """Goal data that never changes (0.3: a variance at the rounding level, not 0): the frame covariance is
    covar_reg times the identity (a unit mean variance)."""
    fitted = fit_pomrp(np.full((24, 2), 0.3), [12, 12], _small_config(n_states=1))
    np.testing.assert_allclose(fitted.data_covar, fitted.off_model_config.covar_reg * np.eye(2), rtol=1e-12, atol=1e-20)


# ----------------------------------------------------------- a hand-written model: exact contracts
_S = np.array([[0.02, 0.002], [0.002, 0.02]])               # the demonstrations' frame covariance
_REFS = np.array([[0.0, 0.0], [0.5, 0.2], [1.0, 0.5]])       # their frames


def _two_state(**kwargs):
    arrays, meta = two_state_model_arrays()
    return Pomrp(GoalHMM.from_arrays(arrays, meta), kwargs.pop("values", [0.2, 1.0]), **kwargs)


def _guarded(**kwargs):
    return _two_state(frame_loglik_range=kwargs.pop("frame_loglik_range", (-3.0, -1.0)), data_covar=_S,
                      references=_REFS, **kwargs)


_REQUIRED = ("frame_loglik_range, data_covar, references: required with off_model.enabled (the demonstrations' "
             "l range, frame covariance and frames, recorded by fit_pomrp); refit, or pass "
             "OffModelConfig(enabled=False) for the thesis's plain rewards")


@pytest.mark.parametrize("kwargs, message", [
    ({"values": [1.0]}, "values: expected 2 finite state values, got shape (1,): [1.]"),
    ({"values": [1.0, np.nan]}, "values: expected 2 finite state values, got shape (2,): [ 1. nan]"),
    ({"verdict": VerdictConfig(loglik_margin=-1.0)}, "verdict.loglik_margin: expected >= 0, got -1.0"),
    ({"verdict": VerdictConfig(loglik_margin=np.nan)}, "verdict.loglik_margin: expected >= 0, got nan"),
    ({"off_model": OffModelConfig(enabled=False, margin=np.inf)},
     "off_model.margin: expected a finite value >= 0 nats, got inf"),
    ({"off_model": OffModelConfig(enabled=False, margin=-0.5)},
     "off_model.margin: expected a finite value >= 0 nats, got -0.5"),
    ({"frame_loglik_range": [1.0]}, "frame_loglik_range: expected finite (min, max) nats, got [1.]"),
    ({"frame_loglik_range": [0.0, np.inf]}, "frame_loglik_range: expected finite (min, max) nats, got [ 0. inf]"),
    ({"frame_loglik_range": [2.0, 1.0]}, "frame_loglik_range: expected finite (min, max) nats, got [2. 1.]"),
    ({"frame_loglik_range": [1.0, 2.0]}, _REQUIRED),
    ({"frame_loglik_range": [1.0, 2.0], "data_covar": _S}, _REQUIRED),
    ({"frame_loglik_range": [1.0, 2.0], "references": _REFS}, _REQUIRED),
    ({"off_model": OffModelConfig(), "data_covar": _S, "references": _REFS}, _REQUIRED),
    ({"data_covar": np.eye(3)}, "data_covar: expected a finite symmetric (2, 2) covariance, got shape (3, 3)"),
    ({"data_covar": [[1.0, 0.5], [0.0, 1.0]]}, "data_covar: expected a finite symmetric (2, 2) covariance, "
                                               "got shape (2, 2)"),
    ({"data_covar": [[1.0, np.nan], [np.nan, 1.0]]}, "data_covar: expected a finite symmetric (2, 2) covariance, "
                                                     "got shape (2, 2)"),
    ({"data_covar": [[1.0, 2.0], [2.0, 1.0]]}, "data_covar: not positive definite"),
    ({"references": np.zeros(2)}, "references: expected finite demonstration frames (N, 2), got shape (2,)"),
    ({"references": np.zeros((3, 3))}, "references: expected finite demonstration frames (N, 2), got shape (3, 3)"),
    ({"references": np.zeros((0, 2))}, "references: expected finite demonstration frames (N, 2), got shape (0, 2)"),
    ({"references": [[0.0, np.nan]]}, "references: expected finite demonstration frames (N, 2), got shape (1, 2)"),
])
def test_each_bad_pomrp_argument_is_named_in_full(kwargs, message):
    with pytest.raises(ValueError) as info:
        _two_state(**kwargs)
    assert str(info.value) == message


def test_pomrp_arguments_at_their_edges():
    """Zero margins and a one-point range are valid; the guard defaults to on exactly when the
    demonstrations' range is given; an unfitted goal model is refused."""
    edge = _guarded(frame_loglik_range=(-2.0, -2.0), verdict=VerdictConfig(loglik_margin=0.0),
                    off_model=OffModelConfig(margin=0.0))
    assert edge.frame_loglik_range == (-2.0, -2.0) and edge.explained_floor == -2.0
    assert edge.loglik_range == (-1.5, -1.2)
    assert _guarded().off_model_config.enabled and not _two_state().off_model_config.enabled
    assert _two_state().explained_floor == -np.inf
    assert _guarded(off_model=OffModelConfig(margin=3.0)).explained_floor == -6.0
    assert _two_state(info={"mrp": 1}).info == {"mrp": 1} and _two_state().info == {}
    with pytest.raises(RuntimeError, match="not fitted"):
        Pomrp(GoalHMM(), [0.0, 1.0])
    message = "frame_loglik: this reward has no data_covar/references (saved before the off-model guard)"
    for partial in ({}, {"data_covar": _S}, {"references": _REFS}):
        with pytest.raises(ValueError) as info:
            _two_state(**partial).frame_loglik(np.zeros((1, 2)))
        assert str(info.value) == message
    # Zero start and transition probabilities (log 0 = -inf) are taken without a warning.
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert _two_state()._log_transmat[1, 0] == -np.inf


def test_hand_written_rewards_weights_and_verdicts():
    """Eq. 4.4 times w_t, Eq. 4.5, the filtered reward and every verdict ingredient, by hand."""
    pomrp = _guarded(frame_loglik_range=(1.0, 2.0), off_model=OffModelConfig(margin=1.0))   # floor 0 nats
    gm = pomrp.goal_model
    rng = np.random.default_rng(1)
    # Near the references, then a last frame in the terminal state but 30 cm (2 std of S) from them.
    G = np.r_[rng.normal(0.0, 0.05, (5, 2)), rng.normal([1.0, 0.5], 0.05, (4, 2)), [[1.3, 0.5]]]
    ell = np.max([multivariate_normal.logpdf(G, x, _S) for x in _REFS], axis=0)     # nearest reference
    log_norm = multivariate_normal.logpdf(_REFS[1], _REFS[1], _S)
    np.testing.assert_allclose(pomrp.frame_loglik(G), ell, rtol=1e-12)
    assert pomrp.frame_loglik(_REFS[1:2])[0] == pytest.approx(log_norm, abs=1e-12)   # on a reference: the peak
    w = np.minimum(1.0, np.exp(ell - 0.0))
    assert w[:-1].min() == 1.0 and w[-1] < 0.9
    np.testing.assert_allclose(pomrp.explained_weights(G), w, rtol=1e-12)
    filtered, smoothed, ll = forward_backward(gm.log_emission(G), gm.startprob_, gm.transmat_)
    h, R = pomrp.reward_and_return(G)
    np.testing.assert_allclose(h, smoothed @ [0.2, 1.0] * w, rtol=1e-12)
    assert R == pytest.approx(h.sum(), rel=1e-15)
    np.testing.assert_array_equal(pomrp.rewards(G), h)
    assert pomrp.episode_return(G) == R
    np.testing.assert_allclose(pomrp.filtered_rewards(G), filtered @ [0.2, 1.0] * w, rtol=1e-12)
    d = pomrp.verdict_details(G)
    assert ll / 10 > 0.8                                       # above [-1.5 - 2, -1.2 + 2]: tighter than the demos
    assert d == {"final_state": 1, "terminal": True, "loglik_per_step": pytest.approx(ll / 10, rel=1e-12),
                 "loglik_in_range": False, "final_frame_loglik": pytest.approx(ell[-1], rel=1e-12),
                 "final_frame_explained": False, "success": False}
    assert pomrp.verdict(G) is False
    # The plain form: no weights, no final-frame rule, the final frame's l not computed.
    plain = _two_state()
    np.testing.assert_array_equal(plain.explained_weights(G), np.ones(10))
    np.testing.assert_allclose(plain.rewards(G), smoothed @ [0.2, 1.0], rtol=1e-12)
    d = plain.verdict_details(G)
    assert np.isnan(d["final_frame_loglik"]) and d["final_frame_explained"] and d["success"] is True
    # Still in state 0 at the end: not terminal.
    assert not plain.verdict_details(G[:5])["terminal"] and plain.verdict_details(G[:5])["final_state"] == 0
    with pytest.raises(ValueError) as info:
        plain.rewards(np.zeros((5, 3)))
    assert str(info.value) == "G: expected 2 features per frame, got shape (5, 3)"


def test_verdict_bounds_are_inclusive():
    """A per-frame log-likelihood exactly at the demonstrations' min (margin 0) is in range, and a
    final frame exactly at the floor (margin 0) is explained."""
    rng = np.random.default_rng(2)
    G = np.r_[rng.normal(0.0, 0.1, (5, 2)), rng.normal([1.0, 0.5], 0.05, (4, 2))]
    per_step = _two_state().verdict_details(G)["loglik_per_step"]
    arrays, meta = two_state_model_arrays()
    for ends in ([per_step, per_step + 1.0], [per_step - 1.0, per_step]):
        gm = GoalHMM.from_arrays({**arrays, "loglik_per_step": np.array(ends)}, meta)
        strict = Pomrp(gm, [0.2, 1.0], VerdictConfig(require_likelihood=True, loglik_margin=0.0))
        d = strict.verdict_details(G)
        assert d["loglik_in_range"] and d["success"]
    l_T = float(_guarded().frame_loglik(G[-1:])[0])
    at_floor = _guarded(frame_loglik_range=(l_T, l_T + 1.0), off_model=OffModelConfig(margin=0.0))
    assert at_floor.verdict_details(G)["final_frame_explained"]
    above = _guarded(frame_loglik_range=(np.nextafter(l_T, np.inf), l_T + 1.0), off_model=OffModelConfig(margin=0.0))
    assert not above.verdict_details(G)["final_frame_explained"]


# ------------------------------------------------------------------ progress reward (method.md 4.4)
@pytest.fixture(scope="module")
def progress_pomrp():
    X, lengths = sample_demonstrations(TRUE, [50, 60, 45], seed=0)
    return fit_pomrp(X, lengths, PomrpConfig(reward="progress", progress=ProgressConfig(scale=100.0))), X, lengths


def test_progress_line_and_the_demonstrations_own_progress(progress_pomrp):
    pomrp, X, lengths = progress_pomrp
    ends = np.cumsum(lengths)
    first, last = X[ends - lengths], X[ends - 1]
    np.testing.assert_allclose(pomrp.progress_line, [first.mean(axis=0), last.mean(axis=0)])
    # p is 0 at the mean first frame and 1 at the mean last frame; the demonstrations average 1.
    np.testing.assert_allclose(pomrp.progress(pomrp.progress_line), [0.0, 1.0], atol=1e-12)
    own = [pomrp.progress(X[e - n:e])[-1] - pomrp.progress(X[e - n:e])[0] for e, n in zip(ends, lengths)]
    assert np.mean(own) == pytest.approx(1.0) and pomrp.progress_least == pytest.approx(min(own))


def test_progress_return_telescopes_and_ranks_how_far_the_object_moved(progress_pomrp, held_out, stalled):
    pomrp = progress_pomrp[0]
    for G in held_out:
        h, R = pomrp.reward_and_return(G)
        phi = pomrp.progress(G) * pomrp.explained_weights(G)
        assert h[0] == 0.0 and R == pytest.approx(100.0 * (phi[-1] - phi[0]))
        assert R == pytest.approx(h.sum()) and R > 50.0      # a demonstration-like run: about c
        np.testing.assert_array_equal(pomrp.filtered_rewards(G), h)
    half, start = pomrp.episode_return(stalled["halfway"]), pomrp.episode_return(stalled["start"])
    assert min(pomrp.episode_return(G) for G in held_out) > half > start >= 0.0
    # A run that ends behind where it started earns 0, as a failed rollout (never less).
    assert pomrp.episode_return(held_out[0][::-1]) == 0.0


def test_progress_verdict_needs_the_least_demonstrations_progress(progress_pomrp, held_out, stalled):
    pomrp = progress_pomrp[0]
    details = pomrp.verdict_details(held_out[0])
    assert details["progress_needed"] == pytest.approx(0.95 * pomrp.progress_least)
    assert all(pomrp.verdict(G) for G in held_out)
    assert not pomrp.verdict(stalled["halfway"]) and not pomrp.verdict(stalled["start"])


def test_progress_streaming_equals_offline_and_round_trips(progress_pomrp, held_out):
    pomrp = progress_pomrp[0]
    G = held_out[1]
    lb, rewards = None, []
    for t, g in enumerate(G):
        lb, _, r = pomrp.filter_update(lb, g, first=(t == 0), previous=None if t == 0 else G[t - 1])
        rewards.append(r)
    np.testing.assert_allclose(rewards, pomrp.filtered_rewards(G), rtol=1e-12, atol=1e-12)
    with pytest.raises(ValueError, match="needs the previous frame"):
        pomrp.filter_update(lb, G[1], first=False)
    arrays, meta = pomrp.to_arrays()
    back = Pomrp.from_arrays(arrays, json.loads(json.dumps(meta)))
    assert back.reward_kind == "progress" and back.progress_config == ProgressConfig(scale=100.0)
    assert back.episode_return(G) == pomrp.episode_return(G) and back.verdict(G) == pomrp.verdict(G)


def test_progress_errors_name_the_cause(progress_pomrp):
    X, lengths = progress_pomrp[1], progress_pomrp[2]
    with pytest.raises(ValueError, match="reward: 'distance'; expected one of states, progress"):
        fit_pomrp(X, lengths, PomrpConfig(reward="distance"))
    still = np.repeat(X[:1], len(X), axis=0) + 1e-3 * np.random.default_rng(0).standard_normal(X.shape)
    still[np.cumsum(lengths) - 1] = still[np.cumsum(lengths) - lengths]    # each ends where it began
    with pytest.raises(ValueError, match="end where they start in goal space"):
        fit_pomrp(still, lengths, PomrpConfig(reward="progress"))
