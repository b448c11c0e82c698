"""``drake-skill learn`` end to end (1 episode x 2 rollouts) and ``drake-skill evaluate``."""

import dataclasses as dc
import json
import subprocess
from importlib import metadata
from pathlib import Path

import numpy as np
import pytest

import drake_skill
from drake_skill.cli.main import main
from drake_skill.learning.evaluation import (CHOICE_SEED0, HELD_OUT_SEED0, apply_initial_rule, best_return_index,
                                            save_fitted_skill)
from drake_skill.learning.loop import ARTIFACTS
from drake_skill.learning.plots import plot_outcomes_by_placement
from drake_skill.learning.runlog import VERSIONED_PACKAGES, read_progress
from drake_skill.skills import load_skill
from drake_skill.fitted_skill import Skill
from drake_skill.station.sim.builder import Station
from pydrake.math import RollPitchYaw

from learning_support import shared_skill


@pytest.fixture(scope="module")
def learned(tmp_path_factory):
    shared = shared_skill(tmp_path_factory)
    out = tmp_path_factory.mktemp("learn_cli") / "run"
    argv = ["learn", "--skill-dir", str(shared["skill_dir"]), "--station-config", str(shared["station_yaml"]),
            "--episodes", "1", "--rollouts", "2", "--held-out", "2", "--seed", "5", "--select-poses", "1",
            "--out", str(out), "--quiet"]
    assert main(argv) == 0
    return shared, out, argv


def test_learn_writes_every_artifact(learned, capsys):
    shared, out, _ = learned
    for name in ARTIFACTS:
        assert (out / name.rstrip("/")).exists(), f"{name} missing"
    summary = json.loads((out / "summary.json").read_text())
    assert summary["method"] == "pi2-es-cov" and summary["reward"] == "dense" and summary["weighting"] == "thesis"
    assert [c["episode"] for c in summary["curve"]] == [0, 1]
    # No --exploration-scale: the skill's default, saved as the number used.
    name = Skill.load(shared["skill_dir"]).name
    recorded = json.loads((out / "config.json").read_text())
    assert recorded["learn"]["exploration_scale"] == load_skill(name).exploration_scale
    # config.json records the software the run used and the commit of the checkout it ran from.
    versions = json.loads((out / "config.json").read_text())["versions"]
    assert {k: versions[k] for k in VERSIONED_PACKAGES} == {k: metadata.version(k) for k in VERSIONED_PACKAGES}
    checkout = Path(drake_skill.__file__).resolve().parents[1]
    head = subprocess.run(["git", "-C", str(checkout), "rev-parse", "HEAD"], capture_output=True, text=True)
    assert versions["git_commit"] == (head.stdout.strip() if head.returncode == 0 else None)
    assert versions["git_commit"] is None or len(versions["git_commit"]) == 40
    assert summary["n_rollouts"] == 2
    # The learned reward's quality over the run's rollouts (issue 45; learning/reward_quality.py).
    # Both rollouts tripped the reflex: nothing to rank, and the rate says so.
    assert {k: summary[k] for k in ("reward_auc", "verdict_fpr", "verdict_fnr", "reflex_rate")} == {
        "reward_auc": None, "verdict_fpr": None, "verdict_fnr": None, "reflex_rate": 1.0}
    records = [json.loads(line) for line in (out / "results.jsonl").read_text().splitlines()]
    # Seed 5: the greedy execution succeeds on its pose before learning and fails after
    # the one update (both rollouts failed). The guarded selection (docs/method.md 5.1) sees it
    # by the learned verdicts and returns alone and returns the start: of the two held-out poses the
    # second succeeds before learning and after (the last mean succeeded on neither).
    assert summary["greedy_success"] == [True, False]
    assert (summary["select"], summary["selected_episode"]) == ("guarded", 0)
    held = [r for r in records if r["type"] == "held_out"]
    assert [r["successes"] for r in held] == [[False, True], [False, True]]
    assert [r["success_rate"] for r in held] == [summary["held_out_before"], summary["held_out_after"]]
    assert summary["held_out_before"] == 0.5 and summary["held_out_after"] == 0.5
    # The greedy execution before learning waits for the one after the update (GREEDY_BATCH = 2).
    assert [r["type"] for r in records] == ["held_out", "rollout", "rollout", "greedy", "episode", "greedy",
                                           "episode", "select", "held_out"]
    select = records[-2]
    # On the selection pose the verdict calls the start a success and the last mean a failure.
    assert [(c["episode"], c["verdict_successes"]) for c in select["candidates"]] == [(0, 1), (1, 0)]
    assert [r["episode"] for r in records if r["type"] == "episode"] == [0, 1]
    # progress.csv: the curve's rows (greedy success True, False, as above).
    rows = read_progress(out / "progress.csv")
    assert [(r["episode"], r["rollouts_used"], r["greedy_success"]) for r in rows] == [(0, 0, 1), (1, 2, 0)]
    assert [r["greedy_return"] for r in rows] == [c["greedy_return"] for c in summary["curve"]]
    for r in records:
        if r["type"] == "rollout":
            assert set(r) >= {"seed", "failed", "reason", "dense_return", "verdict", "success", "wall_s",
                              "ik_warnings", "reward"}
            assert r["reward"] == (0.0 if r["failed"] else r["dense_return"])
    assert (out / "learning_curve.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    for name in ("replay_first.html", "replay_last.html"):
        html = (out / name).read_text()
        assert html.lstrip().lower().startswith("<!doctype html") or "<html" in html[:500].lower()
        assert "animation" in html.lower()
    learned_skill = Skill.load(out / "skill")
    assert learned_skill.info["learning"]["episodes"] == 1
    # The returned skill is the start (selected above), not the last mean.
    np.testing.assert_array_equal(learned_skill.initial_weights, Skill.load(shared["skill_dir"]).initial_weights)


def test_held_out_poses_are_the_fixed_seeds_not_the_training_ones(learned):
    """learn's held-out evaluation, before and after, runs on the poses of seeds
    HELD_OUT_SEED0.. (evaluate's), none of them a pose the search trained on."""
    shared, out, _ = learned
    records = [json.loads(line) for line in (out / "results.jsonl").read_text().splitlines()]
    held = [r for r in records if r["type"] == "held_out"]
    assert [r["phase"] for r in held] == ["before", "after"]
    assert all(r["seeds"] == [HELD_OUT_SEED0, HELD_OUT_SEED0 + 1] for r in held)
    trained = [r["seed"] for r in records if r["type"] in ("rollout", "greedy")]
    assert len(trained) == 4 and not set(trained) & {HELD_OUT_SEED0, HELD_OUT_SEED0 + 1}
    # The poses the held-out rollouts ran on (the simulator's): the station's poses of
    # those seeds, away from every training pose.
    station = Station(dc.replace(shared["station"], enable_camera=False))   # the placement needs no camera
    poses = [station.random_object_pose(HELD_OUT_SEED0 + i) for i in range(2)]
    expected = [[*X.translation()[:2], RollPitchYaw(X.rotation()).yaw_angle()] for X in poses]
    for r in held:
        np.testing.assert_allclose(r["object_poses"], expected, atol=1e-9)
    for seed in trained:
        p = station.random_object_pose(seed).translation()
        assert min(np.linalg.norm(p - X.translation()) for X in poses) > 1e-3


def test_learn_refuses_to_overwrite_and_to_resume_nothing(learned, tmp_path, capsys):
    _, out, argv = learned
    assert main(argv) == 2
    assert "--resume" in capsys.readouterr().err
    empty = tmp_path / "empty"
    assert main([*argv[:-3], "--out", str(empty), "--resume", "--quiet"]) == 2
    assert "no checkpoint" in capsys.readouterr().err
    assert main(["learn", "--episodes", "0", "--out", str(tmp_path / "x")]) == 2
    assert "--episodes" in capsys.readouterr().err


def test_evaluate_the_learned_skill(learned, capsys):
    shared, out, _ = learned
    capsys.readouterr()
    assert main(["evaluate", "--skill-dir", str(out / "skill"), "--station-config", str(shared["station_yaml"]),
                 "--poses", "2", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["learned"] and report["seeds"] == [900000, 900001]
    assert report == json.loads((out / "skill" / "evaluation.json").read_text())
    # The held-out poses of learn's final evaluation are the same poses: the same verdicts.
    held = [json.loads(line) for line in (out / "results.jsonl").read_text().splitlines()][-1]
    policy = report["policies"][str(report["initial_index"])]
    assert policy["successes"] == held["successes"] and policy["returns"] == held["returns"]
    # Per rollout: where the object stood (the station's pose of that seed) and why it failed.
    station = Station(dc.replace(shared["station"], enable_camera=False))   # the placement needs no camera
    for seed, (x, y, yaw) in zip(report["seeds"], policy["object_poses"], strict=True):
        X_WO = station.random_object_pose(seed)
        assert np.allclose([x, y], X_WO.translation()[:2], atol=1e-9)
        assert yaw == pytest.approx(RollPitchYaw(X_WO.rotation()).yaw_angle(), abs=1e-9)
    assert policy["reasons"] == held["reasons"]
    assert sum(reason != "" for reason in policy["reasons"]) == sum(policy["failures"].values())
    assert (out / "skill" / "evaluation.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # The evaluation's rollouts are kept beside its report, with what a replay builds its runner from;
    # they are the same executions as learn's held-out after (the same weights and poses).
    from drake_skill.learning.rollout_store import load_rollout, rollouts_path

    index = report["initial_index"]
    kept = load_rollout(rollouts_path(out / "skill", f"evaluation_dmp_{index}"), 1)
    after = load_rollout(rollouts_path(out, "held_out_after"), 1)
    assert kept["seed"] == 900001 and kept["meta"]["skill_dir"] == str((out / "skill").resolve())
    np.testing.assert_array_equal(kept["weights"], after["weights"])
    np.testing.assert_array_equal(kept["ee_pose"], after["ee_pose"])
    assert main(["replay", str(out / "skill"), "--list"]) == 0
    assert capsys.readouterr().out == f"evaluation_dmp_{index}: 2 rollouts\n"


def test_the_placement_plot_marks_every_outcome(tmp_path):
    """One panel per policy, side by side; a rollout without a placement is left out."""
    report = {"skill": "open", "object_pose": "perceived", "learned": False, "policies": {
        "0": {"initial": False, "success_rate": 0.5, "successes": [True, False, False, False],
              "reasons": ["", "reflex", "", "solver"], "final_object_state": [1.9, None, 0.0, None],
              "object_poses": [[0.58, -0.01, 0.02], [0.61, 0.0, -0.05], [0.60, 0.01, 0.0], None]},
        "1": {"initial": True, "success_rate": 0.0, "successes": [False], "reasons": [""],
              "final_object_state": [0.3], "object_poses": [[0.6, 0.0, 0.0]]}}}
    path = plot_outcomes_by_placement(report, tmp_path / "evaluation.png")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    from PIL import Image
    assert Image.open(path).size[0] > Image.open(path).size[1]   # two panels side by side


def test_evaluate_explore_reports_the_spread_of_exploratory_returns(learned, capsys, tmp_path):
    shared, _, _ = learned
    capsys.readouterr()
    out = tmp_path / "exploration.json"
    assert main(["evaluate", "--skill-dir", str(shared["skill_dir"]), "--station-config", str(shared["station_yaml"]),
                 "--explore", "2", "--out", str(out), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report == json.loads(out.read_text())
    assert report["seeds"] == [900000, 900001] and len(report["returns"]) == 2
    assert len(report["object_poses"]) == 2 and report["object_poses"][0] != report["object_poses"][1]
    assert out.with_suffix(".png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert report["exploration_scale"] == Skill.load(shared["skill_dir"]).spec.exploration_scale
    spread = report["return_spread"]
    assert spread["min"] == min(report["returns"]) and spread["max"] == max(report["returns"])
    assert spread["min"] <= spread["median"] <= spread["max"]
    assert spread["std"] == pytest.approx(np.std(report["returns"]))
    # A failed rollout returns 0, one that ran its learned dense return (> 0); at least
    # one of the two ran (the spread is not only of failures).
    ran = [reason == "" for reason in report["reasons"]]
    assert any(ran)
    assert all((r > 0.0) == ok and (ok or r == 0.0) for r, ok in zip(report["returns"], ran)), report
    assert main(["evaluate", "--skill-dir", str(shared["skill_dir"]), "--explore", "-1"]) == 2
    assert report["approach_exploration"] == 1.0
    assert main(["evaluate", "--skill-dir", str(shared["skill_dir"]), "--explore", "2",
                 "--approach-exploration", "0"]) == 2
    assert "approach_exploration (--approach-exploration): expected a factor in (0, 1]" in capsys.readouterr().err


def test_learn_config_file_flags_override_it_and_print_config_shows_the_effect(tmp_path, capsys):
    from pydrake.common.yaml import yaml_load_typed

    from drake_skill.cli.learn_config import LearnFile

    config = tmp_path / "learn.yaml"
    config.write_text("skill: draw\nworkers: 1\nlearn: {method: cma-es, episodes: 3, seed: 4}\n"
                      "station:\n  object: {x: 0.66}\n")
    assert main(["learn", "--config", str(config), "--episodes", "4", "--print-config"]) == 0
    effective = yaml_load_typed(schema=LearnFile, data=capsys.readouterr().out)
    assert (effective.skill, effective.workers) == ("draw", 1)
    # The file's settings, the flag over the file, LearnConfig's defaults for the rest.
    assert (effective.learn.method, effective.learn.episodes, effective.learn.seed, effective.learn.rollouts) == (
        "cma-es", 4, 4, 6)
    # The station: the skill's scenario (the drawer) with the file's override.
    assert (effective.station.object.model, effective.station.object.x) == ("drawer", 0.66)
    assert effective.station.success.joint == "drawer_slide"
    config.write_text("skill: draw\nlearn: {methd: cma-es}\n")
    assert main(["learn", "--config", str(config), "--print-config"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--config" in err and "methd" in err


def test_a_learn_run_from_a_config_file_equals_the_same_run_from_flags(learned, tmp_path):
    """learned's run (flags: --skill-dir, --station-config, --episodes 1 --rollouts 2 --held-out 2 --seed 5
    --select-poses 1)
    again from one --config file holding the same settings and the station: the same numbers."""
    shared, out, _ = learned
    station = "".join(f"  {line}\n" for line in shared["station_yaml"].read_text().splitlines())
    config = tmp_path / "run.yaml"
    config.write_text(f"skill_dir: {shared['skill_dir']}\nout: {tmp_path / 'run'}\n"
                      "learn: {episodes: 1, rollouts: 2, held_out: 2, seed: 5, select_poses: 1}\n"
                      f"station:\n{station}")
    assert main(["learn", "--config", str(config), "--quiet", "--no-replay"]) == 0

    def numbers(folder):
        records = [json.loads(line) for line in (folder / "results.jsonl").read_text().splitlines()]
        return [{k: v for k, v in r.items() if k not in ("wall_s", "wall_s_this_call")} for r in records]

    assert numbers(tmp_path / "run") == numbers(out)
    settings = {k: v for k, v in json.loads((out / "config.json").read_text()).items() if k != "versions"}
    again = {k: v for k, v in json.loads((tmp_path / "run" / "config.json").read_text()).items() if k != "versions"}
    assert again == settings


def test_best_return_index_keeps_the_seeded_pick_on_a_tie():
    assert best_return_index([3.0, 5.0, 1.0], default=0) == 1
    assert best_return_index([5.0, 2.0, 5.0], default=2) == 2       # the seed's pick is among the best
    assert best_return_index([5.0, 2.0, 5.0], default=1) == 0       # it is not: the lowest of the best
    with pytest.raises(ValueError, match="mean_returns: expected finite returns, one per DMP"):
        best_return_index([1.0, float("nan")], default=0)


def test_best_return_starts_from_the_demonstration_the_learned_reward_rates_best(tmp_path_factory, tmp_path):
    """A skill file's ``initial_dmp: best-return`` (docs/method.md section 5): the seed drew DMP 1,
    whose weights are blown up so that its imitation fails (return 0); the learned return of one
    greedy execution per DMP picks DMP 0, the skill is rewritten with the choice and its record,
    and ``random`` leaves the seed's pick."""
    shared = shared_skill(tmp_path_factory)
    skill = Skill.load(shared["skill_dir"])
    spec = dc.replace(skill.spec, initial_dmp="best-return", initial_dmp_poses=1)
    broken = dc.replace(skill, initial_index=1, config=dc.replace(skill.config, spec=spec),
                        dmps=[skill.dmps[0], dc.replace(skill.dmps[1], weights=skill.dmps[1].weights * 1e3)])
    lines = []
    saved = save_fitted_skill(broken, tmp_path / "best", station_config=shared["station"], progress=False,
                              log=lines.append)
    [line] = lines
    choice = Skill.load(tmp_path / "best").info["initial_choice"]
    assert saved.initial_index == 0 and saved.info["initial_choice"] == choice     # the rewritten skill
    assert choice["seeds"] == [CHOICE_SEED0] and choice["executions"] == 2 and choice["seeded_index"] == 1
    assert choice["mean_returns"][1] == 0.0 < choice["mean_returns"][0], choice
    assert choice["index"] == 0 and Skill.load(tmp_path / "best").initial_index == 0
    assert line.startswith("initial DMP: 0 (best mean learned return over 1 poses: DMP 0 ") and "drew 1)" in line
    # The ground truth is recorded beside the choice, one list per DMP.
    assert [len(s) for s in choice["successes"]] == [1, 1]
    # The rule applied to the saved skill from disk chooses again, with the same seeds and numbers.
    assert apply_initial_rule(tmp_path / "best", station_config=shared["station"], progress=False) == line
    random_spec = dc.replace(spec, initial_dmp="random")
    kept = dc.replace(broken, config=dc.replace(broken.config, spec=random_spec))
    assert save_fitted_skill(kept, tmp_path / "random", station_config=shared["station"], log=lines.append) is kept
    assert apply_initial_rule(tmp_path / "random", station_config=shared["station"], progress=False) is None
    assert Skill.load(tmp_path / "random").initial_index == 1


def test_every_rollout_is_kept_and_a_reflex_trip_replays_with_its_contacts(learned, capsys, tmp_path):
    """Issue 51 item 3: every rollout keeps its weights, seed, path and last frame; a stopped one also its
    joints and a frame a second up to the stop; ``drake-skill replay`` re-simulates one from its weights
    and seed, names the bodies in contact and follows the stored path."""
    from drake_skill.learning.rollout_store import load_rollout, rollouts_path, stored_names

    _, out, _ = learned
    assert stored_names(out) == ["episode_001", "greedy_000", "greedy_001", "held_out_after", "held_out_before",
                                 "select"]
    records = [json.loads(line) for line in (out / "results.jsonl").read_text().splitlines()]
    rollout = [r for r in records if r["type"] == "rollout"][0]
    kept = load_rollout(rollouts_path(out, "episode_001"), 0)
    assert kept["seed"] == rollout["seed"] and kept["meta"]["n"] == 2 and rollout["reason"] == "reflex"
    stop = rollout["contact"]["t"]
    # Stopped early: the path, joints and object state up to the stop, a frame a second from t = 0.
    assert kept["times"][-1] <= stop + 0.1 and len(kept["joints"]) == len(kept["times"]) == len(kept["ee_pose"])
    assert list(kept["frame_times"]) == list(range(len(kept["frame_times"]))) and kept["frame_times"][-1] <= stop
    assert kept["frames"].dtype == np.uint8 and kept["frames"].shape[1:] == kept["last_frame"].shape
    assert kept["frames"].shape[0] == int(stop) + 1 and kept["last_frame"].shape[2] == 3
    greedy = load_rollout(rollouts_path(out, "greedy_000"), 0)    # ran to its end: no frames
    assert "frames" not in greedy and greedy["last_frame"].std() > 0 and greedy["times"][-1] > stop
    with pytest.raises(ValueError, match=r"no rollout 2; it holds 2 \(indices 0..1\)"):
        load_rollout(rollouts_path(out, "episode_001"), 2)

    page = tmp_path / "trip.html"
    assert main(["replay", str(out), "--episode", "1", "--index", "0", "--out", str(page)]) == 0
    printed = capsys.readouterr().out
    assert f"episode_001 rollout 0 (seed {rollout['seed']}): wrote {page}" in printed
    assert "re-simulated: failed (reflex" in printed and "hand path as stored: yes" in printed
    pairs = "; ".join(f"{a} - {b} {f:.0f} N" for a, b, f in rollout["contact"]["pairs"])
    assert f"contact at t = {stop} s ({rollout['contact']['cause']}): {pairs}" in printed
    assert b"/drake/contact_forces" in _meshcat_messages(page.read_text())    # the forces are drawn
    assert main(["replay", str(out), "--greedy", "3"]) == 2
    assert "no kept rollouts 'greedy_003' (rollouts/greedy_003.npz); it has episode_001, greedy_000" in \
        capsys.readouterr().err


def _meshcat_messages(html: str) -> bytes:
    """The bytes of every base64 run of a Meshcat page (its recorded messages are msgpack in base64)."""
    import base64
    import binascii
    import re

    out = []
    for run in re.findall(r"[A-Za-z0-9+/]{16,}={0,2}", html):
        try:
            out.append(base64.b64decode(run + "=" * (-len(run) % 4)))
        except binascii.Error:
            continue
    return b"".join(out)
