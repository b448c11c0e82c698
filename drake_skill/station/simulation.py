"""Build once, reset and re-simulate: the station driven by a keyframed plan.

``StationSimulation`` wires a :class:`~drake_skill.station.Station` to a
:class:`~drake_skill.station.pose_source.PoseTrajectorySource` in one diagram, with one
Simulator and one Context that every run reuses:

    sim = StationSimulation(scenario_for_skill("open"))
    X_WO = sim.reset(seed=3)            # defaults + object pose drawn from the seed
    log = sim.run(plan, duration=8.0)   # records the hand pose and object state

The same seed gives bit-identical trajectories (the plant is discrete, the
controllers are discrete, and the randomisation reads only the seed).
"""

from __future__ import annotations

import dataclasses as dc

import numpy as np
from pydrake.math import RigidTransform
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from drake_skill.station.pose_source import PosePlan, PoseTrajectorySource, hold_plan
from drake_skill.station.builder import Station, build_station
from drake_skill.station.config import StationConfig
from drake_skill.station.success import judge_success


def pose_to_vector(X: RigidTransform) -> np.ndarray:
    """[x, y, z, qw, qx, qy, qz] of a RigidTransform."""
    return np.r_[X.translation(), X.rotation().ToQuaternion().wxyz()]


@dc.dataclass
class RunLog:
    """What one run recorded, at ``record_hz``.

    times: (T,) [s]; ee_pose: (T, 7) X_WE as xyz + wxyz; q: (T, 7) joint
    positions [rad]; object_state: (T,) lid angle [rad] or drawer travel [m];
    X_WO: the object pose the run started from (ground truth).
    """

    times: np.ndarray
    ee_pose: np.ndarray
    q: np.ndarray
    object_state: np.ndarray
    X_WO: RigidTransform

    @property
    def final_object_state(self) -> float:
        return float(self.object_state[-1])


class DivergedError(RuntimeError):
    """The simulation produced non-finite or runaway states."""


def record_station(simulator, station, root_context, t0: float, n: int, record_hz: float):
    """Advances ``simulator`` from t0 over n periods of 1 / record_hz, sampling the
    station at each of the n + 1 instants. Returns (times (T,), ee_pose (T, 7),
    q (T, 7), object_state (T,)); raises DivergedError on non-finite joint
    states or joint speeds above 50 rad/s.
    """
    context = station.GetMyContextFromRoot(root_context)
    ee, state_port, obj = (station.GetOutputPort(name) for name in ("ee_pose", "panda_state", "object_state"))
    times, poses, qs, objs = [], [], [], []
    for k in range(n + 1):
        t = t0 + k / record_hz
        if k > 0:
            simulator.AdvanceTo(t)
        state = state_port.Eval(context)
        if not np.all(np.isfinite(state)) or np.max(np.abs(state[7:])) > 50.0:
            raise DivergedError(
                f"simulation diverged at t = {t:.3f} s (joint state {np.round(state, 3)}); "
                "check the commanded poses and the plant time_step")
        times.append(t)
        poses.append(pose_to_vector(ee.Eval(context)))
        qs.append(state[:7].copy())
        objs.append(float(obj.Eval(context)[0]))
    return np.array(times), np.array(poses), np.array(qs), np.array(objs)


class StationSimulation:
    """One station diagram, one simulator, reused for every run."""

    def __init__(self, config: StationConfig | None = None, meshcat=None):
        builder = DiagramBuilder()
        self.station: Station = builder.AddNamedSystem("station", build_station(config, meshcat))
        self.config = self.station.config
        self.source = builder.AddNamedSystem("plan", PoseTrajectorySource())
        builder.Connect(self.source.GetOutputPort("X_WE_desired"),
                        self.station.GetInputPort("ee_pose_desired"))
        builder.Connect(self.source.GetOutputPort("gripper_command"),
                        self.station.GetInputPort("gripper_command"))
        self.diagram = builder.Build()
        self.context = self.diagram.CreateDefaultContext()
        self.simulator = Simulator(self.diagram, self.context)
        self.meshcat = meshcat
        self._X_WO = self.reset(None)

    @property
    def X_WO(self) -> RigidTransform:
        """Ground-truth object pose of the current run."""
        return self._X_WO

    def station_context(self):
        return self.station.GetMyContextFromRoot(self.context)

    def reset(self, seed: int | None = None) -> RigidTransform:
        """Context back to its defaults; object pose drawn from ``seed``. Returns X_WO."""
        self.diagram.SetDefaultContext(self.context)
        self.context.SetTime(0.0)
        self._X_WO = self.station.reset(self.context, seed)
        home = self.station.GetOutputPort("ee_pose").Eval(self.station_context())
        self.source.set_plan(self.source.GetMyMutableContextFromRoot(self.context),
                             hold_plan(home, self.config.gripper_home))
        self.simulator.Initialize()
        # Process the events due at t = 0 (periodic perception systems sample
        # their first frame then) before the first step.
        self.simulator.AdvanceTo(0.0)
        return self._X_WO

    def home_pose(self) -> RigidTransform:
        """X_WE of the hand at the home joint positions."""
        return self.station.GetOutputPort("ee_pose").Eval(self.station_context())

    def set_plan(self, plan: PosePlan) -> None:
        self.source.set_plan(self.source.GetMyMutableContextFromRoot(self.context), plan)
        self.simulator.Initialize()

    def object_state(self) -> float:
        return float(self.station.GetOutputPort("object_state").Eval(self.station_context())[0])

    def ee_pose(self) -> RigidTransform:
        return self.station.GetOutputPort("ee_pose").Eval(self.station_context())

    def run(self, plan: PosePlan | None, duration: float, record_hz: float = 100.0) -> RunLog:
        """Plays ``plan`` (None: keep the current one) for ``duration`` s from the
        current time, recording at ``record_hz``; raises DivergedError on NaN."""
        if plan is not None:
            self.set_plan(plan)
        if duration <= 0:
            raise ValueError(f"duration must be positive, got {duration}")
        times, poses, qs, objs = record_station(self.simulator, self.station, self.context,
                                                self.context.get_time(), int(round(duration * record_hz)),
                                                record_hz)
        return RunLog(times, poses, qs, objs, self._X_WO)

    def judge(self, skill: str, object_state: float | None = None) -> bool:
        """Ground-truth success of ``skill`` for the current (or given) object state."""
        value = self.object_state() if object_state is None else object_state
        return judge_success(skill, value, self.config.success)
