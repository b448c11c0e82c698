"""Executing a DMP policy in the station: build once, reset, write weights, simulate.

The diagram (docs/architecture.md, "One diagram per skill execution")::

    [ObjectPoseSource] --X_WO--> [DmpSystem] --X_WE_desired--> [Station]
                                                  gripper 0 --> [Station]

``ObjectPoseSource`` holds the object pose the DMP's object frame is mapped
with, as an abstract *parameter* written at reset: the simulator's ground
truth, or (``object_pose="perceived"``) the segmenter's estimate from the
camera's first frame (docs/method.md section 2: the object frame comes from the
perceived object at the start of the execution). The DMP starts from the
hand's actual pose at reset, expressed in that object frame.

    runner = RolloutRunner(station_config, dmp, dmp_config)
    result = runner.run(weights, seed=4)      # success from ground truth
"""

from __future__ import annotations

import dataclasses as dc

import numpy as np
from pydrake.common.value import AbstractValue, Value
from pydrake.math import RigidTransform
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem
from pydrake.systems.primitives import ConstantVectorSource

from drake_skill.action.dmp import Dmp, DmpConfig
from drake_skill.action.systems import DmpSystem
from drake_skill.station.simulation import DivergedError, pose_to_vector, record_station
from drake_skill.station.builder import Station, build_station
from drake_skill.station.config import StationConfig
from drake_skill.station.success import judge_success


class ObjectPoseSource(LeafSystem):
    """Outputs ``X_WO``: a RigidTransform held in an abstract parameter."""

    def __init__(self):
        super().__init__()
        self._index = self.DeclareAbstractParameter(AbstractValue.Make(RigidTransform()))
        self.DeclareAbstractOutputPort("X_WO", lambda: Value(RigidTransform()), self._calc,
                                       {self.all_parameters_ticket()})

    def set_pose(self, context, X_WO: RigidTransform) -> None:
        context.get_mutable_abstract_parameter(self._index).set_value(X_WO)

    def _calc(self, context, output):
        output.set_value(context.get_abstract_parameter(self._index).get_value())


@dc.dataclass
class RolloutResult:
    """One execution: ground-truth verdict and what the simulator recorded.

    times (T,) [s]; ee_pose (T, 7) world xyz + wxyz; object_state (T,);
    X_WO the object pose used for the DMP's frame; X_WO_true the ground truth.
    """

    seed: int
    success: bool
    final_object_state: float
    times: np.ndarray
    ee_pose: np.ndarray
    object_state: np.ndarray
    X_WO: RigidTransform
    X_WO_true: RigidTransform


class RolloutRunner:
    """One diagram (station + DMP) reused for every rollout of a skill."""

    def __init__(self, station_config: StationConfig, dmp: Dmp, dmp_config: DmpConfig | None = None,
                 skill: str = "open", object_pose: str = "ground_truth", settle_time: float = 1.0,
                 record_hz: float = 10.0, meshcat=None):
        if object_pose not in ("ground_truth", "perceived"):
            raise ValueError(f"object_pose must be 'ground_truth' or 'perceived', got {object_pose!r}")
        if object_pose == "perceived" and not station_config.enable_camera:
            raise ValueError("object_pose='perceived' needs station_config.enable_camera = true")
        self.skill = skill
        self.object_pose_mode = object_pose
        self.settle_time = float(settle_time)
        self.record_hz = float(record_hz)
        builder = DiagramBuilder()
        self.station: Station = builder.AddNamedSystem("station", build_station(station_config, meshcat))
        self.config = self.station.config
        self.pose_source = builder.AddNamedSystem("object_pose", ObjectPoseSource())
        self.dmp_system = builder.AddNamedSystem("dmp", DmpSystem(dmp, dmp_config))
        gripper = builder.AddNamedSystem("gripper", ConstantVectorSource([0.0]))
        builder.Connect(self.pose_source.GetOutputPort("X_WO"), self.dmp_system.get_X_WO_input_port())
        builder.Connect(self.dmp_system.get_X_WE_desired_output_port(),
                        self.station.GetInputPort("ee_pose_desired"))
        builder.Connect(gripper.get_output_port(), self.station.GetInputPort("gripper_command"))
        self.segmenter = None
        if object_pose == "perceived":
            from drake_skill.perception.systems import add_object_segmenter
            self.segmenter = add_object_segmenter(builder, self.station)
        self.diagram = builder.Build()
        self.context = self.diagram.CreateDefaultContext()
        self.simulator = Simulator(self.diagram, self.context)

    def _sub(self, system):
        return system.GetMyMutableContextFromRoot(self.context)

    def perceive_object_pose(self) -> RigidTransform:
        """The segmenter's X_WO estimate from the current camera frame."""
        if self.segmenter is None:
            raise ValueError("this runner was built with object_pose='ground_truth'")
        context = self._sub(self.segmenter)
        if self.segmenter.GetOutputPort("valid").Eval(context)[0] < 0.5:
            raise RuntimeError("the segmenter does not see the object at the start of the rollout")
        return self.segmenter.GetOutputPort("X_WO").Eval(context)

    def reset(self, weights, seed: int) -> RigidTransform:
        """Defaults, object pose from ``seed``, ``weights`` (B, d) into the DMP. Returns X_WO used."""
        self.diagram.SetDefaultContext(self.context)
        self.context.SetTime(0.0)
        X_WO_true = self.station.reset(self.context, seed)
        self.simulator.Initialize()
        self.simulator.AdvanceTo(0.0)
        X_WO = X_WO_true if self.segmenter is None else self.perceive_object_pose()
        self.pose_source.set_pose(self._sub(self.pose_source), X_WO)
        dmp_context = self._sub(self.dmp_system)
        self.dmp_system.set_weights(dmp_context, weights)
        X_WE = self.station.GetOutputPort("ee_pose").Eval(self.station.GetMyContextFromRoot(self.context))
        y0 = pose_to_vector(X_WO.inverse() @ X_WE)
        dmp = self.dmp_system.get_dmp(dmp_context)
        if np.dot(y0[3:], dmp.goal[3:]) < 0:   # same quaternion hemisphere as the goal
            y0[3:] *= -1
        self.dmp_system.set_start_goal(dmp_context, y0, dmp.goal)
        self.simulator.Initialize()           # re-latch X_WO into the DMP
        self._X_WO, self._X_WO_true = X_WO, X_WO_true
        return X_WO

    def duration(self) -> float:
        return self.dmp_system.get_dmp(self._sub(self.dmp_system)).tau + self.settle_time

    def run(self, weights, seed: int) -> RolloutResult:
        """One rollout of ``weights`` from the object pose drawn from ``seed``."""
        self.reset(weights, seed)
        n = int(np.ceil(self.duration() * self.record_hz))
        try:
            times, poses, _, objs = record_station(self.simulator, self.station, self.context, 0.0, n,
                                                   self.record_hz)
        except DivergedError as e:
            raise DivergedError(f"rollout seed {seed}: {e}") from e
        final = float(objs[-1])
        return RolloutResult(seed, judge_success(self.skill, final, self.config.success), final,
                             times, poses, objs, self._X_WO, self._X_WO_true)
