#!/usr/bin/env python3
"""Writes ``constraints.txt``: the exact versions installed here of what drake-skill names.

pyproject.toml gives version ranges; this file records the versions the test
suite passed with, for ``pip install -c constraints.txt -e '.[test]'`` (the
Makefile does). It lists the project's dependencies, its test extra and its
build requirement, each at the version installed in the running interpreter's
environment (``importlib.metadata``); a local version label (``+cpu``) is
dropped so that the constraint matches a CPU or CUDA build of the same release.

    .venv/bin/python tools/write_constraints.py          # rewrites constraints.txt
"""

from __future__ import annotations

import argparse
import importlib.metadata
import re
import sys
import tomllib
from pathlib import Path

HEADER = """\
# The exact versions drake-skill's test suite passed with (pyproject.toml has the ranges).
# Written by tools/write_constraints.py from the working .venv; the Makefile installs with
#   pip install -c constraints.txt -e '.[test]'
"""


def _name(requirement: str) -> str:
    return re.match(r"[A-Za-z0-9][A-Za-z0-9._-]*", requirement.strip()).group(0)


def requirement_names(pyproject: Path) -> list[str]:
    """Names of the dependencies, the test extra and the build requirements, in that order, once each."""
    data = tomllib.loads(pyproject.read_text())
    names = [_name(r) for r in data["project"]["dependencies"]]
    names += [_name(r) for r in data["project"]["optional-dependencies"]["test"]]
    names += [_name(r) for r in data["build-system"]["requires"]]
    seen, out = set(), []
    for n in names:
        key = n.lower().replace("_", "-")
        if key not in seen:
            seen.add(key)
            out.append(n)
    return out


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--pyproject", type=Path, default=Path("pyproject.toml"))
    p.add_argument("--out", type=Path, default=Path("constraints.txt"))
    args = p.parse_args()
    lines, missing = [], []
    for name in requirement_names(args.pyproject):
        try:
            version = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            missing.append(name)
            continue
        lines.append(f"{name}=={version.split('+')[0]}")
    if missing:
        print(f"not installed here: {', '.join(missing)}; install them (pip install -e '.[test]') and run again",
              file=sys.stderr)
        return 2
    args.out.write_text(HEADER + "\n".join(lines) + "\n")
    print(f"wrote {args.out} ({len(lines)} packages)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
