"""Goal HMM: state-count selection, robustness of Baum-Welch, inference vs hmmlearn."""

import json
import logging
import re
import warnings

import numpy as np
import pytest
from hmmlearn.hmm import GaussianHMM
from pydrake.common.yaml import yaml_load_typed

from drake_skill.bench.reward import left_to_right_model, sample_demonstrations
from drake_skill.fileio import atomic_save_npz, atomic_write_json, load_npz
from goal_model_support import two_state_model_arrays
from scipy.special import logsumexp
from scipy.stats import multivariate_normal

from drake_skill.reward.goal_model import (
    GoalHMM,
    GoalModelConfig,
    check_sequences,
    forward_backward,
    forward_log,
    n_free_parameters,
    viterbi,
)
from drake_skill.reward.goal_model.inference import _backward_log

LENGTHS = [50, 60, 45]


def _data(k, seed, lengths=LENGTHS):
    model = left_to_right_model(n_states=k, seed=seed)
    X, lengths = sample_demonstrations(model, lengths, seed=seed)
    return model, X, lengths


def _reference(gm: GoalHMM) -> GaussianHMM:
    ref = GaussianHMM(n_components=gm.n_states_, covariance_type="full", init_params="")
    ref.startprob_, ref.transmat_, ref.means_, ref.covars_ = gm.startprob_, gm.transmat_, gm.means_, gm.covars_
    return ref


@pytest.fixture(scope="module")
def fitted4():
    model, X, lengths = _data(4, 0)
    return model, X, lengths, GoalHMM(random_state=0).fit(X, lengths)


def _match(gm, true_means):
    """Fitted state nearest to each true state's mean, and the distances."""
    dist = np.linalg.norm(gm.means_[:, None, :] - true_means[None, :, :], axis=2)  # (fitted, true)
    return dist.argmin(axis=0), dist.min(axis=0)


@pytest.mark.parametrize("k_true", [3, 6])
def test_aic_picks_true_state_count(k_true):
    # Default criterion (AIC), default range 2..8, diag and full: 3 seeds each.
    chosen = []
    for seed in range(3):
        _, X, lengths = _data(k_true, seed)
        chosen.append(GoalHMM(random_state=seed).fit(X, lengths).n_states_)
    assert chosen == [k_true] * 3


def test_fit_finds_states_terminal_and_structure(fitted4):
    model, X, lengths, gm = fitted4
    _, _, true_means, _ = model
    assert gm.n_states_ == 4
    assert gm.covariance_type_ in ("diag", "full")
    nearest, dist = _match(gm, true_means)
    assert sorted(nearest) == [0, 1, 2, 3] and dist.max() < 0.1
    # The one terminal state is the fitted copy of the true absorbing state.
    assert gm.terminal_states_.tolist() == [nearest[-1]]
    assert gm.startprob_[nearest[0]] > 0.99
    # Left to right: each state mostly stays or moves to the next true state.
    for a, b in zip(nearest[:-1], nearest[1:]):
        assert gm.transmat_[a, a] + gm.transmat_[a, b] > 0.98
    assert gm.converged_ and 0 <= gm.restart_ < 4
    ok = [r for r in gm.criterion_table_ if r["status"] == "ok"]
    best = min(ok, key=lambda r: r["aic"])
    assert (best["k"], best["covariance_type"]) == (gm.n_states_, gm.covariance_type_)
    assert gm.loglik_per_step_.shape == (3,)
    assert np.isclose(gm.log_likelihood_, gm.score(X, lengths))


def test_parameter_counts():
    # start k-1, transitions k(k-1), means k d, covariances by type.
    assert n_free_parameters(3, 8, "diag") == 2 + 6 + 24 + 24
    assert n_free_parameters(3, 8, "full") == 2 + 6 + 24 + 3 * 36
    assert n_free_parameters(3, 8, "spherical") == 2 + 6 + 24 + 3
    assert n_free_parameters(3, 8, "tied") == 2 + 6 + 24 + 36
    with pytest.raises(ValueError, match="covariance_type"):
        n_free_parameters(3, 8, "banana")


def test_every_covariance_type_fits():
    _, X, lengths = _data(3, 2, [40, 50])
    gm = GoalHMM(n_states_min=2, n_states_max=3, n_restarts=2,
                 covariance_types=["spherical", "diag", "full", "tied"]).fit(X, lengths)
    status = {(r["k"], r["covariance_type"]): r["status"] for r in gm.criterion_table_}
    assert len(status) == 8 and "failed" not in status.values()
    assert status[(3, "spherical")] == status[(3, "diag")] == status[(3, "tied")] == "ok"
    assert gm.n_states_ == 3
    # The true noise is isotropic: the fewest-parameter type that fits it wins.
    assert gm.covariance_type_ == "spherical"
    assert gm.covars_.shape == (3, 8, 8)


def test_bic_is_an_option(fitted4):
    _, X, lengths, gm = fitted4
    bic = GoalHMM(criterion="bic", random_state=0).fit(X, lengths)
    assert bic.n_states_ == 4
    rows = [r for r in bic.criterion_table_ if r["status"] == "ok"]
    assert min(rows, key=lambda r: r["bic"])["k"] == 4
    row = rows[0]
    assert np.isclose(row["bic"], -2 * row["log_likelihood"] + row["n_params"] * np.log(sum(lengths)))
    assert np.isclose(row["aic"], -2 * row["log_likelihood"] + 2 * row["n_params"])


def test_fit_is_deterministic():
    _, X, lengths = _data(3, 5)
    kw = dict(n_states_max=5, n_restarts=3, random_state=7)
    a, b = GoalHMM(**kw).fit(X, lengths), GoalHMM(**kw).fit(X, lengths)
    for name in ("startprob_", "transmat_", "means_", "covars_", "terminal_states_"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert a.criterion_table_ == b.criterion_table_


def test_fit_never_fails_on_few_short_sequences():
    # 20 seeds of 2-3 short, unstructured sequences (random walks of varied
    # scale); hmmlearn's own random init gives NaN start probabilities on some.
    for seed in range(20):
        rng = np.random.default_rng(seed)
        lengths = rng.integers(8, 20, size=rng.integers(2, 4))
        X = np.cumsum(rng.normal(0, rng.uniform(0.02, 0.5), (lengths.sum(), 8)), axis=0)
        # Default range k = 2..8 (capped by the shortest sequence); 2 restarts for time.
        gm = GoalHMM(n_restarts=2, random_state=seed).fit(X, lengths)
        k = gm.n_states_
        assert 2 <= k <= min(8, lengths.min())
        assert all(r["status"] != "failed" for r in gm.criterion_table_)
        for a in (gm.startprob_, gm.transmat_, gm.means_, gm.covars_):
            assert np.all(np.isfinite(a))
        assert np.isclose(gm.startprob_.sum(), 1) and np.allclose(gm.transmat_.sum(axis=1), 1)
        assert np.all(np.linalg.eigvalsh(gm.covars_) > 0)
        assert len(gm.terminal_states_) >= 1
        assert np.isfinite(gm.score(X, lengths))


def test_constant_feature_is_regularised():
    # A feature that never changes: without an M-step prior its variance is 0.
    _, X, lengths = _data(3, 1)
    X = X.copy()
    X[:, 5] = 0.3
    gm = GoalHMM(n_states_max=4, n_restarts=2, covariance_types=["full"]).fit(X, lengths)
    assert gm.covariance_type_ == "full"
    eps = 1e-3 * X.var(axis=0).mean()
    # covars = (eps I + scatter) / occupancy, occupancy <= N.
    assert np.linalg.eigvalsh(gm.covars_).min() >= eps / len(X) * 0.99
    assert np.isfinite(gm.score(X, lengths))


def test_convergence_read_from_history():
    _, X, lengths = _data(3, 2)
    one = GoalHMM(n_states_min=3, n_states_max=3, n_restarts=1, n_iter=1).fit(X, lengths)
    assert not one.converged_ and one.n_iter_ == 1  # budget ran out; hmmlearn says "converged"
    full = GoalHMM(n_states_min=3, n_states_max=3, n_restarts=1, n_iter=200).fit(X, lengths)
    assert full.converged_ and 2 <= full.n_iter_ < 200


def test_inference_matches_hmmlearn(fitted4):
    model, X, lengths, gm = fitted4
    ref = _reference(gm)
    G, _ = sample_demonstrations(model, [40], seed=99, reach_end=False)
    np.testing.assert_allclose(gm.predict_proba(G), ref.predict_proba(G), atol=1e-10)
    assert np.isclose(gm.score(G), ref.score(G), rtol=1e-10)
    assert np.isclose(gm.score(X, lengths), ref.score(X, lengths), rtol=1e-10)
    np.testing.assert_array_equal(gm.decode(G), ref.decode(G)[1])
    # Far from every state: probabilities underflow, the log-space recursion is exact.
    far = G + 40.0
    np.testing.assert_allclose(gm.predict_proba(far), ref.predict_proba(far), atol=1e-8)
    assert np.isclose(gm.score(far), ref.score(far), rtol=1e-10)


def test_forward_backward_brute_force():
    # Enumerate all k^T paths of a small random HMM.
    rng = np.random.default_rng(3)
    k, T = 3, 5
    pi = rng.dirichlet(np.ones(k))
    P = rng.dirichlet(np.ones(k), size=k)
    log_b = rng.normal(0, 2, (T, k))
    paths = np.array(np.meshgrid(*[np.arange(k)] * T, indexing="ij")).reshape(T, -1).T
    w = pi[paths[:, 0]] * np.prod(P[paths[:, :-1], paths[:, 1:]], axis=1) * np.exp(log_b[np.arange(T), paths].sum(1))
    filtered, smoothed, ll = forward_backward(log_b, pi, P)
    assert np.isclose(ll, np.log(w.sum()))
    for t in range(T):
        np.testing.assert_allclose(smoothed[t], np.bincount(paths[:, t], weights=w, minlength=k) / w.sum())
        # Filtered: marginalise the future out of the prefix likelihood.
        wt = pi[paths[:, 0]] * np.prod(P[paths[:, :t], paths[:, 1:t + 1]], axis=1) * np.exp(
            log_b[np.arange(t + 1), paths[:, :t + 1]].sum(1))
        f = np.bincount(paths[:, t], weights=wt, minlength=k)
        np.testing.assert_allclose(filtered[t], f / f.sum())
    path, lp = viterbi(log_b, pi, P)
    assert np.array_equal(path, paths[np.argmax(w)]) and np.isclose(lp, np.log(w.max()))
    # The plain reference recursion: log alpha_t(s) = log P(g_1..g_t, s_t = s), and log P(G).
    la, ll_ref = forward_log(log_b, np.log(pi), np.log(P))
    assert np.isclose(ll_ref, np.log(w.sum()))
    for t in range(T):
        wt = pi[paths[:, 0]] * np.prod(P[paths[:, :t], paths[:, 1:t + 1]], axis=1) * np.exp(
            log_b[np.arange(t + 1), paths[:, :t + 1]].sum(1))
        np.testing.assert_allclose(np.exp(la[t]), np.bincount(paths[:, t], weights=wt, minlength=k) / k ** (T - t - 1))


def test_save_load_round_trip(tmp_path, fitted4):
    _, X, lengths, gm = fitted4
    arrays, meta = gm.to_arrays()
    atomic_save_npz(tmp_path / "hmm.npz", arrays)
    atomic_write_json(tmp_path / "hmm.json", meta)
    back = GoalHMM.from_arrays(load_npz(tmp_path / "hmm.npz"), json.loads((tmp_path / "hmm.json").read_text()))
    assert back.n_states_ == gm.n_states_ and back.covariance_type_ == gm.covariance_type_
    assert back.restart_ == gm.restart_ and back.get_params() == gm.get_params()
    assert (back.converged_, back.n_iter_, back.log_likelihood_) == (gm.converged_, gm.n_iter_, gm.log_likelihood_)
    assert back.criterion_table_ == gm.criterion_table_ and back.n_iter_ > 1 and len(back.criterion_table_) == 14
    np.testing.assert_array_equal(back.terminal_states_, gm.terminal_states_)
    np.testing.assert_array_equal(back.predict_proba(X[:50]), gm.predict_proba(X[:50]))
    with pytest.raises(ValueError, match="means"):
        GoalHMM.from_arrays({k: v for k, v in arrays.items() if k != "means"}, meta)


def test_config_loads_from_yaml():
    cfg = yaml_load_typed(schema=GoalModelConfig, data="""
n_states_min: 3
n_states_max: 5
criterion: bic
covariance_types: [diag]
random_state: 4
""")
    gm = GoalHMM.from_config(cfg)
    assert (gm.n_states_min, gm.n_states_max, gm.criterion, list(gm.covariance_types), gm.random_state) == (
        3, 5, "bic", ["diag"], 4)


def test_bad_input_is_a_clear_error(fitted4):
    _, X, lengths, gm = fitted4
    with pytest.raises(ValueError, match=r"X: expected a 2-D array .* shape \(50,\)"):
        GoalHMM().fit(X[:50, 0])
    bad = X.copy()
    bad[7, 2] = np.nan
    with pytest.raises(ValueError, match="X: non-finite value nan at frame 7, feature 2"):
        GoalHMM().fit(bad, lengths)
    with pytest.raises(ValueError, match="X: empty sequence"):
        GoalHMM().fit(np.zeros((0, 8)))
    with pytest.raises(ValueError, match="lengths: sum 100 does not match the 155 frames"):
        GoalHMM().fit(X, [50, 50])
    with pytest.raises(ValueError, match="lengths: every sequence needs at least one frame"):
        GoalHMM().fit(X, [50, 105, 0])
    with pytest.raises(ValueError, match="lengths: demonstration 0 has 3 frames, fewer than .* n_states_min=4"):
        GoalHMM(n_states_min=4).fit(X[:3])
    with pytest.raises(ValueError, match="criterion"):
        GoalHMM(criterion="hqc").fit(X, lengths)
    with pytest.raises(ValueError, match=r"G: expected 8 features per frame, got shape \(10, 7\)"):
        gm.predict_proba(X[:10, :7])
    with pytest.raises(RuntimeError, match="not fitted"):
        GoalHMM().predict_proba(X[:10])


# ----------------------------------------------------------- log-space posteriors
def _strict_chain(k):
    """Strict left-to-right chain: stay 0.9 or move one state on; zero elsewhere."""
    P = np.zeros((k, k))
    for i in range(k - 1):
        P[i, i], P[i, i + 1] = 0.9, 0.1
    P[-1, -1] = 1.0
    pi = np.zeros(k)
    pi[0] = 1.0
    return pi, P


def _reference_posteriors(log_b, pi, P):
    """scipy logsumexp recursions (forward_log, _backward_log): the log-space reference."""
    with np.errstate(divide="ignore"):
        log_pi, log_P = np.log(pi), np.log(P)
    la, ll = forward_log(log_b, log_pi, log_P)
    lb = _backward_log(log_b, log_P)

    def norm(x):
        return np.exp(x - logsumexp(x, axis=1, keepdims=True))

    return norm(la), norm(la + lb), ll


@pytest.mark.parametrize("k, visits", [(3, [0] * 10 + [1] * 10 + [0] * 30),
                                       (4, [0] * 10 + [1] * 10 + [2] * 10 + [1] * 10 + [0] * 10)])
@pytest.mark.parametrize("gap", [20.0, 100.0, 1000.0])
def test_posteriors_are_exact_for_zero_transitions_and_huge_gaps(k, visits, gap):
    """The issue-12 reproducer: a strict chain visited 0 -> 1 -> 0 with log z_i = -gap |i - s_t|
    (NaN returns at gap 100 with the probability-space recursion)."""
    pi, P = _strict_chain(k)
    s = np.array(visits)
    log_b = -gap * np.abs(np.arange(k)[None, :] - s[:, None]).astype(float)
    filtered, smoothed, ll = forward_backward(log_b, pi, P)
    ref_f, ref_s, ref_ll = _reference_posteriors(log_b, pi, P)
    assert np.all(np.isfinite(filtered)) and np.all(np.isfinite(smoothed))
    np.testing.assert_allclose(filtered, ref_f, atol=1e-12)
    np.testing.assert_allclose(smoothed, ref_s, atol=1e-12)
    assert ll == pytest.approx(ref_ll, rel=1e-12)
    # Every row is a distribution (the probability-space recursion gave NaN or lost whole
    # posterior masses here).
    np.testing.assert_allclose(filtered.sum(axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(smoothed.sum(axis=1), 1.0, atol=1e-12)
    # The numpy fallback (hmmlearn's compiled recursions absent) gives the same numbers.
    import drake_skill.reward.goal_model.inference as gm_module
    saved = gm_module._hmmc
    try:
        gm_module._hmmc = None
        with warnings.catch_warnings():
            warnings.simplefilter("error")          # log 0 of a state no path reaches: no warning
            f2, s2, ll2 = forward_backward(log_b, pi, P)
    finally:
        gm_module._hmmc = saved
    np.testing.assert_allclose(f2, ref_f, atol=1e-12)
    np.testing.assert_allclose(s2, ref_s, atol=1e-12)
    assert ll2 == pytest.approx(ref_ll, rel=1e-12)


def test_from_arrays_validates_like_a_fit(fitted4):
    _, _, _, gm = fitted4
    arrays, meta = gm.to_arrays()
    k = gm.n_states_

    def broken(**changes):
        return {**arrays, **changes}

    cov = arrays["covars"].copy()
    cov[1, 0, 0] = np.nan
    rows = arrays["transmat"].copy()
    rows[2] *= 0.5
    not_pd = arrays["covars"].copy()
    not_pd[0] = -np.eye(not_pd.shape[1])
    for changes, message in [
            ({"covars": cov}, r"covars: contains NaN or inf"),
            ({"covars": not_pd}, r"covars: a covariance is not positive definite"),
            ({"transmat": rows}, r"transmat: row 2 sums to 0\.5"),
            ({"startprob": np.full(k, 0.5)}, r"startprob: not a probability vector"),
            ({"terminal_states": np.array([k])}, rf"terminal_states: \[{k}\], expected distinct states in \[0, {k}\)"),
            ({"terminal_states": np.array([], dtype=int)}, r"terminal_states: \[\], expected a non-empty"),
            ({"startprob": np.ones(k + 1) / (k + 1)}, rf"startprob: shape \({k + 1},\), expected \({k},\)")]:
        with pytest.raises(ValueError, match=message):
            GoalHMM.from_arrays(broken(**changes), meta, prefix="")
    with pytest.raises(ValueError, match=r"metadata 'n_states' = 99 disagrees"):
        GoalHMM.from_arrays(arrays, {**meta, "n_states": 99})


# ----------------------------------------------------------- hmmlearn API used
def test_compiled_forward_backward_is_hmmlearns_and_equals_plain_numpy():
    """goal_model keeps hmmlearn's private compiled recursions (filtered posteriors
    need the forward lattice, which the public API does not return): pinned here
    against the plain numpy recursion on a small model."""
    import drake_skill.reward.goal_model.inference as gm_module

    assert gm_module._hmmc is not None, "hmmlearn's compiled _hmmc.forward_log/backward_log are gone"
    rng = np.random.default_rng(7)
    k, T = 4, 30
    P = rng.dirichlet(np.ones(k), size=k)
    P[0, 2] = 0.0                      # a forbidden transition (log 0 = -inf)
    P /= P.sum(axis=1, keepdims=True)
    pi = rng.dirichlet(np.ones(k))
    log_b = rng.normal(scale=30.0, size=(T, k))
    la, lb = gm_module._lattices(log_b, pi, P, smooth=True)
    with np.errstate(divide="ignore"):
        log_pi, log_P = np.log(pi), np.log(P)
    np.testing.assert_allclose(la, gm_module._forward_log_np(log_b, log_pi, log_P), rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(lb, gm_module._backward_log_np(log_b, log_P), rtol=1e-12, atol=1e-9)


def test_posteriors_equal_hmmlearns_public_score_samples(fitted4):
    model, X, lengths, gm = fitted4
    G, _ = sample_demonstrations(model, [40], seed=5, reach_end=False)
    log_prob, posteriors = _reference(gm).score_samples(G)
    _, smoothed, log_lik = forward_backward(gm.log_emission(G), gm.startprob_, gm.transmat_)
    np.testing.assert_allclose(smoothed, posteriors, atol=1e-10)
    assert log_lik == pytest.approx(log_prob, rel=1e-10)


@pytest.mark.parametrize("ct", ["spherical", "diag", "full", "tied"])
def test_full_covariances_from_the_public_property(ct):
    """_full_covars reads hmmlearn's public covars_ (with the spherical shape fix): the
    same matrices, bit for bit, as built by hand from the private _covars_."""
    from drake_skill.reward.goal_model.initialisation import _full_covars

    rng = np.random.default_rng(1)
    X = rng.normal(size=(80, 3)) + np.repeat(np.eye(3)[:2] * 4, 40, axis=0)
    m = GaussianHMM(2, covariance_type=ct, n_iter=5, random_state=0).fit(X)
    c, eye = np.asarray(m._covars_, dtype=float), np.eye(3)
    by_hand = {"spherical": lambda: np.ravel(c).reshape(2, -1).mean(axis=1)[:, None, None] * eye,
               "diag": lambda: c[:, :, None] * eye,
               "tied": lambda: np.broadcast_to(c, (2, 3, 3)),
               "full": lambda: c}[ct]()
    np.testing.assert_array_equal(_full_covars(m), by_hand)


# ----------------------------------------------------------- exact contracts
@pytest.mark.parametrize("call, message", [
    (lambda: check_sequences(np.zeros(5)), "X: expected a 2-D array (frames, features), got shape (5,)"),
    (lambda: check_sequences(np.zeros((0, 8))), "X: empty sequence (shape (0, 8)); expected at least one frame"),
    (lambda: check_sequences(np.zeros((10, 7)), name="G", n_features=8),
     "G: expected 8 features per frame, got shape (10, 7)"),
    (lambda: check_sequences(np.array([[0.0, 1.0], [np.inf, 0.0], [np.nan, 0.0]])),
     "X: non-finite value inf at frame 1, feature 0"),
    (lambda: check_sequences(np.zeros((3, 2)), [[1, 2]]),
     "lengths: expected a non-empty 1-D list of integers, got [[1, 2]]"),
    (lambda: check_sequences(np.zeros((3, 2)), []), "lengths: expected a non-empty 1-D list of integers, got []"),
    (lambda: check_sequences(np.zeros((3, 2)), [np.nan]),
     "lengths: expected a non-empty 1-D list of integers, got [nan]"),
    (lambda: check_sequences(np.zeros((3, 2)), [1.5, 1.5]),
     "lengths: expected a non-empty 1-D list of integers, got [1.5, 1.5]"),
    (lambda: check_sequences(np.zeros((3, 2)), [3, 0]), "lengths: every sequence needs at least one frame, got [3, 0]"),
    (lambda: check_sequences(np.zeros((3, 2)), [2, 2]), "lengths: sum 4 does not match the 3 frames of X"),
    (lambda: n_free_parameters(3, 8, "banana"),
     "covariance_type: 'banana', expected one of ('spherical', 'diag', 'full', 'tied')"),
    (lambda: GoalHMM(criterion="hqc").fit(np.zeros((5, 2))), "criterion: 'hqc', expected one of ('aic', 'bic')"),
    (lambda: GoalHMM(covariance_types=[]).fit(np.zeros((5, 2))),
     "covariance_types: [], expected a non-empty subset of ('spherical', 'diag', 'full', 'tied')"),
    (lambda: GoalHMM(covariance_types=["diag", "round"]).fit(np.zeros((5, 2))),
     "covariance_types: ['diag', 'round'], expected a non-empty subset of ('spherical', 'diag', 'full', 'tied')"),
    (lambda: GoalHMM(n_states_min=0).fit(np.zeros((5, 2))),
     "n_states_min, n_states_max: (0, 8), expected 1 <= n_states_min <= n_states_max"),
    (lambda: GoalHMM(n_states_min=5, n_states_max=4).fit(np.zeros((5, 2))),
     "n_states_min, n_states_max: (5, 4), expected 1 <= n_states_min <= n_states_max"),
    (lambda: GoalHMM(n_restarts=0).fit(np.zeros((5, 2))), "n_restarts, n_iter: (0, 100), expected >= 1"),
    (lambda: GoalHMM(n_iter=0).fit(np.zeros((5, 2))), "n_restarts, n_iter: (4, 0), expected >= 1"),
    (lambda: GoalHMM(tol=0.0).fit(np.zeros((5, 2))), "tol, covar_reg: (0.0, 0.001), expected > 0"),
    (lambda: GoalHMM(covar_reg=-1.0).fit(np.zeros((5, 2))), "tol, covar_reg: (0.001, -1.0), expected > 0"),
    (lambda: GoalHMM(covar_reg=0.0).fit(np.zeros((5, 2))), "tol, covar_reg: (0.001, 0.0), expected > 0"),
    (lambda: GoalHMM(n_states_min=3).fit(np.zeros((7, 2)), [5, 2]),
     "lengths: demonstration 1 has 2 frames, fewer than the smallest state count n_states_min=3; "
     "expected every demonstration to have >= 3 frames"),
    (lambda: forward_backward(np.zeros((0, 2)), np.ones(2) / 2, np.eye(2)),
     "log_b: expected shape (T >= 1, k), got (0, 2)"),
    (lambda: forward_backward(np.array([[-np.inf, 0.0], [0.0, 0.0]]), np.array([1.0, 0.0]), np.eye(2)),
     "forward_backward: the sequence has probability zero under the chain "
     "(no state sequence allowed by startprob/transmat explains it)"),
])
def test_each_bad_goal_model_input_is_named_in_full(call, message):
    with pytest.raises(ValueError) as info:
        call()
    assert str(info.value) == message


def test_sequences_that_are_valid_at_the_edges():
    X, lengths = check_sequences([[1, 2]])
    assert X.dtype == float and lengths.tolist() == [1] and lengths.dtype.kind == "i"
    X, lengths = check_sequences(np.zeros((3, 2)), [1.0, 2.0])
    assert lengths.tolist() == [1, 2] and lengths.dtype.kind == "i"
    # One state, one restart, one iteration: the smallest model fits (k = 1 has no transitions to count).
    gm = GoalHMM(n_states_min=1, n_states_max=1, n_restarts=1, n_iter=1,
                 covariance_types=["spherical"]).fit(np.arange(10.0).reshape(5, 2))
    assert gm.n_states_ == 1 and gm.transmat_.tolist() == [[1.0]] and gm.startprob_.tolist() == [1.0]
    assert gm.criterion_table_[0]["n_params"] == n_free_parameters(1, 2, "spherical") == 3


@pytest.mark.parametrize("ct, covariance_params", [("spherical", 3), ("diag", 6), ("full", 9), ("tied", 3)])
def test_parameter_counts_of_three_states_in_two_dimensions(ct, covariance_params):
    count = n_free_parameters(3, 2, ct)
    assert count == 2 + 6 + 6 + covariance_params and isinstance(count, int)


def test_a_demonstration_of_exactly_n_states_min_frames_and_constant_data_fit():
    """The shortest demonstration may have exactly n_states_min frames; goal data that never changes
    (zero variance) is regularised with covar_reg itself and still fits."""
    _, X, _ = _data(3, 2, [40, 3])
    gm = GoalHMM(n_states_min=3, n_states_max=3, n_restarts=1, covariance_types=["diag"]).fit(X, [40, 3])
    assert gm.n_states_ == 3
    flat = GoalHMM(n_states_min=1, n_states_max=1, n_restarts=1, covariance_types=["diag"]).fit(np.ones((6, 2)))
    assert np.all(np.isfinite(flat.covars_)) and np.allclose(flat.means_, 1.0)


def test_the_state_count_is_capped_by_the_shortest_demonstration():
    _, X, lengths = _data(3, 2, [40, 3])
    gm = GoalHMM(n_states_max=6, n_restarts=1, covariance_types=["diag"]).fit(X, lengths)
    assert [row["k"] for row in gm.criterion_table_] == [2, 3]
    for row in gm.criterion_table_:
        if row["log_likelihood"] is not None:
            p, ll = row["n_params"], row["log_likelihood"]
            assert row["aic"] == float(-2 * ll + 2 * p) and row["bic"] == float(-2 * ll + p * np.log(43))


def test_inference_of_a_hand_written_model():
    """log_emission is the Gaussian log density; filtered, smoothed, score and decode agree with the
    recursions and with hmmlearn's public API on a model with a forbidden transition."""
    arrays, meta = two_state_model_arrays()
    gm = GoalHMM.from_arrays(arrays, meta)
    rng = np.random.default_rng(2)
    G = np.r_[rng.normal(0.0, 0.2, (6, 2)), rng.normal([1.0, 0.5], 0.1, (5, 2))]
    log_b = gm.log_emission(G)
    for i in range(2):
        np.testing.assert_allclose(log_b[:, i], multivariate_normal.logpdf(G, arrays["means"][i], arrays["covars"][i]),
                                   rtol=1e-12)
    filtered, smoothed, ll = forward_backward(log_b, arrays["startprob"], arrays["transmat"])
    np.testing.assert_array_equal(gm.filtered_posteriors(G), filtered)
    np.testing.assert_array_equal(gm.predict_proba(G), smoothed)
    assert not np.allclose(filtered, smoothed)
    ref = _reference(gm)
    assert gm.score(G) == pytest.approx(ref.score(G), rel=1e-12) == pytest.approx(ll, rel=1e-12)
    two = np.r_[G, G[::-1][:4]]
    assert gm.score(two, [11, 4]) == pytest.approx(ref.score(two, [11, 4]), rel=1e-12)
    with pytest.raises(ValueError) as info:
        gm.score(np.zeros((10, 3)))
    assert str(info.value) == "X: expected 2 features per frame, got shape (10, 3)"
    log_prob, path = ref.decode(G)
    assert np.array_equal(gm.decode(G), path) and path[0] == 0 and path[-1] == 1
    assert viterbi(log_b, arrays["startprob"], arrays["transmat"])[1] == pytest.approx(log_prob, rel=1e-12)


def test_samples_follow_the_model():
    arrays, meta = two_state_model_arrays()
    gm = GoalHMM.from_arrays(arrays, meta)
    G, states = gm.sample(400, random_state=3)
    again = gm.sample(400, random_state=3)
    assert states.dtype.kind == "i" and G.dtype == np.float64
    assert np.array_equal(G, again[0]) and np.array_equal(states, again[1])
    assert G.shape == (400, 2) and states[0] == 0 and np.all(np.diff(states) >= 0)      # 0 -> 1, never back
    assert 4 <= np.argmax(states == 1) <= 40                                            # leaves 0 at rate 0.1
    late = G[states == 1]
    np.testing.assert_allclose(late.mean(axis=0), arrays["means"][1], atol=0.02)
    np.testing.assert_allclose(np.cov(late.T), arrays["covars"][1], atol=0.003)
    with pytest.raises(RuntimeError) as info:
        GoalHMM().sample(3)
    assert str(info.value) == "GoalHMM: not fitted; call fit() or from_arrays() first"


def test_to_arrays_and_from_arrays_defaults():
    arrays, meta = two_state_model_arrays()
    gm = GoalHMM.from_arrays(arrays, {})
    assert (gm.n_states_, gm.n_features_in_, gm.covariance_type_, gm.restart_, gm.converged_, gm.n_iter_) == (
        2, 2, "full", 0, True, 0)
    assert np.isnan(gm.log_likelihood_) and gm.criterion_table_ == []
    assert gm.get_params() == GoalHMM().get_params() == {
        "n_states_min": 2, "n_states_max": 8, "criterion": "aic", "covariance_types": ["diag", "full"],
        "n_restarts": 4, "n_iter": 100, "tol": 1e-3, "covar_reg": 1e-3, "random_state": 0}
    out, out_meta = GoalHMM.from_arrays(arrays, {**meta, "params": {"n_states_max": 5}, "restart": 2}).to_arrays()
    assert sorted(out) == sorted(arrays)
    for name, value in arrays.items():
        np.testing.assert_array_equal(out[name], value)
    assert out["terminal_states"].dtype.kind == "i" and out["lengths"].dtype.kind == "i"
    assert out_meta == {"params": {**GoalHMM().get_params(), "n_states_max": 5}, "n_states": 2, "n_features": 2,
                        "covariance_type": "full", "restart": 2, "converged": True, "n_iter": 0,
                        "log_likelihood": out_meta["log_likelihood"], "criterion_table": []}
    assert json.dumps(out_meta["params"]) and GoalHMM.from_config(GoalModelConfig()).get_params()["covar_reg"] == 0.03
    given = GoalHMM.from_arrays(arrays, {"converged": False, "n_iter": 7, "log_likelihood": -3.5,
                                         "criterion_table": [{"k": 2}]})
    assert (given.converged_, given.n_iter_, given.log_likelihood_, given.criterion_table_) == (False, 7, -3.5,
                                                                                              [{"k": 2}])
    params = GoalHMM(criterion="bic", covariance_types=("full", "tied")).get_params()
    assert params["criterion"] == "bic" and params["covariance_types"] == ["full", "tied"]
    unsorted = GoalHMM.from_arrays({**arrays, "terminal_states": np.array([1.0, 0.0])}, meta)
    assert unsorted.terminal_states_.tolist() == [0, 1] and unsorted.terminal_states_.dtype.kind == "i"
    with pytest.raises(RuntimeError):
        GoalHMM().to_arrays()


def _arrays_with(**changes):
    arrays, _ = two_state_model_arrays()
    return {**arrays, **changes}


@pytest.mark.parametrize("arrays, metadata, message", [
    ({k: v for k, v in _arrays_with().items() if k not in ("means", "lengths")}, {},
     "missing array(s) ['hmm/means', 'hmm/lengths']"),
    (_arrays_with(), {"params": {"bogus": 1}},      # Python's own words, whatever it calls the constructor
     re.compile(r"goal-model metadata 'params': GoalHMM\.\S*__init__\S*\(\) "
                r"got an unexpected keyword argument 'bogus'")),
    (_arrays_with(means=np.array([["a", "b"], ["c", "d"]])), {}, "hmm/means: dtype <U1, expected numbers"),
    (_arrays_with(means=np.zeros(2)), {}, "hmm/means: shape (2,), expected (k, d) with k, d >= 1"),
    (_arrays_with(means=np.zeros((0, 2))), {}, "hmm/means: shape (0, 2), expected (k, d) with k, d >= 1"),
    (_arrays_with(transmat=np.eye(3)), {},
     "hmm/transmat: shape (3, 3), expected (2, 2) for 2 states of 2 features (means (2, 2))"),
    (_arrays_with(covars=np.stack([np.eye(3)] * 2)), {},
     "hmm/covars: shape (2, 3, 3), expected (2, 2, 2) for 2 states of 2 features (means (2, 2))"),
    (_arrays_with(means=np.array([[0.0, np.nan], [1.0, 0.5]])), {}, "hmm/means: contains NaN or inf"),
    (_arrays_with(startprob=np.array([np.inf, 0.0])), {}, "hmm/startprob: contains NaN or inf"),
    (_arrays_with(transmat=np.array([[0.9, 0.1], [np.nan, 1.0]])), {}, "hmm/transmat: contains NaN or inf"),
    (_arrays_with(loglik_per_step=np.array([-1.0, np.nan])), {}, "hmm/loglik_per_step: contains NaN or inf"),
    (_arrays_with(startprob=np.array([1.5, -0.5])), {},
     "hmm/startprob: not a probability vector (sum 1, min -0.5); expected non-negative entries summing to 1"),
    (_arrays_with(startprob=np.array([1.0, 2e-6])), {},
     "hmm/startprob: not a probability vector (sum 1, min 2e-06); expected non-negative entries summing to 1"),
    (_arrays_with(transmat=np.array([[0.9, 0.1], [1.5, -0.5]])), {},
     "hmm/transmat: row 1 sums to 1 (min entry -0.5); expected non-negative rows summing to 1"),
    (_arrays_with(transmat=np.array([[0.9, 0.1], [0.0, 1.0 + 2e-6]])), {},
     "hmm/transmat: row 1 sums to 1 (min entry 0); expected non-negative rows summing to 1"),
    (_arrays_with(covars=np.array([[[0.04, 0.01], [0.0, 0.09]], [[0.01, 0.0], [0.0, 0.01]]])), {},
     "hmm/covars: not symmetric"),
    (_arrays_with(covars=np.array([[[0.04, 0.01 + 1e-10], [0.01, 0.09]], [[0.01, 0.0], [0.0, 0.01]]])), {},
     "hmm/covars: not symmetric"),                                   # 1e-10 on 0.01: beyond rounding
    (_arrays_with(transmat=np.array([[1.0, 0.0], [0.5, 0.4]])), {},   # a zero entry is fine; row 1 is not
     "hmm/transmat: row 1 sums to 0.9 (min entry 0.4); expected non-negative rows summing to 1"),
    (_arrays_with(terminal_states=np.array([[1]])), {},
     "hmm/terminal_states: [[1]], expected a non-empty list of state indices"),
    (_arrays_with(terminal_states=np.array([0.5])), {},
     "hmm/terminal_states: [0.5], expected a non-empty list of state indices"),
    (_arrays_with(terminal_states=np.array([-1])), {}, "hmm/terminal_states: [-1], expected distinct states in [0, 2)"),
    (_arrays_with(terminal_states=np.array([1, 1])), {},
     "hmm/terminal_states: [1, 1], expected distinct states in [0, 2)"),
    (_arrays_with(lengths=np.array([20, 0])), {}, "hmm/lengths: [20, 0], expected demonstration frame counts >= 1"),
    (_arrays_with(lengths=np.array([], dtype=int)), {}, "hmm/lengths: [], expected demonstration frame counts >= 1"),
    (_arrays_with(lengths=np.array([20.5, 30])), {},
     "hmm/lengths: [20.5, 30.0], expected demonstration frame counts >= 1"),
    (_arrays_with(lengths=np.array([[20, 30]])), {},
     "hmm/lengths: [[20, 30]], expected demonstration frame counts >= 1"),
    (_arrays_with(loglik_per_step=np.array([-1.0, -1.0, -1.0])), {},
     "hmm/loglik_per_step: shape (3,), expected one value per demonstration (2,)"),
    (_arrays_with(), {"n_features": 5},
     "goal-model metadata 'n_features' = 5 disagrees with hmm/means of shape (2, 2)"),
    (_arrays_with(), {"covariance_type": "banana"},
     "goal-model metadata 'covariance_type' = 'banana', expected one of ('spherical', 'diag', 'full', 'tied')"),
])
def test_each_bad_saved_goal_model_is_named_in_full(arrays, metadata, message):
    with pytest.raises(ValueError) as info:
        GoalHMM.from_arrays(arrays, metadata, prefix="hmm/")
    if isinstance(message, re.Pattern):
        assert message.fullmatch(str(info.value)), str(info.value)
    else:
        assert str(info.value) == message


def test_saved_model_edges_load():
    """One state, a one-frame demonstration and integer arrays load (as floats); without a prefix the
    messages name the bare array."""
    one = {"startprob": np.array([1]), "transmat": np.array([[1]]), "means": np.array([[0, 1]]),
           "covars": np.array([[[1, 0], [0, 1]]]), "terminal_states": np.array([0]), "lengths": np.array([1, 30]),
           "loglik_per_step": np.array([-1, -2])}
    gm = GoalHMM.from_arrays(one, {})
    assert gm.n_states_ == 1 and gm.lengths_.tolist() == [1, 30]
    for name in ("startprob_", "transmat_", "means_", "covars_", "loglik_per_step_"):
        assert getattr(gm, name).dtype == np.float64
    with pytest.raises(ValueError) as info:
        GoalHMM.from_arrays({**one, "lengths": np.array([0])}, {})
    assert str(info.value) == "lengths: [0], expected demonstration frame counts >= 1"


def test_saved_probabilities_within_the_tolerance_load():
    gm = GoalHMM.from_arrays(_arrays_with(startprob=np.array([1.0, 5e-7]),
                                          transmat=np.array([[0.9, 0.1], [0.0, 1.0 - 5e-7]])), {})
    assert gm.startprob_[1] == 5e-7


def _brute_force_change_points(s, k):
    """Labels of the least-squares split of s into k contiguous non-empty segments, by enumeration."""
    from itertools import combinations

    best = None
    for cuts in combinations(range(1, len(s)), k - 1):
        bounds = (0, *cuts, len(s))
        cost = sum(((s[a:b] - s[a:b].mean(axis=0)) ** 2).sum() for a, b in zip(bounds[:-1], bounds[1:]))
        if best is None or cost < best[0] - 1e-12:
            best = (cost, np.repeat(np.arange(k), np.diff(bounds)))
    return best[1]


@pytest.mark.parametrize("seed, k", [(0, 1), (0, 2), (1, 3), (2, 4)])
def test_change_points_are_the_least_squares_split(seed, k):
    from drake_skill.reward.goal_model.initialisation import _change_point_labels

    rng = np.random.default_rng(seed)
    s = np.repeat(rng.normal(size=(k, 2)) * 2, rng.integers(2, 5, size=k), axis=0) + rng.normal(0, 0.3, (1, 2))
    s = s + rng.normal(0, 0.4, s.shape)
    assert np.array_equal(_change_point_labels(s, k), _brute_force_change_points(s, k))


def test_change_points_weigh_the_first_frame_and_exact_zeros():
    """The first frame is part of the first segment (an outlier there gets a segment of its own), and
    goal data with exact zeros splits as any other."""
    from drake_skill.reward.goal_model.initialisation import _change_point_labels

    s = np.array([[10.0, 1.0], [0.0, 0.0], [0.0, 0.0], [0.0, 0.0], [5.0, 0.0], [5.0, 0.0]])
    for k in (2, 3):
        assert np.array_equal(_change_point_labels(s, k), _brute_force_change_points(s, k))
    assert _change_point_labels(s, 2).tolist() == [0, 1, 1, 1, 1, 1]


def test_segmental_kmeans_is_a_fixed_point_of_the_left_to_right_alignment():
    """Each demonstration's labels are the cheapest path 0 -> ... (stay or step one state on) against
    the means of those labels, found here by enumerating every such path."""
    from drake_skill.reward.goal_model.initialisation import _segmental_kmeans

    rng = np.random.default_rng(4)
    k = 3
    segs = [np.repeat([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]], n, axis=0) + rng.normal(0, 0.3, (3 * n, 2))
            for n in (3, 4)]
    start = [np.r_[0, 1, np.full(len(s) - 2, 2)] for s in segs]           # a poor first split
    labels = _segmental_kmeans(segs, start, k)
    X = np.concatenate(segs)
    means = np.array([X[labels == j].mean(axis=0) for j in range(k)])
    np.testing.assert_array_equal(labels, _cheapest_left_to_right_paths(segs, means))
    assert not np.array_equal(labels, np.concatenate(start))              # the rounds moved something


def _cheapest_left_to_right_paths(segs, means):
    """Each sequence's cheapest path 0 -> ... (stay or step one state on, squared distances to the
    means), by enumerating every such path; concatenated."""
    best = []
    for s in segs:
        n = len(s)
        cost = ((s[:, None] - means[None]) ** 2).sum(axis=2)
        paths = [np.r_[0, np.cumsum(steps)] for steps in np.ndindex(*[2] * (n - 1))]
        paths = [p for p in paths if p.max() < len(means)]
        best.append(min(paths, key=lambda p: cost[np.arange(n), p].sum()))
    return np.concatenate(best)


# ----------------------------------------------------------- what fit keeps, and its rules
def test_fitted_attributes_are_those_of_the_winning_run(fitted4):
    _, X, lengths, gm = fitted4
    ends = np.cumsum(lengths)
    demos = [X[e - n:e] for e, n in zip(ends, lengths)]
    np.testing.assert_allclose(gm.loglik_per_step_, [gm.score(G) / len(G) for G in demos], rtol=1e-12)
    assert gm.log_likelihood_ == pytest.approx(gm.score(X, lengths), rel=1e-12)
    assert gm.terminal_states_.tolist() == sorted({int(gm.decode(G)[-1]) for G in demos})
    assert gm.lengths_.tolist() == list(lengths) and gm.n_features_in_ == 8
    row = next(r for r in gm.criterion_table_ if (r["k"], r["covariance_type"]) == (gm.n_states_, gm.covariance_type_))
    assert (row["restart"], row["converged"], row["n_iter"], row["status"]) == (
        gm.restart_, gm.converged_, gm.n_iter_, "ok")
    assert row["log_likelihood"] == pytest.approx(gm.log_likelihood_, rel=1e-9)
    assert [(r["k"], r["covariance_type"]) for r in gm.criterion_table_] == [
        (k, ct) for k in range(2, 9) for ct in ("diag", "full")]
    ok = [r for r in gm.criterion_table_ if r["status"] == "ok"]
    assert row["aic"] == min(r["aic"] for r in ok)
    json.dumps(gm.criterion_table_)


def _run_of(history, n_iter=100, tol=1e-3, transmat=((0.9, 0.1), (0.0, 1.0)), startprob=(1.0, 0.0),
            covariance_type="full", covars=None, frames=None):
    """``GoalHMM._validate_run`` of a real hmmlearn model with the given parameters and monitor history,
    on ``frames`` (default: 6 frames near each state's mean); returns ``(run, frames)``."""
    arrays, _ = two_state_model_arrays()
    model = GaussianHMM(n_components=2, covariance_type=covariance_type, init_params="")
    model.n_features = 2
    model.startprob_, model.transmat_ = np.array(startprob), np.array(transmat)
    model.means_ = arrays["means"]
    model.covars_ = arrays["covars"] if covars is None else covars
    model.monitor_.history.extend(history)
    X = frames
    if X is None:
        rng = np.random.default_rng(0)
        X = np.r_[rng.normal(0.0, 0.1, (6, 2)), rng.normal([1.0, 0.5], 0.05, (6, 2))]
    return GoalHMM(n_iter=n_iter, tol=tol)._validate_run(model, X, np.array([len(X)]), 3), X


@pytest.mark.parametrize("history, n_iter, converged", [
    ([-10.0, -9.0, -8.9995], 100, True),              # stopped on the tolerance
    ([-10.0, -9.0], 100, False),                      # last gain 1 >= tol: not by the tolerance
    ([-10.0], 100, False),                            # one iteration tells nothing
    ([-10.0, -9.0, -8.9995], 3, False),               # the budget ran out (hmmlearn says converged)
    ([-10.0, -9.0, -9.5, -9.4999], 100, False),       # a real likelihood drop
    ([-1000.0, -999.0, -999.000001, -999.0000005], 100, True),   # a drop of 1e-6 nats: rounding at 1e3
    ([-3.0, -1.0, -1.000000015], 100, False),         # 1.5e-8 nats below 1 nat: the floor of 1e-8 nats
    ([], 100, False),                                 # no iteration at all
])
def test_convergence_rule_on_the_monitor_history(history, n_iter, converged):
    run, _ = _run_of(history, n_iter=n_iter)
    assert run["converged"] is converged and run["n_iter"] == len(history) and run["restart"] == 3


def test_a_last_gain_of_exactly_the_tolerance_is_not_convergence():
    """hmmlearn stops when the gain is below tol; a gain equal to tol (exact in binary) is not."""
    assert not _run_of([-10.0, -9.0, -8.5], tol=0.5)[0]["converged"]
    assert _run_of([-10.0, -9.0, -8.5], tol=0.5000001)[0]["converged"]


def test_validated_run_repairs_and_measures():
    """A state without frames (an all-zero transition row) becomes absorbing, the start vector is
    renormalised; the log-likelihood is the forward pass's; occupancy is the smoothed posteriors' sum."""
    run, X = _run_of([-10.0, -9.0, -8.9995], transmat=((0.9, 0.1), (0.0, 0.0)), startprob=(2.0, 0.0))
    np.testing.assert_array_equal(run["transmat"], [[0.9, 0.1], [0.0, 1.0]])
    np.testing.assert_array_equal(run["startprob"], [1.0, 0.0])
    arrays, meta = two_state_model_arrays()
    gm = GoalHMM.from_arrays(arrays, meta)
    assert run["log_likelihood"] == pytest.approx(gm.score(X), rel=1e-12)
    assert run["min_occupancy"] == pytest.approx(gm.predict_proba(X).sum(axis=0).min(), rel=1e-12)
    assert 5.0 < run["min_occupancy"] < 7.0 and not run["degenerate"]        # 6 frames each: >= d + 1 = 3
    np.testing.assert_array_equal(run["covars"], arrays["covars"])


@pytest.mark.parametrize("covariance_type, covars, degenerate", [
    ("full", None, False),
    ("diag", np.array([[0.04, 0.09], [0.01, 0.01]]), False),
    ("spherical", np.array([0.05, 0.01]), False),
    ("tied", np.array([[0.04, 0.0], [0.0, 0.04]]), False),
])
def test_occupancy_needed_per_covariance_type(covariance_type, covars, degenerate):
    run, _ = _run_of([-10.0, -9.0, -8.9995], covariance_type=covariance_type, covars=covars)
    assert run["degenerate"] is degenerate


def test_a_state_explaining_two_frames_is_degenerate_for_a_full_covariance_only():
    """Occupancy 2 frames: a variance (diag) can be estimated, a 2-D full covariance needs d + 1 = 3."""
    rng = np.random.default_rng(0)
    X = np.r_[rng.normal(0.0, 0.05, (2, 2)), rng.normal([1.0, 0.5], 0.05, (10, 2))]
    for ct, covars, expected in (("full", None, True), ("diag", np.array([[0.04, 0.09], [0.01, 0.01]]), False)):
        run, _ = _run_of([-10.0, -9.0, -8.9995], covariance_type=ct, covars=covars, frames=X)
        assert run["min_occupancy"] == pytest.approx(2.0, abs=1e-3) and run["degenerate"] is expected


@pytest.mark.parametrize("covariance_type, covars, n0, degenerate", [
    ("full", np.array([[[0.01, 0.0], [0.0, 0.01]]] * 2), 2, True),     # 2.5 frames < d + 1 = 3
    ("full", np.array([[[0.01, 0.0], [0.0, 0.01]]] * 2), 3, False),    # 3.5 frames
    ("diag", np.full((2, 2), 0.01), 1, True),                          # 1.5 < 2
    ("diag", np.full((2, 2), 0.01), 2, False),                         # 2.5
    ("spherical", np.full(2, 0.01), 1, True),
    ("spherical", np.full(2, 0.01), 2, False),
    ("tied", np.array([[0.01, 0.0], [0.0, 0.01]]), 0, False),          # half a frame: tied needs none
])
def test_the_occupancy_a_covariance_needs_is_sharp(covariance_type, covars, n0, degenerate):
    """State 0 explains n0 frames at its mean plus half of a frame at the midpoint of the two means
    (equal densities, and stay probabilities equal so either split of the path is as likely):
    degenerate exactly when n0 + 0.5 is below d + 1 (full), 2 (diag, spherical) or 0 (tied)."""
    arrays, _ = two_state_model_arrays()
    m0, m1 = arrays["means"]
    X = np.r_[np.tile(m0, (n0, 1)), [(m0 + m1) / 2], np.tile(m1, (10, 1))]
    run, _ = _run_of([-10.0, -9.0, -8.9995], transmat=((0.9, 0.1), (0.1, 0.9)), startprob=(0.9, 0.1),
                     covariance_type=covariance_type, covars=covars, frames=X)
    assert run["min_occupancy"] == pytest.approx(n0 + 0.5, abs=1e-6) and run["degenerate"] is degenerate


def test_unusable_runs_are_dropped():
    assert _run_of([-1.0, -0.5], transmat=((np.nan, 1.0), (0.0, 1.0)))[0] is None
    assert _run_of([-1.0, -0.5], startprob=(np.inf, 0.0))[0] is None


@pytest.mark.parametrize("k", [1, 3])
def test_first_initialisation_is_left_to_right(k):
    """Restart 0: change points refined by segmental k-means; start on state 0 (leak 0.02 spread over
    the others), stay probabilities from the mean segment duration, clipped to [0.5, 0.98], the leak
    spread evenly; means of each label; covariances pulled toward the global diagonal by d + 2 frames."""
    from drake_skill.reward.goal_model.initialisation import _change_point_labels, _segmental_kmeans

    _, X, lengths = _data(3, 2, [30, 40])
    gm = GoalHMM(n_restarts=1)
    eps = 1e-3
    r, start, trans, means, covs = next(gm._inits(X, np.array(lengths), k, 1, eps))
    segs = [X[:30], X[30:]]
    lab = _segmental_kmeans(segs, [_change_point_labels(s, k) for s in segs], k)
    np.testing.assert_allclose(means, [X[lab == j].mean(axis=0) for j in range(k)], rtol=1e-12)
    assert r == 0
    if k == 1:
        assert start.tolist() == [1.0] and trans.tolist() == [[1.0]]
        return
    np.testing.assert_allclose(start, [0.98, 0.01, 0.01], rtol=1e-12)
    n = np.bincount(lab, minlength=k)
    stay = np.clip(1.0 - 2.0 / n, 0.5, 0.98)                       # duration = frames per demonstration
    expected = np.full((k, k), 0.01)
    for j in range(k - 1):
        expected[j, j], expected[j, j + 1] = stay[j] * 0.98, (1 - stay[j]) * 0.98
    expected[-1, -1] = 0.98
    np.testing.assert_allclose(trans, expected / expected.sum(axis=1, keepdims=True), rtol=1e-12)
    d = X.shape[1]
    glob = np.diag(X.var(axis=0) + eps)
    j = 1
    S = np.cov(X[lab == j].T, bias=True)
    np.testing.assert_allclose(covs[j], (n[j] * S + (d + 2.0) * glob / k) / (n[j] + d + 2.0) + eps * np.eye(d),
                               rtol=1e-12)


def test_later_initialisations_are_seeded_and_time_ordered():
    """Odd restarts: k-means clusters relabelled by mean relative time; even ones: random time cuts.
    Each restart draws from its own seed (random_state, k, covariance type, restart)."""
    _, X, lengths = _data(3, 2, [30, 40])
    inits = list(GoalHMM(n_restarts=4, random_state=5)._inits(X, np.array(lengths), 3, 1, 1e-3))
    assert [i[0] for i in inits] == [0, 1, 2, 3]
    again = list(GoalHMM(n_restarts=4, random_state=5)._inits(X, np.array(lengths), 3, 1, 1e-3))
    other = list(GoalHMM(n_restarts=4, random_state=6)._inits(X, np.array(lengths), 3, 1, 1e-3))
    for a, b in zip(inits, again):
        np.testing.assert_array_equal(a[3], b[3])
    assert any(not np.array_equal(a[3], b[3]) for a, b in zip(inits[1:], other[1:]))
    rel_t = np.r_[np.linspace(0, 1, 30), np.linspace(0, 1, 40)]
    for _, _, _, means, _ in inits:
        # The state means are ordered in time: the frames nearest each mean come later for later states.
        nearest = np.argmin(((X[:, None] - means[None]) ** 2).sum(axis=2), axis=1)
        order = [rel_t[nearest == j].mean() for j in range(3)]
        assert order == sorted(order)


@pytest.mark.parametrize("r", [1, 2, 3])
def test_later_restarts_follow_their_documented_recipes(r):
    """Restart r draws from default_rng([random_state, k, covariance type index, r]). Even r > 0: each
    demonstration cut at Dirichlet(2, ..., 2) fractions of its length (a frame on a cut starts the next
    segment), refined by segmental k-means. Odd r: k-means with one initialisation seeded from that
    generator, clusters relabelled in order of their frames' mean relative time."""
    from sklearn.cluster import KMeans

    from drake_skill.reward.goal_model.initialisation import _segmental_kmeans

    X, lengths = np.random.default_rng(0).normal(size=(70, 2)), [30, 40]   # no structure: starts matter
    k, ct_index = 3, 1
    inits = list(GoalHMM(n_restarts=4, random_state=5)._inits(X, np.array(lengths), k, ct_index, 1e-3))
    rng = np.random.default_rng([5, k, ct_index, r])
    segs = [X[:30], X[30:]]
    if r % 2 == 0:
        labels = []
        for s in segs:
            cuts = np.round(np.cumsum(rng.dirichlet(np.full(k, 2.0)))[:-1] * len(s)).astype(int)
            labels.append(np.searchsorted(cuts, np.arange(len(s)), side="right"))
        lab = _segmental_kmeans(segs, labels, k)
    else:
        raw = KMeans(n_clusters=k, n_init=1, random_state=int(rng.integers(2**31 - 1))).fit_predict(X)
        rel_t = np.r_[np.linspace(0, 1, 30), np.linspace(0, 1, 40)]
        lab = np.argsort(np.argsort([rel_t[raw == j].mean() for j in range(k)]))[raw]
    np.testing.assert_allclose(inits[r][3], [X[lab == j].mean(axis=0) for j in range(k)], rtol=1e-12)


def _init_covariance(pts, X, k, eps):
    """Restart covariances: the label's biased sample covariance pulled toward the global diagonal
    (variance + eps) by d + 2 pseudo-frames split over the k states, plus eps I."""
    n, d = pts.shape
    S = np.cov(pts.T, bias=True) if n > 1 else np.zeros((d, d))
    glob = np.diag(X.var(axis=0) + eps)
    return (n * S + (d + 2.0) * glob / k) / (n + d + 2.0) + eps * np.eye(d)


def test_first_initialisation_of_one_short_demonstration():
    """One demonstration of three well-separated pairs, three states: each state's mean and covariance
    are its pair's; of three frames: each state is one frame, with no sample covariance."""
    pairs = np.array([[0.0, 0.0], [0.1, 0.05], [3.0, 1.0], [3.2, 0.9], [6.0, 2.0], [5.9, 2.2]])
    for X, per_state in ((pairs, 2), (pairs[::2], 1)):
        _, _, trans, means, covs = next(GoalHMM(n_restarts=1)._inits(X, np.array([len(X)]), 3, 1, 1e-3))
        for j in range(3):
            pts = X[per_state * j:per_state * (j + 1)]
            np.testing.assert_allclose(means[j], pts.mean(axis=0), rtol=1e-12)
            np.testing.assert_allclose(covs[j], _init_covariance(pts, X, 3, 1e-3), rtol=1e-12)
        # 1 - 1 / duration is 0.5 or 0 here: the stay probability's floor 0.5 holds either way.
        expected = np.array([[0.49, 0.49, 0.01], [0.01, 0.49, 0.49], [0.01, 0.01, 0.98]])
        np.testing.assert_allclose(trans, expected / expected.sum(axis=1, keepdims=True), rtol=1e-12)


def test_first_initialisation_of_long_segments_with_two_states():
    """200 frames per state: stay 1 - 1/200 is capped at 0.98 (state 0 keeps 0.98 once its row is
    normalised); with two states the last state's whole leak 0.02 goes to the one other state."""
    X = np.repeat([[0.0, 0.0], [3.0, 1.0]], 200, axis=0) + np.random.default_rng(0).normal(0.0, 0.1, (400, 2))
    _, start, trans, _, _ = next(GoalHMM(n_restarts=1)._inits(X, np.array([400]), 2, 1, 1e-3))
    np.testing.assert_allclose(start, [0.98, 0.02], rtol=1e-12)
    np.testing.assert_allclose(trans, [[0.98, 0.02], [0.02, 0.98]], rtol=1e-12)


def test_a_state_the_alignment_leaves_empty_starts_on_one_random_frame():
    """Two 3-frame demonstrations whose left-to-right alignment never reaches state 2: that state starts
    on the one frame drawn from restart 0's generator, with no sample covariance."""
    from drake_skill.reward.goal_model.initialisation import _change_point_labels, _segmental_kmeans

    rng = np.random.default_rng(502)
    segs = [rng.normal(size=(int(rng.integers(3, 7)), 2)) for _ in range(2)]
    X = np.concatenate(segs)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        labels = _segmental_kmeans(segs, [_change_point_labels(s, 3) for s in segs], 3)
    assert 2 not in labels
    # Still a fixed point: the empty state's mean is that of all frames.
    means = np.array([X[labels == 0].mean(axis=0), X[labels == 1].mean(axis=0), X.mean(axis=0)])
    np.testing.assert_array_equal(labels, _cheapest_left_to_right_paths(segs, means))
    _, _, _, means, covs = next(GoalHMM(n_restarts=1, random_state=0)._inits(X, np.array([3, 3]), 3, 1, 1e-3))
    pick = X[np.random.default_rng([0, 3, 1, 0]).integers(len(X), size=1)]
    np.testing.assert_allclose(means[2], pick[0], rtol=1e-12)
    np.testing.assert_allclose(covs[2], _init_covariance(pick, X, 3, 1e-3), rtol=1e-12)


def test_numpy_recursions_where_no_path_explains_a_frame_from_some_state():
    """Emissions of -inf (a frame one state cannot emit): the numpy fallbacks keep -inf where no path
    continues (the backward pass from state 1, which must move to state 2 and cannot emit frame 2)
    and equal the scipy reference and hmmlearn's compiled recursions, without warnings."""
    import drake_skill.reward.goal_model.inference as gm_module

    pi = np.array([0.5, 0.5, 0.0])
    P = np.array([[0.5, 0.5, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    with np.errstate(divide="ignore"):
        log_b = np.log(np.array([[0.5, 0.2, 0.1], [0.3, 0.4, 0.2], [0.6, 0.1, 0.0], [0.2, 0.3, 0.5]]))
        log_pi, log_P = np.log(pi), np.log(P)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        la, lb = gm_module._forward_log_np(log_b, log_pi, log_P), gm_module._backward_log_np(log_b, log_P)
    assert lb[1, 1] == -np.inf and np.isfinite(lb[1, 0])
    np.testing.assert_array_equal(np.isinf(la), np.isinf(forward_log(log_b, log_pi, log_P)[0]))
    np.testing.assert_allclose(la, forward_log(log_b, log_pi, log_P)[0], rtol=1e-12)
    ref_lb = _backward_log(log_b, log_P)
    np.testing.assert_array_equal(np.isinf(lb), np.isinf(ref_lb))
    np.testing.assert_allclose(lb[np.isfinite(lb)], ref_lb[np.isfinite(ref_lb)], rtol=1e-12)
    c_la, c_lb = gm_module._lattices(log_b, pi, P, smooth=True)
    np.testing.assert_allclose(la, c_la, rtol=1e-12)
    np.testing.assert_allclose(lb[np.isfinite(lb)], c_lb[np.isfinite(c_lb)], rtol=1e-12)


def test_the_tolerance_reaches_baum_welch():
    """A tolerance of 1000 nats stops EM at its second iteration (the first gain it can measure)."""
    _, X, lengths = _data(3, 2)
    gm = GoalHMM(n_states_min=3, n_states_max=3, n_restarts=1, tol=1e3, covariance_types=["diag"]).fit(X, lengths)
    assert gm.n_iter_ == 2 and gm.converged_


# --------------------------------------------------- fits built to reach rare branches
def _three_features(seed=0, lengths=(30, 40)):
    """Two-state left-to-right goal data in 3-D, shifted so each feature has its own mean
    (the per-feature mean and variance then differ from those of all entries)."""
    _, X, lengths = _data(2, seed, list(lengths))
    return X[:, :3] + np.array([1.0, -2.0, 3.0]), np.asarray(lengths)


def _m_step(X, G, eps, ct):
    """The regularised M-step of the goal model's Baum-Welch for posteriors ``G`` (N, k):
    ``mu_j = sum_t g_tj x_t / n_j``, ``n_j = sum_t g_tj``; full ``(eps I + S_j) / n_j`` with scatter
    ``S_j = sum_t g_tj (x_t - mu_j)(x_t - mu_j)^T``; diag its diagonal; spherical the mean of that
    diagonal; tied ``(eps I + sum_j S_j) / N`` (docs/method.md section 3, the goal model)."""
    n = G.sum(axis=0)
    mu = G.T @ X / n[:, None]
    S = np.stack([(G[:, j, None] * (X - mu[j])).T @ (X - mu[j]) for j in range(G.shape[1])])
    eye = np.eye(X.shape[1])
    if ct == "full":
        return mu, (eps * eye + S) / n[:, None, None]
    if ct == "tied":
        return mu, np.broadcast_to((eps * eye + S.sum(axis=0)) / n.sum(), S.shape)
    var = (eps + np.diagonal(S, axis1=1, axis2=2)) / n[:, None]
    if ct == "spherical":
        var = np.repeat(var.mean(axis=1, keepdims=True), X.shape[1], axis=1)
    return mu, var[:, :, None] * eye


def _posteriors(X, lengths, start, trans, means, covars):
    ref = GaussianHMM(n_components=len(start), covariance_type="full", init_params="")
    ref.startprob_, ref.transmat_, ref.means_, ref.covars_ = start, trans, means, covars
    return np.concatenate([ref.predict_proba(X[sl]) for sl in np.split(np.arange(len(X)), np.cumsum(lengths)[:-1])])


@pytest.mark.parametrize("ct", ["spherical", "diag", "full", "tied"])
def test_a_converged_fit_is_the_fixed_point_of_the_regularised_m_step(ct):
    """Run to a tight tolerance, the fitted means and covariances are the M-step of their own
    posteriors, with eps = covar_reg * (mean per-feature variance)."""
    X, lengths = _three_features()
    gm = GoalHMM(n_states_min=2, n_states_max=2, n_restarts=1, covariance_types=[ct], tol=1e-9, n_iter=1000,
                 covar_reg=0.05).fit(X, lengths)
    assert gm.converged_
    G = _posteriors(X, lengths, gm.startprob_, gm.transmat_, gm.means_, gm.covars_)
    mu, covars = _m_step(X, G, 0.05 * X.var(axis=0).mean(), ct)
    np.testing.assert_allclose(gm.means_, mu, rtol=1e-8)
    np.testing.assert_allclose(gm.covars_, covars, rtol=1e-6, atol=1e-12)


@pytest.mark.parametrize("ct", ["spherical", "diag", "full", "tied"])
def test_one_iteration_is_the_m_step_of_the_first_initialisation(ct):
    """n_iter = 1: the fit is one M-step from the posteriors of restart 0's initialisation, whose
    covariances enter as themselves (full), their mean (tied), diagonal (diag) or mean variance
    (spherical)."""
    X, lengths = _three_features()
    gm = GoalHMM(n_states_min=2, n_states_max=2, n_restarts=1, covariance_types=[ct], n_iter=1,
                 covar_reg=0.05).fit(X, lengths)
    eps = 0.05 * X.var(axis=0).mean()
    _, start, trans, means, covs = next(gm._inits(X, lengths, 2, ["spherical", "diag", "full", "tied"].index(ct), eps))
    eye = np.eye(3)
    covs = {"full": covs, "tied": np.broadcast_to(covs.mean(axis=0), covs.shape),
            "diag": np.diagonal(covs, axis1=1, axis2=2)[:, :, None] * eye,
            "spherical": np.trace(covs, axis1=1, axis2=2)[:, None, None] / 3 * eye}[ct]
    mu, covars = _m_step(X, _posteriors(X, lengths, start, trans, means, covs), eps, ct)
    np.testing.assert_allclose(gm.means_, mu, rtol=1e-8)
    np.testing.assert_allclose(gm.covars_, covars, rtol=1e-6, atol=1e-12)


@pytest.mark.parametrize("value", [1.0, 0.3])
def test_constant_goal_data_is_regularised_by_covar_reg_itself(value):
    """Goal data that never changes: eps = covar_reg * 1, so one state over six identical frames has
    variance eps / 6, also for a value (0.3) whose computed variance is rounding (about 1e-33), not 0."""
    flat = GoalHMM(n_states_min=1, n_states_max=1, n_restarts=1, covariance_types=["diag"],
                   covar_reg=0.03).fit(np.full((12, 2), value), [6, 6])
    np.testing.assert_allclose(flat.covars_, [0.0025 * np.eye(2)], rtol=1e-9, atol=1e-20)


def test_regulariser_scale_is_the_mean_variance_above_rounding():
    from drake_skill.reward.goal_model import regulariser_scale

    X = np.random.default_rng(0).normal([1.0, -2.0], [0.5, 2.0], (200, 2))
    assert regulariser_scale(X) == pytest.approx(X.var(axis=0).mean(), rel=1e-12)
    assert regulariser_scale(np.full((5, 3), 0.3)) == 1.0 and regulariser_scale(np.zeros((5, 3))) == 1.0
    tiny = np.r_[np.zeros((5, 1)), np.full((5, 1), 1e-10)]        # a real spread of 5e-11, far above rounding
    assert regulariser_scale(tiny) == pytest.approx(0.25e-20, rel=1e-12)


class _FarLastState(GoalHMM):
    """Fault injection: restart 0 starts its last state's mean far from every frame, so that state
    receives no frame in the first E-step and keeps none."""

    def _inits(self, X, lengths, k, ct_index, eps):
        logging.getLogger("drake_skill.test").warning("far start")  # the user's logs must still reach them
        for r, start, trans, means, covs in super()._inits(X, lengths, k, ct_index, eps):
            means = means.copy()
            means[-1] = X.mean(axis=0) + 1e3 * X.std(axis=0).max()
            yield r, start, trans, means, covs


@pytest.mark.parametrize("ct, pseudo_frames", [("spherical", 1e-5), ("diag", 1e-5), ("full", 1e-8)])
def test_a_state_that_loses_every_frame_gets_the_prior(ct, pseudo_frames, caplog):
    """A state with no frame: its mean is the data's per-feature mean (the means prior), its covariance
    eps I over the prior's pseudo-occupancy (1e-8 for full; hmmlearn's floor 1e-5 for diag/spherical),
    its row absorbing; the run is usable, labelled degenerate, and no warning or hmmlearn log escapes,
    while other loggers still reach the user."""
    X, lengths = _three_features()
    caplog.set_level(logging.DEBUG)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        gm = _FarLastState(n_states_min=3, n_states_max=3, n_restarts=1, covariance_types=[ct]).fit(X, lengths)
    eps = 1e-3 * X.var(axis=0).mean()
    assert [row["status"] for row in gm.criterion_table_] == ["degenerate"]
    np.testing.assert_allclose(gm.means_[2], X.mean(axis=0), rtol=1e-9)
    np.testing.assert_allclose(gm.covars_[2], eps / pseudo_frames * np.eye(3), rtol=1e-6)
    assert gm.transmat_[2].tolist() == [0.0, 0.0, 1.0] and gm.startprob_[2] == 0.0
    assert [(r.name, r.getMessage()) for r in caplog.records] == [("drake_skill.test", "far start")]
    assert logging.getLogger("hmmlearn").level == logging.NOTSET  # restored after the fit


class _FailingRuns(GoalHMM):
    """Fault injection: the runs of the state counts in ``fail_k`` and the restarts in ``fail_restarts``
    are unusable (as non-finite parameters make them)."""

    def __init__(self, fail_k=(), fail_restarts=(), **kwargs):
        super().__init__(**kwargs)
        self.fail_k, self.fail_restarts = fail_k, fail_restarts

    def _validate_run(self, model, X, lengths, r):
        if model.n_components in self.fail_k or r in self.fail_restarts:
            return None
        return super()._validate_run(model, X, lengths, r)


def test_a_candidate_whose_every_run_fails_is_a_failed_row():
    X, lengths = _three_features()
    kwargs = dict(n_states_min=2, n_states_max=3, n_restarts=1, covariance_types=["diag"])
    gm = _FailingRuns(fail_k=(2,), **kwargs).fit(X, lengths)
    assert gm.criterion_table_[0] == {"k": 2, "covariance_type": "diag", "n_params": n_free_parameters(2, 3, "diag"),
                                      "status": "failed", "log_likelihood": None, "aic": None, "bic": None,
                                      "restart": None, "converged": False, "n_iter": None}
    assert gm.criterion_table_[1]["status"] == "ok" and gm.n_states_ == 3
    with pytest.raises(RuntimeError, match=r"^GoalHMM\.fit: every Baum-Welch run produced non-finite parameters$"):
        _FailingRuns(fail_k=(2, 3), **kwargs).fit(X, lengths)


def test_a_failed_restart_is_followed_by_the_next():
    X, lengths = _three_features()
    kwargs = dict(n_states_min=2, n_states_max=2, n_restarts=2, covariance_types=["diag"])
    assert _FailingRuns(fail_restarts=(0,), **kwargs).fit(X, lengths).restart_ == 1

    class BadFirstStart(GoalHMM):  # restart 0's start probabilities sum to 2: hmmlearn raises ValueError
        def _inits(self, X, lengths, k, ct_index, eps):
            for r, start, *rest in super()._inits(X, lengths, k, ct_index, eps):
                yield (r, start * 2.0 if r == 0 else start, *rest)

    assert BadFirstStart(**kwargs).fit(X, lengths).restart_ == 1


def test_a_proper_restart_beats_a_degenerate_one_of_higher_likelihood():
    class FirstDegenerate(GoalHMM):
        def _validate_run(self, model, X, lengths, r):
            run = super()._validate_run(model, X, lengths, r)
            return dict(run, degenerate=True, log_likelihood=run["log_likelihood"] + 1e3) if r == 0 else run

    X, lengths = _three_features()
    gm = FirstDegenerate(n_states_min=2, n_states_max=2, n_restarts=2, covariance_types=["diag"]).fit(X, lengths)
    assert gm.restart_ == 1 and gm.criterion_table_[0]["status"] == "ok"


def test_the_terminal_state_is_the_last_frames_viterbi_state():
    """Each demonstration ends with one frame far from the rest: that frame's state is terminal,
    not the state of the frame before it."""
    rng = np.random.default_rng(0)
    demo = lambda: np.r_[rng.normal(0.0, 0.1, (8, 2)), rng.normal(3.0, 0.1, (8, 2)), rng.normal(9.0, 0.1, (1, 2))]  # noqa: E731
    X = np.concatenate([demo() for _ in range(3)])
    gm = GoalHMM(n_states_min=3, n_states_max=3, n_restarts=1, covariance_types=["diag"]).fit(X, [17, 17, 17])
    last = int(np.argmin(np.linalg.norm(gm.means_ - 9.0, axis=1)))
    assert gm.terminal_states_.tolist() == [last]
    assert gm.decode(X[:17])[-2] != last
