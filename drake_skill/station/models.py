"""The Drake package map for drake-skill's model files.

The models folder is the installed package ``drake_skill.models``
(``drake_skill.resources.models_dir``, found with ``importlib.resources``).
For Drake it is the package ``drake_skill_models``, so SDF files are
addressed as ``package://drake_skill_models/<file>``. ``DRAKE_SKILL_MODELS``
overrides the folder.
"""

from __future__ import annotations

from drake_skill.resources import model_path, models_dir

__all__ = ["PACKAGE_NAME", "add_package_paths", "model_path", "model_url", "models_dir"]

PACKAGE_NAME = "drake_skill_models"
"""The Drake (package.xml) package name of the models folder."""


def model_url(filename: str) -> str:
    return f"package://{PACKAGE_NAME}/{filename}"


def add_package_paths(package_map) -> None:
    """Registers ``drake_skill_models`` in a Drake PackageMap (idempotent)."""
    if not package_map.Contains(PACKAGE_NAME):
        package_map.Add(PACKAGE_NAME, str(models_dir()))
