"""Fixtures shared by several test modules."""

import logging

import pytest


@pytest.fixture(scope="module")
def quiet_differential_ik():
    """Differential IK's warnings off for one module's tests (``pytestmark``); set at
    import instead, it would hide them from every later test (the rollout runner counts them)."""
    logger = logging.getLogger("drake")
    level = logger.level
    logger.setLevel(logging.ERROR)
    yield
    logger.setLevel(level)


#: Files whose tests share no expensive fixture and run long: spread test by test.
SPREAD = ("test_physics.py", "test_notebooks.py")
#: Files run one after the other on one worker: the hardware tests run two real-time
#: simulators, and while test_experiment's Ray cluster of 3 nodes started beside them the
#: simulated robot lagged real time (refinement 3.9 -> 5.4 mm RMS instead of -> ~2).
SEQUENTIAL = ("test_hardware.py", "test_experiment.py")


def pytest_xdist_make_scheduler(config, log):
    """Under pytest-xdist with ``--dist loadscope`` (``make test``), each test file runs on
    one worker, so its module fixtures (a fitted skill, a grid) are built once;
    test_physics's long, independent checks and the notebooks spread over the workers, and
    the files of ``SEQUENTIAL`` share one worker.

    (A scheduler of our own, not ``xdist_group`` marks with ``--dist loadgroup``:
    pytest-xdist 3.8 groups by rewriting ``item._nodeid``, which pytest 9 no longer
    reads, so every group was split over both workers and every module fixture was
    built twice.)"""
    if config.getvalue("dist") != "loadscope":
        return None
    from xdist.scheduler import LoadScopeScheduling

    class FileScopes(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            path = nodeid.split("::", 1)[0]
            if path.endswith(SPREAD):
                return nodeid
            return "real-time and Ray cluster" if path.endswith(SEQUENTIAL) else path

    return FileScopes(config, log)
