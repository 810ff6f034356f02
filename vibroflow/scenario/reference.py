"""The scenario reference, generated from the records of `vibroflow.scenario.model`.

    from vibroflow.scenario.reference import scenario_reference_markdown
    print(scenario_reference_markdown())

One Markdown table per TOML table of a scenario: each key with its TOML type, its default (the
value of the reference case tub47, `Scenario()`), the values allowed (the field's bounds, a
string's choices) and its unit and meaning (the field's `description`).  docs/user-guide.md
holds this text between its scenario-reference markers, and tests/test_docs.py checks that it
is the text the model gives, so the guide cannot drift from the code.

A pure function of the model: the same code gives the same text, byte for byte.
"""
from __future__ import annotations

import inspect
import math
import types
import typing
from typing import Any, Literal, get_args, get_origin

from pydantic import BaseModel

from vibroflow.scenario.model import (
    Analysis,
    ContactPair,
    Fill,
    Material,
    Motion,
    ParticleSpec,
    Probe,
    Run,
    Scenario,
    Tub,
    PartSpec,
    WallSpec,
)

__all__ = ["TABLES", "scenario_reference_markdown"]

#: the TOML tables in the order the reference lists them: (heading, record, what it is)
TABLES: tuple[tuple[str, type[BaseModel], str], ...] = (
    ("top level", Scenario, "The keys outside any table, and the tables of a scenario."),
    ("[materials.NAME]", Material, "One table per material, keyed by its name."),
    ("[[contacts]]", ContactPair, "One entry per pair of materials that can touch."),
    ("[run]", Run, "Time stepping, averaging and output of a run."),
    ("[fill]", Fill, "The balls filled into the tub (tub mode; absent in explicit mode)."),
    ("[tub]", Tub, "The U tub (tub mode; absent in explicit mode)."),
    ("[motion]", Motion, "The tub's rigid vibration in its x-z plane."),
    ("[analysis]", Analysis, "The cells and probes every method's results are measured on."),
    ("[analysis.probes.NAME]", Probe, "One probe point per name, in the tub frame."),
    ("[[particles]]", ParticleSpec, "Explicit mode: one entry per ball, placed as given."),
    ("[[walls]]", WallSpec, "Explicit mode: infinite plane walls."),
    ("[[parts]]", PartSpec, "Rigid parts in the bed (a workpiece, a fixture, a sensor), in "
     "either mode: a cylinder across the slice, a box, a sphere or an STL surface, fixed in the "
     "tub frame or in the lab; what each receives is recorded."),
)

# Units and meanings of the fields whose records carry no `description`: the model's own
# description, where it has one, always wins.
_NOTES: dict[tuple[str, str], str] = {
    ("Scenario", "case"): "the case's name; it reaches file names, the LIGGGHTS deck and the "
                          "report",
    ("Scenario", "gravity"): "m/s^2, lab frame (x across, y along the length, z up)",
    ("Scenario", "materials"): "the materials, by name",
    ("Scenario", "contacts"): "the contact laws; a table given replaces tub47's whole list",
    ("Scenario", "run"): "time stepping and averaging",
    ("Scenario", "fill"): "the fill; absent in explicit mode",
    ("Scenario", "tub"): "the tub; absent in explicit mode",
    ("Scenario", "motion"): "the tub's vibration",
    ("Scenario", "analysis"): "cells and probes",
    ("Scenario", "particles"): "explicit mode's balls; given, there is no tub and no fill",
    ("Scenario", "walls"): "explicit mode's plane walls",
    ("Scenario", "parts"): "rigid parts in the bed",
    ("PartSpec", "name"): "a name (file names, the report)",
    ("PartSpec", "material"): "a key of [materials]; each ball material needs a contact law "
                              "with it",
    ("ContactPair", "pair"): "the two materials' names; their order does not matter",
    ("ContactPair", "model"): "normal force law: linear spring-dashpot or Hertz-Mindlin",
    ("Run", "record_impacts"): "record every impact (time, kind, normal speed, place)",
    ("Fill", "material"): "the balls' material (a key of [materials])",
    ("Tub", "wall_material"): "the tub wall's lining (a key of [materials])",
    ("Tub", "partition_material"): "the partitions' material (a key of [materials])",
    ("Motion", "phase_x"): "rad",
    ("Motion", "phase_z"): "rad",
    ("Motion", "phase_theta"): "rad",
    ("Analysis", "probes"): "probe points by name",
    ("Probe", "x"): "m, tub frame, across",
    ("Probe", "z"): "m, tub frame, up from the tub's lowest point",
    ("ParticleSpec", "position"): "m, lab frame",
    ("ParticleSpec", "velocity"): "m/s",
    ("ParticleSpec", "angular_velocity"): "rad/s",
    ("ParticleSpec", "material"): "a key of [materials]",
    ("WallSpec", "point"): "m, a point of the plane",
    ("WallSpec", "normal"): "unit normal towards the balls (normalised on reading)",
    ("WallSpec", "material"): "a key of [materials]",
    ("WallSpec", "velocity"): "m/s, constant",
    ("WallSpec", "amplitude"): "m, harmonic displacement per axis",
    ("WallSpec", "phase"): "rad",
}

# the record each nested table's heading documents
_TABLE_OF: dict[type[BaseModel], str] = {cls: heading for heading, cls, _ in TABLES}


def _float(v: float) -> str:
    """A float as TOML writes it, short: 7800.0, 0.015, 5e4, 2e11, 1e-5."""
    if not math.isfinite(v):
        return repr(v)
    if v != 0 and (abs(v) >= 1e4 or abs(v) < 1e-3):
        mantissa, exponent = f"{v:.15e}".split("e")
        mantissa = mantissa.rstrip("0").rstrip(".")
        return f"{mantissa}e{int(exponent)}"
    return repr(float(v))


def _value(v: Any) -> str:
    """A value as it is written in TOML."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return _float(v)
    if isinstance(v, str):
        return f'"{v}"'
    if isinstance(v, (tuple, list)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    return str(v)


def _strip_none(annotation: Any) -> tuple[Any, bool]:
    """(the annotation without None, whether None was allowed)."""
    if get_origin(annotation) in (typing.Union, types.UnionType):
        args = [a for a in get_args(annotation) if a is not type(None)]
        if len(args) < len(get_args(annotation)):
            return (args[0] if len(args) == 1 else annotation), True
    return annotation, False


_SCALARS = {bool: "boolean", int: "integer", float: "float", str: "string"}


def _type(annotation: Any) -> str:
    """The TOML type of an annotation, in words."""
    annotation, optional = _strip_none(annotation)
    origin, args = get_origin(annotation), get_args(annotation)
    if annotation in _SCALARS:
        text = _SCALARS[annotation]
    elif origin is Literal:
        text = "string"
    elif origin is tuple and args and Ellipsis not in args and len(set(args)) == 1:
        text = f"array of {len(args)} {_SCALARS.get(args[0], str(args[0]))}s"
    elif origin is list and args and isinstance(args[0], type) and issubclass(args[0],
                                                                              BaseModel):
        text = f"array of tables {_TABLE_OF.get(args[0], args[0].__name__)}"
    elif origin is dict and args and isinstance(args[1], type) and issubclass(args[1],
                                                                              BaseModel):
        text = f"tables {_TABLE_OF.get(args[1], args[1].__name__)}"
    elif isinstance(annotation, type) and issubclass(annotation, BaseModel):
        text = f"table {_TABLE_OF.get(annotation, annotation.__name__)}"
    else:
        text = str(annotation)
    return text + (" (optional)" if optional else "")


def _allowed(field: Any) -> str:
    """The field's bounds and choices, from its metadata and its Literal type."""
    annotation, _ = _strip_none(field.annotation)
    if get_origin(annotation) is Literal:
        return ", ".join(f"`{_value(a)}`" for a in get_args(annotation))
    lo = hi = None
    lo_open = hi_open = False
    for m in field.metadata:
        for attr, side, is_open in (("gt", "lo", True), ("ge", "lo", False),
                                    ("lt", "hi", True), ("le", "hi", False)):
            bound = getattr(m, attr, None)
            if bound is None:
                continue
            if side == "lo":
                lo, lo_open = bound, is_open
            else:
                hi, hi_open = bound, is_open
    if lo is not None and hi is not None:
        return f"{'(' if lo_open else '['}{_value(lo)}, {_value(hi)}{')' if hi_open else ']'}"
    if lo is not None:
        return f"{'>' if lo_open else '>='} {_value(lo)}"
    if hi is not None:
        return f"{'<' if hi_open else '<='} {_value(hi)}"
    return ""


def _cell(text: str) -> str:
    """Text safe in one Markdown table cell."""
    return " ".join(text.split()).replace("|", "\\|")


def _default(cls: type[BaseModel], name: str, instance: BaseModel | None) -> str:
    """tub47's value of a field: the reference instance's where the table has one, else the
    record's own default."""
    field = cls.model_fields[name]
    if instance is not None:
        value = getattr(instance, name)
    elif field.is_required():
        return "required"
    else:
        value = field.get_default(call_default_factory=True)
    if value is None:
        return "absent"
    if isinstance(value, BaseModel):
        return "see its table"
    if isinstance(value, dict):
        return ", ".join(f"`{k}`" for k in value)
    if isinstance(value, list) and value and isinstance(value[0], BaseModel):
        return f"{len(value)} entries, below"
    return f"`{_value(value)}`"


def _rows(cls: type[BaseModel], instance: BaseModel | None) -> list[str]:
    lines = ["| key | type | default (tub47) | allowed | unit, meaning |",
             "|---|---|---|---|---|"]
    for name, field in cls.model_fields.items():
        note = field.description or _NOTES.get((cls.__name__, name), "")
        lines.append(f"| `{name}` | {_cell(_type(field.annotation))} | "
                     f"{_cell(_default(cls, name, instance))} | {_cell(_allowed(field))} | "
                     f"{_cell(note)} |")
    return lines


def _differences(record: BaseModel, skip: tuple[str, ...] = ()) -> str:
    """The fields of `record` that differ from its record's defaults, as key = value."""
    cls = type(record)
    parts = []
    for name, field in cls.model_fields.items():
        if name in skip:
            continue
        value = getattr(record, name)
        default = None if field.is_required() else field.get_default(call_default_factory=True)
        if value != default:
            parts.append(f"{name} = {_value(value)}")
    return ", ".join(parts) if parts else "the defaults above"


def _entries(heading: str, reference: Scenario) -> list[str]:
    """tub47's entries of a table that holds several (materials, contacts, probes)."""
    if heading == "[materials.NAME]":
        items = [f"`{name}`: " + ", ".join(f"{k} = {_value(v)}"
                                           for k, v in m.model_dump().items())
                 for name, m in reference.materials.items()]
        return ["tub47's materials: " + "; ".join(items) + "."]
    if heading == "[[contacts]]":
        items = [f"{_value(list(c.pair))}: {_differences(c, skip=('pair',))}"
                 for c in reference.contacts]
        return ["tub47's contacts (ball-ball, ball-tub wall, ball-partition): "
                + "; ".join(items) + "."]
    if heading == "[analysis.probes.NAME]":
        items = [f"`{name}` ({_value(p.x)}, {_value(p.z)})"
                 for name, p in reference.analysis.probes.items()]
        return ["tub47's probes, (x, z) in m: " + ", ".join(items) + "."]
    return []


def _doc(cls: type[BaseModel]) -> str:
    own = cls.__dict__.get("__doc__")
    return " ".join(inspect.cleandoc(own).split()) if own else ""


def scenario_reference_markdown() -> str:
    """The scenario reference as Markdown: one table per TOML table, keys in the records'
    order, defaults from tub47 (`Scenario()`)."""
    reference = Scenario()
    instances: dict[type[BaseModel], BaseModel | None] = {
        Scenario: reference, Run: reference.run, Fill: reference.fill, Tub: reference.tub,
        Motion: reference.motion, Analysis: reference.analysis,
    }
    out: list[str] = []
    for heading, cls, what in TABLES:
        out.append(f"### {heading if heading == 'top level' else '`' + heading + '`'}")
        out.append("")
        doc = _doc(cls)
        out.append(what + (" " + doc if doc else ""))
        out.append("")
        out.extend(_rows(cls, instances.get(cls)))
        extra = _entries(heading, reference)
        if extra:
            out.append("")
            out.extend(extra)
        out.append("")
    return "\n".join(out).rstrip("\n") + "\n"
