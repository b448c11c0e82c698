"""``drake-skill learn``: improve a skill by policy search on its learned reward (the main job).

    drake-skill learn --skill SKILL | --skill-dir DIR | --demos DIR [--method pi2-es-cov] [--method pi2-es-cov]
                      [--reward dense] [--episodes 5] [--rollouts 6] [--seed 0] [--workers N]
                      [--held-out 10] [--out results/learn/SKILL] [--resume] [--meshcat]

The skill comes from ``--skill-dir`` (a fitted skill, ``drake-skill fit``), or
is fitted from ``--demos`` (``drake-skill demos record``), or, with neither,
the scripted demonstrator records ``--skill``'s demonstrations (its skill
file's keyframes and count; the thesis's 3 Open, 2 Close, 2 Draw) into ``OUT/demos/`` and the skill is fitted into
``OUT/initial_skill/`` (reused when already there). Then (docs/method.md
section 5) the held-out greedy success over ``--held-out`` object poses, one
greedy execution, and ``--episodes`` updates of ``--rollouts`` rollouts each,
a greedy execution after every update, and the held-out success again.

Writes into ``--out``:

    config.json          the settings (``--resume`` checks them) and the software versions and git commit
    results.jsonl        one JSON object per line: held_out, greedy, rollout, episode records
    progress.csv         one row per greedy-evaluated episode, appended as the run goes (plot it live)
    tensorboard/         the same rows as TensorBoard scalars (with pip install 'drake-skill[tensorboard]')
    summary.json         greedy success per episode, held-out success before/after, failures
    learning_curve.png   greedy success and returns per episode
    skill/               the learned skill (drake-skill evaluate --skill-dir OUT/skill)
    replay_first.html    Meshcat replay of the greedy execution before learning
    replay_last.html     ... and of the last one (open in a browser, press play)
    checkpoint/          run state after every episode (--resume continues from it; the appended
                         logs are cut back to it, so no row appears twice)

A table row per episode: greedy success (ground truth) and return, mean and
best rollout return, exploration size (RMS standard deviation of the weight
noise), failed rollouts by reason. ``--meshcat`` opens Meshcat (URL printed)
and shows the greedy executions live.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from drake_skill.cli import errors, options

NAME = "learn"
HELP = "improve a skill by policy search on its learned reward (the main job)"

_METHODS = ("power", "pi2", "pi2-cov", "pi2-es", "pi2-es-cov", "cma-es")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from drake_skill.learning.loop import exploration_scales_text
    from drake_skill.learning.workers import default_workers

    parser.description = __doc__
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    source = parser.add_argument_group("skill")
    source.add_argument("--config", type=Path, metavar="FILE",
                        help="the run's settings in one YAML (skill, out, workers, learn: LearnConfig, station: "
                             "overrides of the skill's scenario; drake_skill/cli/learn_config.py); flags override it")
    source.add_argument("--print-config", action="store_true",
                        help="print the effective settings (file, flags and defaults) as YAML and run nothing")
    source.add_argument("--skill", default=None, metavar="SKILL",
                        help="the skill to learn: a shipped skill's name (drake-skill skills) or a skill "
                             "file; needed unless --skill-dir or --demos of a shipped skill says it")
    source.add_argument("--skill-dir", type=Path, help="start from this fitted skill")
    source.add_argument("--demos", type=Path, help="fit the skill from these demonstrations (demo_*.npz)")
    from drake_skill.cli.fit import add_fit_argument
    add_fit_argument(source, "how a skill recorded or fitted here is fitted: ")
    search = parser.add_argument_group("policy search")
    search.add_argument("--method", choices=_METHODS, default=None, help="default: pi2-es-cov")
    search.add_argument("--reward", choices=("dense", "sparse"), default=None,
                        help="dense: POMRP return (per-step rewards for pi2, pi2-cov); sparse: the "
                             "goal model's verdict (default dense)")
    search.add_argument("--weighting", choices=("thesis", "range"), default=None,
                        help="rollout weighting of the PI^2 family: thesis (Eq. 5.1, exp(R/C)) or range "
                             "(exp(h (R - min)/(max - min))); default: the method's. With --reward sparse "
                             "use range: Eq. 5.1 weighs a success (R = 1) only e^(1/C) times a failure "
                             "(1.18 at C = 6 rollouts)")
    search.add_argument("--episodes", type=int, default=None, help="updates (default 5)")
    search.add_argument("--rollouts", type=int, default=None, help="rollouts per update (default 6)")
    search.add_argument("--exploration-scale", type=float, default=None, metavar="S",
                        help="sigma_0 of thesis Eq. 5.3: the first episode explores with S x Sigma_0, the "
                             "demonstrations' weight covariance (default: the skill's, "
                             f"{exploration_scales_text()}; the thesis: 1)")
    search.add_argument("--seed", type=int, default=None, help="policy search and object-pose seed (default 0)")
    search.add_argument("--held-out", type=int, default=None,
                        help="held-out object poses for greedy success before and after (0: off; default 10)")
    search.add_argument("--select", choices=("guarded", "last"), default=None,
                        help="which policy the run returns: guarded (default) runs the start, the best-scoring "
                             "greedy mean and the last on --select-poses shared poses and keeps the best by the "
                             "learned verdict and return (never the ground truth; docs/method.md 5.1); last: "
                             "the final mean, as the thesis does")
    search.add_argument("--exploration", choices=("basis", "span"), default=None,
                        help="what the search varies: basis (thesis Eq. 5.3, default: every basis's weights from "
                             "Sigma_0) or span (blends and extrapolations of the demonstrations' DMPs; "
                             "docs/method.md 5.2)")
    search.add_argument("--approach-exploration", type=float, default=None, metavar="F",
                        help="a factor in (0, 1] on Sigma_0 of the bases that move the hand before the "
                             "demonstrations first touch the object: samples keep the demonstrated approach and "
                             "explore the contact and after (default 1: off, as the thesis; docs/method.md 5.4)")
    search.add_argument("--select-poses", type=int, default=None, metavar="N",
                        help="object poses each guarded candidate runs on (default 3)")
    run = parser.add_argument_group("run")
    run.add_argument("--workers", type=int, default=None,
                        help="rollout worker processes (default: one per CPU this process may use, "
                             f"{default_workers()} here)")
    run.add_argument("--ray-address", default=None, type=options.ray_address,
                     help="run rollouts on Ray actors of this cluster ('auto', 'ray://host:port'; "
                          "needs pip install ray)")
    run.add_argument("--ray", action="store_true", help="run rollouts on Ray actors of a local ray.init()")
    run.add_argument("--out", type=Path, default=None, help="output folder (default results/learn/SKILL)")
    run.add_argument("--resume", action="store_true", help="continue the interrupted run in --out")
    run.add_argument("--force", action="store_true", help="start over in an --out that holds a run")
    run.add_argument("--meshcat", action="store_true", help="watch the greedy executions live in Meshcat")
    run.add_argument("--no-replay", action="store_true", help="do not write the Meshcat HTML replays")
    options.add_ground_truth_pose(run)
    options.add_scenario(run, "--station-config", what="the skill's scenario (and --config's station)")
    run.add_argument("--quiet", action="store_true", help="no progress bars")


def _station_config(args, skill):
    """The skill's scenario, under the --config file's ``station`` and then --scenario."""
    from drake_skill.typed_yaml import load_typed
    from drake_skill.station.scenario import validate_scenario
    from drake_skill.skills import scenario_for_skill

    station = scenario_for_skill(skill)
    if args.config is not None:
        from drake_skill.cli.learn_config import LearnFile
        station = load_typed(LearnFile, what="--config", path=args.config,
                             defaults=LearnFile(station=station)).station
        try:
            validate_scenario(station)
        except ValueError as e:
            raise ValueError(f"--config {args.config}: station: {e}") from None
    from drake_skill.inputs import scenario

    return scenario(station, args.station_config, args.scenario_text)


_FILE_FLAGS = ("skill", "skill_dir", "demos", "out")
_LEARN_FLAGS = ("method", "reward", "weighting", "episodes", "rollouts", "seed", "held_out", "exploration_scale",
                "select", "select_poses", "exploration", "approach_exploration")


def _apply_config_file(args) -> None:
    """Fills the flags not given from the --config file, then from LearnConfig's defaults."""
    from drake_skill.learning.loop import LearnConfig

    learn = LearnConfig()
    if args.config is not None:
        from drake_skill.cli.learn_config import LearnFile
        from drake_skill.typed_yaml import load_typed

        errors.input_file(args.config, "--config", "a YAML file of drake-skill learn settings")
        loaded = load_typed(LearnFile, what="--config", path=args.config)
        for name in _FILE_FLAGS:
            if getattr(args, name) is None and getattr(loaded, name):
                setattr(args, name, getattr(loaded, name) if name == "skill" else Path(getattr(loaded, name)))
        if args.workers is None and loaded.workers:
            args.workers = loaded.workers
        learn = loaded.learn
    for name in _LEARN_FLAGS:
        if getattr(args, name) is None:
            setattr(args, name, getattr(learn, name))


def _print_config(args) -> None:
    """The effective settings as the --config file would hold them."""
    from pydrake.common.yaml import yaml_dump_typed

    from drake_skill.cli.learn_config import LearnFile
    from drake_skill.learning.loop import LearnConfig
    from drake_skill.fitted_skill import Skill

    if args.skill is not None:
        spec = errors.skill(args.skill)
    elif args.skill_dir is not None:
        spec = Skill.load(args.skill_dir).spec
    elif args.demos is not None:
        from drake_skill.demos.format import load_demonstrations
        demos = load_demonstrations(args.demos)
        spec = errors.skill(demos[0].skill if demos else "", f"--demos {args.demos}")
    else:
        raise ValueError("--print-config: no skill; give --skill, --skill-dir or --demos (or put one in --config)")
    learn = LearnConfig(**{name: getattr(args, name) or ("" if name == "weighting" else None)
                           if name in ("weighting", "exploration_scale") else getattr(args, name)
                           for name in _LEARN_FLAGS})
    effective = LearnFile(skill=str(args.skill or ""), skill_dir=str(args.skill_dir or ""),
                          demos=str(args.demos or ""), out=str(args.out or ""), workers=int(args.workers or 0),
                          learn=learn.validate(), station=_station_config(args, spec))
    print(yaml_dump_typed(effective), end="")


def prepare_skill(args, out: Path) -> Path:
    """The fitted skill's directory (:func:`drake_skill.workflow.prepare.prepare_skill` on the flags)."""
    from drake_skill.workflow.prepare import PrepareConfig, prepare_skill as prepare

    return prepare(PrepareConfig(skill=args.skill, skill_dir=args.skill_dir, demos=args.demos,
                                 station_for=lambda spec: _station_config(args, spec),
                                 fit=getattr(args, "fit", "tolerance"), quiet=bool(args.quiet)), out)


def run(args: argparse.Namespace) -> int:
    from drake_skill.learning.loop import LearnConfig, learn
    from drake_skill.fitted_skill import Skill

    _apply_config_file(args)
    if args.print_config:
        _print_config(args)
        return 0
    if args.workers is None:
        from drake_skill.learning.workers import default_workers

        args.workers = default_workers()
    for name in ("episodes", "rollouts", "workers", "select_poses"):
        if getattr(args, name) < 1:
            raise ValueError(f"--{name.replace('_', '-')} must be at least 1, got {getattr(args, name)}")
    if args.held_out < 0:
        raise ValueError(f"--held-out must be 0 (off) or a number of poses, got {args.held_out}")
    if args.resume and args.force:
        raise ValueError("--resume continues a run and --force starts over: give one of them")
    guessed = (errors.skill(args.skill).name if args.skill else
               Skill.load(args.skill_dir).name if args.skill_dir else None)
    if guessed is None and args.demos is not None:
        from drake_skill.demos.format import load_demonstrations
        demos = load_demonstrations(args.demos)
        guessed = demos[0].skill if demos else None
    if guessed is None:
        raise ValueError("--skill: missing; name the skill to learn (a shipped skill: drake-skill skills, "
                         "or a skill file), or give --skill-dir or --demos")
    out = args.out if args.out is not None else Path("results") / "learn" / guessed
    if out.exists() and not out.is_dir():
        raise NotADirectoryError(f"--out {out} is a file; give a folder")
    if (out / "checkpoint" / "state.json").exists() and not (args.resume or args.force):
        raise FileExistsError(f"{out} holds a learning run; pass --resume to continue it, --force to "
                              "start over, or choose another --out")
    out.mkdir(parents=True, exist_ok=True)
    skill_dir = prepare_skill(args, out)
    skill = Skill.load(skill_dir)
    config = LearnConfig(method=args.method, reward=args.reward, weighting=args.weighting or "",
                         episodes=args.episodes, rollouts=args.rollouts, seed=args.seed,
                         held_out=args.held_out, exploration_scale=args.exploration_scale,
                         select=args.select, select_poses=args.select_poses, exploration=args.exploration,
                         approach_exploration=args.approach_exploration)
    rollout = options.rollout_config(args)
    meshcat = None
    if args.meshcat:
        from pydrake.geometry import Meshcat
        meshcat = Meshcat()
        print(f"Meshcat: {meshcat.web_url()}")
    outcome = learn(skill_dir, out, config, station_config=_station_config(args, skill.spec),
                    rollout_config=rollout, workers=args.workers, ray_address=args.ray_address,
                    use_ray=args.ray, resume=args.resume, force=args.force, meshcat=meshcat,
                    replay=not args.no_replay, progress=not args.quiet)
    s = outcome.summary
    before, after = s.get("held_out_before"), s.get("held_out_after")
    if before is not None:
        print(f"held-out greedy success: {before * 100:.0f} % before, {after * 100:.0f} % after learning "
              f"({config.held_out} poses)")
    if s.get("select") == "guarded":
        print(f"returned the policy after update {s['selected_episode']} of {s['episodes']} (--select guarded: "
              "the best of the start, the best greedy mean and the last, by the learned verdict and return)")
    print(f"wrote {out}/ ({', '.join(s['artifacts'])})")
    return 0


def main(argv=None) -> int:
    """``drake-skill learn ARGV...`` (scripts and tests): errors as one line, exit status 2."""
    from drake_skill.cli.main import command_main

    return command_main(NAME, argv)
