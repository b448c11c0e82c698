"""Skills as data: the shipped skill files, the loader's checks and the keyframes' follow-through."""

import math
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from drake_skill.skills import keyframes, load_skill, shipped_skill_names
from drake_skill.skills.spec import REACH_M, SHOULDER
from drake_skill.station.scenario import SuccessConfig

SKILL = """\
name: {name}
scenario: {scenario}
demonstrations: 2
dmp_bases: 10
exploration_scale: 0.5
success: {{joint: {joint}, {rule}}}
keyframes:
  - {{t: 1.0, gripper: 0.0, pose: {{translation: {p1}, rotation: !Rpy {{deg: [180.0, 0.0, 0.0]}}}}}}
  - {{t: 2.0, gripper: 0.0, pose: {{translation: [-0.1, 0.0, 0.3], rotation: !Rpy {{deg: [180.0, 0.0, 0.0]}}}}}}
"""


def _write(tmp_path, name="push", scenario="drawer", joint="drawer_slide", rule="above: 0.05",
           p1="[-0.2, 0.0, 0.3]", text=None):
    path = tmp_path / f"{name}.yaml"
    path.write_text(text if text is not None else SKILL.format(name=name, scenario=scenario, joint=joint,
                                                                 rule=rule, p1=p1))
    return path


#: The shipped skills by name: the thesis's three, Slide, and the new kinds of object
#: (docs/skills.md "The shipped skills").
SHIPPED = ["close", "draw", "open", "press", "push", "slide", "swing", "tilt", "turn"]


def test_the_shipped_skills_are_data_files():
    assert shipped_skill_names() == SHIPPED
    opened, closed, drawn = load_skill("open"), load_skill("close"), load_skill("draw")
    # Thesis 6.2 and Table 6.1; docs/method.md section 5 for the exploration scales.
    # dmp_bases left out: fit chooses B from the tolerance (docs/method.md 2.2); the thesis's
    # Table 6.1 values live with its reproduction (drake_skill.fitted_skill.THESIS_DMP_BASES).
    assert [(s.demonstrations, s.dmp_bases, s.exploration_scale) for s in (opened, closed, drawn)] == [
        (3, None, 0.1), (2, None, 1.0), (2, None, 0.1)]
    assert [s.scenario_path().name for s in (opened, closed, drawn)] == ["box_closed.yaml", "box_open.yaml",
                                                                         "drawer.yaml"]
    assert [len(s.keyframes) for s in (opened, closed, drawn)] == [16, 10, 6]
    # Draw keeps its hook's x_O and starts from its best-imitating demonstration (docs/method.md 2, 5).
    assert [(s.dmp_unscaled_dims, s.initial_dmp) for s in (opened, closed, drawn)] == [
        ([], "random"), ([], "random"), ([0], "best-return")]
    # Open's first via point: the hand turned to point along the hinge, 0.2 m above the lip's side.
    t, p, R, w = keyframes(opened)[0]
    assert (t, w) == (3.0, 0.08)
    np.testing.assert_allclose(p, [-0.1615, -0.209, 0.315], atol=1e-12)
    np.testing.assert_allclose(R.col(2), [0.0, 1.0, 0.0], atol=1e-12)      # the hand points along +y_O


def test_follow_through_moves_along_the_screw_from_least_to_pose():
    """Open's sweep turns the hand with the lid about the hinge: every follow-through keeps the
    fingertip at the same distance from the hinge axis (a straight blend would cut the arc)."""
    spec = load_skill("open")
    hinge = np.array([0.10, 0.13])               # models/box.sdf: the hinge axis along y_O at (x, z)
    full, least, half = keyframes(spec, 1.0), keyframes(spec, 0.0), keyframes(spec, 0.5)
    moved = [i for i, k in enumerate(spec.keyframes) if k.least is not None]
    assert len(moved) == 10
    for i in moved[:-2]:                          # the sweep's via points (the last two leave sideways)
        radius = [np.linalg.norm(f[i][1][[0, 2]] - hinge) for f in (full, least, half)]
        np.testing.assert_allclose(radius, radius[0], atol=1e-12)
    last = moved[-3]
    assert not np.allclose(half[last][1], 0.5 * (full[last][1] + least[last][1]), atol=1e-4)
    # Keyframes that do not move with the object are the same at any follow-through.
    for i in set(range(len(full))) - set(moved):
        np.testing.assert_array_equal(half[i][1], full[i][1])
    with pytest.raises(ValueError, match="follow_through"):
        keyframes(spec, 1.5)


def test_a_users_skill_file_loads_with_its_scenario_relative_to_it(tmp_path):
    (tmp_path / "scenes").mkdir()
    scene = (load_skill("draw").scenario_path().read_text()).replace("x: 0.68", "x: 0.62")
    (tmp_path / "scenes" / "my_drawer.yaml").write_text(scene)
    spec = load_skill(_write(tmp_path, scenario="scenes/my_drawer.yaml"))
    config = spec.station_config()
    assert spec.name == "push" and config.object.x == 0.62
    assert (config.success.joint, config.success.above) == ("drawer_slide", 0.05)


@pytest.mark.parametrize("changes, field", [
    (dict(scenario="nowhere.yaml"), "scenario"),
    (dict(scenario="cupboard"), "scenario"),
    (dict(joint="lid_hinge"), "success.joint"),
    (dict(rule="above: 0.1, below: 0.2"), "success.above/below"),
    (dict(rule="settle_time: 1.0"), "success.above/below"),
    (dict(p1="[-0.2, 0.0, 1.2]"), "keyframes[0].pose"),
    (dict(name="my skill"), "name"),
    (dict(text="name: push\nscenario: drawer\nsucess: {}\n"), "sucess"),
    (dict(text="name: push\nscenario: drawer\ninitial_dmp: best\n"), "initial_dmp"),
    (dict(text="name: push\nscenario: drawer\ninitial_dmp_poses: 0\n"), "initial_dmp_poses"),
    (dict(text="name: push\nscenario: drawer\ndmp_unscaled_dims: [0, 7]\n"), "dmp_unscaled_dims"),
    (dict(text="name: push\nscenario: drawer\ndmp_unscaled_dims: [1, 1]\n"), "dmp_unscaled_dims"),
    # A keyframe time that repeats the previous one (issue 47: a `>=` for `>` went uncaught).
    (dict(text=SKILL.format(name="push", scenario="drawer", joint="drawer_slide", rule="above: 0.05",
                            p1="[-0.2, 0.0, 0.3]").replace("t: 2.0", "t: 1.0")), "keyframes[1].t"),
])
def test_a_bad_skill_file_is_one_line_naming_the_file_and_the_field(tmp_path, changes, field):
    path = _write(tmp_path, **changes)
    with pytest.raises((ValueError, FileNotFoundError)) as raised:
        load_skill(path)
    message = str(raised.value)
    assert "\n" not in message and str(path) in message and field in message, message
    assert message.count(str(path)) == 1, f"the file named twice: {message}"


def test_keyframes_beyond_the_reach_name_the_distance(tmp_path):
    reach = r"keyframes\[0\]\.pose.*within the Panda's 0.855 m reach.*m from the shoulder"
    with pytest.raises(ValueError, match=reach):
        load_skill(_write(tmp_path, p1="[0.3, 0.0, 0.3]"))
    # The shipped skills stay within it on every pose their scenarios draw.
    for name in shipped_skill_names():
        spec = load_skill(name)
        obj = spec.station_config().object
        for _, p, _, _ in keyframes(spec):
            far = np.linalg.norm(np.array([obj.x + p[0], obj.y + p[1], p[2]]) - SHOULDER)
            assert far < REACH_M + 0.05


def test_skills_command_lists_the_shipped_skills_and_checks_a_file(tmp_path):
    listing = subprocess.run([sys.executable, "-m", "drake_skill.cli.main", "skills"], capture_output=True,
                             text=True, check=True).stdout
    assert [line.split()[0] for line in listing.splitlines()[1:1 + len(SHIPPED)]] == SHIPPED
    assert re.search(r"open\s+box_closed\s+3\s+auto\s+0.1\s+random\s+lid_hinge >= 1.7 after 1 s\s+16", listing)
    assert re.search(r"draw\s+drawer\s+2\s+auto\s+0.1\s+best-return\s+drawer_slide >= 0.1 after 1 s\s+6", listing)
    bad = subprocess.run([sys.executable, "-m", "drake_skill.cli.main", "skills",
                          str(_write(tmp_path, joint="lid_hinge"))], capture_output=True, text=True)
    assert bad.returncode == 2 and "success.joint" in bad.stderr and len(bad.stderr.strip().splitlines()) == 1


# ----------------------------------------------------------------------------- the checks' bounds, one field each
def _spec(**changes):
    """A valid skill (the drawer's scenario, one keyframe) with ``changes``."""
    from drake_skill.skills.spec import Keyframe, SkillSpec

    fields = dict(name="a-b_C9", scenario="drawer", success=SuccessConfig(joint="drawer_slide", above=0.05),
                  keyframes=[Keyframe(t=1.0, gripper=0.0)])
    fields.update(changes)
    return SkillSpec(**fields)


def _check_message(**changes):
    from drake_skill.skills.spec import _check

    try:
        _check(_spec(**changes), "W")
    except ValueError as e:
        return str(e)
    return None


@pytest.mark.parametrize("changes", [
    {}, dict(demonstrations=1), dict(dmp_bases=3), dict(dmp_bases=100), dict(exploration_scale=100.0),
    dict(exploration_scale=1e-9), dict(dmp_unscaled_dims=[0, 6]), dict(initial_dmp="best-return"),
    dict(initial_dmp_poses=1), dict(initial_dmp_poses=100), dict(gripper_opening=0.0), dict(gripper_opening=0.08),
    dict(scenario="drake_skill/station/scenarios/drawer.yaml"),
])
def test_the_edges_of_every_skill_field_are_valid(changes):
    if "scenario" in changes:
        from drake_skill.station.scenario import SCENARIO_DIR

        changes = dict(scenario=str(SCENARIO_DIR / "drawer.yaml"))
    assert _check_message(**changes) is None


def test_each_skill_field_error_in_full():
    from drake_skill.skills.spec import Keyframe
    from drake_skill.station.scenario import SCENARIO_DIR, SuccessConfig

    expected = {
        "name": "a name of letters, digits, '_' and '-'",
    }
    assert _check_message(name="") == f"skill file W field 'name' = '': expected {expected['name']}"
    assert _check_message(name="a.b") == f"skill file W field 'name' = 'a.b': expected {expected['name']}"
    assert _check_message(scenario="") == ("skill file W field 'scenario' = '': expected a shipped scenario's "
                                           "name (drake-skill skills) or a scenario YAML")
    shipped = ", ".join(sorted(p.stem for p in SCENARIO_DIR.glob("*.yaml")))
    assert "drawer" in shipped and "box_closed" in shipped
    assert _check_message(scenario="cupboard") == (
        f"skill file W field 'scenario' = 'cupboard': expected a shipped scenario ({shipped}) or an existing "
        f"YAML file ({SCENARIO_DIR / 'cupboard.yaml'} does not exist)")
    assert _check_message(demonstrations=0) == \
        "skill file W field 'demonstrations' = 0: expected at least 1 (the thesis: 2 or 3)"
    for bases in (2, 101):
        assert _check_message(dmp_bases=bases) == (
            f"skill file W field 'dmp_bases' = {bases}: expected 3..100 basis functions (thesis Table 6.1: 9-20), "
            "or null to choose them from the fit tolerance")
    for scale in (0.0, -1.0, 100.5, math.inf, math.nan):
        assert _check_message(exploration_scale=scale) == \
            f"skill file W field 'exploration_scale' = {scale!r}: expected a factor in (0, 100] on Sigma_b^0"
    for dims in ([-1], [7], [2, 2]):
        assert _check_message(dmp_unscaled_dims=dims) == (
            f"skill file W field 'dmp_unscaled_dims' = {dims!r}: expected distinct weight columns in 0..6 (0-2: "
            "x, y, z; 3-6: quaternion w, x, y, z)")
    assert _check_message(initial_dmp="best") == \
        "skill file W field 'initial_dmp' = 'best': expected one of random, best-return"
    for poses in (0, 101):
        assert _check_message(initial_dmp_poses=poses) == (
            f"skill file W field 'initial_dmp_poses' = {poses}: expected 1..100 object poses per demonstration's DMP")
    for opening in (-0.001, 0.0801):
        assert _check_message(gripper_opening=opening) == (
            f"skill file W field 'gripper_opening' = {opening}: expected an opening in [0, 0.08] m, or null for "
            "the demonstrations' median")
    assert _check_message(success=SuccessConfig(joint="", above=0.05)) == (
        "skill file W field 'success.joint' = '': expected the name of the object's joint the rule reads")
    keys = [Keyframe(t=1.0), Keyframe(t=1.0)]
    assert _check_message(keyframes=keys) == (
        "skill file W field 'keyframes[1].t' = 1.0: expected times that increase from 0 (the previous is 1.0 s)")
    for t in (0.0, math.nan):
        assert _check_message(keyframes=[Keyframe(t=t)]) == (
            f"skill file W field 'keyframes[0].t' = {t!r}: expected times that increase from 0 (the previous is "
            "0.0 s)")
    assert _check_message(keyframes=[Keyframe(t=0.5, gripper=0.08), Keyframe(t=1.0, gripper=0.0801)]) == (
        "skill file W field 'keyframes[1].gripper' = 0.0801: expected an opening in [0, 0.08] m")
    assert _check_message(keyframes=[Keyframe(t=0.5, gripper=-0.001)]).startswith(
        "skill file W field 'keyframes[0].gripper' = -0.001")


def _at_origin(spec, x=0.0, randomize_xy=0.0, randomize_yaw=0.0):
    config = spec.station_config()
    o = config.object
    o.x, o.y, o.yaw, o.randomize_xy, o.randomize_yaw = x, 0.0, 0.0, randomize_xy, randomize_yaw
    return config


def test_reach_is_checked_on_every_corner_of_the_placement_range():
    """Via points just within the 0.855 m reach at the nominal pose, out of it on one corner
    of the placement range: x or y shifted out, or the yaw turned one way."""
    from pydrake.common.schema import Transform

    from drake_skill.skills.spec import Keyframe, check_with_scenario

    def at(p):
        return _spec(keyframes=[Keyframe(t=1.0, pose=Transform(translation=p))])

    def message(spec, config):
        with pytest.raises(ValueError) as e:
            check_with_scenario(spec, config, "W")
        return str(e.value)

    along_x, along_y = at([0.8404, 0.0, 0.333]), at([0.0, -0.84, 0.333])     # 0.84 m from the shoulder
    check_with_scenario(along_x, _at_origin(along_x, randomize_xy=0.01))     # at most 0.85 m
    for spec in (along_x, along_y):
        assert message(spec, _at_origin(spec, randomize_xy=0.02)).endswith(
            "expected a pose within the Panda's 0.855 m reach on every object pose the scenario draws (this one "
            "is 0.86 m from the shoulder); move it or the object closer")
    assert message(along_x, _at_origin(along_x, randomize_xy=0.02)).startswith(
        "skill file W field 'keyframes[0].pose' = [0.84, 0.0, 0.333]: ")
    # Each sign of each loop: -x and +y too, within reach at 0.01 but not at 0.02; the yaw by 0.01 each way.
    for spec in (at([-0.84, 0.0, 0.333]), at([0.0, 0.84, 0.333])):
        check_with_scenario(spec, _at_origin(spec, randomize_xy=0.01))
        assert "(this one is 0.86 m" in message(spec, _at_origin(spec, randomize_xy=0.02))
    for p in ([0.7, 0.3, 0.333], [0.7, -0.3, 0.333]):
        check_with_scenario(at(p), _at_origin(at(p), x=0.1, randomize_yaw=0.01))       # 0.8547 m at most
        assert "(this one is 0.86 m" in message(at(p), _at_origin(at(p), x=0.1, randomize_yaw=0.02))
    # Off the axis, 0.854 m at the nominal pose: turned by -0.1 rad it is 0.857 m away, by +0.1 rad 0.850 m.
    off = at([0.7, 0.3, 0.333])
    check_with_scenario(off, _at_origin(off, x=0.1))
    assert "(this one is 0.86 m" in message(off, _at_origin(off, x=0.1, randomize_yaw=0.1))
    mirrored = at([0.7, -0.3, 0.333])
    assert "(this one is 0.86 m" in message(mirrored, _at_origin(mirrored, x=0.1, randomize_yaw=0.1))
    # The second keyframe is named by its index.
    two = _spec(keyframes=[Keyframe(t=1.0), Keyframe(t=2.0, pose=Transform(translation=[0.9, 0.0, 0.333]))])
    assert message(two, _at_origin(two)).startswith("skill file W field 'keyframes[1].pose' = [0.9, 0.0, 0.333]")
    spec = _spec(success=SuccessConfig(joint="lid_hinge", above=1.0))
    with pytest.raises(ValueError) as e:
        check_with_scenario(spec, spec.station_config())
    assert str(e.value) == ("skill file skill 'a-b_C9' field 'success.joint' = 'lid_hinge': expected the "
                            "scenario's object's one joint, 'drawer_slide'")


def test_follow_through_bounds_and_the_ends_of_the_screw():
    spec = load_skill("open")
    moved = [i for i, k in enumerate(spec.keyframes) if k.least is not None]
    full, least = keyframes(spec, 1.0), keyframes(spec, 0.0)
    for i in moved:
        X, X0 = spec.keyframes[i].pose.GetDeterministicValue(), spec.keyframes[i].least.GetDeterministicValue()
        np.testing.assert_array_equal(full[i][1], X.translation())              # exactly the pose at 1
        np.testing.assert_array_equal(full[i][2].matrix(), X.rotation().matrix())
        np.testing.assert_array_equal(least[i][1], X0.translation())            # exactly least at 0
        assert (full[i][0], full[i][3]) == (spec.keyframes[i].t, spec.keyframes[i].gripper)
    for f in (-1e-9, 1.0 + 1e-9):
        with pytest.raises(ValueError) as e:
            keyframes(spec, f)
        assert str(e.value) == f"follow_through: expected a fraction in [0, 1], got {f!r}"


def test_screw_motion_by_hand():
    """A quarter turn about z with a translation: the screw's pose at 1/2 is an eighth turn,
    half the rise, on the helix; at 0 and below it is the start."""
    from pydrake.math import RigidTransform, RotationMatrix

    from drake_skill.skills.spec import _screw

    X0 = RigidTransform([1.0, 0.0, 0.0])
    X1 = RigidTransform(RotationMatrix.MakeZRotation(np.pi / 2), [0.0, 1.0, 0.4])
    half = _screw(X0, X1, 0.5)
    np.testing.assert_allclose(half.translation(), [np.cos(np.pi / 4), np.sin(np.pi / 4), 0.2], atol=1e-12)
    np.testing.assert_allclose(half.rotation().matrix(), RotationMatrix.MakeZRotation(np.pi / 4).matrix(), atol=1e-12)
    assert _screw(X0, X1, 0.0) is X0 and _screw(X0, X1, -0.5) is X0
    np.testing.assert_allclose(_screw(X0, X1, 1.0).GetAsMatrix4(), X1.GetAsMatrix4(), atol=1e-12)


def test_scenario_paths_and_load_errors(tmp_path):
    from drake_skill.skills.spec import SKILL_DIR, SkillSpec, scenario_for_skill
    from drake_skill.station.scenario import SCENARIO_DIR

    assert SkillSpec(scenario="drawer").scenario_path() == SCENARIO_DIR / "drawer.yaml"
    for text in ("my.yaml", "my.yml", "scenes/drawer"):
        assert SkillSpec(scenario=text).scenario_path() == Path(text)
    assert SkillSpec(scenario="").scenario_path() == Path("")
    spec = load_skill("draw")
    assert load_skill(spec) is spec
    assert (SKILL_DIR / "draw.yaml").is_file()
    names = ", ".join(shipped_skill_names())
    with pytest.raises(FileNotFoundError) as e:
        load_skill("jump")
    assert str(e.value) == (f"skill 'jump': not a shipped skill ({names}) and not a file; give one of those or a "
                            "path to a skill YAML")
    for text in (str(tmp_path / "jump.yaml"), "jump.yml", "nowhere/jump"):
        with pytest.raises(FileNotFoundError) as e:
            load_skill(text)
        assert str(e.value) == (f"skill file {text}: no such file; give a shipped skill's name ({names}) or an "
                                "existing skill YAML")
    path = _write(tmp_path, text="name: push\nscenario: drawer\nsucess: {}\n")
    with pytest.raises(ValueError) as e:
        load_skill(path)
    assert str(e.value).endswith("; see docs/skills.md for the fields") and str(path) in str(e.value)
    assert str(e.value).startswith(f"skill file ({path}): field ")
    # The reach check names the skill file itself (no scenario prefix).
    far = _write(tmp_path, name="far", p1="[0.3, 0.0, 0.3]")
    with pytest.raises(ValueError) as e:
        load_skill(far)
    assert str(e.value).startswith(f"skill file {far} field 'keyframes[0].pose' = ")
    # A scenario whose own check fails (a bad scenario file) is named after the skill file.
    (tmp_path / "bad.yaml").write_text(load_skill("draw").scenario_path().read_text() + "\ntime_step: -1.0\n")
    path = _write(tmp_path, scenario="bad.yaml")
    with pytest.raises(ValueError) as e:
        load_skill(path)
    assert str(e.value).startswith(f"{path}: scenario {tmp_path / 'bad.yaml'}: ")
    # An absolute scenario path is kept as it is.
    absolute = _write(tmp_path, name="abs", scenario=str(SCENARIO_DIR / "drawer.yaml"))
    assert load_skill(absolute).scenario == str(SCENARIO_DIR / "drawer.yaml")
    assert scenario_for_skill("draw").success.joint == "drawer_slide"
    defaults = load_skill("draw").station_defaults()
    assert defaults.object.model == "drawer" and defaults.success == load_skill("draw").success
    (tmp_path / "over.yaml").write_text("object: {x: 0.61}\n")
    over = load_skill("draw").station_defaults(tmp_path / "over.yaml")
    assert over.object.x == 0.61 and over.object.model == "drawer" and over.success.joint == "drawer_slide"
