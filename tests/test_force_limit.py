"""The force limit (drake_skill.station.force_limit): the hand yields before the reflex trips."""

import numpy as np
import pytest
from pydrake.math import RigidTransform

from drake_skill.skills import scenario_for_skill
from drake_skill.station.force_limit import DAMPING, force_limit_step, load_fraction
from drake_skill.station.pose_source import PosePlan
from drake_skill.station.sim.simulation import StationSimulation

F_MAX, TAU_MAX = 30.0, np.array([30.0, 30.0, 27.0, 27.0, 24.0, 21.0, 18.0])
# [start, gain, relax_time, max_offset, f_max, tau_max (7)]
PARAMS = np.r_[0.6, 0.3, 1.0, 0.05, F_MAX, TAU_MAX]
# A Jacobian whose first three joints move the TCP along x, y, z (1 m/rad each).
J = np.hstack([np.eye(3), np.zeros((3, 4))])


def _reflex_state(force, tau):
    return np.r_[force, tau, 0.0, force]


def test_the_load_is_the_reflexs_largest_fraction():
    assert load_fraction(_reflex_state(15.0, np.zeros(7)), F_MAX, TAU_MAX) == pytest.approx(0.5)
    tau = np.zeros(7)
    tau[6] = -16.2                      # 0.9 of joint 7's 18 N m
    assert load_fraction(_reflex_state(15.0, tau), F_MAX, TAU_MAX) == pytest.approx(0.9)


def test_below_the_start_the_offset_relaxes_and_above_it_the_hand_yields_along_the_force():
    h = 0.01
    delta = np.array([0.01, 0.0, 0.0])
    # Load 0.5 < start 0.6: delta <- delta (1 - h / T).
    np.testing.assert_allclose(force_limit_step(delta, _reflex_state(15.0, np.r_[0, 0, 10.0, 0, 0, 0, 0]), J,
                                                PARAMS, h), delta * (1 - h / 1.0))
    # Load 0.8 (24 N; joint 3's 18 N m is 0.67 of its limit) pushing the hand up (+z): it moves
    # up at 0.3 x (0.8 - 0.6) = 0.06 m/s.
    tau = np.r_[0.0, 0.0, 18.0, 0, 0, 0, 0]
    got = force_limit_step(np.zeros(3), _reflex_state(24.0, tau), J, PARAMS, h)
    np.testing.assert_allclose(got, [0.0, 0.0, h * 0.3 * 0.2], rtol=1e-12)
    # The direction is the damped estimate's: (J J^T + lambda^2 I)^-1 J tau, here along -x + y.
    tau = np.r_[-20.0, 20.0, 0.0, 0, 0, 0, 0]
    got = force_limit_step(np.zeros(3), _reflex_state(27.0, tau), J, PARAMS, h)
    np.testing.assert_allclose(got, h * 0.3 * 0.3 * np.array([-1.0, 1.0, 0.0]) / np.sqrt(2), rtol=1e-9)
    assert DAMPING > 0


def test_no_direction_below_one_newton_and_the_offset_is_bounded():
    h = 0.01
    # A squeeze the joints do not feel (f_hat high, tau_hat ~ 0): no direction, only relaxing.
    got = force_limit_step(np.zeros(3), _reflex_state(29.0, np.full(7, 1e-3)), J, PARAMS, h)
    np.testing.assert_array_equal(got, np.zeros(3))
    # At the bound, the offset keeps its direction and max_offset's length.
    delta = np.array([0.0, 0.03, 0.04])           # 5 cm
    got = force_limit_step(delta, _reflex_state(29.0, np.r_[0.0, 29.0, 0.0, 0, 0, 0, 0]), J, PARAMS, h)
    assert np.linalg.norm(got) == pytest.approx(0.05)
    assert got[1] > 0.03 and got[2] < 0.04


@pytest.mark.parametrize("enabled", [False, True])
def test_pressing_the_hand_into_the_lid_yields_below_the_reflex_with_the_force_limit(enabled):
    """The TCP commanded 3 cm into the closed lid at 3 cm/s (tests/test_physics.py's press,
    slower: a faster hand strikes the lid, an impact no command can soften). Without the force
    limit the contact force climbs past the reflex's 30 N; with it the hand presses past the
    limit's start (18 N) and holds below the reflex."""
    from drake_skill.station.recording import ReflexError

    config = scenario_for_skill("open")
    config.enable_camera = False
    config.controller.force_limit.enabled = enabled
    sim = StationSimulation(config)
    X_WO = sim.reset(0)
    home = sim.home_pose()
    above = RigidTransform(home.rotation(), X_WO @ np.array([0.0, 0.0, 0.30]))
    into = RigidTransform(home.rotation(), X_WO @ np.array([0.0, 0.0, 0.12]))
    plan = PosePlan.from_poses([0.0, 2.0, 8.0], [home, above, into], [0.0, 0.0, 0.0])
    if not enabled:
        with pytest.raises(ReflexError) as info:
            sim.run(plan, 9.0, record_hz=20)
        assert info.value.cause == "force"
        return
    log = sim.run(plan, 9.0, record_hz=20)
    limit = config.reflex.contact_force_max
    assert 0.6 * limit < log.peak_force < limit
    tcp_z = np.asarray(log.ee_pose)[-1, 2]
    assert tcp_z > (X_WO @ np.array([0.0, 0.0, 0.12]))[2] + 0.02     # it gave way: 2 cm or more above the command
