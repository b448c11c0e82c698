#!/usr/bin/env python3
"""Learning-run wall time on 1 worker and the default; see drake_skill/bench/learn.py."""
import sys

from drake_skill.bench.learn import main

if __name__ == "__main__":
    sys.exit(main())
