#!/usr/bin/env python3
"""Perception benchmark (segmentation and encoding ms per frame); see drake_skill/bench/perception.py.

Single-threaded: the thread variables are set before numpy or torch is imported.
"""
import os
import sys

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

from drake_skill.bench.perception import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
