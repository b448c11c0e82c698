"""The learning run: rewards per method, seeds, configuration, checkpoint/resume and its logs."""

import importlib.util
import io
import json
import subprocess
import sys
import types

import numpy as np
import pytest

from drake_skill.learning.loop import LearnConfig, episode_rewards, learn, pose_seed
from drake_skill.learning.runlog import PROGRESS_COLUMNS, RunLog, _git_commit, progress_row, read_progress
from drake_skill.skills import load_skill
from drake_skill.fitted_skill import Skill

from learning_support import rollout_config, shared_skill

TENSORBOARD = importlib.util.find_spec("tensorboard") is not None


def _result(failed=False, dense=0.0, filtered=(), verdict=False):
    return types.SimpleNamespace(failed=failed, dense_return=dense, filtered_rewards=np.array(filtered, float),
                                 verdict=verdict)


def test_episode_rewards_for_black_box_and_per_step_methods():
    results = [_result(dense=120.0, filtered=[1, 2, 3], verdict=True),
               _result(failed=True, dense=55.0, filtered=[5, 5], verdict=True),   # failed: counts 0
               _result(dense=64.0, filtered=[4, 4])]
    np.testing.assert_array_equal(episode_rewards(results, "dense", False), [120.0, 0.0, 64.0])
    np.testing.assert_array_equal(episode_rewards(results, "sparse", False), [1.0, 0.0, 0.0])
    np.testing.assert_array_equal(episode_rewards(results, "dense", True),
                                  [[1, 2, 3], [0, 0, 0], [4, 4, 0]])     # zero-padded to the longest
    np.testing.assert_array_equal(episode_rewards(results, "sparse", True), [[0, 0, 1], [0, 0, 0], [0, 0, 0]])


def test_pose_seeds_are_fixed_and_distinct():
    seeds = {pose_seed(0, e, c) for e in range(1, 6) for c in range(6)} | {pose_seed(0, e) for e in range(6)}
    assert len(seeds) == 36 and all(0 <= s < 2 ** 31 for s in seeds)
    assert pose_seed(3, 2, 1) == pose_seed(3, 2, 1) != pose_seed(4, 2, 1)


def test_learn_config_errors_name_the_field():
    for changes, field in (({"method": "sgd"}, "method"), ({"reward": "shaped"}, "reward"),
                           ({"episodes": 0}, "episodes"), ({"method": "power", "weighting": "range"}, "weighting"),
                           ({"method": "cma-es", "rollouts": 1}, "rollouts"), ({"held_out": -1}, "held_out"),
                           ({"exploration_scale": 0.0}, "exploration_scale"),
                           ({"exploration_scale": float("nan")}, "exploration_scale")):
        with pytest.raises(ValueError, match=field):
            LearnConfig(**changes).validate()
    assert LearnConfig().search_options() == {"n_episodes": 5, "seed": 0}


def test_exploration_scale_defaults_per_skill():
    # docs/method.md section 5: Open a tenth of Sigma_0, Close the thesis' sigma_0 = 1 (their skill files).
    assert LearnConfig().exploration_scale is None
    assert load_skill("open").exploration_scale == 0.1 and load_skill("close").exploration_scale == 1.0


def _scalars(log_dir, column):
    """(step, value) of TensorBoard scalar ``progress/<column>`` in ``log_dir``, as TensorBoard shows them."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    events = EventAccumulator(str(log_dir))
    events.Reload()
    return [(e.step, e.value) for e in events.Scalars(f"progress/{column}")]


def _numbers(records):
    """The records without wall-clock times."""
    def strip(r):
        return {k: v for k, v in r.items() if k not in ("wall_s",)}
    return [strip(r) for r in records]


def test_resume_after_an_interruption_reproduces_the_uninterrupted_run(tmp_path_factory, tmp_path):
    shared = shared_skill(tmp_path_factory)
    config = LearnConfig(episodes=2, rollouts=2, held_out=1, seed=3, select_poses=1)
    kwargs = dict(station_config=shared["station"], rollout_config=rollout_config(), replay=False,
                  progress=False)
    rows = []
    whole = learn(shared["skill_dir"], tmp_path / "whole", config, on_episode=rows.append, **kwargs)
    assert whole.complete and whole.search.episode == 2
    # on_episode got each greedy-evaluated episode's row, progress.csv holds the same rows, and
    # both are the curve's numbers (seed 3: the greedy execution succeeds only after the second update).
    assert rows == read_progress(tmp_path / "whole" / "progress.csv")
    assert [r["episode"] for r in rows] == [0, 1, 2] and [r["rollouts_used"] for r in rows] == [0, 2, 4]
    assert [r["greedy_success"] for r in rows] == [0, 0, 1]
    for row, c in zip(rows, whole.summary["curve"], strict=True):
        for column in ("greedy_return", "mean_return", "best_return", "exploration"):
            assert row[column] == c[column]
        assert row["failures"] == (None if c["episode"] == 0 else sum(c["failures"].values()))

    part = learn(shared["skill_dir"], tmp_path / "part", config, stop_after=1, **kwargs)
    assert not part.complete and part.search.episode == 1
    state = json.loads((tmp_path / "part" / "checkpoint" / "state.json").read_text())
    assert state["episode"] == 1 and not (tmp_path / "part" / "summary.json").exists()
    # The greedy executions before and after the first update wait, with their means, to run as a pair.
    assert [p["episode"] for p in state["pending"]] == [0, 1] and state["curve"] == []
    np.testing.assert_array_equal(state["pending"][1]["mean"], part.search.mean)
    with pytest.raises(FileExistsError, match="--resume"):
        learn(shared["skill_dir"], tmp_path / "part", config, **kwargs)
    with pytest.raises(ValueError, match="learn"):           # other settings: refused
        learn(shared["skill_dir"], tmp_path / "part", LearnConfig(episodes=2, rollouts=2, held_out=1, seed=4,
                                                                  select_poses=1),
              resume=True, **kwargs)
    # A crash after the logs were appended to, before the next checkpoint: results.jsonl holds the
    # record that comes next and half a line, progress.csv a row, TensorBoard an event, none of them
    # in the checkpoint. And the software changed (drake "0.0.0"): the versions are not settings.
    part_dir = tmp_path / "part"
    following = (tmp_path / "whole" / "results.jsonl").read_text().splitlines()[len(state["records"])]
    with open(part_dir / "results.jsonl", "a") as f:
        f.write(following + "\n" + following[:25])
    with open(part_dir / "progress.csv", "a") as f:
        f.write("0,0,1,1,999.0,,,1.0,,,,\n")
    if TENSORBOARD:
        from torch.utils.tensorboard import SummaryWriter

        with SummaryWriter(str(part_dir / "tensorboard")) as writer:
            writer.add_scalar("progress/greedy_return", 999.0, global_step=0)
    saved = json.loads((part_dir / "config.json").read_text())
    saved["versions"]["drake"] = "0.0.0"
    (part_dir / "config.json").write_text(json.dumps(saved))
    resumed_rows, log = [], io.StringIO()
    resumed = learn(shared["skill_dir"], tmp_path / "part", config, resume=True, on_episode=resumed_rows.append,
                    log=log, **kwargs)
    assert resumed.complete
    assert "drake 0.0.0 -> " in log.getvalue()
    assert json.loads((part_dir / "config.json").read_text())["versions"]["drake"] == "0.0.0"   # as started
    # The logs were cut back to the checkpoint: the resumed run's are the uninterrupted run's.
    assert resumed_rows == rows                   # the checkpoint's curve was empty: every row after it
    assert (part_dir / "progress.csv").read_bytes() == (tmp_path / "whole" / "progress.csv").read_bytes()
    if TENSORBOARD:                               # TensorBoard shows the curve, the stale event purged
        for column in ("greedy_return", "greedy_success", "mean_return", "exploration"):
            expected = [(r["episode"], np.float32(r[column])) for r in rows if r[column] is not None]
            assert _scalars(tmp_path / "whole" / "tensorboard", column) == expected
            assert _scalars(part_dir / "tensorboard", column) == expected
    else:
        assert not (part_dir / "tensorboard").exists()

    np.testing.assert_array_equal(resumed.search.mean, whole.search.mean)
    np.testing.assert_array_equal(resumed.search.covariances, whole.search.covariances)
    lines = {name: [json.loads(line) for line in (tmp_path / name / "results.jsonl").read_text().splitlines()]
             for name in ("whole", "part")}
    assert _numbers(lines["part"]) == _numbers(lines["whole"])
    kinds = [r["type"] for r in lines["whole"]]
    assert kinds.count("rollout") == 4 and kinds.count("greedy") == 3 and kinds.count("held_out") == 2
    assert resumed.summary["curve"] == whole.summary["curve"]
    # The guarded selection (docs/method.md 5.1) ran the start and the last, which is also the best
    # greedy mean (update 2: the highest greedy return, 139.4), on one shared pose (select_poses=1) and
    # kept the last: every verdict a success, and the higher learned return.
    select = [r for r in lines["whole"] if r["type"] == "select"]
    assert len(select) == 1 and select[0]["episode"] == 2 == whole.summary["selected_episode"]
    scores = [(c["episode"], c["verdict_successes"], round(c["mean_return"], 1)) for c in select[0]["candidates"]]
    assert scores == [(0, 1, 130.5), (2, 1, 134.7)]
    assert len({tuple(e["seed"] for e in c["executions"]) for c in select[0]["candidates"]}) == 1
    # The learned skill holds the selected mean and loads back.
    learned = Skill.load(tmp_path / "part" / "skill")
    np.testing.assert_array_equal(learned.initial_weights, whole.weights)
    np.testing.assert_array_equal(whole.weights, json.loads(
        (tmp_path / "whole" / "checkpoint" / "state.json").read_text())["candidates"]["2"])
    np.testing.assert_array_equal(whole.weights, whole.search.mean)
    assert learned.info["learning"]["method"] == "pi2-es-cov"
    assert (learned.info["learning"]["select"], learned.info["learning"]["selected_episode"]) == ("guarded", 2)
    # The search moved: the learned weights are not the initial ones.
    assert not np.array_equal(learned.initial_weights, Skill.load(shared["skill_dir"]).initial_weights)


def test_greedy_every_runs_greedy_executions_after_every_nth_update_and_the_last(tmp_path_factory, tmp_path):
    """PoWER's thesis budget: 30 updates of 1 rollout, a greedy execution every 6 (here 3 updates, every 2)."""
    shared = shared_skill(tmp_path_factory)
    config = LearnConfig(method="power", episodes=3, rollouts=1, held_out=0, seed=5, greedy_every=2, select="last")
    outcome = learn(shared["skill_dir"], tmp_path / "run", config, station_config=shared["station"],
                    rollout_config=rollout_config(), replay=False, progress=False)
    curve = outcome.summary["curve"]
    assert [c["episode"] for c in curve] == [0, 2, 3]
    records = [json.loads(line) for line in (tmp_path / "run" / "results.jsonl").read_text().splitlines()]
    assert [r["episode"] for r in records if r["type"] == "greedy"] == [0, 2, 3]
    rewards = {r["episode"]: r["reward"] for r in records if r["type"] == "rollout"}
    assert sorted(rewards) == [1, 2, 3]
    # Episode 2's row sums the block of updates 1 and 2; episode 3's is its own.
    assert curve[1]["mean_return"] == pytest.approx((rewards[1] + rewards[2]) / 2)
    assert curve[1]["best_return"] == max(rewards[1], rewards[2])
    assert curve[2]["mean_return"] == pytest.approx(rewards[3])
    # progress.csv: a row per greedy execution, the rollouts used by then, the block's numbers.
    rows = read_progress(tmp_path / "run" / "progress.csv")
    assert [(r["episode"], r["rollouts_used"]) for r in rows] == [(0, 0), (2, 2), (3, 3)]
    assert [r["mean_return"] for r in rows] == [None, curve[1]["mean_return"], curve[2]["mean_return"]]
    with pytest.raises(ValueError, match="greedy_every"):
        LearnConfig(greedy_every=0).validate()


def _curve_row(episode, greedy_return, mean_return=None, failures=None):
    return {"episode": episode, "greedy_success": greedy_return > 100, "greedy_verdict": True,
            "greedy_return": greedy_return, "mean_return": mean_return,
            "best_return": None if mean_return is None else mean_return + 5.0, "exploration": 0.25,
            "failures": failures or {}, "rollout_successes": 1, "ik_warnings": 0}


@pytest.mark.skipif(not TENSORBOARD, reason="tensorboard is not installed (pip install 'drake-skill[tensorboard]')")
def test_a_resumed_log_purges_the_tensorboard_events_after_its_checkpoint(tmp_path):
    """Episodes 0-1 checkpointed, episode 2 logged before a crash (return 999), then resumed."""
    first = RunLog(tmp_path, io.StringIO(), rollouts_per_episode=6)
    first.start([], [], fresh=True)
    curve = [_curve_row(0, 80.0), _curve_row(1, 120.5, 90.0, {"reflex": 2, "solver": 1})]
    rows = [first.row(c) for c in curve]
    first.row(_curve_row(2, 999.0, 1.0))
    first.close()
    assert len(read_progress(tmp_path / "progress.csv")) == 3
    assert rows[1]["rollouts_used"] == 6 and rows[1]["failures"] == 3
    assert rows[1]["failure_reasons"] == "reflex:2 solver:1"
    resumed = RunLog(tmp_path, io.StringIO(), rollouts_per_episode=6)
    resumed.start([{"type": "held_out"}], curve, fresh=False)
    resumed.row(_curve_row(2, 130.25, 100.0))
    resumed.close()
    assert [r["greedy_return"] for r in read_progress(tmp_path / "progress.csv")] == [80.0, 120.5, 130.25]
    assert (tmp_path / "results.jsonl").read_text() == '{"type": "held_out"}\n'
    assert _scalars(tmp_path / "tensorboard", "greedy_return") == [(0, 80.0), (1, 120.5), (2, 130.25)]
    assert _scalars(tmp_path / "tensorboard", "rollouts_used") == [(0, 0.0), (1, 6.0), (2, 12.0)]
    assert _scalars(tmp_path / "tensorboard", "mean_return") == [(1, 90.0), (2, 100.0)]


def test_without_tensorboard_the_log_says_so_in_one_line(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "tensorboard", None)        # import tensorboard raises ImportError
    note, seen = io.StringIO(), []
    log = RunLog(tmp_path, note, rollouts_per_episode=2, on_episode=seen.append)
    log.start([], [], fresh=True)
    row = log.row(_curve_row(0, 50.0))
    log.close()
    assert note.getvalue().count("\n") == 1 and "pip install 'drake-skill[tensorboard]'" in note.getvalue()
    assert not (tmp_path / "tensorboard").exists() and seen == [row]
    assert (tmp_path / "progress.csv").read_text().splitlines() == [",".join(PROGRESS_COLUMNS),
                                                                   "0,0,0,1,50.0,,,0.25,,,,"]
    assert progress_row(_curve_row(0, 50.0), 2) == row


def test_the_git_commit_is_recorded_only_for_a_drake_skill_checkout(tmp_path):
    """None outside a git checkout, and None for a package inside some other repository (a venv in a checkout)."""
    assert _git_commit(tmp_path) == (None, None)
    subprocess.run(["git", "init", "-q", str(tmp_path)], check=True)
    subprocess.run(["git", "-C", str(tmp_path), "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-q",
                    "--allow-empty", "-m", "x"], check=True)
    (tmp_path / "venv" / "site-packages").mkdir(parents=True)
    assert _git_commit(tmp_path / "venv" / "site-packages") == (None, None)
    commit, dirty = _git_commit(tmp_path)
    assert len(commit) == 40 and dirty is False


def _execution(verdict, dense, failed=False):
    return {"seed": 1, "failed": failed, "reason": "reflex" if failed else "", "verdict": verdict,
            "dense_return": dense, "success": verdict, "final_object_state": 0.0}


def test_the_guarded_selection_keeps_the_start_unless_a_learned_mean_scores_at_least_as_well():
    from drake_skill.learning.selection import Candidate, best_greedy_episode, choose, score, select_seed

    start = Candidate(0, [_execution(True, 300.0), _execution(True, 280.0)])
    worse = Candidate(5, [_execution(True, 900.0), _execution(False, 50.0)])      # a verdict lost
    tripped = Candidate(3, [_execution(True, 999.0, failed=True), _execution(True, 400.0)])   # a trip: a failure
    assert score(start.executions) == (2, 290.0) and score(tripped.executions) == (1, 200.0)
    assert choose([start, worse, tripped]) is start
    better = Candidate(5, [_execution(True, 300.0), _execution(True, 281.0)])
    assert choose([start, better]) is better
    equal = Candidate(5, [_execution(True, 280.0), _execution(True, 300.0)])
    assert choose([start, equal]) is equal                      # a tie goes to the later mean
    assert choose([Candidate(0, []), start]) is start
    with pytest.raises(ValueError, match="no candidate"):
        choose([])
    greedy = [{"episode": e, **_execution(v, r, f)} for e, v, r, f in
              ((0, True, 900.0, False), (1, True, 200.0, False), (2, True, 500.0, True), (3, True, 200.0, False))]
    assert best_greedy_episode(greedy) == 3 and best_greedy_episode(greedy[:1]) is None
    seeds = {select_seed(0, k) for k in range(10)}
    assert len(seeds) == 10 and not seeds & {pose_seed(0, e, c) for e in range(6) for c in range(6)}


def test_a_run_that_makes_the_skill_worse_returns_the_start(tmp_path_factory, tmp_path):
    """Exploration 100 x Sigma_0 throws the mean far off; the guarded selection, judging by the learned
    verdict and return alone, returns the start W_0, and its held-out success is the start's."""
    shared = shared_skill(tmp_path_factory)
    config = LearnConfig(episodes=1, rollouts=2, held_out=1, seed=2, exploration_scale=100.0, select_poses=2)
    outcome = learn(shared["skill_dir"], tmp_path / "run", config, station_config=shared["station"],
                    rollout_config=rollout_config(), replay=False, progress=False, log=io.StringIO())
    s = outcome.summary
    assert s["selected_episode"] == 0 and s["held_out_after"] == s["held_out_before"]
    np.testing.assert_array_equal(outcome.weights, Skill.load(shared["skill_dir"]).initial_weights)
    np.testing.assert_array_equal(Skill.load(tmp_path / "run" / "skill").initial_weights, outcome.weights)
    assert not np.array_equal(outcome.search.mean, outcome.weights)
    select = [json.loads(line) for line in (tmp_path / "run" / "results.jsonl").read_text().splitlines()][-2]
    assert select["type"] == "select" and [c["episode"] for c in select["candidates"]] == [0, 1]
    start, last = select["candidates"]
    assert (start["verdict_successes"], start["mean_return"]) > (last["verdict_successes"], last["mean_return"])
    with pytest.raises(ValueError, match="select"):
        LearnConfig(select="best").validate()


def test_span_exploration_maps_blends_of_the_demonstrations_and_their_covariance():
    from drake_skill.learning.exploration import SpanExploration

    w0, w1, w2 = np.zeros((4, 7)), np.arange(28.0).reshape(4, 7), np.ones((4, 7))
    span = SpanExploration(w0, [w1, w2], ridge=0.0)
    np.testing.assert_array_equal(span.weights([[1.0, 0.0]]), w1)            # the unit vectors: the demos
    np.testing.assert_array_equal(span.weights([[0.5, 2.0]]), 0.5 * w1 + 2.0 * w2)
    batch = span.weights(np.array([[[1.0, 0.0]], [[0.0, -1.0]]]))
    assert batch.shape == (2, 4, 7) and np.array_equal(batch[1], -w2)
    # The demonstrations' coordinates 0, e1, e2: variances 1/3, covariance -1/6 (ddof 1).
    np.testing.assert_allclose(span.initial_covariance(), [[[1 / 3, -1 / 6], [-1 / 6, 1 / 3]]])
    with pytest.raises(ValueError, match="at least 2 demonstrations"):
        SpanExploration(w0, [])
    with pytest.raises(ValueError, match="exploration"):
        LearnConfig(exploration="wide").validate()


def test_approach_exploration_quiets_the_bases_before_the_demonstrations_first_contact():
    """docs/method.md 5.4: the bases centred up to APPROACH_MARGIN_S after the first contact (centres
    equally spaced over [0, tau]) are scaled by the factor, the rest kept; no contact or a factor of 1
    leaves Sigma_b^0 as it is. The first contact comes back from the fit's start_join."""
    from drake_skill.fitted_skill import START_JOIN_FRACTION
    from drake_skill.learning.exploration import APPROACH_MARGIN_S, approach_covariance, first_contact_time

    sigma0 = np.stack([np.eye(7) * (b + 1.0) for b in range(11)])          # centres 0, 1, ..., 10 s
    quiet = approach_covariance(sigma0, 10.0, 4.0 - APPROACH_MARGIN_S + 0.5, 0.01)
    np.testing.assert_allclose(quiet[:5], 0.01 * sigma0[:5])                # centres 0-4 s <= 4.5 s
    np.testing.assert_array_equal(quiet[5:], sigma0[5:])
    np.testing.assert_array_equal(approach_covariance(sigma0, 10.0, None, 0.01), sigma0)
    np.testing.assert_array_equal(approach_covariance(sigma0, 10.0, 4.0, 1.0), sigma0)
    skill = types.SimpleNamespace(config=types.SimpleNamespace(dmp=types.SimpleNamespace(start_join=0.3)),
                                  dmps=[types.SimpleNamespace(tau=12.0)], initial_index=0)
    assert first_contact_time(skill) == pytest.approx(0.3 / START_JOIN_FRACTION * 12.0)
    skill.config.dmp.start_join = 0.0
    assert first_contact_time(skill) is None
    for bad in (0.0, 1.5, float("nan")):
        with pytest.raises(ValueError, match="approach_exploration"):
            LearnConfig(approach_exploration=bad).validate()
    with pytest.raises(ValueError, match="approach_exploration.*span"):
        LearnConfig(approach_exploration=0.1, exploration="span").validate()


def test_a_run_exploring_the_span_returns_a_blend_of_the_demonstrations(tmp_path_factory, tmp_path):
    """``exploration: span`` (docs/method.md 5.2): every sample, and so the learned mean, lies on the line
    through the two Close demonstrations' weights; the scale defaults to 1."""
    shared = shared_skill(tmp_path_factory)
    skill = Skill.load(shared["skill_dir"])
    config = LearnConfig(episodes=1, rollouts=2, held_out=0, seed=1, exploration="span", select="last")
    outcome = learn(shared["skill_dir"], tmp_path / "run", config, station_config=shared["station"],
                    rollout_config=rollout_config(), replay=False, progress=False, log=io.StringIO())
    assert outcome.search.mean.shape == (1, 1)            # theta: one coordinate for two demonstrations
    other = skill.dmps[1 - skill.initial_index].weights
    theta = float(outcome.search.mean[0, 0])
    assert theta != 0.0
    np.testing.assert_allclose(outcome.weights, skill.initial_weights + theta * (other - skill.initial_weights))
    np.testing.assert_array_equal(Skill.load(tmp_path / "run" / "skill").initial_weights, outcome.weights)
    assert json.loads((tmp_path / "run" / "config.json").read_text())["learn"]["exploration_scale"] == 1.0


# ----------------------------------------------------------------------------- runlog's pieces, by hand
def test_progress_rows_and_their_csv_lines_by_hand(tmp_path):
    from drake_skill.learning.runlog import _csv_line

    row = progress_row({"episode": 3, "greedy_success": 1, "greedy_verdict": 0, "greedy_return": 12.5,
                        "mean_return": 7.25, "best_return": 9.0, "exploration": 0.5, "rollout_successes": 2,
                        "failures": {"solver": 1, "reflex": 2}, "ik_warnings": 4}, 5)
    assert row == {"episode": 3, "rollouts_used": 15, "greedy_success": 1, "greedy_verdict": 0,
                   "greedy_return": 12.5, "mean_return": 7.25, "best_return": 9.0, "exploration": 0.5,
                   "rollout_successes": 2, "failures": 3, "failure_reasons": "reflex:2 solver:1", "ik_warnings": 4}
    assert list(row) == list(PROGRESS_COLUMNS)
    assert type(row["greedy_success"]) is int and type(row["greedy_verdict"]) is int
    # Episode 0 (no rollouts yet): the rollout columns are None, not 0, whatever the row holds.
    first = progress_row({"episode": 0, "greedy_success": True, "greedy_verdict": False, "greedy_return": 1.0,
                          "exploration": 0.5, "rollout_successes": 0, "failures": {"x": 1}, "ik_warnings": 0}, 5)
    assert (first["rollouts_used"], first["greedy_success"], first["greedy_verdict"]) == (0, 1, 0)
    assert [first[k] for k in ("mean_return", "best_return", "rollout_successes", "failures", "ik_warnings")] \
        == [None] * 5
    assert first["failure_reasons"] == "x:1"
    assert progress_row({"episode": 2, "greedy_success": 0, "greedy_verdict": 0, "greedy_return": 1.0,
                         "exploration": 0.5, "mean_return": 0.0, "failures": None}, 3)["failures"] == 0
    # Floats by repr (round trip), None empty, ints and text as they are, quoted where CSV needs it.
    assert _csv_line([1, 0.1, None, np.float64(1 / 3), "a b", "x,y"]) == '1,0.1,,0.3333333333333333,a b,"x,y"\n'
    log = RunLog(tmp_path, io.StringIO(), rollouts_per_episode=5)
    log._tensorboard = lambda purge_step: None
    log.start([], [], fresh=True)
    log.row({"episode": 3, "greedy_success": 1, "greedy_verdict": 0, "greedy_return": 12.5, "mean_return": 7.25,
             "best_return": 9.0, "exploration": 0.5, "rollout_successes": 2, "failures": {"solver": 1, "reflex": 2},
             "ik_warnings": 4})
    assert (tmp_path / "progress.csv").read_text().splitlines()[1] == \
        "3,15,1,0,12.5,7.25,9.0,0.5,2,3,reflex:2 solver:1,4"
    back, = read_progress(tmp_path / "progress.csv")
    assert back == row and [type(back[k]) for k in ("episode", "greedy_return", "failures")] == [int, float, int]


def test_the_logs_of_a_fresh_and_a_resumed_start(tmp_path):
    note = io.StringIO()
    (tmp_path / "tensorboard").mkdir()
    (tmp_path / "tensorboard" / "old").write_text("x")
    purges = []
    log = RunLog(tmp_path, note, rollouts_per_episode=2)
    assert (log.results_path, log.progress_path, log.tensorboard_dir) == \
        (tmp_path / "results.jsonl", tmp_path / "progress.csv", tmp_path / "tensorboard")
    log._tensorboard = lambda purge_step: purges.append(purge_step)
    log.start([{"b": 1, "a": [2, 3]}], [], fresh=True)
    assert not (tmp_path / "tensorboard").exists() and purges == [None]
    assert (tmp_path / "results.jsonl").read_text() == '{"a": [2, 3], "b": 1}\n'
    assert (tmp_path / "progress.csv").read_text() == ",".join(PROGRESS_COLUMNS) + "\n"
    log.records([])
    log.records([{"z": 0}, {"y": None}])
    assert (tmp_path / "results.jsonl").read_text() == '{"a": [2, 3], "b": 1}\n{"z": 0}\n{"y": null}\n'
    log.close()
    # A resume keeps tensorboard/ and purges from the episode after the checkpoint's last.
    (tmp_path / "tensorboard").mkdir()
    resumed = RunLog(tmp_path, note, rollouts_per_episode=2)
    resumed._tensorboard = lambda purge_step: purges.append(purge_step)
    resumed.start([], [_curve_row(0, 1.0), _curve_row(7, 2.0, 1.0), _curve_row(4, 2.0, 1.0)], fresh=False)
    resumed.start([], [], fresh=False)
    assert purges == [None, 5, 0] and (tmp_path / "tensorboard").is_dir()
    assert (tmp_path / "results.jsonl").read_text() == ""
    assert note.getvalue() == ""


def test_software_versions_name_every_package_and_the_checkout(monkeypatch):
    from importlib import metadata
    from pathlib import Path

    import drake_skill
    from drake_skill.learning import runlog

    monkeypatch.setattr(runlog, "VERSIONED_PACKAGES", ("numpy", "no-such-distribution-xyz"))
    versions = runlog.software_versions()
    assert list(versions) == ["numpy", "no-such-distribution-xyz", "python", "git_commit", "git_dirty"]
    assert versions["numpy"] == metadata.version("numpy") and versions["no-such-distribution-xyz"] is None
    assert versions["python"] == sys.version.split()[0]
    root = Path(drake_skill.__file__).resolve().parent.parent
    assert (versions["git_commit"], versions["git_dirty"]) == _git_commit(root)


class _Writer:
    """A stand-in SummaryWriter: what was written, flushed and closed."""

    def __init__(self):
        self.scalars, self.flushes, self.closed = [], 0, False

    def add_scalar(self, tag, value, global_step):
        self.scalars.append((tag, value, global_step))

    def flush(self):
        self.flushes += 1

    def close(self):
        self.closed = True


def test_rows_go_to_the_writer_as_scalars_until_it_is_closed(tmp_path, monkeypatch):
    writer = _Writer()
    log = RunLog(tmp_path, io.StringIO(), rollouts_per_episode=3)
    log.row(_curve_row(0, 5.0))                    # before start: no writer, the row is still appended
    log._tensorboard = lambda purge_step: writer
    log.start([], [], fresh=True)
    log.row(_curve_row(2, 7.5, 6.0, {"reflex": 1}))
    assert writer.scalars == [("progress/rollouts_used", 6.0, 2), ("progress/greedy_success", 0.0, 2),
                              ("progress/greedy_verdict", 1.0, 2), ("progress/greedy_return", 7.5, 2),
                              ("progress/mean_return", 6.0, 2), ("progress/best_return", 11.0, 2),
                              ("progress/exploration", 0.25, 2), ("progress/rollout_successes", 1.0, 2),
                              ("progress/failures", 1.0, 2), ("progress/ik_warnings", 0.0, 2)]
    assert all(type(v) is float for _, v, _ in writer.scalars) and writer.flushes == 1
    log.close()
    assert writer.closed
    log.row(_curve_row(3, 8.0))                    # after close: appended, not written to the closed writer
    log.close()
    assert len(writer.scalars) == 10 and [r["episode"] for r in read_progress(tmp_path / "progress.csv")] == [2, 3]
    # Without the tensorboard package: one exact line on the run's stream.
    monkeypatch.setitem(sys.modules, "tensorboard", None)
    note = io.StringIO()
    assert RunLog(tmp_path, note, 3)._tensorboard(purge_step=None) is None
    assert note.getvalue() == ("tensorboard is not installed: no TensorBoard events "
                               "(pip install 'drake-skill[tensorboard]')\n")


def test_a_damaged_progress_file_says_what_holds_the_same_curve(tmp_path):
    path = tmp_path / "progress.csv"
    path.write_text("episode,greedy\n0,1\n")
    with pytest.raises(ValueError) as e:
        read_progress(path)
    assert str(e.value) == (f"{path}: not a learning run's progress.csv (columns ['episode', 'greedy']; expected "
                            f"{', '.join(PROGRESS_COLUMNS)})")
    path.write_bytes((",".join(PROGRESS_COLUMNS) + "\n").encode() + b"\xff0")
    with pytest.raises(ValueError) as e:
        read_progress(path)
    assert str(e.value).startswith(f"{path}: damaged CSV (") and str(e.value).endswith(
        "); summary.json and results.jsonl beside it hold the same curve")


def test_the_git_state_ignores_untracked_files_and_sees_changed_ones(tmp_path):
    def git(*args):
        subprocess.run(["git", "-C", str(tmp_path), "-c", "user.name=t", "-c", "user.email=t@t", *args], check=True,
                       capture_output=True)

    git("init", "-q")
    (tmp_path / "tracked.txt").write_text("a")
    git("add", "tracked.txt")
    git("commit", "-q", "-m", "x")
    (tmp_path / "untracked.txt").write_text("b")
    commit, dirty = _git_commit(tmp_path)
    assert dirty is False and len(commit) == 40
    (tmp_path / "tracked.txt").write_text("changed")
    assert _git_commit(tmp_path) == (commit, True)
