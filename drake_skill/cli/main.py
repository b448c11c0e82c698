"""``drake-skill``: the command line.

Subcommands (``drake-skill <command> --help`` for each):

  station-demo   scripted Open, Close and Draw in the simulated station
  demos record   record demonstrations (scripted or interactive in Meshcat)
  fit            fit a skill from demonstrations
  bench NAME     benchmarks: station, dmp, perception, reward (``--json``)

Every subcommand's module has a ``main(argv) -> int``; this file only
dispatches, so ``--help`` texts live beside the code they describe.
"""

from __future__ import annotations

import importlib
import logging
import sys

COMMANDS = {
    "station-demo": ("drake_skill.cli.station_demo", "scripted Open/Close/Draw in the simulated station"),
    "demos": ("drake_skill.cli.demos", "record demonstrations: demos record --skill open --count 3 --out DIR"),
    "fit": ("drake_skill.cli.fit", "fit a skill (DMPs + goal model) from demonstrations"),
    "bench": (None, "benchmarks: station, dmp, perception, reward"),
}
BENCHES = ("station", "dmp", "perception", "reward")


def _usage() -> str:
    lines = ["usage: drake-skill <command> [options]", "", "Robot skill learning from very few "
             "demonstrations, as a Drake diagram.", "", "commands:"]
    lines += [f"  {name:<14}{text}" for name, (_, text) in COMMANDS.items()]
    lines += ["", "Run 'drake-skill <command> --help' for a command's options.",
              "--verbose (any command) also prints differential IK's unreachable-pose warnings."]
    return "\n".join(lines)


class _QuietDiffIk(logging.Filter):
    """Counts, instead of printing, differential IK's "no solution"/"stuck" warnings.

    They come whenever a commanded hand pose is out of reach (a DMP exploring
    far from the demonstrations does that); one line per episode drowns the
    progress bars. ``--verbose`` shows them all.
    """

    def __init__(self):
        super().__init__()
        self.count = 0

    def filter(self, record):
        if "Differential IK" in record.getMessage():
            self.count += 1
            return False
        return True


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    quiet = _QuietDiffIk()
    if "--verbose" in argv:
        argv.remove("--verbose")
    else:
        logging.getLogger("drake").addFilter(quiet)
    try:
        return _dispatch(argv)
    finally:
        logging.getLogger("drake").removeFilter(quiet)
        if quiet.count:
            print(f"({quiet.count} differential-IK warnings about unreachable hand poses hidden; "
                  "--verbose shows them)", file=sys.stderr)


def _dispatch(argv) -> int:
    if not argv or argv[0] in ("-h", "--help"):
        print(_usage())
        return 0
    if argv[0] in ("-V", "--version"):
        from drake_skill import __version__
        print(__version__)
        return 0
    command, rest = argv[0], argv[1:]
    if command not in COMMANDS:
        print(f"drake-skill: unknown command {command!r}\n\n{_usage()}", file=sys.stderr)
        return 2
    if command == "bench":
        if not rest or rest[0] in ("-h", "--help"):
            print(f"usage: drake-skill bench {{{','.join(BENCHES)}}} [--json] [options]\n\n"
                  "Benchmarks print a short table, or one JSON object with --json.\n"
                  "'drake-skill bench NAME --help' describes what NAME measures.")
            return 0
        if rest[0] not in BENCHES:
            print(f"drake-skill bench: unknown benchmark {rest[0]!r}; choose from {', '.join(BENCHES)}",
                  file=sys.stderr)
            return 2
        module = importlib.import_module(f"drake_skill.bench.{rest[0]}")
        return int(module.main(rest[1:]) or 0)
    module = importlib.import_module(COMMANDS[command][0])
    return int(module.main(rest) or 0)


if __name__ == "__main__":
    raise SystemExit(main())
