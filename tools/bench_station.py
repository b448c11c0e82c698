#!/usr/bin/env python3
"""Station real-time factor benchmark; see drake_skill/bench/station.py."""
import sys

from drake_skill.bench.station import main

if __name__ == "__main__":
    sys.exit(main())
