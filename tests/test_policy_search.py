"""Policy search (drake_skill.learning.policy_search): docs/method.md section 5.

The analytic task is a self-contained numpy DMP (it does not use the
project's DMP module) whose trajectory should pass through a via-point at
mid-time. Hand-computed updates are written out with explicit loops, apart
from the implementation's vectorised code path.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from drake_skill.learning.policy_search import (
    CMAES,
    METHODS,
    PER_STEP_METHODS,
    PI2ES,
    PI2ESCov,
    PoWER,
    load_policy_search,
    make_policy_search,
    policy_search_from_state,
    reward_to_go,
    rollout_probabilities,
    sigma_schedule,
)

# ---------------------------------------------------------------------------
# A tiny DMP via-point task
# ---------------------------------------------------------------------------

N_BASES, N_DIMS, N_STEPS = 6, 2, 100
DT, K, DAMPING, ALPHA_X = 1.0 / N_STEPS, 100.0, 20.0, 4.0  # tau = 1 s
Y0, GOAL = np.zeros(N_DIMS), np.ones(N_DIMS)
VIA_STEP, VIA_POINT = N_STEPS // 2, np.array([0.9, 0.4])
ACTION_COST = 1e-3
CENTRES = np.exp(-ALPHA_X * np.linspace(0.0, 1.0, N_BASES))
WIDTHS = 1.0 / np.diff(CENTRES, append=0.5 * CENTRES[-1]) ** 2
RETURN_SCALE = 100.0  # returns of order ten, as Eq. 5.1's weighting needs


def dmp_rollout(weights: np.ndarray) -> np.ndarray:
    """Euler-integrate the DMP for a batch of weights (n, B, D) -> (n, T, D).

    tau dz = K (g - y) - D z + f(x), tau dy = z, tau dx = -alpha x,
    f(x) = K x sum_b psi_b(x) w_b / sum_b psi_b(x) (forcing in units of K).
    """
    weights = np.asarray(weights, dtype=float)
    n = len(weights)
    y = np.tile(Y0, (n, 1))
    z = np.zeros((n, N_DIMS))
    x = 1.0
    path = np.empty((n, N_STEPS, N_DIMS))
    for t in range(N_STEPS):
        psi = np.exp(-WIDTHS * (x - CENTRES) ** 2)
        forcing = K * x * np.einsum("b,nbd->nd", psi, weights) / psi.sum()
        z = z + DT * (K * (GOAL - y) - DAMPING * z + forcing)
        y = y + DT * z
        x = x - DT * ALPHA_X * x
        path[:, t] = y
    return path


def task_terms(weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Squared via-point miss (n,) and action cost (n,)."""
    path = dmp_rollout(weights)
    miss = np.sum((path[:, VIA_STEP] - VIA_POINT) ** 2, axis=1)
    action = ACTION_COST * np.sum(np.asarray(weights) ** 2, axis=(1, 2))
    return miss, action


def task_cost(weights: np.ndarray) -> np.ndarray:
    miss, action = task_terms(weights)
    return miss + action


def task_results(method: str, weights: np.ndarray) -> np.ndarray:
    """What each method is told: returns (n,) or per-step rewards (n, T)."""
    miss, action = task_terms(weights)
    if method == "power":
        return np.exp(-10.0 * (miss + action))  # non-negative returns
    if method in PER_STEP_METHODS:
        rewards = np.tile(-action[:, None] / N_STEPS, (1, N_STEPS))
        rewards[:, VIA_STEP] -= miss
        return RETURN_SCALE * rewards
    return -RETURN_SCALE * (miss + action)


def initial_distribution(scale: float = 1.0):
    mean = np.zeros((N_BASES, N_DIMS))
    covariances = np.tile(scale ** 2 * np.eye(N_DIMS), (N_BASES, 1, 1))
    return mean, covariances


#: Thesis budgets (docs/method.md section 5): (episodes E, rollouts C).
BUDGETS = {"power": (30, 1), "pi2": (5, 6), "pi2-cov": (5, 6),
           "pi2-es": (5, 6), "pi2-es-cov": (5, 6), "cma-es": (5, 6)}


def run_task(method: str, seed: int, **options) -> float:
    """Greedy cost after learning / greedy cost before."""
    n_episodes, n_rollouts = BUDGETS[method]
    mean, covariances = initial_distribution()
    search = make_policy_search(method, mean, covariances,
                                n_episodes=n_episodes, seed=seed, **options)
    before = task_cost(mean[None])[0]
    for _ in range(n_episodes):
        samples = search.ask(n_rollouts)
        search.tell(samples, task_results(method, samples))
    return task_cost(search.mean[None])[0] / before


@pytest.mark.parametrize("method", METHODS)
def test_every_method_improves_the_via_point_task(method):
    ratios = np.array([run_task(method, seed) for seed in range(10)])
    assert np.sum(ratios < 0.5) >= 9, ratios
    assert np.median(ratios) < 0.5, ratios


@pytest.mark.parametrize("method", ["pi2-es", "pi2-es-cov"])
def test_range_weighting_also_improves(method):
    ratios = np.array([run_task(method, seed, weighting="range")
                       for seed in range(10)])
    assert np.sum(ratios < 0.5) >= 9, ratios


# ---------------------------------------------------------------------------
# Hand-computed updates on a tiny example: B = 2, D = 2, C = 3
# ---------------------------------------------------------------------------

MEAN0 = np.array([[0.0, 0.0], [1.0, -1.0]])
SIGMA0 = np.array([[[1.0, 0.2], [0.2, 0.5]], [[2.0, 0.0], [0.0, 1.0]]])
SAMPLES = np.array([
    [[0.5, -0.2], [1.3, -0.4]],
    [[-0.3, 0.8], [0.2, -1.5]],
    [[0.1, 0.4], [1.9, -0.7]],
])
RETURNS = np.array([1.0, 3.0, 2.0])
REWARDS = np.array([  # per-step rewards (C = 3, T = 3)
    [0.0, 1.0, 0.0],
    [2.0, 0.5, 0.0],
    [0.0, 0.0, 0.0],
])


def weighted_mean(weights, samples):
    out = np.zeros_like(samples[0])
    for w, s in zip(weights, samples):
        out += w * s
    return out


def weighted_covariances(weights, samples, centre):
    out = np.zeros((samples.shape[1], samples.shape[2], samples.shape[2]))
    for w, s in zip(weights, samples):
        for b in range(samples.shape[1]):
            d = s[b] - centre[b]
            out[b] += w * np.outer(d, d)
    return out


def thesis_probabilities(returns):
    c = len(returns)
    e = [math.exp(r / c) for r in returns]
    return np.array(e) / sum(e)


def range_probabilities(returns, h=10.0):
    lo, hi = min(returns), max(returns)
    if hi == lo:
        return np.full(len(returns), 1.0 / len(returns))
    e = [math.exp(h * (r - lo) / (hi - lo)) for r in returns]
    return np.array(e) / sum(e)


def test_hand_probabilities():
    # Eq. 5.1: exp(R / 3) = e^(1/3), e^1, e^(2/3).
    p = thesis_probabilities(RETURNS)
    z = math.exp(1 / 3) + math.e + math.exp(2 / 3)
    np.testing.assert_allclose(p, [math.exp(1 / 3) / z, math.e / z,
                                   math.exp(2 / 3) / z])
    # Range: exponents 10 * (R - 1) / 2 = 0, 10, 5.
    p = range_probabilities(RETURNS)
    z = 1 + math.exp(10) + math.exp(5)
    np.testing.assert_allclose(p, [1 / z, math.exp(10) / z, math.exp(5) / z])


@pytest.mark.parametrize("weighting", ["thesis", "range"])
def test_pi2_es_update_by_hand(weighting):
    search = make_policy_search("pi2-es", MEAN0, SIGMA0, weighting=weighting)
    search.tell(SAMPLES, RETURNS)
    p = (thesis_probabilities if weighting == "thesis"
         else range_probabilities)(RETURNS)
    np.testing.assert_allclose(search.mean, weighted_mean(p, SAMPLES),
                               rtol=1e-12)
    np.testing.assert_array_equal(search.covariances, SIGMA0)  # schedule only


@pytest.mark.parametrize("weighting", ["thesis", "range"])
def test_pi2_es_cov_update_by_hand(weighting):
    search = make_policy_search("pi2-es-cov", MEAN0, SIGMA0,
                                weighting=weighting, floor_fraction=1e-6)
    search.tell(SAMPLES, RETURNS)
    p = (thesis_probabilities if weighting == "thesis"
         else range_probabilities)(RETURNS)
    np.testing.assert_allclose(search.mean, weighted_mean(p, SAMPLES),
                               rtol=1e-12)
    # Eq. 5.5 around the mean the episode was sampled from (MEAN0).
    np.testing.assert_allclose(search.covariances,
                               weighted_covariances(p, SAMPLES, MEAN0),
                               rtol=1e-12, atol=1e-15)
    assert search.sigma == 1.0


def per_step_probabilities_by_hand(rewards, h=10.0):
    """P_{t,c} (T, C) from the reward-to-go, range weighting at each step."""
    n_rollouts, n_steps = rewards.shape
    out = np.zeros((n_steps, n_rollouts))
    for t in range(n_steps):
        to_go = [sum(rewards[c, t:]) for c in range(n_rollouts)]
        out[t] = range_probabilities(to_go, h)
    return out


def test_reward_to_go():
    np.testing.assert_array_equal(
        reward_to_go(REWARDS), [[1.0, 1.0, 0.0], [2.5, 0.5, 0.0],
                                [0.0, 0.0, 0.0]])


def test_pi2_update_by_hand():
    search = make_policy_search("pi2", MEAN0, SIGMA0)
    search.tell(SAMPLES, REWARDS)
    p = per_step_probabilities_by_hand(REWARDS)
    # Eq. 3.28 per step, then Eq. 3.29 with weights T - t = 3, 2, 1.
    per_step = [weighted_mean(p[t], SAMPLES) for t in range(3)]
    expected = (3 * per_step[0] + 2 * per_step[1] + 1 * per_step[2]) / 6
    np.testing.assert_allclose(search.mean, expected, rtol=1e-12)
    # The last step's reward-to-go is 0 for every rollout: uniform weights.
    np.testing.assert_allclose(per_step[2], SAMPLES.mean(axis=0))


def test_pi2_cov_update_by_hand():
    search = make_policy_search("pi2-cov", MEAN0, SIGMA0, floor_fraction=1e-6)
    search.tell(SAMPLES, REWARDS)
    p = per_step_probabilities_by_hand(REWARDS)
    means = [weighted_mean(p[t], SAMPLES) for t in range(3)]
    covs = [weighted_covariances(p[t], SAMPLES, MEAN0) for t in range(3)]
    np.testing.assert_allclose(
        search.mean, (3 * means[0] + 2 * means[1] + means[2]) / 6, rtol=1e-12)
    # Eq. 3.30 per step around the sampled-from mean, Eq. 3.31 average.
    np.testing.assert_allclose(
        search.covariances, (3 * covs[0] + 2 * covs[1] + covs[2]) / 6,
        rtol=1e-12, atol=1e-15)


def test_power_update_by_hand():
    search = make_policy_search("power", MEAN0, SIGMA0, n_best=2)
    search.tell(SAMPLES, RETURNS)
    # Best two of [1, 3, 2]: rollouts 1 (R = 3) and 2 (R = 2).
    m1 = MEAN0 + ((SAMPLES[1] - MEAN0) * 3 + (SAMPLES[2] - MEAN0) * 2) / 5
    np.testing.assert_allclose(search.mean, m1, rtol=1e-12)
    new = np.array([[[2.0, 2.0], [0.0, 0.0]], [[-1.0, 0.5], [0.5, 0.5]]])
    search.tell(new, [0.5, 4.0])
    # Memory returns [1, 3, 2, 0.5, 4]: best two are new[1] (4), SAMPLES[1] (3).
    m2 = m1 + ((new[1] - m1) * 4 + (SAMPLES[1] - m1) * 3) / 7
    np.testing.assert_allclose(search.mean, m2, rtol=1e-12)
    memory_samples, memory_returns = search.memory
    assert memory_samples.shape == (5, 2, 2)
    np.testing.assert_array_equal(memory_returns, [1.0, 3.0, 2.0, 0.5, 4.0])


def test_power_all_zero_returns_leave_the_mean():
    search = make_policy_search("power", MEAN0, SIGMA0)
    search.tell(SAMPLES, np.zeros(3))
    np.testing.assert_array_equal(search.mean, MEAN0)
    assert search.episode == 1


def test_cma_es_first_update_by_hand():
    # popsize 4: mu = 2 recombination weights ln(5/2) - ln(i), normalised;
    # CMA-ES's first mean is their average of the two best samples.
    search = make_policy_search("cma-es", MEAN0, SIGMA0, popsize=4, seed=3)
    np.testing.assert_array_equal(search.sampling_covariances, SIGMA0)
    samples = search.ask(4)
    returns = np.array([1.0, 3.0, 2.0, 0.5])
    search.tell(samples, returns)
    w = np.array([math.log(2.5), math.log(2.5) - math.log(2.0)])
    w /= w.sum()
    np.testing.assert_allclose(search.mean, w[0] * samples[1] + w[1] * samples[2],
                               rtol=1e-12, atol=1e-14)


def test_sampling_uses_the_scaled_covariance():
    # Eq. 5.3: w^c = w + sqrt(sigma_e) L z with Sigma0 = L L^T; the draws are
    # standard normals (C, B, D) from the seeded generator, one block per ask.
    search = make_policy_search("pi2-es", MEAN0, SIGMA0, n_episodes=5, seed=7)
    rng = np.random.default_rng(7)
    lower = np.linalg.cholesky(SIGMA0)
    for sigma in [1.0, 1.0, 0.8]:
        z = rng.standard_normal((3, 2, 2))
        expected = search.mean + math.sqrt(sigma) * np.einsum(
            "bij,nbj->nbi", lower, z)
        assert search.sigma == pytest.approx(sigma)
        samples = search.ask(3)
        np.testing.assert_allclose(samples, expected, rtol=1e-12)
        search.tell(samples, RETURNS)


def _block_covariances(samples, mean):
    """Per-basis sample covariances (B, D, D) of samples (n, B, D) about ``mean`` (B, D)."""
    d = samples - mean
    return np.einsum("nbi,nbj->bij", d, d) / len(samples)


def test_cma_es_samples_follow_the_whitened_covariance():
    # vec(W) = vec(W0) + L z, z ~ N(0, sigma0^2 I): the samples' covariance is
    # sigma0^2 Sigma0 per basis and zero across bases. Sigma0 strongly
    # correlated, so that L L^T and L^T L differ (4.81 against 4 in [0, 0, 0]).
    sigma0 = np.array([[[4.0, 1.8], [1.8, 1.0]], [[0.5, -0.3], [-0.3, 2.0]]])
    n = 4000   # sample covariances within about 5 %, fixed seed
    search = make_policy_search("cma-es", MEAN0, sigma0, sigma0=0.5, popsize=n, seed=2)
    samples = search.ask(n)
    np.testing.assert_allclose(samples.mean(axis=0), MEAN0, atol=0.05)
    np.testing.assert_allclose(_block_covariances(samples, MEAN0), 0.25 * sigma0, rtol=0.08, atol=0.02)
    np.testing.assert_allclose(search.sampling_covariances, 0.25 * sigma0, rtol=1e-3)
    across = np.einsum("ni,nj->ij", samples[:, 0] - MEAN0[0], samples[:, 1] - MEAN0[1]) / n
    assert np.abs(across).max() < 0.05
    # After an update, the next samples follow what the search reports: its mean
    # and sampling_covariances (the blocks of sigma^2 L C L^T).
    search.tell(samples, -np.sum((samples - [[1.0, 0.0], [0.0, 1.0]]) ** 2, axis=(1, 2)))
    after = search.ask(n)
    np.testing.assert_allclose(after.mean(axis=0), search.mean, atol=0.05)
    expected = search.sampling_covariances
    assert not np.allclose(expected, 0.25 * sigma0, rtol=0.2)   # the update changed them
    np.testing.assert_allclose(_block_covariances(after, search.mean), expected, rtol=0.1,
                               atol=0.03 * np.abs(expected).max())


# ---------------------------------------------------------------------------
# Sigma schedule (Eq. 5.4), eigenvalue floor
# ---------------------------------------------------------------------------


def test_sigma_schedule_thesis_budgets():
    # E = 5, U = 1.25: decay starts after episode index 1.
    values = [sigma_schedule(e, 5) for e in range(5)]
    np.testing.assert_allclose(values, [1.0, 1.0, 1 - 0.75 / 3.75,
                                        1 - 1.75 / 3.75, 1 - 2.75 / 3.75])
    assert values[-1] > 0
    # Past the budget the last value is kept, never zero.
    assert sigma_schedule(5, 5) == sigma_schedule(50, 5) == values[-1]
    # E = 30 (PoWER), U = 7.5.
    assert sigma_schedule(7, 30) == 1.0
    assert sigma_schedule(8, 30) == pytest.approx(1 - 0.5 / 22.5)
    assert sigma_schedule(29, 30) == pytest.approx(1 / 22.5)
    assert sigma_schedule(2, 5, sigma0=2.0) == pytest.approx(1.6)
    assert sigma_schedule(0, 1) == 1.0


@pytest.mark.parametrize("method", ["power", "pi2", "pi2-es"])
def test_methods_follow_the_schedule(method):
    search = make_policy_search(method, MEAN0, SIGMA0, n_episodes=5)
    results = REWARDS if method in PER_STEP_METHODS else RETURNS
    seen = []
    for _ in range(6):
        seen.append(search.sigma)
        search.tell(SAMPLES, results)
    np.testing.assert_allclose(seen, [sigma_schedule(e, 5) for e in range(6)])


@pytest.mark.parametrize("method", ["pi2-cov", "pi2-es-cov"])
def test_adaptive_methods_have_no_schedule(method):
    search = make_policy_search(method, MEAN0, SIGMA0)
    results = REWARDS if method in PER_STEP_METHODS else RETURNS
    for _ in range(4):
        assert search.sigma == 1.0
        search.tell(SAMPLES, results)


def generalised_eigenvalues(covariances, reference):
    """Eigenvalues of L^-1 S L^-T with reference = L L^T, per basis."""
    out = []
    for s, r in zip(covariances, reference):
        lower = np.linalg.cholesky(r)
        inv = np.linalg.inv(lower)
        out.append(np.linalg.eigvalsh(inv @ s @ inv.T))
    return np.array(out)


def test_floor_of_a_rank_one_update_by_hand():
    # One rollout: Sigma = u u^T, rank one; the floor lifts the null
    # direction so that Sigma >= f Sigma0:
    # Sigma' = u u^T + f (Sigma0 - u u^T / (u^T Sigma0^-1 u)).
    sigma0 = np.array([[[4.0, 0.0], [0.0, 1.0]]])
    mean0 = np.zeros((1, 2))
    u = np.array([0.6, 0.8])
    f = 0.05
    search = make_policy_search("pi2-es-cov", mean0, sigma0, floor_fraction=f)
    search.tell(u[None, None, :], [1.0])
    norm = u @ np.linalg.inv(sigma0[0]) @ u
    expected = np.outer(u, u) + f * (sigma0[0] - np.outer(u, u) / norm)
    np.testing.assert_allclose(search.covariances[0], expected, rtol=1e-10)
    np.testing.assert_allclose(
        generalised_eigenvalues(search.covariances, sigma0)[0], [f, norm],
        rtol=1e-10)


def test_absolute_floor():
    search = make_policy_search("pi2-es-cov", MEAN0, SIGMA0,
                                floor_fraction=0.0, min_eigenvalue=0.3)
    search.tell(SAMPLES[:1], [1.0])  # rank one per basis
    values = np.linalg.eigvalsh(search.covariances)
    assert values.min() == pytest.approx(0.3)


def test_pi2_es_cov_covariance_shrinks_above_the_floor():
    floor = 1e-2
    mean, covariances = initial_distribution()
    search = make_policy_search("pi2-es-cov", mean, covariances,
                                floor_fraction=floor, seed=0)
    traces = [np.trace(covariances, axis1=1, axis2=2).sum()]
    hit_floor = False
    for _ in range(15):
        samples = search.ask(6)
        # Larger returns: Eq. 5.1 then puts most weight on one rollout.
        search.tell(samples, 10 * task_results("pi2-es-cov", samples))
        values = generalised_eigenvalues(search.covariances, covariances)
        assert values.min() >= floor * (1 - 1e-9)
        hit_floor |= bool(np.isclose(values.min(), floor, rtol=1e-6))
        traces.append(np.trace(search.covariances, axis1=1, axis2=2).sum())
    assert hit_floor
    assert traces[-1] < 0.2 * traces[0]
    assert task_cost(search.mean[None])[0] < 0.5 * task_cost(mean[None])[0]


# ---------------------------------------------------------------------------
# State save / restore
# ---------------------------------------------------------------------------


def continue_run(search, method, n_episodes, n_rollouts):
    trace = []
    for _ in range(n_episodes):
        samples = search.ask(n_rollouts)
        search.tell(samples, task_results(method, samples))
        trace.append((samples, search.mean, search.covariances, search.sigma,
                      search.episode))
    return trace


@pytest.mark.parametrize("method", METHODS)
def test_state_restores_exactly(method, tmp_path):
    n_rollouts = 1 if method == "power" else 4
    mean, covariances = initial_distribution()
    search = make_policy_search(method, mean, covariances, n_episodes=6,
                                seed=11)
    continue_run(search, method, 2, n_rollouts)
    state = search.state_dict()
    for key, value in state.items():
        assert isinstance(value, (np.ndarray, int, float, str)), key
        if isinstance(value, np.ndarray):
            assert value.dtype != object, key
    path = tmp_path / "search.npz"
    search.save(path)
    reference = continue_run(search, method, 2, n_rollouts)

    from_file = load_policy_search(path)
    from_dict = policy_search_from_state(state)
    fresh = make_policy_search(method, np.ones_like(mean), 2 * covariances,
                               n_episodes=3, seed=99)
    fresh.load_state_dict(state)
    for restored in (from_file, from_dict, fresh):
        assert restored.episode == 2
        trace = continue_run(restored, method, 2, n_rollouts)
        for got, want in zip(trace, reference):
            for a, b in zip(got, want):
                np.testing.assert_array_equal(a, b)


def test_state_of_power_keeps_its_memory():
    search = make_policy_search("power", MEAN0, SIGMA0, n_best=2)
    search.tell(SAMPLES, RETURNS)
    restored = policy_search_from_state(search.state_dict())
    for a, b in zip(restored.memory, search.memory):
        np.testing.assert_array_equal(a, b)


def test_cma_es_state_with_a_pending_ask():
    mean, covariances = initial_distribution()
    search = make_policy_search("cma-es", mean, covariances, seed=5)
    continue_run(search, "cma-es", 1, 6)
    pending = search.ask(6)
    restored = policy_search_from_state(search.state_dict())
    restored.tell(pending, task_results("cma-es", pending))
    search.tell(pending, task_results("cma-es", pending))
    np.testing.assert_array_equal(restored.ask(6), search.ask(6))


def test_same_seed_same_samples():
    for method in METHODS:
        a = make_policy_search(method, MEAN0, SIGMA0, seed=4)
        b = make_policy_search(method, MEAN0, SIGMA0, seed=4)
        np.testing.assert_array_equal(a.ask(3), b.ask(3))


# ---------------------------------------------------------------------------
# Bad input
# ---------------------------------------------------------------------------


def test_unknown_method():
    with pytest.raises(ValueError, match="unknown policy-search method 'pi3'"):
        make_policy_search("pi3", MEAN0, SIGMA0)


def test_unknown_option():
    with pytest.raises(TypeError, match="n_best"):
        make_policy_search("pi2-es", MEAN0, SIGMA0, n_best=3)


def test_wrong_return_shape():
    search = make_policy_search("pi2-es", MEAN0, SIGMA0)
    with pytest.raises(ValueError, match=r"shape \(3,\).*sum per-step"):
        search.tell(SAMPLES, REWARDS)
    with pytest.raises(ValueError, match=r"shape \(3,\)"):
        search.tell(SAMPLES, RETURNS[:2])
    per_step = make_policy_search("pi2", MEAN0, SIGMA0)
    with pytest.raises(ValueError, match=r"per-step rewards of shape \(C, T\)"):
        per_step.tell(SAMPLES, RETURNS)


@pytest.mark.parametrize("method", ["pi2-es", "pi2", "power", "cma-es"])
def test_nan_results(method):
    options = {"popsize": 3} if method == "cma-es" else {}
    search = make_policy_search(method, MEAN0, SIGMA0, **options)
    samples = search.ask(3)
    results = (REWARDS if method in PER_STEP_METHODS else RETURNS).copy()
    results[1] = np.nan
    with pytest.raises(ValueError, match=r"NaN or inf \(rollouts \[1\]\)"):
        search.tell(samples, results)
    assert search.episode == 0


def test_negative_power_returns():
    search = make_policy_search("power", MEAN0, SIGMA0)
    with pytest.raises(ValueError, match="non-negative returns.*rollout 1"):
        search.tell(SAMPLES, [1.0, -0.5, 2.0])


def test_bad_samples():
    search = make_policy_search("pi2-es", MEAN0, SIGMA0)
    with pytest.raises(ValueError, match=r"samples must have shape \(C, B, D\)"):
        search.tell(SAMPLES.reshape(3, 4), RETURNS)
    bad = SAMPLES.copy()
    bad[2, 0, 1] = np.inf
    with pytest.raises(ValueError,
                       match=r"samples contain NaN or inf \(rollouts \[2\]\)"):
        search.tell(bad, RETURNS)


def test_bad_covariances():
    with pytest.raises(ValueError,
                       match=r"covariances must have shape \(B, D, D\) = \(2, 2, 2\)"):
        make_policy_search("pi2-es", MEAN0, SIGMA0[0])
    asymmetric = SIGMA0.copy()
    asymmetric[1, 0, 1] = 0.3
    with pytest.raises(ValueError, match=r"covariances\[1\] is not symmetric"):
        make_policy_search("pi2-es-cov", MEAN0, asymmetric)
    singular = SIGMA0.copy()
    singular[0] = [[1.0, 1.0], [1.0, 1.0]]
    with pytest.raises(ValueError, match=r"covariances\[0\] is not positive definite"):
        make_policy_search("power", MEAN0, singular)
    with pytest.raises(ValueError, match="mean must be the DMP weights"):
        make_policy_search("pi2", MEAN0[0], SIGMA0)


def test_bad_counts_and_options():
    search = make_policy_search("pi2-es", MEAN0, SIGMA0)
    with pytest.raises(ValueError, match="n must be an integer >= 1"):
        search.ask(0)
    with pytest.raises(TypeError, match="n must be an integer"):
        search.ask(2.5)
    with pytest.raises(ValueError, match="weighting must be one of"):
        make_policy_search("pi2-es", MEAN0, SIGMA0, weighting="softmax")
    with pytest.raises(ValueError, match="floor_fraction and min_eigenvalue"):
        make_policy_search("pi2-es-cov", MEAN0, SIGMA0, floor_fraction=0.0)
    with pytest.raises(ValueError, match="n_episodes must be an integer >= 1"):
        make_policy_search("pi2", MEAN0, SIGMA0, n_episodes=0)


def test_cma_es_needs_its_own_samples():
    search = make_policy_search("cma-es", MEAN0, SIGMA0, seed=0)
    samples = search.ask(4)
    with pytest.raises(ValueError, match=r"shape \(4,\)"):
        search.tell(samples, RETURNS)  # 3 returns for 4 samples
    with pytest.raises(RuntimeError, match="before asking again"):
        search.ask(4)
    with pytest.raises(ValueError, match="exactly those of the last ask"):
        search.tell(samples + 1.0, np.ones(4))
    search.tell(samples, np.ones(4))
    with pytest.raises(ValueError, match="popsize = 4"):
        search.ask(3)


# ---------------------------------------------------------------------------
# What the mutation audit of policy_search.py found untested (issue 33,
# docs/mutation.md): defaults, boundaries, named errors, state round trips
# ---------------------------------------------------------------------------

def _options(search):
    state = search.state_dict()
    return {k[len("option_"):]: v for k, v in state.items() if k.startswith("option_")}


def test_default_options_are_the_documented_ones():
    expected = {
        "power": {"n_episodes": 30, "n_best": 6, "sigma0": 1.0, "decay_start": 7.5},
        "pi2": {"n_episodes": 5, "sigma0": 1.0, "decay_start": 1.25, "weighting": "range", "h": 10.0},
        "pi2-es": {"n_episodes": 5, "sigma0": 1.0, "decay_start": 1.25, "weighting": "thesis", "h": 10.0},
        "pi2-cov": {"n_episodes": 5, "weighting": "range", "h": 10.0, "floor_fraction": 1e-2,
                    "min_eigenvalue": 0.0},
        "pi2-es-cov": {"n_episodes": 5, "weighting": "thesis", "h": 10.0, "floor_fraction": 1e-2,
                       "min_eigenvalue": 0.0},
        "cma-es": {"n_episodes": 5, "sigma0": 1.0, "popsize": 0},
    }
    for method in METHODS:
        search = make_policy_search(method, MEAN0, SIGMA0)
        assert _options(search) == expected[method], method
        assert search.sigma == 1.0, method


def test_options_reach_the_search():
    given = {
        "power": {"n_episodes": 7, "n_best": 1, "sigma0": 0.5, "decay_start": 0.0},
        "pi2-es": {"n_episodes": 7, "sigma0": 0.5, "decay_start": 0.0, "weighting": "range", "h": 3.0},
        "pi2-es-cov": {"n_episodes": 7, "weighting": "range", "h": 3.0, "floor_fraction": 1.0,
                       "min_eigenvalue": 0.0},
        "cma-es": {"n_episodes": 7, "sigma0": 0.5, "popsize": 2},
    }
    for method, options in given.items():
        search = make_policy_search(method, MEAN0, SIGMA0, **options)
        assert _options(search) == options, method
        assert search.n_episodes == 7
    cma_es = make_policy_search("cma-es", MEAN0, SIGMA0, popsize=4, seed=0)
    assert cma_es.popsize == 4
    with pytest.raises(ValueError, match="popsize = 4; got 3"):
        cma_es.ask(3)
    # Eq. 5.4 with U = 0 given: sigma_1 = 1 - 1 / 5 (U = E / 4 would keep 1).
    search = make_policy_search("pi2-es", MEAN0, SIGMA0, decay_start=0.0, sigma0=0.5)
    search.tell(SAMPLES, RETURNS)
    assert search.sigma == pytest.approx(0.5 * 0.8)
    assert sigma_schedule(1, 5, decay_start=0.0) == pytest.approx(0.8)


def test_pi2_es_range_weighting_uses_its_h():
    search = make_policy_search("pi2-es", MEAN0, SIGMA0, weighting="range", h=3.0)
    search.tell(SAMPLES, RETURNS)
    np.testing.assert_allclose(search.mean, weighted_mean(range_probabilities(RETURNS, h=3.0), SAMPLES),
                               rtol=1e-12)


def test_rollout_probabilities_defaults_and_range_by_hand():
    # Defaults: thesis weighting of returns (Eq. 5.1), h = 10 for "range".
    np.testing.assert_allclose(rollout_probabilities(RETURNS), thesis_probabilities(RETURNS), rtol=1e-12)
    returns = np.array([5.1, 5.3, 5.2])           # span below one, minimum far from zero
    np.testing.assert_allclose(rollout_probabilities(returns, weighting="range"),
                               range_probabilities(returns), rtol=1e-12)
    np.testing.assert_allclose(rollout_probabilities(returns, weighting="range", h=2.0),
                               range_probabilities(returns, h=2.0), rtol=1e-12)


def test_per_step_range_probabilities_by_hand():
    """Eq. 3.27-3.29: range weighting of each step's reward-to-go, averaged with T - t."""
    rewards = np.array([[4.0, 1.0, 0.0], [0.0, 0.5, 3.0], [1.0, 2.0, 1.0]])
    togo = [[sum(row[t:]) for t in range(3)] for row in rewards]
    per_step = [range_probabilities([togo[c][t] for c in range(3)], h=4.0) for t in range(3)]
    expected = sum((3 - t) * per_step[t] for t in range(3)) / 6.0
    np.testing.assert_allclose(rollout_probabilities(rewards, weighting="range", h=4.0, per_step=True),
                               expected, rtol=1e-12)


def test_per_step_methods_take_one_step_rollouts():
    search = make_policy_search("pi2", MEAN0, SIGMA0)
    search.tell(SAMPLES, RETURNS[:, None])        # T = 1 (PI^2's default: the range weighting)
    np.testing.assert_allclose(search.mean, weighted_mean(range_probabilities(RETURNS), SAMPLES),
                               rtol=1e-12)


def test_power_uses_the_six_best_by_default():
    search = make_policy_search("power", MEAN0, SIGMA0)
    samples = np.stack([np.full((2, 2), float(k)) for k in range(7)])
    returns = np.array([0.01, 0.02, 0.03, 0.04, 0.05, 0.06, 0.005])   # the best six sum below one
    search.tell(samples, returns)
    best = returns[:6]
    np.testing.assert_allclose(search.mean, MEAN0 + np.einsum("k,kbd->bd", best, samples[:6] - MEAN0)
                               / best.sum(), rtol=1e-12)


def test_power_ties_go_to_the_earlier_rollout():
    search = make_policy_search("power", MEAN0, SIGMA0, n_best=6)
    returns = np.array([1.0, 2, 1, 1, 2, 1, 1, 1, 2, 1, 1, 2, 1, 1, 1, 1, 2, 2, 1, 1, 1, 2])
    samples = np.stack([np.full((2, 2), float(k)) for k in range(len(returns))])
    search.tell(samples, returns)
    first_six = np.flatnonzero(returns == 2.0)[:6]               # rollouts 1, 4, 8, 11, 16, 17
    np.testing.assert_allclose(search.mean, MEAN0 + (samples[first_six] - MEAN0).mean(axis=0), rtol=1e-12)


def test_floor_with_a_correlated_initial_covariance_by_hand():
    """Sigma_b >= f Sigma_b^0: the floor is applied to L^-1 S L^-T and mapped back with L . L^T."""
    f = 0.3
    search = make_policy_search("pi2-es-cov", MEAN0, SIGMA0, floor_fraction=f)
    search.tell(SAMPLES, np.array([0.0, 300.0, 0.0]))   # all weight on rollout 1: rank one
    deviation = SAMPLES[1] - MEAN0
    for b in range(2):
        lower = np.linalg.cholesky(SIGMA0[b])
        inv = np.linalg.inv(lower)
        white = inv @ np.outer(deviation[b], deviation[b]) @ inv.T
        values, vectors = np.linalg.eigh(white)
        expected = lower @ (vectors @ np.diag(np.maximum(values, f)) @ vectors.T) @ lower.T
        np.testing.assert_allclose(search.covariances[b], expected, rtol=1e-9, atol=1e-12)
        assert np.linalg.eigvalsh(search.covariances[b] - f * SIGMA0[b]).min() > -1e-12


def test_generator_seed_state_round_trips_through_json():
    """A generator with array state (MT19937) continues bit for bit after a state round trip."""
    for method in ("pi2-es", "cma-es"):
        search = make_policy_search(method, MEAN0, SIGMA0,
                                    seed=np.random.Generator(np.random.MT19937(3)))
        restored = policy_search_from_state(search.state_dict())
        np.testing.assert_array_equal(restored.ask(3), search.ask(3))


def test_state_round_trips_before_the_first_tell():
    for method in METHODS:
        for options in ({}, {"popsize": 3}) if method == "cma-es" else ({},):
            search = make_policy_search(method, MEAN0, SIGMA0, seed=5, **options)
            restored = policy_search_from_state(search.state_dict())
            assert restored.episode == 0 and _options(restored) == _options(search)
            np.testing.assert_array_equal(restored.ask(3), search.ask(3))


def test_state_of_numpy_scalars_restores():
    search = make_policy_search("pi2-es", MEAN0, SIGMA0, seed=2)
    search.tell(search.ask(3), RETURNS)
    state = {k: (np.int64(v) if isinstance(v, int) else v) for k, v in search.state_dict().items()}
    restored = policy_search_from_state(state)
    assert restored.episode == 1
    np.testing.assert_array_equal(restored.ask(3), search.ask(3))


def test_cma_es_restored_twice_continues_the_run():
    search = make_policy_search("cma-es", MEAN0, SIGMA0, seed=1)
    search.tell(search.ask(4), np.arange(4.0))
    twice = policy_search_from_state(policy_search_from_state(search.state_dict()).state_dict())
    np.testing.assert_array_equal(twice.ask(4), search.ask(4))


@pytest.mark.parametrize("key", ["episode", "mean", "rng_state"])
def test_cma_es_refuses_a_state_its_history_does_not_reproduce(key):
    search = make_policy_search("cma-es", MEAN0, SIGMA0, seed=1)
    search.tell(search.ask(4), np.arange(4.0))
    state = search.state_dict()
    state[key] = {"episode": 2, "mean": state["mean"] + 1e-3,
                  "rng_state": make_policy_search("cma-es", MEAN0, SIGMA0, seed=2).state_dict()["rng_state"]}[key]
    import cma
    with pytest.raises(RuntimeError, match=rf"did not reproduce the saved state \(saved with cma "
                                           rf"{cma.__version__}, running cma {cma.__version__}\)"):
        policy_search_from_state(state)


def test_cma_es_prints_and_writes_nothing(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    search = make_policy_search("cma-es", MEAN0, SIGMA0, seed=0)
    for _ in range(3):
        search.tell(search.ask(4), np.arange(4.0))
    assert capsys.readouterr() == ("", "")
    assert list(tmp_path.iterdir()) == []


def test_loading_refuses_pickled_arrays(tmp_path):
    search = make_policy_search("pi2-es", MEAN0, SIGMA0)
    state = search.state_dict()
    state["evil"] = np.array([{"a": 1}], dtype=object)
    path = tmp_path / "pickled.npz"
    np.savez(path, **state)
    with pytest.raises(ValueError, match="allow_pickle=False"):
        load_policy_search(path)


def test_samples_of_the_wrong_shape_or_none():
    search = make_policy_search("pi2-es", MEAN0, SIGMA0)
    for bad in (np.zeros((3, 3, 2)), np.zeros((0, 2, 2))):
        with pytest.raises(ValueError, match=r"samples must have shape \(C, B, D\) = \(C, 2, 2\) with C >= 1"):
            search.tell(bad, RETURNS[:len(bad)])


def test_result_shape_errors_name_the_expected_shape():
    search = make_policy_search("pi2-es", MEAN0, SIGMA0)
    with pytest.raises(ValueError, match=r"shape \(3,\), for 'pi2-es'; got \(2, 3\)$"):
        search.tell(SAMPLES, np.zeros((2, 3)))              # no per-step hint: not (C, T)
    with pytest.raises(ValueError, match=r"shape \(3,\), for 'pi2-es'; got \(2,\)$"):
        search.tell(SAMPLES, np.zeros(2))
    per_step = make_policy_search("pi2", MEAN0, SIGMA0)
    with pytest.raises(ValueError, match=r"per-step rewards of shape \(C, T\) = \(3, T\) with T >= 1"):
        per_step.tell(SAMPLES, np.zeros((2, 3)))
    nan = RETURNS.copy()
    nan[0] = np.nan
    with pytest.raises(ValueError, match=r"count a failed rollout with return 0 \(docs/method.md section 5\)"):
        search.tell(SAMPLES, nan)


def test_covariance_checks_are_relative_to_each_block():
    big = SIGMA0.copy()
    big[0] *= 1e6
    big[0, 0, 1] += 1e-5                               # 1e-11 of the block: rounding
    make_policy_search("pi2-es", MEAN0, big)
    big[1, 0, 1] += 1e-3                               # 1e-3 of its own block, 1e-9 of the largest
    with pytest.raises(ValueError) as info:
        make_policy_search("pi2-es", MEAN0, big)
    assert str(info.value) == "covariances[1] is not symmetric (max |S - S^T| = 0.001); pass 0.5 * (S + S^T)"
    zero = SIGMA0.copy()
    zero[1] = 0.0
    with pytest.raises(ValueError, match=r"covariances\[1\] is not positive definite"):
        make_policy_search("pi2-es", MEAN0, zero)


@pytest.mark.parametrize("build, error, message", [
    (lambda: sigma_schedule(-1, 5), ValueError, "episode must be an integer >= 0; got -1"),
    (lambda: sigma_schedule(0, 0), ValueError, "n_episodes must be an integer >= 1; got 0"),
    (lambda: sigma_schedule(0, 5, sigma0=0.0), ValueError, "sigma0 must be > 0; got 0.0"),
    (lambda: sigma_schedule(0, 5, decay_start=-1.0), ValueError, "decay_start must be >= 0; got -1.0"),
    (lambda: rollout_probabilities(RETURNS, h=0.0), ValueError, "h must be > 0; got 0.0"),
    (lambda: rollout_probabilities(RETURNS, weighting="soft"), ValueError,
     "weighting must be one of ('thesis', 'range'); got 'soft'"),
    (lambda: rollout_probabilities(REWARDS), ValueError, "returns must have shape (C,); got (3, 3)"),
    (lambda: rollout_probabilities(RETURNS, per_step=True), ValueError,
     "per-step results must have shape (C, T); got (3,)"),
    (lambda: PI2ES(MEAN0, SIGMA0, sigma0=-1.0), ValueError, "sigma0 must be > 0; got -1.0"),
    (lambda: PI2ES(MEAN0, SIGMA0, decay_start=-0.5), ValueError, "decay_start must be >= 0; got -0.5"),
    (lambda: PI2ES(MEAN0, SIGMA0, h=0.0), ValueError, "h must be > 0; got 0.0"),
    (lambda: PI2ES(MEAN0, SIGMA0, h=True), TypeError, "h must be a real number; got True"),
    (lambda: PI2ESCov(MEAN0, SIGMA0, floor_fraction=-0.1), ValueError, "floor_fraction must be >= 0; got -0.1"),
    (lambda: PI2ESCov(MEAN0, SIGMA0, floor_fraction=1.5), ValueError, "floor_fraction must be in [0, 1]; got 1.5"),
    (lambda: PI2ESCov(MEAN0, SIGMA0, min_eigenvalue=-1.0), ValueError, "min_eigenvalue must be >= 0; got -1.0"),
    (lambda: PI2ESCov(MEAN0, SIGMA0, floor_fraction=0.0), ValueError,
     "floor_fraction and min_eigenvalue are both 0: the covariance update can collapse to a singular "
     "matrix; set floor_fraction > 0 (default 1e-2) or min_eigenvalue > 0"),
    (lambda: PoWER(MEAN0, SIGMA0, n_best=0), ValueError, "n_best must be an integer >= 1; got 0"),
    (lambda: CMAES(MEAN0, SIGMA0, sigma0=0.0), ValueError, "sigma0 must be > 0; got 0.0"),
    (lambda: CMAES(MEAN0, SIGMA0, popsize=1), ValueError, "popsize must be an integer >= 2; got 1"),
    (lambda: CMAES(MEAN0, SIGMA0).tell(SAMPLES, RETURNS), RuntimeError, "cma-es: tell() needs the samples of an ask()"),
    (lambda: PI2ES(MEAN0, SIGMA0, seed=True), TypeError,
     "seed must be an int, None or a numpy.random.Generator; got True"),
    (lambda: PI2ES(MEAN0, SIGMA0, seed=1.5), TypeError,
     "seed must be an int, None or a numpy.random.Generator; got 1.5"),
    (lambda: PI2ES(MEAN0, SIGMA0, h=np.inf), ValueError, "h must be finite; got inf"),
    (lambda: PI2ES(MEAN0, SIGMA0).tell(SAMPLES, REWARDS), ValueError,
     "results must be one return per rollout, shape (3,), for 'pi2-es'; got (3, 3) (sum per-step rewards "
     "over time for a black-box method)"),
    (lambda: PoWER(MEAN0, SIGMA0).tell(SAMPLES, [1.0, -0.5, 2.0]), ValueError,
     "PoWER needs non-negative returns; got -0.5 at rollout 1. Map returns to >= 0 with a transform fixed "
     "for the whole run (e.g. exp(-cost)), not a per-episode shift"),
    (lambda: PI2ES(np.zeros((3, 2)), np.tile(np.eye(2), (3, 1, 1))).tell(np.zeros((1, 2, 3)), [0.0]), ValueError,
     "samples must have shape (C, B, D) = (C, 3, 2) with C >= 1, as returned by ask(); got (1, 2, 3)"),
    (lambda: make_policy_search("pi3", MEAN0, SIGMA0), ValueError,
     "unknown policy-search method 'pi3'; choose one of power, pi2, pi2-cov, pi2-es, pi2-es-cov, cma-es"),
    (lambda: make_policy_search("pi2-es", MEAN0, SIGMA0, n_best=3, foo=1), TypeError,
     "'pi2-es' does not take option(s) foo, n_best; its options are n_episodes, weighting, h, sigma0, "
     "decay_start, seed"),
    (lambda: policy_search_from_state({"method": "pi3"}), ValueError,
     "state names unknown method 'pi3'; expected one of power, pi2, pi2-cov, pi2-es, pi2-es-cov, cma-es"),
    (lambda: policy_search_from_state({**PI2ES(MEAN0, SIGMA0).state_dict(), "format": 2}), ValueError,
     "state format 2 is not supported (expected 1)"),
    (lambda: policy_search_from_state({**PoWER(MEAN0, SIGMA0).state_dict(), "memory_samples": SAMPLES[:2],
                                       "memory_returns": RETURNS[:1]}), ValueError,
     "memory_samples (2, 2, 2) and memory_returns (1,) disagree on the number of rollouts"),
    (lambda: policy_search_from_state({**PI2ES(MEAN0, SIGMA0).state_dict(),
                                       "rng_state": '{"bit_generator": "NoSuchGenerator", "state": {}}'}),
     ValueError, "rng_state names unknown bit generator 'NoSuchGenerator'"),
    (lambda: PI2ES([[0.0, np.nan]], SIGMA0[:1]), ValueError, "mean contains NaN or inf"),
    (lambda: PI2ES(MEAN0, np.full_like(SIGMA0, np.inf)), ValueError, "covariances contains NaN or inf"),
    (lambda: make_policy_search("pi2-es", MEAN0, SIGMA0, n_best=3), TypeError,
     "'pi2-es' does not take option(s) n_best; its options are n_episodes, weighting, h, sigma0, "
     "decay_start, seed"),
    (lambda: policy_search_from_state([("method", "pi2")]), TypeError, "state must be a mapping; got list"),
    (lambda: PI2ES.from_state_dict(PI2ESCov(MEAN0, SIGMA0).state_dict()), ValueError,
     "state is for method 'pi2-es-cov', not 'pi2-es'; use policy_search_from_state() to dispatch on the method"),
    (lambda: policy_search_from_state({**PI2ES(MEAN0, SIGMA0).state_dict(),
                                       "rng_state": '{"bit_generator": "default_rng", "state": {}}'}),
     ValueError, "rng_state names unknown bit generator 'default_rng'"),
    (lambda: policy_search_from_state({**CMAES(MEAN0, SIGMA0).state_dict(), "history_returns": np.zeros(3)}),
     ValueError, "cma-es: history_returns must be (episodes, popsize); got shape (3,)"),
])
def test_bad_arguments_are_named(build, error, message):
    with pytest.raises(error) as info:
        build()
    assert str(info.value) == message


def test_boundary_values_are_accepted():
    PoWER(MEAN0, SIGMA0, n_best=1)
    CMAES(MEAN0, SIGMA0, popsize=2)
    PI2ESCov(MEAN0, SIGMA0, floor_fraction=1.0)
    PI2ESCov(MEAN0, SIGMA0, floor_fraction=0.0, min_eigenvalue=1e-6)
    assert sigma_schedule(0, 5, decay_start=0.0) == 1.0
    assert sigma_schedule(0, 5, sigma0=1e-300) == 1e-300


def test_thesis_weighting_of_large_returns_does_not_overflow():
    """exp(R / C) overflows for returns in the thousands; the weights are formed after a shift."""
    returns = np.array([3000.0, 2997.0, 0.0])
    exponents = returns / 3 - 1000.0
    expected = np.exp(exponents) / np.exp(exponents).sum()
    np.testing.assert_allclose(rollout_probabilities(returns), expected, rtol=1e-12)
    # Per step: each step's reward-to-go is shifted by its own maximum.
    rewards = np.array([[3000.0, 1.0, 0.0], [0.0, 2.0, 1.0], [0.0, 0.0, 3.0]])
    togo = reward_to_go(rewards) / 3
    per_step = np.exp(togo - togo.max(axis=0))
    per_step /= per_step.sum(axis=0)
    expected = per_step @ np.array([3.0, 2.0, 1.0]) / 6.0
    np.testing.assert_allclose(rollout_probabilities(rewards, per_step=True), expected, rtol=1e-12)


def test_cma_es_refuses_samples_not_its_own_in_words():
    search = make_policy_search("cma-es", MEAN0, SIGMA0, seed=0)
    samples = search.ask(3)
    with pytest.raises(ValueError) as info:
        search.tell(samples[::-1], RETURNS)
    assert str(info.value) == "cma-es: samples must be exactly those of the last ask(), in the same order"
