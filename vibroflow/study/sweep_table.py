"""The sweep's table: one row per point and method, read from the points' own summary.json.

Columns (SI units): the varied values; method; status (done, failed, running, pending) and the
error of a failed point; per probe P: P_vx, P_vx_stderr, P_vz, P_vz_stderr (m/s, tub frame);
circulation sense, strength and its standard error (m^2/s); mean normal impact speeds ball-ball
and ball-wall with their standard errors (m/s; a continuum's inferred speed: its run's error
and its calibrated relation's, measure.contacts.mean_speed_stderr); the method's wall time (s); for
a continuum method its field difference E against the DEM and whether the circulations agree
(tub47.md "Judging a comparison").  A point that has no summary has one row with an empty
method.
"""
from __future__ import annotations

import csv
import io
import json
import math
from pathlib import Path
from typing import Any

from rich.table import Table

from vibroflow.io.atomic import write_text_atomic
from vibroflow.measure.contacts import mean_speed_stderr
from vibroflow.rounding import plus_minus
from vibroflow.study.sweep_folder import point_dir, point_state
from vibroflow.study.sweep_points import FACTOR_KEY

IMPACT_KINDS = ("ball_ball", "ball_wall")


def _num(x: Any) -> float | None:
    try:
        v = float(x)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


def point_rows(out: Path, name: str, values: dict[str, Any]) -> list[dict[str, Any]]:
    """The rows of one point (status from its folder; numbers from its summary.json)."""
    status, error = point_state(out, name)
    head = {"point": name, **values}
    summary = None
    if status == "done":
        try:
            summary = json.loads((point_dir(out, name) / "summary.json").read_text())
            methods = summary["methods"]
        except (OSError, ValueError, KeyError, TypeError):
            status, error, summary = "failed", "unreadable summary.json", None
    if summary is None:
        return [{**head, "method": "", "status": status, "error": error or ""}]
    rows = []
    for method, m in methods.items():
        row: dict[str, Any] = {**head, "method": method, "status": status, "error": ""}
        for p, v in m.get("probes", {}).items():
            for c in ("vx", "vz"):
                row[f"{p}_{c}"] = _num(v.get(c))
                row[f"{p}_{c}_stderr"] = _num(v.get(f"{c}_stderr"))
        c = m.get("circulation", {})
        row["circulation_sense"] = c.get("sense")
        row["circulation_strength"] = _num(c.get("strength"))
        row["circulation_strength_stderr"] = _num(c.get("strength_stderr"))
        im = m.get("impacts", {})
        for kind in IMPACT_KINDS:
            row[f"impact_{kind}"] = _num(im.get(f"{kind}_mean_normal_speed"))
            row[f"impact_{kind}_stderr"] = _num(mean_speed_stderr(im, kind))
        row["wall_time_s"] = _num(m.get("wall_time_s"))
        a = m.get("against_dem")
        row["E_against_dem"] = _num(a.get("field_difference_E")) if a else None
        row["E_against_dem_stderr"] = _num(a.get("field_difference_E_stderr")) if a else None
        row["circulation_agrees"] = a.get("circulation_agrees") if a else None
        rows.append(row)
    return rows


def sweep_rows(out: Path, points: dict[str, dict], varied: list[str]) -> list[dict[str, Any]]:
    """Every point's rows, sorted by the varied values (amplitude factor first)."""
    def key(item):
        vals = item[1].get("values", {})
        return tuple((0, v, "") if isinstance(v, (int, float)) and not isinstance(v, bool)
                     else (1, 0, str(v)) for v in (vals.get(k) for k in varied))

    rows: list[dict[str, Any]] = []
    for name, p in sorted(points.items(), key=key):
        rows += point_rows(out, name, {k: p.get("values", {}).get(k) for k in varied})
    return rows


def columns(rows: list[dict[str, Any]], varied: list[str]) -> list[str]:
    first = ["point", *varied, "method", "status", "error"]
    rest: list[str] = []
    for r in rows:
        for k in r:
            if k not in first and k not in rest:
                rest.append(k)
    return first + rest


def _cell(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(v)
    return str(v)


def write_csv_atomic(path: Path, rows: list[dict[str, Any]], varied: list[str]) -> None:
    """sweep.csv (a reader sees the old table or the whole new one, never a part)."""
    buf = io.StringIO()
    cols = columns(rows, varied)
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    for r in rows:
        w.writerow([_cell(r.get(c)) for c in cols])
    write_text_atomic(path, buf.getvalue())


def _pm(v, e, scale: float = 1.0, fmt: str = ".3g") -> str:
    if v is None:
        return "-"
    return format(v * scale, fmt) if e is None else plus_minus(v * scale, e * scale, fmt)


def rich_table(rows: list[dict[str, Any]], varied: list[str]):
    """The table for the terminal: values, method, status, circulation, E, impacts, wall time
    (the probes are in sweep.csv)."""
    t = Table(title="vibroflow sweep", show_lines=False)
    for k in varied:
        t.add_column("factor" if k == FACTOR_KEY else k, justify="right")
    t.add_column("method", no_wrap=True, min_width=10)
    t.add_column("status")
    t.add_column("circulation (1e-4 m²/s)", justify="right")
    t.add_column("E vs DEM", justify="right")
    t.add_column("impacts b-b / b-w (m/s)", justify="right")
    t.add_column("wall (s)", justify="right")
    for r in rows:
        if r["status"] != "done":
            t.add_row(*[_cell(r.get(k)) for k in varied], r["method"] or "-",
                      r["status"] + (f": {r['error']}" if r.get("error") else ""),
                      "", "", "", "")
            continue
        sense = {"clockwise": " cw", "counterclockwise": " ccw"}.get(r["circulation_sense"], "")
        E = r.get("E_against_dem")
        bb, bw = r.get("impact_ball_ball"), r.get("impact_ball_wall")
        t.add_row(*[_cell(r.get(k)) for k in varied], r["method"], r["status"],
                  _pm(r["circulation_strength"], r["circulation_strength_stderr"], 1e4) + sense,
                  "" if E is None else _pm(E, r.get("E_against_dem_stderr"), fmt=".3f"),
                  f"{_pm(bb, r.get('impact_ball_ball_stderr'))} / "
                  f"{_pm(bw, r.get('impact_ball_wall_stderr'))}",
                  "" if r["wall_time_s"] is None else f"{r['wall_time_s']:.3g}")
    return t
