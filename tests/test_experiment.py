"""``drake-skill experiment``: a tiny grid end to end on worker processes, resuming, retries, the report,
and on a Ray cluster of 3 nodes (a head and 2 workers) in a network namespace of its own.

The grid: the shared small Close skill (learning_support), PI^2-ES-Cov and
PoWER with the dense reward, 2 runs each, 1 episode of 2 rollouts (PoWER: 2
episodes of 1), 1 held-out pose, the segmenter's object frame, 2 workers.
"""

import importlib.util
import json
import os
import shutil
import signal
import time
from pathlib import Path

import numpy as np
import pytest

from drake_skill.cli.main import main
from drake_skill.experiments.grid import GridConfig, before_path, plan_tasks, run_dir, run_grid
from drake_skill.experiments.pool import MAX_ATTEMPTS, run_on_processes
from drake_skill.experiments.report import write_report
from drake_skill.experiments.table import COLUMNS, read_table, table_text

from learning_support import rollout_config, shared_skill
from ray_cluster_support import netns_unavailable, start_cluster

RAY = importlib.util.find_spec("ray") is not None
CONFIG = dict(skills=("close",), methods=("pi2-es-cov", "power"), rewards=("dense",), runs=2, episodes=1,
              rollouts=2, held_out=1)


def _grid(shared, out, use_ray=False, **changes):
    return run_grid(out, GridConfig(**{**CONFIG, **changes}), skill_dir=shared["skill_dir"],
                    station_yaml=shared["station_yaml"], rollout_config=rollout_config(), workers=2,
                    use_ray=use_ray, progress=False, quiet=True)


@pytest.fixture(scope="module")
def grid(tmp_path_factory):
    shared = shared_skill(tmp_path_factory)
    out = tmp_path_factory.mktemp("experiment") / "grid"
    outcome = _grid(shared, out)
    return shared, out, outcome


def _keys(rows):
    return [(r["skill"], r["method"], r["reward"], r["run"], r["episode"]) for r in rows]


def test_tiny_grid_runs_every_cell_on_worker_processes(grid):
    _, out, outcome = grid
    assert outcome.failed == [] and outcome.ran == 4 and outcome.stored == 4 and outcome.workers == 2
    assert json.loads((out / "close" / "held_out_before.json").read_text())["report"]["seeds"] == [900000]
    rows = read_table(out / "table.csv")
    # PoWER (METHODS order): 2 updates of 1 rollout, greedy before and after the 2nd (every C = 2);
    # PI^2-ES-Cov: greedy before and after its one update of 2 rollouts.
    expected = [("close", m, "dense", run, e) for m, episodes in (("power", (0, 2)), ("pi2-es-cov", (0, 1)))
                for run in (0, 1) for e in episodes]
    assert _keys(rows) == expected
    assert [r["rollouts_used"] for r in rows if r["method"] == "power"][:2] == [0, 2]  # greedy every C
    assert [r["rollouts_used"] for r in rows if r["method"] == "pi2-es-cov"][:2] == [0, 2]
    for r in rows:
        assert r["success"] in (0, 1) and 0.0 <= r["held_out_after"] <= 1.0 and r["held_out_before"] is not None
    for method in ("pi2-es-cov", "power"):
        folder = run_dir(out, "close", method, "dense", 1)
        summary = json.loads((folder / "summary.json").read_text())
        assert summary["workers"] == 1 and summary["seed"] == 1 and summary["held_out_poses"] == 1
        assert (folder / "checkpoint" / "search.npz").is_file() and not (folder / "skill").exists()
    assert not list(out.glob("**/.*.partial"))


def test_a_grid_run_is_the_learn_run_of_its_settings(grid, tmp_path):
    """The grid's run 0 of PI^2-ES-Cov gives the numbers of learn() called with the same settings."""
    from drake_skill.learning.loop import learn

    shared, out, _ = grid
    config = GridConfig(**CONFIG).learn_config("pi2-es-cov", "dense", 0)
    direct = learn(out / "close" / "initial_skill", tmp_path / "direct", config, station_config=shared["station"],
                   rollout_config=rollout_config(), replay=False, progress=False, log=open(os.devnull, "w"))
    stored = json.loads((run_dir(out, "close", "pi2-es-cov", "dense", 0) / "summary.json").read_text())
    strip = lambda curve: [{k: v for k, v in c.items() if k != "mean"} for c in curve]  # noqa: E731
    assert strip(stored["curve"]) == json.loads(json.dumps(strip(direct.summary["curve"])))


def test_resume_skips_finished_runs_redoes_a_deleted_one_and_ends_a_partial_one(grid):
    shared, out, _ = grid
    table = (out / "table.csv").read_bytes()
    kept = run_dir(out, "close", "pi2-es-cov", "dense", 0) / "summary.json"
    kept_stat = kept.stat().st_mtime_ns
    shutil.rmtree(run_dir(out, "close", "pi2-es-cov", "dense", 1))
    # A worker that died after learn() ended, before the rename: a partial folder with the last checkpoint.
    partial = run_dir(out, "close", "power", "dense", 1).with_name(".run_001.partial")
    run_dir(out, "close", "power", "dense", 1).rename(partial)
    (partial / "summary.json").unlink()
    outcome = _grid(shared, out)
    assert outcome.ran == 2 and outcome.stored == 4 and outcome.failed == []
    assert kept.stat().st_mtime_ns == kept_stat                 # not run again
    assert json.loads((run_dir(out, "close", "power", "dense", 1) / "summary.json").read_text())["resumed"]
    assert not partial.exists()
    # The redone and the resumed run give the same numbers: the same table, no duplicate, no gap.
    assert (out / "table.csv").read_bytes() == table
    rows = read_table(out / "table.csv")
    assert len(set(_keys(rows))) == len(rows)
    # Raising --runs adds only the new runs; other settings are refused.
    specs = {"close": None}
    names = [t.name for t in plan_tasks(out, GridConfig(**{**CONFIG, "runs": 3}), specs)]
    assert names == ["close/pi2-es-cov/dense/run_002", "close/power/dense/run_002"]  # the order of --methods
    with pytest.raises(ValueError, match="--episodes 2: the runs stored"):
        _grid(shared, out, episodes=2)


def _die_once(path):
    """A task for the pool: the first attempt kills its worker process, the next returns."""
    marker = Path(path)
    if not marker.exists():
        marker.write_text("died")
        os._exit(3)
    return {"path": path}


def _always_die(path):
    os._exit(4)


def test_a_run_whose_worker_dies_is_retried(tmp_path):
    done = {}
    tasks = [str(tmp_path / f"task{i}") for i in range(3)]
    run_on_processes(tasks, _die_once, 2, lambda t, result, error: done.setdefault(t, (result, error)))
    assert done == {t: ({"path": t}, None) for t in tasks}
    done.clear()
    run_on_processes(["x"], _always_die, 1, lambda t, result, error: done.setdefault(t, (result, error)))
    assert done["x"][0] is None and f"worker died {MAX_ATTEMPTS} times" in done["x"][1]


def _synthetic_table(path):
    """A table of every method and reward over 2 skills, 4 runs, 5 x 6 (PoWER 30 x 1)."""
    rng = np.random.default_rng(0)
    rows = []
    for skill in ("open", "close"):
        for method in ("power", "pi2", "pi2-cov", "pi2-es", "pi2-es-cov", "cma-es"):
            for reward in ("dense", "sparse"):
                for run in range(4):
                    n, per = (6, 6)                 # PoWER's 30 x 1: greedy every 6th update
                    step = 6 if method == "power" else 1
                    rows += [dict(skill=skill, method=method, reward=reward, run=run, episode=e * step,
                                  rollouts_used=e * per, success=int(rng.random() < e / n), return_=0.0,
                                  held_out_after=float(rng.integers(0, 11)) / 10, held_out_before=0.4)
                             for e in range(n)]
    for r in rows:
        r["return"] = r.pop("return_")
    path.write_text(table_text(rows))
    return path


def test_report_from_the_table_alone_is_the_same_twice(grid, tmp_path):
    _, out, _ = grid
    for name, table in (("tiny", out / "table.csv"), ("full", _synthetic_table(tmp_path / "synthetic.csv"))):
        saved = tmp_path / name
        saved.mkdir()
        shutil.copy(table, saved / "table.csv")
        first = {p.name: p.read_bytes() for p in write_report(saved / "table.csv", saved / "a")}
        second = {p.name: p.read_bytes() for p in write_report(saved / "table.csv", saved / "b")}
        assert first == second and "results.md" in first
        skills = sorted({r["skill"] for r in read_table(table)})
        assert sorted(first) == sorted(["results.md", *(f"{s}_methods.png" for s in skills),
                                        *(f"{s}_dense.png" for s in skills)])
        text = first["results.md"].decode()
        # Each claim is marked, whichever way (the verdicts are reported, not asserted).
        assert sum(f"**{v}**" in text for v in ("holds", "does not hold", "cannot tell")) >= 1
        assert text.count("**") == 6
        assert "Notes" not in text
    # Hand-written notes beside the table end results.md as they are.
    (saved / "notes.md").write_text("Draw: what limits it.\n\n- tried: a\n")
    noted = {p.name: p.read_bytes() for p in write_report(saved / "table.csv", saved / "c")}
    assert noted["results.md"].decode().endswith(
        "## Notes (`notes.md`, written by hand beside the table)\n\nDraw: what limits it.\n\n- tried: a\n")
    assert noted["results.md"].startswith(first["results.md"].rstrip(b"\n"))
    assert {k: v for k, v in noted.items() if k != "results.md"} == {k: v for k, v in first.items()
                                                                     if k != "results.md"}


def test_report_cli_and_bad_input_name_the_flag(grid, tmp_path, capsys):
    _, out, _ = grid
    shutil.copy(out / "table.csv", tmp_path / "table.csv")
    assert main(["experiment", "report", str(tmp_path)]) == 0
    assert (tmp_path / "results.md").is_file()
    bad = [(["--methods", "pi3"], "--methods pi3"), (["--skills", "fly"], "--skills fly"),
           (["--rewards", "medium"], "--rewards medium"), (["--runs", "0"], "--runs 0")]
    if not RAY:
        bad.append((["--ray"], "pip install ray"))
    for argv, text in bad:
        capsys.readouterr()
        assert main(["experiment", "run", "--out", str(tmp_path / "bad"), *argv]) == 2
        err = capsys.readouterr().err
        assert text in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "bad").exists()
    (tmp_path / "other.csv").write_text("a,b\n1,2\n")
    assert main(["experiment", "report", str(tmp_path), "--table", str(tmp_path / "other.csv")]) == 2
    assert "not an experiment table" in capsys.readouterr().err
    assert tuple(read_table(tmp_path / "table.csv")[0]) == COLUMNS


def test_a_ray_task_needs_nothing_under_out_and_only_the_driver_writes_there(grid, tmp_path):
    """Issue 48 item 1: what a Ray worker runs (execute_remote) reads and writes nothing under --out
    (here moved away while it runs), and the driver's store gives the process pool's file."""
    import pickle

    from drake_skill.experiments.grid import _runner_specs, execute_task
    from drake_skill.experiments.remote import execute_remote, remote_tasks, store_result

    shared, out, _ = grid
    config = GridConfig(**CONFIG).validate()
    new = tmp_path / "out"
    specs = _runner_specs(new, config, shared["skill_dir"], shared["station_yaml"], rollout_config(), True)
    (task,) = [t for t in plan_tasks(new, config, specs) if t.kind == "before"]
    remote, skills = remote_tasks([task], execute_task)
    assert str(new).encode() not in pickle.dumps(remote[0]).replace(str(new / "close" / "initial_skill").encode(), b"")
    assert remote[0].task.path == ""     # (the skill folder goes only as the label for config.json)
    new.rename(tmp_path / "away")                  # the worker's node has no --out at all
    payload = execute_remote(remote[0], pickle.loads(pickle.dumps(skills)))
    (tmp_path / "away").rename(new)
    store_result(task, payload)
    assert Path(task.path).read_bytes() == (out / "close" / "held_out_before.json").read_bytes()


def test_skills_are_names_or_skill_files(tmp_path):
    """``--skills`` takes a shipped skill's name or a skill file; the grid goes by the
    file's skill name, and one skill given twice is a one-line error."""
    from drake_skill.skills.spec import SKILL_DIR

    text = (SKILL_DIR / "open.yaml").read_text().replace("name: open", "name: my-open", 1)
    (tmp_path / "my_open.yaml").write_text(text)
    config = GridConfig(skills=(str(tmp_path / "my_open.yaml"), "close")).validate()
    assert config.skills == ("my-open", "close")
    assert config.sources == {"my-open": str(tmp_path / "my_open.yaml"), "close": "close"}
    assert config.validate().skills == ("my-open", "close")          # validating twice changes nothing
    with pytest.raises(ValueError, match=r"^--skills .*open\.yaml: skill 'open' is already given as open;"):
        GridConfig(skills=("open", str(SKILL_DIR / "open.yaml"))).validate()
    with pytest.raises(ValueError, match=r"^--skills .*nope\.yaml: skill file"):
        GridConfig(skills=(str(tmp_path / "nope.yaml"),)).validate()


def test_a_grid_prepares_a_skill_on_the_skill_s_scenario_under_its_scenario_file(tmp_path):
    """A grid with no ``--skill-dir`` records and fits each skill as ``drake-skill learn`` does
    (``workflow.prepare``), on the skill's scenario under ``--scenario``, typed: no command's
    flags (a hand-built namespace once lacked ``--config`` and failed here)."""
    from drake_skill.experiments.grid import prepare_config
    from drake_skill.skills import load_skill

    (tmp_path / "near.yaml").write_text("object: {x: 0.62}\n")
    config = prepare_config("draw", tmp_path / "near.yaml", quiet=True)
    assert (config.skill, config.quiet, config.fit, config.skill_dir, config.demos) == ("draw", True, "thesis",
                                                                                       None, None)
    spec = load_skill("draw")
    assert config.station_for(spec).object.x == 0.62
    assert prepare_config("draw").station_for(spec).object.x == 0.68


def test_the_thesis_grid_runs_without_the_force_limit_that_the_skills_scenarios_turn_on(tmp_path):
    """The shipped scenarios give way before the reflex (docs/method.md 5.3); the chapter-7 grid
    (``GridConfig.station`` "thesis", its default) lays THESIS_STATION under ``--scenario``, so it
    runs the thesis's station, while the generalization study runs each skill's as ``learn`` does.
    A ``--scenario`` file still reaches the thesis station, and a station stored by older code,
    which today's schema cannot read, is a different station (not a traceback)."""
    from drake_skill.experiments.generalization import generalization_config
    from drake_skill.experiments.grid import GridConfig, grid_station
    from drake_skill.inputs import scenario
    from drake_skill.station.scenario import dump_scenario, same_station

    assert (GridConfig().station, generalization_config(["open"]).station) == ("thesis", "skill")
    for skill in ("open", "close", "draw"):
        assert scenario(skill).controller.force_limit.enabled
        assert not grid_station(skill).controller.force_limit.enabled
        assert grid_station(skill, thesis_station=False).controller.force_limit.enabled
    (tmp_path / "near.yaml").write_text("object: {x: 0.62}\n")
    near = grid_station("draw", tmp_path / "near.yaml")
    assert (near.object.x, near.controller.force_limit.enabled) == (0.62, False)
    old = dump_scenario(grid_station("open")).replace("object:\n", "object:\n  kind: box\n", 1)
    assert not same_station(old, dump_scenario(grid_station("open")))
    with pytest.raises(ValueError, match="station 'robot': unknown; give thesis or skill"):
        GridConfig(station="robot").validate()




def test_an_unreachable_ray_address_is_one_line_within_seconds(tmp_path, capsys):
    """Issue 48's bad input: a --ray-address nothing answers at ends as one line where the value enters,
    in seconds (ray.init alone retries for minutes), before anything is written to --out."""
    import socket

    with socket.socket() as s:          # a loopback port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    for argv in (["experiment", "run", "--skills", "close"], ["learn", "--skill", "close"]):
        assert main([*argv, "--ray-address", f"127.0.0.1:{port}", "--out", str(tmp_path / "out")]) == 2
        err = capsys.readouterr().err
        assert f"argument --ray-address: 127.0.0.1:{port}: nothing answers there within 5 s" in err
        assert err.count("\n") == 1
    assert not (tmp_path / "out").exists()


# ----------------------------------------------------------------------- on a Ray cluster
def _cluster_unavailable() -> str | None:
    return "ray is not installed (pip install ray)" if not RAY else netns_unavailable()


@pytest.fixture(scope="module", autouse=True)
def _cluster_started(request, tmp_path_factory):
    """The cluster, started with the module (it comes up while the process pool's grid runs) when a
    selected test uses it, and shut down after the module; None when not."""
    module = [item for item in request.session.items if item.module is request.module]
    if not any("cluster" in item.fixturenames for item in module) or _cluster_unavailable():
        yield None
        return
    started = start_cluster(tmp_path_factory.mktemp("ray_cluster"))
    yield started
    started.close()


@pytest.fixture(scope="module")
def cluster(_cluster_started):
    """A Ray cluster of a head with no CPU and 2 worker nodes of 1 CPU each, on this machine, in a
    network namespace whose only interface is loopback (tests/ray_cluster_support.py)."""
    reason = _cluster_unavailable()
    if reason:
        pytest.skip(reason)
    return _cluster_started


#: The runs of the tiny grid.
RUNS = CONFIG["runs"] * len(CONFIG["methods"])


def _grid_argv(shared, out, address, runs=CONFIG["runs"]) -> list:
    """``drake-skill experiment run`` of the tiny grid (CONFIG, the process pool's) on the cluster."""
    c = CONFIG
    return ["experiment", "run", "--skills", *c["skills"], "--methods", *c["methods"], "--rewards", *c["rewards"],
            "--runs", runs, "--episodes", c["episodes"], "--rollouts", c["rollouts"], "--held-out", c["held_out"],
            "--skill-dir", shared["skill_dir"], "--station-config", shared["station_yaml"],
            "--ray-address", address, "--out", out, "--quiet"]


def _until(condition, what: str, running=lambda: True, timeout: float = 300.0):
    """Waits for ``condition()`` while ``running()`` holds (the driver has not ended)."""
    end = time.monotonic() + timeout
    while not condition():
        assert running(), f"the driver ended before {what}"
        assert time.monotonic() < end, f"not within {timeout:g} s: {what}"
        time.sleep(0.1)


def _stored(out) -> list[str]:
    return sorted(str(p.parent.relative_to(out)) for p in Path(out).glob("close/*/dense/run_*/summary.json"))


def _finished(stdout: str) -> str:
    """"N run(s) finished, M stored" of ``experiment run``'s summary line (Ray prints its own lines
    there too: a task it retries)."""
    (line,) = [line for line in stdout.splitlines() if " run(s) finished in " in line]
    ran, rest = line.split(" run(s) finished in ", 1)
    return f"{ran} run(s) finished, {rest.split('; ')[1].split(' stored in ')[0]} stored"


def _task_folders(node: Path) -> set[str]:
    """The temporary folders of the grid's tasks on a worker node (``remote.execute_remote``'s: one
    left there is a task whose process was killed)."""
    return {p.name for p in node.glob("drake_skill_task_*")}


@pytest.fixture(scope="module")
def cluster_grid(grid, cluster):
    """The tiny grid run by ``drake-skill experiment run --ray-address`` on the cluster, through two faults.

    The first driver is killed with SIGKILL as soon as the grid has stored its first unit (the held-out
    record before learning; a run is under way on the other node). When its tasks have ended (Ray ends
    a dead driver's tasks), the same command is started again and resumes; while it runs, worker node 0
    is removed as a run starts on it (the run's task folder appears in the node's TMPDIR), and a new
    node is added in its place."""
    shared, _, _ = grid
    out = cluster.folder / "grid"
    argv = _grid_argv(shared, out, cluster.address)
    record = before_path(out, "close")

    def tasks() -> list[int]:
        return cluster.call(op="running", name="execute_remote")["pids"]

    first = cluster.spawn(argv, "first")
    _until(record.is_file, "the held-out record is stored", lambda: cluster.wait(first, 0) is None)
    under_way = tasks()
    os.kill(first, signal.SIGKILL)
    killed = {"rc": cluster.wait(first, 60), "runs": _stored(out), "record": record.stat().st_mtime_ns,
              "under_way": under_way}
    _until(lambda: not tasks(), "the killed driver's tasks end", timeout=60)
    node = cluster.folder / "node_0"
    earlier = _task_folders(node)
    second = cluster.spawn(argv, "second")
    _until(lambda: _task_folders(node) - earlier, "a run starts on node 0", lambda: cluster.wait(second, 0) is None)
    removed = {"runs": _stored(out), "folders": _task_folders(node) - earlier}
    assert cluster.call(op="remove_node")["tmpdir"] == str(node)
    cluster.call(op="add_node")
    rc = cluster.wait(second, 400)
    stdout, stderr = cluster.output("second")
    return {"out": out, "killed": killed, "removed": removed, "rc": rc, "stdout": stdout, "stderr": stderr,
            "left": _task_folders(node)}


def test_a_grid_on_a_ray_cluster_gives_the_process_pool_table(grid, cluster_grid):
    """Issue 48: ``experiment run --ray-address`` on a cluster of 2 worker nodes (here through the faults
    of the next two tests) writes the process pool's table byte for byte and the same run folders; each
    run's config.json names the driver's skill folder, not the worker's copy."""
    _, out, _ = grid
    ray_out = cluster_grid["out"]
    assert cluster_grid["rc"] == 0, cluster_grid["stdout"] + cluster_grid["stderr"][-3000:]
    assert (ray_out / "table.csv").read_bytes() == (out / "table.csv").read_bytes()
    for method in CONFIG["methods"]:
        for run in range(CONFIG["runs"]):
            pool_run, ray_run = (run_dir(o, "close", method, "dense", run) for o in (out, ray_out))
            assert sorted(p.name for p in ray_run.iterdir()) == sorted(p.name for p in pool_run.iterdir())
            assert json.loads((ray_run / "config.json").read_text())["skill_dir"] == \
                str((ray_out / "close" / "initial_skill").resolve())
    assert not list(ray_out.glob("**/.*.partial"))


def test_the_driver_killed_mid_grid_resumes_to_the_same_table(cluster_grid):
    """The held-out record the killed driver stored is kept (not measured again), the runs it had under
    way are run by the second driver, once each; the table is the pool's (the test above)."""
    killed = cluster_grid["killed"]
    assert killed["rc"] == -signal.SIGKILL and killed["under_way"]
    assert before_path(cluster_grid["out"], "close").stat().st_mtime_ns == killed["record"]
    todo = RUNS - len(killed["runs"])
    assert todo > 0 and _finished(cluster_grid["stdout"]) == f"{todo} run(s) finished, {RUNS} stored"
    assert "not finished" not in cluster_grid["stdout"]


def test_a_worker_node_lost_mid_grid_loses_no_run_and_runs_none_twice(cluster_grid):
    """Worker node 0 went while a run was on it (its task folder is left there, never finished) and
    runs were still to be stored; every run is stored once (the second driver's count of finished runs
    is the runs it had to do, not more: Ray retried the lost task, and only that) and the table has
    each row once."""
    removed, killed = cluster_grid["removed"], cluster_grid["killed"]
    assert removed["folders"] and removed["folders"] <= cluster_grid["left"]
    assert len(removed["runs"]) < RUNS
    todo = RUNS - len(killed["runs"])
    assert _finished(cluster_grid["stdout"]) == f"{todo} run(s) finished, {RUNS} stored"
    rows = read_table(cluster_grid["out"] / "table.csv")
    assert len(set(_keys(rows))) == len(rows) == 2 * RUNS          # a greedy point before and after
    assert _stored(cluster_grid["out"]) == [f"close/{m}/dense/run_{r:03d}" for m in sorted(CONFIG["methods"])
                                            for r in range(CONFIG["runs"])]


def test_learn_on_a_ray_cluster_gives_the_serial_curve(grid, cluster):
    """``learn --ray-address`` with the settings of the grid's run 0 of PI^2-ES-Cov (learn() serially in
    one worker: test_a_grid_run_is_the_learn_run_of_its_settings) gives its curve and its search state.
    ``--workers 3`` on the cluster's 2 CPUs makes 2 actors (a third waited for a CPU forever)."""
    shared, out, _ = grid
    config = GridConfig(**CONFIG).learn_config("pi2-es-cov", "dense", 0)
    learned = cluster.folder / "learn"
    argv = ["learn", "--skill-dir", shared["skill_dir"], "--station-config", shared["station_yaml"],
            "--method", config.method, "--reward", config.reward, "--episodes", config.episodes,
            "--rollouts", config.rollouts, "--seed", config.seed, "--held-out", config.held_out,
            "--select", config.select, "--workers", 3, "--no-replay", "--quiet",
            "--ray-address", cluster.address, "--out", learned]
    assert cluster.wait(cluster.spawn(argv, "learn"), 300) == 0, cluster.output("learn")
    serial_run = run_dir(out, "close", "pi2-es-cov", "dense", 0)
    on_ray, serial = (json.loads((d / "summary.json").read_text()) for d in (learned, serial_run))
    assert (on_ray["workers"], serial["workers"]) == (2, 1)
    assert on_ray["curve"] == serial["curve"] and len(serial["curve"]) == 2
    with np.load(learned / "checkpoint" / "search.npz") as a, np.load(serial_run / "checkpoint" / "search.npz") as b:
        assert sorted(a.files) == sorted(b.files)
        for key in a.files:
            np.testing.assert_array_equal(a[key], b[key])


def _files(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_a_cluster_with_no_free_cpu_is_one_line_within_seconds(grid, cluster, tmp_path):
    """Issue 48's bad input: with every CPU of the cluster reserved, ``experiment run --ray-address`` with
    runs to do (--runs 3 over a stored grid) ends with one line, in seconds, and the stored grid is as it
    was (connect_ray's refusal)."""
    shared, out, _ = grid
    stored = tmp_path / "grid"
    shutil.copytree(out, stored)
    files = _files(stored)
    assert cluster.call(op="occupy")["held"] == 2
    try:
        start = time.monotonic()
        code = cluster.wait(cluster.spawn(_grid_argv(shared, stored, cluster.address, runs=3), "busy"), 120)
        wall = time.monotonic() - start
    finally:
        cluster.call(op="release")
    stdout, stderr = cluster.output("busy")
    assert code == 2, stdout + stderr
    line = (f"drake-skill: error: --ray-address {cluster.address}: the cluster has no free CPU (2 in all, 0 free); "
            "free some, add a node, or leave --ray-address out to run here")
    # (Before it, Ray's own log lines of the connection.)
    assert stderr.endswith(f"\n{line}\n") and stderr.count("drake-skill") == 1 and "Traceback" not in stderr
    assert wall < 60
    assert _files(stored) == files
