"""The report page: one self-contained HTML file (inline CSS, every image a base64 data URI,
no script and no external link), assembled from a study's data (vibroflow.report.data), its
figures (vibroflow.report.figures), the calibration's own pictures (dem/calibration/*.png, drawn
by vibroflow.calibration.plots) and the DEM animation (vibroflow.report.animation).

Every number in a table cell carries its full value in a `data-value` attribute (the text shows
it rounded), so a reader or a test can take the exact number from the page.
"""
from __future__ import annotations

import base64
import csv
import html
import math
import time
from pathlib import Path

from vibroflow.report import figures
from vibroflow.report.data import StudyData

#: section id -> heading, in page order (tests check the headings)
SECTIONS = {
    "velocity": "Velocity field",
    "probes": "Probes",
    "circulation": "Circulation and agreement with the DEM",
    "shear": "Shear rate",
    "impacts": "Impact speeds",
    "wall": "Wall friction",
    "rheology": "mu(I) fit",
    "animation": "DEM animation",
    "sweep": "Sweep",
    "cost": "Cost",
    "scenario": "Scenario",
}

CSS = """
body { font-family: system-ui, sans-serif; margin: 1.5em auto; max-width: 1400px; color: #222;
       padding: 0 1em; }
h1 { font-size: 1.6em; margin-bottom: 0.2em; }
h2 { border-bottom: 1px solid #ccc; padding-bottom: 0.2em; margin-top: 1.6em; }
.meta { color: #555; }
nav a { margin-right: 0.9em; }
table { border-collapse: collapse; margin: 0.6em 0; font-size: 0.9em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: right; }
th { background: #f2f2f2; }
td.l, th.l { text-align: left; }
img { max-width: 100%; height: auto; display: block; margin: 0.5em 0; }
pre { background: #f7f7f7; border: 1px solid #ddd; padding: 0.8em; overflow-x: auto;
      font-size: 0.85em; }
.note { color: #8a5a00; }
.ok { color: #1a7f37; } .bad { color: #b42318; }
"""


def data_uri(payload: bytes, mime: str) -> str:
    return f"data:{mime};base64," + base64.b64encode(payload).decode("ascii")


def _img(payload: bytes, alt: str, mime: str = "image/png") -> str:
    return f'<img alt="{html.escape(alt)}" src="{data_uri(payload, mime)}">'


def _e(text) -> str:
    return html.escape(str(text))


def _num(x, fmt: str = ".4g", unit: str = "") -> str:
    """A table cell of a number (n/a when missing or not finite)."""
    if not isinstance(x, (int, float)) or isinstance(x, bool) or not math.isfinite(x):
        return '<td data-value="nan">n/a</td>'
    return f'<td data-value="{float(x)!r}">{format(x, fmt)}{unit}</td>'


def _pm(x, se, fmt: str = ".4g") -> str:
    """A cell 'x ± se' (data-value x, data-stderr se)."""
    if not isinstance(x, (int, float)) or not math.isfinite(x):
        return '<td data-value="nan">n/a</td>'
    txt = format(x, fmt)
    attr = f'data-value="{float(x)!r}"'
    if isinstance(se, (int, float)) and math.isfinite(se):
        txt += f" ± {se:.2g}"
        attr += f' data-stderr="{float(se)!r}"'
    return f"<td {attr}>{txt}</td>"


def _table(head: list[str], rows: list[str], cls: str = "") -> str:
    h = "".join(f'<th class="l">{_e(c)}</th>' if i == 0 else f"<th>{_e(c)}</th>"
                for i, c in enumerate(head))
    return f'<table{f" class={cls!r}" if cls else ""}><tr>{h}</tr>' + "".join(rows) + "</table>"


def _note(text: str) -> str:
    return f'<p class="note">{_e(text)}</p>'


# ----------------------------------------------------------------------------------------------
# sections

def _probes(data: StudyData) -> str:
    methods = data.summary["methods"]
    head = ["probe (x, z m)"]
    for name in data.methods:
        head += [f"{name} vx (m/s)", f"{name} vz (m/s)"]
        if name != "dem":
            head += [f"{name} - dem vx", f"{name} - dem vz"]
    rows = []
    for probe, p in data.scenario.analysis.probes.items():
        cells = [f'<td class="l">{_e(probe)} ({p.x:g}, {p.z:g})</td>']
        for name in data.methods:
            q = methods[name]["probes"].get(probe, {})
            cells.append(_pm(q.get("vx"), q.get("vx_stderr")).replace(
                "<td ", f'<td data-method="{_e(name)}" data-probe="{_e(probe)}" data-q="vx" ', 1))
            cells.append(_pm(q.get("vz"), q.get("vz_stderr")).replace(
                "<td ", f'<td data-method="{_e(name)}" data-probe="{_e(probe)}" data-q="vz" ', 1))
            if name != "dem":
                dif = (methods[name].get("against_dem") or {}).get("probe_differences_m_s", {})
                dq = dif.get(probe, {})
                cells.append(_num(dq.get("dvx")).replace(
                    "<td ", f'<td data-method="{_e(name)}" data-probe="{_e(probe)}" '
                    'data-q="dvx" ', 1))
                cells.append(_num(dq.get("dvz")).replace(
                    "<td ", f'<td data-method="{_e(name)}" data-probe="{_e(probe)}" '
                    'data-q="dvz" ', 1))
        rows.append("<tr>" + "".join(cells) + "</tr>")
    return (_table(head, rows, "probes")
            + "<p>Bulk velocity relative to the tub (tub axes) of the cell holding each probe, "
              "time-averaged over the window, ± the batch-means standard error; the last "
              "columns of each continuum method are its difference to the DEM.</p>")


def _circulation(data: StudyData) -> str:
    rows = []
    for name in data.methods:
        m = data.summary["methods"][name]
        c = m.get("circulation", {})
        a = m.get("against_dem") or {}
        verdict = a.get("circulation_agrees")
        v = ("" if name == "dem" else
             '<td class="ok">agrees</td>' if verdict is True else
             '<td class="bad">differs</td>' if verdict is False else "<td>n/a</td>")
        E = a.get("field_difference_E")
        rows.append(f'<tr><td class="l">{_e(name)}</td><td>{_e(c.get("sense", "?"))}</td>'
                    + _pm(c.get("strength"), c.get("strength_stderr"))
                    + (_num(E, ".3f") if name != "dem" else "<td>reference</td>")
                    + (v or "<td>reference</td>")
                    + f'<td class="l">{_e(a.get("field_difference_note") or "")}</td></tr>')
    msf = data.min_solid_fraction
    return (_table(["method", "sense", "strength (m²/s)", "E against the DEM",
                    "circulation verdict", "note"], rows, "circulation")
            + f"<p>Strength: the extreme of the stream function of the mean flow (tub47.md). E: "
              f"the field difference of the bulk velocity against the DEM's over the cells "
              f"with solid fraction ≥ {msf:g} (vibroflow.analysis.compare); the verdict: the "
              f"strengths agree within their combined standard errors and the senses match "
              f"(tub47.md \"Judging a comparison\").</p>")


def _shear(data: StudyData) -> str:
    out = [_img(figures.shear_rate_maps(data), "shear-rate maps")]
    head = ["probe", "dem (fields.nc, 1/s)"] + [f"{n} (1/s)" for n in data.continuum_methods]
    rows = []
    blocks = {n: data.continuum_block(n) for n in data.continuum_methods}
    for probe, p in data.scenario.analysis.probes.items():
        cells = [f'<td class="l">{_e(probe)}</td>', _num(data.dem_shear_rate_at(p.x, p.z))]
        for n in data.continuum_methods:
            r = (blocks[n].get("probes") or {}).get(probe, {})
            cells.append(_pm(r.get("shear_rate_1_s"), r.get("shear_rate_1_s_stderr")))
        rows.append("<tr>" + "".join(cells) + "</tr>")
    out.append(_table(head, rows, "shear"))
    out.append("<p>Cycle-mean shear rate in each probe's cell: for the DEM the mass-weighted "
               "mean of the coarse-grained field's grid points in the cell (5 mm grid), for a "
               "continuum method the cycle mean of its phase-resolved velocity field's shear "
               "rate at the cell's centre (vibroflow.measure.phase_shear).</p>")
    if data.dem_fields is None:
        out.append(_note(data.notes.get("dem_fields", "no DEM fields")))
    return "\n".join(out)


def _impacts(data: StudyData) -> str:
    out = [_img(figures.impact_maps(data), "impact-speed maps")]
    rows = []
    for name in data.methods:
        im = data.summary["methods"][name].get("impacts", {}) or {}
        how = ("inferred from its shear rate" if im.get("inferred_from_shear_rate") else
               "measured" if (im.get("count") or 0) > 0 else "none")
        rows.append(f'<tr><td class="l">{_e(name)}</td>'
                    + _pm(im.get("ball_ball_mean_normal_speed"),
                          im.get("ball_ball_mean_normal_speed_stderr"))
                    + _pm(im.get("ball_wall_mean_normal_speed"),
                          im.get("ball_wall_mean_normal_speed_stderr"))
                    + f'<td>{int(im.get("count") or 0)}</td><td class="l">{how}</td></tr>')
    out.append(_table(["method", "ball-ball (m/s)", "ball-wall (m/s)", "impacts counted",
                       "how"], rows, "impacts"))
    fit = data.impact_fit("ball_ball")
    if fit is not None and data.impacts is not None:
        head = ["probe", "dem measured (m/s)", "impacts"] + [
            f"{n} inferred (m/s)" for n in data.continuum_methods]
        inferred = {n: figures.inferred_impact_speeds(data, n) for n in data.continuum_methods}
        rows = []
        for probe, p in data.scenario.analysis.probes.items():
            v, k = data.impacts.at(p.x, p.z)
            rows.append(f'<tr><td class="l">{_e(probe)}</td>' + _num(v) + f"<td>{k}</td>"
                        + "".join(_num(inferred[n].get(probe)) for n in data.continuum_methods)
                        + "</tr>")
        out.append(_table(head, rows, "impact-probes"))
        out.append(f"<p>Mean normal approach speed of ball-ball impacts. A continuum sees no "
                   f"impact: it infers the speed from its shear rate by the relation fitted to "
                   f"the DEM, v = c0 + c1 d gamma_dot with c0 = {fit['c0']:.3g} m/s, c1 = "
                   f"{fit['c1']:.3g} (calibration.toml [impacts.ball_ball] "
                   f"{_e(fit['which'])}), gamma_dot the cycle mean of the phase-resolved "
                   f"velocity field on the analysis cells, measured alike on both.</p>")
    else:
        why = [data.notes.get("impacts")] if data.impacts is None else []
        if fit is None:
            why.append("the calibration has no ball-ball impact relation")
        out.append(_note("No per-probe comparison of impact speeds: " + "; ".join(
            w for w in why if w) + "."))
    return "\n".join(out)


def _picture(data: StudyData, rel: str, alt: str) -> str:
    path = data.out / rel
    if path.is_file():
        return _img(path.read_bytes(), alt)
    return _note(f"{rel} is missing (the calibration draws it: `vibroflow calibrate`).")


def _wall(data: StudyData) -> str:
    rows = []
    for name in data.methods:
        w = data.summary["methods"][name].get("wall_contacts") or {}
        if not w:
            s = data.out / name / "summary.json"
            try:
                import json

                w = json.loads(s.read_text()).get("wall_contacts") or {}
            except (OSError, ValueError, AttributeError):
                w = {}
        rows.append(f'<tr><td class="l">{_e(name)}</td>'
                    + _pm(w.get("ratio_of_sums"), w.get("ratio_of_sums_stderr"))
                    + _pm(w.get("mean_ft_over_fn"), w.get("mean_ft_over_fn_stderr"))
                    + _pm(w.get("sliding_fraction"), w.get("sliding_fraction_stderr"))
                    + f'<td>{_e(w.get("count", "n/a"))}</td></tr>')
    cal = (data.calibration or {}).get("wall") or {}
    text = ""
    if cal:
        text = (f"<p>Calibrated wall friction (the continuum's): {cal.get('friction', 'n/a'):.4g}"
                f" ± {cal.get('friction_stderr', float('nan')):.2g} — "
                f"{_e(cal.get('choice', ''))}.</p>")
    return (_picture(data, "dem/calibration/wall_friction.png", "wall friction histogram")
            + text + _table(["method", "sum|F_t| / sum F_n", "mean |F_t|/F_n",
                             "sliding fraction", "contacts"], rows, "wall"))


def _rheology(data: StudyData) -> str:
    r = (data.calibration or {}).get("rheology") or {}
    text = ""
    if r:
        def v(k):
            x = r.get(k)
            se = r.get(k + "_stderr")
            if not isinstance(x, (int, float)):
                return "n/a"
            return f"{x:.4g}" + (f" ± {se:.2g}" if isinstance(se, (int, float)) and
                                 math.isfinite(se) else "")
        text = (f"<p>mu_s = {v('mu_s')}, mu_2 = {v('mu_2')}, I_0 = {v('I_0')}; phi_max = "
                f"{v('phi_max')}, phi_min = {v('phi_min')} ({_e(r.get('source', ''))}; "
                f"status {_e(r.get('status', 'n/a'))}).</p>")
    return _picture(data, "dem/calibration/mu_I.png", "mu(I) fit") + text


def _animation(data: StudyData, gif: Path | None, why: str | None) -> str:
    if gif is None:
        return _note(f"No animation: {why}.")
    return (_img(gif.read_bytes(), "DEM slice animation", "image/gif")
            + f"<p>The DEM's balls within a slab about the tub's mid-length, over the last "
              f"snapshots of the run ({data.scenario.run.phases_per_cycle} a vibration cycle), "
              f"drawn in the tub frame (the U stays put) and coloured by their speed relative "
              f"to the tub. Also in {_e(gif.relative_to(data.out))}.</p>")


def _sweep(data: StudyData) -> str:
    if data.sweep_table is None and not data.sweep_images:
        return "<p>No sweep in this folder (run <code>vibroflow sweep</code> for one).</p>"
    where = (data.sweep_table or data.sweep_images[0]).parent
    if where.name == "plots" and data.sweep_table is None:
        where = where.parent
    out = []
    if where.resolve() != data.out.resolve():
        out.append(f"<p>From the sweep this study is a point of: {_e(where.resolve())}.</p>")
    for p in data.sweep_images:
        stamp = time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime(p.stat().st_mtime))
        out.append(f"<p>{_e(p.name)} (written {stamp})</p>" + _img(p.read_bytes(), p.stem))
    if data.sweep_table is not None:
        try:
            with open(data.sweep_table, newline="") as f:
                rows = list(csv.reader(f))
        except (OSError, UnicodeDecodeError, csv.Error) as exc:
            rows = []
            out.append(_note(f"{data.sweep_table}: unreadable ({type(exc).__name__})"))
        if rows:
            head, body = rows[0], rows[1:]
            limit = 200
            out.append(_table(head, ["<tr>" + "".join(
                f'<td class="l">{_e(c)}</td>' if i == 0 else f"<td>{_e(c)}</td>"
                for i, c in enumerate(r)) + "</tr>" for r in body[:limit]], "sweep"))
            if len(body) > limit:
                out.append(_note(f"first {limit} of {len(body)} rows; the whole table is "
                                 f"{data.sweep_table}"))
    return "\n".join(out)


def _cost(data: StudyData) -> str:
    methods = data.summary["methods"]
    dem_wall = (methods.get("dem") or {}).get("wall_time_s")
    rows = []
    order = ["dem", "calibration", *data.continuum_methods, "comparison", "report"]
    order += [s for s in data.stages if s not in order]
    for stage in order:
        rec = data.stages.get(stage)
        m = methods.get(stage) or {}
        if rec is None and not m:
            continue
        solver = m.get("wall_time_s")
        ratio = (solver / dem_wall if isinstance(solver, (int, float)) and
                 isinstance(dem_wall, (int, float)) and dem_wall > 0 else None)
        stage_wall = rec.get("wall_time_s") if rec else None
        kept = "resumed" if rec and rec.get("resumed") else ""
        rows.append(f'<tr><td class="l">{_e(stage)}</td>' + _num(stage_wall, ".3g")
                    + _num(solver, ".3g") + _num(ratio, ".3g")
                    + f'<td class="l">{_e((rec or {}).get("finished", ""))} {kept}</td></tr>')
    return (_table(["stage", "stage wall time (s)", "solver wall time (s)",
                    "solver time / DEM's", "finished"], rows, "cost")
            + "<p>Stage wall time: the whole stage (DIR/&lt;stage&gt;/stage.json; a stage "
              "being written now, such as this report, has none yet). Solver wall time: the "
              "method's own run (summary.json wall_time_s).</p>")


def _scenario(data: StudyData) -> str:
    if not data.scenario_toml:
        return _note("The scenario text is not in the study.")
    return ("<p>As <code>vibroflow scenario show</code> prints it (from dem/dem.h5):</p>"
            f"<pre>{_e(data.scenario_toml)}</pre>")


# ----------------------------------------------------------------------------------------------

def render(data: StudyData, gif: Path | None = None, gif_note: str | None = None) -> str:
    """The whole page (a str of HTML)."""
    from vibroflow import __version__

    s = data.summary
    case = s.get("case", "?")
    now = time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime())
    body = {
        "velocity": _img(figures.velocity_fields(data), "velocity fields"),
        "probes": _probes(data),
        "circulation": _circulation(data),
        "shear": _shear(data),
        "impacts": _impacts(data),
        "wall": _wall(data),
        "rheology": _rheology(data),
        "animation": _animation(data, gif, gif_note),
        "sweep": _sweep(data),
        "cost": _cost(data),
        "scenario": _scenario(data),
    }
    nav = " ".join(f'<a href="#{k}">{_e(v)}</a>' for k, v in SECTIONS.items())
    parts = [
        "<!DOCTYPE html>", '<html lang="en"><head><meta charset="utf-8">',
        f"<title>vibroflow study: {_e(case)}</title>", f"<style>{CSS}</style></head><body>",
        f"<h1>vibroflow study: {_e(case)}</h1>",
        f'<p class="meta">Folder {_e(data.out.resolve())}; results of vibroflow '
        f'{_e(s.get("vibroflow_version", "?"))}, report by vibroflow {_e(__version__)}, '
        f'{now}. Methods: {_e(", ".join(data.methods))} (the DEM is the reference). Units: '
        f'SI.</p>',
        f"<nav>{nav}</nav>",
    ]
    for key, title in SECTIONS.items():
        parts.append(f'<section id="{key}"><h2>{_e(title)}</h2>\n{body[key]}\n</section>')
    if data.notes:
        parts.append('<section id="notes"><h2>Missing pieces</h2><ul>' + "".join(
            f"<li>{_e(k)}: {_e(v)}</li>" for k, v in data.notes.items()) + "</ul></section>")
    parts.append("</body></html>\n")
    return "\n".join(parts)
