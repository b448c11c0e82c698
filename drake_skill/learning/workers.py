"""Rollouts in parallel: persistent worker processes (or Ray actors), each owning one built diagram.

A Drake diagram and its context cannot be pickled, so a worker builds its own
:class:`~drake_skill.learning.rollout.RolloutRunner` once, from a
:class:`RunnerSpec` of plain data (the skill's directory, the station
configuration as YAML, the rollout configuration), and then receives only
``(weights, seed)`` per rollout and sends back the
:class:`~drake_skill.learning.rollout.RolloutResult`. A rollout's numbers
depend only on ``(weights, seed)`` (the runner resets its context to the
defaults every time), so the same seeds give the same results serially, on
the process pool and on Ray, whichever worker runs which rollout.

    spec = RunnerSpec.create("skills/open", station_config, RolloutConfig())
    with make_pool(spec, workers=2) as pool:
        results = pool.map([(W1, 11), (W2, 12)])          # in task order

- :class:`SerialPool`: one runner in this process (``workers=1``).
- :class:`ProcessPool`: ``workers`` processes started with ``spawn`` (no
  fork of a process holding Drake, VTK and torch threads), each with one
  thread for numpy/BLAS/torch and the software renderer (:data:`_WORKER_ENV`);
  tasks go to whichever worker is free. A
  worker that dies mid-rollout is replaced and its rollout recorded as
  failed (reason ``error``).
- :class:`RayPool`: one Ray actor per worker (``pip install ray``): an
  existing cluster (``ray_address``) or a local ``ray.init()``.

The worker processes are started with ``spawn``, which imports the main
module again in each worker: a script that makes a :class:`ProcessPool`
must guard its entry point with ``if __name__ == "__main__":``.

Messages between processes use multiprocessing's (or Ray's) own pickling
of this package's plain dataclasses and numpy arrays, between processes of
one run; nothing read from disk is unpickled.
"""

from __future__ import annotations

import dataclasses as dc
import logging
import multiprocessing
import os
from collections.abc import Callable, Sequence
from multiprocessing.connection import wait
from pathlib import Path
from typing import Any

import numpy as np

from drake_skill.learning.rollout import RolloutConfig, RolloutResult, RolloutRunner

__all__ = ["ProcessPool", "RayPool", "RunnerSpec", "SerialPool", "default_workers", "make_pool", "ray_available"]

#: Environment of a worker process: one thread per numerical library, so N
#: workers on N cores do not oversubscribe them; Mesa's software renderer
#: (llvmpipe, headless EGL without a GPU) rasterises in the calling thread
#: (``LP_NUM_THREADS=0``) instead of handing each frame to its own threads.
#: None of these changes a number (the images are the same); only how the
#: workers share the cores. A GPU driver ignores the last one.
_WORKER_ENV = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
               "LP_NUM_THREADS": "0"}

Task = tuple[np.ndarray, int]
Progress = Callable[[int, RolloutResult], None]


@dc.dataclass(frozen=True)
class RunnerSpec:
    """Plain data a worker builds its :class:`RolloutRunner` from.

    skill_dir: a saved :class:`~drake_skill.fitted_skill.Skill`; station_yaml: the
    ``Scenario`` as YAML (``dump_scenario``; the worker loads it with ``load_scenario``); rollout: the
    ``RolloutConfig`` fields; quiet_ik: drop differential IK's warnings in
    the worker after counting them (the main process reports the counts);
    dmp_index: the demonstration whose DMP (goal and duration) the rollouts
    execute (None: the skill's initial DMP; ``RolloutRunner``'s ``dmp``).
    """

    skill_dir: str
    station_yaml: str
    rollout: dict
    quiet_ik: bool = True
    dmp_index: int | None = None

    @classmethod
    def create(cls, skill_dir, station_config, rollout_config: RolloutConfig | None = None,
               quiet_ik: bool = True, dmp_index: int | None = None) -> "RunnerSpec":
        from drake_skill.station.scenario import dump_scenario

        if not (Path(skill_dir) / "skill.json").is_file():
            raise FileNotFoundError(f"{skill_dir}: no skill.json (workers load the skill from a saved "
                                    "skill directory; save it first)")
        rollout_config = (rollout_config or RolloutConfig()).validate()
        return cls(str(Path(skill_dir).resolve()), dump_scenario(station_config),
                   dc.asdict(rollout_config), quiet_ik, None if dmp_index is None else int(dmp_index))

    def build(self, meshcat=None) -> RolloutRunner:
        from drake_skill.fitted_skill import Skill
        from drake_skill.station.scenario import load_scenario

        station_config = load_scenario(data=self.station_yaml)     # the dumped Scenario, checked again
        skill = Skill.load(self.skill_dir)
        dmp = None
        if self.dmp_index is not None:
            if not 0 <= self.dmp_index < len(skill.dmps):
                raise ValueError(f"dmp_index {self.dmp_index}: the skill in {self.skill_dir} has "
                                 f"{len(skill.dmps)} demonstration DMPs (0..{len(skill.dmps) - 1})")
            dmp = skill.dmps[self.dmp_index]
        return RolloutRunner(skill, station_config, RolloutConfig(**self.rollout), meshcat=meshcat, dmp=dmp)


class _Pool:
    """Common interface: ``map(tasks, progress)`` -> results in task order."""

    n_workers: int = 1

    def map(self, tasks: Sequence[Task], progress: Progress | None = None) -> list[RolloutResult]:
        raise NotImplementedError

    def run(self, weights, seed: int) -> RolloutResult:
        return self.map([(weights, seed)])[0]

    def close(self) -> None:
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class SerialPool(_Pool):
    """Rollouts one after another on one runner in this process."""

    def __init__(self, runner: RolloutRunner):
        self.runner = runner
        self.n_workers = 1

    def map(self, tasks, progress=None):
        results = []
        for i, (weights, seed) in enumerate(tasks):
            results.append(self.runner.run(weights, int(seed)))
            if progress is not None:
                progress(i, results[-1])
        return results


# ------------------------------------------------------------------------ processes
def _quiet_ik() -> None:
    class _Drop(logging.Filter):
        def filter(self, record):
            return "Differential IK" not in record.getMessage()

    logging.getLogger("drake").addFilter(_Drop())


def _worker_main(spec: RunnerSpec, connection) -> None:
    """A worker process: build the runner, then serve (index, weights, seed) until None."""
    try:
        if spec.quiet_ik:
            _quiet_ik()
        runner = spec.build()
        connection.send(("ready", None))
    except BaseException as error:  # report why the worker could not start
        connection.send(("error", f"{type(error).__name__}: {error}"))
        return
    while True:
        try:
            message = connection.recv()
        except EOFError:
            return
        if message is None:
            return
        index, weights, seed = message
        try:
            result = runner.run(weights, seed)
        except BaseException as error:  # a wrong task (shape); keep serving
            result = RolloutResult(seed=int(seed), failed=True, reason="error",
                                   message=f"{type(error).__name__}: {error}"[:500], weights=np.asarray(weights))
        connection.send(("result", (index, result)))


def spawn_worker(context, target: Callable, payload) -> tuple[Any, Any]:
    """Starts ``target(payload, connection)`` in a process of the multiprocessing
    ``context`` with the workers' environment (:data:`_WORKER_ENV`, inherited by the
    spawned interpreter; this process's is restored). Returns (process, this end of
    the pipe)."""
    parent, child = context.Pipe()
    saved = {key: os.environ.get(key) for key in _WORKER_ENV}
    os.environ.update(_WORKER_ENV)
    try:
        process = context.Process(target=target, args=(payload, child), daemon=True)
        process.start()
    finally:
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value
    child.close()
    return process, parent


class ProcessPool(_Pool):
    """``n_workers`` persistent worker processes (``spawn``), one runner each.

    Workers start (and build their diagrams) in the constructor; it returns
    when all are ready, or raises RuntimeError with the first worker's error.
    """

    def __init__(self, spec: RunnerSpec, n_workers: int):
        if int(n_workers) < 1:
            raise ValueError(f"workers: expected >= 1, got {n_workers}")
        self.spec = spec
        self.n_workers = int(n_workers)
        self._context = multiprocessing.get_context("spawn")
        self._workers: list[tuple[Any, Any]] = []
        try:
            for _ in range(self.n_workers):
                self._workers.append(self._start())
            for process, connection in self._workers:
                self._await_ready(process, connection)
        except BaseException:
            self.close()
            raise

    def _start(self):
        return spawn_worker(self._context, _worker_main, self.spec)

    @staticmethod
    def _await_ready(process, connection) -> None:
        try:
            kind, payload = connection.recv()
        except EOFError:
            raise RuntimeError(f"a rollout worker exited while starting (exit code {process.exitcode})") from None
        if kind != "ready":
            raise RuntimeError(f"a rollout worker could not build its runner: {payload}")

    def map(self, tasks, progress=None):
        tasks = list(tasks)
        results: list[RolloutResult | None] = [None] * len(tasks)
        pending = list(range(len(tasks)))[::-1]
        busy: dict[int, int] = {}            # worker slot -> task index
        done = 0

        def dispatch(slot: int) -> None:
            index = pending.pop()
            weights, seed = tasks[index]
            self._workers[slot][1].send((index, np.asarray(weights, dtype=float), int(seed)))
            busy[slot] = index

        for slot in range(self.n_workers):
            if pending:
                dispatch(slot)
        while busy:
            ready = wait([self._workers[slot][1] for slot in busy])
            for slot in [s for s in list(busy) if self._workers[s][1] in ready]:
                connection = self._workers[slot][1]
                try:
                    kind, payload = connection.recv()
                    index, result = payload
                except EOFError:     # the worker died mid-rollout: record it, replace the worker
                    index = busy[slot]
                    process = self._workers[slot][0]
                    process.join(timeout=5)
                    result = RolloutResult(seed=int(tasks[index][1]), failed=True, reason="error",
                                           message=f"the worker process died (exit code {process.exitcode})",
                                           weights=np.asarray(tasks[index][0]))
                    self._workers[slot] = self._start()
                    self._await_ready(*self._workers[slot])
                del busy[slot]
                results[index] = result
                done += 1
                if progress is not None:
                    progress(index, result)
                if pending:
                    dispatch(slot)
        return results  # type: ignore[return-value]

    def close(self) -> None:
        for _process, connection in self._workers:
            try:
                connection.send(None)
            except (BrokenPipeError, OSError):
                pass
        for process, connection in self._workers:
            process.join(timeout=10)
            if process.is_alive():
                process.terminate()
                process.join(timeout=5)
            connection.close()
        self._workers = []


# ------------------------------------------------------------------------ Ray
def ray_available() -> bool:
    """Whether the optional ``ray`` package is installed."""
    try:
        import ray  # noqa: F401
    except ImportError:
        return False
    return True


#: How long an address is given to answer before ``--ray-address`` is an error [s].
RAY_CONNECT_TIMEOUT_S = 5.0


def check_ray_address(address: str, timeout: float = RAY_CONNECT_TIMEOUT_S) -> None:
    """A TCP connection to ``host:port`` (or ``ray://host:port``) within ``timeout`` s, or a
    one-line ValueError: ``ray.init`` itself retries an address that does not answer for minutes."""
    import socket

    hostport = address.split("://", 1)[-1]
    host, _, port = hostport.rpartition(":")
    if not host or not port.isdigit():
        raise ValueError(f"--ray-address {address}: expected 'auto', HOST:PORT or ray://HOST:PORT")
    try:
        socket.create_connection((host, int(port)), timeout=timeout).close()
    except OSError as e:
        raise ValueError(f"--ray-address {address}: nothing answers there within {timeout:g} s ({e}); start the "
                         "cluster (ray start --head) and give its address, or leave --ray-address out to run "
                         "here") from None


def connect_ray(address: str | None, n_cpus: int, **options) -> bool:
    """``ray.init`` on the cluster at ``address`` (probed first, bounded in time) or, with None, a
    local one of ``n_cpus`` CPUs; True when this call started Ray (the caller shuts it down). A
    cluster with no free CPU is a one-line ValueError (its tasks would wait forever)."""
    import ray

    if ray.is_initialized():
        return False
    if not address:
        ray.init(num_cpus=max(int(n_cpus), 1), include_dashboard=False, **options)
        return True
    if address != "auto":
        check_ray_address(address)
    try:
        ray.init(address=address, **options)
    except ConnectionError as e:
        raise ValueError(f"--ray-address {address}: {' '.join(str(e).split())[:200]}; start the cluster "
                         "(ray start --head), or leave --ray-address out to run here") from None
    free = ray.available_resources().get("CPU", 0.0)
    if free < 1.0:
        total = ray.cluster_resources().get("CPU", 0.0)
        ray.shutdown()
        raise ValueError(f"--ray-address {address}: the cluster has no free CPU ({total:g} in all, {free:g} free); "
                         "free some, add a node, or leave --ray-address out to run here")
    return True


class _RayWorkerImpl:
    """Body of the Ray actor: one runner, built once, from the skill's files as the driver sent them
    (written into the actor's own temporary folder: no node needs the driver's disk)."""

    def __init__(self, spec: RunnerSpec, skill_files: dict[str, bytes]):
        import atexit
        import shutil
        import tempfile

        from drake_skill.fileio import unpack_folder

        for key, value in _WORKER_ENV.items():
            os.environ.setdefault(key, value)
        if spec.quiet_ik:
            _quiet_ik()
        folder = unpack_folder(skill_files, tempfile.mkdtemp(prefix="drake_skill_skill_"))
        atexit.register(shutil.rmtree, folder, True)     # the actor's copy goes with its process
        self._runner = dc.replace(spec, skill_dir=str(folder)).build()

    def run(self, weights, seed):
        return self._runner.run(np.asarray(weights, dtype=float), int(seed))


class RayPool(_Pool):
    """One Ray actor per worker (each builds one runner).

    ``address``: an existing Ray cluster ("auto" or "ray://host:port"); None
    starts a local Ray with ``ray.init()`` (and shuts it down on close).
    ``num_cpus`` per actor: 1. The skill goes to the actors through Ray's
    object store and the results come back as the tasks' returns: nothing
    on disk is shared. On a cluster, at most one actor per free CPU
    (``n_workers`` is the count made): an actor holds its CPU for its life,
    so one more would wait for a CPU that never frees, and the rollouts given
    to it with it (a hang); the results do not depend on the count.
    """

    def __init__(self, spec: RunnerSpec, n_workers: int, address: str | None = None):
        try:
            import ray
        except ImportError:
            raise ValueError("--ray-address / RayPool needs the optional ray package: "
                             ".venv/bin/pip install ray") from None
        if int(n_workers) < 1:
            raise ValueError(f"workers: expected >= 1, got {n_workers}")
        self._ray = ray
        self._owns_ray = connect_ray(address, n_workers, log_to_driver=False) and not address
        free = int(ray.available_resources().get("CPU", 0)) if address else int(n_workers)
        self.n_workers = max(1, min(int(n_workers), free))
        from drake_skill.fileio import pack_folder

        actor = ray.remote(num_cpus=1)(_RayWorkerImpl)
        skill_files = ray.put(pack_folder(spec.skill_dir))      # once, through the object store
        self._actors = [actor.remote(spec, skill_files) for _ in range(self.n_workers)]

    def map(self, tasks, progress=None):
        ray = self._ray
        tasks = list(tasks)
        results: list[RolloutResult | None] = [None] * len(tasks)
        pending = list(range(len(tasks)))[::-1]
        busy: dict[Any, tuple[int, int]] = {}   # object ref -> (actor slot, task index)

        def dispatch(slot: int) -> None:
            index = pending.pop()
            weights, seed = tasks[index]
            ref = self._actors[slot].run.remote(np.asarray(weights, dtype=float), int(seed))
            busy[ref] = (slot, index)

        for slot in range(self.n_workers):
            if pending:
                dispatch(slot)
        while busy:
            ready, _ = ray.wait(list(busy), num_returns=1)
            for ref in ready:
                slot, index = busy.pop(ref)
                try:
                    result = ray.get(ref)
                except Exception as error:   # the actor died: record, go on with the others
                    result = RolloutResult(seed=int(tasks[index][1]), failed=True, reason="error",
                                           message=f"Ray actor failed: {error}"[:500])
                results[index] = result
                if progress is not None:
                    progress(index, result)
                if pending:
                    dispatch(slot)
        return results  # type: ignore[return-value]

    def close(self) -> None:
        for actor in getattr(self, "_actors", []):
            try:
                self._ray.kill(actor)
            except Exception:
                pass
        self._actors = []
        if self._owns_ray:
            self._ray.shutdown()
            self._owns_ray = False


def default_workers() -> int:
    """Rollout workers by default: the CPUs this process may run on
    (``os.sched_getaffinity``; ``os.cpu_count()`` where that is not available)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:      # not on Linux
        return max(1, os.cpu_count() or 1)


def make_pool(spec: RunnerSpec, workers: int = 1, ray_address: str | None = None, use_ray: bool = False,
              runner: RolloutRunner | None = None) -> _Pool:
    """The pool for ``workers``: serial (1, on ``runner`` or one built from ``spec``),
    processes (> 1), or Ray (``use_ray`` or a ``ray_address``)."""
    if int(workers) < 1:
        raise ValueError(f"workers: expected >= 1, got {workers}")
    if use_ray or ray_address:
        return RayPool(spec, workers, ray_address)
    if int(workers) == 1:
        return SerialPool(runner if runner is not None else spec.build())
    return ProcessPool(spec, workers)
