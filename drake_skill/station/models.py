"""Where drake-skill's model files live, and the package map that finds them.

The models (Panda, table, box, drawer, trained PCAE weights) are in the
repository's ``models/`` folder, registered as the package
``drake_skill_models`` so SDF files are addressed as
``package://drake_skill_models/<file>``. ``DRAKE_SKILL_MODELS`` overrides the
folder.
"""

from __future__ import annotations

import os
from pathlib import Path

PACKAGE_NAME = "drake_skill_models"


def models_dir() -> Path:
    """The folder holding the models (``$DRAKE_SKILL_MODELS`` or ``<repo>/models``)."""
    env = os.environ.get("DRAKE_SKILL_MODELS")
    path = Path(env) if env else Path(__file__).resolve().parents[2] / "models"
    if not (path / "package.xml").is_file():
        raise FileNotFoundError(
            f"drake-skill models folder {path} has no package.xml; set DRAKE_SKILL_MODELS "
            "to the repository's models/ folder")
    return path


def model_url(filename: str) -> str:
    return f"package://{PACKAGE_NAME}/{filename}"


def add_package_paths(package_map) -> None:
    """Registers ``drake_skill_models`` in a Drake PackageMap (idempotent)."""
    if not package_map.Contains(PACKAGE_NAME):
        package_map.Add(PACKAGE_NAME, str(models_dir()))
