"""The end-effector controller: hand pose in, rate-limited joint commands out.

Drake's ``DifferentialInverseKinematicsIntegrator`` solves, every period, the
QP of differential IK (min ||J v - V_WE_desired||, subject to joint position
and velocity limits) and integrates the joint velocities. A
:class:`RateLimiter` then turns those joint positions into the commanded
state [q_c, v_c] that the Panda's joint impedance tracks, with the joint
velocity, acceleration and jerk bounded by Franka's published limits
(``drake_skill.station.limits``), as ``libfranka``'s own rate limiter bounds
every command the robot accepts. The same class limits the finger speed.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from pydrake.math import RigidTransform
from pydrake.multibody.inverse_kinematics import (
    DifferentialInverseKinematicsIntegrator,
    DifferentialInverseKinematicsParameters,
)
from pydrake.multibody.parsing import ModelDirectives, Parser, ProcessModelDirectives
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import FixedOffsetFrame
from pydrake.systems.framework import BasicVector, Diagram, DiagramBuilder, LeafSystem

from drake_skill.station import limits
from drake_skill.station.models import add_package_paths, hand_mount, instance_directives, robot_directives
from drake_skill.station.scenario import ControllerConfig

# Hand frame H is the flange turned -45 degrees about z (Franka Hand mounting; the
# robot's directives, models/panda_robot.dmd.yaml, say so once and X_FLANGE_HAND reads it);
# the tool centre point E (the "hand pose" everywhere in drake-skill) is
# 0.1034 m along z_H, between the fingertips.
X_FLANGE_HAND = hand_mount()
X_HAND_TCP = RigidTransform([0.0, 0.0, 0.1034])

# Kept for callers of the previous name; the one definition is limits.QD_MAX.
PANDA_QD_MAX = limits.QD_MAX
#: The fingers' acceleration bound used by the finger rate limiter [m/s^2]
#: (not published by Franka; it only shapes the start and stop of a finger move).
FINGER_ACCEL_MAX = 4.0


def add_scenario_instances(plant: MultibodyPlant, instances, directives=None) -> list:
    """Adds the model instances ``instances`` of ``directives`` (a scenario's; default the robot's
    own, ``station.models.ROBOT_FILE``) to an unfinalised ``plant``, with their welds; returns them.
    Drake's ``MakeMultibodyPlant(scenario, model_instance_names)`` in the ``manipulation``
    repository: the auxiliary plants (gravity compensation, the controller's kinematics, the
    hardware station's drawing) come from the station's own scenario, so a changed mount cannot
    drift between them."""
    parser = Parser(plant)
    add_package_paths(parser.package_map())
    kept = robot_directives(instances) if directives is None else instance_directives(directives, instances)
    ProcessModelDirectives(ModelDirectives(directives=kept), plant, parser)
    return [plant.GetModelInstanceByName(name) for name in instances]


def add_arm_and_hand(plant: MultibodyPlant, directives=None) -> tuple:
    """Adds the Panda arm (base welded to the world) and its hand (welded to the flange) of
    ``directives`` (a scenario's; default the robot's own) to an unfinalised ``plant``; returns
    the two model instances."""
    arm, hand = add_scenario_instances(plant, ("panda", "panda_hand"), directives)
    return arm, hand


def make_control_plant(directives=None) -> MultibodyPlant:
    """A 7-DoF kinematic model of the arm (``panda`` of ``directives``, a scenario's; default the
    robot's own) with the TCP frame named ``ee``: the hand's mount (the scenario's weld) then
    ``X_HAND_TCP``."""
    plant = MultibodyPlant(time_step=0.0)
    add_scenario_instances(plant, ("panda",), directives)
    X_8H = X_FLANGE_HAND if directives is None else hand_mount(directives)
    plant.AddFrame(FixedOffsetFrame("ee", plant.GetFrameByName("panda_link8"), X_8H @ X_HAND_TCP))
    plant.Finalize()
    return plant


class LimiterConstants(NamedTuple):
    """The per-limiter constants of :func:`limiter_step`: period h [s], w^2, 2 w,
    h / max(reference_period, h), and per joint j_max h, a_max, v_max."""

    h: float
    w2: float
    two_w: float
    gain_ref: float
    jh: list
    a_max: list
    v_max: list


def limiter_step(x: list, r: list, c: LimiterConstants) -> list:
    """One step of :class:`RateLimiter` (its docstring's equations) on Python floats.

    x: the state [q_c (n), v_c (n), a (n), r_prev (n), r_dot (n)]; r: the
    (clipped) reference (n). Returns the next state, same layout.

    Every element goes through the same IEEE operations in the same order as
    the vector form (numpy's elementwise ``+ - * /``, ``abs``, ``max``, and
    ``np.maximum(a, b)`` = ``a if a >= b else b`` for numbers), so the result
    is the same floats; written element by element because at 1 kHz and
    n <= 7 numpy's per-call overhead is most of the cost.
    """
    n = len(r)
    h, w2, two_w, g = c.h, c.w2, c.two_w, c.gain_ref
    r_dot, a, da = [], [], []
    jerk = over = 0.0
    for i in range(n):
        qi, vi, pi, di = x[i], x[n + i], x[2 * n + i], x[4 * n + i]
        ri = r[i]
        di = di + g * ((ri - x[3 * n + i]) / h - di)
        ai = w2 * (ri - qi) + two_w * (di - vi)
        r_dot.append(di)
        a.append(ai)
        da.append(ai - pi)
        jerk = max(jerk, abs(ai - pi) / c.jh[i])
    # Scale, not clip per joint: the commanded joint motion keeps the IK's
    # direction (near a singularity the IK moves joints in cancelling pairs,
    # e.g. joints 1 and 3; clipping them differently moves the hand).
    if jerk > 1.0:
        a = [x[2 * n + i] + da[i] / jerk for i in range(n)]
    for i in range(n):
        over = max(over, abs(a[i]) / c.a_max[i])
    if over > 1.0:
        a = [ai / over for ai in a]
    q_new, v_new = [], []
    for i in range(n):
        vi, vm = x[n + i], c.v_max[i]
        lo, hi = (-vm - vi) / h, (vm - vi) / h
        ai = a[i]
        ai = ai if ai >= lo else lo
        ai = ai if ai <= hi else hi
        a[i] = ai
        vi = vi + ai * h
        v_new.append(vi)
        q_new.append(x[i] + vi * h)
    return q_new + v_new + a + r + r_dot


class RateLimiter(LeafSystem):
    """Tracks a position reference with bounded velocity, acceleration and jerk.

    Input ``reference`` (n): target positions r (held between updates, e.g. the
    IK's 100 Hz output). Output ``state`` (2n): the commanded [q_c, v_c].
    Every ``period`` h, with r_dot a first-order estimate of the reference's
    velocity (time constant ``reference_period``),

        a* = w^2 (r - q_c) + 2 w (r_dot - v_c)          (critically damped, w = bandwidth)
        a  = a_prev + (a* - a_prev) / max(1, max_i |a*_i - a_prev_i| / (j_max_i h)),
        a  = a / max(1, max_i |a_i| / a_max_i),
        a  = clip(a, (-v_max - v_c) / h, (v_max - v_c) / h),
        v_c <- v_c + a h,  q_c <- q_c + v_c h.

    The first two steps scale the whole vector (the joint motion keeps its
    direction); |v_c| <= v_max and |a| <= a_max hold exactly, the jerk bound
    yields only where the acceleration or velocity bound cuts in. State (discrete, per run): [q_c,
    v_c, a, r_prev, r_dot]. ``reference_scale`` multiplies the reference (a
    finger opening -> each finger's position) and ``lower``/``upper`` clip it.

    ``update_period`` (default ``period``) is how often the system's discrete
    update runs: an integer number k of periods, each update taking the k
    steps above in turn with the reference read at the update. In a station
    whose plant reads the command every k periods (``update_period`` = the
    plant's step), the plant sees the state of every k-th step as before,
    with one Python callback (and one simulator step) per plant step instead
    of k; the reference is then held for the k steps, which differs from
    reading it every period only in the steps after a change of the
    reference inside an update (differential IK's output, every 10 ms: a
    1 ms delay at a 2 ms plant step; ``tools/check_physics.py`` checks it).

    ``initial`` (n, default zeros): the positions the limiter rests at in a
    default context, so that ``SetDefaultContext`` starts a run at home.
    """

    def __init__(self, n: int, period: float, bandwidth: float, v_max, a_max, j_max,
                 reference_period: float, reference_scale: float = 1.0, lower=None, upper=None,
                 update_period: float | None = None, initial=None):
        super().__init__()
        self._n, h, w = int(n), float(period), float(bandwidth)
        update = h if update_period is None else float(update_period)
        self._substeps = int(round(update / h))
        if self._substeps < 1 or abs(self._substeps * h - update) > 1e-9 * update:
            raise ValueError(f"RateLimiter: update_period = {update} s must be a whole number of "
                             f"periods ({h} s); set controller.limiter_period to divide the plant's time_step")

        def per_joint(value) -> list:
            return np.broadcast_to(np.asarray(value, dtype=float), (self._n,)).tolist()

        # The docstring's constants, folded once to the same floats its
        # expressions give: w^2, 2 w, j_max h, h / max(reference_period, h).
        self._consts = LimiterConstants(h, w * w, 2.0 * w, h / max(float(reference_period), h),
                                        [j * h for j in per_joint(j_max)], per_joint(a_max), per_joint(v_max))
        self._scale = float(reference_scale)
        self._lower = None if lower is None else per_joint(lower)
        self._upper = None if upper is None else per_joint(upper)
        self._ref = self.DeclareVectorInputPort("reference", n)
        self._x = self.DeclareDiscreteState(self._rest(np.zeros(n) if initial is None else initial))
        self.DeclarePeriodicDiscreteUpdateEvent(self._substeps * h, 0.0, self._update)
        self.DeclareVectorOutputPort("state", 2 * n, self._calc_state, {self.xd_ticket()})
        self.DeclareVectorOutputPort("acceleration", n, self._calc_accel, {self.xd_ticket()})

    def _rest(self, q) -> np.ndarray:
        """The state [q_c, v_c, a, r_prev, r_dot] at rest at positions q: [q, 0, 0, q, 0]."""
        n = self._n
        q = np.broadcast_to(np.asarray(q, dtype=float), (n,))
        x = np.zeros(5 * n)
        x[:n] = q
        x[3 * n:4 * n] = q
        return x

    def set_position(self, context, q) -> None:
        """Starts the limiter at rest at positions q."""
        context.get_mutable_discrete_state(self._x).SetFromVector(self._rest(q))

    def _update(self, context, discrete_state):
        # This runs at 1 kHz in Python for n <= 7: on Python floats it costs a
        # fraction of the numpy version (whose per-call overhead dominates at
        # this size) and gives the same floats (limiter_step's docstring).
        x = context.get_discrete_state(self._x).value().tolist()
        r = (self._scale * self._ref.Eval(context)).tolist()
        if self._lower is not None:
            r = [lo if ri < lo else ri for ri, lo in zip(r, self._lower)]   # np.maximum(r, lower)
            r = [hi if ri > hi else ri for ri, hi in zip(r, self._upper)]   # np.minimum(r, upper)
        for _ in range(self._substeps):
            x = limiter_step(x, r, self._consts)
        discrete_state.set_value(self._x, x)

    def _calc_state(self, context, output: BasicVector):
        x = context.get_discrete_state(self._x).value()
        output.SetFromVector(x[:2 * self._n])

    def _calc_accel(self, context, output: BasicVector):
        x = context.get_discrete_state(self._x).value()
        output.SetFromVector(x[2 * self._n:3 * self._n])


def make_finger_limiter(config: ControllerConfig, update_period: float | None = None,
                        opening: float = 0.0) -> RateLimiter:
    """Opening w [m] in -> both fingers' commanded [q, q, v, v] out, each at w / 2
    within its travel, at most ``limits.FINGER_SPEED_MAX``; ``update_period`` as
    :class:`RateLimiter`'s; at rest at ``opening`` [m] in a default context."""
    return _FingerLimiter(config, update_period, opening)


def _half_opening(opening: float) -> float:
    return float(np.clip(opening / 2, 0.0, limits.FINGER_MAX))


class _FingerLimiter(Diagram):
    def __init__(self, config: ControllerConfig, update_period: float | None = None, opening: float = 0.0):
        super().__init__()
        from pydrake.systems.primitives import MatrixGain

        builder = DiagramBuilder()
        split = builder.AddNamedSystem("split", MatrixGain(np.array([[1.0], [1.0]])))
        limiter = builder.AddNamedSystem("limiter", RateLimiter(
            2, config.limiter_period, config.limiter_bandwidth, limits.FINGER_SPEED_MAX,
            FINGER_ACCEL_MAX, 100.0 * FINGER_ACCEL_MAX, config.diff_ik_period, reference_scale=0.5,
            lower=0.0, upper=limits.FINGER_MAX, update_period=update_period, initial=_half_opening(opening)))
        builder.Connect(split.get_output_port(), limiter.get_input_port())
        builder.ExportInput(split.get_input_port(), "opening")
        builder.ExportOutput(limiter.GetOutputPort("state"), "finger_state_desired")
        builder.BuildInto(self)
        self.limiter = limiter

    def set_opening(self, context, opening: float) -> None:
        half = _half_opening(opening)
        self.limiter.set_position(self.limiter.GetMyMutableContextFromRoot(context), [half, half])


class EndEffectorController(Diagram):
    """Input ``X_WE_desired`` (RigidTransform), outputs ``panda_state_desired`` (14)
    and ``joint_acceleration_commanded`` (7, rad/s^2).

    Joint limits are Franka's, shrunk by a 0.05 rad margin; IK's velocity
    limits are Franka's scaled by ``config.velocity_scale``; the hand's
    translational speed is limited to ``config.ee_speed_max`` m/s; the
    commanded joint motion passes the :class:`RateLimiter` at Franka's
    velocity, acceleration and jerk limits (updated every ``update_period``,
    see :class:`RateLimiter`). The arm's kinematics are those of ``directives``
    (the scenario's; :func:`make_control_plant`).

    A default context starts the rate limiter at rest at ``q_home``; the IK's
    integrator starts, at ``Initialize``, at the positions of the optional input
    ``robot_state`` (14: the arm's [q, v]) when it is connected, else call
    :meth:`set_joint_positions`.

    With ``config.force_limit.enabled`` (and ``reflex``, the scenario's ``ReflexConfig``), a
    :class:`~drake_skill.station.force_limit.ForceLimit` after the rate limiter moves the
    commanded joint positions so that the hand yields along the measured external force near
    the reflex's limits (updated every ``update_period``, default the limiter's). It adds the
    input ``reflex_state`` (the reflex monitor's ``filtered``) and reads ``robot_state``,
    which must then be connected.
    """

    def __init__(self, config: ControllerConfig, q_home, update_period: float | None = None, directives=None,
                 reflex=None):
        super().__init__()
        builder = DiagramBuilder()
        self.control_plant = make_control_plant(directives)
        plant = self.control_plant
        q_home = np.asarray(q_home, dtype=float)
        # The integrator's default state is the positions in this context.
        plant.SetDefaultPositions(q_home)
        context = plant.CreateDefaultContext()

        params = DifferentialInverseKinematicsParameters(plant.num_positions(), plant.num_velocities())
        params.set_time_step(config.diff_ik_period)
        margin = 0.05
        params.set_joint_position_limits((plant.GetPositionLowerLimits() + margin,
                                          plant.GetPositionUpperLimits() - margin))
        qd = limits.QD_MAX * config.velocity_scale
        params.set_joint_velocity_limits((-qd, qd))
        v = config.ee_speed_max
        params.set_end_effector_translational_velocity_limits([-v] * 3, [v] * 3)
        params.set_end_effector_angular_speed_limit(2.0)
        params.set_nominal_joint_position(q_home)
        params.set_joint_centering_gain(config.joint_centering_gain * np.eye(7))

        self._diff_ik = builder.AddNamedSystem("diff_ik", DifferentialInverseKinematicsIntegrator(
            plant, plant.world_frame(), plant.GetFrameByName("ee"), config.diff_ik_period, params, context, True))
        self._limiter = builder.AddNamedSystem("rate_limiter", RateLimiter(
            7, config.limiter_period, config.limiter_bandwidth, limits.QD_MAX, limits.QDD_MAX,
            limits.QDDD_MAX, config.diff_ik_period, update_period=update_period, initial=q_home))
        builder.Connect(self._diff_ik.GetOutputPort("joint_positions"), self._limiter.get_input_port())
        builder.ExportInput(self._diff_ik.GetInputPort("X_AE_desired"), "X_WE_desired")
        # Optional: the arm's measured state [q, v] (14); connected, Drake's integrator starts at
        # its q in an initialization event (it still integrates open loop afterwards).
        builder.ExportInput(self._diff_ik.GetInputPort("robot_state"), "robot_state")
        self.force_limit = None
        state = self._limiter.GetOutputPort("state")
        if config.force_limit.enabled:
            from drake_skill.station.force_limit import ForceLimit
            if reflex is None:
                raise ValueError("controller.force_limit.enabled needs the scenario's reflex limits "
                                 "(EndEffectorController(..., reflex=scenario.reflex))")
            self.force_limit = builder.AddNamedSystem("force_limit", ForceLimit(
                plant, config.force_limit, reflex, update_period or config.limiter_period))
            builder.Connect(state, self.force_limit.GetInputPort("panda_state_desired"))
            builder.ExportInput(self.force_limit.GetInputPort("reflex_state"), "reflex_state")
            builder.ConnectInput("robot_state", self.force_limit.GetInputPort("robot_state"))
            state = self.force_limit.GetOutputPort("panda_state_commanded")
        builder.ExportOutput(state, "panda_state_desired")
        builder.ExportOutput(self._limiter.GetOutputPort("acceleration"), "joint_acceleration_commanded")
        builder.BuildInto(self)
        self._q_home = q_home

    def set_joint_positions(self, context, q) -> None:
        """Resets the integrator and the rate limiter (at rest) to joint positions q."""
        q = np.asarray(q, dtype=float)
        self._diff_ik.SetPositions(self._diff_ik.GetMyMutableContextFromRoot(context), q)
        self._limiter.set_position(self._limiter.GetMyMutableContextFromRoot(context), q)
