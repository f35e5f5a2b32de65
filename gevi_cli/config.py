"""Typed run configuration: per-stage dataclasses whose defaults are the product.

A configuration is a tree of dataclasses (one per stage).  YAML files (``configs/*.yaml``) and
``--set stage.key=value`` only *override* fields; every field has a default, every key is checked
(an unknown stage or key, or a value of the wrong type, is a one-line error naming the file or
option), and the effective configuration is written to each run folder as ``config.yaml``.
"""
from __future__ import annotations

import dataclasses
import typing
from pathlib import Path

from gevi_cli.errors import GeviError


def _field_types(cls) -> dict[str, type]:
    hints = typing.get_type_hints(cls)
    return {f.name: hints[f.name] for f in dataclasses.fields(cls)}


def _coerce(value, typ, where: str):
    """``value`` as type ``typ`` (bool/int/float/str or Optional of those; dataclass fields are
    handled by :func:`override`)."""
    origin = typing.get_origin(typ)
    if origin in (typing.Union, getattr(__import__("types"), "UnionType", typing.Union)):
        args = [a for a in typing.get_args(typ) if a is not type(None)]
        if value is None:
            return None
        typ = args[0]
    if typ is bool:
        if isinstance(value, bool):
            return value
        raise GeviError(where, f"expected true or false, got {value!r}")
    if typ is int:
        if isinstance(value, int) and not isinstance(value, bool):
            return value
        raise GeviError(where, f"expected an integer, got {value!r}")
    if typ is float:
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return float(value)
        if isinstance(value, str):  # YAML 1.1 reads '1e-6' (no dot) as a string
            try:
                return float(value)
            except ValueError:
                pass
        raise GeviError(where, f"expected a number, got {value!r}")
    if typ is str:
        if isinstance(value, (str, int, float)) and not isinstance(value, bool):
            return str(value)
        raise GeviError(where, f"expected a string, got {value!r}")
    return value


def check_choice(value, choices: tuple, where: str) -> None:
    if value not in choices:
        raise GeviError(where, f"{value!r} is not one of {', '.join(map(str, choices))}")


def override(cfg, data: dict, where: str):
    """A copy of dataclass ``cfg`` with the (nested) mapping ``data`` applied; keys are checked."""
    if not isinstance(data, dict):
        raise GeviError(where, f"expected a mapping of {type(cfg).__name__} keys, got {type(data).__name__}")
    types = _field_types(type(cfg))
    changes = {}
    for key, value in data.items():
        if key not in types:
            raise GeviError(where, f"unknown key {key!r}; known: {', '.join(types)}")
        current = getattr(cfg, key)
        if dataclasses.is_dataclass(current):
            changes[key] = override(current, value, f"{where}: {key}")
        else:
            changes[key] = _coerce(value, types[key], f"{where}: {key}")
    try:
        return dataclasses.replace(cfg, **changes)
    except ValueError as err:  # a stage config's own check (__post_init__) refused the values
        raise GeviError(where, str(err)) from None


def parse_set(items: typing.Iterable[str]) -> dict:
    """``["a.b=1", "c.d=x"]`` -> ``{"a": {"b": 1}, "c": {"d": "x"}}`` with YAML scalars."""
    import yaml

    out: dict = {}
    for item in items:
        if "=" not in item:
            raise GeviError("--set", f"expected stage.key=value, got {item!r}")
        key, text = item.split("=", 1)
        parts = key.strip().split(".")
        if len(parts) < 2 or not all(parts):
            raise GeviError("--set", f"expected stage.key=value, got {item!r}")
        try:
            value = yaml.safe_load(text) if text.strip() else ""
        except yaml.YAMLError:
            value = text
        node = out
        for p in parts[:-1]:
            node = node.setdefault(p, {})
            if not isinstance(node, dict):
                raise GeviError("--set", f"{key}: conflicts with an earlier --set")
        node[parts[-1]] = value
    return out


def load_yaml(path: Path) -> dict:
    """A config mapping of ``stage: {key: value}`` (empty file: ``{}``); errors are one line with file and line."""
    from gevi_cli.datasets.yamlio import load_yaml as read_mapping

    return read_mapping(Path(path), empty_ok=True, what="config file")


def flat_items(cfg, prefix: str = "") -> list[tuple[str, object, str]]:
    """(dotted key, default value, help) for every leaf field (``gevi run --dump-config``)."""
    out = []
    for f in dataclasses.fields(cfg):
        value = getattr(cfg, f.name)
        key = f"{prefix}{f.name}"
        if dataclasses.is_dataclass(value):
            out += flat_items(value, key + ".")
        else:
            out.append((key, value, f.metadata.get("help", "")))
    return out


def opt(default, help: str):
    """A dataclass field with a help text (shown by ``--dump-config``)."""
    return dataclasses.field(default=default, metadata={"help": help})
