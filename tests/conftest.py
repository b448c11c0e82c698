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
