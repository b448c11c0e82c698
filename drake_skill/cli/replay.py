"""``drake-skill replay``: any kept rollout of a learn run or an evaluation, shown in Meshcat.

    drake-skill replay RUN --episode E --index C        an exploratory rollout of update E
    drake-skill replay RUN --greedy E                   the greedy execution after update E
    drake-skill replay RUN --held-out before|after --index C
    drake-skill replay RUN --select --index C           the guarded selection's executions
    drake-skill replay FOLDER --evaluation I --index C  drake-skill evaluate's, DMP I
    drake-skill replay FOLDER --exploration --index C   drake-skill evaluate --explore's
    drake-skill replay RUN --list                       the kept sets and their sizes

Every rollout a run or an evaluation executes keeps its weights, seed, hand
path and last camera frame in ``rollouts/`` (a failed one also its frames
up to the stop; ``drake_skill.learning.rollout_store``). ``replay``
re-simulates one from its weights and seed on the run's skill, scenario and
rollout settings, with Meshcat recording and contact forces drawn as
arrows, writes the recording as a standalone HTML page (default
``RUN/replays/NAME_cC.html``; open it in a browser, no server needed), and
prints the outcome beside the stored one and whether the path is the same.
``--stored`` draws the stored joints instead of simulating (a robot run's
rollouts; no forces).
"""

from __future__ import annotations

import argparse
from pathlib import Path

NAME = "replay"
HELP = "show any kept rollout of a run or an evaluation in Meshcat (re-simulated, with contact forces)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("folder", type=Path, metavar="RUN",
                        help="a learn run's folder (learn --out), or the folder of an evaluate report")
    which = parser.add_mutually_exclusive_group()
    which.add_argument("--episode", type=int, metavar="E", help="an exploratory rollout of update E (1..episodes)")
    which.add_argument("--greedy", type=int, metavar="E", help="the greedy execution after update E (0: before)")
    which.add_argument("--held-out", choices=("before", "after"), help="a held-out execution before or after learning")
    which.add_argument("--select", action="store_true", help="an execution of the guarded selection")
    which.add_argument("--evaluation", type=int, metavar="I", help="an execution of DMP I by drake-skill evaluate")
    which.add_argument("--exploration", action="store_true", help="a rollout of drake-skill evaluate --explore")
    which.add_argument("--list", action="store_true", help="list the kept sets of rollouts and exit")
    parser.add_argument("--index", type=int, default=0, metavar="C",
                        help="the rollout within the set (default 0; results.jsonl's 'index')")
    parser.add_argument("--stored", action="store_true",
                        help="draw the stored joints instead of re-simulating (a robot run; no contact forces)")
    parser.add_argument("--out", type=Path, help="HTML page to write (default RUN/replays/NAME_cC.html)")


def set_name(args) -> str:
    """The kept set the flags name (``rollouts/NAME.npz``)."""
    if args.episode is not None:
        return f"episode_{args.episode:03d}"
    if args.greedy is not None:
        return f"greedy_{args.greedy:03d}"
    if args.held_out is not None:
        return f"held_out_{args.held_out}"
    if args.select:
        return "select"
    if args.evaluation is not None:
        return f"evaluation_dmp_{args.evaluation}"
    if args.exploration:
        return "exploration"
    raise ValueError("which rollout? give --episode E --index C, --greedy E, --held-out before|after, "
                     "--select, --evaluation I or --exploration (--list shows what the folder keeps)")


def run(args) -> int:
    from drake_skill.learning.rollout_store import load_rollout, rollouts_path, stored_names

    if not args.folder.is_dir():
        raise FileNotFoundError(f"{args.folder}: no such folder (a learn run's --out, or an evaluation's folder)")
    if args.list:
        for name in stored_names(args.folder):
            print(f"{name}: {load_rollout(rollouts_path(args.folder, name), 0)['meta']['n']} rollouts")
        return 0
    from drake_skill.learning.replay import replay_rollout

    name = set_name(args)
    replayed = replay_rollout(args.folder, name, args.index, args.out, stored=args.stored)
    print(f"{name} rollout {args.index} (seed {replayed.stored['seed']}): wrote {replayed.html}")
    if replayed.result is not None:
        r = replayed.result
        outcome = f"failed ({r.reason}: {r.message})" if r.failed else (
            f"{'success' if r.success else 'failure'}, return {r.dense_return:.1f}, "
            f"final state {r.final_object_state:.4g}")
        print(f"re-simulated: {outcome}")
        if r.contact is not None:
            pairs = "; ".join(f"{a} - {b} {f:.0f} N" for a, b, f in r.contact["pairs"] or [])
            print(f"contact at t = {r.contact['t']} s ({r.contact['cause']}): {pairs or 'not reported'}")
        if replayed.same is not None:
            print(f"hand path as stored: {'yes' if replayed.same else 'no'} "
                  f"(largest difference {replayed.path_error_m * 1000:.3f} mm)")
    return 0
