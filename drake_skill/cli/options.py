"""Options several commands share, defined once: the object frame's source, and the
:class:`~drake_skill.learning.rollout.RolloutConfig` it selects."""

from __future__ import annotations

import argparse
from pathlib import Path

__all__ = ["add_ground_truth_pose", "rollout_config"]


def add_ground_truth_pose(parser, on_robot: bool = False) -> None:
    """``--ground-truth-pose``: the object frame from the simulator's ground truth (on the robot:
    the placed pose) instead of the camera's segmenter (docs/method.md section 2)."""
    where = "the placed pose" if on_robot else "the simulator's ground truth"
    parser.add_argument("--ground-truth-pose", action="store_true",
                        help=f"object frame from {where} instead of the camera's segmenter")


def add_scenario(parser, *names: str, what: str = "the skill's scenario", dest: str = "station_config") -> None:
    """``--scenario FILE`` (also ``names``) and ``--scenario-text YAML`` (repeatable): the scenario
    a command runs is ``what``, then the file, then each text in turn (``inputs.scenario``)."""
    parser.add_argument("--scenario", *names, dest=dest, type=Path, metavar="FILE", default=None,
                        help=f"a scenario YAML laid over {what} (keys left out keep its values)")
    parser.add_argument("--scenario-text", action="append", default=[], metavar="YAML",
                        help="YAML laid over the scenario after --scenario, e.g. 'enable_camera: false' "
                             "or 'driver: !PandaLcmDriver {lcm_url: \"memq://\"}' (repeatable, in order)")


def rollout_config(args: argparse.Namespace, camera: bool = True):
    """The RolloutConfig of the parsed flags: the object frame perceived unless
    ``--ground-truth-pose`` or no camera; the learned reward only with a camera."""
    from drake_skill.learning.rollout import RolloutConfig

    perceived = camera and not args.ground_truth_pose
    return RolloutConfig(object_pose="perceived" if perceived else "ground_truth", goal_model=camera)


def ray_address(text: str) -> str:
    """``--ray-address``'s type: 'auto', or an address that answers within 5 s (checked where the value
    enters, before any work: ``ray.init`` would retry a dead address for minutes)."""
    if text != "auto":
        from drake_skill.learning.workers import check_ray_address

        try:
            check_ray_address(text)
        except ValueError as e:
            raise argparse.ArgumentTypeError(str(e).removeprefix("--ray-address ")) from None
    return text
