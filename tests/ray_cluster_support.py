"""Ray for the tests, kept on loopback: a network namespace of its own, and a cluster of a head and
worker nodes on this machine in it (tests/test_experiment.py, tests/test_workers.py).

Ray binds this machine's network address, not loopback, even for a local ``ray.init``, and the
tests' traffic must stay on this machine. So Ray, and every driver that talks to it, runs inside
a fresh network namespace whose only interface is loopback: ``unshare -rn`` (a user namespace
that maps this user to root, and a network namespace in it; no privilege needed where user
namespaces are allowed). Where ``unshare`` cannot make one, :func:`netns_unavailable` says why
and the tests skip.

- :func:`in_netns`: the argv for one command in a namespace of its own; :func:`local_ray_map`:
  rollouts on the Ray actors of a local ``ray.init`` there.
- :func:`start_cluster`: :func:`serve` in a namespace: a ``ray.cluster_utils.Cluster`` of a head
  with no CPU (the drivers connect to it) and worker nodes of 1 CPU each. The test process talks to
  it by JSON lines over its stdin and stdout (:class:`ClusterClient`): start a driver there
  (``spawn``: ``drake-skill ARGV`` through :func:`cli`; ``wait`` for it), remove a worker node, add
  one, list the processes running a task (``running``), reserve every free CPU (``occupy`` /
  ``release``). PIDs and files are not namespaced, so the
  test signals a driver and reads ``--out`` itself. End of input shuts the cluster down.

Every worker node runs with a ``TMPDIR`` of its own (``TMP/node_N``): what a task left there when
its process was killed shows where it was running.
"""

from __future__ import annotations

import dataclasses as dc
import json
import os
import select
import shutil
import subprocess
import sys
import tempfile
import time
import traceback
from pathlib import Path

#: The shell that brings loopback up in the new namespace and runs the command ("$0" "$@") there.
_UP = 'ip link set lo up && exec "$0" "$@"'

_UNAVAILABLE: list[str | None] = []


def netns_unavailable() -> str | None:
    """Why no network namespace can be made here (the tests' skip reason), or None."""
    if not _UNAVAILABLE:
        reason = None
        if shutil.which("unshare") is None or shutil.which("ip") is None:
            reason = "unshare or ip (util-linux, iproute2) is not installed"
        else:
            done = subprocess.run(["unshare", "-rn", "sh", "-c", _UP, "true"], capture_output=True, text=True,
                                  timeout=30)
            if done.returncode != 0:
                reason = f"unshare -rn cannot make a network namespace here: {done.stderr.strip()[:200]}"
        _UNAVAILABLE.append(reason)
    return _UNAVAILABLE[0]


def in_netns(argv: list[str]) -> list[str]:
    """``argv`` run in a network namespace of its own whose only interface is loopback."""
    return ["unshare", "-rn", "sh", "-c", _UP, *argv]


# ----------------------------------------------------------------------- in the test process
class ClusterError(RuntimeError):
    """The cluster process answered an error, none in time, or ended; the message ends with its log."""


@dc.dataclass
class ClusterClient:
    """The test's end of :func:`serve` (see the module docstring). It does not wait for the
    cluster to start: :attr:`address` (and the first request) does, up to ``start_s`` s."""

    process: subprocess.Popen
    folder: Path
    start_s: float = 120.0
    _address: str | None = None

    @property
    def address(self) -> str:
        """The head's address (HOST:PORT)."""
        if self._address is None:
            self._address = _read_line(self.process, self.start_s, self.folder)["address"]
        return self._address

    def call(self, within: float = 60.0, **request) -> dict:
        """Sends ``request``; its answer within ``within`` s, or a :class:`ClusterError`."""
        assert self.address
        self.process.stdin.write(json.dumps(request) + "\n")
        self.process.stdin.flush()
        answer = _read_line(self.process, within, self.folder)
        if not answer.get("ok"):
            raise ClusterError(f"{request['op']}: {answer.get('error')}")
        return answer

    def spawn(self, argv: list[str], name: str) -> int:
        """``drake-skill ARGV`` started in the namespace, its output in ``FOLDER/NAME.out`` / ``.err``;
        its PID."""
        return self.call(op="spawn", argv=[str(a) for a in argv], log=str(self.folder / name))["pid"]

    def wait(self, pid: int, timeout: float) -> int | None:
        """The exit status of the spawned ``pid`` (negative: killed by that signal), or None if it is
        still running after ``timeout`` s."""
        return self.call(within=timeout + 30.0, op="wait", pid=pid, timeout=timeout)["rc"]

    def output(self, name: str) -> tuple[str, str]:
        """(stdout, stderr) of the spawned command named ``name``."""
        return tuple((self.folder / f"{name}.{e}").read_text() for e in ("out", "err"))  # type: ignore

    def close(self) -> None:
        """Shuts the cluster down (end of input), and kills its process if it has not ended in 60 s."""
        try:
            self.process.stdin.close()
        except OSError:
            pass
        try:
            self.process.wait(timeout=60)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()


def _read_line(process: subprocess.Popen, timeout: float, folder: Path) -> dict:
    ready, _, _ = select.select([process.stdout], [], [], timeout)
    line = process.stdout.readline() if ready else ""
    if not line:
        log = (folder / "cluster.log").read_text(errors="replace")[-3000:]
        what = f"no answer in {timeout:g} s" if not ready else f"it ended (exit status {process.poll()})"
        raise ClusterError(f"the cluster process: {what}; its log ends:\n{log}")
    return json.loads(line)


def start_cluster(folder: Path, workers: int = 2) -> ClusterClient:
    """Starts :func:`serve` in a network namespace with ``workers`` worker nodes, its files (the logs,
    the nodes' ``TMPDIR``) in ``folder``; returns at once (the cluster takes seconds to start)."""
    folder.mkdir(parents=True, exist_ok=True)
    with open(folder / "cluster.log", "w") as log:
        process = subprocess.Popen(in_netns([sys.executable, __file__, "serve", str(folder), str(workers)]),
                                   stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=log, text=True,
                                   bufsize=1)
    return ClusterClient(process, folder)


def local_ray_map(folder: Path, timeout: float = 300.0) -> None:
    """:func:`ray_pool_map` in a network namespace of its own, on ``FOLDER/tasks.pkl`` (pickled:
    the ``RunnerSpec``, the tasks, the workers), into ``FOLDER/results.pkl``."""
    done = subprocess.run(in_netns([sys.executable, __file__, "ray-pool", str(folder)]), capture_output=True,
                          text=True, timeout=timeout)
    assert done.returncode == 0, f"exit status {done.returncode}:\n{done.stderr[-3000:]}"


# ----------------------------------------------------------------------- in the namespace
def ray_pool_map(folder: Path) -> None:
    """The tasks of ``FOLDER/tasks.pkl`` on a :class:`~drake_skill.learning.workers.RayPool` of a local
    ``ray.init`` (its files in a temporary folder of its own), the results into ``FOLDER/results.pkl``."""
    import pickle

    os.environ["RAY_USAGE_STATS_ENABLED"] = "0"
    os.environ["RAY_TMPDIR"] = tempfile.mkdtemp(prefix="ray_", dir="/tmp")
    try:
        from drake_skill.learning.workers import make_pool

        spec, tasks, workers = pickle.loads((folder / "tasks.pkl").read_bytes())
        with make_pool(spec, workers=workers, use_ray=True) as pool:
            results = pool.map(tasks)
        (folder / "results.pkl").write_bytes(pickle.dumps(results))
    finally:
        shutil.rmtree(os.environ["RAY_TMPDIR"], ignore_errors=True)


def cli(argv: list[str]) -> int:
    """``drake-skill ARGV`` with the rollouts of the tests' skill: ``learning_support.SETTLE`` s of
    settling (no flag sets it; the grid and learn runs the tests compare with use it)."""
    from drake_skill.cli import options
    from drake_skill.cli.main import main

    from learning_support import SETTLE

    chosen = options.rollout_config
    options.rollout_config = lambda *a, **k: dc.replace(chosen(*a, **k), settle_time=SETTLE)
    return main(argv)


class _Cluster:
    """What :func:`serve` holds: the cluster, its worker nodes, the drivers it started."""

    def __init__(self, folder: Path, workers: int):
        from ray.cluster_utils import Cluster

        self.folder = folder
        self.cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 0, "include_dashboard": False})
        self.nodes: list = []
        self.added = 0
        for _ in range(workers):
            self.add_node()
        self.cluster.wait_for_nodes()
        self.drivers: dict[int, subprocess.Popen] = {}
        self.held: list = []

    def add_node(self) -> dict:
        tmp = self.folder / f"node_{self.added}"
        tmp.mkdir()
        self.added += 1
        self.nodes.append((self.cluster.add_node(num_cpus=1, env_vars={"TMPDIR": str(tmp)}), tmp))
        return {"tmpdir": str(tmp)}

    def remove_node(self) -> dict:
        """The oldest worker node's processes killed at once (as a node that crashes or is
        preempted; ``allow_graceful`` would let them end their work first)."""
        node, tmp = self.nodes.pop(0)
        self.cluster.remove_node(node, allow_graceful=False)
        return {"tmpdir": str(tmp)}

    def spawn(self, argv: list[str], log: str) -> dict:
        with open(f"{log}.out", "w") as out, open(f"{log}.err", "w") as err:
            process = subprocess.Popen([sys.executable, __file__, "cli", *argv], stdout=out, stderr=err)
        self.drivers[process.pid] = process
        return {"pid": process.pid}

    def wait(self, pid: int, timeout: float) -> dict:
        try:
            return {"rc": self.drivers[pid].wait(timeout=timeout)}
        except subprocess.TimeoutExpired:
            return {"rc": None}

    def occupy(self) -> dict:
        """Every free CPU reserved by a placement group of this process's own driver, until
        :meth:`release`."""
        import ray
        from ray.util.placement_group import placement_group

        if not ray.is_initialized():
            ray.init(address=self.cluster.address, log_to_driver=False)
        free = int(ray.available_resources().get("CPU", 0))
        self.held = [placement_group([{"CPU": 1}] * free, strategy="SPREAD")]
        ray.get(self.held[0].ready(), timeout=60)
        _until(lambda: ray.available_resources().get("CPU", 0) == 0)
        return {"held": free}

    def release(self) -> dict:
        import ray
        from ray.util.placement_group import remove_placement_group

        for group in self.held:
            remove_placement_group(group)
        self.held = []
        _until(lambda: ray.available_resources().get("CPU", 0) >= 1)
        return {}

    def running(self, name: str) -> dict:
        """The processes of this cluster running Ray task ``name`` now (a Ray worker's process title
        is ``ray::NAME`` while it runs a task of that function, ``ray::IDLE`` between tasks)."""
        children: dict[int, list[int]] = {}
        titles = {}
        for entry in Path("/proc").iterdir():
            try:
                stat = (entry / "stat").read_text()
                titles[int(entry.name)] = (entry / "cmdline").read_bytes().split(b"\0")[0]
            except (ValueError, OSError):
                continue
            children.setdefault(int(stat.rsplit(")", 1)[1].split()[1]), []).append(int(entry.name))
        found, todo = [], [os.getpid()]
        while todo:
            for child in children.get(todo.pop(), []):
                todo.append(child)
                if titles.get(child) == f"ray::{name}".encode():
                    found.append(child)
        return {"pids": sorted(found)}

    def shutdown(self) -> None:
        import ray

        for process in self.drivers.values():
            if process.poll() is None:
                process.kill()
                process.wait()
        if ray.is_initialized():
            ray.shutdown()
        self.cluster.shutdown()


def _until(condition, timeout: float = 30.0) -> None:
    end = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > end:
            raise TimeoutError(f"not so after {timeout:g} s")
        time.sleep(0.1)


def serve(folder: Path, workers: int) -> None:
    """Starts the cluster, answers ``{"address"}``, then one answer per request line until the end
    of input (``op``: a method of :class:`_Cluster`, the other keys its arguments)."""
    answers = os.fdopen(os.dup(sys.stdout.fileno()), "w", buffering=1)
    os.dup2(sys.stderr.fileno(), sys.stdout.fileno())       # Ray's prints go to the log, not the answers
    os.environ["RAY_USAGE_STATS_ENABLED"] = "0"
    # Ray's files (its sockets: a short path) and the address file a local ray.init() reads
    # (ray_current_cluster) in a folder of this cluster's own, not the machine's /tmp/ray.
    os.environ["RAY_TMPDIR"] = tempfile.mkdtemp(prefix="ray_", dir="/tmp")
    try:
        cluster = _Cluster(folder, workers)
        try:
            answers.write(json.dumps({"ok": True, "address": cluster.cluster.address}) + "\n")
            for line in sys.stdin:
                request = json.loads(line)
                try:
                    answer = {"ok": True, **getattr(cluster, request.pop("op"))(**request)}
                except Exception:
                    answer = {"ok": False, "error": traceback.format_exc()}
                answers.write(json.dumps(answer) + "\n")
        finally:
            cluster.shutdown()
    finally:
        shutil.rmtree(os.environ["RAY_TMPDIR"], ignore_errors=True)


if __name__ == "__main__":
    if sys.argv[1] == "serve":
        serve(Path(sys.argv[2]), int(sys.argv[3]))
    elif sys.argv[1] == "cli":
        sys.exit(cli(sys.argv[2:]))
    elif sys.argv[1] == "ray-pool":
        ray_pool_map(Path(sys.argv[2]))
