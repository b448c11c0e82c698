"""Rollouts on worker processes (and Ray): the same seeds give the same numbers."""

import dataclasses as dc
import pickle

import numpy as np
import pytest

from drake_skill.learning.workers import ProcessPool, RunnerSpec, SerialPool, make_pool, ray_available
from drake_skill.fitted_skill import Skill

from learning_support import rollout_config, shared_skill
from ray_cluster_support import local_ray_map, netns_unavailable


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    shared = shared_skill(tmp_path_factory)
    skill = Skill.load(shared["skill_dir"])
    spec = RunnerSpec.create(shared["skill_dir"], shared["station"], rollout_config())
    W = skill.initial_weights
    rng = np.random.default_rng(4)
    L = np.linalg.cholesky(skill.sigma0)
    explored = W + np.einsum("bij,bj->bi", L, rng.standard_normal(W.shape))
    # Rollout 1 is a runaway sample: it fails (workspace) and the others go on.
    tasks = [(W, 31), (W * 1e6, 32), (explored, 33), (W, 34)]
    serial_runner = spec.build()
    serial = SerialPool(serial_runner).map(tasks)
    return spec, tasks, serial


def test_serial_and_two_workers_give_identical_results(setup):
    spec, tasks, serial = setup
    done = []
    with make_pool(spec, workers=2) as pool:
        assert isinstance(pool, ProcessPool) and pool.n_workers == 2
        parallel = pool.map(tasks, progress=lambda i, r: done.append(i))
        assert sorted(done) == [0, 1, 2, 3]
        # The pool stays up between calls (persistent workers, diagrams built once).
        again = pool.map(tasks[:1])
    assert [r.seed for r in parallel] == [31, 32, 33, 34]
    for a, b in zip(serial, parallel):
        assert a.equal_numbers(b), f"seed {a.seed}: serial and pool differ"
    assert again[0].equal_numbers(serial[0])
    # Different weights or poses give different numbers: the comparison can fail.
    assert not serial[0].equal_numbers(serial[3])
    assert serial[2].failed or not np.array_equal(serial[0].ee_pose, serial[2].ee_pose)


def test_a_failed_rollout_is_recorded_and_the_run_goes_on(setup):
    _, _, serial = setup
    failed = serial[1]
    assert failed.failed and failed.reason == "workspace" and failed.dense_return == 0.0
    assert not failed.success and len(failed.rewards) == 0
    # The rollouts after it ran (they have a recorded path, or their own reason).
    for r in (serial[2], serial[3]):
        assert r.reason != "workspace"
        assert r.failed or (len(r.times) > 0 and len(r.rewards) > 0)


def test_pool_arguments_are_checked(setup):
    spec, _, _ = setup
    with pytest.raises(ValueError, match="workers"):
        make_pool(spec, workers=0)
    with pytest.raises(FileNotFoundError, match="skill.json"):
        RunnerSpec.create("/nonexistent/skill", None)


def test_a_demonstrations_dmp_runs_with_its_own_goal_and_duration(setup):
    """Plain imitation of demonstration j (``evaluate --all-demos``) executes DMP j whole:
    its weights, goal and duration, not its weights on the initial DMP's goal."""
    spec, _, _ = setup
    skill = Skill.load(spec.skill_dir)
    other = 1 - skill.initial_index
    assert not np.allclose(skill.dmps[other].goal, skill.initial_dmp.goal)   # the check can fail
    for index, expected in ((None, skill.initial_dmp), (other, skill.dmps[other])):
        runner = dc.replace(spec, dmp_index=index).build()
        runner.reset(expected.weights, 35)
        dmp = runner.dmp_system.get_dmp(runner.dmp_system.GetMyContextFromRoot(runner.context))
        np.testing.assert_array_equal(dmp.goal, expected.goal)
        np.testing.assert_array_equal(dmp.weights, expected.weights)
        assert dmp.tau == expected.tau and runner.duration() == expected.tau + runner.settle_time
    with pytest.raises(ValueError, match="dmp_index 2: the skill .* has 2 demonstration DMPs"):
        dc.replace(spec, dmp_index=2).build()


@pytest.mark.skipif(not ray_available(), reason="ray is not installed (optional: pip install ray)")
def test_ray_actors_give_the_same_results(setup, tmp_path):
    """The Ray actors of a local ray.init, in a network namespace of its own (Ray would bind this
    machine's address: tests/ray_cluster_support.py)."""
    reason = netns_unavailable()
    if reason:
        pytest.skip(reason)
    spec, tasks, serial = setup
    (tmp_path / "tasks.pkl").write_bytes(pickle.dumps((spec, tasks, 2)))
    local_ray_map(tmp_path)
    results = pickle.loads((tmp_path / "results.pkl").read_bytes())
    assert [r.seed for r in results] == [31, 32, 33, 34]
    for a, b in zip(serial, results):
        assert a.equal_numbers(b), f"seed {a.seed}: serial and Ray differ"
