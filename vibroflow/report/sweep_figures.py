"""The sweep report's figures (matplotlib, Agg backend), each PNG bytes against the amplitude
factor: the circulation strength (+- its batch-means standard error), its sense, and every
continuum's field difference E against the DEM with the fields-agree limit drawn.

One line per method (colour) and, when other keys vary too, per combination of their values
(line style).  A sweep that varies run.seed draws its rows pooled over the seeds
(vibroflow.report.sweep_pool): the mean over seeds with its standard error, for the strength
and for E alike.  A point that did not finish is drawn as a red cross on the axis at its factor
(labelled with its status), not left out.
"""
from __future__ import annotations

from collections import defaultdict
from typing import Any

from vibroflow.report.figures import png_bytes
from vibroflow.report.sweep_data import SweepData, group_key
from vibroflow.report.sweep_pool import SENSES
from vibroflow.io.pictures import pyplot
from vibroflow.study.sweep_plots import NAMES as PLOT_NAMES
from vibroflow.study.sweep_plots import draw as draw_plots
from vibroflow.study.sweep_points import FACTOR_KEY

XLABEL = "amplitude factor (-)"
_STYLES = ("-", "--", ":", "-.")
_MARKERS = ("o", "s", "^", "D", "v", "P")


def _series(data: SweepData, methods: set[str] | None = None) -> dict[tuple, list[dict]]:
    """(method, other varied values) -> its finished (pooled) rows in order of the factor."""
    others = [k for k in data.shown if k != FACTOR_KEY]
    out: dict[tuple, list[dict]] = defaultdict(list)
    for r in data.pooled:
        if r["status"] == "done" and r["method"] and (methods is None or r["method"] in methods):
            out[(r["method"], tuple(r.get(k) for k in others))].append(r)
    for rows in out.values():
        rows.sort(key=lambda r: r[FACTOR_KEY])
    return dict(sorted(out.items(), key=lambda kv: (kv[0][0] != "dem", kv[0][0],
                                                    str(kv[0][1]))))


def _style(data: SweepData, key: tuple) -> dict[str, Any]:
    methods = sorted({r["method"] for r in data.rows if r["method"]},
                     key=lambda m: (m != "dem", m))
    others = [k for k in data.shown if k != FACTOR_KEY]
    combos = sorted({tuple(r.get(k) for k in others) for r in data.pooled
                     if r["status"] == "done"}, key=str)
    mi, ci = methods.index(key[0]), combos.index(key[1])
    label = key[0] + "".join(f", {k}={v}" for k, v in zip(others, key[1]))
    return dict(color=f"C{mi}", ls=_STYLES[ci % len(_STYLES)],
                marker=_MARKERS[ci % len(_MARKERS)], label=label)


def _unfinished(ax, data: SweepData, legend: bool = True) -> None:
    """A red cross on the x axis at the factor of every point that did not finish (in the
    legend too, unless `legend` is False)."""
    others = [k for k in data.varied if k != FACTOR_KEY]
    seen: set[str] = set()
    for r in data.failed:
        which = ", ".join(f"{k}={r.get(k)}" for k in others)
        label = (f"{r['status']}: {which}" if which else f"{r['status']} point") + \
            " (see the table)"
        ax.plot([r[FACTOR_KEY]], [0.0], "x", color="#b42318", ms=11, mew=2.5, clip_on=False,
                transform=ax.get_xaxis_transform(), zorder=5,
                label=None if label in seen or not legend else label)
        seen.add(label)


def _axes(plt, title: str, ylabel: str):
    fig, ax = plt.subplots(figsize=(8.5, 4.0))
    ax.set_xlabel(XLABEL)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(alpha=0.3)
    return fig, ax


def _finish(fig, ax) -> bytes:
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.tight_layout()
    return png_bytes(fig)


def strength_figure(data: SweepData) -> bytes:
    """Circulation strength (1e-4 m^2/s) +- its standard error, every method (over seeds: the
    larger of the seed-to-seed and the combined batch-means error)."""
    plt = pyplot()
    fig, ax = _axes(plt, "circulation strength, mean" + (" over seeds" if data.seeds_pooled
                                                          else "") + " ± standard error",
                    "circulation strength (1e-4 m²/s)")
    for key, rows in _series(data).items():
        y = [_scaled(r.get("circulation_strength"), 1e4) for r in rows]
        e = [_scaled(r.get("circulation_strength_stderr"), 1e4, 0.0) for r in rows]
        ax.errorbar([r[FACTOR_KEY] for r in rows], y, yerr=e, ms=5, capsize=3,
                    **_style(data, key))
    ax.set_ylim(bottom=0.0)
    _unfinished(ax, data)
    return _finish(fig, ax)


def sense_figure(data: SweepData) -> bytes:
    """The circulation's sense (counterclockwise +1, none 0, clockwise -1), every method; the
    methods' markers are set side by side around each factor so that none hides another."""
    plt = pyplot()
    fig, ax = _axes(plt, "circulation sense (tub frame, x right, z up)", "sense")
    series = _series(data)
    shifts = sense_offsets(data)
    for key, rows in series.items():
        dx = shifts[_style(data, key)["label"]]
        ax.plot([r[FACTOR_KEY] + dx for r in rows],
                [_sense_y(r) for r in rows], ms=7,
                **{**_style(data, key), "ls": "none"})
    ax.set_yticks(list(SENSES.values()), [f"{k} ({v:+.0f})" for k, v in SENSES.items()])
    ax.set_ylim(-1.5, 1.5)
    _unfinished(ax, data)
    return _finish(fig, ax)


def sense_offsets(data: SweepData) -> dict[str, float]:
    """Each line's shift off its amplitude factor in the sense figure, by its legend label:
    the lines side by side within half the factors' spacing, the DEM's first."""
    series = _series(data)
    factors = sorted({r[FACTOR_KEY] for r in data.rows})
    step = min((b - a for a, b in zip(factors, factors[1:])), default=1.0)
    n = max(len(series), 1)
    return {_style(data, key)["label"]: (i - (n - 1) / 2) * 0.5 * step / n
            for i, key in enumerate(series)}


def e_figure(data: SweepData) -> bytes:
    """Each continuum's E against the DEM (over seeds: the mean with its seed-to-seed standard
    error); the fields-agree limit as a bar at each factor that has one (with its standard
    error where known)."""
    plt = pyplot()
    fig, ax = _axes(plt, "field difference E against the DEM (tub47.md)" +
                    (", mean over seeds ± standard error" if data.seeds_pooled else ""), "E (-)")
    continua = {r["method"] for r in data.rows if r["method"] and r["method"] != "dem"}
    for key, rows in _series(data, continua).items():
        ax.errorbar([r[FACTOR_KEY] for r in rows],
                    [_scaled(r.get("E_against_dem"), 1.0) for r in rows],
                    yerr=[_scaled(r.get("E_against_dem_stderr"), 1.0, 0.0) for r in rows],
                    ms=5, capsize=3, **_style(data, key))
    done = False
    for key, lim in sorted(data.limits.items(), key=lambda kv: str(kv[0])):
        xs = sorted({r[FACTOR_KEY] for r in data.rows if group_key(r, data.varied) == key})
        se = 1.5 * (lim.stderr or 0.0)
        ax.errorbar(xs, [lim.limit] * len(xs), yerr=[se] * len(xs), color="k", ls="none",
                    marker="_", ms=18, capsize=4,
                    label=None if done else ("fields-agree limit (1.5 × seed-to-seed E"
                                             + (" of the sweep's seeds)" if data.seeds_pooled
                                                else ")")))
        done = True
    ax.set_ylim(bottom=0.0)
    _unfinished(ax, data)
    return _finish(fig, ax)


def table_plots(data: SweepData) -> dict[str, bytes]:
    """The sweep's probes, impacts and wall-time figures (vibroflow.study.sweep_plots, the
    files of plots/) drawn again from the rows of the page's table, with the red crosses of
    the unfinished points: the page never shows a plot older than its table."""
    figs = draw_plots(data.rows, data.varied)
    out = {}
    for name in PLOT_NAMES[0], PLOT_NAMES[2], PLOT_NAMES[3]:
        fig = figs.pop(name)
        for ax in fig.axes:
            _unfinished(ax, data, legend=False)
        out[name] = png_bytes(fig)
    for fig in figs.values():
        pyplot().close(fig)
    return out


def _sense_y(row: dict) -> float:
    """A row's sense as +1, 0, -1; pooled over seeds, the mean over them."""
    if row.get("sense_mean") is not None:
        return float(row["sense_mean"])
    return SENSES.get(row.get("circulation_sense"), 0.0)


def _scaled(v, scale: float, missing: float = float("nan")) -> float:
    return missing if v is None else float(v) * scale
