"""Checks of a user's inputs, run before any expensive work, raising the user errors that
``drake_skill.cli.main`` prints as one line (exit status 2). The commands
(``drake_skill.cli.errors``) and the library's workflows share them.

Each raises ``FileNotFoundError``, ``NotADirectoryError``, ``FileExistsError``
or ``ValueError`` with a message that names the option, the path and the fix.
No heavy imports here.
"""

from __future__ import annotations

from pathlib import Path


def input_folder(path: Path, option: str, what: str) -> Path:
    """``path`` must be an existing folder."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{option} {path}: no such folder; give the folder of {what}")
    if not path.is_dir():
        raise NotADirectoryError(f"{option} {path}: is a file, not a folder; give the folder of {what}")
    return path


def input_file(path: Path, option: str, what: str) -> Path:
    """``path`` must be an existing regular file."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{option} {path}: no such file; give {what}")
    if not path.is_file():
        raise ValueError(f"{option} {path}: is not a regular file; give {what}")
    return path


def output_folder(path: Path, option: str, *, occupied: bool = False, force: bool = False,
                  what: str = "its contents") -> Path:
    """``path`` must be a folder or creatable as one (its parent writable).

    ``occupied``: the folder already holds what the command would write; an
    error unless ``force``.
    """
    import os

    path = Path(path)
    if path.exists() and not path.is_dir():
        raise NotADirectoryError(f"{option} {path}: exists and is a file; choose a folder path for {what}")
    parent = next((p for p in [path, *path.parents] if p.exists()), Path("."))
    if not parent.is_dir():
        raise NotADirectoryError(f"{option} {path}: {parent} is a file, so the folder cannot be created")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise PermissionError(f"{option} {path}: {parent} is not writable; choose another folder")
    if occupied and not force:
        raise FileExistsError(f"{option} {path}: already holds {what}; pass --force to replace it "
                              "or choose another folder")
    return path


def load_yaml(schema, path: Path, option: str, defaults=None):
    """A dataclass ``schema`` from YAML file ``path`` (keys left out keep ``defaults``).

    Bad YAML or an unknown key is a ValueError naming the file and the key.
    """
    from drake_skill.typed_yaml import load_typed

    path = input_file(path, option, f"a YAML file of {schema.__name__} fields")
    return load_typed(schema, what=option, path=path, defaults=defaults)


def skill(value, option: str = "--skill"):
    """The SkillSpec of a shipped skill's name or a skill file's path (errors as one line)."""
    from drake_skill.skills import load_skill

    try:
        return load_skill(value)
    except FileNotFoundError as e:
        raise FileNotFoundError(f"{option}: {e}") from None
    except ValueError as e:
        raise ValueError(f"{option}: {e}") from None


def scenario(base, path: Path | None = None, texts=(), option: str = "--scenario"):
    """The scenario a command runs, layered once (``station.config.load_scenario``): ``base`` (a
    skill's name, spec or file: its shipped scenario; or a Scenario), then the user's ``--scenario``
    file ``path``, then the YAML ``texts`` in order (``--scenario-text``, and the command's flags
    written as YAML). Every problem is one line naming the option, the file or text, and the field."""
    import yaml

    from drake_skill.station.scenario import Scenario, load_scenario
    from drake_skill.skills import scenario_for_skill

    defaults = base if isinstance(base, Scenario) else scenario_for_skill(base)
    if path is not None:
        input_file(path, option, "a station scenario YAML file (see drake_skill/station/scenarios/)")
    try:
        return load_scenario(path, overrides=list(texts), defaults=defaults)
    except (ValueError, yaml.YAMLError) as e:
        label = f"{option} {path}" if path is not None else "--scenario-text"
        raise ValueError(f"{label}: {' '.join(str(e).split())}") from e

