"""The simulated station: models, control accuracy, camera, scripted skills, reset, config errors."""

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant

from drake_skill.station.models import add_package_paths, model_url
from drake_skill.station.pose_source import hold_plan
from drake_skill.demos.scripted import scripted_plan
from drake_skill.station.sim.simulation import StationSimulation
from drake_skill.station.scenario import Scenario, load_scenario
from drake_skill.skills import scenario_for_skill
from drake_skill.station.success import judge_success


def _no_camera(skill):
    config = scenario_for_skill(skill)
    config.enable_camera = False
    return config


@pytest.fixture(scope="module")
def open_sim():
    return StationSimulation(_no_camera("open"))


@pytest.mark.parametrize("filename", ["panda_arm.sdf", "panda_hand.sdf", "table.sdf", "box.sdf", "drawer.sdf"])
def test_models_parse_without_warnings(filename, caplog):
    plant = MultibodyPlant(0.001)
    parser = Parser(plant)
    add_package_paths(parser.package_map())
    parser.SetStrictParsing()  # warnings become errors
    assert parser.AddModels(url=model_url(filename))
    plant.Finalize()


def test_panda_kinematics_match_published_values():
    """At q = 0 Franka's flange is at (0.088, 0, 0.926) m."""
    from drake_skill.station.controller import make_control_plant
    plant = make_control_plant()
    context = plant.CreateDefaultContext()
    X = plant.CalcRelativeTransform(context, plant.world_frame(), plant.GetFrameByName("panda_link8"))
    np.testing.assert_allclose(X.translation(), [0.088, 0.0, 0.926], atol=1e-6)


@pytest.mark.parametrize("offset,rpy", [
    ([0.10, 0.05, -0.10], [0.0, 0.0, 0.0]),
    ([0.15, -0.10, -0.15], [0.0, 0.3, 0.0]),
    ([0.05, 0.15, 0.05], [0.2, 0.0, 0.4]),
])
def test_hand_reaches_commanded_pose(open_sim, offset, rpy):
    open_sim.reset(0)
    home = open_sim.home_pose()
    target = RigidTransform(RollPitchYaw(rpy).ToRotationMatrix() @ home.rotation(),
                            home.translation() + offset)
    open_sim.run(hold_plan(target), duration=2.5, record_hz=10)
    X = open_sim.ee_pose()
    position_error = np.linalg.norm(X.translation() - target.translation())
    angle_error = np.degrees(abs((X.rotation().inverse() @ target.rotation()).ToAngleAxis().angle()))
    assert position_error < 0.005, f"position error {position_error * 1000:.1f} mm"
    assert angle_error < 2.0, f"orientation error {angle_error:.2f} deg"


# Open, Close and Draw: 10 seeds with the reflex on in test_physics.py.
@pytest.mark.parametrize("skill", ["slide"])
def test_scripted_motion_succeeds_and_parked_fails(skill):
    sim = StationSimulation(_no_camera(skill))
    for seed in (0, 7):
        X_WO = sim.reset(seed)
        plan = scripted_plan(skill, X_WO, sim.home_pose())
        log = sim.run(plan, plan.duration + sim.config.success.settle_time, record_hz=20)
        assert sim.judge_log(log), f"{skill} seed {seed}: final object state {log.final_object_state:.3f}"
        assert judge_success(log.final_object_state, sim.config.success)
    sim.reset(3)
    log = sim.run(None, 4.0, record_hz=10)   # the hand holds its home pose
    assert not sim.judge_log(log), f"{skill} judged a success with the arm parked"
    assert np.ptp(log.object_state) < 1e-6


def test_reset_is_bit_identical_for_a_seed(open_sim):
    def rollout(seed):
        X_WO = open_sim.reset(seed)
        plan = scripted_plan("open", X_WO, open_sim.home_pose())
        log = open_sim.run(plan, 4.5, record_hz=50)
        return np.c_[log.ee_pose, log.q, log.object_state]

    a, b, c = rollout(11), rollout(11), rollout(12)
    assert np.array_equal(a, b)
    assert not np.allclose(a, c)
    assert open_sim.reset(11).IsExactlyEqualTo(open_sim.reset(11))


@pytest.fixture(scope="module")
def camera_sim():
    return StationSimulation(scenario_for_skill("open"))


def _blue(rgb):
    r, g, b = (rgb[i].astype(int) for i in range(3))
    return (b > 80) & (b > 2 * r) & (b > 1.5 * g)


def test_camera_sees_blue_object_and_table(camera_sim):
    camera_sim.reset(0)
    station, context = camera_sim.station, camera_sim.station_context()
    cloud = station.GetOutputPort("point_cloud").Eval(context)
    xyz, rgb = cloud.xyzs(), cloud.rgbs()
    valid = np.isfinite(xyz).all(axis=0)
    blue = _blue(rgb) & valid
    assert blue.sum() > 5000, "too few blue points"
    # Blue points lie on the box: inside its footprint around X_WO, below 16 cm.
    p_OP = camera_sim.X_WO.inverse().multiply(xyz[:, blue])
    assert np.all(np.abs(p_OP[0]) < 0.13) and np.all(np.abs(p_OP[1]) < 0.16)
    assert np.all((p_OP[2] > -0.005) & (p_OP[2] < 0.16))
    # Table points (z ~ 0, not blue) are plentiful.
    table = valid & ~blue & (np.abs(xyz[2]) < 0.003)
    assert table.sum() > 50000
    # The label image agrees: box body and lid pixels are the blue pixels.
    labels = station.GetOutputPort("label_image").Eval(context).data[:, :, 0].ravel()
    plant = station.plant
    box_labels = [int(plant.GetBodyByName(n).index()) for n in ("box_base", "box_lid")]
    in_box = np.isin(labels, box_labels)
    assert in_box.sum() > 5000
    iou = (in_box & blue).sum() / (in_box | blue).sum()
    assert iou > 0.95
    assert (labels == int(plant.GetBodyByName("table_top").index())).sum() > 50000


def test_images_have_kinect_shape(camera_sim):
    camera_sim.reset(0)
    context = camera_sim.station_context()
    color = camera_sim.station.GetOutputPort("color_image").Eval(context)
    depth = camera_sim.station.GetOutputPort("depth_image").Eval(context)
    assert (color.width(), color.height()) == (640, 480)
    d = depth.data[:, :, 0]
    finite = d[np.isfinite(d)]
    assert finite.min() >= 0.5 and finite.max() <= 4.0


def test_object_state_port_reports_lid_angle():
    config = _no_camera("close")
    sim = StationSimulation(config)
    assert sim.object_state() == pytest.approx(config.object.initial_joint)


@pytest.mark.parametrize("yaml_text,field", [
    ("object: {kind: box}", "kind"),
    ("camera: {width: 0, height: 480}", "camera.width"),
    ("camera: {width: 100000}", "camera.width"),
    ("time_stepp: 0.001", "time_stepp"),
    ("plant: {time_step: 0.5}", "plant.time_step"),
    ("plant: {discrete_contact_approximation: tamsi}", "plant.discrete_contact_approximation"),
    ("object: {initial_joint: 5.0}", "object.initial_joint"),
    ("q_home: [0, 0, 0]", "q_home"),
    # issue 12, group 3: NaN poses and ranges, negative gains and limits, out of reach
    ("object: {x: .nan}", "object.x"),
    ("object: {yaw: .inf}", "object.yaw"),
    ("object: {randomize_xy: .nan}", "object.randomize_xy"),
    ("object: {randomize_yaw: -0.1}", "object.randomize_yaw"),
    ("object: {x: 1.5}", "object.x/object.y"),
    ("object: {joint_friction: -1.0}", "object.joint_friction"),
    ("object: {footprint_heights: [0.2, 0.1]}", "object.footprint_heights"),
    ("object: {footprint_heights: [0.1]}", "object.footprint_heights"),
    ("controller: {kp: [-600, 600, 600, 600, 250, 150, 50]}", r"controller.kp[0]"),
    ("controller: {ee_speed_max: -0.1}", "controller.ee_speed_max"),
    ("controller: {velocity_scale: .nan}", "controller.velocity_scale"),
    ("controller: {finger_kp: 0.0}", "controller.finger_kp"),
    ("reflex: {contact_force_max: -5}", "reflex.contact_force_max"),
    ("contact: {object: {friction: .nan}}", "contact.object.friction"),
    ("contact: {lid: {friction: 0.5}}", "lid"),
    ("object: {joint: hinge}", "object.joint"),
    ("object: {base_body: lid}", "object.base_body"),
    ("object: {model: cupboard}", "object.model"),
    ("object: {colour: {saturation_min: 1.0}}", "object.colour.saturation_min"),
    ("object: {colour: {hue_min_deg: 220, hue_max_deg: 220}}", "object.colour.hue_min_deg/hue_max_deg"),
    ("directives: [{add_model: {name: box, file: package://drake_skill_models/box.sdf}}]", "directives"),
    ("directives: [{add_model: {name: box, file: nowhere/box.sdf}}]", "directives[0].add_model.file"),
    ("camera: {focal: !FovDegrees {x: 200.0, y: 43.0}}", "camera.focal.x"),
    ("camera: {fps: 0.0}", "camera.fps"),
    ("success: {open_min: 1.7}", "open_min"),
    ("success: {joint: lid_hinge, above: .nan}", "success.above"),
    ("success: {joint: lid_hinge, above: 1.0, below: 0.5}", "success.above/below"),
    ("success: {joint: drawer_slide, above: 0.1}", "success.joint"),
])
def test_bad_config_names_the_field(yaml_text, field):
    import re
    with pytest.raises(ValueError, match=re.escape(field)):
        load_scenario(data=yaml_text)


def test_config_yaml_round_trip(tmp_path):
    path = tmp_path / "scenario.yaml"
    path.write_text("plant:\n  time_step: 0.001\nobject:\n  x: 0.68\ncamera:\n  fps: 5.0\n")
    config = load_scenario(path)
    assert config.object.joint == "lid_hinge" and config.object.x == 0.68
    assert config.time_step == 0.001 and config.camera.fps == 5.0
    assert config.camera.width == Scenario().camera.width
    # Keys left out keep their defaults, including the plant's contact settings.
    assert config.plant.discrete_contact_approximation == "sap"
    with pytest.raises(FileNotFoundError, match="nope.yaml"):
        load_scenario(tmp_path / "nope.yaml")


def test_shipped_scenarios_are_yaml_files_in_the_package():
    from drake_skill.skills import load_skill
    from drake_skill.station.scenario import dump_scenario
    for skill, model, x, joint in (("open", "box", 0.60, 0.0), ("close", "box", 0.46, 1.9),
                                   ("draw", "drawer", 0.68, 0.0)):
        path = load_skill(skill).scenario_path()
        assert path.parent.name == "scenarios" and path.suffix == ".yaml" and path.is_file()
        config = scenario_for_skill(skill)
        assert config.success == load_skill(skill).success    # the skill's rule, not the scene's
        assert (config.object.model, config.object.x, config.object.initial_joint) == (model, x, joint)
        assert config.object.gravity
        # The dump of a loaded scenario loads back to the same values.
        again = load_scenario(data=dump_scenario(config))
        assert dump_scenario(again) == dump_scenario(config)


def test_the_workcell_written_out_builds_the_same_station():
    """models/workcell.dmd.yaml (the robot and the table, written once; issue 46 item 3), and a user's
    scenario that lists its three directives itself, build the same plant; a run stored with the
    three lines is the same station as one with the workcell's add_directives."""
    from pydrake.multibody.tree import BodyIndex

    from drake_skill.station.make import make_station
    from drake_skill.station.scenario import ROBOT_DIRECTIVES, WORKCELL_FILE, dump_scenario, same_station

    assert ROBOT_DIRECTIVES.strip() == f'- add_directives: {{file: "{WORKCELL_FILE}"}}'
    box = '- add_model: {name: box, file: "package://drake_skill_models/box.sdf"}\n'
    written_out = """directives:
- add_directives: {file: "package://drake_skill_models/panda_robot.dmd.yaml"}
- add_model: {name: table, file: "package://drake_skill_models/table.sdf"}
- add_weld: {parent: world, child: table::table_top}
""" + box
    configs = [load_scenario(data=text, overrides=["enable_camera: false"])
               for text in ("directives:" + ROBOT_DIRECTIVES + box, written_out)]
    poses = []
    for config in configs:
        plant = make_station(config).plant
        context = plant.CreateDefaultContext()
        poses.append({(plant.GetModelInstanceName(b.model_instance()), b.name()):
                      plant.EvalBodyPoseInWorld(context, b).GetAsMatrix4().tolist()
                      for b in (plant.get_body(BodyIndex(i)) for i in range(plant.num_bodies()))})
    assert poses[0] == poses[1]
    assert poses[0][("table", "table_top")] == np.eye(4).tolist()
    assert same_station(*(dump_scenario(c) for c in configs))
    assert not same_station(dump_scenario(configs[0]), dump_scenario(configs[0]).replace("box.sdf", "drawer.sdf"))


def test_object_joint_can_be_set():
    sim = StationSimulation(_no_camera("open"))
    sim.station.set_object_joint(sim.context, 0.7)
    assert sim.object_state() == pytest.approx(0.7)
    sim.reset(0)
    assert sim.object_state() == pytest.approx(0.0, abs=1e-6)   # the lid rests on its stop by its weight


def test_more_cameras_are_data_and_export_their_images():
    """A scenario's ``cameras`` render beside the perception camera, which stays the one perception reads."""
    from drake_skill.station.make import make_station

    config = load_scenario(data="""
cameras:
- name: overhead
  width: 64
  height: 48
  focal: !FovDegrees {y: 60.0}
  renderer_name: vtk
  X_PB: {translation: [0.55, 0.0, 1.2], rotation: !Rpy {deg: [180.0, 0.0, 90.0]}}
""")
    station = make_station(config)
    context = station.CreateDefaultContext()
    image = station.GetOutputPort("overhead_color_image").Eval(context)
    labels = station.GetOutputPort("overhead_label_image").Eval(context)
    assert (image.width(), image.height()) == (64, 48)
    # Looking straight down at the box: the middle pixel sees it (a label of a body, not empty).
    assert int(labels.data[24, 32, 0]) not in (0, 32767, 32766)
    assert station.GetOutputPort("point_cloud").Eval(context).size() == 640 * 480
    with pytest.raises(ValueError, match=r"cameras\[0\]\.name"):
        load_scenario(data="cameras: [{name: kinect, renderer_name: vtk}]")
    with pytest.raises(ValueError, match=r"cameras\[0\]\.renderer_name"):
        load_scenario(data="cameras: [{name: top, renderer_name: gl}]")
