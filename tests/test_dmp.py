"""Tests of the numpy DMP (drake_skill.action.dmp): fitting, integration, exploration covariance, input checks."""

import json
import math

import numpy as np
import pytest
import scipy.linalg
from scipy.integrate import solve_ivp

from drake_skill.bench.dmp import synthetic_demonstration
from drake_skill.action.dmp import (
    Dmp,
    DmpConfig,
    _discrete_filter,
    basis_centres_widths,
    basis_features,
    exploration_covariance,
    fit_demonstrations,
    fit_dmp,
    fit_weights,
    forcing_amplitude,
    initial_weights,
    integrate,
    phase,
    validate_demonstration,
)
from drake_skill.action.quaternion import quaternion_distance, rotation_angle

Y0 = np.array([0.0, 0.1, 0.2, 1.0, 0.0, 0.0, 0.0])
GOAL = np.array([0.3, -0.1, 0.25, 0.8, 0.6, 0.0, 0.0])


@pytest.fixture(scope="module")
def demo():
    return synthetic_demonstration(duration=5.0, rate_hz=100.0)


def _errors(out, poses):
    rmse = np.sqrt(np.mean(np.sum((out[:, :3] - poses[:, :3]) ** 2, axis=1)))
    return rmse, quaternion_distance(out[:, 3:], poses[:, 3:])


def test_config_loads_from_yaml():
    from pydrake.common.yaml import yaml_load_typed

    cfg = yaml_load_typed(schema=DmpConfig, data="n_basis: 10\nquaternion: ude\nK: 64.0\nD: 16.0\n")
    assert (cfg.n_basis, cfg.quaternion, cfg.K, cfg.D, cfg.width_scale) == (10, "ude", 64.0, 16.0, 1.0)
    assert cfg.weight_dim == 6
    assert math.isclose(phase(1.0, 1.0, DmpConfig().alpha_x), 0.01)


def test_basis_placement():
    c, h = basis_centres_widths(5, math.log(100.0), width_scale=1.0)
    np.testing.assert_allclose(c, np.exp(-math.log(100.0) * np.array([0, 0.25, 0.5, 0.75, 1.0])))
    np.testing.assert_allclose(h[:4], 1.0 / np.diff(c) ** 2)
    assert h[4] == h[3]
    phi = basis_features(np.array([1.0, 0.5, 0.01]), c, h)
    np.testing.assert_allclose(phi.sum(axis=1), [1.0, 0.5, 0.01])  # normalised mixture times x


def test_reproduces_smooth_demonstration(demo):
    times, poses = demo
    cfg = DmpConfig(n_basis=20)
    dmp = fit_dmp(times, poses, cfg)
    assert dmp.weights.shape == (20, 7) and dmp.tau == pytest.approx(5.0)
    out = integrate(dmp, cfg, times)
    rmse, qdist = _errors(out, poses)
    assert rmse < 1e-3  # 0.73 mm measured
    assert qdist.max() < 0.01  # 1.2e-3 measured
    np.testing.assert_allclose(np.linalg.norm(out[:, 3:], axis=1), 1.0, atol=1e-12)
    # ends at the goal
    assert np.linalg.norm(out[-1, :3] - dmp.goal[:3]) < 1e-3
    assert quaternion_distance(out[-1, 3:], dmp.goal[3:]) < 1e-3
    # default grid: 1 ms steps over [0, tau]
    full = integrate(dmp, cfg)
    assert full.shape == (5001, 7)
    np.testing.assert_allclose(full[::10], out, atol=1e-12)


def test_reproduces_demonstration_downsampled_to_10_hz():
    times, poses = synthetic_demonstration(duration=5.0, rate_hz=10.0)
    cfg = DmpConfig(n_basis=20)
    out = integrate(fit_dmp(times, poses, cfg), cfg, times)
    rmse, qdist = _errors(out, poses)
    assert rmse < 1.5e-3 and qdist.max() < 0.01


def test_fewer_bases_reproduce_worse(demo):
    times, poses = demo
    errs = []
    for b in (5, 10, 20):
        cfg = DmpConfig(n_basis=b)
        errs.append(_errors(integrate(fit_dmp(times, poses, cfg), cfg, times), poses)[0])
    assert errs[0] > errs[1] > errs[2]


def test_recovers_weights_of_a_dmp_generated_trajectory():
    rng = np.random.default_rng(0)
    w = rng.normal(0.0, 1.0, (20, 7))
    cfg = DmpConfig(regression="least_squares")
    t = np.arange(3001) * 1e-3
    y = integrate(Dmp(w, Y0, GOAL, 3.0), cfg, t, normalize_quaternion=False)
    w_fit = fit_weights(t, y, cfg, y0=Y0, goal=GOAL)
    assert np.abs(w_fit - w).max() < 0.03  # |w| up to 2.4; residual from numerical derivatives
    # LWR (the thesis' regression) is exact when the weights do not vary over the bases
    w_const = np.tile(rng.normal(0.0, 1.0, 7), (20, 1))
    cfg_lwr = DmpConfig(regression="lwr", width_scale=4.0)
    y = integrate(Dmp(w_const, Y0, GOAL, 3.0), cfg_lwr, t, normalize_quaternion=False)
    w_lwr = fit_weights(t, y, cfg_lwr, y0=Y0, goal=GOAL)
    # (0.011 on the first basis, from the one-sided second derivative at t = 0; 1.4e-4 elsewhere)
    assert np.abs(w_lwr[1:] - w_const[1:]).max() < 1e-3
    assert np.abs(w_lwr - w_const).max() < 0.02


def test_integration_matches_adaptive_ode_solver():
    rng = np.random.default_rng(1)
    cfg = DmpConfig()
    w = rng.normal(0.0, 1.0, (20, 7))
    tau = 2.0
    dmp = Dmp(w, Y0, GOAL, tau)
    c, h = basis_centres_widths(20, cfg.alpha_x, cfg.width_scale)
    a = forcing_amplitude(Y0, GOAL, cfg)

    def rhs(t, s):
        y, z = s[:7], s[7:]
        f = basis_features(phase(np.array([t]), tau, cfg.alpha_x), c, h)[0] @ (w * a)
        return np.concatenate([z / tau, (cfg.K * (GOAL - y) - cfg.D * z + f) / tau])

    t_eval = np.linspace(0.0, 2.5, 26)  # also past tau
    ref = solve_ivp(rhs, (0.0, 2.5), np.concatenate([Y0, np.zeros(7)]), t_eval=t_eval, rtol=1e-11, atol=1e-12).y[:7].T
    out = integrate(dmp, cfg, t_eval, normalize_quaternion=False)
    np.testing.assert_allclose(out, ref, atol=1e-8)
    # off-grid times are interpolated linearly from the 1 ms grid: error <= h^2 max|ydd| / 8 (~2e-6 m here)
    odd = np.array([0.0, 0.0123, 0.5004, 1.7777])
    odd_ref = solve_ivp(rhs, (0.0, 1.7777), np.concatenate([Y0, np.zeros(7)]), t_eval=odd,
                        rtol=1e-11, atol=1e-12).y[:7].T
    np.testing.assert_allclose(integrate(dmp, cfg, odd, normalize_quaternion=False), odd_ref, atol=5e-6)


def test_closed_form_discretisation_matches_expm():
    for k, d, tau, h in [(100.0, 20.0, 5.0, 1e-3), (100.0, 20.0, 0.3, 0.01),
                         (100.0, 5.0, 2.0, 1e-3), (100.0, 40.0, 2.0, 0.1)]:
        m = np.zeros((3, 3))
        m[0, 1], m[1, 0], m[1, 1], m[1, 2] = 1.0, -k / tau**2, -d / tau, 1.0 / tau**2
        e = scipy.linalg.expm(m * h)
        ad, bd = e[:2, :2], e[:2, 2]
        b_ref = [0.0, bd[0], -ad[1, 1] * bd[0] + ad[0, 1] * bd[1]]
        a_ref = [1.0, -np.trace(ad), np.linalg.det(ad)]
        b, a = _discrete_filter(k, d, tau, h)
        np.testing.assert_allclose(b, b_ref, rtol=1e-9)
        np.testing.assert_allclose(a, a_ref, atol=1e-14)


def test_batch_integration_equals_single_calls(demo):
    times, poses = demo
    cfg = DmpConfig()
    dmp = fit_dmp(times, poses, cfg)
    rng = np.random.default_rng(2)
    samples = dmp.weights + rng.normal(0.0, 5.0, (4, 20, 7))
    batch = integrate(dmp, cfg, times, weights=samples)
    assert batch.shape == (4, len(times), 7)
    for s in range(4):
        np.testing.assert_allclose(batch[s], integrate(Dmp(samples[s], dmp.y0, dmp.goal, dmp.tau), cfg, times),
                                   atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(batch[..., 3:], axis=-1), 1.0, atol=1e-12)
    assert not np.allclose(batch[0], batch[1])


def test_degenerate_amplitude_gives_finite_fit():
    # y returns to its start (g - y0 = 0) after a 5 cm excursion
    t = np.linspace(0.0, 2.0, 201)
    s = t / 2.0
    poses = np.zeros((201, 7))
    poses[:, 0] = 0.05 * np.sin(np.pi * s) ** 2
    poses[:, 1] = 0.2 * (10 * s**3 - 15 * s**4 + 6 * s**5)
    poses[:, 3] = 1.0
    for cfg in (DmpConfig(scale_by_amplitude=True), DmpConfig()):
        dmp = fit_dmp(t, poses, cfg)
        assert np.all(np.isfinite(dmp.weights))
        out = integrate(dmp, cfg, t)
        assert np.all(np.isfinite(out))
        assert np.sqrt(np.mean((out[:, 0] - poses[:, 0]) ** 2)) < 1e-3
    # the floor keeps the sign of a tiny amplitude (thesis form); no scaling by default
    a = forcing_amplitude(np.zeros(7), np.array([1e-5, -1e-5, 0.5, 0, 0, 0, 0]), DmpConfig(scale_by_amplitude=True))
    np.testing.assert_allclose(a[:3], [0.01, -0.01, 0.5])
    np.testing.assert_array_equal(forcing_amplitude(np.zeros(7), np.ones(7), DmpConfig()), np.ones(7))


def _lift_and_return():
    """x: 0.3 m minimum jerk; z: a 10 cm lift that returns to its start height (g_z = y0_z)."""
    t = np.linspace(0.0, 4.0, 401)
    s = t / 4.0
    poses = np.zeros((401, 7))
    poses[:, 0] = 0.3 * (10 * s**3 - 15 * s**4 + 6 * s**5)
    poses[:, 2] = 0.2 + 0.10 * np.sin(np.pi * s) ** 2
    poses[:, 3] = 1.0
    return t, poses


@pytest.mark.parametrize("dz", [0.005, -0.005])
def test_start_shift_keeps_the_demonstrated_shape(dz):
    t, poses = _lift_and_return()
    shifted = {}
    for scale in (False, True):
        cfg = DmpConfig(n_basis=20, scale_by_amplitude=scale)
        dmp = fit_dmp(t, poses, cfg)
        y0 = dmp.y0.copy()
        y0[2] += dz
        shifted[scale] = integrate(Dmp(dmp.weights, y0, dmp.goal, dmp.tau), cfg, t)
    # Default (no amplitude scaling): the start shift decays, the path stays
    # within |dz| of the demonstration (measured 5.0 mm max for 5 mm; 1.2 mm
    # of it is the fit itself at dz = 0).
    dev = np.abs(shifted[False][:, :3] - poses[:, :3]).max()
    assert dev < 0.01
    assert shifted[False][:, 2].max() - 0.2 > 0.095
    # Thesis form: a = g - y0 changes sign when the start moves up, so the
    # lift becomes a dip of about the same size (measured -9.9 cm).
    if dz > 0:
        assert shifted[True][:, 2].min() - 0.2 < -0.09
    else:
        assert np.abs(shifted[True][:, :3] - poses[:, :3]).max() < 0.01


def test_bad_dmp_input_names_the_field():
    t, poses = _lift_and_return()
    dmp = fit_dmp(t, poses, DmpConfig(n_basis=20))
    zero = dmp.y0.copy()
    zero[3:] = 0.0
    with pytest.raises(ValueError, match=r"Dmp\.y0: quaternion .* has norm 0"):
        Dmp(dmp.weights, zero, dmp.goal, dmp.tau)
    with pytest.raises(ValueError, match=r"Dmp\.goal: quaternion"):
        Dmp(dmp.weights, dmp.y0, zero, dmp.tau)
    bad = poses.copy()
    bad[5, 3:] = 0.0
    with pytest.raises(ValueError, match=r"poses\[:, 3:7\]: quaternion at index \(5,\) has norm 0"):
        fit_dmp(t, bad, DmpConfig(n_basis=20))
    with pytest.raises(ValueError, match=r"DmpConfig\.n_basis: 20 bases but the demonstration has only 8 samples"):
        fit_dmp(t[:8], poses[:8], DmpConfig(n_basis=20))
    with pytest.raises(ValueError, match=r"Dmp\.tau: 1000000\.0 s is longer than the 3600 s"):
        Dmp(dmp.weights, dmp.y0, dmp.goal, 1e6)
    with pytest.raises(ValueError, match=r"times: integrating to 1e\+07 s .* raise DmpConfig\.dt"):
        integrate(dmp, DmpConfig(n_basis=20), times=[0.0, 1e7])
    long = Dmp(dmp.weights, dmp.y0, dmp.goal, 3000.0)
    with pytest.raises(ValueError, match=r"times: integrating to 3000 s at DmpConfig\.dt = 0\.001 s"):
        integrate(long, DmpConfig(n_basis=20))


def test_ude_orientation_formulation(demo):
    times, poses = demo
    cfg = DmpConfig(quaternion="ude")
    dmp = fit_dmp(times[::5], poses[::5], cfg)  # fitted at 20 Hz
    assert dmp.weights.shape == (20, 6)
    out = integrate(dmp, cfg, times[::5])
    rmse, qdist = _errors(out, poses[::5])
    assert rmse < 1e-3 and qdist.max() < 0.01
    np.testing.assert_allclose(np.linalg.norm(out[:, 3:], axis=1), 1.0, atol=1e-12)
    batch = integrate(dmp, cfg, times[::50], weights=np.stack([dmp.weights, dmp.weights + 1.0]))
    np.testing.assert_allclose(batch[0], out[::10], atol=1e-12)
    assert rotation_angle(batch[1, 5, 3:], batch[0, 5, 3:]) > 1e-3
    with pytest.raises(ValueError, match=r"weights: expected shape \(20, 6\)"):
        integrate(dmp, cfg, weights=np.zeros((20, 7)))


def test_demonstrations_give_spd_covariance_with_ridge():
    demos = [synthetic_demonstration(4.0, 20.0, variant=v) for v in range(3)]
    cfg = DmpConfig(n_basis=10)
    fit = fit_demonstrations(demos, cfg, seed=0, ridge=0.1, floor=1e-8)
    w = np.stack([d.weights for d in fit.dmps])
    assert w.shape == (3, 10, 7) and fit.sigma0.shape == (10, 7, 7)
    for b in range(10):
        sample = np.cov(w[:, b, :], rowvar=False)
        np.testing.assert_allclose(fit.sigma0[b], sample + 0.1 * np.diag(np.diag(sample)) + 1e-8 * np.eye(7),
                                   rtol=1e-12, atol=1e-15)
        np.testing.assert_array_equal(fit.sigma0[b], fit.sigma0[b].T)
        assert np.linalg.eigvalsh(fit.sigma0[b]).min() > 0
        assert np.linalg.matrix_rank(sample) <= 2  # why the ridge is needed
    # the initial weights are one of the fits, chosen by the seed
    idx, w0 = initial_weights(fit.dmps, seed=0)
    assert idx == fit.initial_index
    np.testing.assert_array_equal(w0, fit.initial.weights)
    picks = {initial_weights(fit.dmps, seed=s)[0] for s in range(20)}
    assert picks == {0, 1, 2}
    with pytest.raises(ValueError, match="demonstrations: expected at least 2"):
        fit_demonstrations(demos[:1], cfg)


def test_quaternion_signs_consistent_across_demonstrations():
    times, poses = synthetic_demonstration(3.0, 20.0)
    negated = poses.copy()
    negated[:, 3:] *= -1.0
    negated[7:, 3:] *= -1.0  # and a sign jump in the middle
    fit = fit_demonstrations([(times, poses), (times, negated)], DmpConfig(n_basis=10))
    np.testing.assert_allclose(fit.dmps[1].weights, fit.dmps[0].weights, atol=1e-9)
    np.testing.assert_allclose(fit.sigma0, np.broadcast_to(1e-8 * np.eye(7), (10, 7, 7)), atol=1e-12)


@pytest.mark.parametrize(
    "mutate, match",
    [
        (lambda t, p: (t, np.where(np.arange(len(t))[:, None] == 4, np.nan, p)), "poses: contains NaN"),
        (lambda t, p: (t[:2], p[:2]), "expected at least 3 samples, got 2"),
        (lambda t, p: (t, p[:, :6]), r"poses: expected shape \(T, 7\).*got \(\d+, 6\)"),
        (lambda t, p: (t[::-1].copy(), p), "times: expected strictly increasing"),
        (lambda t, p: (np.where(np.arange(len(t)) == 3, t[2], t), p), "times: expected strictly increasing"),
        (lambda t, p: (t, p * np.array([1, 1, 1, 1.2, 1.2, 1.2, 1.2])), r"quaternion at index \(0,\) has norm 1\.2"),
        (lambda t, p: (t[:, None], p), r"times: expected shape \(T,\)"),
    ],
)
def test_bad_demonstration_raises(mutate, match):
    times, poses = synthetic_demonstration(1.0, 20.0)
    bad_t, bad_p = mutate(times, poses)
    with pytest.raises(ValueError, match=match):
        fit_dmp(bad_t, bad_p, DmpConfig(n_basis=5))


def test_bad_config_and_weights_raise():
    times, poses = synthetic_demonstration(1.0, 20.0)
    with pytest.raises(ValueError, match=r"DmpConfig.n_basis: expected an integer >= 2, got 1"):
        fit_dmp(times, poses, DmpConfig(n_basis=1))
    with pytest.raises(ValueError, match="DmpConfig.quaternion"):
        DmpConfig(quaternion="euler").validate()
    with pytest.raises(ValueError, match="n_basis"):
        basis_centres_widths(1, 1.0)
    dmp = fit_dmp(times, poses, DmpConfig(n_basis=5))
    with pytest.raises(ValueError, match=r"weights: expected shape \(5, 7\) or \(S, 5, 7\), got \(4, 7\)"):
        integrate(dmp, DmpConfig(n_basis=5), weights=np.zeros((4, 7)))
    with pytest.raises(ValueError, match="weights: contain NaN"):
        integrate(dmp, DmpConfig(n_basis=5), weights=np.full((5, 7), np.nan))
    with pytest.raises(ValueError, match="times: expected non-decreasing"):
        integrate(dmp, DmpConfig(n_basis=5), times=[0.0, 0.2, 0.1])
    with pytest.raises(ValueError, match="Dmp.tau"):
        Dmp(np.zeros((5, 7)), Y0, GOAL, 0.0)
    with pytest.raises(ValueError, match=r"weights: expected shape \(N >= 2 fits, B, d\)"):
        exploration_covariance(np.zeros((1, 5, 7)))


def test_dmp_round_trips_through_arrays(tmp_path):
    from drake_skill.fileio import atomic_save_npz, load_npz

    rng = np.random.default_rng(4)
    dmp = Dmp(rng.normal(size=(6, 7)), Y0, GOAL, 2.5)
    atomic_save_npz(tmp_path / "dmp.npz", dmp.to_arrays("open_"))
    back = Dmp.from_arrays(load_npz(tmp_path / "dmp.npz"), "open_")
    np.testing.assert_array_equal(back.weights, dmp.weights)
    assert back.tau == 2.5
    with pytest.raises(ValueError, match="missing DMP entry 'close_weights'"):
        Dmp.from_arrays(load_npz(tmp_path / "dmp.npz"), "close_")


def test_benchmark_prints_one_json_object(capsys):
    from drake_skill.bench.dmp import main

    assert main(["--json", "--repeats", "2", "--batch", "8", "--no-orientation", "--no-mp"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert {"single_ms", "batch1000_s", "movement_primitives_single_ms"} <= set(result)
    assert result["batch_shape"] == [8, 5001, 7] and result["movement_primitives_single_ms"] is None
    assert 0 < result["single_ms"] < 1000 and result["reproduction"]["position_rmse_mm"] < 1.0


def test_fit_demonstrations_scales_only_the_columns_that_move():
    """Default: columns every demonstration moves along by >= 5 cm keep a = g - y0 (thesis
    scaling toward a new start), nearly-still ones are not scaled; both continuous in y0."""
    t, poses = _lift_and_return()
    other = poses.copy()
    other[:, 0] *= 1.1
    fit = fit_demonstrations([(t, poses), (t, other)], DmpConfig(n_basis=20))
    assert fit.config.scaled_dims == [0]  # x moves 0.3 m; z returns to its start, quaternion fixed
    dmp = fit.dmps[0]
    for dz in (0.005, -0.005):
        y0 = dmp.y0.copy()
        y0[2] += dz
        out = integrate(Dmp(dmp.weights, y0, dmp.goal, dmp.tau), fit.config, t)
        assert np.abs(out[:, :3] - poses[:, :3]).max() < 0.01
    # A start 5 cm further from the goal along x stretches the x motion (thesis scaling):
    y0 = dmp.y0.copy()
    y0[0] -= 0.05
    out = integrate(Dmp(dmp.weights, y0, dmp.goal, dmp.tau), fit.config, t)
    s = (out[:, 0] - y0[0]) / (dmp.goal[0] - y0[0])
    np.testing.assert_allclose(s, (poses[:, 0] - poses[0, 0]) / (poses[-1, 0] - poses[0, 0]), atol=0.01)
    # scale_threshold <= 0 keeps scaled_dims as given (here: none, no scaling at all).
    plain = fit_demonstrations([(t, poses), (t, other)], DmpConfig(n_basis=20, scale_threshold=0.0))
    assert plain.config.scaled_dims == []
    with pytest.raises(ValueError, match=r"DmpConfig\.scaled_dims: expected distinct weight columns in \[0, 7\)"):
        DmpConfig(scaled_dims=[7]).validate()
    # unscaled_dims keeps a moving column out of the choice: x keeps its shape from any start.
    kept = fit_demonstrations([(t, poses), (t, other)], DmpConfig(n_basis=20, unscaled_dims=[0]))
    assert (kept.config.scaled_dims, kept.config.unscaled_dims) == ([], [0])
    out = integrate(Dmp(kept.dmps[0].weights, y0, dmp.goal, dmp.tau), kept.config, t)
    shift = out[:, 0] - poses[:, 0]                   # a start 5 cm back: the offset decays, never grows
    assert shift[0] == pytest.approx(-0.05) and np.all(np.abs(shift) <= 0.05 + 1e-3) and abs(shift[-1]) < 5e-3
    with pytest.raises(ValueError, match=r"DmpConfig\.unscaled_dims: expected distinct weight columns in \[0, 7\)"):
        DmpConfig(unscaled_dims=[0, 0]).validate()


def _minimum_jerk(s):
    return 10 * s**3 - 15 * s**4 + 6 * s**5


def test_each_column_is_scaled_only_when_every_demonstration_moves_along_it():
    """Two demonstrations that move differently per column: y moves in both (scaled);
    x moves 0.3 m in one but only 2 cm net in the other (a 10 cm push that comes back):
    not scaled, so that demonstration's push keeps its shape from a start past its goal."""
    t = np.linspace(0.0, 4.0, 401)
    s, bump = t / 4.0, np.sin(np.pi * t / 4.0) ** 2
    a, b = np.zeros((401, 7)), np.zeros((401, 7))
    a[:, 0], a[:, 1], a[:, 2] = 0.3 * _minimum_jerk(s), 0.2 * _minimum_jerk(s), 0.2 + 0.1 * bump
    b[:, 0], b[:, 1], b[:, 2] = 0.1 * bump + 0.02 * _minimum_jerk(s), 0.25 * _minimum_jerk(s), 0.2 + 0.08 * bump
    a[:, 3] = b[:, 3] = 1.0
    fit = fit_demonstrations([(t, a), (t, b)], DmpConfig(n_basis=20))
    assert fit.config.scaled_dims == [1]
    # y (scaled): a start 5 cm further from the goal stretches the demonstrated profile.
    dmp = fit.dmps[0]
    y0 = dmp.y0.copy()
    y0[1] -= 0.05
    out = integrate(Dmp(dmp.weights, y0, dmp.goal, dmp.tau), fit.config, t)
    np.testing.assert_allclose((out[:, 1] - y0[1]) / (dmp.goal[1] - y0[1]), _minimum_jerk(s), atol=0.01)
    # x (not scaled): 3 cm past the goal of the second demonstration, the push keeps
    # its 10 cm (scaled by a = g - y0, it would turn into a 5 cm pull the other way).
    dmp = fit.dmps[1]
    y0 = dmp.y0.copy()
    y0[0] += 0.03
    out = integrate(Dmp(dmp.weights, y0, dmp.goal, dmp.tau), fit.config, t)
    assert np.abs(out[:, 0] - b[:, 0]).max() < 0.035
    assert out[:, 0].max() - out[0, 0] > 0.08


def _yaw_quaternions(yaw):
    """Unit quaternions (T, 4), wxyz, of rotations by ``yaw`` (T,) rad about z."""
    yaw = np.asarray(yaw, dtype=float)
    return np.stack([np.cos(yaw / 2), np.zeros_like(yaw), np.zeros_like(yaw), np.sin(yaw / 2)], axis=-1)


def test_ude_rotation_columns_scale_from_a_rotated_start():
    """Ude's orientation amplitude a_o = 2 log(g * conj(q0)): demonstrations that turn
    1.2 and 1.0 rad about z (with an overshoot) scale the z-rotation column; from a start
    turned 0.3 rad further from the goal the turn is the demonstrated profile stretched."""
    t = np.linspace(0.0, 4.0, 401)
    s, bump = t / 4.0, np.sin(np.pi * t / 4.0) ** 2
    profile = _minimum_jerk(s) + 0.25 * bump                     # 0 -> 1, overshooting on the way
    demos = []
    for turn, reach in ((1.2, 0.3), (1.0, 0.33)):
        poses = np.zeros((401, 7))
        poses[:, 0] = reach * _minimum_jerk(s)
        poses[:, 3:] = _yaw_quaternions(0.2 + turn * profile)    # from yaw 0.2 rad
        demos.append((t, poses))
    cfg = DmpConfig(n_basis=20, quaternion="ude")
    a = forcing_amplitude(demos[0][1][0], demos[0][1][-1], DmpConfig(quaternion="ude", scale_by_amplitude=True))
    np.testing.assert_allclose(a, [0.3, 0.01, 0.01, 0.01, 0.01, 1.2], atol=1e-12)   # floored where 0
    fit = fit_demonstrations(demos, cfg)
    assert fit.config.scaled_dims == [0, 5]                      # x and the rotation about z
    dmp = fit.dmps[0]
    yaw = lambda q: 2 * np.arctan2(q[:, 3], q[:, 0])           # noqa: E731
    out = integrate(dmp, fit.config, t)
    np.testing.assert_allclose(yaw(out[:, 3:]), 0.2 + 1.2 * profile, atol=0.005)
    # Start turned 0.3 rad away from the goal: a_o = 1.5 rad, the profile stretched by 1.5 / 1.2.
    y0 = dmp.y0.copy()
    y0[3:] = _yaw_quaternions(-0.1)
    out = integrate(Dmp(dmp.weights, y0, dmp.goal, dmp.tau), fit.config, t)
    np.testing.assert_allclose(yaw(out[:, 3:]), -0.1 + 1.5 * profile, atol=0.005)
    np.testing.assert_allclose(out[:, 4:6], 0.0, atol=1e-9)     # still a turn about z only


# ---------------------------------------------------------------------------
# What the mutation audit of dmp.py found untested (issue 33, docs/mutation.md)
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("eps", [4e-5, -4e-5, 1e-9])
def test_discretisation_near_critical_damping_matches_expm(eps):
    """|s h| below 1e-3 but not 0 (nearly critically damped): the series branch of sinh(s h)/s."""
    k, tau, h = 100.0, 1.0, 0.01
    d = 2.0 * math.sqrt(k) * (1.0 + eps)
    m = np.zeros((3, 3))
    m[0, 1], m[1, 0], m[1, 1], m[1, 2] = 1.0, -k / tau**2, -d / tau, 1.0 / tau**2
    e = scipy.linalg.expm(m * h)
    ad, bd = e[:2, :2], e[:2, 2]
    b, a = _discrete_filter(k, d, tau, h)
    np.testing.assert_allclose(b, [0.0, bd[0], -ad[1, 1] * bd[0] + ad[0, 1] * bd[1]], rtol=1e-12, atol=1e-18)
    np.testing.assert_allclose(a, [1.0, -np.trace(ad), np.linalg.det(ad)], rtol=1e-13, atol=1e-15)


@pytest.mark.parametrize("quaternion", ["vector", "ude"])
def test_off_grid_times_interpolate_between_grid_samples(demo, quaternion):
    """Times off the integration grid are the linear (quaternions: normalised linear)
    interpolation of the two grid samples around them; past the grid's end, its last sample."""
    times, poses = demo
    cfg = DmpConfig(quaternion=quaternion)
    dmp = fit_dmp(times[::5], poses[::5], cfg)
    rng = np.random.default_rng(0)
    weights = dmp.weights + rng.normal(0.0, 20.0, dmp.weights.shape)   # a visibly curved path
    grid = cfg.dt * np.arange(int(round(dmp.tau / cfg.dt)) + 1)
    on = integrate(dmp, cfg, grid, weights=weights)
    query = np.array([0.0, 0.25 * cfg.dt, 7.6 * cfg.dt, 0.5 * dmp.tau + 0.3 * cfg.dt, grid[-1]])
    got = integrate(dmp, cfg, query, weights=weights)
    for t, row in zip(query, got):
        i = min(int(np.floor(t / cfg.dt + 1e-12)), len(grid) - 2)
        f = t / cfg.dt - i
        expected = (1.0 - f) * on[i] + f * on[i + 1]
        expected[3:] /= np.linalg.norm(expected[3:])
        # (vector form: the 4-vector is interpolated before it is normalised: 1e-11 apart)
        np.testing.assert_allclose(row, expected, atol=1e-9)
    assert not np.allclose(got[2], on[7]) and not np.allclose(got[2], on[8])


def test_uniform_times_of_another_step_are_integrated_on_a_finer_grid(demo):
    """Times 0, d, 2d, ... with d a multiple of dt (10 Hz) give the grid's own samples."""
    times, poses = demo
    cfg = DmpConfig()
    dmp = fit_dmp(times, poses, cfg)
    fine = integrate(dmp, cfg, cfg.dt * np.arange(int(round(dmp.tau / cfg.dt)) + 1))
    step = int(round(0.1 / cfg.dt))
    coarse = integrate(dmp, cfg, 0.1 * np.arange(int(dmp.tau / 0.1) + 1))
    np.testing.assert_allclose(coarse, fine[::step][:len(coarse)], atol=1e-12)
    single = integrate(dmp, cfg, [0.0])                       # one time: the start
    np.testing.assert_allclose(single[0], dmp.y0, atol=1e-12)


def test_ude_single_trajectory_equals_the_batch_for_rotations_about_every_axis():
    """The scalar recursion of one orientation DMP and the batched one agree, for
    forcing that turns the hand about x, y and z (and an unchanged goal orientation)."""
    cfg = DmpConfig(quaternion="ude", n_basis=8)
    start = np.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0])
    for goal_q, axis in (([1.0, 0.0, 0.0, 0.0], 0), ([0.8, 0.0, 0.6, 0.0], 1), ([0.6, 0.0, 0.0, 0.8], 2)):
        weights = np.zeros((8, 6))
        weights[:, 3 + axis] = np.linspace(40.0, -40.0, 8)
        weights[:, 3 + (axis + 1) % 3] = 15.0
        dmp = Dmp(weights, start, np.r_[0.1, 0.2, 0.3, goal_q], 2.0)
        times = np.linspace(0.0, 2.0, 41)
        single = integrate(dmp, cfg, times)
        batch = integrate(dmp, cfg, times, weights=np.stack([weights, 2.0 * weights]))
        np.testing.assert_allclose(single, batch[0], atol=1e-12)
        np.testing.assert_allclose(np.linalg.norm(single[:, 3:], axis=1), 1.0, atol=1e-12)
        assert rotation_angle(single[20, 3:], start[3:]) > 0.05


_W5 = np.zeros((5, 7))
_T20 = np.linspace(0.0, 1.0, 20)
_P20 = np.tile(Y0, (20, 1))
_P20[:, 0] = np.linspace(0.0, 0.3, 20)
_CFG5 = DmpConfig(n_basis=5)


def _nan_at(array, row, col):
    out = np.array(array, dtype=float)
    out[row, col] = np.nan
    return out


@pytest.mark.parametrize("build, message", [
    (lambda: integrate(Dmp(_W5, Y0, GOAL, 1.0), _CFG5, np.zeros((2, 2))), "times: expected shape (T,), got (2, 2)"),
    (lambda: integrate(Dmp(_W5, Y0, GOAL, 1.0), _CFG5, []), "times: expected at least one time, got none"),
    (lambda: integrate(Dmp(_W5, Y0, GOAL, 1.0), _CFG5, [0.0, np.nan]), "times: contains NaN or inf"),
    (lambda: integrate(Dmp(_W5, Y0, GOAL, 1.0), _CFG5, [-0.1, 0.5]),
     "times: expected times >= 0 s from the start of the movement, min is -0.1"),
    (lambda: integrate(Dmp(_W5, Y0, GOAL, 1.0), _CFG5, [0.5, 0.2]), "times: expected non-decreasing times"),
    (lambda: integrate(Dmp(_W5, Y0, GOAL, 1.0), DmpConfig(n_basis=5, quaternion="ude")),
     "weights: expected shape (5, 6) or (S, 5, 6), got (5, 7)"),
    (lambda: exploration_covariance([_W5, _W5 + 1.0], ridge=-1.0), "ridge: expected a finite value >= 0, got -1.0"),
    (lambda: exploration_covariance([_W5, _W5 + 1.0], floor=0.0), "floor: expected a finite value > 0, got 0.0"),
    (lambda: exploration_covariance([_W5, _W5 + 1.0], floor=np.inf), "floor: expected a finite value > 0, got inf"),
    (lambda: exploration_covariance([_W5, _W5 + np.nan]), "weights: contain NaN or inf"),
    (lambda: fit_weights(_T20, _P20[:10], _CFG5),
     "times/values: expected shapes (T,) and (T, n), got (20,) and (10, 7)"),
    (lambda: fit_weights(_T20[:5], _P20[:5, 0], _CFG5),
     "times/values: expected shapes (T,) and (T, n), got (5,) and (5,)"),
    (lambda: fit_weights(_T20[:2], _P20[:2, :3], DmpConfig(n_basis=2)), "times: expected at least 3 samples, got 2"),
    (lambda: fit_weights(np.r_[_T20[:-1], np.nan], _P20[:, :3], _CFG5), "times/values: contain NaN or inf"),
    (lambda: fit_weights(_T20, _nan_at(_P20[:, :3], 3, 1), _CFG5), "times/values: contain NaN or inf"),
    (lambda: fit_weights(np.r_[_T20[:5], _T20[4:-1]], _P20[:, :3], _CFG5),
     "times: expected strictly increasing timestamps"),
    (lambda: validate_demonstration(_T20, _P20[:10]), "demonstration: times has 20 samples but poses has 10"),
    (lambda: validate_demonstration(_T20[:2], _P20[:2]), "demonstration: expected at least 3 samples, got 2"),
    (lambda: validate_demonstration(_T20, _nan_at(_P20, 3, 5)),
     "demonstration poses: contains NaN or inf (first at sample 3, column 5)"),
    (lambda: validate_demonstration(np.r_[_T20[:5], _T20[4:-1]], _P20, name="demo 2"),
     "demo 2 times: expected strictly increasing timestamps, got t[4]=0.21052631578947367 >= "
     "t[5]=0.21052631578947367"),
    (lambda: initial_weights([], 0), "dmps: expected at least one fitted DMP, got none"),
    (lambda: DmpConfig(n_basis=1).validate(), "DmpConfig.n_basis: expected an integer >= 2, got 1"),
    (lambda: DmpConfig(n_basis=True).validate(), "DmpConfig.n_basis: expected an integer >= 2, got True"),
    (lambda: DmpConfig(n_basis=5.0).validate(), "DmpConfig.n_basis: expected an integer >= 2, got 5.0"),
    (lambda: DmpConfig(K=0.0).validate(), "DmpConfig.K: expected a finite value > 0, got 0.0"),
    (lambda: DmpConfig(K="1").validate(), "DmpConfig.K: expected a finite value > 0, got '1'"),
    (lambda: DmpConfig(D=-1.0).validate(), "DmpConfig.D: expected a finite value >= 0, got -1.0"),
    (lambda: DmpConfig(D=np.nan).validate(), "DmpConfig.D: expected a finite value >= 0, got nan"),
    (lambda: DmpConfig(scaled_dims=[True]).validate(),
     "DmpConfig.scaled_dims: expected distinct weight columns in [0, 7), got [True]"),
    (lambda: DmpConfig(scaled_dims=[7]).validate(),
     "DmpConfig.scaled_dims: expected distinct weight columns in [0, 7), got [7]"),
    (lambda: Dmp(np.zeros(7), Y0, GOAL, 1.0), "Dmp.weights: expected shape (B >= 2, 7 or 6), got (7,)"),
    (lambda: Dmp(np.zeros((5, 5)), Y0, GOAL, 1.0), "Dmp.weights: expected shape (B >= 2, 7 or 6), got (5, 5)"),
    (lambda: Dmp(np.zeros((1, 7)), Y0, GOAL, 1.0), "Dmp.weights: expected shape (B >= 2, 7 or 6), got (1, 7)"),
    (lambda: Dmp(_W5, Y0[:6], GOAL, 1.0), "Dmp.y0: expected shape (7,), got (6,)"),
    (lambda: Dmp(_W5 + np.nan, Y0, GOAL, 1.0), "Dmp.weights: contains NaN or inf (shape (5, 7))"),
    (lambda: Dmp(_W5, Y0, GOAL, 1e9), "Dmp.tau: 1000000000.0 s is longer than the 3600 s accepted; expected the "
                                      "duration of one skill execution in seconds"),
    (lambda: Dmp(_W5, np.r_[Y0[:3], 2.0, 0.0, 0.0, 0.0], GOAL, 1.0),
     "Dmp.y0: quaternion [2. 0. 0. 0.] has norm 2; expected a unit quaternion (w, x, y, z) within 0.01"),
    (lambda: fit_demonstrations([(_T20, _P20)], _CFG5),
     "demonstrations: expected at least 2 (covariance across fits), got 1"),
    (lambda: fit_demonstrations([(_T20, _P20, 1), (_T20, _P20)], _CFG5),
     "demonstrations[0]: expected a pair (times, poses), got 3 items"),
    (lambda: fit_demonstrations([(_T20, _P20), (_T20, _P20[:10])], _CFG5),
     "demonstrations[1]: times has 20 samples but poses has 10"),
])
def test_each_bad_dmp_input_is_named_in_full(build, message):
    with pytest.raises(ValueError) as info:
        build()
    assert str(info.value) == message


def test_smallest_valid_dmp_inputs():
    assert integrate(Dmp(_W5, Y0, GOAL, 1.0), _CFG5, [0.2, 0.2]).shape == (2, 7)    # repeated times
    assert fit_weights(_T20[:3], _P20[:3, :3], DmpConfig(n_basis=2)).shape == (2, 3)
    assert validate_demonstration(_T20[:3], _P20[:3])[0].shape == (3,)
    assert initial_weights([Dmp(_W5, Y0, GOAL, 1.0)], 0)[0] == 0
    assert DmpConfig(n_basis=2).validate().n_basis == 2 and DmpConfig(D=0.0).validate().D == 0.0
    assert Dmp(np.zeros((2, 7)), Y0, GOAL, 1.0).n_basis == 2 and Dmp(_W5, Y0, GOAL, 3600.0).tau == 3600.0
    cov = exploration_covariance([_W5, _W5 + 1.0], ridge=0.0)
    np.testing.assert_allclose(cov[0], 0.5 * np.ones((7, 7)) + 1e-8 * np.eye(7), rtol=1e-12)


def test_forcing_target_derivatives_are_second_order_at_the_ends():
    """Eq. 3.7's target from np.gradient with second-order ends: exact for a quadratic path, also on
    uneven times and at the first and last samples (first-order ends err there by ~h)."""
    from drake_skill.action.dmp import _f_target

    t = np.array([0.0, 0.05, 0.15, 0.2, 0.35, 0.5, 0.55, 0.7])
    y = np.c_[3.0 * t**2 - t + 0.5, -2.0 * t**2]
    goal, tau, cfg = np.array([1.0, -0.5]), 0.7, DmpConfig()
    dy = np.c_[6.0 * t - 1.0, -4.0 * t]
    ddy = np.tile([6.0, -4.0], (len(t), 1))
    expected = tau * tau * ddy - cfg.K * (goal - y) + cfg.D * tau * dy
    np.testing.assert_allclose(_f_target(t, y, goal, tau, cfg), expected, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("regression", ["lwr", "least_squares"])
def test_weights_of_the_scaled_form_do_not_depend_on_the_amplitude(regression):
    """Thesis Eq. 3.4 (scale_by_amplitude): f = (g - y0) w . phi, so a demonstration twice as large,
    start and goal included, has the same weights, in both regressions."""
    t = np.linspace(0.0, 1.0, 50)
    path = np.c_[0.2 + np.sin(2 * t) / np.sin(2), -0.3 + 0.5 * t**2]          # amplitudes 1 and 0.5
    cfg = DmpConfig(n_basis=8, regression=regression, scale_by_amplitude=True)
    w = fit_weights(t, path, cfg)
    np.testing.assert_allclose(fit_weights(t, 2.0 * path, cfg), w, rtol=1e-9, atol=1e-9 * np.abs(w).max())
    assert np.abs(w).max() > 10.0


def test_as_many_bases_as_samples_and_a_basis_without_samples():
    t = np.linspace(0.0, 1.0, 12)
    y = np.c_[np.sin(t), np.cos(t)]
    assert fit_weights(t, y, DmpConfig(n_basis=12)).shape == (12, 2)
    with pytest.raises(ValueError) as info:
        fit_weights(t, y, DmpConfig(n_basis=13))
    assert str(info.value) == ("DmpConfig.n_basis: 13 bases but the demonstration has only 12 samples; "
                               "use at most 12 bases or a longer demonstration")
    # Per-basis LWR with very narrow bases and samples only at the two ends: the middle bases see none.
    gap = np.r_[np.linspace(0.0, 0.05, 20), np.linspace(0.95, 1.0, 20)]
    narrow = DmpConfig(n_basis=10, regression="lwr", width_scale=200.0)
    with pytest.raises(ValueError) as info:
        fit_weights(gap, np.c_[gap, gap**2], narrow)
    assert str(info.value) == "demonstration: basis 2 (centre x=0.359) receives no samples; use fewer bases"
    assert np.all(np.isfinite(fit_weights(np.linspace(0.0, 1.0, 40), np.c_[t[:1].repeat(40), np.linspace(0, 1, 40)],
                                          narrow)))


def _demo(columns, q=(1.0, 0.0, 0.0, 0.0)):
    """20 samples over 2 s: xyz from ``columns`` (3 arrays) and a constant quaternion ``q``."""
    t = np.linspace(0.0, 2.0, 20)
    return t, np.c_[np.column_stack(columns), np.tile(q, (20, 1))]


def test_scaled_columns_are_those_every_demonstration_moves_at_least_the_threshold():
    """x moves exactly 5 cm in both (scaled: "at least"), y 6 cm in one and 4.9 cm in the other (not
    scaled), z jumps 10 cm on the first step of one and the last step of the other (scaled: the
    amplitude is the last sample minus the first); the constant quaternion is not scaled."""
    ramp = np.linspace(0.0, 1.0, 20)
    first_step, last_step = np.r_[0.0, np.full(19, 0.1)], np.r_[np.zeros(19), 0.1]
    demos = [_demo([0.05 * ramp, 0.06 * ramp, first_step]), _demo([0.05 * ramp, 0.049 * ramp, last_step])]
    fit = fit_demonstrations(demos, DmpConfig(n_basis=5))
    assert fit.config.scaled_dims == [0, 2]
    assert all(dmp.weights.shape == (5, 7) for dmp in fit.dmps)
    given = DmpConfig(n_basis=5, scale_threshold=0.0, scaled_dims=[1])                  # threshold 0: as given
    assert fit_demonstrations(demos, given).config.scaled_dims == [1]
    assert fit_demonstrations(demos, DmpConfig(n_basis=5, scale_by_amplitude=True)).config.scaled_dims == []
    # A threshold below the amplitude floor: still only what moves (the floor is not applied here).
    assert fit_demonstrations(demos, DmpConfig(n_basis=5, scale_threshold=0.005)).config.scaled_dims == [0, 1, 2]
    # Ude rotations: 6 columns, the rotation vector's z (column 5) moves 0.4 rad in both.
    turn = [np.c_[np.cos(a / 2), 0 * a, 0 * a, np.sin(a / 2)] for a in (0.4 * ramp,)][0]
    ude = [(t, np.c_[p[:, :3], turn]) for t, p in demos]
    assert fit_demonstrations(ude, DmpConfig(n_basis=5, quaternion="ude")).config.scaled_dims == [0, 2, 5]
    # The same turn as a vector quaternion: only its z component moves 5 cm or more (sin 0.2 = 0.199).
    assert fit_demonstrations(ude, DmpConfig(n_basis=5)).config.scaled_dims == [0, 2, 6]


@pytest.mark.parametrize("first_sign", [1.0, -1.0])
def test_every_demonstration_is_put_on_the_first_ones_hemisphere(first_sign):
    """The same path with its quaternions negated (the same rotations) fits the same DMP, on the
    hemisphere of the first demonstration's first quaternion, whichever sign that has."""
    q = np.array([np.cos(0.2), 0.0, 0.0, np.sin(0.2)])
    path = [0.1 * np.linspace(0.0, 1.0, 20), np.zeros(20), 0.2 * np.linspace(0.0, 1.0, 20) ** 2]
    demos = [_demo(path, first_sign * q), _demo(path, -first_sign * q)]
    for quaternion in ("vector", "ude"):
        fit = fit_demonstrations(demos, DmpConfig(n_basis=5, quaternion=quaternion))
        for dmp in fit.dmps:
            np.testing.assert_allclose(dmp.y0[3:], first_sign * q, atol=1e-12)
            np.testing.assert_allclose(dmp.goal[3:], first_sign * q, atol=1e-12)
        np.testing.assert_allclose(fit.dmps[1].weights, fit.dmps[0].weights, atol=1e-9)



def test_the_orientation_amplitude_is_the_rotation_from_start_to_goal_in_the_world():
    """UDE's orientation amplitude 2 log(g * conj(q0)) (docs/method.md 2.1) against scipy's
    rotation vector of R_g R_0^-1, for a start and a goal that do not commute (about one axis
    the product's order does not matter, and a swapped order went uncaught)."""
    from scipy.spatial.transform import Rotation

    r0, rg = Rotation.from_euler("xyz", [0.4, -0.3, 0.2]), Rotation.from_euler("xyz", [-0.5, 0.6, 1.1])
    assert not np.allclose((rg * r0.inv()).as_rotvec(), (r0.inv() * rg).as_rotvec(), atol=0.05)
    wxyz = [np.roll(r.as_quat(), 1) for r in (r0, rg)]
    y0 = np.concatenate([[0.1, 0.2, 0.3], wxyz[0]])
    goal = np.concatenate([[0.4, -0.2, 0.5], wxyz[1]])
    a = forcing_amplitude(y0, goal, DmpConfig(quaternion="ude", scale_by_amplitude=True))
    np.testing.assert_allclose(a[:3], goal[:3] - y0[:3])
    np.testing.assert_allclose(a[3:], (rg * r0.inv()).as_rotvec(), atol=1e-12)
