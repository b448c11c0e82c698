"""MRP state values: Monte Carlo (thesis Eqs. 4.1-4.3) against dynamic programming."""

import warnings

import numpy as np
import pytest
from pydrake.common.yaml import yaml_load_typed

from drake_skill.reward.mrp import (
    MrpConfig,
    discounted_returns,
    exact_values,
    expected_visit_times,
    monte_carlo_values,
    sample_state_sequences,
    state_marginals,
)

# A 4-state left-to-right chain with a leak back from state 2, like a fitted goal model.
PI = np.array([0.9, 0.1, 0.0, 0.0])
P = np.array([
    [0.85, 0.15, 0.00, 0.00],
    [0.00, 0.80, 0.20, 0.00],
    [0.00, 0.05, 0.80, 0.15],
    [0.00, 0.00, 0.00, 1.00],
])
TERMINAL = [3]
L = 50


def test_returns_follow_eq_4_1():
    r = np.array([0.0, 1.0, 0.0, 1.0])
    # G_4 = 1, G_3 = 0.9, G_2 = 1 + 0.81, G_1 = 0.9 * 1.81
    np.testing.assert_allclose(discounted_returns(r, 0.9), [1.629, 1.81, 0.9, 1.0])


def test_monte_carlo_converges_to_dynamic_programming():
    exact = exact_values(PI, P, TERMINAL, L, gamma=0.9, terminal_scale=2.0)
    mc = monte_carlo_values(PI, P, TERMINAL, L, n_sequences=300_000, gamma=0.9, terminal_scale=2.0,
                            random_state=1)
    np.testing.assert_allclose(mc, exact, atol=0.02)
    # The thesis' n = 100 is already close but visibly noisier.
    mc100 = monte_carlo_values(PI, P, TERMINAL, L, random_state=1)
    assert 0.02 < np.abs(mc100 - exact).max() < 0.5


def test_values_rise_toward_the_terminal_state():
    for v in (exact_values(PI, P, TERMINAL, L), monte_carlo_values(PI, P, TERMINAL, L, random_state=0)):
        assert np.all(np.diff(v) > 0), v


def test_absorbing_terminal_state_closed_form():
    # One absorbing terminal state: u_t = (1 - g^(L-t+1)) / (1 - g); v = mean over t, times c.
    g, n = 0.9, 20
    u = (1 - g ** np.arange(n, 0, -1)) / (1 - g)
    expected = 3.0 * u.mean()
    assert np.isclose(exact_values([1.0], [[1.0]], [0], n, gamma=g, terminal_scale=3.0)[0], expected)
    mc = monte_carlo_values([1.0], [[1.0]], [0], n, n_sequences=3, gamma=g, terminal_scale=3.0)
    assert np.isclose(mc[0], expected)


def test_terminal_scale_and_unvisited_states():
    P5 = np.eye(5)
    P5[:4] = np.hstack([P, np.zeros((4, 1))])  # state 4 is unreachable
    pi5 = np.r_[PI, 0.0]
    v1 = exact_values(pi5, P5, TERMINAL, L, terminal_scale=1.0)
    v2 = exact_values(pi5, P5, TERMINAL, L, terminal_scale=2.0)
    assert np.isclose(v2[3], 2 * v1[3]) and np.allclose(v2[:3], v1[:3])
    assert v2[4] == 0.0
    mc = monte_carlo_values(pi5, P5, TERMINAL, L, random_state=0)
    assert mc[4] == 0.0 and np.isnan(expected_visit_times(pi5, P5, L)[4])


def test_sampling_is_seeded_and_follows_the_chain():
    a = sample_state_sequences(PI, P, 2000, L, random_state=3)
    b = sample_state_sequences(PI, P, 2000, L, random_state=3)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, sample_state_sequences(PI, P, 2000, L, random_state=4))
    # Empirical marginals match pi P^t; forbidden moves never happen.
    emp = np.stack([np.bincount(a[:, t], minlength=4) / 2000 for t in range(L)])
    np.testing.assert_allclose(emp, state_marginals(PI, P, L), atol=0.04)
    moves = set(zip(a[:, :-1].ravel(), a[:, 1:].ravel()))
    assert all(P[i, j] > 0 for i, j in moves)
    np.testing.assert_array_equal(monte_carlo_values(PI, P, TERMINAL, L, random_state=5),
                                  monte_carlo_values(PI, P, TERMINAL, L, random_state=5))


def test_config_loads_from_yaml():
    cfg = yaml_load_typed(schema=MrpConfig, data="n_sequences: 500\nterminal_scale: 3.0\n")
    assert (cfg.n_sequences, cfg.gamma, cfg.terminal_scale, cfg.length) == (500, 0.9, 3.0, 0)


def test_bad_input_is_a_clear_error():
    with pytest.raises(ValueError, match=r"transmat: expected shape \(4, 4\)"):
        exact_values(PI, P[:3], TERMINAL, L)
    with pytest.raises(ValueError, match="transmat: expected non-negative rows summing to 1"):
        exact_values(PI, P * 0.5, TERMINAL, L)
    with pytest.raises(ValueError, match="startprob: expected a probability vector"):
        monte_carlo_values([0.5, 0.6, 0, 0], P, TERMINAL, L)
    with pytest.raises(ValueError, match=r"terminal_states: .* in \[0, 4\), got \[4\]"):
        monte_carlo_values(PI, P, [4], L)
    with pytest.raises(ValueError, match="length: expected a sequence length >= 1, got 0"):
        exact_values(PI, P, TERMINAL, 0)
    with pytest.raises(ValueError, match="gamma"):
        exact_values(PI, P, TERMINAL, L, gamma=1.5)
    # a (1, 4) row of start probabilities would pass the transmat shape check
    with pytest.raises(ValueError, match=r"startprob: expected shape \(k,\), got \(1, 4\)"):
        exact_values(PI[None], P, TERMINAL, L)
    with pytest.raises(ValueError, match=r"startprob: expected shape \(k,\), got \(0,\)"):
        exact_values([], P, TERMINAL, L)


def test_short_chain_values_and_visit_times_by_hand():
    """A 3-step chain worked by hand; every reachable state has total visit mass <= 1
    (0.75 and 0.5), state 3 is never reached (value 0, visit time NaN).

    p_t: (1, 0, 0, 0), (.5, .5, 0, 0), (.25, .25, .5, 0); u_2 = r, u_1 = (0, .9, 1.9, .),
    u_0 = (.405, 1.71, 2.71, .); v = sum_t p_t u_t / sum_t p_t, then v(T) *= 2.
    """
    pi = np.array([1.0, 0.0, 0.0, 0.0])
    P = np.array([[0.5, 0.5, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]])
    v = exact_values(pi, P, [2], 3, gamma=0.9, terminal_scale=2.0)
    np.testing.assert_allclose(v, [0.405 / 1.75, 0.45 / 0.75, 2.0, 0.0], rtol=1e-12)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the unreachable state is not a 0/0 RuntimeWarning
        times = expected_visit_times(pi, P, 3)
    np.testing.assert_allclose(times[:3], [1.0 / 1.75, 1.0 / 0.75, 2.0], rtol=1e-12)
    assert np.isnan(times[3])


def test_sequence_counts_are_checked():
    S = sample_state_sequences(PI, P, 1, 5, random_state=0)
    assert S.shape == (1, 5)
    S = sample_state_sequences(PI, P, 3, 1, random_state=0)  # one frame: the start states only
    assert S.shape == (3, 1) and set(S[:, 0]) <= {0, 1}
    for n, L in ((0, 5), (5, 0)):
        with pytest.raises(ValueError, match=r"n_sequences, length"):
            sample_state_sequences(PI, P, n, L, random_state=0)


def test_returns_of_integer_rewards_are_not_truncated():
    G = discounted_returns(np.array([[0, 0, 1], [1, 0, 0]]), 0.9)
    np.testing.assert_allclose(G, [[0.81, 0.9, 1.0], [1.0, 0.0, 0.0]], rtol=1e-12)


def test_terminal_states_forms():
    """One index, a list, a float array of indices: the same set T; several states; negatives refused."""
    v = exact_values(PI, P, [3], L)
    for form in (3, np.array([3.0])):
        np.testing.assert_array_equal(exact_values(PI, P, form, L), v)
    both = exact_values(PI, P, [2, 3], L, terminal_scale=2.0)
    assert both[2] > v[2] and both[3] == v[3]  # state 2 is now rewarded (and scaled) too
    with pytest.raises(ValueError, match=r"terminal_states: .* got \[-1\]"):
        exact_values(PI, P, [-1], L)


def test_parameter_bounds_are_inclusive():
    """length 1, gamma 0 and gamma 1 are valid; terminal_scale 0 is not."""
    np.testing.assert_allclose(exact_values(PI, P, [1], 1), [0.0, 2.0, 0.0, 0.0])  # one frame: v = c r
    np.testing.assert_allclose(exact_values(PI, P, [3], L, gamma=0.0), [0.0, 0.0, 0.0, 2.0])
    assert exact_values(PI, P, [3], L, gamma=1.0)[0] > exact_values(PI, P, [3], L, gamma=0.9)[0]
    with pytest.raises(ValueError, match=r"terminal_scale: expected c > 0 .* got 0"):
        exact_values(PI, P, [3], L, terminal_scale=0)


def test_monte_carlo_values_by_hand():
    """Eqs. 4.1-4.3 written as loops over the sampled sequences: per state, the mean return of its
    visits, 0 for a state never visited, the terminal states' values times c."""
    pi5 = np.r_[PI, 0.0]
    P5 = np.zeros((5, 5))
    P5[:4, :4], P5[4, 4] = P, 1.0                                 # state 4 is never reached
    S = sample_state_sequences(pi5, P5, 7, 12, 3)
    gamma, scale = 0.8, 1.5
    sums, counts = np.zeros(5), np.zeros(5)
    for seq in S:
        for t, s in enumerate(seq):
            sums[s] += sum(gamma ** (j - t) * (seq[j] in TERMINAL) for j in range(t, len(seq)))
            counts[s] += 1
    expected = np.divide(sums, counts, out=np.zeros(5), where=counts > 0)
    expected[TERMINAL] *= scale
    v = monte_carlo_values(pi5, P5, TERMINAL, 12, n_sequences=7, gamma=gamma, terminal_scale=scale, random_state=3)
    np.testing.assert_allclose(v, expected, rtol=1e-12)
    assert v[4] == 0.0 and counts[4] == 0
    # The defaults: 100 sequences, gamma 0.9, c = 2, seed 0.
    np.testing.assert_array_equal(monte_carlo_values(PI, P, TERMINAL, L),
                                  monte_carlo_values(PI, P, TERMINAL, L, n_sequences=100, gamma=0.9,
                                                     terminal_scale=2.0, random_state=0))


def test_a_state_visited_once_has_that_visit_s_return():
    """A deterministic chain 0 -> 1 -> 2 (terminal, absorbing) over 5 frames: states 0 and 1 are each
    visited once, so their values are those visits' returns (not the 0 of a never-visited state)."""
    P3 = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    v = monte_carlo_values([1.0, 0.0, 0.0], P3, [2], 5, n_sequences=1, gamma=0.5, terminal_scale=1.0)
    # Returns along [0, 1, 2, 2, 2] with r = [0, 0, 1, 1, 1]: G_3..5 = 1.75, 1.5, 1; G_2 = 0.875; G_1 = 0.4375.
    np.testing.assert_allclose(v, [0.4375, 0.875, (1.75 + 1.5 + 1.0) / 3], rtol=1e-12)
