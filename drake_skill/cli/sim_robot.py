"""``drake-skill sim-robot``: a simulated Panda that speaks the drake-franka-driver's LCM protocol.

    drake-skill sim-robot --skill SKILL [--lcm-url URL] [--seed N] [--scenario FILE] [--scenario-text YAML]
                          [--no-camera] [--duration S] [--guide]

Runs the simulated station in real time behind Drake's PandaCommandReceiver /
PandaStatusSender: it listens for lcmt_panda_command on PANDA_COMMAND
(position mode, wall-clock utime: commands further than 0.1 s from the wall
clock are dropped, as the driver does), publishes lcmt_panda_status on
PANDA_STATUS every plant step, the camera's images (lcmt_image_array) on
DRAKE_RGBD_CAMERA_IMAGES at the camera rate and the object state (lid angle
/ drawer travel, lcmt_scope) on SIM_OBJECT_STATE; channels and URL from
--scenario (a scenario YAML laid over the skill's, its ``driver: !PandaLcmDriver
{...}``; ``--config`` is the same option) or the defaults. The object is placed at
the pose drawn from --seed, as ``drake-skill hardware run --seed0`` expects.

--guide plays the skill's scripted, human-like demonstration on the arm (a
person guiding it by hand) instead of following commands, for trying
``drake-skill hardware record-demo``.

Stop it with Ctrl-C or SIGTERM (or after --duration seconds).
"""

from __future__ import annotations

import argparse
import signal

from drake_skill.cli import options

NAME = "sim-robot"
HELP = "a simulated Panda behind the driver's LCM protocol (for hardware run / record-demo)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.description = __doc__
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    parser.add_argument("--lcm-url", default=None, help="LCM URL (default: the config's, or LCM's default)")
    parser.add_argument("--skill", required=True, metavar="SKILL",
                        help="the skill whose scenario the robot stands in (a shipped skill's name or a skill file)")
    parser.add_argument("--seed", type=int, default=None, help="object pose seed (default: the nominal pose)")
    options.add_scenario(parser, "--config", what="the skill's (its driver a !PandaLcmDriver: channels, URL, "
                         "timeouts)")
    parser.add_argument("--no-camera", action="store_true", help="no camera (faster; no images published)")
    parser.add_argument("--duration", type=float, default=float("inf"), help="stop after this many seconds")
    parser.add_argument("--guide", action="store_true",
                        help="play the skill's scripted demonstration on the arm (kinesthetic stand-in)")


def load_config(path, lcm_url, skill, camera: bool = True, texts=()):
    """The scenario of the CLI options, layered once (``inputs.scenario``): the skill's, with a
    ``!PandaLcmDriver``; then the ``--scenario`` file ``path``; then ``--scenario-text``; then
    ``--lcm-url`` and ``--no-camera``, written as YAML overrides."""
    import json

    from drake_skill.cli import errors
    from drake_skill.inputs import scenario
    from drake_skill.station.drivers import PandaLcmDriver, require_panda_driver

    base = errors.skill(skill).station_config()
    base.driver = PandaLcmDriver()
    texts = list(texts)
    if lcm_url is not None:
        texts.append(f"driver: !PandaLcmDriver {{lcm_url: {json.dumps(lcm_url)}}}")
    if not camera:
        texts.append("enable_camera: false")
    config = scenario(base, path, texts)
    require_panda_driver(config, "the robot", "" if path is None else str(path))
    return config


def run(args: argparse.Namespace) -> int:
    if not args.duration > 0:
        raise ValueError(f"--duration must be positive, got {args.duration}")
    config = load_config(args.station_config, args.lcm_url, args.skill, not args.no_camera, args.scenario_text)

    from drake_skill.cli import errors
    from drake_skill.station.sim.lcm_robot import SimRobot

    guide = None
    if args.guide:
        from drake_skill.demos.demonstrator import DemonstratorConfig, humanlike_plan

        spec = errors.skill(args.skill)

        def guide(X_WO, X_WE_home, seed):
            """The skill's scripted, human-like demonstration for the run's seed."""
            return humanlike_plan(spec, X_WO, X_WE_home, seed, DemonstratorConfig())[0]
    robot = SimRobot(config, guide=guide)
    driver = config.driver
    url = driver.lcm_url or "(LCM default)"
    print(f"sim-robot: {args.skill} scenario on {url}: commands {driver.command_channel}, "
          f"status {driver.status_channel}, hand {driver.hand_command_channel}"
          + (f", camera {driver.camera_channel}" if config.enable_camera else "")
          + (f", object state {driver.ground_truth_channel}" if driver.ground_truth_channel else ""))
    print("guiding the arm through the scripted demonstration" if args.guide else
          "following position commands; Ctrl-C stops")
    def stop(signum, frame):
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, stop)   # SIGTERM stops it as Ctrl-C does
    try:
        robot.run(args.duration, seed=args.seed)
    except KeyboardInterrupt:
        pass
    finally:
        signal.signal(signal.SIGTERM, previous)
    print(f"sim-robot: stopped at t = {robot.time():.2f} s; object state {robot.object_state():.3f}; "
          f"commands accepted {robot.command_counts()[0]}, dropped as expired {robot.command_counts()[1]}")
    return 0


def main(argv=None) -> int:
    """Stand-alone entry (the dispatcher normally calls add_arguments / run)."""
    parser = argparse.ArgumentParser(prog="drake-skill sim-robot")
    add_arguments(parser)
    return run(parser.parse_args(argv))
