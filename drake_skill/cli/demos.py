"""``drake-skill demos``: record, list, replay, export and import demonstrations.

record: the scripted demonstrator (default) or you (``--interactive``)
demonstrate a skill in the simulated station. Scripted: the human-like
scripted demonstrator plays the skill (``drake_skill.demos.demonstrator``);
a variation that fails the ground-truth judge is replaced by the next seed.
Interactive: drake-skill's teleoperation page opens (its URL is printed;
the Meshcat view embedded, beside a panel that shows the state: idle or
recording and its time, demonstration k of n, the last verdict and why, the
time limits); you drive the hand with keys (while no text box has focus),
Meshcat's sliders or a gamepad and press Record / Stop
(``drake_skill.demos.teleop``). Writes
``OUT/demo_000.npz``, ``demo_001.npz``, ... (format:
``drake_skill.demos.format``), ``OUT/demos.json`` (the list of the set) and
``OUT/demos.png`` (the demonstrated hand paths in the object frame and the
object state over time), then prints a table, and a warning naming each
file whose peak contact force or external joint torque passed 60 % of the
reflex's limit (``drake_skill.demos.force_margin``). Existing demo files are never
replaced without ``--force``; with it the whole set is replaced at once
(an interruption leaves the old set or the new one, never a mix).
Interactive recordings keep each successful demonstration on disk as it
ends (with ``--force`` the new set grows in ``.OUT.recording`` beside the
old one): Ctrl-C, SIGTERM or closing the page keeps every finished one
(replacing the old set once one is finished), says how many, and exits with
status 130.

list: a table of a folder's demonstrations (index, file, skill, duration,
samples, ground-truth success, source).

replay: one standalone Meshcat HTML page per demonstration (``--out``,
default ``DIR_replay`` beside DIR, so that re-recording DIR leaves no stale
pages in it): the recorded joint positions played back on the
skill's scenario plant; open it in a browser.

export / import: a robomimic dataset (one HDF5 file, ``data/demo_N/obs``,
``actions``, ...; see ``drake_skill.demos.robomimic``) from a folder, and a
folder (with ``demos.json``) from such a file, the arrays bit for bit.

examples:
  drake-skill demos record --skill open --out demos/open
  drake-skill demos record --skill close --count 2 --seed 10 --out demos/close
  drake-skill demos record --skill draw --interactive --out demos/draw_by_hand
  drake-skill demos list demos/open
  drake-skill demos replay demos/open --out replays/
  drake-skill demos export --format robomimic demos/open open.hdf5
  drake-skill demos import open.hdf5 demos/open_again
"""

import argparse
import dataclasses as dc
from pathlib import Path

import numpy as np

from drake_skill.cli import errors, options
from drake_skill.fileio import write_figure_png

FORMATS = ("robomimic",)   # drake_skill.demos.robomimic.FORMATS (not imported here: --help stays light)

NAME = "demos"
HELP = "demonstrations: record, list, replay (Meshcat HTML), export / import (robomimic HDF5)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    rec = sub.add_parser("record", help="record demonstrations of a skill",
                         description=parser.description, formatter_class=argparse.RawDescriptionHelpFormatter)
    rec.add_argument("--verbose", action="store_true", default=argparse.SUPPRESS,
                     help="print tracebacks of errors and every differential-IK warning")
    rec.add_argument("--skill", required=True, metavar="SKILL",
                     help="the skill to demonstrate: a shipped skill's name (drake-skill skills) or a skill file")
    rec.add_argument("--count", type=int, default=0,
                     help="demonstrations to record (default: the thesis' 3 open, 2 close, 2 draw)")
    rec.add_argument("--out", type=Path, required=True, help="folder for demo_NNN.npz, demos.json and demos.png")
    rec.add_argument("--seed", type=int, default=None,
                     help="first seed: object pose and variation of the first demonstration "
                          "(default: the config's, 0)")
    rec.add_argument("--interactive", action="store_true",
                     help="drive the hand yourself in Meshcat instead of the scripted demonstrator")
    rec.add_argument("--no-camera", action="store_true",
                     help="skip the camera (much faster; the files then have no perception fields)")
    rec.add_argument("--config", type=Path,
                     help="YAML file of DemonstratorConfig fields (variation, rates, attempts)")
    options.add_scenario(rec, what="the skill's shipped scenario", dest="scenario")
    rec.add_argument("--force", action="store_true",
                     help="replace the demonstrations already in --out (the whole set at once)")
    rec.add_argument("--quiet", action="store_true", help="no progress bar")
    rec.set_defaults(_action=record)

    def action(name, help, func):
        p = sub.add_parser(name, help=help, description=help)
        p.add_argument("--verbose", action="store_true", default=argparse.SUPPRESS,
                       help="print tracebacks of errors")
        p.set_defaults(_action=func)
        return p

    ls = action("list", "a table of a folder's demonstrations", list_demos)
    ls.add_argument("dir", type=Path, metavar="DIR", help="a demonstration folder (demo_NNN.npz)")
    rp = action("replay", "a standalone Meshcat HTML replay per demonstration", replay)
    rp.add_argument("dir", type=Path, metavar="DIR", help="a demonstration folder (demo_NNN.npz)")
    rp.add_argument("--out", type=Path, default=None, help="folder for demo_NNN.html (default DIR_replay, beside DIR)")
    options.add_scenario(rp, what="the skill's shipped scenario", dest="scenario")
    ex = action("export", "write a folder's demonstrations as one dataset file", export)
    ex.add_argument("--format", choices=FORMATS, default="robomimic", help="dataset layout (default robomimic)")
    ex.add_argument("dir", type=Path, metavar="DIR", help="a demonstration folder (demo_NNN.npz)")
    ex.add_argument("out", type=Path, metavar="OUT.hdf5", help="the file to write")
    ex.add_argument("--force", action="store_true", help="replace OUT.hdf5 if it exists")
    im = action("import", "a demonstration folder from a dataset file written by export", import_)
    im.add_argument("--format", choices=FORMATS, default="robomimic", help="dataset layout (default robomimic)")
    im.add_argument("file", type=Path, metavar="IN.hdf5", help="a dataset written by 'demos export'")
    im.add_argument("dir", type=Path, metavar="DIR", help="the folder for demo_NNN.npz and demos.json")
    im.add_argument("--force", action="store_true", help="replace the demonstrations already in DIR")


def run(args: argparse.Namespace) -> int:
    return args._action(args)


def _plot(demos, path: Path) -> Path:
    from drake_skill.fileio import new_figure

    fig = new_figure((12, 4.2))
    ax3 = fig.add_subplot(1, 3, 1, projection="3d")
    ax_xz = fig.add_subplot(1, 3, 2)
    ax_obj = fig.add_subplot(1, 3, 3)
    for i, d in enumerate(demos):
        p = d.X_OE_100hz[:, :3]
        label = f"demo {i} (seed {d.seed})"
        line, = ax3.plot(p[:, 0], p[:, 1], p[:, 2], lw=1.2, label=label)
        ax3.scatter(*d.X_OE[:, :3].T, s=4, color=line.get_color())
        ax_xz.plot(p[:, 0], p[:, 2], lw=1.2, color=line.get_color(), label=label)
        ax_xz.plot(p[0, 0], p[0, 2], "o", color=line.get_color())
        ax_obj.plot(d.times_100hz, d.object_state_100hz, color=line.get_color(), label=label)
    skill = demos[0].skill
    # Equal scale on the three axes (the y extent is often tiny).
    pts = np.concatenate([d.X_OE_100hz[:, :3] for d in demos])
    centre, half = (pts.max(0) + pts.min(0)) / 2, max(np.ptp(pts, axis=0).max() / 2, 0.01)
    ax3.set_xlim(centre[0] - half, centre[0] + half)
    ax3.set_ylim(centre[1] - half, centre[1] + half)
    ax3.set_zlim(centre[2] - half, centre[2] + half)
    ax3.set_title(f"{skill}: hand path in the object frame")
    ax3.set_xlabel("x_O [m]")
    ax3.set_ylabel("y_O [m]")
    ax3.set_zlabel("z_O [m]")
    ax_xz.set_title("side view (o = start; dots: 10 Hz samples in 3-D)")
    ax_xz.set_xlabel("x_O [m]")
    ax_xz.set_ylabel("z_O [m]")
    ax_xz.set_aspect("equal", adjustable="datalim")
    ax_xz.grid(alpha=0.3)
    ax_obj.set_title("object state (ground truth)")
    ax_obj.set_xlabel("time [s]")
    ax_obj.set_ylabel("object joint [rad or m]")
    ax_obj.grid(alpha=0.3)
    ax_obj.legend(fontsize=8)
    fig.tight_layout()
    written = write_figure_png(fig, path, dpi=100)
    return written


def table(rows) -> str:
    """The summary table printed at the end; rows are (file, demo) pairs."""
    lines = [f"{'file':<14}{'seed':>6}{'duration s':>12}{'samples 100/10 Hz':>19}{'perception':>12}"
             f"{'success':>9}{'final state':>13}"]
    for name, d in rows:
        perception = f"{int(d.perception_valid.sum())}/{d.n_samples}" if d.has_perception else "-"
        lines.append(f"{name:<14}{d.seed:>6}{d.duration:>12.2f}{d.times_100hz.size:>11} / {d.n_samples:<5}"
                     f"{perception:>12}{'yes' if d.success else 'NO':>9}{d.final_object_state:>13.3f}")
    return "\n".join(lines)


def warn_force_margin(demos, paths, reflex) -> None:
    """One ``drake-skill: warning:`` line (stderr) per demonstration that pressed over
    ``drake_skill.demos.force_margin.FORCE_MARGIN`` of a reflex limit, naming its file."""
    import sys

    from drake_skill.demos.force_margin import margin_warnings

    for path, demo in zip(paths, demos):
        for message in margin_warnings(demo, reflex, str(path)):
            print(f"drake-skill: warning: {message}", file=sys.stderr)


def record(args) -> int:
    from drake_skill.demos.demonstrator import DemonstratorConfig, load_demonstrator_config
    from drake_skill.demos.format import existing_demo_files, save_demonstrations

    # Everything a user can get wrong is checked before the first simulation.
    if args.count < 0:
        raise ValueError(f"--count {args.count}: expected a positive number of demonstrations (0 = the default)")
    existing = existing_demo_files(args.out)
    held = (f"{len(existing)} demonstration file(s) "
            f"({', '.join(p.name for p in existing[:3])}{', ...' if len(existing) > 3 else ''})")
    errors.output_folder(args.out, "--out", occupied=bool(existing), force=args.force,
                         what=held if existing else "the demonstrations")
    if args.config:
        errors.input_file(args.config, "--config", "a YAML file of DemonstratorConfig fields")
    config = load_demonstrator_config(args.config) if args.config else DemonstratorConfig()
    spec = errors.skill(args.skill)
    station_config = errors.scenario(spec, args.scenario, args.scenario_text) \
        if args.scenario or args.scenario_text else None
    count = args.count or config.count or int(spec.demonstrations)
    seed = config.seed if args.seed is None else args.seed
    config = dc.replace(config, count=count, seed=seed, record_perception=not args.no_camera)
    if args.interactive:
        from drake_skill.demos.teleop import RecordingInterrupted, TeleopConfig, record_interactive_into

        def plot(tmp, demos):
            _plot(demos, tmp / "demos.png")

        try:
            paths, demos = record_interactive_into(
                args.out, spec, count, force=args.force, extra=plot, seed=seed,
                config=TeleopConfig(record_perception=not args.no_camera), station_config=station_config)
        except RecordingInterrupted as stop:
            import sys

            print(f"drake-skill: {stop}", file=sys.stderr)
            return 130
    else:
        from drake_skill.demos.demonstrator import ScriptedDemonstrator
        demos = ScriptedDemonstrator(spec, config, station_config=station_config).record_many(
            progress=not args.quiet)
        paths = save_demonstrations(demos, args.out, force=args.force,
                                    extra=lambda tmp: _plot(demos, tmp / "demos.png"))
    print(table([(p.name, d) for p, d in zip(paths, demos)]))
    print(f"wrote {len(demos)} demonstration(s) to {args.out}/ and {args.out / 'demos.png'}")
    warn_force_margin(demos, paths, (station_config or spec.station_config()).reflex)
    return 0 if all(d.success for d in demos) else 1


def list_table(rows) -> str:
    """The ``demos list`` table; rows are (index, file name, Demonstration or error message)."""
    lines = [f"{'#':>3}  {'file':<14}{'skill':<7}{'duration s':>11}{'samples 100/10 Hz':>19}"
             f"{'perception':>12}{'success':>9}  source"]
    for i, name, d in rows:
        if isinstance(d, str):
            lines.append(f"{i:>3}  {name:<14}unreadable: {d}")
            continue
        perception = f"{int(d.perception_valid.sum())}/{d.n_samples}" if d.has_perception else "-"
        success = "yes" if d.success else "NO"
        if "verdict" in d.metadata:
            success += f" ({d.metadata['verdict']})"
        lines.append(f"{i:>3}  {name:<14}{d.skill:<7}{d.duration:>11.2f}{d.times_100hz.size:>11} / {d.n_samples:<5}"
                     f"{perception:>12}{success:>9}  {d.metadata.get('source', '-')}")
    return "\n".join(lines)


def list_demos(args) -> int:
    import sys

    from drake_skill.demos.format import (DemonstrationError, check_manifest, existing_demo_files,
                                          load_demonstration)

    errors.input_folder(args.dir, "DIR", "demonstrations (demo_NNN.npz)")
    paths = existing_demo_files(args.dir)
    if not paths:
        raise FileNotFoundError(f"{args.dir}: no demo_*.npz files (record some with "
                                f"'drake-skill demos record --out {args.dir}')")
    rows = []
    for i, p in enumerate(paths):
        try:
            rows.append((i, p.name, load_demonstration(p)))
        except (ValueError, OSError) as e:
            rows.append((i, p.name, str(e).replace(f"{p}: ", "")))
    print(list_table(rows))
    problems = [r for r in rows if isinstance(r[2], str)]
    try:
        check_manifest(Path(args.dir), paths)
    except DemonstrationError as e:
        problems.append(e)
        print(f"drake-skill: warning: {e}", file=sys.stderr)
    skills = sorted({d.skill for _, _, d in rows if not isinstance(d, str)})
    if len(skills) > 1:
        problems.append(skills)
        print(f"drake-skill: warning: {args.dir} mixes skills ({', '.join(skills)})", file=sys.stderr)
    print(f"{len(paths)} demonstration(s) in {args.dir}" + ("" if not problems else "; the folder does not load "
                                                           "as one set (see above)"))
    return 1 if problems else 0


def replay(args) -> int:
    from drake_skill.demos.format import load_demonstrations
    from drake_skill.demos.replay import write_replay

    errors.input_folder(args.dir, "DIR", "demonstrations (demo_NNN.npz)")
    demos = load_demonstrations(args.dir)
    folder = args.dir.resolve()
    out = args.out if args.out is not None else folder.with_name(f"{folder.name}_replay")
    errors.output_folder(out, "--out", what="the replays")
    configs = {}
    for d in demos:
        if d.skill not in configs:
            configs[d.skill] = errors.scenario(d.skill, args.scenario, args.scenario_text)
    from pydrake.geometry import Meshcat
    meshcat = Meshcat()
    written = [write_replay(d, out / Path(d.path).with_suffix(".html").name, configs[d.skill], meshcat)
               for d in demos]
    for p, d in zip(written, demos):
        print(f"wrote {p} ({d.skill}, {d.duration:.1f} s)")
    return 0


def export(args) -> int:
    from drake_skill.demos.robomimic import export_robomimic

    errors.input_folder(args.dir, "DIR", "demonstrations (demo_NNN.npz)")
    if args.out.exists() and not args.force:
        raise FileExistsError(f"OUT.hdf5 {args.out}: exists; pass --force to replace it or choose another file")
    if args.out.exists() and not args.out.is_file():
        raise ValueError(f"OUT.hdf5 {args.out}: is not a regular file; give the path of the .hdf5 file to write")
    path, demos = export_robomimic(args.dir, args.out)
    print(list_table([(i, f"demo_{i}", d) for i, d in enumerate(demos)]))
    print(f"wrote {path}: {len(demos)} demonstration(s), {sum(d.n_samples for d in demos)} samples "
          f"(robomimic layout, data/demo_N)")
    return 0


def import_(args) -> int:
    from drake_skill.demos.format import existing_demo_files
    from drake_skill.demos.robomimic import import_robomimic

    errors.input_file(args.file, "IN.hdf5", "a dataset written by 'drake-skill demos export'")
    existing = existing_demo_files(args.dir)
    errors.output_folder(args.dir, "DIR", occupied=bool(existing), force=args.force,
                         what=f"{len(existing)} demonstration file(s)" if existing else "the demonstrations")
    paths, demos = import_robomimic(args.file, args.dir, force=args.force)
    print(list_table([(i, p.name, d) for i, (p, d) in enumerate(zip(paths, demos))]))
    print(f"wrote {len(paths)} demonstration(s) to {args.dir}/")
    return 0


def main(argv=None) -> int:
    """``drake-skill demos ARGV...`` (for scripts and tests)."""
    from drake_skill.cli.main import command_main
    return command_main(NAME, argv)
