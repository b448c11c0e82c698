"""Skill fitting from recorded demonstrations: round trip, rewards, verdicts, PCA variance."""

import numpy as np
import pytest

from drake_skill.demos.demonstrator import DemonstratorConfig, ScriptedDemonstrator
from drake_skill.station.pose_source import hold_plan
from drake_skill.fitted_skill import Skill, default_skill_config, fit_skill, hold_invalid


def _parked_goal_clouds(demonstrator, seed, duration=6.0):
    """Object clouds (T, 2048, 3), flags and the perceived X_WO (7,) while the arm stays at home."""
    sim = demonstrator.sim
    sim.reset(seed)
    sim.set_plan(hold_plan(sim.home_pose()))
    frames = sim.record(int(duration * 10), 10.0).frames   # logged from the diagram's ObjectSegmenter
    return frames.points, frames.valid, frames.X_WO[frames.first_valid]


@pytest.fixture(scope="module")
def close_data():
    """Two Close demonstrations to fit on, one held out, and a parked execution."""
    config = DemonstratorConfig(seed=0, pause_probability=0.0)
    demonstrator = ScriptedDemonstrator("close", config)
    demos = demonstrator.record_many(3, progress=False)
    parked = _parked_goal_clouds(demonstrator, seed=40)
    return demos[:2], demos[2], parked


@pytest.fixture(scope="module")
def close_skill(close_data):
    """The thesis's fit (10 Hz data, Table 6.1's 10 bases), whose structure the tests below check."""
    demos, _, _ = close_data
    return fit_skill(demos, default_skill_config("close", fit="thesis"))


def test_default_fit_chooses_the_bases_that_meet_the_tolerance(close_data):
    """docs/method.md section 2.2: the 100 Hz data, the fewest bases of the ladder that reproduce
    each demonstration within 2 mm near contact and 3 mm RMS, reported for skill.json and fit."""
    from drake_skill.action.fitting import BASIS_LADDER

    demos, _, _ = close_data
    config = default_skill_config("close")
    assert config.spec.dmp_bases is None and config.dmp_data == "100hz"
    skill = fit_skill(demos, config)
    report = skill.info["dmp_fit"]
    assert report["tolerance_met"] and report["n_basis"] == skill.config.dmp.n_basis in BASIS_LADDER
    assert report["n_basis"] > 10 and skill.initial_weights.shape == (report["n_basis"], 7)
    for e in report["errors"]:
        assert e["fit_rms_mm"] <= 3.0 and e["fit_contact_max_mm"] <= 2.0 and e["contact_samples"] > 0
    assert 0 < skill.config.dmp.start_join < 1
    lines, warnings = skill.fit_report()
    assert lines[0].startswith(f"DMP: B = {report['n_basis']} bases (the fewest that meet the tolerance")
    assert len(lines) == 1 + len(demos) + 2 and warnings == []


def test_fitted_skill_has_thesis_structure(close_skill):
    skill = close_skill
    assert len(skill.dmps) == 2 and skill.config.dmp.n_basis == 10
    assert skill.initial_weights.shape == (10, 7)
    assert skill.sigma0.shape == (10, 7, 7)
    assert np.all(np.linalg.eigvalsh(skill.sigma0) > 0)
    # PCA 128 -> 8 on demonstration codes; the thesis saw > 90 % explained variance.
    assert skill.goal_features.n_components == 8
    assert 0.9 < skill.info["pca_explained_variance"] <= 1.0 + 1e-9
    assert skill.pomrp.n_states >= 2
    assert all(skill.info["demo_verdicts"])


def test_goal_model_judges_held_out_demo_and_parked_arm(close_skill, close_data):
    _, held_out, (parked_points, parked_valid, parked_X_WO) = close_data
    G_demo = close_skill.goal_data(held_out.object_points, held_out.perception_valid, X_WO=held_out.X_WO_start)
    G_parked = close_skill.goal_data(parked_points, parked_valid, X_WO=parked_X_WO)
    assert close_skill.verdict(G_demo), "held-out demonstration judged a failure"
    assert not close_skill.verdict(G_parked), "parked arm judged a success"
    # Dense returns order them the same way (per frame, as lengths differ).
    assert close_skill.dense_return(G_demo) / len(G_demo) > close_skill.dense_return(G_parked) / len(G_parked)


def test_skill_round_trips_with_identical_rewards(close_skill, close_data, tmp_path):
    _, held_out, _ = close_data
    path = close_skill.save(tmp_path / "close_skill")
    loaded = Skill.load(path)
    for a, b in zip(close_skill.dmps, loaded.dmps):
        np.testing.assert_array_equal(a.weights, b.weights)
    np.testing.assert_array_equal(close_skill.sigma0, loaded.sigma0)
    G1 = close_skill.goal_data(held_out.object_points, held_out.perception_valid, X_WO=held_out.X_WO_start)
    G2 = loaded.goal_data(held_out.object_points, held_out.perception_valid, X_WO=held_out.X_WO_start)
    np.testing.assert_array_equal(G1, G2)
    assert close_skill.dense_return(G1) == loaded.dense_return(G2)
    np.testing.assert_array_equal(close_skill.pomrp.rewards(G1), loaded.pomrp.rewards(G2))
    assert loaded.summary() == close_skill.summary()
    with pytest.raises(FileExistsError):
        close_skill.save(path)


def test_a_skill_saved_before_the_module_was_renamed_still_loads():
    """skill.json names its format "drake_skill.skill" (the module's old name): a committed skill fitted
    before ``skill.py`` became ``fitted_skill.py`` loads, with its DMPs and goal model."""
    from pathlib import Path

    folder = Path(__file__).resolve().parent.parent / "docs" / "results" / "generalization" / "open" / "initial_skill"
    skill = Skill.load(folder)
    assert skill.name == "open" and len(skill.dmps) == 3 and skill.initial_weights.shape == (100, 7)


def test_corrupt_skill_directory_is_refused(close_skill, tmp_path):
    path = close_skill.save(tmp_path / "skill")
    (path / "pcae.safetensors").write_bytes(b"not the weights")
    with pytest.raises(ValueError, match="pcae.safetensors"):
        Skill.load(path)
    path = close_skill.save(tmp_path / "skill2")
    (path / "arrays.npz").write_bytes(b"garbage")
    with pytest.raises(ValueError, match="arrays.npz"):
        Skill.load(path)
    with pytest.raises(FileNotFoundError, match="skill.json"):
        Skill.load(tmp_path / "nothing")


def test_fit_rejects_bad_input(close_data):
    demos, _, _ = close_data
    with pytest.raises(ValueError, match="at least 2"):
        fit_skill(demos[:1], default_skill_config("close"))
    with pytest.raises(ValueError, match="'close' demonstration given to fit 'open'"):
        fit_skill(demos, default_skill_config("open"))


def test_hold_invalid_frames():
    codes = np.arange(5, dtype=float)[:, None] * np.ones((5, 3))
    held = hold_invalid(codes, np.array([False, True, False, False, True]))
    np.testing.assert_array_equal(held[:, 0], [1, 1, 1, 1, 4])
    with pytest.raises(ValueError, match="never segmented"):
        hold_invalid(codes, np.zeros(5, bool))


def _run_pipeline(skill, plan_for, seed, duration):
    """Station + plan + segmenter -> featurizer -> reward in one diagram; returns the reward system's
    verdict and return."""
    from pydrake.systems.analysis import Simulator
    from pydrake.systems.framework import DiagramBuilder

    from drake_skill.reward.systems import add_goal_pipeline
    from drake_skill.station.pose_source import PoseTrajectorySource
    from drake_skill.station.make import make_station
    from drake_skill.skills import scenario_for_skill

    builder = DiagramBuilder()
    station = builder.AddNamedSystem("station", make_station(scenario_for_skill("close")))
    source = builder.AddNamedSystem("plan", PoseTrajectorySource())
    builder.Connect(source.GetOutputPort("X_WE_desired"), station.GetInputPort("ee_pose_desired"))
    builder.Connect(source.GetOutputPort("gripper_command"), station.GetInputPort("gripper_command"))
    pipeline = add_goal_pipeline(builder, station, skill)
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    X_WO = station.reset(context, seed)
    home = station.GetOutputPort("ee_pose").Eval(station.GetMyContextFromRoot(context))
    source.set_plan(source.GetMyMutableContextFromRoot(context), plan_for(X_WO, home))
    simulator = Simulator(diagram, context)
    simulator.AdvanceTo(duration)
    reward_context = pipeline.reward.GetMyContextFromRoot(context)
    G = pipeline.reward.goal_sequence(reward_context)
    return pipeline.reward.verdict(reward_context), pipeline.reward.smoothed_return(reward_context), G


def test_goal_pipeline_in_the_diagram_rewards_closing_over_parking(close_skill):
    """The ARCHITECTURE chain, simulated: a scripted Close earns a success verdict and a
    higher return per frame than the parked arm, from the camera alone."""
    from drake_skill.demos.scripted import scripted_plan

    ok, R, G = _run_pipeline(close_skill, lambda X_WO, home: scripted_plan("close", X_WO, home), 21, 11.0)
    parked_ok, parked_R, parked_G = _run_pipeline(close_skill, lambda X_WO, home: hold_plan(home), 21, 5.0)
    assert G.shape[1] == 8 and len(G) >= 100
    assert ok and not parked_ok
    assert R / len(G) > 3 * parked_R / len(parked_G)
    # The system's return is the numpy POMRP's on the same goal data.
    assert R == pytest.approx(close_skill.dense_return(G))


def test_fit_cli_writes_skill_and_pictures(close_data, tmp_path, capsys):
    from drake_skill.cli.main import main
    from drake_skill.demos.format import save_demonstration

    demos, _, _ = close_data
    for i, demo in enumerate(demos):
        save_demonstration(demo, tmp_path / "demos" / f"demo_{i:03d}.npz")
    out = tmp_path / "skill"
    assert main(["fit", "--demos", str(tmp_path / "demos"), "--out", str(out)]) == 0
    captured = capsys.readouterr()
    printed = captured.out
    assert "goal HMM" in printed and "explained variance" in printed
    # The fit's report (docs/method.md 2.2) and the refinement on the simulated station (2.3): each
    # demonstration's DMP either follows it more closely after refinement or keeps its plain fit, said.
    assert "DMP: B = " in printed and printed.count("fit error max") == 2
    refined = Skill.load(out).info["dmp_refinement"]
    assert [r["demo"] for r in refined] == [str(tmp_path / "demos" / f"demo_{i:03d}.npz") for i in range(2)]
    for r in refined:
        assert 1 <= len(r["errors_mm"]) <= 2 and r["errors_mm"][0] > 0   # one when the plain imitation failed
        said = (f"{r['demo']}: imitation {r['errors_mm'][0]:.1f} -> " in printed if not r["kept_plain"]
                else f"{r['demo']}: refining its DMP on the simulated station did not bring" in captured.err)
        assert said and r["kept_plain"] == (min(r["errors_mm"]) == r["errors_mm"][0])
    for name in ("skill.yaml", "skill.json", "arrays.npz", "pcae.safetensors", "goal_model.png", "demo_returns.png"):
        assert (out / name).stat().st_size > 0, name
    assert Skill.load(out).name == "close"
    capsys.readouterr()
    # never replaces a skill without --force: one error line, status 2, before any fitting
    assert main(["fit", "--demos", str(tmp_path / "demos"), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"drake-skill: error: --out {out}: already holds a skill; pass --force to replace it "
                   "or choose another folder"]
    assert Skill.load(out).name == "close"
    # The thesis's fit (docs/method.md 2.2): 10 Hz data, Table 6.1's 10 bases, no refinement.
    assert main(["fit", "--demos", str(tmp_path / "demos"), "--out", str(tmp_path / "thesis"), "--fit", "thesis"]) == 0
    thesis = Skill.load(tmp_path / "thesis")
    assert thesis.config.dmp.n_basis == 10 and thesis.config.dmp_data == "10hz" and thesis.config.dmp_refine == 0
    assert thesis.info["dmp_fit"]["how"] == "thesis Table 6.1 (fit: thesis)" and "dmp_refinement" not in thesis.info
