"""The station demo: scripted Open, Close and Draw, judged from ground truth.

``drake-skill station-demo [--meshcat] [--scenario FILE]`` runs each skill's scripted motion on
a randomised object pose, then once more with the arm parked (which must
fail), prints a table and writes to ``--out`` (default
``results/station_demo/``):

* ``summary.json``: per skill, the final object state, threshold and verdicts;
* ``object_state.png``: lid angle / drawer travel against time for each run;
* ``camera_<skill>.png``: what the Kinect-like camera sees at the end.

``--scenario FILE`` overrides each skill's shipped station scenario with the
keys of a YAML file (validated; errors name the field).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from drake_skill.cli import errors, options
from drake_skill.fileio import atomic_write_json, write_figure_png

NAME = "station-demo"
HELP = "scripted Open/Close/Draw in the simulated station"

def run_demo(skills, seed: int, out: Path, meshcat=None, realtime: float = 0.0, scenario: Path | None = None,
             scenario_text=()) -> dict:
    from drake_skill.fileio import new_figure

    from drake_skill.demos.scripted import scripted_plan
    from drake_skill.station.sim.simulation import StationSimulation
    from drake_skill.station.success import rule_text
    skills = [errors.skill(skill, "--skills") for skill in skills]
    configs = {spec.name: errors.scenario(spec, scenario, scenario_text) for spec in skills}  # all checked first
    specs, skills = {spec.name: spec for spec in skills}, [spec.name for spec in skills]
    summary, logs = {}, {}
    for skill in skills:
        config = configs[skill]
        sim = StationSimulation(config, meshcat=meshcat)
        sim.simulator.set_target_realtime_rate(realtime)
        start = time.perf_counter()
        X_WO = sim.reset(seed)
        plan = scripted_plan(specs[skill], X_WO, sim.home_pose())
        log = sim.run(plan, plan.duration + 0.5, record_hz=20)
        success = sim.judge()
        image = sim.station.GetOutputPort("color_image").Eval(sim.station_context()).data[:, :, :3].copy()
        sim.reset(seed)
        parked = sim.run(None, 3.0, record_hz=20)
        parked_success = sim.judge()
        summary[skill] = {
            "seed": seed,
            "object_xy_yaw": [float(X_WO.translation()[0]), float(X_WO.translation()[1]),
                              float(np.arctan2(X_WO.rotation().matrix()[1, 0], X_WO.rotation().matrix()[0, 0]))],
            "final_object_state": log.final_object_state,
            "threshold": rule_text(config.success),
            "scripted_success": bool(success),
            "parked_success": bool(parked_success),
            "wall_s": round(time.perf_counter() - start, 2),
        }
        logs[skill] = (log, parked)
        fig = new_figure((6.4, 4.8))
        ax = fig.subplots()
        ax.imshow(image)
        ax.axis("off")
        ax.set_title(f"{skill}: camera view at the end")
        write_figure_png(fig, out / f"camera_{skill}.png", dpi=110, bbox_inches="tight")

    fig = new_figure((4.2 * len(skills), 3.4))
    axes = fig.subplots(1, len(skills), squeeze=False)
    for ax, skill in zip(axes[0], skills):
        log, parked = logs[skill]
        ax.plot(log.times, log.object_state, label="scripted")
        ax.plot(parked.times, parked.object_state, "--", label="parked")
        ax.set_title(f"{skill} ({'success' if summary[skill]['scripted_success'] else 'failure'})")
        ax.set_xlabel("time [s]")
        ax.set_ylabel(f"{configs[skill].success.joint} [rad or m]")
        ax.grid(alpha=0.3)
        ax.legend()
    fig.tight_layout()
    write_figure_png(fig, out / "object_state.png", dpi=110, bbox_inches="tight")
    atomic_write_json(out / "summary.json", summary)
    return summary


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--skills", nargs="+", default=None, metavar="SKILL",
                        help="skills to run: shipped skills' names or skill files (default: every shipped "
                             "skill with keyframes)")
    parser.add_argument("--seed", type=int, default=0, help="object pose seed (default 0)")
    parser.add_argument("--out", type=Path, default=Path("results/station_demo"),
                        help="output folder (default results/station_demo)")
    options.add_scenario(parser, what="each skill's shipped scenario", dest="scenario")
    parser.add_argument("--meshcat", action="store_true",
                        help="show the simulation in Meshcat (prints the URL; runs in real time)")


def run(args: argparse.Namespace) -> int:
    errors.output_folder(args.out, "--out", what="the demo's results")
    if args.skills is None:
        from drake_skill.skills import shipped_skills
        args.skills = [spec.name for spec in shipped_skills() if spec.keyframes]
    if args.scenario is not None or args.scenario_text:
        for skill in args.skills:
            errors.scenario(skill, args.scenario, args.scenario_text)
    meshcat = None
    if args.meshcat:
        from pydrake.geometry import StartMeshcat
        meshcat = StartMeshcat()
        print(f"Meshcat: {meshcat.web_url()}")
    summary = run_demo(args.skills, args.seed, args.out, meshcat, realtime=1.0 if meshcat else 0.0,
                       scenario=args.scenario, scenario_text=args.scenario_text)
    print(f"{'skill':<7}{'final state':>13}  {'threshold':<20}{'scripted':>10}{'parked':>9}{'wall s':>8}")
    for skill, row in summary.items():
        print(f"{skill:<7}{row['final_object_state']:>13.3f}  {row['threshold']:<20}"
              f"{'success' if row['scripted_success'] else 'FAILURE':>10}"
              f"{'success' if row['parked_success'] else 'failure':>9}{row['wall_s']:>8.1f}")
    print(f"wrote {args.out}/summary.json, object_state.png, camera_<skill>.png")
    ok = all(r["scripted_success"] and not r["parked_success"] for r in summary.values())
    return 0 if ok else 1


def main(argv=None) -> int:
    """``drake-skill station-demo ARGV...`` (for scripts and tests)."""
    from drake_skill.cli.main import command_main
    return command_main(NAME, argv)
