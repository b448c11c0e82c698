"""The hand yields before the collision reflex trips (docs/method.md 5.3, an Extension).

The collision reflex (``drake_skill.station.reflex``) stops the robot when its
filtered contact force or an external joint torque crosses a limit; a
policy-search sample that presses a centimetre further into the object than
the demonstrations trips it (docs/method.md 5.2). Measured on Open, the
filtered force of a tripping sample climbs from 15 N to the 30 N limit in
0.15 s, slowly enough for the command to give way. :class:`ForceLimit` sits
after the end-effector controller's rate limiter and moves the commanded
joint positions so that the hand gives way along the measured external force
while the load is near the limit. Every period h [s]:

    e     = max(f_hat / f_max, max_i |tau_hat_i| / tau_max_i)    the reflex's load (1: it trips)
    F_hat = (J J^T + lambda^2 I)^-1 J tau_hat                    [N], J (3 x 7): the TCP's
                                                                 translational Jacobian at q
    u     = F_hat / |F_hat|                                      (0 where |F_hat| < 1 N)
    delta <- delta + h (k max(0, e - e_0) u - delta / T),  then |delta| <= delta_max   [m]
    q_c   <- q_c + J^T (J J^T + lambda^2 I)^-1 delta             [rad]

with e_0 = ``start``, k = ``gain`` [m/s], T = ``relax_time`` [s] and
delta_max = ``max_offset`` [m] (``scenario.ForceLimitConfig``), lambda =
0.01 m. tau_hat is the contact forces' generalized force on the arm, J^T F
for a force F on the hand, so u points away from what the hand presses on.
f_hat and tau_hat are the reflex monitor's own filtered values (the station's
``reflex_state``), in simulation and on the robot alike, so the limiter
reads the load the reflex judges. The orientation is left as commanded.
It acts after the rate limiter because a loop through differential IK and
the limiter (about 70 ms of lag) oscillated against the stiff joint
impedance at every gain fast enough to stop a 3 cm/s press; the offset is
integrated, so the commanded positions stay continuous.

Written here because Drake has no force-limiting (admittance) stage for a
joint impedance command; the math is :func:`force_limit_step`, numpy only.
"""

from __future__ import annotations

import numpy as np
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.framework import BasicVector, LeafSystem

from drake_skill.station.reflex import FILTERED_FORCE, FILTERED_TORQUE, REFLEX_STATE_SIZE

__all__ = ["ForceLimit", "force_limit_step", "load_fraction"]

N_JOINTS = 7
#: Damping lambda [m] of the force estimate's least squares (a near-singular arm gives no
#: spurious direction).
DAMPING = 0.01
#: Below this estimated force [N] the direction is not trusted and the hand only relaxes.
MIN_FORCE_N = 1.0
# Parameter layout: [start, gain, relax_time, max_offset, f_max, tau_max (7)].
_PARAM_SIZE = 5 + N_JOINTS


def load_fraction(reflex_state, f_max: float, tau_max) -> float:
    """e: the largest of f_hat / f_max and |tau_hat_i| / tau_max_i (the reflex trips above 1)."""
    x = np.asarray(reflex_state, dtype=float)
    tau = np.abs(x[FILTERED_TORQUE]) / np.asarray(tau_max, dtype=float)
    return float(max(x[FILTERED_FORCE] / float(f_max), tau.max()))


def force_limit_step(delta, reflex_state, J, params, h: float) -> np.ndarray:
    """One update of the module docstring's offset: delta (3) [m], ``reflex_state`` (the reflex
    monitor's [f_hat, tau_hat (7), ...]), J (3 x 7) the TCP's translational Jacobian, params
    [start, gain, relax_time, max_offset, f_max, tau_max (7)], h [s]. Returns the next delta."""
    start, gain, relax, max_offset, f_max = (float(v) for v in params[:5])
    x = np.asarray(reflex_state, dtype=float)
    excess = max(0.0, load_fraction(x, f_max, params[5:]) - start)
    J = np.asarray(J, dtype=float)
    force = np.linalg.solve(J @ J.T + DAMPING ** 2 * np.eye(3), J @ x[FILTERED_TORQUE])
    norm = float(np.linalg.norm(force))
    push = gain * excess * force / norm if norm >= MIN_FORCE_N else np.zeros(3)
    delta = np.asarray(delta, dtype=float)
    delta = delta + h * (push - delta / relax)
    length = float(np.linalg.norm(delta))
    return delta * (max_offset / length) if length > max_offset else delta


class ForceLimit(LeafSystem):
    """Inputs ``panda_state_desired`` [14] (the rate limiter's [q_c, v_c]), ``reflex_state`` [10]
    (the reflex monitor's ``filtered``) and ``robot_state`` [14] (the arm's [q, v]); output
    ``panda_state_commanded`` [14]: [q_c + J^+ delta, v_c], the module docstring's yielding command.

    ``plant``: the arm's kinematic model with the TCP frame ``ee`` (the end-effector
    controller's ``make_control_plant``); ``config``: ``ForceLimitConfig``; ``reflex``:
    ``ReflexConfig`` (its limits, 1 on the load scale); ``period`` h [s]. Per run: the offset
    delta [m] in discrete state (zero in a default context), the constants in a numeric
    parameter.
    """

    def __init__(self, plant, config, reflex, period: float):
        super().__init__()
        params = np.r_[config.start, config.gain, config.relax_time, config.max_offset,
                       reflex.contact_force_max, np.asarray(reflex.external_torque_max, dtype=float)]
        if params.shape != (_PARAM_SIZE,):
            raise ValueError(f"reflex.external_torque_max: expected {N_JOINTS} values, got {params.size - 5}")
        self._plant, self._h = plant, float(period)
        self._ee = plant.GetFrameByName("ee")
        # Scratch memory for the Jacobian, not run state: every update writes q first.
        self._kinematics = plant.CreateDefaultContext()
        self._params = self.DeclareNumericParameter(BasicVector(params))
        self._desired = self.DeclareVectorInputPort("panda_state_desired", 2 * N_JOINTS)
        self._reflex = self.DeclareVectorInputPort("reflex_state", REFLEX_STATE_SIZE)
        self._robot = self.DeclareVectorInputPort("robot_state", 2 * N_JOINTS)
        # [delta (3) [m], J^+ delta (7) [rad]]: the joint offset kept from the update that made it.
        self._state = self.DeclareDiscreteState(3 + N_JOINTS)
        self.DeclarePeriodicDiscreteUpdateEvent(self._h, 0.0, self._update)
        self.DeclareVectorOutputPort("panda_state_commanded", 2 * N_JOINTS, self._calc,
                                     {self._desired.ticket(), self.xd_ticket()})

    def jacobian(self, q) -> np.ndarray:
        """J (3 x 7): the TCP's translational velocity in the world per joint velocity, at q."""
        self._plant.SetPositions(self._kinematics, np.asarray(q, dtype=float))
        world = self._plant.world_frame()
        return self._plant.CalcJacobianTranslationalVelocity(
            self._kinematics, JacobianWrtVariable.kV, self._ee, np.zeros(3), world, world)

    def offset(self, context) -> np.ndarray:
        """delta [m]: how far the command moves the hand from the desired pose now."""
        return context.get_discrete_state(self._state).get_value()[:3].copy()

    def _update(self, context, discrete_state):
        J = self.jacobian(self._robot.Eval(context)[:N_JOINTS])
        params = context.get_numeric_parameter(self._params).get_value()
        delta = force_limit_step(self.offset(context), self._reflex.Eval(context), J, params, self._h)
        dq = J.T @ np.linalg.solve(J @ J.T + DAMPING ** 2 * np.eye(3), delta)
        discrete_state.set_value(self._state, np.r_[delta, dq])

    def _calc(self, context, output):
        x = self._desired.Eval(context).copy()
        x[:N_JOINTS] += context.get_discrete_state(self._state).get_value()[3:]
        output.SetFromVector(x)
