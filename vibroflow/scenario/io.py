"""Reading, overriding, writing and hashing scenarios (TOML, SI units).

A scenario comes from a shipped preset (`tub47`, `tub47-quick`) or a user TOML file; keys the
file omits take the tub47 defaults of `vibroflow.scenario.model`.  `--set key=value` overrides
are applied to the raw TOML data before validation, so they are checked like the file itself.
Every input error is raised as `InputError` with one line "FIELD = VALUE: what is allowed".
"""
from __future__ import annotations

import copy
import hashlib
import json
import re
import tomllib
import types
import typing
from collections.abc import Iterable, Mapping
from functools import lru_cache
from importlib import resources
from pathlib import Path
from typing import Any, get_args, get_origin

import tomli_w
from pydantic import BaseModel, ValidationError

from vibroflow.errors import InputError
from vibroflow.scenario.model import Scenario

PRESETS: tuple[str, ...] = ("tub47", "tub47-quick", "tub47-bar")

__all__ = [
    "PRESETS", "load_scenario", "parse_scenario", "apply_overrides", "dump_scenario",
    "scenario_hash", "format_validation_error", "read_preset_text",
]


# ----------------------------------------------------------------------------------------------
# Loading

def read_preset_text(name: str) -> str:
    """TOML text of a shipped preset (with its comments)."""
    if name not in PRESETS:
        raise InputError(f"{name}: no such preset (presets: {', '.join(PRESETS)})")
    return resources.files("vibroflow.scenario").joinpath("presets", f"{name}.toml").read_text(
        encoding="utf-8")


def _parse_toml(text: str, origin: str) -> dict[str, Any]:
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise InputError(f"{origin}: malformed TOML: {e}") from e


def _read_source(source: str | Path) -> tuple[dict[str, Any], str]:
    """Raw TOML data of a preset name or a file, and a name for messages."""
    path = Path(source)
    if path.is_file():
        try:
            text = path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as e:
            raise InputError(f"{path}: cannot read: {e}") from e
        raw = _parse_toml(text, str(path))
        # a user file that does not name its case is not tub47 (which the defaults would say):
        # it is named after the file, made a safe name (model.NAME_PATTERN)
        raw.setdefault("case", _name_of_file(path))
        _resolve_part_files(raw, path.parent)
        return raw, str(path)
    if str(source) in PRESETS:
        return _parse_toml(read_preset_text(str(source)), f"preset {source}"), str(source)
    raise InputError(f"{source}: no such scenario file or preset (presets: "
                     f"{', '.join(PRESETS)})")


def _resolve_part_files(raw: dict[str, Any], base: Path) -> None:
    # an STL part's file is named relative to the scenario file that names it, so a scenario
    # and its meshes travel together; the record keeps the absolute path
    parts = raw.get("parts")
    if isinstance(parts, list):
        for part in parts:
            if isinstance(part, dict) and isinstance(part.get("file"), str):
                f = Path(part["file"]).expanduser()
                part["file"] = str(f if f.is_absolute() else (base / f).resolve())


def _name_of_file(path: Path) -> str:
    name = re.sub(r"[^A-Za-z0-9_.+-]+", "-", path.stem).lstrip("_.+-")[:64]
    return name or "scenario"


def load_scenario(source: str | Path, overrides: Iterable[str] = ()) -> Scenario:
    """The validated scenario of a preset name or TOML file, with `key=value` overrides.

    Raises `InputError` (one line naming the field, the value and what is allowed) on a missing
    file, malformed TOML, a bad override or a value the model rejects.
    """
    raw, _ = _read_source(source)
    return parse_scenario(raw, overrides)


def parse_scenario(raw: Mapping[str, Any], overrides: Iterable[str] = ()) -> Scenario:
    """Validate raw TOML data (a dict) with `key=value` overrides into a Scenario."""
    data = apply_overrides(raw, overrides)
    try:
        return Scenario.model_validate(data)
    except ValidationError as e:
        raise InputError(format_validation_error(e)) from e


# ----------------------------------------------------------------------------------------------
# --set key=value

@lru_cache(maxsize=1)
def _defaults_json() -> str:
    return json.dumps(Scenario().model_dump(mode="json", exclude_none=True))


def _defaults() -> dict[str, Any]:
    # a fresh copy each time: callers graft pieces of it into user data
    return json.loads(_defaults_json())


def parse_value(text: str) -> Any:
    """A `--set` value: a TOML value (number, bool, string, array, inline table), else the bare
    text as a string (so `case=my-run` needs no quotes)."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text.strip()


@typing.overload
def apply_overrides(base: Scenario, overrides: Iterable[str]) -> Scenario: ...
@typing.overload
def apply_overrides(base: Mapping[str, Any], overrides: Iterable[str]) -> dict[str, Any]: ...


def apply_overrides(base, overrides):
    """Apply `dotted.key=value` overrides to raw scenario data (returns a new dict) or to a
    Scenario (returns a new, validated Scenario).

    Dotted keys go through tables by name and arrays by index (`contacts.0.friction=0.3`).  A
    table the data lacks is taken from the tub47 defaults first, so `--set
    materials.steel.density=8000` changes one number rather than replacing every material.  An
    unknown key is left for validation to reject by name.
    """
    if isinstance(base, Scenario):
        return parse_scenario(base.model_dump(mode="json", exclude_none=True), overrides)
    data = copy.deepcopy(dict(base))
    for item in overrides:
        key, sep, text = str(item).partition("=")
        key = key.strip()
        parts = key.split(".")
        if not sep or not key or any(not p.strip() for p in parts):
            raise InputError(f"--set {item}: expected KEY=VALUE with a dotted key, e.g. "
                             f"run.duration=0.2")
        parts = [p.strip() for p in parts]
        _set_path(data, parts, parse_value(text))
    return data


def _set_path(data: dict[str, Any], parts: list[str], value: Any) -> None:
    node: Any = data
    default: Any = _defaults()
    for depth, part in enumerate(parts):
        here = ".".join(parts[: depth + 1])
        last = depth == len(parts) - 1
        if isinstance(node, dict):
            if last:
                node[part] = value
                return
            if part not in node or node[part] is None:
                graft = default.get(part) if isinstance(default, dict) else None
                node[part] = copy.deepcopy(graft) if graft is not None else {}
            node = node[part]
            default = default.get(part) if isinstance(default, dict) else None
        elif isinstance(node, list):
            parent = ".".join(parts[:depth])
            try:
                index = int(part)
            except ValueError:
                raise InputError(f"{here}: {parent} is an array; use an index 0..{len(node) - 1}"
                                 ) from None
            if not 0 <= index < len(node):
                raise InputError(f"{here}: no such entry ({parent} has {len(node)}, indices "
                                 f"0..{len(node) - 1})")
            if last:
                node[index] = value
                return
            node = node[index]
            default = (default[index] if isinstance(default, list) and index < len(default)
                       else None)
        else:
            parent = ".".join(parts[:depth])
            raise InputError(f"{here}: {parent} = {_fmt(node)} is a value, not a table")


# ----------------------------------------------------------------------------------------------
# Writing and hashing

_HEADER = "# vibroflow scenario (SI units: m, s, kg, Pa, rad, Hz)\n"


# an array of scalars that tomli_w spread over several lines (one item a line, indented)
_SPREAD_ARRAY = re.compile(r"\[\n((?:[ \t]+[^\[\]{}\n]+,\n)+)\]")


def _inline_arrays(text: str) -> str:
    # `position = [0.0, 0.0, 0.01]` reads better than five lines, and [[particles]] stay short
    return _SPREAD_ARRAY.sub(
        lambda m: "[" + ", ".join(line.strip()[:-1] for line in m.group(1).splitlines()) + "]",
        text)


def dump_scenario(s: Scenario) -> str:
    """TOML text of a scenario that loads back to an equal Scenario (fields that are None, such
    as the tub in explicit mode, are left out: loading restores them)."""
    return _HEADER + _inline_arrays(tomli_w.dumps(s.model_dump(mode="json", exclude_none=True)))


def _get_path(data: Any, dotted: str) -> Any:
    node = data
    for part in dotted.split("."):
        if isinstance(node, list):
            node = node[int(part)]
        elif isinstance(node, dict) and part in node:
            node = node[part]
        else:
            raise KeyError(f"scenario_hash: no field {dotted!r}")
    return node


def scenario_hash(s: Scenario, fields: Iterable[str] | None = None) -> str:
    """sha256 (hex) of the canonical JSON of a scenario, or of some of its fields only.

    `fields` are top-level or dotted names (`"fill"`, `"run.seed"`); hashing only what a
    result depends on (e.g. the settled fill) lets a cache survive changes elsewhere.
    """
    data = s.model_dump(mode="json")
    if fields is not None:
        data = {f: _get_path(data, f) for f in sorted(set(fields))}
    text = json.dumps(data, sort_keys=True, separators=(",", ":"), ensure_ascii=True,
                      allow_nan=False)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


# ----------------------------------------------------------------------------------------------
# pydantic errors as one line "FIELD = VALUE: what is allowed"

def _fmt(value: Any, limit: int = 80) -> str:
    """A value as TOML would show it, cut to `limit` characters."""
    if isinstance(value, bool):
        text = "true" if value else "false"
    elif isinstance(value, (int, float)):
        text = repr(value)
    elif isinstance(value, str):
        text = json.dumps(value)
    elif isinstance(value, (list, tuple)):
        text = "[" + ", ".join(_fmt(v, limit) for v in value) + "]"
    elif isinstance(value, Mapping):
        text = "{" + ", ".join(f"{k} = {_fmt(v, limit)}" for k, v in value.items()) + "}"
    elif value is None:
        text = "(none)"
    else:
        text = str(value)
    text = " ".join(text.split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _unwrap(ann: Any) -> Any:
    """X from `X | None` / `Optional[X]`."""
    if get_origin(ann) in (typing.Union, types.UnionType):
        args = [a for a in get_args(ann) if a is not type(None)]
        if len(args) == 1:
            return args[0]
    return ann


def _resolve(loc: tuple) -> tuple[Any, Any]:
    """(annotation, FieldInfo or None) of the scenario field at a pydantic error location."""
    ann: Any = Scenario
    info = None
    for part in loc:
        ann = _unwrap(ann)
        origin = get_origin(ann)
        if isinstance(ann, type) and issubclass(ann, BaseModel):
            if not isinstance(part, str) or part not in ann.model_fields:
                return None, None
            info = ann.model_fields[part]
            ann = info.annotation
        elif origin in (list, dict):
            ann, info = get_args(ann)[-1], None
        elif origin is tuple:
            args = get_args(ann)
            if len(args) == 2 and args[1] is Ellipsis:
                ann = args[0]
            elif isinstance(part, int) and part < len(args):
                ann = args[part]
            else:
                return None, None
            info = None
        else:
            return None, None
    return _unwrap(ann), info


def _bounds_words(info: Any) -> str | None:
    """'> 0', '>= 0' or 'in (0, 1]' from a field's numeric constraints."""
    if info is None:
        return None
    lo = hi = None
    for m in info.metadata:
        for attr, side in (("gt", "lo"), ("ge", "lo"), ("lt", "hi"), ("le", "hi")):
            v = getattr(m, attr, None)
            if v is not None:
                if side == "lo":
                    lo = (attr, v)
                else:
                    hi = (attr, v)
    if lo and hi:
        return (f"in {'(' if lo[0] == 'gt' else '['}{lo[1]:g}, {hi[1]:g}"
                f"{')' if hi[0] == 'lt' else ']'}")
    sym = {"gt": ">", "ge": ">=", "lt": "<", "le": "<="}
    if lo or hi:
        kind, v = lo or hi
        return f"{sym[kind]} {v:g}"
    return None


_TYPE_WORDS = {
    "float_type": "must be a number", "float_parsing": "must be a number",
    "finite_number": "must be a finite number",
    "int_type": "must be an integer", "int_parsing": "must be an integer",
    "int_from_float": "must be an integer", "bool_type": "must be true or false",
    "bool_parsing": "must be true or false", "string_type": "must be a string",
    "list_type": "must be an array", "tuple_type": "must be an array",
    "model_type": "must be a table", "model_attributes_type": "must be a table",
    "dict_type": "must be a table",
}

_BOUND_TYPES = {"greater_than": ">", "greater_than_equal": ">=", "less_than": "<",
                "less_than_equal": "<="}


def format_validation_error(err: ValidationError) -> str:
    """One line for the first error of a scenario's validation (see module docstring)."""
    e = err.errors(include_url=False)[0]
    loc = tuple(e.get("loc", ()))
    path = ".".join(str(p) for p in loc)
    kind = e.get("type", "")
    ctx = e.get("ctx") or {}
    value = e.get("input")
    msg = str(e.get("msg", ""))

    if kind == "scenario":  # cross-field checks of the model: already a full line
        return " ".join(str(ctx.get("message", msg)).split())
    if kind == "extra_forbidden":
        parent, _ = _resolve(loc[:-1])
        allowed = ""
        if isinstance(parent, type) and issubclass(parent, BaseModel):
            allowed = f" (allowed: {', '.join(parent.model_fields)})"
        return f"{path}: unknown key{allowed}"
    if kind == "missing":
        parent, _ = _resolve(loc[:-1])
        args = get_args(parent) if get_origin(parent) is tuple else ()
        if args and Ellipsis not in args:  # a short fixed-size array, e.g. a 2-vector for 3
            head = ".".join(str(p) for p in loc[:-1])
            return f"{head} = {_fmt(value)}: must have {len(args)} items"
        return f"{path}: required but missing"

    ann, info = _resolve(loc)
    if kind in _BOUND_TYPES:
        words = _bounds_words(info)
        if words is None:
            bound = next(iter(ctx.values()), "?")
            words = f"{_BOUND_TYPES[kind]} {bound}"
        words = f"must be {words}"
    elif kind in _TYPE_WORDS:
        words = _TYPE_WORDS[kind]
    elif kind == "literal_error":
        words = f"must be one of {ctx.get('expected', '?')}"
    elif kind in ("too_short", "too_long"):
        args = get_args(ann) if get_origin(ann) is tuple else ()
        n = len(args) if args and Ellipsis not in args else None
        words = (f"must have {n} items" if n else
                 f"must have {ctx.get('min_length', 0)} to {ctx.get('max_length', '...')} items")
    elif kind in ("value_error", "assertion_error"):
        words = msg.split(", ", 1)[1] if msg.startswith(("Value error, ", "Assertion failed, "))\
            else msg
        if isinstance(value, Mapping):  # a whole table's check: the message names its keys
            model, _ = _resolve(loc)
            first = words.split(" ", 1)[0]
            if (path and isinstance(model, type) and issubclass(model, BaseModel)
                    and first in model.model_fields):
                return " ".join(f"{path}.{words}".split())  # "tub.rim_height = 0.1: ..."
            return " ".join(f"{path}: {words}".split()) if path else words
    else:
        words = msg[:1].lower() + msg[1:]
    line = f"{path} = {_fmt(value)}: {words}" if path else f"{_fmt(value)}: {words}"
    return " ".join(line.split())
