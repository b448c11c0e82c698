"""The generalization study's report (issue 45 item 6), from stored runs written here by hand."""

import csv
import json

import pytest

from drake_skill.cli.main import main
from drake_skill.experiments.generalization import COLUMNS, generalization_config, verdicts, write_report


def _rollout(episode, index, dense, success, verdict, state, failed=False):
    return {"type": "rollout", "episode": episode, "index": index, "failed": failed,
            "reason": "reflex" if failed else "", "dense_return": 0.0 if failed else dense, "verdict": verdict,
            "success": success, "final_object_state": None if failed else state}


def _store(out, skill, seed, after, rollouts, wall=100.0):
    folder = out / skill / "pi2-es-cov" / "dense" / f"run_{seed:03d}"
    folder.mkdir(parents=True)
    (folder / "results.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rollouts))
    (folder / "config.json").write_text(json.dumps({"versions": {"git_commit": "abc123"}}))
    (folder / "summary.json").write_text(json.dumps({
        "skill": skill, "method": "pi2-es-cov", "reward": "dense", "run": seed, "seed": seed,
        "held_out_after": after, "reward_auc": None, "verdict_fpr": None, "verdict_fnr": None,
        "reflex_rate": sum(r["failed"] for r in rollouts) / len(rollouts), "n_rollouts": len(rollouts),
        "selected_episode": 5, "wall_s": wall}))


def test_the_report_pools_each_skills_rollouts_and_marks_the_criteria(tmp_path):
    out = tmp_path / "generalization"
    # "lift": the return ranks every success above every failure; one trip in 8 rollouts.
    good = [_rollout(1, i, 100.0 * (i + 1), i >= 4, i >= 3, 0.1 * i) for i in range(7)]
    _store(out, "lift", 0, 1.0, good + [_rollout(1, 7, 0, False, False, None, failed=True)])
    _store(out, "lift", 1, 0.8, good + [_rollout(1, 7, 800.0, True, True, 0.7)], wall=120.0)
    (out / "lift" / "held_out_before.json").write_text(json.dumps({"success_rate": 0.6}))
    # "turn" (a below rule): returns reversed, and a seed ends 0.3 below its start.
    bad = [_rollout(1, i, 100.0 * (i + 1), i < 2, True, 0.1 * i) for i in range(6)]
    _store(out, "turn", 0, 0.4, bad)
    (out / "turn" / "held_out_before.json").write_text(json.dumps({"success_rate": 0.7}))
    rules = {"lift": {"above": 0.35, "below": None}, "turn": {"above": None, "below": 0.15}}
    write_report(out, rules)

    summary = json.loads((out / "summary.json").read_text())
    assert summary["code"] == "abc123" and sorted(summary["skills"]) == ["lift", "turn"]
    lift, turn = summary["skills"]["lift"], summary["skills"]["turn"]
    assert lift["reward_auc"] == 1.0 and lift["rollouts"] == 16 and lift["reflex_rate"] == 1 / 16
    assert lift["verdict_fpr"] == 2 / 8 and lift["verdict_fnr"] == 0.0      # index 3, in both runs
    assert (lift["held_out_before"], lift["held_out_after"]) == ([0.6, 0.6], [1.0, 0.8])
    assert turn["reward_auc"] == 0.0 and turn["verdict_fpr"] == 1.0 and turn["verdict_fnr"] == 0.0
    assert verdicts(lift) == {"reward AUC >= 0.95": True, "held-out after: mean >= 0.9, worst >= 0.8": True,
                              "no seed ends > 0.1 below its start": True, "reflex trips <= 5 % of rollouts": False}
    assert verdicts(turn) == {"reward AUC >= 0.95": False, "held-out after: mean >= 0.9, worst >= 0.8": False,
                              "no seed ends > 0.1 below its start": False, "reflex trips <= 5 % of rollouts": True}
    rows = list(csv.DictReader((out / "table.csv").open()))
    assert tuple(rows[0]) == COLUMNS and [(r["skill"], r["seed"]) for r in rows] == [("lift", "0"), ("lift", "1"),
                                                                                    ("turn", "0")]
    assert [r["held_out_after"] for r in rows] == ["1", "0.8", "0.4"] and rows[1]["wall_s"] == "120"
    readme = (out / "README.md").read_text()
    assert "| lift | 2 | - | - | 1.00 | 0.25 | 0.00 | 0.6 | 1.0, 0.8 | 0.06 | 0, 0 | 16 | 3 of 4 |" in readme
    assert readme.startswith("# Generalization: learning on every skill with `drake-skill learn`'s defaults")
    # A study of the span (grid.json says so) names it.
    (out / "grid.json").write_text(json.dumps({"exploration": "span"}))
    write_report(out, rules)
    readme = (out / "README.md").read_text()
    assert readme.startswith("# Generalization: learning on every skill with `drake-skill learn --exploration span`")
    assert "PI^2-ES-Cov over the demonstrations' span" in readme
    assert "reflex trips <= 5 % of rollouts: NOT met" in readme
    for skill in ("lift", "turn"):
        for figure in ("held_out", "return_vs_state"):
            assert (out / f"{skill}_{figure}.png").read_bytes()[:4] == b"\x89PNG"


def test_greedy_drops_count_failures_after_a_success(tmp_path):
    def greedy(episode, success, failed=False):
        return {"type": "greedy", "episode": episode, "success": success, "failed": failed}

    # Episodes 0..5 (stored out of order): F S F S S F -> two drops; a reflex (failed) counts as one.
    _store(tmp_path, "lift", 0, 1.0, [greedy(3, True), greedy(0, False), greedy(1, True), greedy(2, False),
                                      greedy(4, True), greedy(5, False, failed=True)])
    _store(tmp_path, "lift", 1, 1.0, [greedy(0, False), greedy(1, False), greedy(2, True), greedy(3, True)])
    (tmp_path / "lift" / "held_out_before.json").write_text(json.dumps({"success_rate": 0.5}))
    write_report(tmp_path, {"lift": {"above": 0.35, "below": None}})
    assert json.loads((tmp_path / "summary.json").read_text())["skills"]["lift"]["greedy_drops"] == [2, 0]
    assert [r["greedy_drops"] for r in csv.DictReader((tmp_path / "table.csv").open())] == ["2", "0"]


def test_the_study_runs_learns_defaults_on_every_shipped_skill(capsys, tmp_path):
    from drake_skill.skills import shipped_skill_names

    config = generalization_config().validate()
    assert config.skills == tuple(shipped_skill_names()) and config.runs == 5
    assert (config.methods, config.rewards, config.fit, config.select) == (("pi2-es-cov",), ("dense",),
                                                                           "tolerance", "guarded")
    learn = config.learn_config("pi2-es-cov", "dense", 2)
    assert (learn.episodes, learn.rollouts, learn.seed, learn.select) == (5, 6, 2, "guarded")
    assert config.settings()["select"] == "guarded"
    assert learn.exploration == "basis" and "exploration" not in config.settings()   # stored studies unchanged
    span = generalization_config(exploration="span").validate()
    assert span.learn_config("pi2-es-cov", "dense", 0).exploration == "span"
    assert span.settings()["exploration"] == "span"          # a resume with the other exploration is refused
    with pytest.raises(ValueError, match="--exploration wide: unknown; give basis or span"):
        generalization_config(exploration="wide").validate()
    assert main(["experiment", "generalization", "--out", "/dev/null/x", "--report-only"]) == 2
    assert "--out" in capsys.readouterr().err
    assert main(["experiment", "generalization", "--scenario", "/nonexistent/limit.yaml", "--out",
                 str(tmp_path / "study")]) == 2
    err = capsys.readouterr().err
    assert "--scenario /nonexistent/limit.yaml" in err and len(err.strip().splitlines()) == 1


def test_fit_refuses_demonstrations_that_never_meet_the_skills_rule(tmp_path_factory, tmp_path, capsys):
    """A skill file whose rule the demonstrations never meet: one line naming the files, the rule and
    the fix, before anything is fitted or written."""
    from learning_support import shared_skill

    from drake_skill.skills.spec import SKILL_DIR

    shared = shared_skill(tmp_path_factory)
    text = (SKILL_DIR / "close.yaml").read_text().replace("below: 0.05", "below: -0.5")
    assert "below: -0.5" in text
    skill_file = tmp_path / "close.yaml"
    skill_file.write_text(text)
    out = tmp_path / "fitted"
    assert main(["fit", "--demos", str(shared["demos_dir"]), "--skill", str(skill_file), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "demo_000.npz" in err and "demo_001.npz" in err
    assert "no demonstration meets the skill's success rule (lid_hinge <= -0.5; they end at" in err
    assert err.endswith("or correct 'success' in the skill file 'close' to what the demonstrations show")
    assert not out.exists()


def test_a_demonstration_ending_at_exactly_zero_is_judged_not_skipped():
    from types import SimpleNamespace

    from drake_skill.fitted_skill import check_demonstrations_meet_rule
    from drake_skill.station.scenario import SuccessConfig

    spec = SimpleNamespace(name="lift", success=SuccessConfig(joint="j", above=0.5))
    demos = [SimpleNamespace(final_object_state=0.0, path="a.npz"), SimpleNamespace(final_object_state=0.2)]
    with pytest.raises(ValueError, match=r"a.npz, demos\[1\]: no demonstration meets .* they end at 0, 0.2"):
        check_demonstrations_meet_rule(demos, spec)
    demos[1].final_object_state = 0.6
    check_demonstrations_meet_rule(demos, spec)                 # one meets it
    demos[1].final_object_state = None                          # no ground truth: not judged
    check_demonstrations_meet_rule(demos, spec)
