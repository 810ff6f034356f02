"""The points of a sweep: `--factors` times every `--vary KEY=V1,V2,...`, validated up front.

A point is one study of the base scenario with a few fields changed: the amplitude factor
(`motion.amplitude_factor`) and any other dotted scenario key (`fill.count`, `contacts.0.friction`)
or continuum option (`lagrangian.dx`).  The points are the Cartesian product of the value lists,
each one a folder DIR/points/<name> whose name shows its values
(`amplitude_factor=0.5,fill.count=400`) and stays the same from run to run, so that a rerun finds
its finished points.

Everything is checked here, before a worker starts: every point's scenario is loaded with its
overrides and every continuum option made, so that a bad key or value is one line naming it.
"""
from __future__ import annotations

import hashlib
import itertools
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from vibroflow.errors import InputError
from vibroflow.scenario.io import load_scenario
from vibroflow.scenario.checks import require_tub_mode
from vibroflow.study.methods import METHODS, method
from vibroflow.study.pipeline import split_settings
from vibroflow.study.stages import Study, stages_of

FACTOR_KEY = "motion.amplitude_factor"
#: the folder-name label of the amplitude factor (the other keys keep their dotted names)
FACTOR_LABEL = "amplitude_factor"
_SAFE = re.compile(r"[A-Za-z0-9._+-]+")
_MAX_NAME = 180  # characters; file systems allow 255 bytes per name


@dataclass(frozen=True)
class Point:
    """One point of the sweep.

    name: its folder name under DIR/points; values: varied key -> value (the amplitude factor
    under FACTOR_KEY); scenario: the validated scenario as JSON data (what the worker runs);
    settings: continuum method -> options (`--set lagrangian.dx=...` fixed or varied);
    overrides: the `--set` items that make it from the base scenario (for the record)."""

    name: str
    values: dict[str, Any]
    scenario: dict[str, Any]
    settings: dict[str, dict[str, Any]]
    overrides: tuple[str, ...]


@dataclass
class SweepPlan:
    """The validated sweep: its points, the varied keys in order (FACTOR_KEY first) and the
    base that every point shares (the scenario with the varied keys taken out, the fixed
    continuum options and the shear-cell flag): a rerun into the same folder must have the
    same base."""

    points: list[Point]
    varied: list[str]
    base: dict[str, Any]
    source: str
    shear_cell: bool = False
    estimate_s: float = 0.0  # rough cost of one point (s), for the first "time left"
    fixed: list[str] = field(default_factory=list)


def parse_scalar(key: str, text: str) -> Any:
    """A --vary value as TOML reads it (number, true/false, quoted string), else the bare text
    as a string (as `--set` does); arrays and tables are not point values."""
    text = text.strip()
    if not text:
        raise InputError(f"--vary {key}: an empty value; give KEY=V1,V2,...")
    try:
        value = tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text
    if isinstance(value, (list, dict)):
        raise InputError(f"--vary {key} = {text}: must be a scalar (a number, true/false or a "
                         "string), not an array or table")
    return value


def parse_factors(text: str) -> list[float]:
    """`0.5,0.75,1` -> [0.5, 0.75, 1.0] (repeats dropped, order kept)."""
    out: list[float] = []
    for item in str(text).split(","):
        try:
            f = float(item.strip())
        except ValueError:
            raise InputError(f"--factors = {text!r}: must be amplitude factors separated by "
                             "commas, e.g. 0.5,0.75,1,1.25,1.5") from None
        if f != f or f in (float("inf"), float("-inf")):
            raise InputError(f"--factors = {text!r}: {item.strip()} is not a finite number")
        if f not in out:
            out.append(f)
    return out


def parse_vary(items: list[str] | None) -> dict[str, list[tuple[str, Any]]]:
    """`--vary KEY=V1,V2,...` items -> key -> [(text, value), ...] (repeats dropped)."""
    out: dict[str, list[tuple[str, Any]]] = {}
    for item in items or []:
        key, sep, rest = str(item).partition("=")
        key = key.strip()
        if not sep or not key or not rest.strip() or any(not p for p in key.split(".")):
            raise InputError(f"--vary {item!r}: expected KEY=V1,V2,... with a dotted scenario "
                             "key, e.g. fill.count=300,400")
        if key == FACTOR_KEY:
            raise InputError(f"--vary {key}: the amplitude factor is swept with --factors")
        if key in out:
            raise InputError(f"--vary {key}: given twice; list all its values in one --vary")
        values: list[tuple[str, Any]] = []
        for text in rest.split(","):
            v = parse_scalar(key, text)
            if all(v != w or type(v) is not type(w) for _, w in values):
                values.append((text.strip(), v))
        out[key] = values
    return out


def format_value(value: Any) -> str:
    """A value as it appears in a point's folder name: TOML-like and stable (0.5, 1.0, 400,
    true, steel); other characters become '_' plus a short hash that keeps names distinct."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    text = str(value)
    if _SAFE.fullmatch(text):
        return text
    digest = hashlib.sha256(text.encode()).hexdigest()[:6]
    return re.sub(r"[^A-Za-z0-9._+-]", "_", text)[:40] + "-" + digest


def point_name(values: dict[str, Any]) -> str:
    """`amplitude_factor=0.5,fill.count=400`: the varied values in order."""
    parts = [f"{FACTOR_LABEL if k == FACTOR_KEY else k}={format_value(v)}"
             for k, v in values.items()]
    name = ",".join(parts)
    if len(name) > _MAX_NAME:
        digest = hashlib.sha256(name.encode()).hexdigest()[:12]
        name = name[: _MAX_NAME - 13] + "-" + digest
    return name


def _get(data: Any, dotted: str) -> Any:
    node = data
    for part in dotted.split("."):
        if isinstance(node, list):
            node = node[int(part)]
        else:
            node = node[part]
    return node


def _drop(data: Any, dotted: str) -> None:
    """Set a dotted field of JSON data to None (the varied fields are no part of the base)."""
    *head, last = dotted.split(".")
    node = data
    try:
        for part in head:
            node = node[int(part)] if isinstance(node, list) else node[part]
        if isinstance(node, list):
            node[int(last)] = None
        elif isinstance(node, dict):
            node[last] = None
    except (KeyError, IndexError, ValueError, TypeError):
        pass  # a field the base lacks (an optional table): nothing to take out


def _method_key(key: str) -> bool:
    head, dot, rest = key.partition(".")
    return head in METHODS and bool(dot and rest)


def plan_sweep(source: str, factors: list[float], vary: dict[str, list[tuple[str, Any]]],
               sets: list[str] | None = None, shear_cell: bool = False) -> SweepPlan:
    """Check every point (its scenario and continuum options) and return the plan.

    sets: the fixed `--set` items (scenario fields and continuum options, as `vibroflow run`
    takes them).  Raises InputError (one line naming the key and value) before anything runs.
    """
    sets = list(sets or [])
    if not factors:
        raise InputError("--factors: give at least one amplitude factor")
    fixed_keys = {s.partition("=")[0].strip(): s for s in sets}
    for key in [FACTOR_KEY, *vary]:
        if key in fixed_keys:
            raise InputError(f"--set {fixed_keys[key]}: {key} is varied by the sweep; give it "
                             f"in {'--factors' if key == FACTOR_KEY else '--vary'} only")
    _, base_settings = split_settings(sets)
    # the base alone is not validated: only the points are run, and a base may be valid only
    # with the varied values (4 200 balls in a tub that --vary fill.count=250,300 fills);
    # every point's scenario is, below
    options_cache: dict[str, Any] = {}
    for name in METHODS:  # the fixed options first: their errors name --set
        options_cache[name] = method(name).make_options(base_settings.get(name, {}))

    keys = [FACTOR_KEY, *vary]
    choices = [[(repr(f), f) for f in factors], *vary.values()]
    points: list[Point] = []
    seen: set[str] = set()
    base = None
    for combo in itertools.product(*choices):
        overrides = [f"{k}={text}" for k, (text, _) in zip(keys, combo)]
        scenario_sets, settings = split_settings([*sets, *overrides])
        s = load_scenario(source, scenario_sets)
        require_tub_mode(s, "a sweep", where=str(source))
        if base is None:
            base = s  # the first point stands for the base; its varied keys go below
        data = s.model_dump(mode="json")
        values: dict[str, Any] = {}
        for k, (_, v) in zip(keys, combo):
            if _method_key(k):
                m, _, opt = k.partition(".")
                values[k] = settings[m][opt]
            else:
                try:  # the model's own type: 1 -> 1.0 for a float field
                    values[k] = _get(data, k)
                except (KeyError, IndexError, ValueError, TypeError):
                    values[k] = v
        for name in METHODS:
            method(name).make_options(settings.get(name, {}))
        pname = point_name(values)
        if pname in seen:
            continue
        seen.add(pname)
        points.append(Point(name=pname, values=values, scenario=data, settings=settings,
                            overrides=tuple(overrides)))

    base_data = base.model_dump(mode="json")
    for key in keys:
        if not _method_key(key):
            _drop(base_data, key)
    base_settings_rec = {m: dict(v) for m, v in base_settings.items()}
    for key in keys:
        if _method_key(key):
            m, _, opt = key.partition(".")
            base_settings_rec[m].pop(opt, None)
    plan = SweepPlan(points=points, varied=keys, source=str(source), shear_cell=shear_cell,
                     base={"scenario": base_data, "settings": base_settings_rec,
                           "shear_cell": bool(shear_cell)}, fixed=sets)
    plan.estimate_s = _point_estimate(base, options_cache, shear_cell)
    return plan


def _point_estimate(scenario, options: dict[str, Any], shear_cell: bool) -> float:
    """The stages' own first estimates of one point's cost (s), as `vibroflow run` makes them;
    the stages without one (the continua's first runs) count nothing here."""
    study = Study(out=Path("."), scenario=scenario,
                  methods=[(method(n), o) for n, o in options.items()], shear_cell=shear_cell)
    estimates = (s.estimate(study) for s in stages_of(study))
    return float(sum(e for e in estimates if e is not None))
