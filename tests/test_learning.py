"""The learning run: rewards per method, seeds, configuration, and checkpoint/resume."""

import json
import types

import numpy as np
import pytest

from drake_skill.learning.loop import LearnConfig, episode_rewards, learn, pose_seed
from drake_skill.skills import load_skill
from drake_skill.skill import Skill

from learning_support import rollout_config, shared_skill


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


def _numbers(records):
    """The records without wall-clock times."""
    def strip(r):
        return {k: v for k, v in r.items() if k not in ("wall_s",)}
    return [strip(r) for r in records]


def test_resume_after_an_interruption_reproduces_the_uninterrupted_run(tmp_path_factory, tmp_path):
    shared = shared_skill(tmp_path_factory)
    config = LearnConfig(episodes=2, rollouts=2, held_out=1, seed=3)
    kwargs = dict(station_config=shared["station"], rollout_config=rollout_config(), replay=False,
                  progress=False)
    whole = learn(shared["skill_dir"], tmp_path / "whole", config, **kwargs)
    assert whole.complete and whole.search.episode == 2

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
        learn(shared["skill_dir"], tmp_path / "part", LearnConfig(episodes=2, rollouts=2, held_out=1, seed=4),
              resume=True, **kwargs)
    resumed = learn(shared["skill_dir"], tmp_path / "part", config, resume=True, **kwargs)
    assert resumed.complete

    np.testing.assert_array_equal(resumed.search.mean, whole.search.mean)
    np.testing.assert_array_equal(resumed.search.covariances, whole.search.covariances)
    lines = {name: [json.loads(line) for line in (tmp_path / name / "results.jsonl").read_text().splitlines()]
             for name in ("whole", "part")}
    assert _numbers(lines["part"]) == _numbers(lines["whole"])
    kinds = [r["type"] for r in lines["whole"]]
    assert kinds.count("rollout") == 4 and kinds.count("greedy") == 3 and kinds.count("held_out") == 2
    assert resumed.summary["curve"] == whole.summary["curve"]
    # The learned skill holds the final mean and loads back.
    learned = Skill.load(tmp_path / "part" / "skill")
    np.testing.assert_array_equal(learned.initial_weights, whole.search.mean)
    assert learned.info["learning"]["method"] == "pi2-es-cov"
    # The search moved: the learned weights are not the initial ones.
    assert not np.array_equal(learned.initial_weights, Skill.load(shared["skill_dir"]).initial_weights)


def test_greedy_every_runs_greedy_executions_after_every_nth_update_and_the_last(tmp_path_factory, tmp_path):
    """PoWER's thesis budget: 30 updates of 1 rollout, a greedy execution every 6 (here 3 updates, every 2)."""
    shared = shared_skill(tmp_path_factory)
    config = LearnConfig(method="power", episodes=3, rollouts=1, held_out=0, seed=5, greedy_every=2)
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
    with pytest.raises(ValueError, match="greedy_every"):
        LearnConfig(greedy_every=0).validate()
