#!/usr/bin/env python3
"""Rollout benchmark (perception-to-reward chain against the plant); see drake_skill/bench/rollout.py."""
import sys

from drake_skill.bench.rollout import main

if __name__ == "__main__":
    sys.exit(main())
