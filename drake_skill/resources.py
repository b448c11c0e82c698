"""Where the installed model files are: the package ``drake_skill.models``.

The repository's ``models/`` folder (Panda, table, box and drawer SDFormat
files, meshes, the trained PCAE weights) is installed as the Python package
``drake_skill.models``: pyproject.toml maps it, so the wheel and an editable
install both carry it. It is found with ``importlib.resources``, never by a
path relative to a source file. ``DRAKE_SKILL_MODELS`` overrides the folder.
Drake-free (numpy-only boxes read the PCAE weights through it).
"""

from __future__ import annotations

import importlib.resources
import os
from pathlib import Path

MODELS_PACKAGE = "drake_skill.models"
"""The Python package that holds the models folder."""


def models_dir() -> Path:
    """The folder holding the models: ``$DRAKE_SKILL_MODELS`` or the installed ``drake_skill.models``.

    Raises FileNotFoundError, saying what to install or set, when there is none.
    """
    env = os.environ.get("DRAKE_SKILL_MODELS")
    if env:
        path = Path(env)
        if not (path / "package.xml").is_file():
            raise FileNotFoundError(f"DRAKE_SKILL_MODELS={env} has no package.xml; point it at a "
                                    "drake-skill models folder or unset it")
        return path
    try:
        root = importlib.resources.files(MODELS_PACKAGE)
    except ModuleNotFoundError:
        raise FileNotFoundError(
            f"drake-skill's models (package {MODELS_PACKAGE}) are not installed; run "
            "`pip install -e .` in the checkout (or install the wheel)") from None
    # Drake's PackageMap and parsers need a real folder: a wheel or an editable
    # install gives one (a zipped install would not).
    if not isinstance(root, Path) or not (root / "package.xml").is_file():
        raise FileNotFoundError(
            f"drake-skill's models package {MODELS_PACKAGE} ({root}) is not a folder with "
            "package.xml; reinstall drake-skill from its wheel or with `pip install -e .`")
    return root


def model_path(filename: str) -> Path:
    """The path of a file in the models folder (``pcae.safetensors``, ``meshes/...``)."""
    return models_dir() / filename
