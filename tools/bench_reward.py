#!/usr/bin/env python3
"""Benchmark of the learned reward; see drake_skill/bench/reward.py (``--json`` for one JSON object)."""

import sys

from drake_skill.bench.reward import main

if __name__ == "__main__":
    sys.exit(main())
