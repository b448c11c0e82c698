"""A YAML field of the wrong type or an unknown key names the file, the field and the fix
(issue 47 item 1): the valid keys and the nearest one, in dataclasses and Drake's config
structs alike, at any depth."""

import re
from pathlib import Path
import pytest

from drake_skill.cli.main import main
from drake_skill.typed_yaml import load_typed
from drake_skill.learning.config import LearnConfig
from drake_skill.station.scenario import Scenario


@pytest.mark.parametrize("text, expected", [
    ("object: {x: 0.6, yy: 1}\n", "field 'object': unknown key 'yy'; valid keys: model, base_body, joint, x, y, "),
    ("object: {yy: 1}\n", "did you mean 'y'?"),
    ("camera: {fps: ten}\n", "field 'camera.fps' = 'ten': expected a number"),
    ("plant: {time_stepp: 0.001}\n", "field 'plant': unknown key 'time_stepp'; valid keys: time_step, "),
    ("plant: {time_stepp: 0.001}\n", "did you mean 'time_step'?"),
    ("reflex: {enabled: maybe}\n", "field 'reflex.enabled' = 'maybe': expected true or false"),
    ("q_home: [0, 0, zero, 0, 0, 0, 0]\n", "field 'q_home[2]' = 'zero': expected a number"),
    ("objekt: {}\n", "field '(top level)': unknown key 'objekt'; valid keys: "),
])
def test_a_station_field_of_the_wrong_type_or_name_is_named(tmp_path, text, expected):
    path = tmp_path / "scene.yaml"
    path.write_text(text)
    with pytest.raises(ValueError) as raised:
        load_typed(Scenario, what="scenario", path=path)
    message = str(raised.value)
    assert message.startswith(f"scenario ({path}): ") and expected in message and "\n" not in message


def test_the_commands_name_the_field_in_one_line(tmp_path, capsys):
    (tmp_path / "learn.yaml").write_text("learn: {episodes: five}\n")
    assert main(["learn", "--skill", "open", "--config", str(tmp_path / "learn.yaml"), "--print-config"]) == 2
    err = capsys.readouterr().err
    assert err == f"drake-skill: error: --config ({tmp_path / 'learn.yaml'}): field 'learn.episodes' = 'five': " \
                  "expected an integer\n"
    (tmp_path / "push.yaml").write_text("name: push\nscenario: drawer\nsucess: {}\n")
    assert main(["skills", str(tmp_path / "push.yaml")]) == 2
    assert "unknown key 'sucess'; valid keys: name, description, scenario" in capsys.readouterr().err


def test_a_file_that_loads_is_not_diagnosed(tmp_path):
    """Tagged values (!Rpy) and Drake structs pass the walk untouched when the file is right."""
    (tmp_path / "ok.yaml").write_text("learn: {episodes: 3}\n")
    from drake_skill.cli.learn_config import LearnFile

    assert load_typed(LearnFile, what="--config", path=tmp_path / "ok.yaml").learn.episodes == 3
    with pytest.raises(ValueError, match="field 'episodes' = 2.5: expected an integer"):
        load_typed(LearnConfig, what="learn config", data="episodes: 2.5\n")


def test_a_damaged_run_or_grid_file_names_itself_and_the_fix(tmp_path):
    """A JSON or table file cut short (issue 47): one line with the file, where, and what to do."""
    from drake_skill.experiments.table import COLUMNS, read_table, stored_runs
    from drake_skill.learning.loop import RunState

    (tmp_path / "checkpoint").mkdir()
    (tmp_path / "checkpoint" / "state.json").write_text('{"format": 2, "episode": 3, "records": [')
    with pytest.raises(ValueError) as raised:
        RunState.load(tmp_path / "checkpoint")
    assert str(raised.value).startswith(f"{tmp_path / 'checkpoint' / 'state.json'}: damaged JSON (")
    assert "start over with --force, or delete the run folder" in str(raised.value)

    run = tmp_path / "grid" / "open" / "pi2" / "dense" / "run_000"
    run.mkdir(parents=True)
    (run / "summary.json").write_bytes(b'{"skill": "op\xff')
    with pytest.raises(ValueError, match=r"summary.json: damaged JSON \(not UTF-8 text\); delete that run's folder"):
        stored_runs(tmp_path / "grid")
    (run / "summary.json").write_text('{"skil": "open", "method": "pi2", "reward": "dense", "run": 0}')
    with pytest.raises(ValueError, match=r"summary.json: not a run summary \(needs skill, method, reward, run\)"):
        stored_runs(tmp_path / "grid")

    from drake_skill.learning.runlog import PROGRESS_COLUMNS, read_progress

    progress = tmp_path / "progress.csv"
    progress.write_bytes((",".join(PROGRESS_COLUMNS) + "\n").encode() + b"\xff\xfe0,1")
    with pytest.raises(ValueError, match=r"progress.csv: damaged CSV \(.*\); summary.json and results.jsonl beside it"):
        read_progress(progress)

    table = tmp_path / "table.csv"
    table.write_text(",".join(COLUMNS) + "\n" + "open,pi2,dense,0,1")
    with pytest.raises(ValueError) as raised:
        read_table(table)
    assert str(raised.value).startswith(f"{table}: line 2: column '") and "writes the table again" in \
        str(raised.value)


# The workcell (models/workcell.dmd.yaml) written out as a user's scenario may write it: the robot's
# add_directives, the table and its weld (``{child}``: the weld's child frame), as directives[0..2].
WORKCELL = """- add_directives: {{file: "package://drake_skill_models/panda_robot.dmd.yaml"}}
- add_model: {{name: table, file: "package://drake_skill_models/table.sdf"}}
- add_weld: {{parent: world, child: {child}}}
"""
WORKCELL_LINE = '- add_directives: {file: "package://drake_skill_models/workcell.dmd.yaml"}\n'


@pytest.mark.parametrize("child, expected", [
    ("table::table_topp", "no frame 'table_topp' in model 'table' (its frames: __model__, table_top)"),
    ("tablee::table_top", "There is no model instance named 'tablee'"),
])
def test_a_directive_naming_no_frame_or_model_is_named_by_its_index(child, expected):
    """A scenario's weld to a frame or model that does not exist: Drake's RuntimeError (a traceback,
    once) becomes one line naming the directive (issue 47)."""
    from pydrake.common.yaml import yaml_load_typed
    from pydrake.multibody.parsing import ModelDirectives

    from drake_skill.skills import scenario_for_skill
    from drake_skill.station.make import make_station

    config = scenario_for_skill("open")
    config.enable_camera = False
    config.directives = yaml_load_typed(schema=ModelDirectives, data="directives:\n" + WORKCELL.format(child=child)
                                        + '- add_model: {name: box, file: "package://drake_skill_models/box.sdf"}\n'
                                        ).directives
    with pytest.raises(ValueError) as raised:
        make_station(config)
    message = str(raised.value)
    assert message.startswith(f"scenario directives[2] (add_weld {{parent: world, child: {child}}}): ")
    assert expected in message and message.endswith("; fix that directive") and "\n" not in message


@pytest.mark.parametrize("edit, expected", [
    ((WORKCELL_LINE, WORKCELL.format(child="table::table_topX")),
     "directives[2] (add_weld {parent: world, child: table::table_topX}): no frame 'table_topX' in model 'table'"),
    (("package://drake_skill_models/drawer.sdf", "broken.sdf"), "directives[1] (add_model {name: drawer, file: file://"),
])
def test_a_scenario_file_with_a_bad_directive_is_one_line_naming_the_file(tmp_path, capsys, edit, expected):
    _bad_scenario(tmp_path, capsys, edit, f"scenario {expected}", "; fix that directive")


def test_a_scenario_including_a_missing_directives_file_names_the_scenario_and_the_field(tmp_path, capsys):
    _bad_scenario(tmp_path, capsys, ("package://drake_skill_models/workcell.dmd.yaml", "no_workcell.dmd.yaml"),
                  "scenario field 'directives[0].add_directives.file' = 'file://",
                  "no_workcell.dmd.yaml does not exist)")


def _bad_scenario(tmp_path, capsys, edit, expected, end):
    """A weld to a frame no model has, or a model file Drake cannot parse: found where the scenario
    file loads, one line naming the file, the directive and its index, exit 2 (issues 46, 47)."""
    import drake_skill

    package = Path(drake_skill.__file__).parent
    (tmp_path / "broken.sdf").write_text('<sdf version="1.7"><model name="drawer"><link name="x"></model></sdf>')
    scenario = tmp_path / "scene.yaml"
    text = (package / "station" / "scenarios" / "drawer.yaml").read_text()
    assert edit[0] in text
    scenario.write_text(text.replace(edit[0], edit[1]))
    skill = tmp_path / "skill.yaml"
    skill.write_text(re.sub(r"(?m)^scenario:.*$", f"scenario: {scenario}",
                            (package / "skills" / "draw.yaml").read_text()))
    code = main(["skills", str(skill), "--check-camera"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "\n" not in err and "Traceback" not in err
    assert f"scenario ({scenario}): {expected}" in err and err.endswith(end), err


@pytest.mark.parametrize("edit, expected, end", [
    (("plant:", "driver: !PandaDriver {lcm_url: memq://}\nplant:"), "field 'driver': unknown type '!PandaDriver'; ",
     "valid types: !EndEffectorDriver, !JointSetpointDriver, !PandaLcmDriver"),
    (("plant:", "driver: {lcm_url: memq://}\nplant:"), "field 'driver': unknown key 'lcm_url'; valid keys: (none) ",
     "or 'driver: !PandaLcmDriver {...}')"),
    (("add_model: {name: drawer,", "add_model: {name: cabinet,"),
     "scenario field 'object.model' = 'drawer': expected the name of a model the directives add ",
     "(cabinet, panda, panda_hand, table)"),
])
def test_a_scenario_naming_an_unknown_driver_or_instance_is_one_line_naming_the_file(tmp_path, capsys, edit,
                                                                                      expected, end):
    """The driver is a scenario field (issue 46 item 2): an unknown type tag, or an untagged driver
    with another type's keys; and an object instance the directives do not add."""
    _bad_scenario(tmp_path, capsys, edit, expected, end)


def test_scenario_text_overrides_are_layered_after_the_file_and_named_in_errors(tmp_path, capsys):
    """--scenario FILE, then each --scenario-text in turn (issue 46 item 1: CLI flags are overrides
    on the one Scenario); a bad override is one line naming the file, the override and the field."""
    from drake_skill.inputs import scenario

    path = tmp_path / "scene.yaml"
    path.write_text("object: {x: 0.5}\nenable_camera: false\n")
    config = scenario("draw", path, ["object: {x: 0.6}", "driver: !PandaLcmDriver {lcm_url: memq://}",
                                     "driver: !PandaLcmDriver {status_timeout: 0.5}"])
    assert (config.object.x, config.enable_camera) == (0.6, False)
    assert (config.driver.lcm_url, config.driver.status_timeout) == ("memq://", 0.5)
    assert main(["skills", "draw", "--check-camera", "--scenario", str(path), "--scenario-text", "object: {x: 3}"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"drake-skill: error: --scenario {path}: scenario ({path} + override 'object: {{x: 3}}'): "
                          "scenario field 'object.x/object.y' = (3.0, 0.0)") and "\n" not in err, err


def test_a_key_written_one_level_too_high_is_pointed_to_where_it_lives(tmp_path):
    """An old hardware file (``lcm_url:`` at the top, before the channels moved into the scenario's
    ``driver: !PandaLcmDriver``) and a colour bound outside ``object.colour`` are told where the key lives."""
    path = tmp_path / "hardware.yaml"
    path.write_text("lcm_url: memq://\n")
    with pytest.raises(ValueError) as raised:
        load_typed(Scenario, what="scenario", path=path)
    assert str(raised.value).endswith("; 'lcm_url' is a key of 'driver' (!PandaLcmDriver)")
    path.write_text("object: {hue_min_deg: 3}\n")
    with pytest.raises(ValueError) as raised:
        load_typed(Scenario, what="scenario", path=path)
    assert str(raised.value).endswith("unknown key 'hue_min_deg'; valid keys: model, base_body, joint, x, y, yaw, "
                                      "initial_joint, randomize_xy, randomize_yaw, gravity, joint_damping, "
                                      "joint_friction, joint_friction_gain, colour, footprint_heights; "
                                      "'hue_min_deg' is a key of 'object.colour'")
