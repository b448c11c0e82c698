"""The force margin at recording (drake_skill.demos.force_margin): a demonstration that presses
over 60 % of a reflex limit is named, with the time and the value of its peak, when it is recorded."""

import re

import numpy as np
import pytest
from drake import lcmt_panda_status, lcmt_scope
from pydrake.lcm import DrakeLcm
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from drake_skill.demos.demonstrator import DemonstratorConfig, ScriptedDemonstrator, demonstration_from
from drake_skill.demos.force_margin import FORCE_MARGIN, check_margin, margin_message, margin_warnings, peaks
from drake_skill.station.scenario import ReflexConfig
from drake_skill.skills import scenario_for_skill

pytestmark = pytest.mark.usefixtures("quiet_differential_ik")

REFLEX = ReflexConfig(contact_force_max=30.0, external_torque_max=[30.0, 30.0, 27.0, 27.0, 24.0, 21.0, 18.0])
NUMBER = r"(\d+\.\d+)"


# --------------------------------------------------------------------------- the pure check
def test_peaks_give_each_columns_peak_and_its_first_time():
    rng = np.random.default_rng(3)
    times = np.arange(200) / 100.0
    values = rng.uniform(0.0, 5.0, size=(200, 7))
    values[123, 3] = -9.0                          # magnitudes: a negative torque counts
    values[[40, 150], 0] = 8.0                     # a tie: the first
    peak, at = peaks(times, values)
    assert peak[3] == 9.0 and at[3] == pytest.approx(1.23)
    assert peak[0] == 8.0 and at[0] == pytest.approx(0.40)
    force, t_force = peaks(times, values[:, 3])
    assert force.shape == (1,) and force[0] == 9.0 and t_force[0] == pytest.approx(1.23)
    with pytest.raises(ValueError, match="200 times for 3 samples"):
        peaks(times, values[:3])


def test_a_peak_over_60_percent_of_the_limit_is_warned_and_one_under_it_is_not():
    assert FORCE_MARGIN == 0.6
    assert check_margin(17.9, 2.0, 30.0) is None                  # 59.7 %
    assert check_margin(18.0, 2.0, 30.0) is None                  # exactly 60 %: not over
    excess = check_margin(22.5, 3.41, 30.0)
    assert excess.fraction == pytest.approx(0.75) and excess.time_s == 3.41 and excess.limit == 30.0
    # Per joint: the worst fraction of its own limit wins (joint 7: 12 / 18 = 67 % over joint 1: 19 / 30 = 63 %).
    excess = check_margin([19.0, 0, 0, 0, 0, 0, -12.0], [1.0, 0, 0, 0, 0, 0, 2.5], REFLEX.external_torque_max)
    assert (excess.index, excess.peak, excess.time_s) == (6, 12.0, 2.5)
    assert check_margin([10.0] * 7, [0.0] * 7, REFLEX.external_torque_max) is None      # 10 / 18 = 56 %
    assert check_margin(25.0, 1.0, 0.0) is None                   # no limit: nothing checked
    assert check_margin(16.0, 1.0, 30.0, margin=0.5) is not None


def test_the_warning_names_the_demonstration_time_force_limit_and_what_to_do():
    message = margin_message("demos/flap/demo_001.npz", check_margin(22.0, 3.456, 30.0))
    assert message == ("demos/flap/demo_001.npz: contact force peaks at 22.0 N at t = 3.46 s, 73 % of the reflex "
                       "limit 30 N (warned above 60 %); demonstrate with a lighter touch, or the imitation and "
                       "exploration will trip the reflex at 30 N")
    assert "\n" not in message


def test_a_demonstrations_metadata_gives_its_warnings():
    class Demo:
        metadata = {"peak_contact_force_N": 20.0, "peak_contact_force_time_s": 1.5,
                    "peak_external_torque_Nm": [1.0, 2.0, 3.0, 20.0, 1.0, 1.0, 1.0],
                    "peak_external_torque_time_s": [0.1, 0.2, 0.3, 4.25, 0.5, 0.6, 0.7]}

    force, torque = margin_warnings(Demo(), REFLEX, "demo_000.npz")
    assert force.startswith("demo_000.npz: contact force peaks at 20.0 N at t = 1.50 s, 67 % of the reflex limit 30 N")
    assert torque.startswith("demo_000.npz: external torque of joint 4 peaks at 20.0 N m at t = 4.25 s, 74 % of "
                             "the reflex limit 27 N m")
    assert torque.endswith("will trip the reflex at 27 N m")
    Demo.metadata = dict(Demo.metadata, peak_contact_force_N=5.0, peak_external_torque_Nm=[1.0] * 7)
    assert margin_warnings(Demo(), REFLEX, "demo_000.npz") == []
    Demo.metadata = {"peak_contact_force_N": 25.0}                # recorded before the times were kept
    (old,) = margin_warnings(Demo(), REFLEX, "demo_000.npz")
    assert "peaks at 25.0 N at t = nan s" in old


# --------------------------------------------------------------------------- a scripted recording
@pytest.fixture(scope="module")
def draw_demo():
    """A scripted Draw (seed 1, no camera) recorded at the shipped reflex limit."""
    demonstrator = ScriptedDemonstrator("draw", DemonstratorConfig(record_perception=False, seed=1))
    return demonstrator.record(1)


def test_a_recording_stores_its_peaks_and_their_times(draw_demo):
    meta = draw_demo.metadata
    force, at = meta["peak_contact_force_N"], meta["peak_contact_force_time_s"]
    assert 0.0 < force and 0.0 < at <= draw_demo.duration
    assert len(meta["peak_external_torque_Nm"]) == 7 and len(meta["peak_external_torque_time_s"]) == 7
    assert max(meta["peak_external_torque_Nm"]) > 0.0
    # Pulling the drawer is within the margin at the shipped limits: no warning.
    assert margin_warnings(draw_demo, scenario_for_skill("draw").reflex, "demo_000.npz") == []


def test_demos_record_warns_about_a_demonstration_over_the_margin(draw_demo, tmp_path, capsys):
    """The same demonstration recorded by ``drake-skill demos record`` with a reflex limit
    lowered so that its peak is 70 % of it: accepted (under max_force_fraction 0.8), warned."""
    from drake_skill.cli.demos import main

    force, at = draw_demo.metadata["peak_contact_force_N"], draw_demo.metadata["peak_contact_force_time_s"]
    limit = round(force / 0.7, 3)
    (tmp_path / "scenario.yaml").write_text(f"reflex:\n  contact_force_max: {limit}\n")
    out = tmp_path / "draw"
    assert main(["record", "--skill", "draw", "--count", "1", "--seed", "1", "--no-camera", "--quiet",
                 "--scenario", str(tmp_path / "scenario.yaml"), "--out", str(out)]) == 0
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if "warning:" in line]
    assert len(lines) == 1, err
    match = re.fullmatch(rf"drake-skill: warning: {re.escape(str(out / 'demo_000.npz'))}: contact force peaks at "
                         rf"{NUMBER} N at t = {NUMBER} s, (\d+) % of the reflex limit {limit:g} N \(warned above "
                         r"60 %\); demonstrate with a lighter touch, or the imitation and exploration will trip the "
                         rf"reflex at {limit:g} N", lines[0])
    assert match, lines[0]
    assert float(match[1]) == pytest.approx(force, abs=0.05) and float(match[2]) == pytest.approx(at, abs=0.005)
    assert match[3] == "70"


def test_an_interactive_recording_is_warned_when_it_is_recorded():
    """A teleoperated hand driven down onto the box through a real Meshcat (as in
    test_teleop.py): the session's status names the demonstration, the time and the force.
    The reflex is off, so that the push is recorded; its limit still decides the warning."""
    from pydrake.geometry import Meshcat
    from test_teleop import SLIDER, click

    from drake_skill.demos.teleop import RECORD_BUTTON, STOP_BUTTON, TeleopConfig, TeleopSession

    station = scenario_for_skill("open")
    station.enable_camera, station.reflex.enabled = False, False
    meshcat = Meshcat()
    session = TeleopSession("open", meshcat, TeleopConfig(realtime_rate=0.0, record_perception=False),
                            station_config=station)
    p_WO = session.reset(0).translation()
    start = {}

    def user(t):
        if not start and t >= 0.05:
            start.update({k: meshcat.GetSliderValue(SLIDER[k]) for k in "xyz"})
            click(meshcat, RECORD_BUTTON)
        elif start and t <= 1.2:                       # over the box, then down to the table's height
            s = min(max((t - 0.1) / 0.8, 0.0), 1.0)
            for k, goal in zip("xyz", (p_WO[0], p_WO[1], 0.0)):
                meshcat.SetSliderValue(SLIDER[k], start[k] + (goal - start[k]) * s)
        if 1.2 <= t < 1.21:
            click(meshcat, STOP_BUTTON)

    lines = []
    demo = session.record(seed=0, user=user, status=lines.append)
    warned = [line for line in lines if line.startswith("warning: ")]
    force = demo.metadata["peak_contact_force_N"]
    assert force > FORCE_MARGIN * station.reflex.contact_force_max
    match = re.match(rf"warning: this demonstration \(seed 0\): contact force peaks at {NUMBER} N at t = {NUMBER} s, "
                     r"\d+ % of the reflex limit 30 N", warned[0])
    assert match, lines
    assert float(match[1]) == pytest.approx(force, abs=0.05)
    assert 0.0 < float(match[2]) == pytest.approx(demo.metadata["peak_contact_force_time_s"], abs=0.005)


# --------------------------------------------------------------------------- the robot: external torques
def _status(q, tau, utime):
    msg = lcmt_panda_status()
    msg.utime, msg.num_joints, msg.robot_mode = utime, 7, lcmt_panda_status.kMove
    for name in ("joint_position_desired", "joint_velocity", "joint_velocity_desired",
                 "joint_acceleration_desired", "joint_torque", "joint_torque_desired"):
        setattr(msg, name, [0.0] * 7)
    msg.joint_position, msg.joint_torque_external = list(q), list(tau)
    return msg


def test_a_kinesthetic_recording_is_warned_by_its_external_torques():
    """The hardware station as ``hardware record-demo`` wires it (nothing commanded), fed the
    driver's status by hand: joint 4's external torque rises to 70 % of its 27 N m limit
    at 0.5 s. The loggers keep the filtered torque's peak and time; the warning names them."""
    from drake_skill.station.drivers import PandaLcmDriver
    from drake_skill.station.make import make_station
    from drake_skill.station.pose_source import PoseTrajectorySource, hold_plan
    from drake_skill.station.loggers import StationLoggers
    from drake_skill.station.recording import advance_station

    config = scenario_for_skill("close")
    config.driver = PandaLcmDriver(lcm_url="memq://", ground_truth_channel="SIM_OBJECT_STATE")
    config.enable_camera = False
    lcm = DrakeLcm("memq://")
    builder = DiagramBuilder()
    station = builder.AddNamedSystem("station", make_station(config, hardware=True, lcm=lcm, commanding=False))
    hold = builder.AddNamedSystem("hold", PoseTrajectorySource())
    builder.Connect(hold.GetOutputPort("X_WE_desired"), station.GetInputPort("ee_pose_desired"))
    builder.Connect(hold.GetOutputPort("gripper_command"), station.GetInputPort("gripper_command"))
    loggers = StationLoggers(builder, station, 100.0, gripper_command=hold.GetOutputPort("gripper_command"))
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    simulator = Simulator(diagram, context)
    q = config.q_home
    limit = config.reflex.external_torque_max[3]

    def publish(t):
        tau = np.zeros(7)
        tau[3] = -0.7 * limit * min(max((t - 0.3) / 0.2, 0.0), 1.0) if t < 0.8 else 0.0   # -18.9 N m, 0.5-0.8 s
        lcm.Publish(config.driver.status_channel, _status(q, tau, int(1e6 * t) + 1).encode())
        scope = lcmt_scope()
        scope.utime, scope.size, scope.value = int(1e6 * t) + 1, 1, [0.1]
        lcm.Publish(config.driver.ground_truth_channel, scope.encode())

    publish(0.0)
    X_WO = station.reset(context, 0)
    X_WE = station.GetOutputPort("ee_pose").Eval(station.GetMyContextFromRoot(context))
    hold.set_plan(hold.GetMyMutableContextFromRoot(context), hold_plan(X_WE, config.gripper_home))
    simulator.Initialize()
    loggers.start(context)
    for n in range(1, 101):                                # 1 s at 100 Hz, ends on a 10 Hz instant
        publish(n / 100)
        advance_station(simulator, station, context, n / 100)
    demo = demonstration_from(loggers.read(context, 100), 100.0, 10.0, "close", 0, X_WO, success=False,
                              metadata={"source": "kinesthetic"})
    meta = demo.metadata
    assert meta["peak_contact_force_N"] == 0.0                # the robot does not measure it
    # The filtered torque (10 ms time constant) follows the 0.2 s ramp within 2 %.
    assert meta["peak_external_torque_Nm"][3] == pytest.approx(0.7 * limit, rel=0.02)
    assert 0.5 <= meta["peak_external_torque_time_s"][3] <= 0.8
    (message,) = margin_warnings(demo, config.reflex, "demos/close/demo_003.npz")
    match = re.fullmatch(rf"demos/close/demo_003\.npz: external torque of joint 4 peaks at {NUMBER} N m at t = "
                         rf"{NUMBER} s, (\d+) % of the reflex limit {limit:g} N m \(warned above 60 %\); demonstrate "
                         rf"with a lighter touch, or the imitation and exploration will trip the reflex at "
                         rf"{limit:g} N m", message)
    assert match, message
    assert float(match[1]) == pytest.approx(0.7 * limit, rel=0.02) and match[3] in ("69", "70")
