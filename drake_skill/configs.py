"""One way to load and check a configuration: ``yaml_load_typed`` and one error format.

Every configuration of drake-skill is a dataclass loaded from YAML by Drake's
``yaml_load_typed`` (:func:`load_typed`) and checked by its ``validate``,
which raises through :func:`bad`. Both raise ``ValueError`` with one line:

    <what> (<file or YAML>): <Drake's message>                   (parse errors, unknown keys)
    <what> field '<field>' = <value>: expected <what would work>   (values that cannot work)

The import of pydrake happens inside :func:`load_typed`, so the Drake-free
modules that validate with :func:`bad` stay Drake-free (tests/test_layout.py).
"""

from __future__ import annotations

from pathlib import Path
from typing import NoReturn

__all__ = ["bad", "load_typed"]


def bad(what: str, field: str, value, expected: str) -> NoReturn:
    """Raises the one-line ValueError of a field that cannot work: ``what`` names the
    configuration ("station config"), ``expected`` says what would work."""
    raise ValueError(f"{what} field '{field}' = {value!r}: expected {expected}")


def load_typed(schema, *, what: str, path: str | Path | None = None, data: str | None = None, defaults=None):
    """``yaml_load_typed`` of a file (``path``) or a YAML string (``data``) into ``schema``.

    Keys left out keep ``defaults`` (else ``schema()``'s). A missing file is a
    FileNotFoundError; YAML that does not parse, an unknown key (a typo) or a
    value of the wrong type is a ValueError naming ``what``, the file and Drake's
    reason. The result is not validated: call the schema's check after.
    """
    import yaml
    from pydrake.common.yaml import yaml_load_typed

    if (path is None) == (data is None):
        raise ValueError("give exactly one of path= or data=")
    if path is not None:
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"{what} {path}: no such file")
    where = str(path) if path is not None else "YAML"
    try:
        return yaml_load_typed(schema=schema, filename=None if path is None else str(path), data=data,
                               defaults=defaults if defaults is not None else schema())
    except (RuntimeError, yaml.YAMLError) as e:
        raise ValueError(f"{what} ({where}): {' '.join(str(e).split())}") from None
