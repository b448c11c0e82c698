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


def pytest_collection_modifyitems(config, items):
    """Under pytest-xdist (``make test``: ``-n 2 --dist loadgroup``), each test file runs
    on one worker, so its module fixtures (a fitted skill, a grid) are built once;
    test_physics's long, independent checks and the notebooks (no shared fixtures)
    spread over the workers."""
    for item in items:
        if item.path.name not in ("test_physics.py", "test_notebooks.py"):
            item.add_marker(pytest.mark.xdist_group(item.path.stem))
