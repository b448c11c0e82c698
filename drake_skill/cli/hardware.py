"""``drake-skill hardware``: a skill on a real Panda through the drake-franka-driver's LCM.

    drake-skill hardware run --skill-dir DIR [--lcm-url URL] [--scenario FILE]
                             [--rollouts 1] [--seed0 0] [--episodes E] [--out DIR] [--yes]
    drake-skill hardware record-demo --skill open --out DIR [--lcm-url URL] [--scenario FILE]
                             [--duration 15] [--seed 0] [--yes]
    drake-skill hardware refine --skill-dir DIR --demos DIR [--iterations 1] [--out DIR]
                             [--lcm-url URL] [--scenario FILE] [--yes]

The same diagram as in simulation, with the simulated station swapped for
the hardware station (``drake_skill.station.hardware.station``): position commands
on PANDA_COMMAND (wall-clock stamped, rate limited, the hand clipped to the
workspace box, the first command the measured position), the status from
PANDA_STATUS (no status for 100 ms stops it), the camera's images from
DRAKE_RGBD_CAMERA_IMAGES. Start the driver first, e.g.
``franka_driver --robot_ip_address=... --control_mode=position`` (or
``drake-skill sim-robot`` to try it without a robot).

run: executes the skill's greedy policy on ``--rollouts`` object poses
(seeds ``seed0, seed0 + 1, ...``) with the rollout runner of simulation, or
with ``--episodes E`` a learning run (``drake-skill learn``'s loop, every
rollout on the robot; its output folder is ``--out``). Before every rollout
it prints where to place the object and waits for Enter (a human resets the
scene; ``--yes`` does not wait, e.g. against sim-robot, which does not reset
itself). Prints a table and writes ``hardware_run.json`` in ``--out``.

refine: removes the robot's own lag and load offset from a fitted skill's
DMPs (docs/method.md section 2.3). For each demonstration the skill was
fitted from (``--demos``, in the fit's order), its DMP runs on the robot on
the demonstration's object pose, then is refitted to demonstration +
(demonstration - measured), ``--iterations`` times; the DMP whose executed
path came closest to the demonstration is kept (the plain one when no
refinement helped, with a warning saying so). Before every run it prints
where to place the object and waits for Enter, after the hand has moved
(slowly, 10 cm/s) to the demonstration's start. The refined skill is written
to ``--out`` (default SKILL/hardware_refined); the fitted skill is never
changed. ``fit`` refines on the simulated station only.

record-demo: records a kinesthetic demonstration: run the driver in a
compliant mode (``--control_mode=torque``: with no command it holds the arm
in gravity compensation and light damping; nothing is commanded from here),
guide the arm by hand for ``--duration`` seconds; the measured hand pose at
100 Hz and the segmented camera cloud at 10 Hz are added to ``--out`` as its
next ``demo_NNN.npz``, with the folder's ``demos.json`` updated in the same
atomic swap (the folder then loads as one set); a demonstration whose
filtered external joint torque passed 60 % of the reflex's
``external_torque_max`` on a joint gets a one-line warning naming the file,
the joint, the time and the torque. The demonstration format needs the object's
state over time (lid angle / drawer travel): it is read from
SIM_OBJECT_STATE (lcmt_scope), which sim-robot publishes; on a real robot a
sensor on the hinge or slide must publish it there.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from drake_skill.cli import options

NAME = "hardware"
HELP = "a skill on a real Panda over LCM: run (greedy or learning), record-demo (kinesthetic), refine"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.description = __doc__
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    actions = parser.add_subparsers(dest="action", metavar="ACTION", title="actions")
    actions.required = True
    run_p = actions.add_parser("run", help="the skill's greedy policy (or --episodes: learning) on the robot",
                               description="Executes a skill on the robot with the simulation's rollout runner.")
    run_p.add_argument("--skill-dir", type=Path, required=True,
                       help="a fitted skill's folder (drake-skill fit / learn)")
    run_p.add_argument("--rollouts", type=int, default=1,
                       help="greedy rollouts (default 1); per episode with --episodes")
    run_p.add_argument("--seed0", type=int, default=0, help="object pose seed of the first rollout (default 0)")
    run_p.add_argument("--episodes", type=int, default=0, help="policy-search episodes (default 0: greedy only)")
    options.add_ground_truth_pose(run_p, on_robot=True)
    run_p.add_argument("--out", type=Path, default=None, help="output folder (default SKILL/hardware_run)")
    demo_p = actions.add_parser("record-demo", help="record a kinesthetic demonstration",
                                description="Records the measured hand path and camera while a person guides the arm.")
    demo_p.add_argument("--skill", required=True, metavar="SKILL",
                        help="the skill demonstrated: a shipped skill's name or a skill file")
    demo_p.add_argument("--out", type=Path, required=True, help="demonstration folder (demo_NNN.npz)")
    demo_p.add_argument("--duration", type=float, default=15.0, help="recording length [s] (default 15)")
    demo_p.add_argument("--seed", type=int, default=0, help="object pose seed: where to place it (default 0)")
    demo_p.add_argument("--no-camera", action="store_true", help="record no perception")
    refine_p = actions.add_parser("refine", help="refine a fitted skill's DMPs on the robot (Enter before each run)",
                                  description="Refits each DMP so that the robot's executed path follows its "
                                              "demonstration (iterative learning control, one run per step).")
    refine_p.add_argument("--skill-dir", type=Path, required=True,
                          help="a skill fitted with --fit tolerance (drake-skill fit's default)")
    refine_p.add_argument("--demos", type=Path, required=True, help="the demonstrations the skill was fitted from")
    refine_p.add_argument("--iterations", type=int, default=1,
                          help="refinement steps per demonstration (default 1: two runs each)")
    refine_p.add_argument("--out", type=Path, default=None,
                          help="folder of the refined skill (default SKILL/hardware_refined)")
    refine_p.add_argument("--force", action="store_true", help="replace a skill already in --out")
    for p in (run_p, demo_p, refine_p):
        p.add_argument("--lcm-url", default=None, help="LCM URL (default: the config's, or LCM's default)")
        options.add_scenario(p, "--config", what="the skill's (its driver a !PandaLcmDriver: channels, URL, "
                             "timeouts, workspace)")
        p.add_argument("--yes", action="store_true", help="do not wait for Enter before each rollout")


def _prompt(enabled: bool):
    """The reset hook: where to place the object; waits for Enter."""
    if not enabled:
        return None

    def hook(seed, X_WO):
        from pydrake.math import RollPitchYaw

        x, y, _ = X_WO.translation()
        yaw = RollPitchYaw(X_WO.rotation()).yaw_angle()
        print(f"rollout seed {seed}: reset the scene; place the object's base at x = {x:.3f} m, "
              f"y = {y:.3f} m, yaw = {math.degrees(yaw):.1f} deg; press Enter to start", flush=True)
        input()

    return hook


def _run(args) -> int:
    from drake_skill.cli.sim_robot import load_config
    from drake_skill.fileio import atomic_write_json
    from drake_skill.learning.rollout import RolloutRunner
    from drake_skill.fitted_skill import Skill
    from drake_skill.station.make import make_station

    if args.rollouts < 1:
        raise ValueError(f"--rollouts must be at least 1, got {args.rollouts}")
    if args.episodes < 0:
        raise ValueError(f"--episodes must be 0 (greedy only) or more, got {args.episodes}")
    if not args.skill_dir.is_dir():
        raise NotADirectoryError(f"--skill-dir {args.skill_dir}: not a folder; "
                                 "give a skill folder (drake-skill fit --out)")
    skill = Skill.load(args.skill_dir)
    config = load_config(args.station_config, args.lcm_url, skill.name, texts=args.scenario_text)
    camera = config.enable_camera
    rollout = options.rollout_config(args, camera=camera)
    out = args.out if args.out is not None else args.skill_dir / "hardware_run"
    station = make_station(config, hardware=True)
    station.set_reset_hook(_prompt(not args.yes))
    runner = RolloutRunner(skill, config=rollout, station=station)
    driver = config.driver
    print(f"hardware station on {driver.lcm_url or '(LCM default)'}: status {driver.status_channel}, "
          f"commands {driver.command_channel}" + (f", camera {driver.camera_channel}" if camera else ""))
    if args.episodes:
        from drake_skill.learning.loop import LearnConfig, learn

        outcome = learn(args.skill_dir, out, LearnConfig(episodes=args.episodes, rollouts=args.rollouts,
                                                     seed=args.seed0, held_out=0),
                        station_config=config, rollout_config=rollout, runner=runner, replay=False)
        print(f"wrote {out} ({outcome!r:.200})")
        return 0
    results = []
    print(f"{'seed':>6} {'verdict':>8} {'return':>9} {'final state':>12} {'wall s':>7}  failure")
    for i in range(args.rollouts):
        result = runner.run(skill.initial_weights, args.seed0 + i)
        results.append(result.summary())
        final = "-" if not math.isfinite(result.final_object_state) else f"{result.final_object_state:.3f}"
        print(f"{result.seed:>6} {str(result.verdict):>8} {result.dense_return:>9.1f} {final:>12} "
              f"{result.wall_s:>7.1f}  {result.message[:80] if result.failed else ''}", flush=True)
        if result.reason == "stale_status" and len(results) == 1:
            raise ConnectionError(result.message.replace("StaleStatusError: ", ""))   # no driver: a user error
        if result.reason in ("stale_status", "reflex"):
            print("stopped: the robot's status stopped or its reflex fired", file=sys.stderr)
            break
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_json(out / "hardware_run.json", {"skill": str(args.skill_dir), "lcm_url": config.driver.lcm_url,
                                                  "rollouts": results})
    print(f"wrote {out / 'hardware_run.json'}")
    return 0 if results and not any(r["failed"] for r in results) else 1


def _record_demo(args) -> int:
    import numpy as np
    from pydrake.systems.analysis import Simulator
    from pydrake.systems.framework import DiagramBuilder

    from drake_skill.cli import errors
    from drake_skill.cli.demos import warn_force_margin
    from drake_skill.cli.sim_robot import load_config
    from drake_skill.demos.demonstrator import demonstration_from
    from drake_skill.demos.format import ACTION_HZ, append_demonstration, existing_demo_files, load_demonstrations
    from drake_skill.demos.format import ACTION_RAW_HZ as RECORD_HZ
    from drake_skill.station.make import make_station
    from drake_skill.station.pose_source import PoseTrajectorySource, hold_plan
    from drake_skill.station.loggers import StationLoggers
    from drake_skill.station.recording import advance_and_check, advance_station, vector_to_pose

    if not args.duration > 0:
        raise ValueError(f"--duration must be positive, got {args.duration}")
    if args.out.exists() and not args.out.is_dir():
        raise NotADirectoryError(f"--out {args.out}: not a folder")
    skill_name = errors.skill(args.skill).name
    if existing_demo_files(args.out):   # a set that does not load (mixed, other skill) is refused before recording
        load_demonstrations(args.out, skill=skill_name)
    config = load_config(args.station_config, args.lcm_url, args.skill, not args.no_camera, args.scenario_text)
    if not config.driver.ground_truth_channel:
        raise ValueError("record-demo needs the object's state over time: set ground_truth_channel "
                         "(a sensor on the hinge/slide, or sim-robot, publishes lcmt_scope there)")
    builder = DiagramBuilder()
    station = builder.AddNamedSystem("station", make_station(config, hardware=True, commanding=False))
    hold = builder.AddNamedSystem("hold", PoseTrajectorySource())   # unused: nothing is commanded
    builder.Connect(hold.GetOutputPort("X_WE_desired"), station.GetInputPort("ee_pose_desired"))
    builder.Connect(hold.GetOutputPort("gripper_command"), station.GetInputPort("gripper_command"))
    segmenter = None
    if config.enable_camera:
        from drake_skill.perception.systems import add_object_segmenter
        segmenter = add_object_segmenter(builder, station)
    # The one recording path (drake_skill.station.loggers); the hand's width is not read
    # back: the gripper logged is the hold's command, gripper_home.
    loggers = StationLoggers(builder, station, RECORD_HZ, segmenter=segmenter,
                             gripper_command=hold.GetOutputPort("gripper_command"))
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    simulator = Simulator(diagram, context)
    simulator.set_target_realtime_rate(1.0)
    station.set_reset_hook(_prompt(not args.yes))
    X_WO_placed = station.reset(context, args.seed)
    X_WE = station.GetOutputPort("ee_pose").Eval(station.GetMyContextFromRoot(context))
    hold.set_plan(hold.GetMyMutableContextFromRoot(context), hold_plan(X_WE, config.gripper_home))
    simulator.Initialize()
    # The status of now, not of the reset, in the first sample; the recording starts at a frame.
    frame_hz = 1.0 / loggers.frame_period if segmenter is not None else ACTION_HZ
    t_start = math.ceil(0.1 * frame_hz - 1e-9) / frame_hz
    advance_station(simulator, station, context, t_start)
    loggers.start(context)
    k = int(round(RECORD_HZ / frame_hz))
    print(f"recording {args.duration:.0f} s: guide the arm now (Ctrl-C ends early)", flush=True)
    n_end = int(math.ceil(args.duration * frame_hz - 1e-9)) * k

    def advance(n: int) -> None:    # to sample n, from Python: Ctrl-C lands between samples
        advance_and_check(simulator, station, context, loggers.grid(n, t_start)[-1])

    n = 0
    try:
        while n < n_end:
            n += 1
            advance(n)
    except KeyboardInterrupt:
        while n % k:                 # end on a frame
            n += 1
            advance(n)
    records = loggers.read(context, n, t_start)
    obj = records.object_state
    if not np.all(np.isfinite(obj)):
        raise ValueError(f"no object state on {config.driver.ground_truth_channel} during the recording: "
                         "the demonstration format needs it (see drake-skill hardware --help)")
    X_WO = X_WO_placed
    if records.frames is not None and records.frames.first_valid is not None:
        X_WO = vector_to_pose(records.frames.X_WO[records.frames.first_valid])
    from drake_skill.station.success import judge_success
    success = judge_success(float(obj[-1]), config.success)
    metadata = {"source": "kinesthetic", "lcm_url": config.driver.lcm_url,
                "X_WO_note": "X_OE uses the perceived X_WO at the first frame (the placed pose without a camera)"}
    demo = demonstration_from(records, RECORD_HZ, frame_hz, skill_name, args.seed, X_WO, success, metadata)
    path = append_demonstration(demo, args.out)      # demos.json updated in the same swap
    print(f"wrote {path}: {demo.duration:.1f} s, final object state {demo.final_object_state:.3f}, "
          f"{'success' if success else 'failure'}")
    # The robot measures the external joint torques, not the contact force (0): the torques decide.
    warn_force_margin([demo], [path], config.reflex)
    return 0


def _refine(args) -> int:
    from drake_skill.cli import errors
    from drake_skill.cli.sim_robot import load_config
    from drake_skill.demos.format import load_demonstrations
    from drake_skill.learning.imitation import check_demo_pairs
    from drake_skill.learning.refine import refine_on_robot, refinement_lines
    from drake_skill.fitted_skill import Skill
    from drake_skill.station.make import make_station

    if args.iterations < 1:
        raise ValueError(f"--iterations must be at least 1, got {args.iterations}")
    errors.input_folder(args.skill_dir, "--skill-dir", "a fitted skill (drake-skill fit)")
    errors.input_folder(args.demos, "--demos", "the demo_*.npz files the skill was fitted from")
    out = args.out if args.out is not None else args.skill_dir / "hardware_refined"
    if out.resolve() == args.skill_dir.resolve():
        raise ValueError(f"--out {out}: is the fitted skill's own folder; choose another (it is never changed)")
    if (out / "skill.json").exists() and not args.force:
        raise FileExistsError(f"--out {out}: already holds a skill; pass --force to replace it")
    skill = Skill.load(args.skill_dir)
    demos = load_demonstrations(args.demos, skill=skill.name)
    check_demo_pairs(skill, demos, f"--demos {args.demos}")
    # The placed pose is the object frame: no camera needed.
    config = load_config(args.station_config, args.lcm_url, skill.name, camera=False, texts=args.scenario_text)
    station = make_station(config, hardware=True)
    runs = len(demos) * (args.iterations + 1)
    print(f"refining {len(demos)} DMPs of {skill.name} on the robot: {runs} runs", flush=True)

    def progress(i, n, name):
        print(f"demonstration {i + 1} of {n}: {Path(str(name)).name}", flush=True)

    report = refine_on_robot(skill, demos, station, args.iterations, progress=progress,
                             prompt=_prompt(not args.yes))
    lines, warnings = refinement_lines(report)
    for line in lines:
        print(line)
    for warning in warnings:
        print(f"warning: {warning}", file=sys.stderr)
    skill.save(out, overwrite=args.force)
    print(f"wrote {out}")
    return 0


def run(args: argparse.Namespace) -> int:
    return {"run": _run, "record-demo": _record_demo, "refine": _refine}[args.action](args)


def main(argv=None) -> int:
    """Stand-alone entry (the dispatcher normally calls add_arguments / run)."""
    parser = argparse.ArgumentParser(prog="drake-skill hardware")
    add_arguments(parser)
    return run(parser.parse_args(argv))
