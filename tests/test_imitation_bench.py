"""The imitation benchmark's figures (drake_skill/action/metrics.py) on synthetic data with known
answers, one imitation in the simulated station, and the benchmark's command line."""

import math

import numpy as np
import pytest

from drake_skill.action import metrics
from drake_skill.action.dmp import Dmp, DmpConfig, fit_dmp, integrate

DT = 0.01


def minimum_jerk_path(t, duration=4.0, start=(0.1, -0.05, 0.3), goal=(0.35, 0.1, 0.12), bump=0.06):
    """(T, 7) a smooth reach with a lift, at rest at both ends; fixed gripper-down orientation."""
    s = np.clip(np.asarray(t, dtype=float) / duration, 0.0, 1.0)
    mj = 10 * s**3 - 15 * s**4 + 6 * s**5
    pos = np.asarray(start) + np.outer(mj, np.subtract(goal, start))
    pos[:, 2] += bump * np.sin(np.pi * s) ** 2
    quat = np.tile([0.0, 1.0, 0.0, 0.0], (len(s), 1))
    return np.concatenate([pos, quat], axis=1)


@pytest.mark.parametrize("shift_s", [0.0234, -0.0171, 0.05])
def test_a_known_time_shift_gives_its_lag_within_a_millisecond(shift_s):
    t = np.arange(0, 5.0 + DT / 2, DT)
    demo = minimum_jerk_path(t)
    imitation = minimum_jerk_path(t - shift_s)      # reaches each point shift_s later
    assert metrics.lag_ms(imitation, demo, DT) == pytest.approx(1e3 * shift_s, abs=1.0)


def test_lag_of_an_imitation_that_stopped_early_and_of_a_still_path():
    t = np.arange(0, 5.0 + DT / 2, DT)
    demo = minimum_jerk_path(t)
    stopped = minimum_jerk_path(t - 0.03)[:300]      # held where it stopped, at 3 s
    assert 0.0 < metrics.lag_ms(stopped, demo, DT) < 100.0
    still = np.tile(demo[:1], (len(t), 1))
    assert metrics.lag_ms(still, still, DT) == 0.0


def test_a_known_offset_gives_the_total_error_and_the_near_contact_error():
    t = np.arange(0, 6.0 + DT / 2, DT)
    demo = minimum_jerk_path(t)
    state = np.clip((t - 2.0) / 1.5, 0.0, 1.0) * 1.2          # the object moves from 2 s to 3.5 s
    mask = metrics.contact_mask(t, state)
    imitation = demo.copy()
    imitation[:, :3] += [0.003, 0.0, -0.004]                  # 5 mm everywhere
    imitation[mask, 1] += 0.012                               # 13 mm near contact
    figures = metrics.total_error(imitation, demo, mask)
    assert figures["contact_max_mm"] == pytest.approx(13.0, abs=1e-9)
    assert figures["total_max_mm"] == pytest.approx(13.0, abs=1e-9)
    share = mask.mean()
    assert figures["total_rms_mm"] == pytest.approx(math.sqrt(25 * (1 - share) + 169 * share), abs=1e-9)
    assert metrics.tracking_error(imitation, demo)[0] == pytest.approx(13.0, abs=1e-9)
    # A longer imitation is compared over the demonstration's samples.
    longer = np.concatenate([imitation, np.tile(imitation[-1:], (50, 1))])
    assert metrics.total_error(longer, demo, mask) == figures


def test_contact_mask_is_where_the_object_moves_dilated():
    t = np.arange(0, 6.0 + DT / 2, DT)
    state = np.clip((t - 2.0) / 1.5, 0.0, 1.0) * 1.2
    mask = metrics.contact_mask(t, state, dilate_s=0.1)
    on = t[mask]
    assert on.min() == pytest.approx(1.9, abs=0.011) and on.max() == pytest.approx(3.6, abs=0.011)
    assert np.all(np.diff(np.flatnonzero(mask)) == 1)          # one segment
    assert not metrics.contact_mask(t, np.zeros_like(t)).any()   # an object that never moves


def test_fit_error_of_a_path_the_dmp_generates_is_zero_and_an_offset_is_seen():
    config = DmpConfig(n_basis=12)
    dmp = Dmp(np.random.default_rng(3).normal(0, 20, (12, 7)), minimum_jerk_path([0.0])[0],
              minimum_jerk_path([4.0])[0], 4.0)
    t = np.arange(0, 4.0 + DT / 2, DT)
    path = integrate(dmp, config, t)
    assert metrics.fit_error(dmp, config, t + 7.0, path)[0] < 1e-9   # times from any start
    shifted = path.copy()
    shifted[:, 2] += 0.002
    assert metrics.fit_error(dmp, config, t, shifted) == pytest.approx((2.0, 2.0), abs=1e-9)


def test_contact_shift_of_an_unscaled_column_is_the_start_offset_decaying():
    """Unscaled: y(t) moves by dy0 (1 - K s(t)) = dy0 (1 + w t) exp(-w t), w = sqrt(K) / tau."""
    tau = 4.0
    t = np.arange(0, tau + DT / 2, DT)
    demo = minimum_jerk_path(t, duration=tau)
    config = DmpConfig(n_basis=15, scaled_dims=[])
    dmp = fit_dmp(t, demo, config)
    w = math.sqrt(config.K) / tau
    for t_on in (0.5, 1.2, 3.0):
        mask = (t >= t_on - 1e-9) & (t <= t_on + 0.6)
        expected = 50.0 * (1 + w * t_on) * math.exp(-w * t_on)
        assert metrics.contact_shift_mm(dmp, config, t, mask) == pytest.approx(expected, rel=1e-6)
    late = t >= 3.6
    assert metrics.contact_shift_mm(dmp, config, t, late) < 0.1       # via points kept late in the motion
    assert math.isnan(metrics.contact_shift_mm(dmp, config, t, np.zeros_like(t, dtype=bool)))
    # A column scaled by g - y0 stretches the whole shape instead: its contact moves far more.
    scaled = DmpConfig(n_basis=15, scaled_dims=[0, 1])
    dmp_scaled = fit_dmp(t, demo, scaled)
    assert metrics.contact_shift_mm(dmp_scaled, scaled, t, (t >= 1.2) & (t <= 1.8)) > \
        metrics.contact_shift_mm(dmp, config, t, (t >= 1.2) & (t <= 1.8)) + 5.0


def test_worst_takes_the_largest_figure_and_the_largest_lag_either_way():
    from drake_skill.bench.imitation import WORST_KEYS, worst_of

    rows = [dict.fromkeys(WORST_KEYS, 1.0), dict.fromkeys(WORST_KEYS, 2.0)]
    rows[0].update(lag_ms=-30.0, contact_max_mm=None, reflex_trips=1)
    rows[1].update(lag_ms=20.0, contact_max_mm=None, reflex_trips=0)
    worst = worst_of(rows)
    assert list(worst) == list(WORST_KEYS)
    assert worst["lag_ms"] == 30.0 and worst["fit_rms_mm"] == 2.0
    assert worst["contact_max_mm"] is None and worst["reflex_trips"] == 1


def test_bench_help_explains_every_figure_and_bad_options_fail(capsys):
    from drake_skill.bench.imitation import WORST_KEYS
    from drake_skill.cli.main import main

    assert main(["bench", "imitation", "--help"]) == 0
    text = capsys.readouterr().out
    for key in WORST_KEYS:
        assert key.replace("_rms_mm", "").replace("_max_mm", "") in text, key
    assert main(["bench", "imitation", "--count", "1", "--demos", "."]) == 2
    assert "at least 2" in capsys.readouterr().err
    assert main(["bench", "imitation", "--skills", "teapot"]) == 2
    assert "teapot" in capsys.readouterr().err


def test_imitate_a_short_free_space_motion_on_the_demonstration_grid():
    """One 2 s reach in free space in the Open scene: records on the demonstration's grid,
    starts where it did, tracks the command within millimetres, lags it a little."""
    from drake_skill.demos.format import Demonstration, downsample_action, object_frame_poses
    from drake_skill.learning.imitation import Imitator, imitation_metrics
    from drake_skill.learning.rollout import ActionModel
    from drake_skill.skills import load_skill
    from drake_skill.station.recording import pose_to_vector

    station_config = load_skill("open").station_config()
    station_config.enable_camera = False
    config = DmpConfig(n_basis=10)
    seed = 5
    t = np.arange(0, 2.0 + DT / 2, DT)
    # Placeholder DMP for the diagram: the imitator runs each demonstration's own.
    placeholder = Dmp(np.zeros((10, 7)), [0, 0, 0.5, 0, 1, 0, 0], [0, 0, 0.5, 0, 1, 0, 0], 2.0)
    imitator = Imitator(ActionModel("open", placeholder, config), station_config)
    station = imitator.station
    X_WO = pose_to_vector(station.random_object_pose(seed))
    X_WE_home = pose_to_vector(station.GetOutputPort("ee_pose").Eval(station.CreateDefaultContext()))
    home = object_frame_poses(X_WO, X_WE_home[None])[0]
    s = t / t[-1]
    X_OE = np.tile(home, (len(t), 1))
    X_OE[:, 2] += 0.06 * (10 * s**3 - 15 * s**4 + 6 * s**5)       # 6 cm up, away from the box
    _, t10, X10 = downsample_action(t, X_OE)
    demo = Demonstration(skill="open", seed=seed, success=True, final_object_state=0.0, times_100hz=t,
                         X_OE_100hz=X_OE, q_100hz=np.zeros((len(t), 7)), gripper_100hz=np.zeros(len(t)),
                         object_state_100hz=np.zeros(len(t)), times=t10, X_OE=X10, X_WO_true=X_WO).validate()
    dmp = fit_dmp(t, X_OE, config)
    run = imitator.imitate(dmp, demo)
    assert not run.failed, run.message
    assert run.times[0] == 0.0 and np.allclose(np.diff(run.times), DT)
    assert len(run.times) == int(round((2.0 + imitator.runner.settle_time) / DT)) + 1
    assert run.X_OE_demo_grid.shape == (len(t), 7)
    assert np.array_equal(run.X_OE_demo_grid[:, :3], run.X_OE[:len(t), :3])
    assert np.linalg.norm(run.X_OE[0, :3] - X_OE[0, :3]) < 1e-3
    figures = imitation_metrics(config, dmp, demo, run)
    assert figures["reflex_trips"] == 0 and figures["contact_samples"] == 0
    assert figures["contact_max_mm"] is None or math.isnan(figures["contact_max_mm"])
    assert figures["tracking_rms_mm"] < 3.0 and figures["total_rms_mm"] < 5.0
    assert 0.0 < figures["lag_ms"] < 80.0
    assert figures["object_state_error"] < 1e-3
    # A demonstration whose object pose its seed does not draw is imitated at its own pose.
    moved = Demonstration(**{**demo.__dict__, "X_WO_true": X_WO + [0.01, 0, 0, 0, 0, 0, 0]})
    assert np.allclose(imitator.imitate(dmp, moved).X_WO, moved.X_WO_true)
    assert "random_object_pose" not in station.__dict__


def test_a_fitted_skill_must_come_with_the_demonstrations_it_was_fitted_from(tmp_path):
    from types import SimpleNamespace

    from drake_skill.bench.imitation import _demo_folder
    from drake_skill.learning.imitation import check_demo_pairs

    start = minimum_jerk_path([0.0])
    dmps = [SimpleNamespace(y0=start[0]), SimpleNamespace(y0=start[0] + [0.02, 0, 0, 0, 0, 0, 0])]
    demos = [SimpleNamespace(X_OE=start, path=f"d/demo_00{i}.npz") for i in range(2)]
    with pytest.raises(ValueError, match="2 demonstrations, but the skill was fitted from 1"):
        check_demo_pairs(SimpleNamespace(dmps=dmps[:1]), demos, "--demos d")
    with pytest.raises(ValueError, match="demo_001.npz starts 20.0 mm from the skill's DMP 1"):
        check_demo_pairs(SimpleNamespace(dmps=dmps), demos, "--demos d")
    (tmp_path / "open").mkdir()
    (tmp_path / "open" / "demo_000.npz").write_bytes(b"")
    assert _demo_folder(tmp_path, "open") == tmp_path / "open"
    assert _demo_folder(tmp_path / "open", "open") == tmp_path / "open"
    with pytest.raises(FileNotFoundError, match="no demo_\\*.npz files for 'close'"):
        _demo_folder(tmp_path, "close")
