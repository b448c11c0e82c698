#!/usr/bin/env python3
"""Benchmark of the DMP action model; see drake_skill/bench/dmp.py (``--json`` for one JSON object)."""

import sys

from drake_skill.bench.dmp import main

if __name__ == "__main__":
    sys.exit(main())
