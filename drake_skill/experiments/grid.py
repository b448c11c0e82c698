"""The experiment grid: skills x methods x rewards x N runs, each run one call of ``learn``.

The thesis's simulation study (section 7.1, docs/method.md sections 5-6)::

    for each skill:       record + fit once            OUT/SKILL/initial_skill/
                          held-out success before      OUT/SKILL/held_out_before.json
    for each run r, skill, method, reward:
        learn(initial_skill, LearnConfig(method, reward, seed = seed0 + r))
        held-out success after learning                OUT/SKILL/METHOD/REWARD/run_RRR/

Every run of a skill starts from the same fitted skill (the same action and
goal model); run ``r`` of every cell uses seed ``seed0 + r`` (the same object
poses for its rollouts in every cell: the methods are compared on the same
draws). Budgets: E episodes x C rollouts (thesis 5 x 6), a greedy execution
before learning and after every update; PoWER E x C episodes of one rollout
(thesis 30 x 1) with a greedy execution every C updates (``LearnConfig.
greedy_every``), so every curve has its points after 0, C, 2C, ... rollouts.

A run executes in a worker (:mod:`~drake_skill.experiments.pool`) with
``workers=1`` inside: ``learn`` on the worker's own runner, built once per
skill and kept. It writes into ``.run_RRR.partial/`` (``learn``'s
checkpoint after every episode), then measures the held-out success of the
learned mean, writes ``summary.json`` and renames the folder to ``run_RRR``:
a run folder exists only whole. A later invocation skips the runs that
exist, resumes a partial one from its checkpoint, and adds the runs of a
larger ``--runs``. ``OUT/grid.json`` holds the settings that decide the
numbers; a later invocation with other settings is refused.
"""

from __future__ import annotations

import dataclasses as dc
import json
import os
import shutil
import sys
import time
from pathlib import Path
from typing import Any

from drake_skill.fileio import atomic_write_json, load_json
from drake_skill.inputs import scenario
from drake_skill.learning.evaluation import HELD_OUT_SEED0
from drake_skill.learning.config import valid_approach_exploration
from drake_skill.learning.exploration import EXPLORATIONS
from drake_skill.learning.loop import REWARDS, LearnConfig
from drake_skill.learning.policy_search import METHODS

__all__ = ["DEFAULT_RUNS", "THESIS_STATION", "GridConfig", "GridOutcome", "GridTask", "before_path", "execute_task",
           "grid_station", "plan_tasks", "prepare_skills", "run_dir", "run_grid"]

#: Independent runs per cell (the thesis's 20).
DEFAULT_RUNS = 20

#: The chapter-7 station laid over every skill's scenario (``GridConfig.station`` "thesis"): the
#: thesis's robot has no force limit (docs/method.md 5.3), which the shipped scenarios turn on.
THESIS_STATION = "controller: {force_limit: {enabled: false}}"

_GRID_FORMAT = 1


def _choices(flag: str, given, allowed, what: str) -> tuple[str, ...]:
    """``given`` without repeats, each checked against ``allowed``; errors name ``flag``."""
    given = tuple(dict.fromkeys(given))
    if not given:
        raise ValueError(f"{flag}: give at least one {what} ({', '.join(allowed)})")
    for value in given:
        if value not in allowed:
            raise ValueError(f"{flag} {value}: unknown {what}; give some of {', '.join(allowed)}")
    return given


def _skill_sources(given) -> dict[str, str]:
    """{skill name: the shipped name or skill file given for it} of ``--skills``; the
    grid's folders and table rows go by the name in the skill file."""
    from drake_skill.skills import load_skill

    sources: dict[str, str] = {}
    for entry in given:
        try:
            name = load_skill(entry).name
        except (FileNotFoundError, ValueError) as e:
            raise ValueError(f"--skills {entry}: {e}") from None
        if name in sources:
            raise ValueError(f"--skills {entry}: skill '{name}' is already given as {sources[name]}; "
                             "give each skill once")
        sources[name] = str(entry)
    return sources


@dc.dataclass
class GridConfig:
    """The grid and the settings of every run in it.

    skills, methods, rewards: the cells (shipped skills' names or skill files,
      ``policy_search.METHODS``, ``loop.REWARDS``); after :meth:`validate`,
      ``skills`` holds the skills' names and ``sources`` what was given for each.
    runs: independent runs per cell, seeds ``seed0 .. seed0 + runs - 1``.
    episodes, rollouts: the budget E x C (PoWER: E x C episodes of 1 rollout).
    held_out: held-out object poses [count] for success before (once per
      skill) and after learning (every run); 0: off. Seeds from
      ``held_out_seed0``, as ``drake-skill learn`` and ``evaluate``.
    keep_skills: keep each run's learned ``skill/`` folder (7 MB each; the
      learned weights are in its ``checkpoint/search.npz`` anyway).
    fit: how each skill is fitted (``drake_skill.fitted_skill.FITS``): "thesis" (the
      default: the committed chapter-7 grid's fit, so a resumed grid never
      mixes fits) or "tolerance" (docs/method.md section 2.2). Stored in
      ``grid.json`` when not "thesis" (grids stored before it have none).
    select: which policy each run returns (``LearnConfig.select``): "last"
      (the default: the thesis's final mean, the chapter-7 grid) or
      "guarded" (``drake-skill learn``'s default, docs/method.md 5.1; the
      generalization study). Stored in ``grid.json`` when not "last".
    exploration: what each run's search varies (``LearnConfig.exploration``, docs/method.md 5.2):
      "basis" (the default, thesis Eq. 5.3) or "span". Stored in ``grid.json`` when not "basis".
    station: "thesis" (the default: the chapter-7 station, each skill's scenario with
      :data:`THESIS_STATION` laid under ``--scenario``: no force limit, as the committed grid
      ran) or "skill" (each skill's scenario as ``learn`` builds it; the generalization study).
      It reaches ``grid.json`` through the station each skill stores there.
    approach_exploration: ``LearnConfig.approach_exploration`` of every run (1: off, the
      thesis's). Stored in ``grid.json`` when not 1.
    """

    skills: tuple[str, ...] = ("open", "close")
    methods: tuple[str, ...] = METHODS
    rewards: tuple[str, ...] = REWARDS
    runs: int = DEFAULT_RUNS
    episodes: int = 5
    rollouts: int = 6
    held_out: int = 10
    held_out_seed0: int = HELD_OUT_SEED0
    seed0: int = 0
    keep_skills: bool = False
    fit: str = "thesis"
    select: str = "last"
    exploration: str = "basis"
    station: str = "thesis"
    approach_exploration: float = 1.0
    sources: dict[str, str] = dc.field(default_factory=dict)

    def validate(self) -> "GridConfig":
        """Raises a one-line ValueError naming the flag and the fix; returns self."""
        self.sources = _skill_sources(self.sources.get(s, s) for s in self.skills)
        self.skills = tuple(self.sources)
        self.methods = _choices("--methods", self.methods, METHODS, "method")
        self.rewards = _choices("--rewards", self.rewards, REWARDS, "reward")
        for flag, value, least in (("--runs", self.runs, 1), ("--episodes", self.episodes, 1),
                                   ("--rollouts", self.rollouts, 1), ("--held-out", self.held_out, 0)):
            if int(value) < least:
                raise ValueError(f"{flag} {value}: expected at least {least}; give {flag} {max(least, 1)} or more")
        if self.select not in ("last", "guarded"):
            raise ValueError(f"--select {self.select}: unknown rule; give last or guarded")
        if self.exploration not in EXPLORATIONS:
            raise ValueError(f"--exploration {self.exploration}: unknown; give {' or '.join(EXPLORATIONS)}")
        if not valid_approach_exploration(float(self.approach_exploration)):
            raise ValueError(f"--approach-exploration {self.approach_exploration}: expected a factor in (0, 1]; "
                             "give 1 (off) or less")
        if self.station not in ("thesis", "skill"):
            raise ValueError(f"station {self.station!r}: unknown; give thesis or skill")
        if self.fit not in ("thesis", "tolerance"):
            raise ValueError(f"--fit {self.fit}: unknown fit; give thesis or tolerance")
        if "cma-es" in self.methods and int(self.rollouts) < 2:
            raise ValueError(f"--rollouts {self.rollouts}: cma-es needs at least 2 rollouts per episode; "
                             "give --rollouts 2 or more, or leave cma-es out of --methods")
        return self

    def budget(self, method: str) -> tuple[int, int]:
        """(episodes, rollouts per episode) of ``method``: E x C, PoWER E*C x 1."""
        if method == "power":
            return int(self.episodes) * int(self.rollouts), 1
        return int(self.episodes), int(self.rollouts)

    def learn_config(self, method: str, reward: str, run: int) -> LearnConfig:
        """``learn``'s settings of run ``run`` of a cell (held-out off: the grid measures it on the policy
        the run returns: by default the final mean, as the thesis's chapter 7 does)."""
        episodes, rollouts = self.budget(method)
        every = int(self.rollouts) if method == "power" else 1
        return LearnConfig(method=method, reward=reward, episodes=episodes, rollouts=rollouts,
                           seed=int(self.seed0) + int(run), held_out=0, greedy_every=every,
                           select=self.select, exploration=self.exploration,
                           approach_exploration=float(self.approach_exploration)).validate()

    def settings(self) -> dict[str, Any]:
        """What decides the numbers of a run beyond its cell (kept in ``grid.json``)."""
        fit = {} if self.fit == "thesis" else {"fit": self.fit}
        select = {} if self.select == "last" else {"select": self.select}
        exploration = {} if self.exploration == "basis" else {"exploration": self.exploration}
        if float(self.approach_exploration) != 1.0:
            exploration["approach_exploration"] = float(self.approach_exploration)
        return {"episodes": int(self.episodes), "rollouts": int(self.rollouts), "held_out": int(self.held_out),
                "held_out_seed0": int(self.held_out_seed0), "seed0": int(self.seed0), **fit, **select,
                **exploration}


def run_dir(out, skill: str, method: str, reward: str, run: int) -> Path:
    """The folder of a finished run: ``OUT/SKILL/METHOD/REWARD/run_RRR``."""
    return Path(out) / skill / method / reward / f"run_{int(run):03d}"


def partial_dir(final: Path) -> Path:
    """Where a run is written until it ends: ``.run_RRR.partial`` beside its folder."""
    return final.with_name(f".{final.name}.partial")


def before_path(out, skill: str) -> Path:
    """The held-out success of a skill's fitted (initial) policy: ``OUT/SKILL/held_out_before.json``."""
    return Path(out) / skill / "held_out_before.json"


@dc.dataclass(frozen=True)
class GridTask:
    """One unit of work for a worker (plain data, pickled to it).

    kind: "run" (a learning run into folder ``path``) or "before" (the
    held-out success of the initial policy into file ``path``).
    spec: the runner to execute on (skill folder, station YAML, rollout settings).
    learn: ``LearnConfig`` fields of a run; held_out, held_out_seed0: poses.
    """

    kind: str
    skill: str
    spec: Any
    path: str
    method: str = ""
    reward: str = ""
    run: int = -1
    learn: dict = dc.field(default_factory=dict)
    held_out: int = 10
    held_out_seed0: int = HELD_OUT_SEED0
    keep_skill: bool = False

    @property
    def name(self) -> str:
        if self.kind == "before":
            return f"{self.skill} held-out before"
        return f"{self.skill}/{self.method}/{self.reward}/run_{self.run:03d}"

    def cost(self) -> int:
        """Executions (rollouts, greedy, held-out) the task runs: the progress bar's unit."""
        if self.kind == "before":
            return self.held_out
        episodes, rollouts = int(self.learn["episodes"]), int(self.learn["rollouts"])
        greedy = -(-episodes // int(self.learn.get("greedy_every", 1))) + 1
        select = 2 * int(self.learn.get("select_poses", 3)) if self.learn.get("select") == "guarded" else 0
        return episodes * rollouts + greedy + select + self.held_out


# ----------------------------------------------------------------------- in a worker
_RUNNERS: dict[str, Any] = {}


def _runner(spec):
    """The worker's runner for ``spec``, built on first use and kept (one per skill)."""
    key = json.dumps(dc.asdict(spec), sort_keys=True)
    if key not in _RUNNERS:
        import logging

        from drake_skill.common import IkWarningCounter

        if not _RUNNERS and spec.quiet_ik:
            logging.getLogger("drake").addFilter(IkWarningCounter(suppress=True))
        _RUNNERS[key] = spec.build()
    return _RUNNERS[key]


def _held_out(runner, weights, n: int, seed0: int) -> dict | None:
    """The ``evaluate_greedy`` report of ``weights`` on the held-out poses (None when n = 0)."""
    from drake_skill.learning.evaluation import evaluate_greedy
    from drake_skill.learning.workers import SerialPool

    if n <= 0:
        return None
    report, _ = evaluate_greedy(SerialPool(runner), weights, [int(seed0) + i for i in range(n)])
    return report


def _execute_before(task: GridTask) -> dict:
    from drake_skill.fitted_skill import Skill

    weights = Skill.load(task.spec.skill_dir).initial_weights
    report = _held_out(_runner(task.spec), weights, task.held_out, task.held_out_seed0)
    record = {"skill": task.skill, "success_rate": report["success_rate"], "report": report}
    atomic_write_json(task.path, record)
    return {"kind": "before", "skill": task.skill, "success_rate": report["success_rate"]}


def _execute_run(task: GridTask) -> dict:
    """``learn`` into the partial folder (resumed from its checkpoint), held-out after, rename."""
    from drake_skill.learning.loop import learn
    from drake_skill.learning.rollout import RolloutConfig

    final = Path(task.path)
    if (final / "summary.json").is_file():
        return load_json(final / "summary.json", f"delete the run folder {final}; the grid redoes the run")
    partial = partial_dir(final)
    resume = (partial / "checkpoint" / "state.json").is_file()
    partial.mkdir(parents=True, exist_ok=True)
    runner = _runner(task.spec)
    start = time.perf_counter()
    with open(partial / "learn.log", "a") as log:
        outcome = learn(task.spec.skill_dir, partial, LearnConfig(**task.learn), station_config=runner.config,
                        rollout_config=RolloutConfig(**task.spec.rollout), resume=resume, force=not resume,
                        replay=False, progress=False, log=log, runner=runner)
    held = _held_out(runner, outcome.weights, task.held_out, task.held_out_seed0)
    if not task.keep_skill:
        shutil.rmtree(partial / "skill", ignore_errors=True)
    summary = {**outcome.summary, "run": task.run, "resumed": resume,
               "held_out_after": None if held is None else held["success_rate"], "held_out_after_report": held,
               "held_out_poses": task.held_out, "wall_s": round(time.perf_counter() - start, 1),
               "artifacts": sorted(p.name + ("/" if p.is_dir() else "") for p in partial.iterdir())}
    atomic_write_json(partial / "summary.json", summary)
    os.rename(partial, final)
    return summary


def execute_task(task: GridTask) -> dict:
    """Runs one task in this process (a worker's entry point); returns a small summary."""
    return _execute_before(task) if task.kind == "before" else _execute_run(task)


# ----------------------------------------------------------------------- planning
def prepare_skills(out: Path, sources: dict[str, str], *, skill_dir: Path | None = None,
                   station_yaml: Path | None = None, quiet: bool = False, fit: str = "thesis",
                   thesis_station: bool = True) -> dict[str, Path]:
    """Each skill's fitted skill ``OUT/SKILL/initial_skill``: recorded and fitted once
    (:func:`drake_skill.workflow.prepare.prepare_skill`, as ``drake-skill learn`` does), or copied
    from ``skill_dir`` (one skill only). ``sources``: {name: shipped name or skill file}."""
    from drake_skill.fitted_skill import Skill
    from drake_skill.workflow.prepare import prepare_skill

    dirs = {}
    for skill, source in sources.items():
        initial = Path(out) / skill / "initial_skill"
        if skill_dir is not None:
            _copy_skill(Path(skill_dir), initial, skill)
        else:
            prepare_skill(prepare_config(source, station_yaml, quiet, fit, thesis_station), Path(out) / skill)
        if Skill.load(initial).name != skill:
            raise ValueError(f"{initial} holds a '{Skill.load(initial).name}' skill, not '{skill}'; "
                             "use another --out")
        dirs[skill] = initial
    return dirs


def prepare_config(source: str, station_yaml: Path | None = None, quiet: bool = False, fit: str = "thesis",
                   thesis_station: bool = True):
    """The :class:`~drake_skill.workflow.prepare.PrepareConfig` of ``drake-skill learn --skill SOURCE
    [--scenario FILE] [--quiet] --fit FIT``: the skill's scenario (with :data:`THESIS_STATION` when
    ``thesis_station``) under ``station_yaml``."""
    from drake_skill.workflow.prepare import PrepareConfig

    return PrepareConfig(skill=str(source), fit=fit, quiet=quiet,
                         station_for=lambda spec: grid_station(spec, station_yaml, thesis_station))


def grid_station(skill, station_yaml: Path | None = None, thesis_station: bool = True):
    """The Scenario a grid runs ``skill`` (a shipped name, skill file or spec) on: its scenario, with
    :data:`THESIS_STATION` laid over it when ``thesis_station``, then ``station_yaml`` (``--scenario``)."""
    base = scenario(skill, texts=[THESIS_STATION]) if thesis_station else skill
    return scenario(base, station_yaml)


def _copy_skill(source: Path, initial: Path, skill: str) -> None:
    """``--skill-dir`` into ``initial`` (once); a different skill already there is an error."""
    from drake_skill.fitted_skill import Skill

    if Skill.load(source).name != skill:
        raise ValueError(f"--skill-dir {source} holds a '{Skill.load(source).name}' skill, not '{skill}'; "
                         f"give --skills {Skill.load(source).name}")
    if not (initial / "skill.json").is_file():
        initial.parent.mkdir(parents=True, exist_ok=True)
        tmp = initial.with_name(".initial_skill.copy")
        shutil.rmtree(tmp, ignore_errors=True)
        shutil.copytree(source, tmp)
        os.rename(tmp, initial)
    elif (initial / "skill.json").read_bytes() != (source / "skill.json").read_bytes():
        raise ValueError(f"--skill-dir {source} is not the skill {initial} the stored runs started from; "
                         "leave out --skill-dir or choose another --out")


def check_settings(out: Path, config: GridConfig, specs: dict) -> None:
    """Stores the settings in ``OUT/grid.json``, or refuses ones that differ from the stored runs'."""
    path = Path(out) / "grid.json"
    now = {"format": _GRID_FORMAT, **config.settings(),
           "skills": {s: {"station": spec.station_yaml, "rollout": spec.rollout} for s, spec in specs.items()}}
    if path.is_file():
        saved = load_json(path, "restore it from a copy, or give another --out (the stored runs' settings "
                                "are unknown without it)")
        for key, value in config.settings().items():
            if saved.get(key) != value:
                flag = "--" + key.replace("_", "-")
                raise ValueError(f"{flag} {value}: the runs stored in {out} used {saved.get(key)}; give "
                                 f"{flag} {saved.get(key)} to continue them, or choose another --out")
        for skill, stored in saved.get("skills", {}).items():
            if skill in now["skills"] and not _same_settings(now["skills"][skill], stored):
                raise ValueError(f"--scenario / --ground-truth-pose: {skill}'s station or rollout settings differ "
                                 f"from the runs stored in {out}; give the same ones, or choose another --out")
        now["skills"] = {**saved.get("skills", {}), **now["skills"]}
    atomic_write_json(path, now)


def _same_settings(now: dict, stored: dict) -> bool:
    """A skill's station and rollout settings as stored, the station compared by what it builds
    (:func:`~drake_skill.station.scenario.same_station`)."""
    from drake_skill.station.scenario import same_station

    return now.get("rollout") == stored.get("rollout") and isinstance(stored.get("station"), str) \
        and same_station(now["station"], stored["station"])


def plan_tasks(out: Path, config: GridConfig, specs: dict) -> list[GridTask]:
    """The tasks not yet stored: each skill's held-out before, then the runs by run
    index (run 0 of every cell first, so that a grid cut short has the cells even)."""
    out = Path(out)
    common = {"held_out": int(config.held_out), "held_out_seed0": int(config.held_out_seed0)}
    tasks = [GridTask("before", s, specs[s], str(before_path(out, s)), **common)
             for s in config.skills if config.held_out > 0 and not before_path(out, s).is_file()]
    for run in range(int(config.runs)):
        for skill in config.skills:
            for method in config.methods:
                for reward in config.rewards:
                    final = run_dir(out, skill, method, reward, run)
                    if (final / "summary.json").is_file():
                        continue
                    learn = dc.asdict(config.learn_config(method, reward, run))
                    tasks.append(GridTask("run", skill, specs[skill], str(final), method, reward, run, learn,
                                          keep_skill=config.keep_skills, **common))
    return tasks


# ----------------------------------------------------------------------- the grid
@dc.dataclass
class GridOutcome:
    """What :func:`run_grid` did: runs ``ran`` in this call, ``stored`` in all,
    ``failed`` (task name, one-line reason), the table's path and the wall time [s]."""

    ran: int
    stored: int
    failed: list
    table: Path
    wall_s: float
    workers: int


def run_grid(out, config: GridConfig, *, skill_dir=None, station_yaml=None, rollout_config=None,
             workers: int | None = None, use_ray: bool = False, ray_address: str | None = None,
             progress: bool = True, quiet: bool = False) -> GridOutcome:
    """Runs the runs of the grid not stored in ``out`` yet, then writes ``OUT/table.csv``
    (also when interrupted: the runs stored so far).

    rollout_config: ``RolloutConfig`` (default: perceived object frame);
    station_yaml: a scenario YAML over each skill's scenario (``--scenario``);
    workers: processes / Ray CPUs (default one per CPU this process may use);
    use_ray / ray_address: Ray (local / a cluster) instead of processes.
    """
    from drake_skill.experiments.pool import ray_or_error
    from drake_skill.experiments.table import stored_runs, write_table
    from drake_skill.learning.workers import default_workers

    config = config.validate()
    if use_ray or ray_address:
        ray_or_error("--ray-address" if ray_address else "--ray")
    workers = default_workers() if workers is None else int(workers)
    if workers < 1:
        raise ValueError(f"--workers {workers}: expected at least 1; leave it out for one per CPU")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    specs = _runner_specs(out, config, skill_dir, station_yaml, rollout_config, quiet)
    check_settings(out, config, specs)
    tasks = plan_tasks(out, config, specs)
    failed: list[tuple[str, str]] = []
    done = {"runs": 0}
    start = time.perf_counter()
    try:
        if tasks:
            _execute(tasks, workers, use_ray, ray_address, _progress(tasks, failed, done, progress))
    finally:                               # interrupted too: the table of the runs stored so far
        table = write_table(out)
    return GridOutcome(done["runs"], len(stored_runs(out)), failed, table, round(time.perf_counter() - start, 1),
                       workers)


def _execute(tasks, workers: int, use_ray: bool, ray_address, progress) -> None:
    """Runs ``tasks`` on Ray or worker processes; ``progress``: (on_done, close)."""
    from drake_skill.experiments.pool import run_on_processes

    on_done, close = progress
    try:
        if use_ray or ray_address:
            _execute_on_ray(tasks, workers, ray_address, on_done)
        else:
            run_on_processes(tasks, execute_task, workers, on_done)
    finally:
        close()


def _execute_on_ray(tasks, workers: int, ray_address, on_done) -> None:
    """The tasks on Ray with nothing shared but Ray: the skills go through its object store, the
    results come back in the tasks' returns, and this process stores them
    (:mod:`~drake_skill.experiments.remote`)."""
    from drake_skill.experiments.pool import run_on_ray
    from drake_skill.experiments.remote import execute_remote, remote_tasks, store_result

    remote, skills = remote_tasks(tasks, execute_task)
    origin = {id(r): t for r, t in zip(remote, tasks)}

    def stored(r, payload, error):
        task = origin[id(r)]
        if payload is None:
            return on_done(task, None, error)
        try:
            summary = store_result(task, payload, partial_dir(Path(task.path)) if task.kind == "run" else None)
        except OSError as e:
            return on_done(task, None, f"storing the result under --out failed: {e}")
        on_done(task, summary, None)

    run_on_ray(remote, execute_remote, workers, stored, address=ray_address, shared=(skills,))


def _runner_specs(out: Path, config: GridConfig, skill_dir, station_yaml, rollout_config, quiet: bool) -> dict:
    """Each skill's :class:`~drake_skill.learning.workers.RunnerSpec` (its fitted skill prepared)."""
    from drake_skill.learning.rollout import RolloutConfig
    from drake_skill.learning.workers import RunnerSpec

    if skill_dir is not None and len(config.skills) != 1:
        raise ValueError(f"--skill-dir {skill_dir}: one fitted skill serves one skill; give one skill in --skills")
    thesis = config.station == "thesis"
    dirs = prepare_skills(out, config.sources, skill_dir=skill_dir, station_yaml=station_yaml, quiet=quiet,
                          fit=config.fit, thesis_station=thesis)
    rollout_config = (rollout_config or RolloutConfig()).validate()
    return {s: RunnerSpec.create(dirs[s], grid_station(config.sources[s], station_yaml, thesis), rollout_config)
            for s in config.skills}


def _progress(tasks, failed: list, done: dict, enabled: bool):
    """``on_done`` for the pool and the bar's close: a tqdm bar counting executions
    (rollouts, greedy, held-out: its ETA), ``done["runs"]`` and ``failed`` filled in."""
    from tqdm import tqdm

    runs = sum(t.kind == "run" for t in tasks)
    bar = tqdm(total=sum(t.cost() for t in tasks), desc="experiment", unit="exec", disable=not enabled,
               file=sys.stderr, dynamic_ncols=True)
    bar.set_postfix_str(f"runs 0/{runs}")

    def on_done(task, result, error):
        if error is not None:
            failed.append((task.name, error))
            bar.write(f"{task.name}: failed: {error}", file=sys.stderr)
        elif task.kind == "run":
            done["runs"] += 1
        bar.update(task.cost())
        bar.set_postfix_str(f"runs {done['runs']}/{runs}" + (f", {len(failed)} failed" if failed else ""))

    return on_done, bar.close
