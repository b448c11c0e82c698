"""``DmpSystem``: the action model as a Drake LeafSystem (docs/architecture.md, box DmpSystem).

A thin wrapper over :mod:`drake_skill.action.dmp` (docs/method.md section 2). Per-run
data live in the context:

- numeric parameters: ``weights`` W (B * d, row-major (B, d); d = 7 for the
  thesis' vector quaternion, 6 for Ude et al.), ``y0`` (7), ``goal`` (7) (DMP
  start and goal poses in the object frame O: xyz m + quaternion wxyz) and
  ``tau`` (1, s). An outer loop writes them between rollouts (see
  :meth:`DmpSystem.set_weights`); nothing is rebuilt.
- discrete state (8): ``[t0, p_WO (3), q_WO (4, wxyz)]``, the start time and
  the object pose read from input ``X_WO`` by an initialization event, i.e.
  latched when the simulator is initialised. Resetting the context to its
  defaults and initialising again re-latches. If ``X_WO`` is not connected
  the identity is latched.
- cache entry: the DMP trajectory in O on a uniform grid over [0, tau] (step
  <= ``DmpConfig.dt``), recomputed only when a parameter changes. Per step
  the outputs are a lookup with linear interpolation (quaternion normalised).

Ports:

- input ``X_WO`` (abstract ``RigidTransform``): object pose in world;
- output ``X_WE_desired`` (abstract ``RigidTransform``):
  ``X_WO_latched * X_OE(t - t0)``; the pose at tau is held afterwards;
- output ``phase`` (vector 1): canonical phase ``x = exp(-alpha_x (t - t0) / tau)``
  (1 before t0; keeps decaying after tau).

The outputs do not depend on the input port directly (only on the latched
state), so the system has no direct feedthrough.
"""

from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue, Value
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.common.eigen_geometry import Quaternion
from pydrake.systems.framework import BasicVector, LeafSystem, ValueProducer

from drake_skill.action.dmp import POSE_DIM, Dmp, DmpConfig, integrate, phase

__all__ = ["DmpSystem"]

_LATCH_SIZE = 8  # t0, p_WO (3), q_WO (4)


class DmpSystem(LeafSystem):
    """Drake system generating the desired end-effector pose from a DMP.

    ``dmp`` gives the default parameter values (weights (B, d), y0, goal,
    tau); ``config`` the fixed hyper-parameters (B must match).
    """

    def __init__(self, dmp: Dmp, config: DmpConfig | None = None):
        super().__init__()
        config = (config or DmpConfig()).validate()
        if dmp.weights.shape[1] != config.weight_dim:
            raise ValueError(
                f"dmp.weights: shape {dmp.weights.shape} does not fit config.quaternion="
                f"{config.quaternion!r} (expected (B, {config.weight_dim}))"
            )
        # Construction-time constants only; everything per run is in the context.
        self._config = config
        self._n_basis, self._weight_dim = dmp.weights.shape

        self._weights_index = self.DeclareNumericParameter(BasicVector(dmp.weights.ravel()))
        self._y0_index = self.DeclareNumericParameter(BasicVector(dmp.y0))
        self._y0_demo_index = self.DeclareNumericParameter(BasicVector(dmp.demonstrated_start))
        self._goal_index = self.DeclareNumericParameter(BasicVector(dmp.goal))
        self._tau_index = self.DeclareNumericParameter(BasicVector([dmp.tau]))

        self._X_WO_port = self.DeclareAbstractInputPort("X_WO", Value(RigidTransform()))

        latch0 = np.zeros(_LATCH_SIZE)
        latch0[4] = 1.0
        self._latch_index = self.DeclareDiscreteState(latch0)
        self.DeclareInitializationDiscreteUpdateEvent(self._latch_object_pose)

        self._trajectory_cache = self.DeclareCacheEntry(
            "DMP trajectory (step s, poses in O (N, 7))",
            ValueProducer(
                allocate=lambda: AbstractValue.Make((1.0, np.zeros((1, POSE_DIM)))),
                calc=self._calc_trajectory,
            ),
            {self.all_parameters_ticket()},
        )
        self._X_WE_port = self.DeclareAbstractOutputPort(
            "X_WE_desired",
            lambda: Value(RigidTransform()),
            self._calc_X_WE_desired,
            prerequisites_of_calc={
                self.time_ticket(),
                self.xd_ticket(),
                self._trajectory_cache.ticket(),
            },
        )
        self._phase_port = self.DeclareVectorOutputPort(
            "phase",
            1,
            self._calc_phase,
            prerequisites_of_calc={self.time_ticket(), self.xd_ticket(), self.all_parameters_ticket()},
        )

    # ---------------------------------------------------------------- ports
    def get_X_WO_input_port(self):
        return self._X_WO_port

    def get_X_WE_desired_output_port(self):
        return self._X_WE_port

    def get_phase_output_port(self):
        return self._phase_port

    @property
    def config(self) -> DmpConfig:
        return self._config

    # ------------------------------------------------------ parameter access
    def set_weights(self, context, weights) -> None:
        """Writes W ((B, d) or flat (B * d,)) into this system's ``context``."""
        w = np.asarray(weights, dtype=float)
        if w.shape not in ((self._n_basis, self._weight_dim), (self._n_basis * self._weight_dim,)):
            raise ValueError(
                f"weights: expected shape ({self._n_basis}, {self._weight_dim}) or "
                f"({self._n_basis * self._weight_dim},), got {w.shape}"
            )
        if not np.all(np.isfinite(w)):
            raise ValueError("weights: contain NaN or inf")
        context.get_mutable_numeric_parameter(self._weights_index).SetFromVector(w.ravel())

    def get_weights(self, context) -> np.ndarray:
        """W (B, d) from this system's ``context`` (a copy)."""
        v = context.get_numeric_parameter(self._weights_index).get_value()
        return np.array(v).reshape(self._n_basis, self._weight_dim)

    def set_start_goal(self, context, y0, goal, y0_demo=None) -> None:
        """Writes the DMP start and goal poses (7,) each, object frame, and, when given, the
        demonstrated start ``y0_demo`` the weights were fitted from (``Dmp.y0_demo``)."""
        poses = (("y0", y0), ("goal", goal)) + ((("y0_demo", y0_demo),) if y0_demo is not None else ())
        for name, v in poses:
            v = np.asarray(v, dtype=float)
            if v.shape != (POSE_DIM,) or not np.all(np.isfinite(v)):
                raise ValueError(f"{name}: expected a finite pose of shape (7,), got {v.shape}: {v}")
            if abs(np.linalg.norm(v[3:]) - 1.0) > 1e-2:
                raise ValueError(f"{name}: quaternion {v[3:]} has norm {np.linalg.norm(v[3:]):.4g}, expected 1")
        context.get_mutable_numeric_parameter(self._y0_index).SetFromVector(np.asarray(y0, dtype=float))
        context.get_mutable_numeric_parameter(self._goal_index).SetFromVector(np.asarray(goal, dtype=float))
        if y0_demo is not None:
            context.get_mutable_numeric_parameter(self._y0_demo_index).SetFromVector(np.asarray(y0_demo, float))

    def set_duration(self, context, tau: float) -> None:
        """Writes the duration tau (s, > 0)."""
        if not (np.isfinite(tau) and tau > 0):
            raise ValueError(f"tau: expected a finite duration > 0 s, got {tau!r}")
        context.get_mutable_numeric_parameter(self._tau_index).SetFromVector([float(tau)])

    def get_dmp(self, context) -> Dmp:
        """The DMP described by this system's parameters in ``context``."""
        return Dmp(
            weights=self.get_weights(context),
            y0=np.array(context.get_numeric_parameter(self._y0_index).get_value()),
            goal=np.array(context.get_numeric_parameter(self._goal_index).get_value()),
            tau=float(context.get_numeric_parameter(self._tau_index).get_value()[0]),
            y0_demo=np.array(context.get_numeric_parameter(self._y0_demo_index).get_value()),
        )

    def get_latched_X_WO(self, context) -> RigidTransform:
        """Object pose latched at initialization."""
        v = context.get_discrete_state(self._latch_index).get_value()
        return RigidTransform(Quaternion(v[4:8] / np.linalg.norm(v[4:8])), v[1:4])

    # ------------------------------------------------------------ callbacks
    def _latch_object_pose(self, context, discrete_state):
        if self._X_WO_port.HasValue(context):
            X_WO = self._X_WO_port.Eval(context)
        else:
            X_WO = RigidTransform()
        q = X_WO.rotation().ToQuaternion()
        v = np.concatenate([[context.get_time()], X_WO.translation(), [q.w(), q.x(), q.y(), q.z()]])
        discrete_state.get_mutable_vector(self._latch_index).SetFromVector(v)

    def _calc_trajectory(self, context, value):
        dmp = self.get_dmp(context)
        n = max(1, int(np.ceil(dmp.tau / self._config.dt - 1e-9)))
        times = np.linspace(0.0, dmp.tau, n + 1)
        poses = integrate(dmp, self._config, times)
        poses.setflags(write=False)
        value.set_value((dmp.tau / n, poses))

    def _pose_in_object_frame(self, context) -> np.ndarray:
        step, poses = self._trajectory_cache.Eval(context)
        t0 = context.get_discrete_state(self._latch_index).get_value()[0]
        u = max(context.get_time() - t0, 0.0) / step
        i = min(int(u), poses.shape[0] - 1)
        frac = min(u - i, 1.0)
        if i >= poses.shape[0] - 1:
            return poses[-1].copy()
        y = poses[i] * (1.0 - frac) + poses[i + 1] * frac
        y[3:] /= np.linalg.norm(y[3:])
        return y

    def _calc_X_WE_desired(self, context, value):
        y = self._pose_in_object_frame(context)
        X_OE = RigidTransform(RotationMatrix(Quaternion(y[3:])), y[:3])
        value.set_value(self.get_latched_X_WO(context) @ X_OE)

    def _calc_phase(self, context, output):
        t0 = context.get_discrete_state(self._latch_index).get_value()[0]
        tau = context.get_numeric_parameter(self._tau_index).get_value()[0]
        output.SetAtIndex(0, float(phase(max(context.get_time() - t0, 0.0), tau, self._config.alpha_x)))
