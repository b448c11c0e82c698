"""``PoseTrajectorySource``: plays a keyframed hand trajectory into the station.

The plan (keyframe times, hand poses X_WE and finger openings) is an abstract
*parameter* of the context, so one built diagram replays any plan: write a new
plan into a reset context and simulate again. Poses are interpolated linearly
in position and by spherical linear interpolation in orientation, Drake's
``PiecewisePose.MakeLinear`` (a first-order hold and a
``PiecewiseQuaternionSlerp``); the finger opening linearly (``np.interp``).
Before the first keyframe the first is held, after the last the last (Drake's
trajectories clamp the time to their span).
"""

from __future__ import annotations

import dataclasses as dc

import numpy as np
from pydrake.common.eigen_geometry import Quaternion
from pydrake.common.value import AbstractValue, Value
from pydrake.math import RigidTransform
from pydrake.systems.framework import LeafSystem
from pydrake.trajectories import PiecewisePose


@dc.dataclass
class PosePlan:
    """Keyframes of a hand trajectory.

    times: (K,) strictly increasing [s]; positions: (K, 3) p_WE [m];
    quaternions: (K, 4) unit (w, x, y, z) of R_WE; gripper: (K,) opening [m].
    """

    times: np.ndarray
    positions: np.ndarray
    quaternions: np.ndarray
    gripper: np.ndarray

    def __post_init__(self):
        self.times = np.asarray(self.times, dtype=float)
        self.positions = np.asarray(self.positions, dtype=float)
        self.quaternions = np.asarray(self.quaternions, dtype=float)
        self.gripper = np.asarray(self.gripper, dtype=float)
        k = self.times.shape[0] if self.times.ndim == 1 else -1
        if k < 1:
            raise ValueError(f"PosePlan.times must be a non-empty 1-D array, got shape {self.times.shape}")
        for name, arr, width in (("positions", self.positions, 3), ("quaternions", self.quaternions, 4)):
            if arr.shape != (k, width):
                raise ValueError(f"PosePlan.{name} must have shape ({k}, {width}), got {arr.shape}")
        if self.gripper.shape != (k,):
            raise ValueError(f"PosePlan.gripper must have shape ({k},), got {self.gripper.shape}")
        for name in ("times", "positions", "quaternions", "gripper"):
            if not np.all(np.isfinite(getattr(self, name))):
                raise ValueError(f"PosePlan.{name} contains NaN or infinity")
        if k > 1 and np.any(np.diff(self.times) <= 0):
            raise ValueError("PosePlan.times must be strictly increasing")
        norms = np.linalg.norm(self.quaternions, axis=1)
        if np.any(np.abs(norms - 1.0) > 1e-3):
            raise ValueError(f"PosePlan.quaternions must be unit quaternions; norms range "
                             f"{norms.min():.4f}..{norms.max():.4f}")
        self.quaternions = self.quaternions / norms[:, None]
        self._trajectory = self._make_trajectory()

    def _make_trajectory(self) -> PiecewisePose:
        """X_WE(t) through the keyframes (one keyframe: held, as two equal knots 1 s apart)."""
        poses = [RigidTransform(Quaternion(q), p) for q, p in zip(self.quaternions, self.positions)]
        times = [float(t) for t in self.times]
        if len(times) == 1:
            times, poses = [times[0], times[0] + 1.0], poses * 2
        return PiecewisePose.MakeLinear(times, poses)

    # The trajectory is derived from the keyframes (Drake trajectories do not pickle):
    # a pickled plan carries its arrays and rebuilds it (worker processes).
    def __getstate__(self):
        return {k: v for k, v in self.__dict__.items() if k != "_trajectory"}

    def __setstate__(self, state):
        self.__dict__.update(state)
        self._trajectory = self._make_trajectory()

    @classmethod
    def from_poses(cls, times, poses, gripper) -> "PosePlan":
        """From a list of RigidTransforms X_WE."""
        return cls(times, [X.translation() for X in poses],
                   [X.rotation().ToQuaternion().wxyz() for X in poses], gripper)

    @property
    def duration(self) -> float:
        return float(self.times[-1])

    @property
    def trajectory(self) -> PiecewisePose:
        """The hand trajectory X_WE(t) (Drake's PiecewisePose; do not modify the keyframe arrays)."""
        return self._trajectory

    def pose(self, t: float) -> RigidTransform:
        """X_WE at time t [s]."""
        return self._trajectory.GetPose(float(t))

    def opening(self, t: float) -> float:
        return float(np.interp(t, self.times, self.gripper))


def hold_plan(X_WE: RigidTransform, opening: float = 0.0) -> PosePlan:
    """A plan that holds one pose."""
    return PosePlan.from_poses([0.0], [X_WE], [opening])


class PoseTrajectorySource(LeafSystem):
    """Outputs ``X_WE_desired`` (RigidTransform) and ``gripper_command`` [1] from a PosePlan.

    The plan is the abstract parameter ``plan`` (see :meth:`set_plan`).
    """

    def __init__(self, default_plan: PosePlan | None = None):
        super().__init__()
        plan = default_plan if default_plan is not None else hold_plan(RigidTransform())
        self._plan_index = self.DeclareAbstractParameter(AbstractValue.Make(plan))
        self.DeclareAbstractOutputPort("X_WE_desired", lambda: Value(RigidTransform()), self._calc_pose,
                                       {self.time_ticket(), self.all_parameters_ticket()})
        self.DeclareVectorOutputPort("gripper_command", 1, self._calc_gripper,
                                     {self.time_ticket(), self.all_parameters_ticket()})

    def plan(self, context) -> PosePlan:
        return context.get_abstract_parameter(self._plan_index).get_value()

    def set_plan(self, context, plan: PosePlan) -> None:
        if not isinstance(plan, PosePlan):
            raise ValueError(f"plan must be a PosePlan, got {type(plan).__name__}")
        context.get_mutable_abstract_parameter(self._plan_index).set_value(plan)

    def _calc_pose(self, context, output):
        output.set_value(self.plan(context).pose(context.get_time()))

    def _calc_gripper(self, context, output):
        output.SetAtIndex(0, self.plan(context).opening(context.get_time()))
