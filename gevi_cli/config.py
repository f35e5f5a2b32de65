"""The run configuration's schema machinery: typed, range-checked settings (pydantic v2 dataclasses).

A configuration is a tree of pydantic dataclasses, one per stage (``gevi_cli/frontend/config.py``,
``gevi_cli/pipelines/config.py``).  Each setting is declared once with :func:`setting`: its type, its
default (the product), its valid domain and a one-line help; a stage lists its ordered pairs
(``ORDERED``, e.g. ``triangulation.min_depth_m < triangulation.max_depth_m``) and, where it applies to one method or one kind of
input only, its :class:`Applies`.  The pipelines read plain attributes (``cfg.pnp.method``).

Layers (defaults, a per-kind YAML, ``--config``, ``--set``, each option) only *override* keys: every
layer is checked completely when it is applied (:func:`build`) - unknown keys (with the nearest valid
name), types, domains, ordered pairs and what does not apply - and a problem is one line naming the
layer (file, option), the key, the value and the rule.
"""
from __future__ import annotations

import dataclasses
import difflib
import functools
import math
import typing
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Callable

import annotated_types as at
from pydantic import AfterValidator, BeforeValidator, Field, Strict, TypeAdapter, ValidationError
from pydantic_core import PydanticCustomError

from gevi_cli.errors import GeviError

#: the input kinds whose front end is the export's own (no image front end)
TRACK_KINDS = ("ov2slam-tracks",)


def _number(value):
    """A finite-or-infinite real number from YAML: bool is not a number; '1e-6' (YAML 1.1 reads it as a
    string) and 'inf' are; NaN is never a setting."""
    if isinstance(value, bool):
        raise PydanticCustomError("number", "expected a number")
    if isinstance(value, str):
        try:
            value = float(value)
        except ValueError:
            raise PydanticCustomError("number", "expected a number") from None
    if isinstance(value, (int, float)):
        if math.isnan(value):
            raise PydanticCustomError("number", "expected a number")
        return float(value)
    raise PydanticCustomError("number", "expected a number")


def _odd(value: int) -> int:
    if value % 2 != 1:
        raise PydanticCustomError("odd", "expected an odd integer")
    return value


Int = Annotated[int, Strict()]
OddInt = Annotated[int, Strict(), AfterValidator(_odd)]
Float = Annotated[float, BeforeValidator(_number)]
Bool = Annotated[bool, Strict()]


def setting(default, help: str, *, ge=None, gt=None, le=None, lt=None, inf: bool = False, applies=None):
    """A setting: ``default``, a one-line ``help`` and its domain (``ge``/``gt``/``le``/``lt``; ``inf``:
    +inf is a value, e.g. an unbounded depth).  ``applies``: an :class:`Applies` narrower than its stage's."""
    extra = {"applies": applies} if applies is not None else None
    kw = {k: v for k, v in (("ge", ge), ("gt", gt), ("le", le), ("lt", lt)) if v is not None}
    if isinstance(default, float) or default is None or inf or type(default) is int:
        kw["allow_inf_nan"] = inf
    return Field(default, description=help, json_schema_extra=extra, **kw)


def stage(default_factory, help: str = ""):
    """A nested stage of a configuration."""
    return Field(default_factory=default_factory, description=help)


@dataclass(frozen=True)
class Applies:
    """Where a setting does something: ``methods`` (None: every method), ``inputs`` ("images": not for a
    track export, "tracks": only for one; None: both), ``values`` (method -> the values it can run),
    ``requires`` (another setting's values under which it is read at all), and why, for the error that
    refuses it elsewhere."""

    methods: tuple | None = None
    inputs: str | None = None
    values: dict | None = None
    requires: tuple | None = None  # (dotted key, the values of it under which this setting is read)
    why: str = ""


def ordered(self):
    """Check the stage's ``ORDERED`` pairs ``(low, high, strict)`` after its fields: ``low < high``
    (``strict``) or ``low <= high``.  Use as ``_order = model_validator(mode="after")(ordered)``."""
    for lo, hi, strict in getattr(self, "ORDERED", ()):
        a, b = getattr(self, lo), getattr(self, hi)
        if not (a < b if strict else a <= b):
            raise PydanticCustomError("crossed", "{lo}={a} must be {op} {hi} ({b})",
                                      {"lo": lo, "hi": hi, "a": show(a), "b": show(b),
                                       "op": "below" if strict else "at most"})
    return self


# --- reading the schema ---------------------------------------------------------------------------------------

def fields(cls) -> dict:
    """name -> pydantic FieldInfo of a stage (declaration order)."""
    return dict(cls.__pydantic_fields__)


def is_stage(info) -> bool:
    return dataclasses.is_dataclass(info.annotation) if isinstance(info.annotation, type) else False


def _base_type(info):
    """(the setting's type without Optional and Annotated, whether it may be null)."""
    ann, optional = info.annotation, False
    if typing.get_origin(ann) is typing.Union:
        ann, optional = [a for a in typing.get_args(ann) if a is not type(None)][0], True
    if typing.get_origin(ann) is Annotated:
        ann = typing.get_args(ann)[0]
    return ann, optional


def choices(info) -> tuple | None:
    ann, _ = _base_type(info)
    return typing.get_args(ann) if typing.get_origin(ann) is typing.Literal else None


def type_name(info) -> str:
    ann, optional = _base_type(info)
    odd = any(isinstance(m, AfterValidator) and m.func is _odd for m in info.metadata)
    c = choices(info)
    name = ("choice" if c is not None else "odd int" if odd else
            {int: "int", float: "float", bool: "bool", str: "str"}.get(ann, str(ann)))
    return name + (" or null" if optional else "")


def show(v) -> str:
    """A setting's value as it is written in YAML and ``--set`` (true, false, null, numbers, words)."""
    if v is True or v is False:
        return str(v).lower()
    return "null" if v is None else str(v)


def _num(v) -> str:
    return "inf" if v == math.inf else f"{v:g}"


def domain(cls, name: str) -> str:
    """The valid values of a setting as text: ``{a, b}``, ``true/false``, ``(0, max_px)``, ``[1, inf)``."""
    info = fields(cls)[name]
    c = choices(info)
    if c is not None:
        return "{" + ", ".join(map(str, c)) + "}"
    ann, _ = _base_type(info)
    if ann is bool:
        return "true/false"
    lo, hi, lo_open, hi_open = "-inf", "inf", True, True
    allow_inf = True
    for m in info.metadata:
        if isinstance(m, at.Ge):
            lo, lo_open = _num(m.ge), False
        elif isinstance(m, at.Gt):
            lo, lo_open = _num(m.gt), True
        elif isinstance(m, at.Le):
            hi, hi_open = _num(m.le), False
        elif isinstance(m, at.Lt):
            hi, hi_open = _num(m.lt), True
    for m in info.metadata:
        # pydantic carries allow_inf_nan in a metadata object whose class changed across 2.x releases
        if getattr(m, "allow_inf_nan", True) is False:
            allow_inf = False
    for a, b, strict in getattr(cls, "ORDERED", ()):
        if name == a:
            hi, hi_open = b, strict
        elif name == b:
            lo, lo_open = a, strict
    if hi == "inf" and allow_inf and ann is float:
        hi_open = False
    return f"{'(' if lo_open else '['}{lo}, {hi}{')' if hi_open else ']'}"


def applies(cls, name: str) -> list[Applies]:
    """Where the setting does something: its stage's :class:`Applies` (``APPLIES``), then its own; both hold
    ([]: everywhere)."""
    extra = fields(cls)[name].json_schema_extra or {}
    return [r for r in (getattr(cls, "APPLIES", None), extra.get("applies")) if r is not None]


def leaves(cfg_cls, prefix: str = "") -> list[tuple[str, type, str]]:
    """(dotted key, stage class, name) of every setting."""
    out = []
    for name, info in fields(cfg_cls).items():
        if is_stage(info):
            out += leaves(info.annotation, f"{prefix}{name}.")
        else:
            out.append((f"{prefix}{name}", cfg_cls, name))
    return out


def get(cfg, key: str):
    for part in key.split("."):
        cfg = getattr(cfg, part)
    return cfg


# --- layers ---------------------------------------------------------------------------------------------------

def _check_keys(cls, data, where: str, prefix: str = "") -> None:
    """Unknown keys and non-mappings where a stage is expected, before the values are checked."""
    if not isinstance(data, dict):
        raise GeviError(where, f"{prefix.rstrip('.') or 'the configuration'}: expected a mapping of "
                               f"{cls.__name__} keys, got {type(data).__name__} {data!r}")
    known = fields(cls)
    for key, value in data.items():
        if key not in known:
            close = difflib.get_close_matches(str(key), list(known), n=1)
            hint = f"did you mean {prefix}{close[0]}?" if close else f"known: {', '.join(known)}"
            raise GeviError(where, f"unknown key {prefix}{key}; {hint}")
        if is_stage(known[key]):
            _check_keys(known[key].annotation, value, where, f"{prefix}{key}.")


def merge(base: dict, data: dict) -> dict:
    """``base`` with the nested mapping ``data`` laid over it (new dicts)."""
    out = dict(base)
    for k, v in data.items():
        out[k] = merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


@functools.lru_cache(maxsize=None)
def _adapter(cls) -> TypeAdapter:
    return TypeAdapter(cls)


def _message(cls, err: dict) -> str:
    """One line for pydantic's first error: the key, the value and the rule."""
    loc = [str(p) for p in err["loc"]]
    owner = cls
    for p in loc[:-1] if err["type"] != "crossed" else loc:
        owner = fields(owner)[p].annotation
    if err["type"] == "crossed":
        ctx = err["ctx"]
        pre = ".".join(loc) + "." if loc else ""
        return f"{pre}{ctx['lo']}={ctx['a']} must be {ctx['op']} {pre}{ctx['hi']} ({ctx['b']})"
    key, name = ".".join(loc), loc[-1]
    info = fields(owner)[name]
    value = show(err.get("input"))
    c = choices(info)
    if c is not None:
        return f"{key}={value}: not one of {', '.join(map(str, c))}"
    if _base_type(info)[0] is bool:
        return f"{key}={value}: expected true or false"
    return f"{key}={value}: expected {type_name(info)} in {domain(owner, name)}"


def validate(cls, data: dict, where: str):
    """``data`` (nested mapping of overrides) as a checked ``cls``; one-line GeviError at ``where``."""
    _check_keys(cls, data, where)
    try:
        return _adapter(cls).validate_python(data)
    except ValidationError as exc:
        raise GeviError(where, _message(cls, exc.errors()[0])) from None


def refuse_inapplicable(cfg, default, method: str | None, kind: str | None, where: str, flag: bool = False,
                        own=None) -> None:
    """A setting that does nothing for ``method`` or for input ``kind`` must keep its ``default``
    value (the configuration of ``default``, before any user layer); else one line at ``where``
    ("does not apply to cfo", "does not apply to ov2slam-tracks sequences").  ``flag``: ``where`` is
    the option that set it, so the key is not repeated.  A setting another one turns off (``requires``)
    must keep the value of ``own`` (gevi's own configuration for the input, its kind's file included;
    default: ``default``)."""
    own = default if own is None else own
    for key, cls, name in leaves(type(cfg)):
        value = get(cfg, key)
        pre = "" if flag else f"{key}={show(value)}: "
        for rule in applies(cls, name):
            if rule.values and method in rule.values and value not in rule.values[method]:
                raise GeviError(where, f"{pre}does not apply to {method} ({rule.why})")
            if rule.requires is not None and value != get(own, key):
                other, values = rule.requires
                if get(cfg, other) not in values:
                    raise GeviError(where, f"{key}={show(value)} does nothing with {other}={show(get(cfg, other))} "
                                           f"({rule.why})")
            if value == get(default, key):
                continue
            if method is not None and rule.methods is not None and method not in rule.methods:
                raise GeviError(where, f"{pre}does not apply to {method} ({rule.why})")
            if kind is not None and rule.inputs is not None and (kind in TRACK_KINDS) != (rule.inputs == "tracks"):
                raise GeviError(where, f"{pre}does not apply to {kind} sequences ({rule.why})")


def build(cls, layers: typing.Iterable[tuple[str, dict, bool]], check: Callable[[Any, str, bool], None] | None = None):
    """``cls`` with each layer ``(where, overrides, is_flag)`` applied in order; each layer is checked as
    it is applied (``check(cfg, where, is_flag)`` after the schema's own checks)."""
    merged: dict = {}
    cfg = cls()
    for where, data, is_flag in layers:
        _check_keys(cls, data, where)
        merged = merge(merged, data)
        cfg = validate(cls, merged, where)
        if check is not None:
            check(cfg, where, is_flag)
    return cfg


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


def describe(cfg) -> list[tuple[str, object, str, object, str, str]]:
    """(dotted key, effective value, type, default, domain, help) of every setting (``--dump-config``)."""
    out = []
    for key, cls, name in leaves(type(cfg)):
        info = fields(cls)[name]
        where = "; ".join(x for rule in applies(cls, name)
                          for x in (rule.methods and "/".join(rule.methods) + " only", rule.inputs and f"{rule.inputs} only",
                                    rule.requires and f"with {rule.requires[0]}={'/'.join(map(show, rule.requires[1]))}")
                          if x)
        help_text = info.description or ""
        out.append((key, get(cfg, key), type_name(info), info.default, domain(cls, name),
                    (f"[{where}] " if where else "") + help_text))
    return out
