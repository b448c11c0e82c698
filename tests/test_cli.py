"""The drake-skill command line: dispatch, help and errors."""

import json
import re
from pathlib import Path

from drake_skill.cli import main as cli_main
from drake_skill.cli.main import main


def test_help_lists_commands(capsys):
    assert main(["--help"]) == 0
    out = capsys.readouterr().out
    for command in ("station-demo", "demos", "fit", "bench"):
        assert command in out


def test_unknown_command_and_benchmark_fail_with_status_2(capsys):
    assert main(["frobnicate"]) == 2
    assert "unknown command 'frobnicate'" in capsys.readouterr().err
    assert main(["bench", "teapot"]) == 2
    assert "unknown benchmark 'teapot'" in capsys.readouterr().err


def test_bench_reward_json_is_one_object(capsys):
    assert main(["bench", "reward", "--json", "--repeats", "5", "--no-fit"]) == 0
    result = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert result["reward_ms"] > 0


def test_station_demo_writes_results(tmp_path, capsys):
    assert main(["station-demo", "--skills", "draw", "--seed", "3", "--out", str(tmp_path)]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["draw"]["scripted_success"] and not summary["draw"]["parked_success"]
    assert (tmp_path / "object_state.png").stat().st_size > 0
    assert (tmp_path / "camera_draw.png").stat().st_size > 0
    assert "draw" in capsys.readouterr().out


# ------------------------------------------------------------- one argparse tree

def test_global_options_are_in_help_and_version_prints(capsys):
    assert main(["--help"]) == 0
    out = capsys.readouterr().out
    assert "--verbose" in out and "--version" in out
    assert main(["--version"]) == 0
    from drake_skill import __version__
    assert capsys.readouterr().out.strip() == f"drake-skill {__version__}"


def test_help_texts_have_no_restructuredtext_markup(capsys):
    names = [m.NAME for m in cli_main.available_commands()]
    assert {"station-demo", "demos", "fit", "bench"} <= set(names)
    for argv in [["--help"], *([n, "--help"] for n in names), ["demos", "record", "--help"],
                 ["hardware", "record-demo", "--help"]]:
        assert main(argv) == 0, argv
        text = capsys.readouterr().out
        assert "``" not in text and not re.search(r":(class|func|meth|mod):`", text), argv
    # The markup is stripped through ArgumentParser's public API, no argparse internals.
    source = Path(cli_main.__file__).read_text()
    assert not re.search(r"argparse\._|\._actions|_choices_actions", source)


def test_missing_command_modules_are_skipped(monkeypatch, capsys):
    monkeypatch.setattr(cli_main, "COMMANDS", ["fit", "no_such_command_module", "bench"])
    assert main(["--help"]) == 0
    out = capsys.readouterr().out
    assert "fit" in out and "bench" in out and "no_such" not in out


def test_bench_discovers_modules():
    from drake_skill.cli.bench import benchmarks
    assert {"dmp", "perception", "reward", "station"} <= set(benchmarks())


def test_fit_missing_folder_is_one_line_and_status_2(capsys):
    assert main(["fit", "--demos", "missing_folder", "--out", "x"]) == 2
    err = capsys.readouterr().err
    assert err.strip().splitlines() == ["drake-skill: error: --demos missing_folder: no such folder; give the "
                                        "folder of demo_*.npz files (drake-skill demos record)"]
    assert "Traceback" not in err
    assert main(["fit", "--demos", "missing_folder", "--out", "x", "--verbose"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("Traceback (most recent call last):") and "FileNotFoundError" in err
    assert err.strip().splitlines()[-1].startswith("drake-skill: error: --demos missing_folder")
    assert main(["--verbose", "fit", "--demos", "missing_folder", "--out", "x"]) == 2
    assert "Traceback" in capsys.readouterr().err


def _one_error_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("drake-skill: error: "), err
    return err[0]


def test_user_errors_are_checked_before_work(tmp_path, capsys):
    demos = tmp_path / "demos"
    demos.mkdir()
    afile = tmp_path / "afile"
    afile.write_text("x")
    # --out that is a file: refused before the demonstrations are even read.
    assert main(["fit", "--demos", str(demos), "--out", str(afile)]) == 2
    assert f"--out {afile}: exists and is a file" in _one_error_line(capsys)
    # A --config that is not valid YAML, and one with an unknown key.
    bad = tmp_path / "bad.yaml"
    bad.write_text("skill: [\n")
    assert main(["fit", "--demos", str(demos), "--out", str(tmp_path / "o"), "--config", str(bad)]) == 2
    assert f"--config ({bad}):" in _one_error_line(capsys)     # one format: drake_skill.typed_yaml
    typo = tmp_path / "typo.yaml"
    typo.write_text("dmp: {n_bases: 3}\n")
    assert main(["fit", "--demos", str(demos), "--out", str(tmp_path / "o"), "--config", str(typo)]) == 2
    assert "n_bases" in _one_error_line(capsys)
    # An empty demonstrations folder.
    assert main(["fit", "--demos", str(demos), "--out", str(tmp_path / "o")]) == 2
    assert "no demo_*.npz files" in _one_error_line(capsys)
    # A non-empty folder that holds no skill is never replaced.
    other = tmp_path / "other"
    other.mkdir()
    (other / "notes.txt").write_text("mine")
    assert main(["fit", "--demos", str(demos), "--out", str(other), "--force"]) == 2
    assert "holds no skill" in _one_error_line(capsys)
    # demos record: --out is a file, bad --count, missing --config.
    assert main(["demos", "record", "--skill", "open", "--out", str(afile)]) == 2
    assert f"--out {afile}: exists and is a file" in _one_error_line(capsys)
    assert main(["demos", "record", "--skill", "open", "--count", "-1", "--out", str(tmp_path / "d")]) == 2
    assert "--count -1" in _one_error_line(capsys)
    assert main(["demos", "record", "--skill", "open", "--out", str(tmp_path / "d"),
                 "--config", str(tmp_path / "none.yaml")]) == 2
    assert "--config" in _one_error_line(capsys) and not (tmp_path / "d").exists()
    # Argument errors are one line too.
    assert main(["fit"]) == 2
    assert "fit: the following arguments are required: --demos, --out" in _one_error_line(capsys)


def test_scenario_option_on_every_station_command(tmp_path, capsys):
    bad = tmp_path / "scenario.yaml"
    bad.write_text("camera: {fps: -3}\n")
    for argv in (["station-demo", "--skills", "open"], ["demos", "record", "--skill", "open"]):
        assert main([*argv, "--scenario", str(bad), "--out", str(tmp_path / "o")]) == 2
        line = _one_error_line(capsys)
        assert f"--scenario {bad}" in line and "camera.fps" in line, line
        assert main([*argv, "--scenario", str(tmp_path / "none.yaml"), "--out", str(tmp_path / "o")]) == 2
        assert "no such file" in _one_error_line(capsys)
    assert not (tmp_path / "o").exists()


def test_a_closed_pipe_ends_the_command_quietly():
    """``drake-skill skills open | head -2``: the reader is gone before the command writes."""
    import subprocess
    import sys

    child = subprocess.Popen([sys.executable, "-m", "drake_skill.cli.main", "skills", "open"],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    child.stdout.close()          # as head does after its lines (here before the first one)
    err = child.stderr.read().decode()
    assert child.wait(timeout=60) == 0 and err == "", err
