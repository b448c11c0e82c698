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


def pytest_xdist_make_scheduler(config, log):
    """Under pytest-xdist with ``--dist loadscope`` (``make test``), each test file runs on
    one worker, so its module fixtures (a fitted skill, a grid) are built once;
    test_physics's long, independent checks and the notebooks spread over the workers.

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
            return nodeid if path.endswith(SPREAD) else path

    return FileScopes(config, log)
