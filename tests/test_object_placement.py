"""Object placement (drake_skill.station.placement): the random poses' range, sign and seeds; the nominal
pose; the object's parts and their errors."""

import numpy as np
import pytest
from pydrake.math import RollPitchYaw

from drake_skill.learning.evaluation import HELD_OUT_SEED0
from drake_skill.station.sim.builder import Station
from drake_skill.skills import scenario_for_skill


def _station(skill="open", **object_changes):
    config = scenario_for_skill(skill)
    config.enable_camera = False          # the placement needs no camera
    for name, value in object_changes.items():
        setattr(config.object, name, value)
    return Station(config)


def _placements(station, seeds):
    """(N, 3) [x m, y m, yaw rad] and the (N, 3) roll, pitch and z of the poses of ``seeds``."""
    out, rest = [], []
    for seed in seeds:
        X = station.random_object_pose(seed)
        rpy = RollPitchYaw(X.rotation())
        out.append([*X.translation()[:2], rpy.yaw_angle()])
        rest.append([rpy.roll_angle(), rpy.pitch_angle(), X.translation()[2]])
    return np.array(out), np.array(rest)


def test_placements_fill_the_configured_range_on_both_sides():
    """Uniform noise of half-width randomize_xy per axis and randomize_yaw about the
    nominal pose (here not at the origin, and with different widths), on the table."""
    station = _station(x=0.55, y=0.1, yaw=0.3, randomize_xy=0.03, randomize_yaw=0.1)
    placements, rest = _placements(station, range(2000))
    noise = placements - [0.55, 0.1, 0.3]
    half = np.array([0.03, 0.03, 0.1])
    assert np.all(np.abs(noise) <= half)
    # Both signs, out to the ends of the range, centred (a one-sided or narrower
    # draw fails here); x and y drawn independently.
    assert np.all(noise.min(axis=0) < -0.95 * half) and np.all(noise.max(axis=0) > 0.95 * half)
    np.testing.assert_allclose(noise.mean(axis=0), 0.0, atol=0.05 * half.max())
    np.testing.assert_allclose(noise.std(axis=0), half / np.sqrt(3), rtol=0.05)   # uniform
    assert abs(np.corrcoef(noise[:, 0], noise[:, 1])[0, 1]) < 0.1
    np.testing.assert_array_equal(rest, 0.0)       # flat on the table top, z = 0
    # No noise: the nominal pose for every seed.
    still, _ = _placements(_station(x=0.55, y=0.1, yaw=0.3, randomize_xy=0.0, randomize_yaw=0.0), range(5))
    np.testing.assert_allclose(still, [[0.55, 0.1, 0.3]] * 5, atol=1e-12)


def test_a_seed_is_always_the_same_placement():
    """The held-out poses of learn and evaluate (seeds from HELD_OUT_SEED0) are fixed
    numbers: results measured on them stay comparable across runs and versions."""
    station = _station("open")
    (x, y, yaw), = _placements(station, [HELD_OUT_SEED0])[0]
    assert (x, y, yaw) == pytest.approx((0.5807381102207582, -0.009664744045886504, 0.028946427337694994),
                                        abs=1e-12)
    again, _ = _placements(_station("open"), [HELD_OUT_SEED0, HELD_OUT_SEED0 + 1])
    np.testing.assert_array_equal(again[0], [x, y, yaw])
    assert not np.allclose(again[1], again[0])


# ----------------------------------------------------------------------------- the module's functions directly
def _object_plant(config):
    """The scenario's directives parsed into a plant (as station.config checks them), and the object's instance."""
    from drake_skill.station.scenario import _directives_key, _directives_plant

    plant = _directives_plant(_directives_key(config.directives))
    return plant, plant.GetModelInstanceByName(config.object.model)


def test_nominal_and_seeded_poses_of_the_placement_functions():
    from drake_skill.station.placement import nominal_object_pose, random_object_pose

    config = scenario_for_skill("open")
    config.object.x, config.object.y, config.object.yaw = 0.6, -0.05, 0.25
    config.object.randomize_xy, config.object.randomize_yaw = 0.04, 0.2
    X = nominal_object_pose(config)
    np.testing.assert_array_equal(X.translation(), [0.6, -0.05, 0.0])
    np.testing.assert_allclose(X.rotation().matrix(), RollPitchYaw(0.0, 0.0, 0.25).ToRotationMatrix().matrix(),
                               rtol=0, atol=1e-15)
    # The draw, by hand: dx, dy from one uniform call of size 2, then dyaw.
    rng = np.random.default_rng(7)
    dx, dy = rng.uniform(-0.04, 0.04, size=2)
    dyaw = rng.uniform(-0.2, 0.2)
    X = random_object_pose(config, 7)
    np.testing.assert_allclose(X.translation(), [0.6 + dx, -0.05 + dy, 0.0], rtol=0, atol=1e-15)
    rpy = RollPitchYaw(X.rotation())
    assert (rpy.roll_angle(), rpy.pitch_angle()) == (0.0, 0.0)
    assert rpy.yaw_angle() == pytest.approx(0.25 + dyaw, abs=1e-14)


def test_object_parts_and_each_error_naming_the_field():
    from drake_skill.station.placement import object_parts

    config = scenario_for_skill("open")
    plant, obj = _object_plant(config)
    base, joint = object_parts(plant, obj, config)
    assert (base.name(), joint.name()) == ("box_base", "lid_hinge")
    config.object.base_body = "box"
    with pytest.raises(ValueError) as e:
        object_parts(plant, obj, config)
    assert str(e.value) == ("scenario field 'object.base_body' = 'box': the model 'box' has no such body; "
                            "expected one of box_base, box_lid")
    config.object.base_body, config.object.joint = "box_base", "hinge"
    with pytest.raises(ValueError) as e:
        object_parts(plant, obj, config)
    assert str(e.value) == ("scenario field 'object.joint' = 'hinge': the model 'box' has no such joint; "
                            "expected one of lid_hinge")
    arm = scenario_for_skill("open")
    arm.object.model, arm.object.base_body, arm.object.joint = "panda", "panda_link0", "hinge"
    with pytest.raises(ValueError) as e:
        object_parts(plant, plant.GetModelInstanceByName("panda"), arm)
    assert str(e.value).endswith("expected one of panda_joint1, panda_joint2, panda_joint3, panda_joint4, "
                                 "panda_joint5, panda_joint6, panda_joint7, world_welds_to_panda_link0")
    # A joint of other than one position (the arm's weld to the world).
    arm = scenario_for_skill("open")
    arm.object.model, arm.object.base_body, arm.object.joint = "panda", "panda_link0", "world_welds_to_panda_link0"
    with pytest.raises(ValueError) as e:
        object_parts(plant, plant.GetModelInstanceByName("panda"), arm)
    assert str(e.value) == ("scenario field 'object.joint' = 'world_welds_to_panda_link0': a weld joint of 0 "
                            "positions; expected a revolute or prismatic joint")


def test_object_parts_without_joints_says_none():
    from drake_skill.station.placement import object_parts

    config = scenario_for_skill("open")
    plant, _ = _object_plant(config)
    config.object.model, config.object.base_body, config.object.joint = "world", "world", "hinge"
    with pytest.raises(ValueError) as e:      # the world's instance: the world body, no joints
        object_parts(plant, plant.world_body().model_instance(), config)
    assert str(e.value).endswith("has no such joint; expected one of (none)")


@pytest.mark.parametrize("initial, ok", [(0.0, True), (1.9, True), (-0.5e-9, True), (1.9 + 0.5e-9, True),
                                         (0.0 - 1e-9, True), (1.9 + 1e-9, True),
                                         (-2e-9, False), (1.9 + 2e-9, False)])
def test_object_parts_initial_joint_within_the_limits_to_a_nanometre(initial, ok):
    from drake_skill.station.placement import object_parts

    config = scenario_for_skill("open")           # the lid's hinge: [0, 1.9] rad
    plant, obj = _object_plant(config)
    config.object.initial_joint = initial
    if ok:
        assert object_parts(plant, obj, config)[1].name() == "lid_hinge"
        return
    with pytest.raises(ValueError) as e:
        object_parts(plant, obj, config)
    assert str(e.value) == (f"scenario field 'object.initial_joint' = {initial!r}: expected a position "
                            "within the joint's limits [0.0, 1.9]")


def test_object_parts_are_those_of_the_given_model_instance():
    """Two copies of the box in one plant: the parts come from the instance passed, not by name alone."""
    from pydrake.multibody.parsing import Parser
    from pydrake.multibody.plant import MultibodyPlant

    from drake_skill.station.models import add_package_paths, model_url
    from drake_skill.station.placement import object_parts

    plant = MultibodyPlant(time_step=0.0)
    parser = Parser(plant)
    add_package_paths(parser.package_map())
    parser.SetAutoRenaming(True)
    first = parser.AddModels(url=model_url("box.sdf"))[0]
    second = parser.AddModels(url=model_url("box.sdf"))[0]
    config = scenario_for_skill("open")
    for instance in (first, second):
        base, joint = object_parts(plant, instance, config)
        assert base.model_instance() == instance and joint.model_instance() == instance
