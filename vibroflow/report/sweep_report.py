"""The sweep report: DIR/report.html of a sweep folder (`vibroflow sweep --out DIR`, also
`vibroflow report DIR`), one self-contained page (inline CSS, images as data URIs, no script)
showing against the amplitude factor, for the DEM and each continuum, the circulation strength
with its standard error, its sense and the field difference E against the DEM beside its
limit (vibroflow.report.sweep_data), with one table row per point and method: a point that did
not finish is a row with its status and reason, and a red cross in every figure.

A sweep that varies run.seed shows its rows pooled over the seeds (vibroflow.report.sweep_pool):
one row per amplitude factor and method with its number of seeds, the strength and E as means
over the seeds with their standard errors; a seed's point that did not finish keeps its own row.

The table fits the page: a fixed layout over the page's width, short headers with their units
on a line of their own, and long words (keys, errors) wrapped anywhere.  Every number cell
carries its full value in `data-value` (the text shows it rounded), like the study report's.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from markupsafe import Markup

from vibroflow import __version__
from vibroflow.io.atomic import write_text_atomic
from vibroflow.report.html import data_uri, environment
from vibroflow.report.page_style import page_css
from vibroflow.report.sweep_data import SweepData, created, describe, point_report
from vibroflow.report.verdict import ELimit
from vibroflow.report.verdict import verdict as e_verdict
from vibroflow.report.sweep_figures import (e_figure, sense_figure, sense_offsets,
                                            strength_figure, table_plots)
from vibroflow.rounding import plus_minus
from vibroflow.study.sweep_folder import TABLE_FILE
from vibroflow.study.sweep_points import FACTOR_KEY

REPORT_NAME = "report.html"
TEMPLATE = "sweep_report.html.j2"

#: section id -> heading, in page order (tests check the headings)
SECTIONS = {
    "strength": "Circulation strength",
    "sense": "Circulation sense",
    "E": "Field difference E against the DEM",
    "table": "Every point",
    "unfinished": "Points that did not finish",
    "plots": "Probes, impacts and cost",
}

CSS = page_css(1200) + """
.meta { color: #555; overflow-wrap: anywhere; }
table.sweep { border-collapse: collapse; margin: 0.6em 0; font-size: 0.82em; width: 100%;
              table-layout: fixed; }
table.sweep th, table.sweep td { border: 1px solid #ccc; padding: 0.2em 0.35em;
              text-align: right; overflow-wrap: anywhere; word-break: break-word;
              vertical-align: top; }
table.sweep th { background: #f2f2f2; font-weight: 600; }
table.sweep th .u { display: block; font-weight: normal; color: #555; font-size: 0.9em; }
table.sweep td.l, table.sweep th.l { text-align: left; }
table.sweep td.why { text-align: left; color: #b42318; }
tr.unfinished td { background: #fdf1f0; }
"""

#: the table's columns after the varied values: (heading, unit line, share of the width)
COLUMNS = (
    ("method", "", 9),
    ("status", "", 6),
    ("sense", "", 12),
    ("strength", "(1e-4 m²/s)", 10),
    ("E vs DEM", "(-)", 6),
    ("E / limit", "(-)", 6),
    ("verdict", "", 22),
    ("impact b-b / b-w", "(m/s)", 12),
    ("wall time", "(s)", 6),
)
#: the share of the width of a varied value's column
VARIED_SHARE = 7
#: the column a sweep over run.seed adds after the varied values: the seeds pooled in a row
SEEDS_COLUMN = ("seeds", "(n)", 5)


@dataclass(frozen=True)
class Cell:
    """One table cell: its text, class, and for a number its full value (data-value)."""
    text: str
    cls: str = ""
    value: str | None = None
    span: int = 1


def _num(x, fmt: str = ".3g", scale: float = 1.0, se=None) -> Cell:
    if x is None:
        return Cell("n/a", value="nan")
    text = format(x * scale, fmt) if se is None else plus_minus(x * scale, se * scale, fmt)
    return Cell(text, value=repr(float(x)))


def _header(key: str) -> tuple[str, str]:
    """A varied key's heading and unit line: the amplitude factor short, others by name (the
    CSS wraps a long one anywhere)."""
    if key == FACTOR_KEY:
        return "factor", "(-)"
    return key, ""


def verdict(row: dict[str, Any], lim: ELimit | None) -> tuple[str, str]:
    """(words, class) for a continuum's row: E against the limit in the study page's words
    (vibroflow.report.verdict.verdict), then the circulation."""
    if row["method"] == "dem":
        return "the reference", ""
    E = row.get("E_against_dem")
    agrees = row.get("circulation_agrees")
    circ = {True: "circulation agrees", False: "circulation differs"}.get(agrees, "")
    if E is None:
        return ("E not computed" + (f"; {circ}" if circ else "")), "note"
    words, cls = e_verdict(E, lim.limit if lim is not None else None)
    if not cls:
        return words + (f"; {circ}" if circ else ""), "note"
    ok = cls == "ok" and agrees is not False
    return words + (f"; {circ}" if circ else ""), "ok" if ok else "bad"


def _strength(r: dict[str, Any]) -> Cell:
    """The strength cell (1e-4 m^2/s): over seeds, the mean +- the error drawn, then the
    seed-to-seed and the combined batch-means errors apart."""
    cell = _num(r.get("circulation_strength"), ".3g", 1e4, r.get("circulation_strength_stderr"))
    if r.get("n_seeds", 1) < 2 or r.get("circulation_strength") is None:
        return cell
    parts = [f"{name} ± {format(e * 1e4, '.2g')}" for name, e in
             (("seeds", r.get("circulation_strength_stderr_seeds")),
              ("batch", r.get("circulation_strength_stderr_batch"))) if e is not None]
    return Cell(f"{cell.text} ({', '.join(parts)})", value=cell.value)


def _impacts(r: dict[str, Any]) -> Cell:
    """Ball-ball / ball-wall mean normal impact speeds (m/s), each ± its standard error."""
    text = " / ".join(plus_minus(r[k], r.get(k + "_stderr"), ".3f") if r.get(k) is not None
                      else "n/a" for k in ("impact_ball_ball", "impact_ball_wall"))
    v = r.get("impact_ball_ball")
    return Cell(text, value="nan" if v is None else repr(float(v)))


def _wall_time(t) -> Cell:
    """A wall time (s) to three significant figures (whole seconds from 1000 s on)."""
    if t is None:
        return Cell("n/a", value="nan")
    decimals = max(0, 2 - math.floor(math.log10(abs(t)))) if t else 0
    return Cell(f"{t:.{decimals}f}", value=repr(float(t)))


def _E(r: dict[str, Any]) -> Cell:
    if r["method"] == "dem":
        return Cell("-")
    return _num(r.get("E_against_dem"), ".3f", se=r.get("E_against_dem_stderr"))


def _seeds(r: dict[str, Any]) -> Cell:
    """The number of seeds in a pooled row (its seeds in the title); '1' for an unfinished
    seed's own row."""
    if r["status"] != "done":
        return Cell("1", value="1")
    return Cell(str(r["n_seeds"]), value=str(r["n_seeds"]))


def table_rows(data: SweepData) -> list[dict[str, Any]]:
    """The table's rows: cells, a class, and the point's own report (a relative link); over
    seeds, one row per group and method after data.pooled (an unfinished seed's row names its
    seed in the reason)."""
    out = []
    span = len(COLUMNS) - 2
    for r in data.pooled:
        vals = [_num(r.get(k), ".6g") if isinstance(r.get(k), (int, float))
                and not isinstance(r.get(k), bool) else Cell(str(r.get(k)), "l")
                for k in data.shown]
        if data.seeds_pooled:
            vals.append(_seeds(r))
        link = point_report(data.out, r["point"])
        if r["status"] != "done":
            why = r.get("error") or {"running": "running now (another process holds it)",
                                     "pending": "not run yet"}.get(r["status"], "")
            if data.seeds_pooled:
                why = f"run.seed = {r.get('run.seed')}: {why}"
            cells = [*vals, Cell(r["method"] or "-", "l"), Cell(r["status"], "l bad"),
                     Cell(why, "why", span=span)]
            out.append({"cells": cells, "cls": "unfinished", "point": r["point"],
                        "status": r["status"], "link": link})
            continue
        lim = data.limit_of(r)
        E = r.get("E_against_dem")
        words, vcls = verdict(r, lim)
        cells = [*vals, Cell(r["method"], "l"), Cell(r["status"], "l"),
                 Cell(str(r.get("circulation_sense") or "n/a"), "l"),
                 _strength(r), _E(r),
                 (_num(E / lim.limit, ".2f") if E is not None and lim is not None
                  else Cell("-" if r["method"] == "dem" else "n/a")),
                 Cell(words, f"l {vcls}".strip()),
                 _impacts(r), _wall_time(r.get("wall_time_s"))]
        out.append({"cells": cells, "cls": "", "point": r["point"], "status": "done",
                    "link": link})
    return out


def _img(payload: bytes) -> Markup:
    return Markup(data_uri(payload, "image/png"))


def limits_text(data: SweepData) -> list[tuple[str, float | None]]:
    """(line, limit or None) per group of points (varied values without run.seed): its limit,
    the floor it is 1.5 x and where that comes from, or why it has none."""
    lines = []
    keys = sorted({*data.limits, *data.no_limit}, key=_order)
    for key in keys:
        at = ", ".join(f"{k} = {v:g}" if isinstance(v, float) else f"{k} = {v}"
                       for k, v in zip(data.shown, key))
        lim = data.limits.get(key)
        if lim is None:
            lines.append((f"No limit on E at {at}: {data.no_limit[key]}.", None))
            continue
        se = "" if lim.stderr is None else f" ± {lim.stderr:.3f}"
        caveat = f"; {lim.caveat}" if lim.caveat else ""
        lines.append((f"Fields agree at {at} when E ≤ {lim.limit:.3f}: 1.5 × the DEM's "
                      f"seed-to-seed E {lim.e_seed:.3f}{se} ({lim.source}{caveat}).",
                      lim.limit))
    return lines


def _order(key: tuple) -> tuple:
    return tuple((0, v, "") if isinstance(v, (int, float)) and not isinstance(v, bool)
                 else (1, 0, str(v)) for v in key)


def point_links(data: SweepData) -> list[tuple[str, str]]:
    """(point, its report) for every finished point that has one, in the table's order."""
    seen: dict[str, str] = {}
    for r in data.rows:
        link = point_report(data.out, r["point"]) if r["status"] == "done" else None
        if link and r["point"] not in seen:
            seen[r["point"]] = link
    return list(seen.items())


def render(data: SweepData) -> str:
    """The page's HTML text."""
    plots = [{"name": name, "src": _img(png)} for name, png in table_plots(data).items()]
    head = ([(*_header(k), VARIED_SHARE) for k in data.shown]
            + ([SEEDS_COLUMN] if data.seeds_pooled else [])
            + [(t, u, w) for t, u, w in COLUMNS])
    total = sum(w for _, _, w in head)
    head = [(t, u, f"{100.0 * w / total:.1f}%") for t, u, w in head]
    counts: dict[str, int] = {}  # status -> points
    for status in {r["point"]: r["status"] for r in data.rows}.values():
        counts[status] = counts.get(status, 0) + 1
    return environment().get_template(TEMPLATE).render(
        css=Markup(CSS), sections=SECTIONS, folder=str(data.out), version=__version__,
        written=time.strftime("%Y-%m-%d %H:%M:%S %z"), updated=created(data.record),
        describe=describe(data.record), counts=sorted(counts.items()),
        strength=_img(strength_figure(data)), sense=_img(sense_figure(data)),
        E=_img(e_figure(data)), limits=limits_text(data),
        head=head, n_varied=len(head) - len(COLUMNS), rows=table_rows(data),
        links=point_links(data), pooled=data.seeds_pooled,
        sense_shifts=sorted(sense_offsets(data).items(), key=lambda kv: kv[1]),
        csv=(data.out / TABLE_FILE).is_file(),
        unfinished=[r for r in data.rows if r["status"] != "done"], plots=plots)


def write_sweep_report(sweep_dir) -> Path:
    """Write DIR/report.html for the sweep in sweep_dir (atomically) and return its path; a
    folder that holds no sweep is an InputError (one line) and nothing is written."""
    data = SweepData.read(sweep_dir)
    return write_text_atomic(Path(sweep_dir) / REPORT_NAME, render(data))
