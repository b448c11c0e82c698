"""Where the grid's runs execute: worker processes, or Ray.

Each task is a whole learning run (minutes); ``fn(task)`` runs it in a
worker and returns a small JSON-able dict. The workers stay up between
tasks, so a worker builds its station once per skill
(:func:`drake_skill.experiments.grid.execute_task` keeps the built runners).

- :func:`run_on_processes`: ``workers`` processes started with ``spawn``
  (as :class:`~drake_skill.learning.workers.ProcessPool`), one task each at
  a time, so a worker that dies is known to have died in its task: the task
  is given to a new worker, up to ``max_attempts`` times in all.
- :func:`run_on_ray`: Ray tasks of one CPU each, on a local ``ray.init()``
  or a cluster (``address``); Ray retries a task whose worker or node died
  (``max_retries``).

An exception raised by ``fn`` is not retried (the same inputs would raise it
again): it is reported as the task's error and the others go on.
``on_done(task, result, error)`` is called in this process as each task
ends: ``result`` a dict, or None with ``error`` a one-line reason.
"""

from __future__ import annotations

import multiprocessing
import traceback
from collections import deque
from collections.abc import Callable, Sequence
from multiprocessing.connection import wait
from typing import Any

__all__ = ["MAX_ATTEMPTS", "RAY_INSTALL", "ray_or_error", "run_on_processes", "run_on_ray"]

#: Attempts per task whose worker process dies (the first and two retries).
MAX_ATTEMPTS = 3

#: How to install the optional Ray package (named in the error when it is missing).
RAY_INSTALL = "pip install ray (in this project: .venv/bin/pip install 'drake-skill[ray]')"

OnDone = Callable[[Any, "dict | None", "str | None"], None]


def _serve(fn: Callable, connection) -> None:
    """A worker process: run ``fn`` on each task received until None."""
    while True:
        try:
            task = connection.recv()
        except EOFError:
            return
        if task is None:
            return
        try:
            connection.send(("ok", fn(task)))
        except Exception as error:          # fn's own error: report it, keep serving
            last = traceback.extract_tb(error.__traceback__)[-1]
            connection.send(("error", f"{type(error).__name__}: {error} ({last.filename}:{last.lineno})"))


class _Workers:
    """Spawned worker processes, each with its pipe; started on demand, replaced when dead."""

    def __init__(self, fn: Callable, n_workers: int):
        self.fn = fn
        self.n_workers = int(n_workers)
        self._context = multiprocessing.get_context("spawn")
        self.idle: list[tuple[Any, Any]] = []
        self.started = 0

    def start(self) -> tuple[Any, Any]:
        from drake_skill.learning.workers import spawn_worker

        worker = spawn_worker(self._context, _serve, self.fn)
        self.started += 1
        return worker

    def send(self, task) -> tuple[Any, Any]:
        """Gives ``task`` to an idle worker (one that died idle is replaced) or a new one."""
        while self.idle:
            worker = self.idle.pop()
            try:
                worker[1].send(task)
                return worker
            except (BrokenPipeError, OSError):
                self.stop(worker, kill=True)
        worker = self.start()
        worker[1].send(task)
        return worker

    @staticmethod
    def stop(worker, kill: bool = False) -> None:
        process, connection = worker
        if not kill:
            try:
                connection.send(None)
            except (BrokenPipeError, OSError):
                pass
            process.join(timeout=10)
        if process.is_alive():
            process.terminate()
            process.join(timeout=5)
        connection.close()


def run_on_processes(tasks: Sequence, fn: Callable, workers: int, on_done: OnDone,
                     max_attempts: int = MAX_ATTEMPTS) -> None:
    """Runs ``fn(task)`` for every task on up to ``workers`` spawned processes.

    ``fn`` must be importable by name (a module-level function). A task whose
    worker dies (killed, out of memory, a crash in native code) goes to a
    new worker, at most ``max_attempts`` times; after that ``on_done`` gets
    the error "worker died".
    """
    if int(workers) < 1:
        raise ValueError(f"--workers {workers}: expected at least 1 process")
    pool = _Workers(fn, min(int(workers), max(len(tasks), 1)))
    pending, busy, attempts = deque(enumerate(tasks)), {}, [0] * len(tasks)
    try:
        while pending or busy:
            while pending and len(busy) < pool.n_workers:
                index, task = pending.popleft()
                worker = pool.send(task)
                busy[worker[1]] = (worker, index)
                attempts[index] += 1
            for connection in wait(list(busy)):
                worker, index = busy.pop(connection)
                try:
                    kind, payload = connection.recv()
                except EOFError:                  # the worker died in this task
                    _died(pool, worker, index, tasks, attempts, max_attempts, pending, on_done)
                    continue
                pool.idle.append(worker)
                on_done(tasks[index], payload if kind == "ok" else None, None if kind == "ok" else payload)
    finally:
        for worker, _ in busy.values():
            pool.stop(worker, kill=True)
        for worker in pool.idle:
            pool.stop(worker)


def _died(pool, worker, index, tasks, attempts, max_attempts, pending, on_done) -> None:
    """A worker died in task ``index``: queue it again first, or give up after ``max_attempts``."""
    worker[0].join(timeout=5)
    code = worker[0].exitcode
    pool.stop(worker, kill=True)
    if attempts[index] < max_attempts:
        pending.appendleft((index, tasks[index]))
    else:
        on_done(tasks[index], None, f"worker died {attempts[index]} times (last exit code {code})")


def ray_or_error(option: str = "--ray"):
    """The ``ray`` module, or a one-line ValueError naming ``option`` and how to install Ray."""
    try:
        import ray
    except ImportError:
        raise ValueError(f"{option}: the optional ray package is not installed; {RAY_INSTALL}, "
                         "or leave out --ray / --ray-address to run on local processes") from None
    return ray


def run_on_ray(tasks: Sequence, fn: Callable, workers: int, on_done: OnDone, address: str | None = None,
               max_attempts: int = MAX_ATTEMPTS, shared: tuple = ()) -> None:
    """Runs ``fn(task, *shared)`` for every task as Ray tasks of one CPU each.

    ``address``: an existing cluster ("auto", "ray://host:port"; nothing on
    disk is shared: ``shared`` goes to every task through Ray's object store,
    put once), or None for a local ``ray.init`` with ``workers`` CPUs (shut
    down at the end). A task whose worker died, or whose node went (preempted,
    crashed, removed), is retried by Ray, ``max_attempts - 1`` times, and a
    finished task's result lost with its node is made again (Ray's lineage
    reconstruction); ``on_done`` is called once per task either way (tests:
    a worker node removed mid-grid, tests/test_experiment.py).
    """
    from drake_skill.learning.workers import _WORKER_ENV, connect_ray

    ray = ray_or_error("--ray-address" if address else "--ray")
    owns = connect_ray(address, workers, runtime_env={"env_vars": dict(_WORKER_ENV)}, log_to_driver=False)
    remote = ray.remote(num_cpus=1, max_retries=int(max_attempts) - 1)(fn)
    try:
        shared_refs = [ray.put(value) for value in shared]
        refs = {remote.remote(task, *shared_refs): task for task in tasks}
        while refs:
            ready, _ = ray.wait(list(refs), num_returns=1)
            for ref in ready:
                task = refs.pop(ref)
                try:
                    on_done(task, ray.get(ref), None)
                except ray.exceptions.RayError as error:     # fn raised, or the worker died every time
                    on_done(task, None, " ".join(str(error).split())[:300])
    finally:
        for ref in list(refs):
            ray.cancel(ref, force=True)
        if owns:
            ray.shutdown()
