"""``drake-skill fit``: demonstrations in, a learned skill (action + goal model) out.

    drake-skill fit --demos DIR --out SKILL_DIR [--config skill.yaml] [--seed N] [--force]

Loads every ``demo_*.npz`` of DIR (see ``drake-skill demos record``), fits the
skill (``drake_skill.fitted_skill.fit_skill``: per-demonstration DMPs and Sigma_0,
PCAE codes -> PCA goal data, goal HMM by AIC, MRP values, POMRP reward),
prints the goal model's summary, and writes SKILL_DIR:

    skill.yaml, skill.json, arrays.npz, pcae.safetensors   the skill (Skill.load reads it)
    goal_model.png      the goal HMM as a graph: states, transitions, values,
                        initial (blue) and terminal (green) states, a cloud per state
    demo_returns.png    the dense return of each demonstration against time
    fit_report.html     per demonstration, on one page opened by any browser: what the
                        segment kept of the object over time (a schema-2 file's stored
                        counts; for schema 1, the scene posed again on the simulated
                        station), three frames with the segment drawn over them, the
                        goal features and the goal model's state over time, the
                        imitation's distance from the demonstration [mm] and the peak
                        contact force (drake_skill.workflow.fit_report)

A stretch of half a second or more in which the segment keeps less than half
of the pixels of the object's hue (schema 2) or of its visible pixels (schema
1, re-posed) is a warning line naming the demonstration, the time and the fix
(the colour range, or the clustering).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from drake_skill.cli import errors
from drake_skill.workflow.fit_report import segment_tracks, write_fit_report
from drake_skill.workflow.prepare import fit_and_refine_report, print_fit_report

NAME = "fit"
HELP = "fit a skill (DMPs + goal model) from demonstrations"


def _state_clouds(skill, demos):
    """For each HMM state, the demonstration cloud whose frame is most likely in it."""
    best = {}
    for demo in demos:
        G = skill.goal_data(demo.object_points, demo.perception_valid, X_WO=demo.X_WO_start)
        _, post, _ = skill.pomrp.posteriors(G)   # smoothed (T, k)
        for s in range(post.shape[1]):
            t = int(np.argmax(post[:, s]))
            if post[t, s] > best.get(s, (-1.0, None))[0]:
                best[s] = (post[t, s], np.asarray(demo.object_points[t]))
    return [best.get(s, (0, None))[1] for s in range(skill.pomrp.n_states)]


def add_fit_argument(parser, help_prefix: str = "") -> None:
    """``--fit tolerance|thesis`` (docs/method.md section 2.2), as ``fit`` and ``learn`` take it."""
    parser.add_argument("--fit", choices=("tolerance", "thesis"), default="tolerance",
                        help=help_prefix + "'tolerance' (default): the 100 Hz action data, the fewest DMP bases "
                             "that reproduce each demonstration within 2 mm near contact and 3 mm RMS (or the skill "
                             "file's dmp_bases), refined on the simulated station; 'thesis': the 10 Hz data, thesis "
                             "Table 6.1's bases, no refinement, as the committed chapter-7 grid "
                             "(docs/method.md section 2.2)")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--demos", type=Path, required=True, help="folder of demo_*.npz files")
    parser.add_argument("--out", type=Path, required=True, help="skill folder to write")
    parser.add_argument("--config", type=Path, help="SkillConfig YAML (defaults: thesis values)")
    parser.add_argument("--skill", metavar="SKILL",
                        help="the skill: a shipped skill's name or a skill file (default: the shipped "
                             "skill the demonstrations name)")
    parser.add_argument("--seed", type=int, help="picks the demonstration policy search starts from")
    parser.add_argument("--force", action="store_true", help="replace an existing skill in --out")
    add_fit_argument(parser)
    parser.add_argument("--no-refine", action="store_true",
                        help="skip the refinement that runs each demonstration's DMP on the scenario's simulated "
                             "station and refits it so that the executed path, not the commanded one, follows the "
                             "demonstration (docs/method.md section 2.3; about the demonstrations' duration each)")


def run(args: argparse.Namespace) -> int:
    # Everything a user can get wrong is checked before the fit starts.
    errors.input_folder(args.demos, "--demos", "demo_*.npz files (drake-skill demos record)")
    errors.output_folder(args.out, "--out", occupied=(args.out / "skill.json").exists(), force=args.force,
                         what="a skill")
    if args.out.is_dir() and any(args.out.iterdir()) and not (args.out / "skill.json").exists():
        raise FileExistsError(f"--out {args.out}: exists, is not empty and holds no skill; choose an empty "
                              "or new folder")

    from drake_skill.demos.format import load_demonstrations
    from drake_skill.reward.plots import plot_goal_model, plot_return
    from drake_skill.learning.evaluation import save_fitted_skill
    from drake_skill.fitted_skill import SkillConfig, _pcae_path, default_skill_config, fit_skill

    if args.config:  # parse errors and unknown keys before reading the demonstrations
        errors.load_yaml(SkillConfig, args.config, "--config").dmp.validate()
    demos = load_demonstrations(args.demos)
    spec = errors.skill(args.skill) if args.skill else errors.skill(
        demos[0].skill, f"--demos {args.demos} (skill '{demos[0].skill}'; give its skill file as --skill)")
    config = default_skill_config(spec, fit=args.fit)
    if args.config:
        config = errors.load_yaml(SkillConfig, args.config, "--config", defaults=config)
        if config.skill != spec.name:
            raise ValueError(f"--config {args.config}: skill '{config.skill}' disagrees with the skill "
                             f"'{spec.name}'; fit it with --skill {config.skill}")
        config.dmp.validate()
    if args.seed is not None:
        config.seed = args.seed
    errors.input_file(_pcae_path(config), "pcae_weights", "the PCAE weights (models/pcae.safetensors)")
    print(f"fitting '{config.skill}' from {len(demos)} demonstrations in {args.demos} ...")
    if args.no_refine:
        config.dmp_refine = 0
    skill = fit_skill(demos, config)
    lines, warnings = fit_and_refine_report(skill, demos)
    skill = save_fitted_skill(skill, args.out, overwrite=args.force)
    print(skill.summary())
    print("checking what the camera kept of each demonstration ...")
    tracks, seen = segment_tracks(skill, demos)
    print_fit_report(lines, warnings + seen)
    write_fit_report(args.out / "fit_report.html", skill, demos, tracks, warnings + seen)
    plot_goal_model(skill.pomrp, args.out / "goal_model.png", clouds=_state_clouds(skill, demos),
                    title=f"goal model of '{config.skill}'")
    rewards = {f"demo {i}": skill.pomrp.rewards(skill.goal_data(d.object_points, d.perception_valid, X_WO=d.X_WO_start))
               for i, d in enumerate(demos)}
    plot_return(rewards, args.out / "demo_returns.png")
    print(f"wrote {args.out}/ (skill.yaml, skill.json, arrays.npz, pcae.safetensors, "
          "goal_model.png, demo_returns.png, fit_report.html)")
    return 0


def main(argv=None) -> int:
    """``drake-skill fit ARGV...`` (for scripts and tests)."""
    from drake_skill.cli.main import command_main
    return command_main(NAME, argv)
