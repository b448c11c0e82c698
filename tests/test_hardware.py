"""The hardware port against a simulated robot that speaks the Panda driver's LCM protocol.

Everything runs in this process over ``memq://`` (one DrakeLcm, which the
hardware station handles; the simulated robot runs on its own simulator in a
background thread, in real time), except the last test, which runs the robot
in a second process inside a network namespace of its own.
"""

import contextlib
import copy
from dataclasses import replace as dc_replace
import json
import os
import re
import shutil
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
from drake import lcmt_panda_command, lcmt_panda_status
from pydrake.common.eigen_geometry import Quaternion
from pydrake.common.value import AbstractValue
from pydrake.lcm import DrakeLcm
from pydrake.math import RigidTransform
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.lcm import LcmSubscriberSystem, SerializerInterface

from drake_skill.action.dmp import DmpConfig, fit_dmp
from drake_skill.action.quaternion import make_quaternions_continuous
from drake_skill.demos.format import downsample_action
from drake_skill.learning.rollout import ActionModel, RolloutConfig, RolloutRunner
from drake_skill.station import limits
from drake_skill.station.make import make_station
from drake_skill.skills import scenario_for_skill
from drake_skill.station.hardware.station import STATUS_CHECK_PERIOD, ReflexError, StaleStatusError, StatusMonitor
from drake_skill.station.scenario import load_scenario
from drake_skill.station.drivers import PandaLcmDriver
from drake_skill.station.pose_source import PosePlan, PoseTrajectorySource
from drake_skill.demos.scripted import scripted_plan
from drake_skill.station.sim.lcm_robot import DriverProtocolError, SimRobot
from drake_skill.station.recording import advance_station, pose_to_vector
from drake_skill.station.sim.simulation import StationSimulation

#: Ports the physics issue adds to the simulated station (the hardware one has them already).
PHYSICS_PORTS = {"external_torque", "joint_acceleration_commanded"}


def _scenario(skill="draw", camera=False):
    config = scenario_for_skill(skill)
    config.enable_camera = camera
    return config


def _hardware_config(station_config):
    """A copy of the scenario with the Panda's LCM driver on an in-process (``memq://``) LCM."""
    config = copy.deepcopy(station_config)
    config.driver = PandaLcmDriver(lcm_url="memq://")
    return config


@pytest.mark.parametrize("camera", [False, True])
def test_ports_match_the_simulated_station(camera):
    from drake_skill.station.interface import (CAMERA_OUTPUTS, INPUTS, OUTPUTS, StationInterface,
                                               station_ports as _ports)

    station_config = _scenario("open", camera)
    sim = make_station(station_config)
    hardware = make_station(_hardware_config(station_config), hardware=True, lcm=DrakeLcm("memq://"))
    # Both are the one declared station, with its ports and their types.
    declared = {**OUTPUTS, **(CAMERA_OUTPUTS if camera else {})}
    for station in (sim, hardware):
        assert isinstance(station, StationInterface)
        ins, outs = _ports(station)
        assert ins == INPUTS
        assert {name: outs.get(name) for name in declared} == declared
    assert (sim.realtime, hardware.realtime) == (False, True)
    assert (sim.object_camera is None, hardware.object_camera is None) == (not camera, not camera)
    sim_in, sim_out = _ports(sim)
    hw_in, hw_out = _ports(hardware)
    assert hw_in == sim_in
    for name, signature in sim_out.items():
        assert hw_out.get(name) == signature, f"output {name}: hardware {hw_out.get(name)}, simulated {signature}"
    assert set(hw_out) - set(sim_out) <= PHYSICS_PORTS
    if camera:
        assert {"point_cloud", "object_point_cloud", "color_image", "depth_image", "label_image"} <= set(hw_out)
    else:      # with Meshcat drawing the measured arm, the same ports
        from pydrake.geometry import Meshcat

        drawn = make_station(_hardware_config(station_config), hardware=True, lcm=DrakeLcm("memq://"),
                             meshcat=Meshcat())
        assert _ports(drawn) == (hw_in, hw_out)


# --------------------------------------------------------------------------- greedy policy
@pytest.fixture(scope="module")
def draw_skill():
    """A DMP fitted to a scripted Draw recorded in the simulated station (seed 5)."""
    config = _scenario("draw")
    recording = copy.deepcopy(config)
    recording.reflex.enabled = False    # the demonstration's contact forces are not under test here
    sim = StationSimulation(recording)
    X_WO = sim.reset(5)
    plan = scripted_plan("draw", X_WO, sim.home_pose())
    log = sim.run(plan, plan.duration, record_hz=100)
    X_OW = X_WO.inverse()
    poses = np.array([pose_to_vector(X_OW @ RigidTransform(Quaternion(p[3:] / np.linalg.norm(p[3:])), p[:3]))
                      for p in log.ee_pose])
    poses[:, 3:] = make_quaternions_continuous(poses[:, 3:])
    _, times, poses = downsample_action(log.times, poses, rate_hz=10)
    dmp_config = DmpConfig(n_basis=30)
    return ActionModel("draw", fit_dmp(times, poses, dmp_config), dmp_config), config


def _distance_to_path(points, path):
    """Distance [m] of each of ``points`` (N, 3) to the polyline ``path`` (M, 3)."""
    a, b = path[:-1], path[1:]
    ab = b - a
    t = np.einsum("nmk,mk->nm", points[:, None, :] - a[None], ab) / np.maximum(np.sum(ab * ab, axis=1), 1e-18)
    closest = a[None] + np.clip(t, 0.0, 1.0)[..., None] * ab[None]
    return np.min(np.linalg.norm(points[:, None, :] - closest, axis=2), axis=1)


def test_greedy_policy_on_the_simulated_robot_matches_direct_simulation(draw_skill):
    model, config = draw_skill
    rollout = RolloutConfig(object_pose="ground_truth", goal_model=False, record_hz=10)
    direct = RolloutRunner(model, config, rollout).run(model.initial_dmp.weights, seed=5)
    assert not direct.failed, direct.message

    lcm = DrakeLcm("memq://")
    hardware_config = _hardware_config(copy.deepcopy(config))
    # Two real-time simulators share this process (and its GIL) on a loaded
    # machine: a looser status timeout than the default 100 ms, which the
    # safety test below checks; and no reflex (tested on its own below): when
    # the simulated robot falls behind real time it tracks the commands with
    # larger errors and presses harder than the direct simulation.
    hardware_config.driver.status_timeout = 0.3
    hardware_config.reflex.enabled = False
    robot = SimRobot(hardware_config, lcm=lcm, pump=False)
    runner = RolloutRunner(model, config=rollout, station=make_station(hardware_config, hardware=True, lcm=lcm))
    robot.start(seed=5)
    try:
        on_robot = runner.run(model.initial_dmp.weights, seed=5)
    finally:
        robot.stop()
    assert not on_robot.failed, on_robot.message
    # The simulated robot's ground truth gives the direct simulation's verdict.
    assert robot.judge() == direct.success
    # Final travel within 2 cm: Draw's lift-away knocks the drawer back by 2-4 cm depending on
    # timing, and the robot lags real time on a loaded machine (measured 1.2 cm in CI, 0.02 cm idle).
    assert abs(robot.object_state() - direct.final_object_state) < 0.02
    assert abs(on_robot.final_object_state - robot.object_state()) < 1e-3   # over the ground-truth channel
    # The hand path (measured through the driver's status): every sample within
    # 2 cm of the direct simulation's path, half within 5 mm, and the end within
    # 1 cm. Geometric distance to the path, not to the sample at the same time:
    # the simulated robot's real-time pacing lags the station's when the
    # machine is loaded, which delays, but does not move, the hand.
    assert len(on_robot.ee_pose) >= int(runner.duration() * 10)
    error = _distance_to_path(on_robot.ee_pose[:, :3], direct.ee_pose[:, :3])
    assert np.median(error) < 0.005 and error.max() < 0.02, (np.median(error), error.max())
    assert np.linalg.norm(on_robot.ee_pose[-1, :3] - direct.ee_pose[-1, :3]) < 0.01
    travel = np.sum(np.linalg.norm(np.diff(direct.ee_pose[:, :3], axis=0), axis=1))
    assert travel > 0.1, "the skill's hand path is too short to say anything"
    # The simulated driver accepts the wall-clock stamps (stamped with simulation
    # time, every command would be dropped); on a loaded machine its thread may
    # look at a command late and drop it, as the real driver would.
    accepted, dropped = robot.command_counts()
    assert accepted > 100 and dropped <= 0.01 * accepted, (accepted, dropped)


def test_a_learning_run_on_the_simulated_robot(tmp_path, tmp_path_factory):
    """``learn`` (drake-skill learn's loop) with every rollout on the hardware station."""
    from learning_support import rollout_config, shared_skill

    from drake_skill.learning.loop import LearnConfig, learn
    from drake_skill.fitted_skill import Skill

    shared = shared_skill(tmp_path_factory)
    hardware_config = _hardware_config(copy.deepcopy(shared["station"]))
    hardware_config.driver.status_timeout = 0.3          # two real-time simulators in one process (see above)
    # The loop on the robot is under test here, not the reflex (tested above and
    # below): on a loaded machine the simulated robot lags the commands and
    # presses the lid harder than the direct simulation does.
    hardware_config.reflex.enabled = False
    lcm = DrakeLcm("memq://")
    robot = SimRobot(hardware_config, lcm=lcm, pump=False)
    runner = RolloutRunner(Skill.load(shared["skill_dir"]), config=rollout_config(),
                           station=make_station(hardware_config, hardware=True, lcm=lcm))
    robot.start(seed=3)
    try:
        outcome = learn(shared["skill_dir"], tmp_path / "learn", LearnConfig(episodes=1, rollouts=2, held_out=0,
                                                                             select_poses=1),
                        station_config=hardware_config, rollout_config=rollout_config(), runner=runner,
                        replay=False, progress=False, log=open(os.devnull, "w"))
    finally:
        robot.stop()
    assert outcome.complete
    records = [json.loads(line) for line in (tmp_path / "learn" / "results.jsonl").read_text().splitlines()]
    rollouts = [r for r in records if r.get("type") in ("rollout", "greedy")]
    assert len(rollouts) >= 4 and not any(r["failed"] for r in rollouts), rollouts
    # The simulated robot publishes its ground truth (ground_truth_channel): the reward's quality is
    # measured as in simulation (a real robot's runs, without it, get the reflex rate only).
    assert "reward_auc" in outcome.summary and outcome.summary["reflex_rate"] == 0.0
    select = records[-1]         # the guarded selection ran the start and the last mean on the robot
    assert select["type"] == "select" and [len(c["executions"]) for c in select["candidates"]] == [1, 1]
    assert all(r["n_frames"] > 10 for r in rollouts)   # the learned reward saw the robot's camera
    assert (tmp_path / "learn" / "skill" / "skill.json").is_file()
    accepted, dropped = robot.command_counts()
    assert accepted > 100 and dropped <= 0.01 * accepted, (accepted, dropped)


def test_refinement_on_the_simulated_robot_brings_its_path_to_the_demonstration(tmp_path, tmp_path_factory):
    """``refine_on_robot`` (drake-skill hardware refine): every execution on the robot, the
    robot's lag removed from a DMP fitted to a path the station measured."""
    from types import SimpleNamespace

    from learning_support import shared_skill

    from drake_skill.learning.refine import refine_on_robot
    from drake_skill.fitted_skill import Skill

    shared = shared_skill(tmp_path_factory)
    station_config = copy.deepcopy(shared["station"])
    station_config.enable_camera = False
    # The "demonstration": a 1 s move of 16 cm in free space as the simulated station measured it (100 Hz).
    sim = StationSimulation(station_config)
    X_WO = sim.reset(seed=3)
    home = sim.home_pose()
    moved = RigidTransform(home.rotation(), home.translation() + [0.0, 0.12, 0.10])
    plan = PosePlan.from_poses([0.0, 0.2, 1.2, 1.5], [home, home, moved, moved], [0.08] * 4)
    log = sim.run(plan, 1.8)
    from drake_skill.demos.format import object_frame_poses

    X_OE = object_frame_poses(pose_to_vector(X_WO), log.ee_pose)
    X_OE[:, 3:] = make_quaternions_continuous(X_OE[:, 3:])
    skill = Skill.load(shared["skill_dir"])
    config = dc_replace(skill.config, dmp_data="100hz", dmp_refine=1)
    skill = dc_replace(skill, config=config, dmps=[fit_dmp(log.times, X_OE, config.dmp)], initial_index=0)
    demo = SimpleNamespace(seed=3, X_WO_true=pose_to_vector(X_WO), times_100hz=log.times, X_OE_100hz=X_OE,
                           path="free_move")

    hardware_config = _hardware_config(station_config)
    hardware_config.driver.status_timeout = 0.3           # two real-time simulators in one process (see above)
    hardware_config.reflex.enabled = False
    # The refinement is under test, on a free move: the force limit (on in the shipped scenarios) has
    # nothing to give way to, but its Python update in the real-time control loop let the simulated
    # robot lag real time on 2 shared cores in a fresh-clone CI run (3.7 -> 4.4 mm, the plain fit kept).
    hardware_config.controller.force_limit.enabled = False
    lcm = DrakeLcm("memq://")
    robot = SimRobot(hardware_config, lcm=lcm, pump=False)
    station = make_station(hardware_config, hardware=True, lcm=lcm)
    placed = []
    robot.start(seed=3)
    try:
        (report,) = refine_on_robot(skill, [demo], station, iterations=1,
                                    prompt=lambda seed, X: placed.append(pose_to_vector(X)))
    finally:
        robot.stop()
    assert report["on"] == "robot" and not report["failures"], report
    # Two runs, each from the demonstration's start (the first run left the hand at its end), after
    # the person was told to place the object at the demonstration's pose.
    assert len(placed) == 2 and np.allclose(placed[0], demo.X_WO_true, atol=1e-9)
    plain, refined = report["errors_mm"]
    # The plain DMP commands the measured path and lags behind it again; one step removes about
    # half of that: 3.5 -> 1.8 mm RMS idle, 3.6 -> 1.8 with both cores busy, 3.8 -> 2.4 while a
    # whole parallel suite ran beside it (the simulated robot then lags real time). Without the
    # refinement the ratio is 1 (the plain fit kept).
    assert not report["kept_plain"] and refined < 0.8 * plain, report
    assert skill.info["dmp_refinement"] == [report]
    skill.save(tmp_path / "refined")
    assert Skill.load(tmp_path / "refined").info["dmp_refinement"][0]["on"] == "robot"


def test_hardware_refine_refuses_a_thesis_fit_and_its_own_folder(tmp_path_factory, capsys):
    from learning_support import shared_skill

    from drake_skill.cli.main import main
    from drake_skill.learning.refine import refine_on_robot
    from drake_skill.fitted_skill import Skill

    shared = shared_skill(tmp_path_factory)
    with pytest.raises(ValueError, match="10 Hz data .* --fit tolerance"):
        refine_on_robot(Skill.load(shared["skill_dir"]), [], station=None)
    assert main(["hardware", "refine", "--skill-dir", str(shared["skill_dir"]), "--demos", str(shared["demos_dir"]),
                 "--out", str(shared["skill_dir"])]) == 2
    assert "the fitted skill's own folder" in capsys.readouterr().err


# --------------------------------------------------------------------------- safety
class _Recorder(SerializerInterface):
    """Every ``lcm_type`` message an LcmSubscriberSystem receives, decoded, in order.

    pydrake's ``DrakeLcm.Subscribe`` makes the handler's ``bytes`` without the
    GIL; pumped by an LcmInterfaceSystem inside ``AdvanceTo`` (which releases
    the GIL) while the SimRobot's thread runs Python, that corrupted the heap
    (a segmentation fault in about one run in four). An LcmSubscriberSystem
    keeps the bytes in C++ and calls ``Deserialize`` with the GIL held.
    """

    def __init__(self, lcm_type):
        SerializerInterface.__init__(self)
        self.lcm_type, self.messages = lcm_type, []

    def CreateDefaultValue(self):
        return AbstractValue.Make(self.lcm_type())

    def Deserialize(self, buffer, abstract_value):
        message = self.lcm_type.decode(bytes(buffer))
        self.messages.append(message)
        abstract_value.set_value(message)

    def Serialize(self, abstract_value):
        return abstract_value.get_value().encode()


def _harness(hardware_config, lcm, recorder=None):
    """The hardware station driven by a PoseTrajectorySource; with ``recorder`` (a
    :class:`_Recorder`), also a subscriber that records every command on the wire."""
    builder = DiagramBuilder()
    station = builder.AddSystem(make_station(hardware_config, hardware=True, lcm=lcm))
    source = builder.AddSystem(PoseTrajectorySource())
    builder.Connect(source.GetOutputPort("X_WE_desired"), station.GetInputPort("ee_pose_desired"))
    builder.Connect(source.GetOutputPort("gripper_command"), station.GetInputPort("gripper_command"))
    if recorder is not None:
        builder.AddSystem(LcmSubscriberSystem(hardware_config.driver.command_channel, recorder, lcm))
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    simulator = Simulator(diagram, context)
    simulator.set_target_realtime_rate(1.0)
    return station, source, context, simulator


def test_jump_is_rate_limited_clipped_and_stale_status_stops_the_station():
    hardware_config = _hardware_config(_scenario("draw"))
    lcm = DrakeLcm("memq://")
    robot = SimRobot(hardware_config, lcm=lcm, pump=False)
    recorder = _Recorder(lcmt_panda_command)
    station, source, context, simulator = _harness(hardware_config, lcm, recorder)
    commands = recorder.messages
    y_max = hardware_config.driver.workspace.upper[1]
    robot.start()
    try:
        station.reset(context)
        station_context = station.GetMyContextFromRoot(context)
        X0 = station.GetOutputPort("ee_pose").Eval(station_context)
        q0 = station.GetOutputPort("panda_state").Eval(station_context)[:7].copy()
        # Hold, then jump 0.5 m sideways: past the workspace's y = 0.45 m.
        target = RigidTransform(X0.rotation(), X0.translation() + [0.0, 0.5, 0.0])
        assert target.translation()[1] > y_max + 0.03
        source.set_plan(source.GetMyMutableContextFromRoot(context),
                        PosePlan.from_poses([0.0, 0.3, 0.31], [X0, X0, target], [0.0] * 3))
        simulator.Initialize()
        simulator.AdvanceTo(2.5)
        p = station.GetOutputPort("ee_pose").Eval(station_context).translation()
        robot.stop()                              # the robot's status stops
        with pytest.raises(StaleStatusError, match="no status from the robot") as stale:
            advance_station(simulator, station, context, 4.0)
    finally:
        robot.stop()
    for _ in range(20):
        lcm.HandleSubscriptions(1)                # what is still queued
    period = hardware_config.driver.command_period

    # The first command is the measured position.
    q = np.array([c.joint_position for c in commands])
    assert np.max(np.abs(q[0] - q0)) < 1e-9
    # On the wire: joint velocity, acceleration and jerk within Franka's limits.
    v = np.diff(q, axis=0) / period
    a = np.diff(v, axis=0) / period
    j = np.diff(a, axis=0) / period
    assert np.max(np.abs(v) / limits.QD_MAX) <= 1 + 1e-6
    assert np.max(np.abs(a) / limits.QDD_MAX) <= 1 + 1e-6
    # The jerk bound yields where the acceleration or velocity bound cuts in
    # (drake_skill.station.controller.RateLimiter); the driver's libfranka
    # rate limiter smooths the rest.
    assert np.max(np.abs(j) / limits.QDDD_MAX) <= 1.1
    assert np.max(np.abs(a) / limits.QDD_MAX) > 0.5, "the jump did not exercise the limits"
    # The out-of-workspace command is clipped: the hand went to y = 0.45 m, no further.
    assert abs(p[1] - y_max) < 0.01 and p[1] < y_max + 0.002, p
    # Stale status: caught within the configured time, commanding stopped there.
    error = stale.value
    age = error.detected_at - error.last_seen
    timeout = hardware_config.driver.status_timeout
    assert timeout < age <= timeout + STATUS_CHECK_PERIOD + 1e-9
    last_command_time = (len(commands) - 1) * period
    assert error.last_seen + timeout - period <= last_command_time
    assert last_command_time <= error.detected_at + 1e-9
    assert all(c.utime > 1e15 for c in commands[:: max(1, len(commands) // 20)])   # wall clock [us]
    assert abs(commands[-1].utime - time.time() * 1e6) < 5e6


@contextlib.contextmanager
def _pressing_into_the_table(force_limit: bool, z_end: float, duration: float):
    """The hardware station, with the simulated robot over in-process LCM, commanded from the home
    pose straight down to the TCP at ``z_end`` [m] over ``duration`` [s] (after 0.2 s at rest),
    initialized; yields (config, station, context, simulator)."""
    hardware_config = _hardware_config(_scenario("open"))
    hardware_config.driver.workspace.lower[2] = -0.3          # let the command go below the table top
    hardware_config.controller.force_limit.enabled = force_limit
    lcm = DrakeLcm("memq://")
    robot = SimRobot(hardware_config, lcm=lcm, pump=False)
    station, source, context, simulator = _harness(hardware_config, lcm)
    robot.start()
    try:
        station.reset(context)
        X0 = station.GetOutputPort("ee_pose").Eval(station.GetMyContextFromRoot(context))
        down = RigidTransform(X0.rotation(), X0.translation() * [1.0, 1.0, 0.0] + [0.0, 0.0, z_end])
        source.set_plan(source.GetMyMutableContextFromRoot(context),
                        PosePlan.from_poses([0.0, 0.2, 0.2 + duration], [X0, X0, down], [0.0] * 3))
        simulator.Initialize()
        yield hardware_config, station, context, simulator
    finally:
        robot.stop()


def test_pressing_into_the_table_trips_the_shared_reflex():
    """The reflex monitor of simulation, shared by the hardware station (advanced as every run is,
    by advance_station), decides the reflex on the robot from the driver's external joint torques."""
    with _pressing_into_the_table(False, -0.2, 2.0) as (hardware_config, station, context, simulator):
        with pytest.raises(ReflexError, match="torque joint") as reflex:
            advance_station(simulator, station, context, 4.0)
    limit = np.asarray(hardware_config.reflex.external_torque_max)
    assert np.any(np.abs(reflex.value.torque_Nm) > limit)
    assert 0.2 < reflex.value.time_s < 4.0


def test_reset_without_a_robot_says_what_to_check():
    hardware_config = _hardware_config(_scenario("open"))
    hardware_config.driver.reset_timeout = 0.2
    station = make_station(hardware_config, hardware=True, lcm=DrakeLcm("memq://"))
    with pytest.raises(StaleStatusError, match="no robot status within 0.2 s.*driver"):
        station.reset(station.CreateDefaultContext(), 0)


def _status(robot_mode=lcmt_panda_status.kMove, utime=1):
    msg = lcmt_panda_status()
    msg.utime, msg.num_joints, msg.robot_mode = utime, 7, robot_mode
    for name in ("joint_position", "joint_position_desired", "joint_velocity", "joint_velocity_desired",
                 "joint_acceleration_desired", "joint_torque", "joint_torque_desired", "joint_torque_external"):
        setattr(msg, name, [0.0] * 7)
    return msg


@pytest.mark.parametrize("mode", [lcmt_panda_status.kReflex, lcmt_panda_status.kUserStopped])
def test_the_robots_own_reflex_stops_the_station(mode):
    monitor = StatusMonitor(0.005, 0.1)
    context = monitor.CreateDefaultContext()
    monitor.GetInputPort("status").FixValue(context, _status(mode))
    monitor.GetInputPort("torque_external").FixValue(context, np.zeros(7))
    monitor.GetInputPort("torque_external").FixValue(context, np.arange(7.0))
    simulator = Simulator(monitor, context)
    # The check stops the simulator at its instant (no exception inside it); the reason is in its state.
    assert monitor.stop_error(context) is None
    status = simulator.AdvanceTo(0.02)
    assert status.reason() == status.ReturnReason.kReachedTerminationCondition
    assert status.return_time() == 0.0 and status.system() is monitor     # the check at t = 0
    error = monitor.stop_error(context)
    assert isinstance(error, ReflexError) and error.reason == "reflex"
    assert error.cause == ("robot reflex" if mode == lcmt_panda_status.kReflex else "robot user stop")
    assert error.time_s == 0.0 and list(error.torque_Nm) == list(range(7))
    # The stop holds until the next reset (the next check stops again); then the monitor runs again.
    again = simulator.AdvanceTo(0.03)
    assert again.reason() == status.ReturnReason.kReachedTerminationCondition and again.return_time() <= 0.005
    assert monitor.stop_error(context).time_s == 0.0
    monitor.GetInputPort("status").FixValue(context, _status(lcmt_panda_status.kMove, utime=2))
    monitor.mark_fresh(context)
    assert monitor.stop_error(context) is None
    assert simulator.AdvanceTo(0.03).reason() == status.ReturnReason.kReachedBoundaryTime


def test_measured_external_torque_goes_to_the_shared_reflex_check():
    """The recorder's reflex monitor (drake_skill.station.recording) reads
    ``robot_scene_contact``; on the robot that is the driver's external torque."""
    hardware_config = _hardware_config(_scenario("open"))
    lcm = DrakeLcm("memq://")
    station = make_station(hardware_config, hardware=True, lcm=lcm)
    context = station.CreateDefaultContext()
    msg = _status()
    msg.joint_position = list(hardware_config.q_home)
    msg.joint_torque_external = [0.0, 0.0, 0.0, 41.0, 0.0, 0.0, -3.0]
    lcm.Publish(hardware_config.driver.status_channel, msg.encode())
    station.reset(context, 0)
    force, tau = station.robot_scene_contact(context)
    assert force == 0.0 and np.array_equal(tau, msg.joint_torque_external)
    np.testing.assert_allclose(station.GetOutputPort("panda_state").Eval(context)[:7], hardware_config.q_home)


def test_first_command_is_the_measured_position_of_a_robot_away_from_home():
    """A robot that is not at q_home when the run starts is commanded to stay where it
    is, not to jump home (the simulated robot always starts at q_home, so the
    rate-limit test above cannot tell "measured" from "home")."""
    hardware_config = _hardware_config(_scenario("open"))
    lcm = DrakeLcm("memq://")
    recorder = _Recorder(lcmt_panda_command)
    station, source, context, simulator = _harness(hardware_config, lcm, recorder)
    q_home = np.asarray(hardware_config.q_home)
    q_measured = q_home + [0.3, -0.2, 0.15, 0.25, -0.2, 0.3, -0.4]
    msg = _status()
    msg.joint_position = list(q_measured)
    lcm.Publish(hardware_config.driver.status_channel, msg.encode())     # the robot's one status: no SimRobot
    station.reset(context, 0)
    station_context = station.GetMyContextFromRoot(context)
    X0 = station.GetOutputPort("ee_pose").Eval(station_context)
    source.set_plan(source.GetMyMutableContextFromRoot(context), PosePlan.from_poses([0.0, 1.0], [X0, X0], [0.0] * 2))
    simulator.Initialize()
    simulator.AdvanceTo(0.02)                  # 20 commands, well within the status timeout
    for _ in range(5):
        lcm.HandleSubscriptions(1)
    q = np.array([c.joint_position for c in recorder.messages])
    assert len(q) >= 10
    np.testing.assert_allclose(q[0], q_measured, atol=1e-9)
    # Then no jump: the hand is held where it is (the commands stray at most 1.5 mrad
    # from the measured joints in these 20 ms, measured).
    assert np.max(np.abs(q - q_measured)) < 0.01
    assert np.min(np.abs(q_measured - q_home)) > 0.1       # far from home in every joint


def test_camera_over_lcm_gives_the_object_pose():
    from drake_skill.perception.systems import add_object_segmenter

    hardware_config = _hardware_config(_scenario("draw", camera=True))
    lcm = DrakeLcm("memq://")
    robot = SimRobot(hardware_config, lcm=lcm, pump=False)
    builder = DiagramBuilder()
    station = builder.AddSystem(make_station(hardware_config, hardware=True, lcm=lcm))
    segmenter = add_object_segmenter(builder, station)
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    robot.start(seed=3)
    try:
        station.reset(context, 3)                 # waits for a status and a camera frame
    finally:
        robot.stop()
    cloud = station.GetOutputPort("point_cloud").Eval(station.GetMyContextFromRoot(context)).xyzs()
    assert np.isfinite(cloud).all(axis=0).sum() > 100_000
    seg_context = segmenter.GetMyContextFromRoot(context)
    assert segmenter.get_valid_output_port().Eval(seg_context)[0] == 1.0
    X_WO = segmenter.get_X_WO_output_port().Eval(seg_context)
    assert np.linalg.norm(X_WO.translation() - robot.X_WO.translation()) < 0.01


def test_simulated_driver_drops_old_commands_and_refuses_wrong_modes():
    hardware_config = _hardware_config(_scenario("open"))
    robot = SimRobot(hardware_config)            # its own memq:// DrakeLcm, handled by its own thread
    robot.start()

    def command(utime, mode=lcmt_panda_status.CONTROL_MODE_POSITION):
        msg = lcmt_panda_command()
        msg.utime, msg.control_mode_expected = utime, mode
        msg.num_joint_position, msg.joint_position = 7, list(hardware_config.q_home)
        robot.lcm.Publish(hardware_config.driver.command_channel, msg.encode())
        time.sleep(0.1)

    command(int(time.time() * 1e6) - 1_000_000)  # 1 s old: dropped
    command(int(time.time() * 1e6))              # accepted
    command(int(time.time() * 1e6), lcmt_panda_status.CONTROL_MODE_VELOCITY)
    time.sleep(0.1)
    with pytest.raises(DriverProtocolError, match="position mode"):
        robot.stop()
    assert robot.command_counts() == (1, 1)


def test_driver_errors_name_the_field():
    with pytest.raises(ValueError, match=r"field 'driver.status_timeout' = 0.0"):
        load_scenario(data="driver: !PandaLcmDriver {status_timeout: 0.0}")
    with pytest.raises(ValueError, match=r"field 'driver.workspace.lower/upper'"):
        load_scenario(data="driver: !PandaLcmDriver {workspace: {lower: [0, 0, 0], upper: [1, -1, 1]}}")
    with pytest.raises(ValueError, match="status_chanel"):
        load_scenario(data="driver: !PandaLcmDriver {status_chanel: X}")
    config = load_scenario(data="driver: !PandaLcmDriver {lcm_url: memq://, command_channel: FRANKA_CMD}")
    assert config.driver.command_channel == "FRANKA_CMD" and config.driver.status_channel == "PANDA_STATUS"


# --------------------------------------------------------------------------- across processes
UDP_URL = "udpm://239.255.76.67:7667?ttl=0"


def _network_namespace_problem() -> str | None:
    """Why a private network namespace with multicast on its loopback cannot be made (None: it can)."""
    if shutil.which("unshare") is None or shutil.which("ip") is None:
        return "unshare or ip is not installed"
    probe = subprocess.run(["unshare", "-rn", "sh", "-c", "ip link set lo up && ip route add 224.0.0.0/4 dev lo"],
                           capture_output=True, text=True, timeout=30)
    if probe.returncode != 0:
        return f"user and network namespaces are not permitted here ({probe.stderr.strip() or probe.returncode})"
    return None


def test_hardware_cli_against_sim_robot_in_another_process(tmp_path, tmp_path_factory):
    """``drake-skill sim-robot`` and ``drake-skill hardware run`` / ``record-demo`` as two
    processes over UDP multicast, inside a network namespace of the test's own
    (its loopback only: nothing reaches the host's network)."""
    problem = _network_namespace_problem()
    if problem is not None:
        pytest.skip(f"cross-process LCM test needs a private network namespace: {problem}")
    from learning_support import shared_skill, small_station
    from pydrake.common.yaml import yaml_dump_typed

    from drake_skill.demos.format import load_demonstration

    skill_dir = shared_skill(tmp_path_factory)["skill_dir"]
    config = small_station("close")               # 160 x 120 camera: small image messages
    config.driver = PandaLcmDriver(lcm_url=UDP_URL)
    # Two processes with real-time simulators and a PCAE on 2 shared cores: the
    # robot's status may stall longer than the default 100 ms (a real driver
    # runs on its own real-time computer); stale status is tested in-process.
    config.driver.status_timeout = 0.5
    config.reflex.enabled = False         # as in the learning-run test: the protocol is under test
    config.controller.force_limit.enabled = False     # (and its Python update would load the real-time loop)
    config.driver.reset_timeout = 120.0                  # record-demo waits for the robot it starts before
    (tmp_path / "hardware.yaml").write_text(yaml_dump_typed(config))
    cli = f"{sys.executable} -m drake_skill.cli.main"
    robot = f"{cli} sim-robot --config hardware.yaml --skill close --seed 7 --duration 120"
    script = textwrap.dedent(f"""
        set -e
        ip link set lo up
        ip route add 224.0.0.0/4 dev lo
        cd {tmp_path}
        {robot} > robot_run.txt 2>&1 &
        ROBOT=$!
        {cli} hardware run --skill-dir {skill_dir} --scenario hardware.yaml --yes --rollouts 1 --seed0 7 --out run \\
            > run.txt 2>&1 || echo "hardware run exit $?" >> run.txt
        kill -TERM $ROBOT; wait $ROBOT || true
        {cli} hardware record-demo --skill close --config hardware.yaml --yes --seed 7 --duration 3 --out demos \\
            --scenario-text "driver: !PandaLcmDriver {{status_timeout: 0.5}}" \\
            > demo.txt 2>&1 &
        DEMO=$!
        {robot} --guide > robot.txt 2>&1 &
        ROBOT=$!
        wait $DEMO || echo "record-demo exit $?" >> demo.txt
        kill -TERM $ROBOT; wait $ROBOT || true
    """)
    env = dict(os.environ, OMP_NUM_THREADS="1", PYTHONPATH=str(Path(__file__).resolve().parents[1]))
    done = subprocess.run(["unshare", "-rn", "bash", "-c", script], capture_output=True, text=True, timeout=400,
                          env=env)
    logs = {name: (tmp_path / name).read_text() if (tmp_path / name).exists() else ""
            for name in ("robot_run.txt", "run.txt", "robot.txt", "demo.txt")}
    assert done.returncode == 0, (done.stderr, logs)
    report = json.loads((tmp_path / "run" / "hardware_run.json").read_text())
    (rollout,) = report["rollouts"]
    assert not rollout["failed"], (rollout["message"], logs)
    assert rollout["n_frames"] > 10 and np.isfinite(rollout["dense_return"])     # the learned reward saw it
    assert rollout["final_object_state"] is not None                              # the robot's ground truth
    counts = re.search(r"commands accepted (\d+), dropped as expired (\d+)", logs["robot_run.txt"])
    assert counts and int(counts[1]) > 100 and int(counts[2]) <= 0.01 * int(counts[1]), logs["robot_run.txt"]
    demo = load_demonstration(tmp_path / "demos" / "demo_000.npz")
    assert demo.metadata["source"] == "kinesthetic" and demo.has_perception
    # The manifest was written with it: the folder loads as a set (it used to "mix recordings").
    from drake_skill.demos.format import load_demonstrations
    assert [d.seed for d in load_demonstrations(tmp_path / "demos", skill="close")] == [7]
    travel = np.sum(np.linalg.norm(np.diff(demo.X_OE_100hz[:, :3], axis=0), axis=1))
    assert travel > 0.05, f"the guided hand moved {travel:.3f} m"


def test_one_factory_builds_each_driver_and_every_port_carries_what_its_name_says():
    """make_station dispatches on the scenario's driver (issue 46 item 2): the hand pose in, or
    the joint set points in (the simulated robot's), never one under the other's name; the robot
    needs a !PandaLcmDriver, and says so in one line."""
    from drake_skill.station.drivers import JointSetpointDriver

    config = _scenario("open")
    end_effector = make_station(config)
    assert end_effector.GetInputPort("ee_pose_desired").get_data_type().name == "kAbstractValued"
    assert not end_effector.HasInputPort("panda_state_desired")
    config.driver = JointSetpointDriver()
    joints = make_station(config)
    assert joints.GetInputPort("panda_state_desired").size() == 14 and not joints.HasInputPort("ee_pose_desired")
    assert joints.ee_controller is None and not joints.HasOutputPort("joint_acceleration_commanded")
    # The set points reach the arm's joint impedance unchanged.
    context = joints.CreateDefaultContext()
    joints.reset(context, None)
    q = np.asarray(config.q_home) + 0.1
    joints.GetInputPort("panda_state_desired").FixValue(context, np.r_[q, np.zeros(7)])
    plant_context = joints.plant.GetMyContextFromRoot(context)
    np.testing.assert_allclose(joints.plant.get_desired_state_input_port(joints.panda).Eval(plant_context)[:7], q)
    with pytest.raises(ValueError, match=r"^scenario: field 'driver' = !JointSetpointDriver: the hardware "
                                         r"station speaks the Panda driver's LCM protocol; give the scenario driver: "
                                         r"!PandaLcmDriver \{\.\.\.\}"):
        make_station(config, hardware=True)


def test_the_hardware_stations_force_limit_reads_the_reflex_monitor_and_the_measured_state():
    """With ``controller.force_limit`` on, the hardware station's controller has the limit, fed by
    the shared reflex monitor (the driver's external torques) and the measured arm state. (The
    limit's behaviour is tests/test_force_limit.py's, in the simulated station: a press closed over
    LCM through the robot's real-time thread depended on the machine's load.)"""
    hardware_config = _hardware_config(_scenario("open"))
    hardware_config.controller.force_limit.enabled = True
    station = make_station(hardware_config, hardware=True, lcm=DrakeLcm("memq://"))
    controller = station.ee_controller
    assert controller.force_limit is not None
    context = controller.GetMyContextFromRoot(station.CreateDefaultContext())
    assert controller.GetInputPort("reflex_state").HasValue(context)
    assert controller.GetInputPort("robot_state").HasValue(context)
    plain_config = _hardware_config(_scenario("open"))
    plain_config.controller.force_limit.enabled = False
    plain = make_station(plain_config, hardware=True, lcm=DrakeLcm("memq://"))
    assert plain.ee_controller.force_limit is None and not plain.ee_controller.HasInputPort("reflex_state")
