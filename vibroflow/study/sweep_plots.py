"""The sweep's pictures (matplotlib Agg, written atomically) against the amplitude factor.

    sweep_probes.png       probe velocities vx, vz (one panel each per probe), error bars
    sweep_circulation.png  circulation strength ± its standard error
    sweep_impacts.png      mean normal impact speeds ball-ball and ball-wall
    sweep_wall_time.png    wall time of each method

One line per method (colour) and, when other keys vary too, per combination of their values
(line style).  Only finished points are drawn.
"""
from __future__ import annotations

from collections import defaultdict
from pathlib import Path
from typing import Any

from vibroflow.io.atomic import atomic_path
from vibroflow.io.pictures import pyplot
from vibroflow.study.sweep_points import FACTOR_KEY

NAMES = ("sweep_probes.png", "sweep_circulation.png", "sweep_impacts.png",
         "sweep_wall_time.png")
_STYLES = ("-", "--", ":", "-.")
_MARKERS = ("o", "s", "^", "D", "v", "P")
XLABEL = "amplitude factor (motion.amplitude_factor)"


def _series(rows: list[dict[str, Any]], varied: list[str]) -> dict[tuple, list[dict]]:
    """(method, other varied values) -> its done rows in order of the amplitude factor."""
    others = [k for k in varied if k != FACTOR_KEY]
    out: dict[tuple, list[dict]] = defaultdict(list)
    for r in rows:
        if r.get("status") == "done" and r.get("method"):
            out[(r["method"], tuple(r.get(k) for k in others))].append(r)
    for v in out.values():
        v.sort(key=lambda r: r[FACTOR_KEY])
    return dict(out)


def _label(key: tuple, varied: list[str]) -> str:
    others = [k for k in varied if k != FACTOR_KEY]
    method, vals = key
    return method + "".join(f", {k}={v}" for k, v in zip(others, vals))


def _save(fig, path: Path) -> None:
    with atomic_path(path) as tmp:  # its name ends with path's: savefig picks the format
        fig.savefig(tmp, dpi=110)


def _draw(ax, series, varied, column: str, scale: float = 1.0, errors: bool = True) -> None:
    methods = sorted({k[0] for k in series})
    combos = sorted({k[1] for k in series}, key=str)
    for key, rows in sorted(series.items(), key=lambda kv: (kv[0][0], str(kv[0][1]))):
        x = [r[FACTOR_KEY] for r in rows]
        y = [(r.get(column) * scale) if r.get(column) is not None else float("nan")
             for r in rows]
        e = None
        if errors:
            e = [(r.get(column + "_stderr") or 0.0) * scale for r in rows]
        mi, ci = methods.index(key[0]), combos.index(key[1])
        ax.errorbar(x, y, yerr=e, color=f"C{mi}", ls=_STYLES[ci % len(_STYLES)],
                    marker=_MARKERS[ci % len(_MARKERS)], ms=4, capsize=3,
                    label=_label(key, varied))


def _one_panel(plt, series, varied, column: str, scale: float, ylabel: str, title: str,
               errors: bool = True):
    """A one-axes figure of `column` against the amplitude factor."""
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    _draw(ax, series, varied, column, scale=scale, errors=errors)
    ax.set_xlabel(XLABEL)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    return _legend(fig, ax, series)


def _legend(fig, legend_ax, series):
    """The legend on legend_ax (when a line is drawn) and the layout; returns the figure."""
    if series:
        legend_ax.legend(fontsize=7)
    fig.tight_layout()
    return fig


def draw(rows: list[dict[str, Any]], varied: list[str]) -> dict[str, Any]:
    """The four figures (matplotlib, open: the caller saves and closes them) by file name,
    drawn from the rows' finished points."""
    plt = pyplot()
    series = _series(rows, varied)
    probes: list[str] = []
    for r in rows:
        for k in r:
            if k.endswith("_vx") and k[:-3] not in probes:
                probes.append(k[:-3])

    n = max(len(probes), 1)
    fig, axes = plt.subplots(n, 2, figsize=(10, 2.4 * n + 0.8), sharex=True, squeeze=False)
    for i, p in enumerate(probes):
        for j, c in enumerate(("vx", "vz")):
            ax = axes[i][j]
            _draw(ax, series, varied, f"{p}_{c}", scale=1e3)
            ax.axhline(0.0, color="0.7", lw=0.6)
            ax.set_ylabel(f"{p} {c} (mm/s)")
    for ax in axes[-1]:
        ax.set_xlabel(XLABEL)
    fig.suptitle("bulk velocity at the probes (tub frame), mean ± standard error")
    out = {NAMES[0]: _legend(fig, axes[0][0], series)}

    out[NAMES[1]] = _one_panel(plt, series, varied, "circulation_strength", 1e4,
                               "circulation strength (1e-4 m²/s)",
                               "circulation strength ± standard error")

    fig, axes = plt.subplots(1, 2, figsize=(10, 4.2), squeeze=False)
    for ax, kind in zip(axes[0], ("ball_ball", "ball_wall")):
        _draw(ax, series, varied, f"impact_{kind}")
        ax.set_xlabel(XLABEL)
        ax.set_ylabel(f"mean normal impact speed {kind.replace('_', '-')} (m/s)")
    fig.suptitle("impact speeds ± standard error (continuum: from the calibrated "
                 "c0 + c1 d gamma_dot)")
    out[NAMES[2]] = _legend(fig, axes[0][0], series)

    out[NAMES[3]] = _one_panel(plt, series, varied, "wall_time_s", 1.0, "wall time (s)",
                               "wall time per method and point", errors=False)
    return out


def write_plots(folder: Path, rows: list[dict[str, Any]], varied: list[str]) -> list[str]:
    """The four pictures in `folder` (made if missing); returns their file names."""
    plt = pyplot()
    folder.mkdir(parents=True, exist_ok=True)
    for name, fig in draw(rows, varied).items():
        _save(fig, folder / name)
        plt.close(fig)
    return list(NAMES)
