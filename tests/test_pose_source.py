"""PosePlan: Drake's PiecewisePose.MakeLinear gives the hand-written interpolation's poses."""

import copy
import pickle

import numpy as np
import pytest
from pydrake.common.eigen_geometry import Quaternion
from pydrake.math import RigidTransform

from drake_skill.station.pose_source import PosePlan, hold_plan

#: How far PosePlan.pose may be from the hand-written interpolation it replaced
#: (position in m, rotation-matrix entries): the same formulas, only rounding apart.
TOLERANCE = 1e-12


def _hand_written_pose(plan: PosePlan, t: float) -> RigidTransform:
    """The interpolation PosePlan did itself before PiecewisePose: linear position,
    Eigen's slerp between the neighbouring keyframes, the ends held."""
    times = plan.times
    if t <= times[0] or len(times) == 1:
        i, s = 0, 0.0
    elif t >= times[-1]:
        i, s = len(times) - 1, 0.0
    else:
        i = int(np.searchsorted(times, t, side="right")) - 1
        s = (t - times[i]) / (times[i + 1] - times[i])
    if s == 0:
        return RigidTransform(Quaternion(plan.quaternions[i]), plan.positions[i])
    p = (1 - s) * plan.positions[i] + s * plan.positions[i + 1]
    q = Quaternion(plan.quaternions[i]).slerp(s, Quaternion(plan.quaternions[i + 1]))
    return RigidTransform(q, p)


def _random_plan(rng, k):
    t = np.cumsum(rng.uniform(0.05, 2.0, k)) - 0.3
    q = rng.normal(size=(k, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    if k > 2:
        q[2] = -q[1]            # the same rotation with the other sign: no detour through slerp
    return PosePlan(t, rng.normal(size=(k, 3)), q, rng.uniform(0.0, 0.08, k))


@pytest.mark.parametrize("seed", range(5))
def test_poses_match_the_hand_written_interpolation(seed):
    rng = np.random.default_rng(seed)
    for k in (1, 2, 3, 7):
        plan = _random_plan(rng, k)
        for t in np.r_[np.linspace(plan.times[0] - 1.0, plan.times[-1] + 1.0, 97), plan.times]:
            X, ref = plan.pose(t), _hand_written_pose(plan, t)
            np.testing.assert_allclose(X.translation(), ref.translation(), rtol=0, atol=TOLERANCE)
            np.testing.assert_allclose(X.rotation().matrix(), ref.rotation().matrix(), rtol=0, atol=TOLERANCE)
        # Keyframes exactly, the first held before and the last after.
        np.testing.assert_allclose(plan.pose(plan.times[-1] + 5.0).translation(), plan.positions[-1], atol=1e-15)
        np.testing.assert_allclose(plan.pose(plan.times[0] - 5.0).translation(), plan.positions[0], atol=1e-15)


def test_a_plan_survives_copy_and_pickle():
    plan = _random_plan(np.random.default_rng(9), 4)
    for other in (copy.deepcopy(plan), pickle.loads(pickle.dumps(plan))):
        t = float(plan.times[1]) + 0.1
        assert other.pose(t).IsExactlyEqualTo(plan.pose(t))
        assert other.opening(t) == plan.opening(t)


def test_hold_plan_holds_one_pose():
    X = RigidTransform(Quaternion(np.array([0.0, 1.0, 0.0, 0.0])), [0.4, 0.1, 0.3])
    plan = hold_plan(X, 0.04)
    for t in (-1.0, 0.0, 0.7, 100.0):
        assert plan.pose(t).IsNearlyEqualTo(X, 1e-15)
        assert plan.opening(t) == 0.04
    assert plan.duration == 0.0
