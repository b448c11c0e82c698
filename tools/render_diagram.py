"""Renders the rollout diagram (station + object pose + DMP + goal pipeline) to SVG.

    python tools/render_diagram.py [--skill-dir DIR] [--depth 1] [--out docs/diagram.svg]

The README's picture: Drake's ``GetGraphvizString`` of the diagram a rollout
runs (``drake_skill.learning.rollout.RolloutRunner``), drawn by graphviz's
``dot`` through pydot (a Drake dependency). Default skill: the fitted Open skill
the experiment grid starts from (committed under docs/results/experiment).
"""

import argparse
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def render(skill_dir: Path, depth: int) -> bytes:
    import pydot

    from drake_skill.learning.rollout import RolloutRunner
    from drake_skill.fitted_skill import Skill

    runner = RolloutRunner(Skill.load(skill_dir))
    (graph,) = pydot.graph_from_dot_data(runner.diagram.GetGraphvizString(max_depth=depth))
    graph.set_rankdir("LR")
    return graph.create_svg()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--skill-dir", type=Path, default=ROOT / "docs/results/experiment/open/initial_skill")
    parser.add_argument("--depth", type=int, default=1, help="GetGraphvizString's max_depth (1: the boxes)")
    parser.add_argument("--out", type=Path, default=ROOT / "docs/diagram.svg")
    args = parser.parse_args()
    from drake_skill.fileio import atomic_write_bytes

    atomic_write_bytes(args.out, render(args.skill_dir, args.depth))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
