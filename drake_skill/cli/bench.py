"""drake-skill bench NAME [--json] [options]: run one benchmark.

A benchmark is a module drake_skill/bench/NAME.py with main(argv) -> int;
every such module is found automatically. Each prints a short table, or one
JSON object with --json; 'drake-skill bench NAME --help' describes what NAME
measures. The same benchmarks run as python tools/bench_NAME.py.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil

NAME = "bench"
HELP = "benchmarks (drake-skill bench NAME --help): " + "{names}"


def benchmarks() -> list[str]:
    """Names of the modules in drake_skill/bench/ (found without importing them)."""
    import drake_skill.bench as package

    return sorted(m.name for m in pkgutil.iter_modules(package.__path__) if not m.name.startswith("_"))


HELP = HELP.format(names=", ".join(benchmarks()))


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("name", metavar="NAME", help="the benchmark: " + ", ".join(benchmarks()))
    parser.add_argument("options", nargs=argparse.REMAINDER,
                        help="the benchmark's own options (--json, ...; see 'drake-skill bench NAME --help')")


def run(args: argparse.Namespace) -> int:
    names = benchmarks()
    if args.name not in names:
        raise ValueError(f"unknown benchmark '{args.name}'; choose from {', '.join(names)}")
    module = importlib.import_module(f"drake_skill.bench.{args.name}")
    options = [o for o in args.options if o != "--verbose"]  # global, handled by drake_skill.cli.main
    return int(module.main(options) or 0)
