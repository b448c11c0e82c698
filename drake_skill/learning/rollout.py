"""The rollout runner: one diagram per skill, built once, reset for every rollout.

The diagram (docs/architecture.md, "One diagram per skill execution")::

    [ObjectPoseSource] --X_WO--> [DmpSystem] --X_WE_desired--> [Station (EndEffectorController inside)]
                    gripper_opening (the skill's) --> [Station]
    [Station] --point_cloud--> [ObjectSegmenter] --> [PcaeFeaturizer] --> [PomrpReward]

built by :class:`RolloutRunner` from a fitted :class:`~drake_skill.fitted_skill.Skill`
(the goal pipeline through :func:`drake_skill.reward.systems.add_goal_pipeline`).
Each :meth:`RolloutRunner.run` (docs/architecture.md, "The outer loop"):

1. resets the one context to its defaults (time 0);
2. places the object at the pose drawn from the rollout's ``seed``;
3. takes the object frame O from the segmenter's estimate on the camera's
   first frame (``object_pose="perceived"``, docs/method.md section 2) or the
   simulator's ground truth (``"ground_truth"``) and writes it into
   ``ObjectPoseSource``'s abstract parameter;
4. writes the sampled weights ``W: (B, 7)`` into the DMP's numeric parameter,
   its start ``y0`` = the hand's measured pose in O;
5. simulates the skill's duration ``tau`` plus ``settle_time`` seconds;
6. reads the learned reward (docs/method.md section 4): the smoothed per-step
   rewards ``h(G, t)`` (thesis Eq. 4.4), the dense return ``R(G)`` (Eq. 4.5),
   the filtered per-step rewards (for the per-step methods) and the goal
   model's verdict, and the ground truth (final object state, success).

Everything per run lives in the context (parameters and state of the
systems), so a rollout's numbers depend only on ``(weights, seed)``: not on
the rollouts run before it, nor on the process that runs it.

A rollout that raises, diverges, fails to converge (SAP), triggers the
station's reflex, does not see the object or gives non-finite values returns
a :class:`RolloutResult` with ``failed=True``, its ``reason``
(:data:`FAILURE_REASONS`) and zero reward (docs/method.md section 5); the
caller goes on.

    runner = RolloutRunner(skill)                       # Skill.load("skills/open")
    result = runner.run(skill.initial_weights, seed=4)
    result.dense_return, result.verdict, result.success
"""

from __future__ import annotations

import dataclasses as dc
import logging
import math
import time
from typing import Any

import numpy as np
from pydrake.common.value import AbstractValue, Value
from pydrake.math import RigidTransform
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem
from pydrake.systems.primitives import ConstantVectorSource

from drake_skill.common import IkWarningCounter
from drake_skill.action.dmp import Dmp, DmpConfig, default_times, integrate
from drake_skill.action.systems import DmpSystem
from drake_skill.station.make import make_station
from drake_skill.station.sim.builder import Station
from drake_skill.station.scenario import Scenario
from drake_skill.station.frames import add_camera_frames
from drake_skill.station.loggers import StationLoggers
from drake_skill.station.recording import advance_station, pose_to_vector, vector_to_pose
from drake_skill.station.success import judge_run

__all__ = ["FAILURE_REASONS", "ActionModel", "ObjectPoseSource", "RolloutConfig", "RolloutResult",
           "RolloutRunner", "classify_failure"]

#: Why a rollout failed: simulation diverged; the SAP contact solver did not
#: converge; the station's reflex stopped the arm (excessive contact force);
#: the segmenter did not see the object on the first frame; a non-finite
#: value (trajectory, goal data, return); the DMP path leaves the workspace
#: (checked before simulating); the robot's status stopped arriving (the
#: hardware station); any other exception.
FAILURE_REASONS = ("diverged", "solver", "reflex", "perception", "non_finite", "workspace", "stale_status", "error")


class _PerceptionError(RuntimeError):
    """The segmenter did not see the object at the start of the rollout."""

    reason = "perception"


class _NonFiniteError(RuntimeError):
    """A trajectory, goal frame or return is not finite."""

    reason = "non_finite"


class _WorkspaceError(RuntimeError):
    """The DMP path goes farther from the object than ``workspace_radius``."""

    reason = "workspace"


def classify_failure(error: BaseException) -> str:
    """The :data:`FAILURE_REASONS` entry for an exception raised by a rollout: its typed ``reason``.

    The station's failures carry their reason (``ReflexError.reason`` =
    "reflex", ``SolverError`` "solver", ``DivergedError`` "diverged",
    ``StaleStatusError`` "stale_status"), as do this module's; anything else
    is "error". Nothing is read from a message's text (Drake's untyped
    solver failure becomes a ``SolverError`` where it is raised,
    ``station.recording.advance_station``).
    """
    reason = getattr(error, "reason", None)
    return reason if isinstance(reason, str) and reason in FAILURE_REASONS else "error"


@dc.dataclass
class RolloutConfig:
    """How :class:`RolloutRunner` executes a rollout (loadable with ``yaml_load_typed``).

    object_pose: "perceived" (the segmenter's X_WO on the camera's first
      frame, docs/method.md section 2) or "ground_truth" (the simulator's).
    settle_time: simulated time after the DMP's duration tau [s]: the hand
      holds its last pose, the object comes to rest, and the reward sees the
      final frames (it lags the camera by one frame). Negative: the station's
      ``success.settle_time`` (the settle phase its success judge reads).
    record_hz: rate of the recorded hand path and object state [Hz].
    goal_model: build the goal pipeline (segmenter -> PCAE -> POMRP reward);
      needs the station's camera. Off, rewards are zero (ground-truth
      success only, e.g. for plain imitation checks without a camera).
    workspace_radius: a rollout whose DMP path (hand positions in the object
      frame) goes farther than this from the object's origin fails with
      reason "workspace" before it is simulated [m]. The Panda reaches
      0.855 m; a path metres away is a runaway sample, and commanding it
      would overflow differential IK's program.
    """

    object_pose: str = "perceived"
    settle_time: float = -1.0
    record_hz: float = 10.0
    goal_model: bool = True
    workspace_radius: float = 3.0

    def validate(self) -> "RolloutConfig":
        """Raises ValueError naming the field that cannot work; returns self."""
        if self.object_pose not in ("perceived", "ground_truth"):
            raise ValueError(f"rollout config field 'object_pose' = {self.object_pose!r}: "
                             "expected 'perceived' or 'ground_truth'")
        if not math.isfinite(self.settle_time):
            raise ValueError(f"rollout config field 'settle_time' = {self.settle_time!r}: expected a "
                             "duration >= 0 s, or < 0 for the station's success.settle_time")
        if not (math.isfinite(self.workspace_radius) and self.workspace_radius > 0):
            raise ValueError(f"rollout config field 'workspace_radius' = {self.workspace_radius!r}: "
                             "expected > 0 m")
        if not (math.isfinite(self.record_hz) and self.record_hz > 0):
            raise ValueError(f"rollout config field 'record_hz' = {self.record_hz!r}: expected > 0 Hz")
        return self


@dc.dataclass
class ActionModel:
    """A skill without a goal model: name, DMP, DMP hyper-parameters, finger opening [m].

    Stands in for a :class:`~drake_skill.fitted_skill.Skill` where only the action
    model matters (ground-truth success of an imitation, no learned reward).
    """

    name: str
    initial_dmp: Dmp
    dmp_config: DmpConfig
    gripper_opening: float = 0.0


@dc.dataclass
class RolloutResult:
    """One execution. Plain numbers and arrays (it crosses process boundaries).

    seed: the object-pose seed; failed / reason / message: see
    :data:`FAILURE_REASONS` (reason and message empty when it did not fail).
    dense_return: R(G) of thesis Eq. 4.5 (0 when failed or without a goal model).
    rewards: (T,) smoothed per-step rewards h(G, t) (Eq. 4.4), one per valid
      camera frame; filtered_rewards: (T,) the same from the filtered
      posterior P(s_t | g_1..g_t) (for the per-step methods).
    verdict: the goal model's success verdict (the sparse reward).
    success: ground-truth success of the final object state (simulation only).
    final_object_state: lid angle [rad] or drawer travel [m] at the end.
    times (N,) [s]; ee_pose (N, 7): the hand path X_WE (world xyz m + wxyz);
    object_state (N,): at ``record_hz``.
    object_pose / object_pose_true: (7,) X_WO used for the DMP frame / the
      ground truth (xyz + wxyz).
    wall_s: wall-clock time of the rollout [s]; ik_warnings: count of
    differential IK's "no solution"/"stuck" warnings during it.
    contact: a reflex trip's ``{"pairs": [[robot body, other body, force_N], ...],
    "point": [x, y, z], "t": s, "cause": "force" | "torque joint i"}`` (the contacts at
    the stop; pairs and point None on the robot); None otherwise.
    weights: (B, 7) the DMP weights executed (what a replay re-simulates with ``seed``).
    joints (N, 7) arm joint positions [rad] at ``times``: a rollout that failed keeps
      these, ``times``, ``ee_pose`` and ``object_state`` up to its stop.
    frame_times (K,) [s], frames (K, h, w, 3) uint8: the perception camera's image once a
      second (:mod:`drake_skill.station.frames`), up to the stop; last_frame (h, w, 3): the
      image at the end or the stop (empty where the runner renders nothing: no goal model and
      the ground-truth object pose).
    """

    seed: int
    failed: bool = False
    reason: str = ""
    message: str = ""
    dense_return: float = 0.0
    rewards: np.ndarray = dc.field(default_factory=lambda: np.zeros(0))
    filtered_rewards: np.ndarray = dc.field(default_factory=lambda: np.zeros(0))
    verdict: bool = False
    success: bool = False
    final_object_state: float = float("nan")
    times: np.ndarray = dc.field(default_factory=lambda: np.zeros(0))
    ee_pose: np.ndarray = dc.field(default_factory=lambda: np.zeros((0, 7)))
    object_state: np.ndarray = dc.field(default_factory=lambda: np.zeros(0))
    object_pose: np.ndarray = dc.field(default_factory=lambda: np.full(7, np.nan))
    object_pose_true: np.ndarray = dc.field(default_factory=lambda: np.full(7, np.nan))
    wall_s: float = 0.0
    ik_warnings: int = 0
    contact: dict | None = None
    weights: np.ndarray = dc.field(default_factory=lambda: np.zeros((0, 7)))
    joints: np.ndarray = dc.field(default_factory=lambda: np.zeros((0, 7)))
    frame_times: np.ndarray = dc.field(default_factory=lambda: np.zeros(0))
    frames: np.ndarray = dc.field(default_factory=lambda: np.zeros((0, 0, 0, 3), dtype=np.uint8))
    last_frame: np.ndarray = dc.field(default_factory=lambda: np.zeros((0, 0, 3), dtype=np.uint8))

    @property
    def X_WO(self) -> RigidTransform:
        """The object pose the DMP's frame was mapped with."""
        return vector_to_pose(self.object_pose)

    @property
    def X_WO_true(self) -> RigidTransform:
        """The simulator's object pose."""
        return vector_to_pose(self.object_pose_true)

    def summary(self) -> dict[str, Any]:
        """JSON-able scalars of the result (no trajectories)."""
        final = self.final_object_state
        return {"seed": int(self.seed), "failed": bool(self.failed), "reason": self.reason,
                "message": self.message, "dense_return": float(self.dense_return),
                "verdict": bool(self.verdict), "success": bool(self.success),
                "final_object_state": None if not math.isfinite(final) else float(final),
                "n_frames": int(len(self.rewards)), "wall_s": round(float(self.wall_s), 3),
                "ik_warnings": int(self.ik_warnings),
                "object_pose": [float(v) for v in self.object_pose]} | (
                    {"contact": self.contact} if self.contact is not None else {})

    def equal_numbers(self, other: "RolloutResult") -> bool:
        """Same numbers in every field but ``wall_s`` (arrays compared exactly, NaN equal to NaN)."""
        for field in dc.fields(self):
            if field.name == "wall_s":
                continue
            a, b = getattr(self, field.name), getattr(other, field.name)
            if isinstance(a, np.ndarray):
                if not np.array_equal(a, b, equal_nan=True):
                    return False
            elif isinstance(a, float) and math.isnan(a):
                if not (isinstance(b, float) and math.isnan(b)):
                    return False
            elif a != b:
                return False
        return True


class ObjectPoseSource(LeafSystem):
    """Outputs ``X_WO``: a RigidTransform held in an abstract parameter (written at reset)."""

    def __init__(self):
        super().__init__()
        self._index = self.DeclareAbstractParameter(AbstractValue.Make(RigidTransform()))
        self.DeclareAbstractOutputPort("X_WO", lambda: Value(RigidTransform()), self._calc,
                                       {self.all_parameters_ticket()})

    def set_pose(self, context, X_WO: RigidTransform) -> None:
        context.get_mutable_abstract_parameter(self._index).set_value(X_WO)

    def get_pose(self, context) -> RigidTransform:
        return context.get_abstract_parameter(self._index).get_value()

    def _calc(self, context, output):
        output.set_value(context.get_abstract_parameter(self._index).get_value())


class RolloutRunner:
    """One diagram (station + object pose + DMP + goal pipeline) reused for every rollout.

    Args:
        skill: a fitted :class:`~drake_skill.fitted_skill.Skill` (action and goal
            model), or an :class:`ActionModel` (no learned reward; then
            ``config.goal_model`` must be off).
        station_config: the scenario (default: the skill's, ``Skill.station_config()``).
        config: :class:`RolloutConfig`.
        meshcat: a ``pydrake.geometry.Meshcat`` to draw the station in (or None).
        station: a built station with the simulated station's ports to use
            instead of ``make_station(station_config)``, e.g. the hardware
            station (``drake_skill.station.hardware.station``); its ``realtime``
            attribute, when true, paces the simulator at real time.
        dmp: the DMP whose goal g and duration tau every rollout executes
            (default the skill's initial DMP, the one policy search starts
            from; ``run`` sets only the weights). Plain imitation of another
            demonstration passes that demonstration's DMP: its weights are
            fitted to its own goal and duration.
    """

    def __init__(self, skill, station_config: Scenario | None = None,
                 config: RolloutConfig | None = None, meshcat=None, station=None, dmp: Dmp | None = None):
        self.skill = skill
        self.dmp = skill.initial_dmp if dmp is None else dmp
        if self.dmp.weights.shape != skill.initial_dmp.weights.shape:
            raise ValueError(f"dmp: weights of shape {self.dmp.weights.shape}, the skill's DMPs have "
                             f"{skill.initial_dmp.weights.shape}")
        self.rollout_config = (config or RolloutConfig()).validate()
        if station is not None:
            station_config = station.config
        station_config = station_config if station_config is not None else skill.station_config()
        dmp_config = skill.dmp_config if isinstance(skill, ActionModel) else skill.config.dmp
        if self.rollout_config.goal_model and isinstance(skill, ActionModel):
            raise ValueError("RolloutConfig.goal_model = true needs a fitted Skill (with a goal model), "
                             "not an ActionModel; set goal_model = false")
        needs_camera = self.rollout_config.goal_model or self.rollout_config.object_pose == "perceived"
        if needs_camera and not station_config.enable_camera:
            raise ValueError("object_pose = 'perceived' and goal_model = true need the station's camera: "
                             "set station_config.enable_camera = true (or object_pose = 'ground_truth' "
                             "and goal_model = false)")
        self.meshcat = meshcat
        builder = DiagramBuilder()
        self.station: Station = builder.AddNamedSystem(
            "station", station if station is not None else make_station(station_config, meshcat=meshcat))
        self.config = self.station.config
        self.pose_source = builder.AddNamedSystem("object_pose", ObjectPoseSource())
        self.dmp_system = builder.AddNamedSystem("dmp", DmpSystem(self.dmp, dmp_config))
        self.dmp_config = self.dmp_system.config
        # The skill's constant finger opening (docs/method.md section 2).
        gripper = builder.AddNamedSystem("gripper", ConstantVectorSource([float(skill.gripper_opening)]))
        builder.Connect(self.pose_source.GetOutputPort("X_WO"), self.dmp_system.get_X_WO_input_port())
        builder.Connect(self.dmp_system.get_X_WE_desired_output_port(),
                        self.station.GetInputPort("ee_pose_desired"))
        builder.Connect(gripper.get_output_port(), self.station.GetInputPort("gripper_command"))
        self.pipeline = None
        self.segmenter = None
        if self.rollout_config.goal_model:
            from drake_skill.reward.systems import add_goal_pipeline
            self.pipeline = add_goal_pipeline(builder, self.station, skill)
            self.segmenter = self.pipeline.segmenter
        elif self.rollout_config.object_pose == "perceived":
            from drake_skill.perception.systems import add_object_segmenter
            self.segmenter = add_object_segmenter(builder, self.station)
        self.loggers = StationLoggers(builder, self.station, self.rollout_config.record_hz)
        # Frames where the runner renders anyway (a runner on the ground truth renders nothing).
        self.frames = add_camera_frames(builder, self.station) if needs_camera else None
        self.diagram = builder.Build()
        self.context = self.diagram.CreateDefaultContext()
        self.simulator = Simulator(self.diagram, self.context)
        if self.station.realtime:
            self.simulator.set_target_realtime_rate(1.0)

    @property
    def skill_name(self) -> str:
        return self.skill.name

    @property
    def weights_shape(self) -> tuple[int, int]:
        return self.dmp.weights.shape

    def _sub(self, system):
        return system.GetMyMutableContextFromRoot(self.context)

    # ------------------------------------------------------------------ reset
    def perceive_object_pose(self) -> RigidTransform:
        """The segmenter's X_WO estimate from the camera frame of the current state."""
        if self.segmenter is None:
            raise ValueError("this runner does not perceive the object (object_pose = 'ground_truth' "
                             "and no goal model)")
        context = self._sub(self.segmenter)
        if self.segmenter.get_valid_output_port().Eval(context)[0] < 0.5:
            raise _PerceptionError("the segmenter does not see the object on the first camera frame")
        return self.segmenter.get_X_WO_output_port().Eval(context)

    def reset(self, weights, seed: int) -> RigidTransform:
        """Context to defaults at t = 0, object pose from ``seed``, object frame,
        ``weights`` (B, 7) and the start pose into the DMP. Returns the X_WO used.

        Raises ValueError for weights of the wrong shape or not finite.
        """
        dmp_context = self._sub(self.dmp_system)
        self.diagram.SetDefaultContext(self.context)
        self.context.SetTime(0.0)
        self.loggers.clear(self.context)      # before anything can fail: a failure reads what they hold
        self.dmp_system.set_weights(dmp_context, weights)
        X_WO_true = self.station.reset(self.context, seed)
        # The object frame from the first camera frame: the segmenter's outputs
        # are computed on evaluation from the current cloud, so no step is needed.
        use_perception = self.rollout_config.object_pose == "perceived"
        X_WO = self.perceive_object_pose() if use_perception else X_WO_true
        self.pose_source.set_pose(self._sub(self.pose_source), X_WO)
        X_WE = self.station.GetOutputPort("ee_pose").Eval(self.station.GetMyContextFromRoot(self.context))
        y0 = pose_to_vector(X_WO.inverse() @ X_WE)
        dmp = self.dmp_system.get_dmp(dmp_context)
        if np.dot(y0[3:], dmp.goal[3:]) < 0:   # same quaternion hemisphere as the goal
            y0[3:] *= -1
        self.dmp_system.set_start_goal(dmp_context, y0, dmp.goal)
        self.simulator.Initialize()           # latches X_WO into the DMP
        return X_WO

    @property
    def settle_time(self) -> float:
        """The settle phase [s] (RolloutConfig.settle_time, or the station's success.settle_time)."""
        if self.rollout_config.settle_time >= 0:
            return float(self.rollout_config.settle_time)
        return float(getattr(self.config.success, "settle_time", 1.0))

    def duration(self) -> float:
        """Simulated time of a rollout [s]: tau + settle time."""
        return self.dmp.tau + self.settle_time

    def _check_trajectory(self) -> None:
        dmp = self.dmp_system.get_dmp(self._sub(self.dmp_system))
        poses = integrate(dmp, self.dmp_config, default_times(dmp.tau, self.dmp_config.dt))
        if not np.all(np.isfinite(poses)):
            raise _NonFiniteError("the DMP trajectory of these weights is not finite")
        with np.errstate(over="ignore", invalid="ignore"):
            reach = float(np.max(np.linalg.norm(poses[:, :3], axis=1)))
        if reach > self.rollout_config.workspace_radius:
            raise _WorkspaceError(f"the DMP path goes {reach:.3g} m from the object (workspace_radius = "
                                  f"{self.rollout_config.workspace_radius} m)")

    # -------------------------------------------------------------------- run
    def run(self, weights, seed: int) -> RolloutResult:
        """One rollout of ``weights`` (B, 7) from the object pose drawn from ``seed``.

        Never raises for what the simulation does (see the module docstring);
        raises ValueError for weights of the wrong shape or containing NaN/inf.
        """
        weights = np.asarray(weights, dtype=float)
        if weights.shape != self.weights_shape:
            raise ValueError(f"weights: expected shape {self.weights_shape} (B, 7), got {weights.shape}")
        if not np.all(np.isfinite(weights)):
            raise ValueError("weights: contain NaN or inf")
        seed = int(seed)
        counter = IkWarningCounter()
        logger = logging.getLogger("drake")
        logger.filters.insert(0, counter)   # ahead of filters that drop the records
        start = time.perf_counter()
        result = RolloutResult(seed=seed)
        try:
            self._run(weights, result)
        except Exception as error:   # recorded, the run goes on (docs/method.md section 5)
            reason = classify_failure(error)
            result = RolloutResult(seed=seed, failed=True, reason=reason,
                                   message=f"{type(error).__name__}: {error}"[:500],
                                   object_pose=result.object_pose, object_pose_true=result.object_pose_true,
                                   contact=self._contact(error) if reason == "reflex" else None)
            self._keep_until_stop(result)
        finally:
            logger.removeFilter(counter)
        result.wall_s = time.perf_counter() - start
        result.ik_warnings = counter.count
        result.weights = weights.copy()
        return result

    def _samples(self) -> int:
        """n: the run's samples are on the grid k / record_hz, k = 0..n, n / record_hz >= duration."""
        return int(np.ceil(self.duration() * self.rollout_config.record_hz - 1e-9))

    def _records(self):
        """The loggers' samples on the ``record_hz`` grid up to where the run got."""
        return self.loggers.read(self.context, self._samples())

    def _keep_until_stop(self, result: RolloutResult) -> None:
        """A failed rollout's path, joints, object state and frames up to the stop (none where it
        failed before simulating: the loggers were cleared at its reset)."""
        try:
            records = self._records()
            result.times, result.ee_pose, result.object_state = records.times, records.ee_pose, records.object_state
            result.joints = records.state[:, :7]
            self._keep_frames(result)
        except Exception:   # what is kept describes a failure; it never turns it into another one
            pass

    def _keep_frames(self, result: RolloutResult) -> None:
        if self.frames is None:
            return
        frames_context = self._sub(self.frames)
        result.frame_times, result.frames = self.frames.frames(frames_context)
        result.last_frame = self.frames.now(frames_context)

    def _contact(self, error) -> dict:
        """A reflex trip's ``{"pairs", "point", "t", "cause"}`` (the contacts at the stop; pairs and
        point None on the robot, which reports no contacts)."""
        report = getattr(self.station, "contact_report", None)
        try:
            contact = report(self.context) if report is not None else {"pairs": None, "point": None}
        except Exception:   # the report describes a stop; it never turns one into another failure
            contact = {"pairs": None, "point": None}
        return {**contact, "t": round(float(getattr(error, "time_s", self.context.get_time())), 4),
                "cause": str(getattr(error, "cause", ""))}

    def _run(self, weights: np.ndarray, result: RolloutResult) -> None:
        """Fills ``result`` as the rollout goes (what it knows before a failure stays)."""
        result.object_pose_true = pose_to_vector(self.station.random_object_pose(result.seed))
        X_WO = self.reset(weights, result.seed)
        result.object_pose = pose_to_vector(X_WO)
        result.object_pose_true = pose_to_vector(self.station.object_pose(self.context))
        self._check_trajectory()
        # One advance over the whole rollout; the loggers in the diagram record it.
        advance_station(self.simulator, self.station, self.context, self._samples() / self.rollout_config.record_hz)
        records = self._records()
        records.check_joint_states()
        times, poses, objs = records.times, records.ee_pose, records.object_state
        final = float(objs[-1])
        success = judge_run(times, objs, records.contact_force, self.config.success)
        result.success, result.final_object_state = bool(success), final
        result.times, result.ee_pose, result.object_state = times, poses, objs
        result.joints = records.state[:, :7]
        self._keep_frames(result)
        if self.pipeline is not None:
            reward = self.pipeline.reward
            G = reward.goal_sequence(self.context)
            if len(G):
                pomrp = reward.pomrp
                rewards, total = pomrp.reward_and_return(G)
                result.rewards = np.asarray(rewards, dtype=float)
                result.dense_return = float(total)
                result.filtered_rewards = reward.filtered_rewards(self.context)   # online, once
                result.verdict = bool(pomrp.verdict(G))
        # A station without ground truth (the robot) reports a NaN object state.
        values = [result.dense_return] + ([final] if getattr(self.station, "has_ground_truth", True) else [])
        if not (np.all(np.isfinite(values)) and np.all(np.isfinite(result.rewards))
                and np.all(np.isfinite(result.filtered_rewards)) and np.all(np.isfinite(poses))):
            raise _NonFiniteError("the rollout's return, rewards or hand path are not finite")
