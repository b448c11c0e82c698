"""The code base is ruff clean (issue 31): ``ruff check`` with pyproject.toml's [tool.ruff] settings."""

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def test_ruff_check_finds_nothing():
    # ruff comes with the test extra (pyproject.toml); run from the root so that it reads [tool.ruff] there.
    result = subprocess.run([sys.executable, "-m", "ruff", "check", "drake_skill", "tests", "tools"],
                            cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, f"ruff check failed (exit {result.returncode}):\n{result.stdout}{result.stderr}"
