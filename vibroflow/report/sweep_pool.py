"""A sweep's rows pooled over fill seeds: when a sweep varies `run.seed`, the finished rows of
one method at one value of the other varied keys (the amplitude factor, ...) become one row,
the mean over its seeds with standard errors:

- circulation strength: the mean over the n seeds; its seed-to-seed standard error
  s / sqrt(n) (s the sample standard deviation, n >= 2), and the runs' batch-means errors
  combined, sqrt(sum se_i^2) / n (the error of the mean if the seeds gave one flow).  The error
  the report draws is the larger of the two: with two or three seeds s can fall below the runs'
  own noise by chance, and the mean is not known better than its runs are;
- E against the DEM: the mean over seeds of each seed's continuum against that seed's DEM,
  with the larger of its seed-to-seed standard error s / sqrt(n) and its runs' errors over
  their batches combined (E_against_dem_stderr), as the strength's;
- the sense: the seeds' common sense, or "mixed" with the count of each; `sense_mean` the mean
  of +1 (counterclockwise), 0, -1 (clockwise) over the seeds;
- impact speeds: the mean over the seeds with the larger of the two errors, as the strength's;
- wall time: the mean over the seeds.

A row that did not finish stays as it is (one per point), so that each failed seed is seen.
"""
from __future__ import annotations

import math
from collections import defaultdict
from typing import Any

SEED_KEY = "run.seed"
#: y of each circulation sense (tub frame, x right, z up)
SENSES = {"counterclockwise": 1.0, "none": 0.0, "clockwise": -1.0}
_SHORT = {"counterclockwise": "ccw", "clockwise": "cw", "none": "none"}
_IMPACTS = ("impact_ball_ball", "impact_ball_wall")


def mean_stderr(values: list[float]) -> tuple[float | None, float | None]:
    """(mean, s / sqrt(n)) of the values; the error is None below two values, both None for
    none."""
    n = len(values)
    if n == 0:
        return None, None
    mean = math.fsum(values) / n
    if n < 2:
        return mean, None
    var = math.fsum((v - mean) ** 2 for v in values) / (n - 1)
    return mean, math.sqrt(var / n)


def combined_batch_stderr(errors: list[float | None]) -> float | None:
    """sqrt(sum se_i^2) / n: the standard error of a mean of n runs from their own errors;
    None when any run has none."""
    if not errors or any(e is None for e in errors):
        return None
    return math.sqrt(math.fsum(e * e for e in errors)) / len(errors)


def _sense(senses: list[str | None]) -> str | None:
    known = [s for s in senses if s is not None]
    if not known:
        return None
    if len(set(known)) == 1 and len(known) == len(senses):
        return known[0]
    counts = ", ".join(f"{known.count(s)} {_SHORT.get(s, s)}" for s in sorted(set(known)))
    return f"mixed ({counts})"


def _agrees(values: list[bool | None]) -> bool | None:
    if any(v is False for v in values):
        return False
    return True if values and all(v is True for v in values) else None


def pool_group(rows: list[dict[str, Any]], keep: dict[str, Any]) -> dict[str, Any]:
    """One pooled row from the finished rows of one method at one group (`keep`: the row's
    varied values without the seed, its method)."""
    s_mean, s_seeds, s_batch = _pooled(rows, "circulation_strength")
    shown = [e for e in (s_seeds, s_batch) if e is not None]
    E_mean, E_seeds, E_batch = _pooled(rows, "E_against_dem")
    E_shown = [e for e in (E_seeds, E_batch) if e is not None]
    E_se = max(E_shown) if E_shown else None
    senses = [r.get("circulation_sense") for r in rows]
    known = [SENSES[s] for s in senses if s in SENSES]
    row = {**keep, "status": "done", "error": "", "n_seeds": len(rows),
           "seeds": sorted((r.get(SEED_KEY) for r in rows), key=str),
           "points": [r["point"] for r in rows], "point": rows[0]["point"],
           "circulation_sense": _sense(senses),
           "sense_mean": math.fsum(known) / len(known) if known else None,
           "circulation_strength": s_mean,
           "circulation_strength_stderr": max(shown) if shown else None,
           "circulation_strength_stderr_seeds": s_seeds,
           "circulation_strength_stderr_batch": s_batch,
           "E_against_dem": E_mean, "E_against_dem_stderr": E_se,
           "n_E": sum(r.get("E_against_dem") is not None for r in rows),
           "circulation_agrees": _agrees([r.get("circulation_agrees") for r in rows])}
    for k in _IMPACTS:
        mean, se_seeds, se_batch = _pooled(rows, k)
        errors = [e for e in (se_seeds, se_batch) if e is not None]
        row[k], row[k + "_stderr"] = mean, max(errors) if errors else None
    row["wall_time_s"] = mean_stderr([r["wall_time_s"] for r in rows
                                      if r.get("wall_time_s") is not None])[0]
    return row


def _pooled(rows: list[dict[str, Any]], key: str) -> tuple[float | None, ...]:
    """(mean over the seeds, seed-to-seed error, the runs' batch-means errors combined) of a
    column with its `_stderr` column."""
    have = [r for r in rows if r.get(key) is not None]
    mean, se_seeds = mean_stderr([r[key] for r in have])
    return mean, se_seeds, combined_batch_stderr([r.get(key + "_stderr") for r in have])


def pool_seeds(rows: list[dict[str, Any]], varied: list[str]) -> list[dict[str, Any]]:
    """The rows pooled over run.seed (see the module's docstring), in the rows' order: each
    group at its first finished row, each unfinished row where it stands.  Without run.seed
    among the varied keys, the rows as they are, each with n_seeds 1."""
    if SEED_KEY not in varied:
        return [{**r, "n_seeds": 1} if r["status"] == "done" else r for r in rows]
    others = [k for k in varied if k != SEED_KEY]
    groups: dict[tuple, list[dict[str, Any]]] = defaultdict(list)
    order: list[tuple | dict] = []
    for r in rows:
        if r["status"] != "done":
            order.append(r)
            continue
        key = (*(r.get(k) for k in others), r["method"])
        if key not in groups:
            order.append(key)
        groups[key].append(r)
    out = []
    for item in order:
        if isinstance(item, dict):
            out.append(item)
        else:
            keep = {**dict(zip(others, item[:-1])), "method": item[-1]}
            out.append(pool_group(groups[item], keep))
    return out
