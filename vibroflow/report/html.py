"""The report page: one self-contained HTML file (inline CSS, every image a base64 data URI,
no script and no external link), assembled from a study's data (vibroflow.report.data), its
figures (vibroflow.report.figures), the calibration's own pictures (calibration/*.png, drawn
by vibroflow.calibration.plots) and the DEM animation (vibroflow.report.animation).

This module computes what each section shows (numbers, table rows, figure bytes); the page
itself is the jinja2 template templates/report.html.j2, which escapes every value it is given
except the data-URI images (markupsafe.Markup).

Every number in a table cell carries its full value in a `data-value` attribute (the text shows
it rounded), so a reader or a test can take the exact number from the page.
"""
from __future__ import annotations

import base64
import csv
import dataclasses
import json
import math
import time
from functools import lru_cache
from pathlib import Path

import jinja2
from markupsafe import Markup

from vibroflow import __version__
from vibroflow.report import figures
from vibroflow.measure.floor_force import REGIONS, dem_wall_feed, take_off_stderr
from vibroflow.measure.contacts import mean_speed_stderr
from vibroflow.report.data import DEM, REPORT_STAGE, StudyData
from vibroflow.report.impact_figures import impact_distribution_section, inferred_from
from vibroflow.report.engineer import Engineer
from vibroflow.report.page_style import page_css
from vibroflow.report.part_sections import part_sections
from vibroflow.report.stress_section import stress_rows
from vibroflow.report.temperature_maps import temperature_maps
from vibroflow.rounding import plus_minus

#: section id -> heading, in page order (tests check the headings)
SECTIONS = {
    "velocity": "Velocity field",
    "differences": "Velocity difference to the DEM",
    "profiles": "Velocity profiles",
    "probes": "Probes",
    "circulation": "Circulation and agreement with the DEM",
    "bed": "Bed state: acceleration, turnover, kinetic energy",
    "shear": "Shear rate",
    "temperature": "Granular temperature and solid fraction",
    "impacts": "Impact speeds",
    "impact_distributions": "Impact speed distributions",
    "wall": "Wall friction",
    "floor": "The floor over the cycle",
    "rheology": "mu(I) fit",
    "rheology_bins": "mu(I) binned",
    "stress": "Stress by height and phase",
    "animation": "DEM animation",
    "sweep": "Sweep",
    "cost": "Cost",
    "scenario": "Scenario",
}

TEMPLATE = "report.html.j2"

CSS = page_css(1400) + """
.meta { color: #555; }
table { border-collapse: collapse; margin: 0.6em 0; font-size: 0.9em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: right; }
th { background: #f2f2f2; }
td.l, th.l { text-align: left; }
pre { background: #f7f7f7; border: 1px solid #ddd; padding: 0.8em; overflow-x: auto;
      font-size: 0.85em; }
"""


@lru_cache(maxsize=1)
def environment() -> jinja2.Environment:
    """The page's template environment: autoescaping always on, and a misspelt name in the
    template is an error rather than an empty string."""
    return jinja2.Environment(
        loader=jinja2.PackageLoader("vibroflow.report", "templates"),
        autoescape=jinja2.select_autoescape(("html", "j2"), default_for_string=True,
                                            default=True),
        undefined=jinja2.StrictUndefined,
        keep_trailing_newline=True,
    )


@dataclasses.dataclass(frozen=True)
class Cell:
    """One table cell: its text, and for a number the full value (data-value, "nan" when
    missing) and standard error (data-stderr)."""
    text: str
    cls: str = ""
    value: str | None = None
    stderr: str | None = None
    attrs: tuple[tuple[str, str], ...] = ()  # more data-* attributes (name, value)

    def tagged(self, **attrs: str) -> Cell:
        return dataclasses.replace(self, attrs=self.attrs + tuple(
            (k.replace("_", "-"), v) for k, v in attrs.items()))


@dataclasses.dataclass(frozen=True)
class Image:
    alt: str
    src: Markup  # a data URI: base64 text, safe in an attribute as it is


def data_uri(payload: bytes, mime: str) -> str:
    return f"data:{mime};base64," + base64.b64encode(payload).decode("ascii")


def _img(payload: bytes, alt: str, mime: str = "image/png") -> Image:
    return Image(alt=alt, src=Markup(data_uri(payload, mime)))


def _text(text, cls: str = "") -> Cell:
    return Cell(text=str(text), cls=cls)


def _num(x, fmt: str = ".4g", unit: str = "") -> Cell:
    """A table cell of a number (n/a when missing or not finite)."""
    if not isinstance(x, (int, float)) or isinstance(x, bool) or not math.isfinite(x):
        return Cell(text="n/a", value="nan")
    return Cell(text=f"{format(x, fmt)}{unit}", value=repr(float(x)))


def _pm(x, se, fmt: str = ".4g", unit: str = "") -> Cell:
    """A cell 'x ± se' (data-value x, data-stderr se), unit after it."""
    if not isinstance(x, (int, float)) or not math.isfinite(x):
        return Cell(text="n/a", value="nan")
    if isinstance(se, (int, float)) and math.isfinite(se):
        return Cell(text=plus_minus(x, se, fmt) + unit, value=repr(float(x)),
                    stderr=repr(float(se)))
    return Cell(text=format(x, fmt) + unit, value=repr(float(x)))


def _picture(data: StudyData, rel: str, alt: str) -> dict:
    path = data.out / rel
    return {"rel": rel, "img": _img(path.read_bytes(), alt) if path.is_file() else None}


# ----------------------------------------------------------------------------------------------
# sections: what each shows, for the template's macro of the same name

def _probes(data: StudyData) -> dict:
    methods = data.summary["methods"]
    head = ["probe (x, z m)"]
    for name in data.methods:
        head += [f"{name} vx (m/s)", f"{name} vz (m/s)"]
        if name != "dem":
            head += [f"{name} - dem vx (m/s)", f"{name} - dem vz (m/s)"]
    rows = []
    for probe, p in data.scenario.analysis.probes.items():
        cells = [_text(f"{probe} ({p.x:g}, {p.z:g})", "l")]
        for name in data.methods:
            q = methods[name]["probes"].get(probe, {})
            for k in ("vx", "vz"):
                cells.append(_pm(q.get(k), q.get(k + "_stderr")).tagged(
                    data_method=name, data_probe=probe, data_q=k))
            if name != "dem":
                dif = (methods[name].get("against_dem") or {}).get("probe_differences_m_s", {})
                dq = dif.get(probe, {})
                for k in ("dvx", "dvz"):
                    cells.append(_pm(dq.get(k), dq.get(k + "_stderr")).tagged(
                        data_method=name, data_probe=probe, data_q=k))
        rows.append(cells)
    return {"head": head, "rows": rows}


def _circulation(data: StudyData, eng: Engineer) -> dict:
    rows = []
    for name in data.methods:
        m = data.summary["methods"][name]
        c = m.get("circulation", {})
        a = m.get("against_dem") or {}
        verdict = a.get("circulation_agrees")
        if name == "dem":
            e_cell = v_cell = _text("reference")
        else:
            e_cell = _pm(a.get("field_difference_E"),
                         eng.judged["rows"].get(name, {}).get("E_batches_stderr"), ".3f")
            v_cell = (_text("agrees", "ok") if verdict is True else
                      _text("differs", "bad") if verdict is False else _text("n/a"))
        rows.append([_text(name, "l"), _text(c.get("sense", "?")),
                     _pm(c.get("strength"), c.get("strength_stderr")), e_cell,
                     *eng.limit_cells(name), v_cell,
                     _text(a.get("field_difference_note") or "", "l")])
    return {"rows": rows, "min_solid_fraction": f"{data.min_solid_fraction:g}",
            "limit": eng.limit_note()}


def _shear(data: StudyData) -> dict:
    head = ["probe", "dem (fields.nc, 1/s)"] + [f"{n} (1/s)" for n in data.continuum_methods]
    rows = []
    blocks = {n: data.continuum_block(n) for n in data.continuum_methods}
    for probe, p in data.scenario.analysis.probes.items():
        cells = [_text(probe, "l"), _pm(*data.dem_shear_rate_at(p.x, p.z))]
        for n in data.continuum_methods:
            r = (blocks[n].get("probes") or {}).get(probe, {})
            cells.append(_pm(r.get("shear_rate_1_s"), r.get("shear_rate_1_s_stderr")))
        rows.append(cells)
    missing = data.notes.get("dem_fields", "no DEM fields") if data.dem_fields is None else None
    return {"img": _img(figures.shear_rate_maps(data), "shear-rate maps"), "head": head,
            "rows": rows, "missing": missing}


def _temperature(data: StudyData) -> dict:
    maps = temperature_maps(data)
    rows = [[_text(name, "l"), _num(m.get("E_thermal"), ".3g"),
             _num(m.get("E_phase_resolved"), ".3g")] for name, m in maps.continua.items()]
    return {"img": _img(figures.temperature_maps(data, maps), "granular temperature and "
                        "solid-fraction maps"),
            "with": list(maps.continua), "without": maps.without,
            "dem_fields": maps.dem is not None, "thermal": maps.dem_thermal is not None,
            "rows": rows, "dem_error": _num(maps.E_dem_error, ".3g")}


def _impacts(data: StudyData) -> dict:
    rows = []
    for name in data.methods:
        im = data.summary["methods"][name].get("impacts", {}) or {}
        sources = inferred_from(im)
        how = ("inferred from its " + " and ".join(sources) if sources else
               "measured" if (im.get("count") or 0) > 0 else "none")
        rows.append([_text(name, "l")]
                    + [_pm(im.get(f"{kind}_mean_normal_speed"), mean_speed_stderr(im, kind))
                       for kind in ("ball_ball", "ball_wall")]
                    + [_text(int(im.get("count") or 0)), _text(how, "l")])
    out = {"img": _img(figures.impact_maps(data), "impact-speed maps"), "rows": rows,
           "fit": None}
    fit = data.impact_fit("ball_ball")
    if fit is not None and data.impacts is not None:
        inferred = {n: figures.inferred_impact_speeds(data, n) for n in data.continuum_methods}
        errors = {n: figures.inferred_impact_speed_errors(data, n)
                  for n in data.continuum_methods}
        probe_rows = []
        for probe, p in data.scenario.analysis.probes.items():
            v, k = data.impacts.at(p.x, p.z)
            probe_rows.append([_text(probe, "l"), _pm(v, data.impacts.stderr_at(p.x, p.z)),
                               _text(k)]
                              + [_pm(inferred[n].get(probe), errors[n].get(probe))
                                 for n in data.continuum_methods])
        out.update(
            fit={"c0": _pm(fit["c0"], fit["c0_stderr"]).text,
                 "c1": _pm(fit["c1"], fit["c1_stderr"]).text, "which": fit["which"]},
            probe_head=["probe", "dem measured (m/s)", "impacts"]
            + [f"{n} inferred (m/s)" for n in data.continuum_methods],
            probe_rows=probe_rows)
    else:
        out["why"] = no_impact_comparison(data, fit)
    return out


def no_impact_comparison(data: StudyData, fit: dict | None) -> list[str]:
    """Why the page has no per-probe comparison of impact speeds: no measured impacts, no
    calibration at all, or a calibration without the ball-ball relation."""
    why = [data.notes.get("impacts")] if data.impacts is None else []
    if data.calibration is None:
        why.append(data.notes.get("calibration", "no calibration in the study"))
    elif fit is None:
        why.append("the calibration has no ball-ball impact relation")
    return [w for w in why if w]


def _impact_distributions(data: StudyData) -> dict:
    s = impact_distribution_section(data)
    stats = [[_text(label, "l"), _text(st.count), _pm(st.mean, st.mean_stderr),
              _pm(st.median, st.median_stderr), _pm(st.p95, st.p95_stderr)]
             for label, st in s["stats"]]
    flags = []
    for r in s["comparisons"]:
        flag = (_text("FLAG: differs by more than a quarter", "bad") if r["flagged"] else
                _text("within a quarter", "ok") if r["flagged"] is False else _text("n/a"))
        flags.append([_text(r["where"], "l"), _text(r["kind"], "l"), _text(r["method"], "l"),
                      _pm(r["measured"], r["measured_stderr"]),
                      _pm(r["inferred"], r["inferred_stderr"]),
                      _pm(100.0 * r["relative"], 100.0 * r["relative_stderr"], "+.0f",
                          " %"),
                      flag.tagged(data_flag=str(r["flagged"]).lower())])
    flagged = sum(r["flagged"] is True for r in s["comparisons"])
    compared = sum(r["flagged"] is not None for r in s["comparisons"])
    return {"why": s["why"], "stats": stats, "flags": flags, "flagged": flagged,
            "compared": compared,
            "histograms": s["histograms"] and _img(s["histograms"], "impact-speed histograms"),
            "wall_map": s["wall_map"] and _img(s["wall_map"], "ball-wall impacts along the U"),
            "seconds": f"{s.get('seconds', float('nan')):.3g}",
            "n_batches": s.get("n_batches", 0), "below": s.get("below", 0),
            "lowest_edge": f"{s.get('lowest_edge', float('nan')):.0e}"}


def _wall(data: StudyData) -> dict:
    rows = []
    for name in data.methods:
        w = data.summary["methods"][name].get("wall_contacts") or {}
        if not w:
            s = data.out / name / "summary.json"
            try:
                w = json.loads(s.read_text()).get("wall_contacts") or {}
            except (OSError, ValueError, AttributeError):
                w = {}
        rows.append([_text(name, "l"),
                     _pm(w.get("ratio_of_sums"), w.get("ratio_of_sums_stderr")),
                     _pm(w.get("mean_ft_over_fn"), w.get("mean_ft_over_fn_stderr")),
                     _pm(w.get("sliding_fraction"), w.get("sliding_fraction_stderr")),
                     _text(w.get("count", "n/a"))])
    out = {"picture": _picture(data, "calibration/wall_friction.png",
                               "wall friction histogram"),
           "rows": rows, "friction": None}
    if data.calibration is not None:
        w = data.calibration.wall
        se = w.friction_stderr if w.friction_stderr is not None else float("nan")
        out.update(friction=f"{w.friction:.4g}", friction_stderr=f"{se:.2g}",
                   choice=w.choice or "")
    return out


def _floor(data: StudyData) -> dict:
    """The floor's force over the cycle and the take-off of every method
    (measure.floor_force), the DEM first; `missing`: the methods whose run has none."""
    floors = {name: data.floor(name) for name in data.methods}
    have = {n: b for n, b in floors.items() if b}
    rows = [[_text(n, "l"), _pm(b.get("take_off_phase"), take_off_stderr(b), ".3f"),
             _text(", ".join("n/a" if t is None else f"{t:.3f}"
                             for t in b.get("take_off_phase_batches") or []), "l"),
             _pm(b.get("cycle_mean_over_weight"), b.get("cycle_mean_over_weight_stderr"),
                 ".3f"),
             _pm(*_lowest_phase(b), ".3f")]
            for n, b in have.items()]
    return {"img": _img(figures.floor_cycle(have), "floor force over the cycle")
            if have else None, "rows": rows, "missing": [n for n in floors if not floors[n]],
            "feed_head": ["method"] + [f"{r} (W/m²)" for r in REGIONS] + ["whole U (W/m²)"],
            "feed_rows": _wall_feed_rows(data), "feed_without": _without_feed(data)}


def _lowest_phase(floor: dict) -> tuple[float | None, float | None]:
    """The floor force's lowest phase mean over the weight and that phase's batch-means
    standard error (None where the floor block holds none)."""
    f = floor.get("force_over_weight") or []
    se = floor.get("force_over_weight_stderr") or []
    phases = [k for k, v in enumerate(f) if isinstance(v, (int, float))]
    if not phases:
        return None, None
    k = min(phases, key=lambda j: f[j])
    return f[k], se[k] if k < len(se) else None


def _without_feed(data: StudyData) -> list[dict]:
    """The continua with no wall-feed row, and why: a feed is the granular temperature's
    balance, so a run without the temperature has none."""
    out = []
    for name in data.continuum_methods:
        own = data.method_summary(name)
        if isinstance(own.get("wall_feed"), dict):
            continue
        opts = (own.get("continuum") or {}).get("options") or {}
        why = ("it ran without the granular temperature (its option temperature off), and the "
               "feed is the temperature's balance" if opts.get("temperature") is False else
               "its summary.json holds no wall_feed block")
        out.append({"name": name, "why": why})
    return out


def _stress(data: StudyData) -> dict:
    """Where each method's bed sits against its yield, by height and phase
    (report.stress_section)."""
    t = stress_rows(data)
    rows = [[_text(name, "l"), _num(n, "d"), _pm(*mu, ".3f"), _pm(*p, ".0f"),
             _pm(100.0 * share[0], 100.0 * share[1], ".1f", " %")]
            + [_text("n/a" if lh is None else
                     f"{plus_minus(lh[0], lh[2], '.3f')} / {plus_minus(lh[1], lh[3], '.3f')}")
               for lh in thirds]
            for name, n, mu, p, share, thirds in t.rows]
    return {"head": t.head, "rows": rows, "mu_s": _num(t.mu_s, ".3f").text,
            "missing": t.missing}


def _wall_feed_rows(data: StudyData) -> list:
    """The U wall's feed of fluctuation energy by region: the DEM's from the calibration's
    [kinetic.wall_flux] (measure.floor_force.dem_wall_feed), each continuum's with the
    granular temperature from its summary's "wall_feed" (continuum/wall_feed.py)."""
    rows = []
    kin = data.calibration.kinetic if data.calibration is not None else None
    table = getattr(kin, "wall_flux", None) if kin is not None else None
    if table is not None:
        d = dem_wall_feed(table, data.geometry.radius)
        rows.append([_text(DEM, "l")]
                    + [_pm(float(m), float(e)) for m, e in zip(d["by_region_W_m2"],
                                                               d["by_region_W_m2_stderr"])]
                    + [_pm(d["u_wall_W_m2"], d["u_wall_W_m2_stderr"])])
    for name in data.continuum_methods:
        b = data.method_summary(name).get("wall_feed")
        if not isinstance(b, dict):
            continue
        m, e = b.get("by_region_W_m2") or {}, b.get("by_region_W_m2_stderr") or {}
        rows.append([_text(name, "l")] + [_pm(m.get(r), e.get(r)) for r in REGIONS]
                    + [_pm(b.get("u_wall_W_m2"), b.get("u_wall_W_m2_stderr"))])
    return rows


def _rheology(data: StudyData) -> dict:
    def v(r, k):
        x, se = getattr(r, k), getattr(r, k + "_stderr")
        return plus_minus(x, se)

    fit = None
    if data.calibration is not None:
        r = data.calibration.rheology
        fit = {k: v(r, k) for k in ("mu_s", "mu_2", "I_0", "phi_max", "phi_min")}
        fit.update(source=r.source or "", status=r.status or "n/a")
    return {"picture": _picture(data, "calibration/mu_I.png", "mu(I) fit"), "fit": fit}


def _animation(data: StudyData, gif: Path | None, why: str | None) -> dict:
    if gif is None:
        return {"img": None, "why": why}
    return {"img": _img(gif.read_bytes(), "DEM slice animation", "image/gif"),
            "phases_per_cycle": data.scenario.run.phases_per_cycle,
            "path": str(gif.relative_to(data.out))}


def _sweep(data: StudyData) -> dict | None:
    if data.sweep_table is None and not data.sweep_images:
        return None
    where = (data.sweep_table or data.sweep_images[0]).parent
    if where.name == "plots" and data.sweep_table is None:
        where = where.parent
    if where.resolve() != data.out.resolve():
        # a point of a sweep: the page links to the sweep's own page (the template's sweep)
        return {"where": str(where.resolve())}
    out = {"where": None, "images": [], "error": None, "head": None}
    for p in data.sweep_images:
        stamp = time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime(p.stat().st_mtime))
        out["images"].append({"name": p.name, "stamp": stamp,
                              "img": _img(p.read_bytes(), p.stem)})
    if data.sweep_table is not None:
        try:
            with open(data.sweep_table, newline="") as f:
                rows = list(csv.reader(f))
        except (OSError, UnicodeDecodeError, csv.Error) as exc:
            rows = []
            out["error"] = f"{data.sweep_table}: unreadable ({type(exc).__name__})"
        if rows:
            head, body = rows[0], rows[1:]
            limit = 200
            out.update(head=head, table=str(data.sweep_table),
                       rows=[[_text(c, "l" if i == 0 else "") for i, c in enumerate(r)]
                             for r in body[:limit]],
                       more=len(body) if len(body) > limit else None)
    return out


def _cost(data: StudyData) -> dict:
    methods = data.summary["methods"]
    dem_wall = (methods.get("dem") or {}).get("wall_time_s")
    rows = []
    order = ["dem", "calibration", *data.continuum_methods, "comparison", "report"]
    order += [s for s in data.stages if s not in order]
    for stage in order:
        rec = data.stages.get(stage)
        m = methods.get(stage) or {}
        if stage == REPORT_STAGE:  # the page being written: an earlier report's record is stale
            rows.append([_text(stage, "l"), _num(None), _num(None), _num(None),
                         _text("being written", "l")])
            continue
        if rec is None and not m:
            continue
        solver = m.get("wall_time_s")
        ratio = (solver / dem_wall if isinstance(solver, (int, float)) and
                 isinstance(dem_wall, (int, float)) and dem_wall > 0 else None)
        stage_wall = rec.get("wall_time_s") if rec else None
        kept = "resumed" if rec and rec.get("resumed") else ""
        rows.append([_text(stage, "l"), _num(stage_wall, ".3g"), _num(solver, ".3g"),
                     _num(ratio, ".3g"),
                     _text(f"{(rec or {}).get('finished', '')} {kept}", "l")])
    return {"rows": rows}


def _parts(data: StudyData) -> tuple[list[dict], list[str]]:
    """The part sections (vibroflow.report.part_sections), one per part, their tables'
    cells formatted; and the notes on methods without parts.nc."""
    sections, notes = part_sections(data)
    out = []
    for s in sections:
        dem, continua = s["has_dem"], s["continua"]
        head = (["patch", "area (m^2)"] + (["DEM (m/s)"] if dem else [])
                + [f"{m} inferred (m/s)" for m in continua]
                + ([f"{m} - DEM (m/s)" for m in continua] if dem else [])
                + (["DEM impacts per area and s (1/(m^2 s))", "DEM energy flux (W/m^2)"]
                   if dem else []))
        rows, dist = [], []
        for r in s["rows"]:
            row = [_text(r["patch"], "l"), _num(r["area"], ".3g")]
            if dem:
                row.append(_pm(*r["dem"]))
            row += [_pm(*r[m]) for m in continua]
            if dem:
                row += [_pm(*r[m + "_diff"]) for m in continua]
                row += [_pm(*r["rate"]), _pm(*r["flux"])]
                dist.append([_text(r["patch"], "l"), _pm(*r["dem"]), _num(r["median"]),
                             _num(r["p95"])])
            rows.append(row)
        forces = []
        for m, (f, se, tq, tq_se) in s["forces"].items():
            for ph in range(f.shape[0]):
                forces.append([_text(m, "l"), _text(ph), _pm(f[ph, 0], se[ph, 0]),
                               _pm(f[ph, 2], se[ph, 2]), _pm(tq[ph, 1], tq_se[ph, 1])])
        whole = []
        for m, w in s["whole"].items():
            (f, fse), (tq, tq_se) = w["force"], w["torque"]
            d, noise = w.get("map", (float("nan"),) * 2)
            whole.append([_text(m, "l"), _num(d), _num(noise), _pm(f[0], fse[0]),
                          _pm(f[2], fse[2]), _pm(tq[1], tq_se[1])])
        out.append({"name": s["name"], "shape": s["shape"], "head": head, "rows": rows,
                    "dist": dist, "forces": forces, "whole": whole,
                    "map": _img(s["map"], f"impact map of {s['name']}"),
                    "distribution": s["distribution"] and _img(
                        s["distribution"], f"DEM normal impact speeds on {s['name']}"),
                    "inferred_from": s["inferred_from"]})
    return out, notes


# ----------------------------------------------------------------------------------------------

def render(data: StudyData, gif: Path | None = None, gif_note: str | None = None) -> str:
    """The whole page (a str of HTML)."""
    s = data.summary
    eng = Engineer(data)
    bodies = {
        "velocity": {"img": _img(figures.velocity_fields(data), "velocity fields")},
        "differences": eng.differences(),
        "profiles": eng.profiles(),
        "probes": _probes(data),
        "circulation": _circulation(data, eng),
        "bed": eng.bed(),
        "shear": _shear(data),
        "temperature": _temperature(data),
        "impacts": _impacts(data),
        "impact_distributions": _impact_distributions(data),
        "wall": _wall(data),
        "floor": _floor(data),
        "rheology": _rheology(data),
        "rheology_bins": eng.rheology_bins(),
        "stress": _stress(data),
        "animation": _animation(data, gif, gif_note),
        "sweep": _sweep(data),
        "cost": _cost(data),
        "scenario": {"toml": data.scenario_toml or ""},
    }
    parts, part_notes = _parts(data)
    return environment().get_template(TEMPLATE).render(
        css=CSS,
        case=s.get("case", "?"),
        folder=str(data.out.resolve()),
        results_version=s.get("vibroflow_version", "?"),
        report_version=__version__,
        now=time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime()),
        methods=list(data.methods),
        sections=SECTIONS,
        bodies=bodies,
        parts=parts,
        part_notes=part_notes,
        notes=dict(data.notes),
    )
