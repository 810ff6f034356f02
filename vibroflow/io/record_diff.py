"""The first field that differs between two records of a run (a scenario, its calibration and
options as nested tables): what a refused resume names, so that the user sees which setting
changed, not only that one did."""
from __future__ import annotations

from collections.abc import Iterator


def _flatten(value, prefix: str = "") -> Iterator[tuple[str, object]]:
    if isinstance(value, dict):
        for k in value:
            yield from _flatten(value[k], f"{prefix}.{k}" if prefix else str(k))
    elif isinstance(value, list) and any(isinstance(v, (dict, list)) for v in value):
        for k, v in enumerate(value):
            yield from _flatten(v, f"{prefix}.{k}")
        yield f"{prefix}.__len__", len(value)
    else:
        yield prefix, value


def first_difference(there: dict | None, now: dict) -> str:
    """"KEY = A there, B now" for the first field that differs between two scenario records
    (in the scenario's own order), or a plain remark when the record there is unknown."""
    if there is None:
        return "it records no scenario"
    a, b = dict(_flatten(there)), dict(_flatten(now))
    for key in [*b, *(k for k in a if k not in b)]:
        if a.get(key, "(none)") != b.get(key, "(none)"):
            name = key.replace(".__len__", " (count)")
            return f"{name} = {a.get(key, '(none)')} there, {b.get(key, '(none)')} now"
    return "another vibroflow's fingerprint"
