"""Tests of drake_skill.resample (100 Hz -> 10 Hz demonstrations)."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from drake_skill.bench.dmp import synthetic_demonstration
from drake_skill.quaternion import quat_exp, rotation_angle
from drake_skill.resample import estimate_rate, resample_demonstration


def test_subsample_100_to_10_hz_keeps_every_tenth_sample():
    times, poses = synthetic_demonstration(duration=5.0, rate_hz=100.0)
    assert estimate_rate(times) == pytest.approx(100.0)
    t10, p10 = resample_demonstration(times, poses, 10.0, "subsample")
    assert t10.shape == (51,) and p10.shape == (51, 7)
    np.testing.assert_allclose(t10, times[::10])
    np.testing.assert_allclose(p10, poses[::10], atol=1e-15)
    assert estimate_rate(t10) == pytest.approx(10.0)


def test_subsample_appends_last_sample_off_grid():
    times, poses = synthetic_demonstration(duration=5.0, rate_hz=100.0)
    t, p = resample_demonstration(times[:-5], poses[:-5], 10.0, "subsample")
    assert t[-1] == times[-6] and t[-2] == times[-11] and len(t) == 51
    np.testing.assert_allclose(p[-1], poses[-6])
    t_nolast, _ = resample_demonstration(times[:-5], poses[:-5], 10.0, "subsample", keep_last=False)
    assert len(t_nolast) == 50


def test_interpolate_slerps_quaternions_and_fixes_signs():
    # irregular 100 Hz-ish times, rotation at constant rate about z, linear position
    rng = np.random.default_rng(0)
    times = np.cumsum(np.r_[0.0, rng.uniform(0.008, 0.012, 300)])
    angle = 1.5 * times / times[-1]
    q = quat_exp(0.5 * angle[:, None] * np.array([0.0, 0.0, 1.0]))
    q[::7] *= -1.0  # sign jumps, as recorded quaternions may have
    pos = np.outer(times, [0.1, -0.2, 0.05])
    t, p = resample_demonstration(times, np.concatenate([pos, q], axis=1), 10.0, "interpolate")
    assert t[0] == times[0] and t[-1] == times[-1]
    np.testing.assert_allclose(np.diff(t[:-1]), 0.1, atol=1e-12)
    np.testing.assert_allclose(p[:, :3], np.outer(t, [0.1, -0.2, 0.05]), atol=1e-12)
    expected = quat_exp(0.5 * (1.5 * t / times[-1])[:, None] * np.array([0.0, 0.0, 1.0]))
    # slerp between samples of a constant-rate rotation is exact
    np.testing.assert_allclose(rotation_angle(p[:, 3:], expected), 0.0, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(p[:, 3:], axis=1), 1.0, atol=1e-12)
    assert np.all(np.einsum("ij,ij->i", p[1:, 3:], p[:-1, 3:]) > 0)  # continuous signs
    np.testing.assert_allclose(p[0, 3:], q[0], atol=1e-12)  # sign of the first source sample (negated by q[::7])


def test_interpolate_matches_subsample_on_uniform_data():
    times, poses = synthetic_demonstration(duration=2.0, rate_hz=100.0)
    ts, ps = resample_demonstration(times, poses, 10.0, "subsample")
    ti, pi = resample_demonstration(times, poses, 10.0, "interpolate")
    np.testing.assert_allclose(ti, ts, atol=1e-12)
    np.testing.assert_allclose(pi, ps, atol=1e-9)
    # scipy's Slerp halfway between two rotations is the half rotation
    r = Rotation.from_rotvec([[0.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    qs = r.as_quat()[:, [3, 0, 1, 2]]
    demo = np.concatenate([np.zeros((3, 3)), np.stack([qs[0], qs[1], qs[1]])], axis=1)
    _, out = resample_demonstration([0.0, 1.0, 2.0], demo, 2.0, "interpolate")
    assert rotation_angle(out[1, 3:], Rotation.from_rotvec([0.0, 0.5, 0.0]).as_quat()[[3, 0, 1, 2]]) < 1e-12


def test_resample_rejects_bad_input():
    times, poses = synthetic_demonstration(duration=1.0, rate_hz=100.0)
    with pytest.raises(ValueError, match="not an integer multiple of 30"):
        resample_demonstration(times, poses, 30.0, "subsample")
    jittered = times.copy()
    jittered[10] += 0.004
    with pytest.raises(ValueError, match=r"subsampling needs uniform timestamps; step (9|10) is 0\.0(14|06)"):
        resample_demonstration(jittered, poses, 10.0, "subsample")
    with pytest.raises(ValueError, match="rate_hz: expected a finite rate > 0"):
        resample_demonstration(times, poses, -1.0)
    with pytest.raises(ValueError, match="method: expected one of"):
        resample_demonstration(times, poses, 10.0, "nearest")
    with pytest.raises(ValueError, match="times: expected strictly increasing"):
        resample_demonstration(times[::-1], poses, 10.0)
