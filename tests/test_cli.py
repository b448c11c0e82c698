"""The drake-skill command line: dispatch, help and errors."""

import json

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
