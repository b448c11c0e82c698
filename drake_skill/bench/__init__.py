"""Benchmarks: one module per subject, each exposing ``main(argv=None) -> int``."""
