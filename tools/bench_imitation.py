#!/usr/bin/env python3
"""Imitation benchmark (plain imitation vs each demonstration); see drake_skill/bench/imitation.py."""
import sys

from drake_skill.bench.imitation import main

if __name__ == "__main__":
    sys.exit(main())
