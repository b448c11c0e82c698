"""The reward-quality measurement (drake_skill/learning/reward_quality.py) on synthetic rollouts whose
answers are known, its plot, and the errors of ``drake-skill bench reward_quality`` (no simulation)."""

from types import SimpleNamespace

import pytest

from drake_skill.learning.reward_quality import (plot_return_vs_state, records_from_report, reward_quality,
                                                 rule_direction)

ABOVE = SimpleNamespace(joint="lid_hinge", above=1.0, below=None)
BELOW = SimpleNamespace(joint="drawer", above=None, below=0.05)


def record(R, success, verdict=None, state=None, failed=False, reason=""):
    """A rollout record as results.jsonl holds it."""
    return {"failed": failed, "reason": reason, "dense_return": R, "success": success,
            "verdict": success if verdict is None else verdict, "final_object_state": state}


def separated():
    """Four successes with returns 10..13 above four failures with 1..4; state grows with the return."""
    return ([record(10.0 + i, True, state=1.2 + 0.1 * i) for i in range(4)]
            + [record(1.0 + i, False, state=0.1 * i) for i in range(4)])


def test_returns_that_separate_successes_give_auc_one_and_reversed_zero():
    assert reward_quality(separated(), ABOVE)["reward_auc"] == 1.0
    reversed_ = [dict(r, dense_return=-r["dense_return"]) for r in separated()]
    assert reward_quality(reversed_, ABOVE)["reward_auc"] == 0.0


def test_auc_counts_ties_as_half_and_matches_a_hand_count():
    # successes 5, 3, 3; failures 3, 1: pairs (s > f) 5>3, 5>1, 3>1, 3>1 = 4, ties 3=3 twice = 1 -> 5/6
    rs = [record(5, True), record(3, True), record(3, True), record(3, False), record(1, False)]
    assert reward_quality(rs, ABOVE)["reward_auc"] == pytest.approx(5 / 6, abs=1e-12)


def test_a_hand_counted_verdict_table_gives_exact_rates():
    # truth success: 5 (verdict: 4 success, 1 failure); truth failure: 4 (verdict: 3 success, 1 failure)
    rs = ([record(1, True, verdict=True)] * 4 + [record(1, True, verdict=False)]
          + [record(0, False, verdict=True)] * 3 + [record(0, False, verdict=False)])
    q = reward_quality(rs, ABOVE)
    assert q["verdict_fpr"] == 3 / 4
    assert q["verdict_fnr"] == 1 / 5
    assert (q["successes"], q["verdict_successes"], q["scored"]) == (5, 7, 9)


def test_a_below_rule_flips_the_sign_of_spearman():
    rs = [record(1.0, False, state=0.1), record(2.0, False, state=0.3), record(3.0, True, state=0.2),
          record(4.0, True, state=0.4)]               # ranks: returns 1 2 3 4, states 1 3 2 4 -> rho 0.8
    assert reward_quality(rs, ABOVE)["state_spearman"] == pytest.approx(0.8, abs=1e-12)
    assert reward_quality(rs, BELOW)["state_spearman"] == pytest.approx(-0.8, abs=1e-12)
    assert reward_quality(separated(), ABOVE)["state_spearman"] == pytest.approx(1.0, abs=1e-12)


def test_failed_rollouts_are_left_out_of_the_scores_and_counted():
    rs = separated() + [record(0.0, False, failed=True, reason="reflex"),
                        record(0.0, True, verdict=True, failed=True, reason="reflex"),
                        record(0.0, False, failed=True, reason="perception")]
    q = reward_quality(rs, ABOVE)
    assert q["reward_auc"] == 1.0                     # the failed ones' return 0 would sit below every success
    assert (q["rollouts"], q["scored"], q["failed"]) == (11, 8, 3)
    assert q["failed_rate"] == 3 / 11
    assert q["failures"] == {"perception": 1, "reflex": 2}
    assert (q["successes"], q["verdict_successes"], q["verdict_fpr"], q["verdict_fnr"]) == (4, 4, 0.0, 0.0)


def test_one_class_or_nothing_scored_gives_none():
    q = reward_quality([record(1.0, True, state=1.1), record(2.0, True, state=1.2)], ABOVE)
    assert (q["reward_auc"], q["verdict_fpr"], q["verdict_fnr"]) == (None, None, 0.0)
    assert q["state_spearman"] == pytest.approx(1.0)
    q = reward_quality([record(0.0, False, failed=True, reason="reflex")], ABOVE)
    assert (q["reward_auc"], q["verdict_fpr"], q["verdict_fnr"], q["state_spearman"]) == (None,) * 4
    assert q["failed_rate"] == 1.0
    empty = reward_quality([], ABOVE)
    assert (empty["rollouts"], empty["failed_rate"]) == (0, None)
    constant = [record(5.0, True, state=1.2), record(5.0, False, state=0.2)]
    assert reward_quality(constant, ABOVE)["state_spearman"] is None
    assert reward_quality(constant, ABOVE)["reward_auc"] == 0.5


def test_bad_rules_and_records_are_one_line_errors():
    with pytest.raises(ValueError, match="exactly one of 'above' and 'below'"):
        reward_quality(separated(), SimpleNamespace(above=1.0, below=0.5))
    with pytest.raises(ValueError, match=r"records\[1\]: missing verdict"):
        reward_quality([record(1, True), {"failed": False, "dense_return": 1.0, "success": True,
                                          "final_object_state": 1.0}], ABOVE)
    with pytest.raises(ValueError, match=r"records\[0\]: dense_return nan"):
        reward_quality([record(float("nan"), True)], ABOVE)
    assert rule_direction({"above": None, "below": 0.05}) == (0.05, -1)


def test_records_from_a_report_of_parallel_lists():
    report = {"seeds": [7, 8], "reasons": ["", "reflex"], "returns": [12.5, 0.0], "verdicts": [True, False],
              "successes": [True, False], "final_object_state": [1.3, None]}
    rs = records_from_report(report, "exploration")
    assert rs == [{"source": "exploration", "seed": 7, "failed": False, "reason": "", "dense_return": 12.5,
                   "verdict": True, "success": True, "final_object_state": 1.3},
                  {"source": "exploration", "seed": 8, "failed": True, "reason": "reflex", "dense_return": 0.0,
                   "verdict": False, "success": False, "final_object_state": None}]
    with pytest.raises(ValueError, match="differ in length"):
        records_from_report(dict(report, seeds=[7]))


def test_the_plot_is_written_as_a_png(tmp_path):
    rs = separated() + [record(0.0, False, failed=True, reason="reflex"),
                        record(0.0, False, failed=True, reason="solver", state=0.4)]
    path = plot_return_vs_state(rs, ABOVE, tmp_path / "fig" / "return_vs_state.png", title="synthetic")
    assert path == tmp_path / "fig" / "return_vs_state.png"
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert [p.name for p in path.parent.iterdir()] == ["return_vs_state.png"]     # no temporary left
    assert plot_return_vs_state([], BELOW, tmp_path / "empty.png").stat().st_size > 1000


def bench(capsys, *argv):
    """``drake-skill bench reward_quality ARGV``: (exit status, stderr)."""
    from drake_skill.cli.main import main

    status = main(["bench", "reward_quality", *argv])
    return status, capsys.readouterr().err.strip()


def test_bench_bad_input_is_one_line_and_exit_status_2(capsys, tmp_path):
    assert bench(capsys) == (2, "drake-skill: error: --skill / --skill-dir: give exactly one (a skill name or "
                                "file to record and fit, or a fitted skill's folder)")
    assert bench(capsys, "--skill", "open", "--rollouts", "0") == (
        2, "drake-skill: error: --rollouts must be at least 1, got 0")
    assert bench(capsys, "--skill-dir", str(tmp_path / "nope"), "--rollouts", "3") == (
        2, f"drake-skill: error: --skill-dir {tmp_path / 'nope'}: no such folder; give the folder of a "
           "fitted skill (drake-skill fit --out / learn --out)")


def test_bench_checks_its_inputs_before_any_simulation(tmp_path):
    from drake_skill.bench.reward_quality import main

    with pytest.raises(ValueError, match=r"^--skill / --skill-dir: give exactly one"):
        main(["--skill", "open", "--skill-dir", str(tmp_path)])
    with pytest.raises(FileNotFoundError, match=f"^--skill-dir {tmp_path / 'skill.json'}: no such file; give a "
                                                "fitted skill's folder, which holds skill.json"):
        main(["--skill-dir", str(tmp_path)])
    with pytest.raises(FileNotFoundError, match="^--skill: skill 'no_such_skill': not a shipped skill"):
        main(["--skill", "no_such_skill"])
    with pytest.raises(ValueError, match="^--demo-poses must be 0 .* got -1$"):
        main(["--skill", "open", "--demo-poses", "-1"])
    with pytest.raises(ValueError, match="^--workers must be at least 1, got 0$"):
        main(["--skill", "open", "--workers", "0"])
