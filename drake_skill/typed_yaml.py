"""One way to load and check a configuration: ``yaml_load_typed`` and one error format.

Every configuration of drake-skill is a dataclass loaded from YAML by Drake's
``yaml_load_typed`` (:func:`load_typed`) and checked by its ``validate``,
which raises through :func:`bad`. Both raise ``ValueError`` with one line:

    <what> (<file or YAML>): field '<a.b>': unknown key '<k>'; valid keys: ...; did you mean '<x>'?
    <what> (<file or YAML>): field '<a.b>' = <value>: expected <type>  (a value of the wrong type)
    <what> (<file or YAML>): <Drake's message>                   (other parse errors)
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
    configuration ("scenario"), ``expected`` says what would work."""
    raise ValueError(f"{what} field '{field}' = {value!r}: expected {expected}")


def load_typed(schema, *, what: str, path: str | Path | None = None, data: str | None = None, defaults=None,
               where: str | None = None):
    """``yaml_load_typed`` of a file (``path``) or a YAML string (``data``) into ``schema``.

    Keys left out keep ``defaults`` (else ``schema()``'s). A missing file is a
    FileNotFoundError; YAML that does not parse, an unknown key (a typo) or a
    value of the wrong type is a ValueError naming ``what``, the file and Drake's
    reason (``where`` names a string's source in the message; default "YAML"). The result is
    not validated: call the schema's check after.
    """
    import yaml
    from pydrake.common.yaml import yaml_load_typed

    if (path is None) == (data is None):
        raise ValueError("give exactly one of path= or data=")
    if path is not None:
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"{what} {path}: no such file")
    where = str(path) if path is not None else (where or "YAML")
    try:
        return yaml_load_typed(schema=schema, filename=None if path is None else str(path), data=data,
                               defaults=defaults if defaults is not None else schema())
    except (RuntimeError, ValueError, TypeError, AssertionError, KeyError, AttributeError, IndexError,
            UnicodeDecodeError, yaml.YAMLError) as e:   # Drake's YAML reader asserts on some shapes (a bare '-')
        text = path.read_text(errors="replace") if path is not None else data
        found = _diagnose(schema, text)
        reason = " ".join(str(e).split()) or f"{type(e).__name__}: the YAML does not have the schema's shape"
        raise ValueError(f"{what} ({where}): {found or reason}") from None


# ------------------------------------------------------------------ diagnosis
# Drake's messages name neither the field of a wrong type ("invalid literal for int()")
# nor the keys that would be valid ("The fields ['x'] were unknown to the schema"). After
# yaml_load_typed fails, the YAML is walked against the schema's fields to say which.


def _plain_loader():
    """A safe YAML loader that reads Drake's tags (!Rpy, !Uniform, ...) as plain nodes."""
    import yaml

    class Loader(yaml.SafeLoader):
        pass

    def untagged(loader, suffix, node):
        if isinstance(node, yaml.MappingNode):
            return {"__tag__": suffix, **loader.construct_mapping(node, deep=True)}
        if isinstance(node, yaml.SequenceNode):
            return loader.construct_sequence(node, deep=True)
        return loader.construct_scalar(node)

    Loader.add_multi_constructor("!", untagged)
    return Loader


def _fields(schema) -> dict | None:
    """{name: type} of a dataclass or a Drake config struct (``__fields__``); None for other types."""
    import dataclasses as dc
    import typing

    if dc.is_dataclass(schema):
        try:
            hints = typing.get_type_hints(schema)
        except Exception:   # an annotation that does not resolve: names only
            hints = {}
        return {f.name: hints.get(f.name) for f in dc.fields(schema)}
    if isinstance(getattr(schema, "__fields__", None), (list, tuple)):
        return {f.name: getattr(f, "type", None) for f in schema.__fields__}
    return None


def _unknown_key(field: str, key: str, valid, kind=None) -> str:
    import difflib

    near = difflib.get_close_matches(key, list(valid), n=1)
    deeper = None if near or kind is None else _where_key_lives(kind, key, field)
    return (f"field '{field or '(top level)'}': unknown key '{key}'; valid keys: {', '.join(valid) or '(none)'}"
            + (f"; did you mean '{near[0]}'?" if near else "")
            + (f"; '{key}' is a key of {deeper}" if deeper else ""))


def _union_options(kind) -> list | None:
    """The types of ``typing.Union[...]`` (``Optional``'s None left out), or None for another type."""
    import typing

    if typing.get_origin(kind) is not typing.Union:
        return None
    return [a for a in typing.get_args(kind) if a is not type(None)]


def _where_key_lives(kind, key: str, field: str, depth: int = 3) -> str | None:
    """Where below ``kind`` a field named ``key`` is (``'driver' (!PandaLcmDriver)``), for a key
    written one level too high (a configuration's field that moved into a nested one); None if nowhere."""
    fields = _fields(kind)
    if fields is None or depth == 0:
        return None
    for name, sub in fields.items():
        path = f"{field}.{name}" if field else name
        options = _union_options(sub) or [sub]
        for option in options:
            inner = _fields(option)
            if inner is None:
                continue
            tag = f" (!{option.__name__})" if len(options) > 1 else ""
            if key in inner:
                return f"'{path}'{tag}"
            found = _where_key_lives(option, key, path, depth - 1)
            if found:
                return found
    return None


_SCALARS = {int: "an integer", float: "a number", str: "a string", bool: "true or false"}


def _wrong_scalar(kind, value) -> bool:
    if kind is bool:
        return not isinstance(value, bool)
    if kind is int:
        return isinstance(value, bool) or not isinstance(value, int)
    if kind is float:
        return isinstance(value, bool) or not isinstance(value, (int, float))
    return not isinstance(value, str)


def _check(kind, value, field: str) -> str | None:
    """The first problem of ``value`` (parsed YAML) against type ``kind``, or None."""
    import typing

    if kind is None or value is None:
        return None
    origin, args = typing.get_origin(kind), typing.get_args(kind)
    if origin is typing.Union:
        options = _union_options(kind)
        if len(options) == 1:
            return _check(options[0], value, field)
        return _check_variant(options, value, field)
    if origin in (list, tuple) and isinstance(value, list) and args:
        for i, item in enumerate(value):
            found = _check(args[0], item, f"{field}[{i}]")
            if found:
                return found
        return None
    if origin is dict and isinstance(value, dict) and len(args) == 2:
        for key, item in value.items():
            found = _check(args[1], item, f"{field}.{key}")
            if found:
                return found
        return None
    if kind in _SCALARS:
        return f"field '{field}' = {value!r}: expected {_SCALARS[kind]}" if _wrong_scalar(kind, value) else None
    fields = _fields(kind)
    if fields is None or not isinstance(value, dict) or "__tag__" in value:
        return None
    for key, item in value.items():
        if key not in fields:
            return _unknown_key(field, str(key), fields, kind)
        found = _check(fields[key], item, f"{field}.{key}" if field else str(key))
        if found:
            return found
    return None


def _check_variant(options, value, field: str) -> str | None:
    """The first problem of ``value`` against a union of config types, chosen by its YAML tag
    (``!Name``) as Drake chooses: an untagged value is the first option. None for unions of
    other types (scalars), which Drake's own message describes."""
    if not all(_fields(o) is not None for o in options) or not isinstance(value, dict):
        return None
    names = {o.__name__: o for o in options}
    tag = value.get("__tag__")
    if tag is not None and tag not in names:
        return (f"field '{field}': unknown type '!{tag}'; valid types: "
                + ", ".join(f"!{n}" for n in names))
    chosen = names[tag] if tag is not None else options[0]
    found = _check(chosen, {k: v for k, v in value.items() if k != "__tag__"}, field)
    if found and tag is None:
        found += (f" (an untagged '{field}' is a !{chosen.__name__}; for another type write its tag, "
                  + " or ".join(f"'{field}: !{n} {{...}}'" for n in list(names)[1:]) + ")")
    return found


def _diagnose(schema, text: str | None) -> str | None:
    """Which field of YAML ``text`` does not fit ``schema`` (an unknown key or a wrong type), or None."""
    import yaml

    try:
        value = yaml.load(text or "", Loader=_plain_loader())
    except yaml.YAMLError:
        return None
    if not isinstance(value, dict):
        return None
    return _check(schema, value, "")
