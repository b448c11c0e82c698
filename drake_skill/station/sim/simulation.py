"""Build once, reset and re-simulate: the simulated station in one diagram.

``StationSimulation`` wires a :class:`~drake_skill.station.sim.builder.Station` to a
:class:`~drake_skill.station.pose_source.PoseTrajectorySource` in one diagram, with one
Simulator and one Context that every run reuses:

    sim = StationSimulation(load_skill("open").station_config())
    X_WO = sim.reset(seed=3)            # defaults + object pose drawn from the seed
    log = sim.run(plan, duration=8.0)   # records the hand pose and object state

Runs are recorded by the diagram's loggers
(:class:`~drake_skill.station.loggers.StationLoggers`, the one recording path:
the gripper command and, with perception, the segmenter's frames included);
:meth:`StationSimulation.record` starts them, advances once and reads them.
Runs end early with ``drake_skill.station.recording``'s exceptions.

The same seed gives bit-identical trajectories (the plant is discrete, the
controllers are discrete, and the randomisation reads only the seed).
"""

from __future__ import annotations

from pydrake.math import RigidTransform
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from drake_skill.station.scenario import Scenario
from drake_skill.station.pose_source import PosePlan, PoseTrajectorySource, hold_plan
from drake_skill.station.loggers import StationLoggers, StationRecords
from drake_skill.station.recording import RunLog, advance_station
from drake_skill.station.make import make_station
from drake_skill.station.sim.builder import Station
from drake_skill.station.success import judge_run, judge_success


class StationSimulation:
    """One station diagram, one simulator, reused for every run.

    perceive: wire an ``ObjectSegmenter`` to the camera (``self.segmenter``),
    for recordings with perception (needs ``config.enable_camera``): the loggers
    (``self.loggers``) then log its frames. record_hz: the loggers' default grid [Hz].
    """

    def __init__(self, config: Scenario | None = None, meshcat=None, perceive: bool = False,
                 record_hz: float = 100.0):
        builder = DiagramBuilder()
        self.station: Station = builder.AddNamedSystem("station", make_station(config, meshcat=meshcat))
        self.config = self.station.config
        self.source = builder.AddNamedSystem("plan", PoseTrajectorySource())
        builder.Connect(self.source.GetOutputPort("X_WE_desired"),
                        self.station.GetInputPort("ee_pose_desired"))
        builder.Connect(self.source.GetOutputPort("gripper_command"),
                        self.station.GetInputPort("gripper_command"))
        self.segmenter = None
        if perceive:
            if not self.config.enable_camera:
                raise ValueError("perceive=True needs a station with enable_camera = true")
            from drake_skill.perception.systems import add_object_segmenter
            self.segmenter = add_object_segmenter(builder, self.station)
        self.loggers = StationLoggers(builder, self.station, record_hz, segmenter=self.segmenter,
                                      gripper_command=self.source.GetOutputPort("gripper_command"))
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

    def plan(self) -> PosePlan:
        return self.source.plan(self.source.GetMyContextFromRoot(self.context))

    def object_state(self) -> float:
        return float(self.station.GetOutputPort("object_state").Eval(self.station_context())[0])

    def ee_pose(self) -> RigidTransform:
        return self.station.GetOutputPort("ee_pose").Eval(self.station_context())

    def record(self, n: int, record_hz: float | None = None, frames: bool = True) -> StationRecords:
        """Plays the current plan for n periods of 1 / record_hz (default the loggers') from
        now, recording the n + 1 samples (with ``frames``, the camera frames too when built
        with perceive=True: now must then be a camera frame instant). Raises
        DivergedError, ReflexError or SolverError (see the module docstring)."""
        hz = self.loggers.record_hz if record_hz is None else float(record_hz)
        t0 = self.loggers.start(self.context)
        advance_station(self.simulator, self.station, self.context, self.loggers.grid(n, t0, hz, frames)[-1])
        records = self.loggers.read(self.context, n, t0, hz, frames)
        records.check_joint_states()
        return records

    def run(self, plan: PosePlan | None, duration: float, record_hz: float = 100.0) -> RunLog:
        """Plays ``plan`` (None: keep the current one) for ``duration`` s from the
        current time, recording at ``record_hz`` (:meth:`record`); raises DivergedError,
        ReflexError or SolverError (see the module docstring)."""
        if plan is not None:
            self.set_plan(plan)
        if duration <= 0:
            raise ValueError(f"duration must be positive, got {duration}")
        r = self.record(int(round(duration * record_hz)), record_hz, frames=False)
        return RunLog(r.times, r.ee_pose, r.state[:, :7], r.object_state, r.contact_force, self._X_WO)

    def judge(self, object_state: float | None = None) -> bool:
        """Ground-truth verdict of the scenario's success rule (its skill's) on the
        final object state alone (see also :meth:`judge_log`)."""
        value = self.object_state() if object_state is None else object_state
        return judge_success(value, self.config.success)

    def judge_log(self, log: RunLog) -> bool:
        """Ground-truth verdict of a run: the final object state, judged only if the
        hand touched nothing in the run's last ``success.settle_time`` s."""
        return judge_run(log.times, log.object_state, log.contact_force, self.config.success)
