"""The report's figures (matplotlib, Agg backend): each a function of the study's data
(`vibroflow.report.data.StudyData`) returning PNG bytes, one panel per method side by side, the
DEM first, on the tub's U outline (tub frame: x across, z up from the bottom of the U, m).

The continuum methods write their cycle-mean shear rate and the impact speed it implies on the
analysis cells (their shear_rate.csv); their panels of the shear-rate and impact maps draw those
maps on the DEM's colour scale (a run older than that map: its probe cells only, from its
summary's `continuum` block); the mean-flow shear-rate row compares every method cell by cell
from its bulk_velocity.csv.
"""
from __future__ import annotations

import io
import math

import numpy as np
from matplotlib.collections import PatchCollection
from matplotlib.colors import LogNorm, Normalize, PowerNorm
from matplotlib.patches import Rectangle

from vibroflow.analysis.impact_stats import same_measured_mean
from vibroflow.io.pictures import pyplot
from vibroflow.measure.stats import (affine_prediction_stderr, jackknife_covariance,
                                     quadrature_stderr)
from vibroflow.report.data import DEM, MIN_IMPACTS_PER_CELL, StudyData, mean_flow_shear_rate
from vibroflow.report.temperature_maps import PHI_KEY, T_KEY, TemperatureMaps
from vibroflow.rounding import plus_minus

DPI = 90


def png_bytes(fig) -> bytes:
    """The figure as PNG bytes (closed afterwards)."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI, bbox_inches="tight")
    pyplot().close(fig)
    return buf.getvalue()


def _outline(ax, data: StudyData, bed_top: float | None = None) -> None:
    geo = data.geometry
    prof = geo.profile(300)
    ax.plot(prof[:, 0], prof[:, 1], "k-", lw=1.2)
    ax.set_aspect("equal")
    top = geo.rim_height if bed_top is None else min(geo.rim_height, bed_top)
    ax.set_xlim(-1.05 * geo.radius, 1.05 * geo.radius)
    ax.set_ylim(-0.03 * geo.radius, top)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("z (m)")


def _bed_top(data: StudyData) -> float:
    """A height (m) above every method's bed, to crop the empty upper tub."""
    top = 0.0
    for ds in data.fields.values():
        z = ds["z"].values
        has = (ds["samples"].values > 0).any(axis=1)
        if has.any():
            top = max(top, float(z[has].max()))
    h = float(data.scenario.analysis.cell_size)
    return top + 2.0 * h if top > 0 else data.geometry.rim_height


def _probes(ax, data: StudyData, labels: bool = True) -> None:
    for name, p in data.scenario.analysis.probes.items():
        ax.plot(p.x, p.z, "k+", ms=8, mew=1.5)
        if labels:
            ax.annotate(name, (p.x, p.z), xytext=(4, 4), textcoords="offset points",
                        fontsize=8)


def _panels(n: int, width: float = 4.6, height: float = 4.2):
    plt = pyplot()
    # constrained layout: two-line panel titles, the suptitle and the colour bar never overlap
    fig, axes = plt.subplots(1, n, figsize=(width * n, height), squeeze=False,
                             layout="constrained")
    return fig, list(axes[0])


def _method_title(data: StudyData, name: str) -> str:
    c = data.summary["methods"][name].get("circulation", {})
    s, se = c.get("strength"), c.get("strength_stderr")
    if s is None:
        return name
    return f"{name}\n{c.get('sense', '?')}, strength {plus_minus(s, se, '.3g')} m²/s"


# ----------------------------------------------------------------------------------------------

def velocity_fields(data: StudyData) -> bytes:
    """The bulk velocity relative to the tub of every method: streamlines of the mean flow over
    |v| in colour (one square-root scale for all methods: the fast surface layer would
    otherwise leave the slow bulk in one colour), on the cells holding bed (solid fraction >=
    half the analysis' min_solid_fraction)."""
    names = data.methods
    fig, axes = _panels(len(names))
    top = _bed_top(data)
    vmax = 0.0
    for name in names:
        ds = data.fields[name]
        sp = np.hypot(ds["vx"].values, ds["vz"].values)
        if np.isfinite(sp).any():
            vmax = max(vmax, float(np.nanmax(sp)))
    norm = PowerNorm(0.5, 0.0, vmax if vmax > 0 else 1.0)
    mesh = None
    for ax, name in zip(axes, names):
        ds = data.fields[name]
        x, z = ds["x"].values, ds["z"].values
        vx, vz = ds["vx"].values, ds["vz"].values
        bed = (ds["solid_fraction"].values >= 0.5 * data.min_solid_fraction) & np.isfinite(
            vx) & np.isfinite(vz)
        sp = np.where(bed, np.hypot(vx, vz), np.nan)
        mesh = ax.pcolormesh(x, z, sp, shading="nearest", cmap="viridis", norm=norm)
        if x.size > 1 and z.size > 1 and bed.sum() > 1:
            # the streamlines stop where the bed ends (masked cells)
            ax.streamplot(x, z, np.ma.masked_where(~bed, np.where(bed, vx, 0.0)),
                          np.ma.masked_where(~bed, np.where(bed, vz, 0.0)), color="white",
                          density=1.1, linewidth=0.8, arrowsize=0.8)
        _outline(ax, data, top)
        _probes(ax, data)
        ax.set_title(_method_title(data, name), fontsize=9)
    if mesh is not None:
        fig.colorbar(mesh, ax=axes, shrink=0.8, label="|v| relative to the tub (m/s)")
    fig.suptitle("bulk (circulation) velocity relative to the tub, time-averaged, "
                 f"{1e3 * data.scenario.analysis.cell_size:g} mm cells: streamlines")
    return png_bytes(fig)


def _cell_squares(ax, data: StudyData, values: dict, norm, cmap):
    """Colour the probe cells by values (probe name -> value); returns the mappable."""
    h = float(data.scenario.analysis.cell_size)
    patches, vals = [], []
    for name, p in data.scenario.analysis.probes.items():
        v = values.get(name)
        if v is None or not math.isfinite(v):
            continue
        cx, cz = math.floor(p.x / h + 0.5) * h, math.floor(p.z / h + 0.5) * h
        patches.append(Rectangle((cx - 0.5 * h, cz - 0.5 * h), h, h))
        vals.append(v)
    pc = PatchCollection(patches, cmap=cmap, norm=norm, edgecolor="k", linewidth=0.6)
    pc.set_array(np.asarray(vals, dtype=float))
    ax.add_collection(pc)
    return pc, len(vals)


def _continuum_map(ax, data: StudyData, grid_map, cells: dict, norm, cmap, mappable):
    """A continuum method's map: its grid (xs, zs, values) where it wrote one, else the probe
    cells coloured by `cells`.  Returns the colour bar's mappable (the grid, or the first drawn
    of `mappable` and the cells) and the number of cells drawn (None for a grid)."""
    if grid_map is not None:
        xs, zs, grid = grid_map
        return ax.pcolormesh(xs, zs, grid, shading="nearest", cmap=cmap, norm=norm), None
    pc, k = _cell_squares(ax, data, cells, norm, cmap)
    return mappable or pc, k


def _log_norm(values):
    v = np.concatenate([np.ravel(np.asarray(a, dtype=float)) for a in values] or [np.zeros(0)])
    v = v[np.isfinite(v) & (v > 0)]
    if v.size == 0:
        return LogNorm(0.1, 1.0)
    hi = float(v.max())
    return LogNorm(max(float(v.min()), hi * 1e-3), hi)


def shear_rate_maps(data: StudyData) -> bytes:
    """Top row: the cycle-mean shear rate the bed feels (DEM: the coarse-grained fields.nc map;
    continuum: its own cycle-mean shear rate in the probe cells).  Bottom row: the shear rate of
    the mean (circulation) flow, from every method's bulk_velocity.csv by the same finite
    differences (data.mean_flow_shear_rate)."""
    plt = pyplot()
    names = data.methods
    n = len(names)
    fig, axes = plt.subplots(2, n, figsize=(4.6 * n, 8.4), squeeze=False, layout="constrained")
    top = _bed_top(data)
    # top row
    ds = data.dem_fields
    dem_map = None
    if ds is not None:
        gname = "shear_rate_cycle_mean" if "shear_rate_cycle_mean" in ds else "shear_rate"
        bed = ds["solid_fraction"].values >= 0.05
        dem_map = np.where(bed, ds[gname].values, np.nan)
    cont = {name: {k: v.get("shear_rate_1_s") for k, v in
                   (data.continuum_block(name).get("probes") or {}).items()}
            for name in data.continuum_methods}
    cmaps = {name: data.continuum_shear_map(name) for name in data.continuum_methods}
    norm = _log_norm([dem_map if dem_map is not None else np.zeros(0)]
                     + [list(c.values()) for c in cont.values()]
                     + [m[2] for m in cmaps.values() if m is not None])
    cmap = "plasma"
    mappable = None
    for ax, name in zip(axes[0], names):
        if name == data.methods[0] and name == "dem":
            if dem_map is None:
                ax.text(0.5, 0.5, "no coarse-grained fields\n(calibration/fields.nc)",
                        ha="center", va="center", transform=ax.transAxes)
            else:
                x, z = ds["x"].values, ds["z"].values
                mappable = ax.pcolormesh(x, z, dem_map.T, shading="nearest", cmap=cmap,
                                         norm=norm)
            ax.set_title("dem: cycle-mean shear rate (fields.nc)", fontsize=9)
        else:
            mappable, k = _continuum_map(ax, data, cmaps.get(name), cont.get(name, {}), norm,
                                         cmap, mappable)
            if k is None:
                ax.set_title(f"{name}: cycle-mean shear rate (shear_rate.csv)", fontsize=9)
            else:
                block = data.continuum_block(name).get("shear_rate") or {}
                m, se = block.get("mean_1_s"), block.get("mean_1_s_stderr")
                txt = (f"bed mean {m:.3g} ± {se:.2g} 1/s" if isinstance(m, (int, float))
                       and math.isfinite(m) else "no shear rate written")
                if k == 0:
                    txt += "\nno probe shear rates"
                ax.text(0.03, 0.97, txt, ha="left", va="top", transform=ax.transAxes,
                        fontsize=8)
                ax.set_title(f"{name}: cycle-mean shear rate in the probe cells", fontsize=9)
        _outline(ax, data, top)
        _probes(ax, data)
    if mappable is not None:
        fig.colorbar(mappable, ax=list(axes[0]), shrink=0.8, label="shear rate (1/s)")
    # bottom row: the mean flow's shear rate
    maps = {}
    for name in names:
        f = data.fields[name]
        h = float(f.attrs.get("cell_size_m", data.scenario.analysis.cell_size))
        g = mean_flow_shear_rate(f["vx"].values, f["vz"].values, h)
        bed = f["solid_fraction"].values >= 0.5 * data.min_solid_fraction
        maps[name] = np.where(bed, g, np.nan)
    norm2 = _log_norm(list(maps.values()))
    m2 = None
    for ax, name in zip(axes[1], names):
        f = data.fields[name]
        m2 = ax.pcolormesh(f["x"].values, f["z"].values, maps[name], shading="nearest",
                           cmap=cmap, norm=norm2)
        _outline(ax, data, top)
        ax.set_title(f"{name}: shear rate of the mean flow", fontsize=9)
    if m2 is not None:
        fig.colorbar(m2, ax=list(axes[1]), shrink=0.8, label="shear rate (1/s)")
    fig.suptitle("shear rate gamma_dot = sqrt(2 D':D')")
    return png_bytes(fig)


def _through_relation(data: StudyData, name: str, key: str, value) -> dict:
    """value(fit, d, x) in each probe cell of a continuum method, x its summary's probe entry
    `key` where finite, fit the calibrated ball-ball relation (StudyData.impact_fit) and d the
    ball diameter (m); {} without a fit."""
    fit = data.impact_fit("ball_ball")
    if fit is None:
        return {}
    out = {}
    for probe, rec in (data.continuum_block(name).get("probes") or {}).items():
        x = rec.get(key)
        if isinstance(x, (int, float)) and math.isfinite(x):
            out[probe] = value(fit, data.diameter, x)
    return out


def inferred_impact_speeds(data: StudyData, name: str) -> dict:
    """A continuum method's ball-ball impact speeds (m/s) inferred in the probe cells from its
    shear rate there by the calibrated v = c0 + c1 d gamma_dot (calibration.toml
    [impacts.ball_ball], the relation its run uses for the bed mean); {} without a fit."""
    return _through_relation(data, name, "shear_rate_1_s",
                             lambda fit, d, g: fit["c0"] + fit["c1"] * d * g)


def inferred_impact_speed_errors(data: StudyData, name: str) -> dict:
    """The standard errors (m/s) of inferred_impact_speeds: the run's batch-means error of the
    shear rate through the relation, |c1| d se(gamma_dot), as the summary's bed means carry
    (continuum.shear_outputs), and the calibrated relation's own at that shear rate
    (measure.stats.affine_prediction_stderr of c0's and c1's errors and covariance), in
    quadrature: the continuum's run and the DEM's calibration are independent.  {} without a
    fit."""
    run = _through_relation(data, name, "shear_rate_1_s_stderr",
                            lambda fit, d, se: abs(fit["c1"]) * d * se)
    relation = _through_relation(
        data, name, "shear_rate_1_s",
        lambda fit, d, g: affine_prediction_stderr(d * g, fit["c0_stderr"], fit["c1_stderr"],
                                                   fit["covariance"]))
    return {probe: quadrature_stderr(se, relation.get(probe)) for probe, se in run.items()}


def inferred_impact_speed_covariances(data: StudyData, name: str) -> dict:
    """The covariance (m^2/s^2) of each probe cell's inferred_impact_speeds with the DEM's
    measured mean speed in that cell, where the relation was calibrated on this study's DEM run
    (the impact fit's measured_mean is the DEM summary's: analysis.impact_stats.
    same_measured_mean): the same cycles move both, and the delete-one-batch jackknife covariance
    (measure.stats.jackknife_covariance) of the prediction c0_b + c1_b d gamma_dot, with the
    calibration's refits without batch b, and the cell's mean without batch b
    (ImpactCells.left_out_at) gives it.  Probes left out where either is unknown or their
    batches differ in number: there the two are independent."""
    fit = data.impact_fit("ball_ball")
    dem = (data.summary["methods"].get(DEM) or {}).get("impacts") or {}
    if (fit is None or fit["left_out"] is None or data.impacts is None
            or not same_measured_mean(fit["measured_mean"],
                                      dem.get("ball_ball_mean_normal_speed"))):
        return {}
    c0s, c1s = fit["left_out"]
    out = {}
    for probe, g in _through_relation(data, name, "shear_rate_1_s", lambda f, d, g: d * g).items():
        p = data.scenario.analysis.probes[probe]
        cell = data.impacts.left_out_at(p.x, p.z)
        if cell is not None and cell.size == c0s.size:
            cov = jackknife_covariance(c0s + c1s * g, cell)
            if math.isfinite(cov):
                out[probe] = cov
    return out


def impact_maps(data: StudyData) -> bytes:
    """Mean ball-ball normal impact speed: the DEM's measured impacts of the averaging window by
    cell (cells with at least MIN_IMPACTS_PER_CELL impacts), against each continuum method's
    inference in the probe cells, on one colour scale."""
    names = data.methods
    fig, axes = _panels(len(names))
    top = _bed_top(data)
    imp = data.impacts
    inferred = {name: inferred_impact_speeds(data, name) for name in data.continuum_methods}
    imaps = {name: data.continuum_shear_map(name, "impact_ball_ball")
             for name in data.continuum_methods}
    vals = [m[2].ravel() for m in imaps.values() if m is not None]
    if imp is not None:
        vals.append(imp.mean_speed[imp.count >= MIN_IMPACTS_PER_CELL])
    vals += [np.asarray(list(v.values()), dtype=float) for v in inferred.values()]
    allv = np.concatenate(vals) if vals else np.zeros(0)
    allv = allv[np.isfinite(allv)]
    norm = Normalize(0.0, float(allv.max()) if allv.size else 1.0)
    cmap = "cividis"
    mappable = None
    h = float(data.scenario.analysis.cell_size)
    for ax, name in zip(axes, names):
        if name == "dem":
            if imp is None:
                ax.text(0.5, 0.5, data.notes.get("impacts", "no measured impacts"),
                        ha="center", va="center", transform=ax.transAxes, wrap=True)
            else:
                ok = imp.count >= MIN_IMPACTS_PER_CELL
                ix = np.rint(imp.x[ok] / h).astype(int)
                iz = np.rint(imp.z[ok] / h).astype(int)
                if ok.any():
                    grid = np.full((iz.max() - iz.min() + 1, ix.max() - ix.min() + 1), np.nan)
                    grid[iz - iz.min(), ix - ix.min()] = imp.mean_speed[ok]
                    xs = np.arange(ix.min(), ix.max() + 1) * h
                    zs = np.arange(iz.min(), iz.max() + 1) * h
                    mappable = ax.pcolormesh(xs, zs, grid, shading="nearest", cmap=cmap,
                                             norm=norm)
                ax.text(0.03, 0.97, f"{int(imp.count.sum())} impacts measured",
                        ha="left", va="top", transform=ax.transAxes, fontsize=8)
            ax.set_title("dem: measured ball-ball impacts", fontsize=9)
        else:
            mappable, k = _continuum_map(ax, data, imaps.get(name), inferred[name], norm, cmap,
                                         mappable)
            if k is None:
                ax.set_title(f"{name}: inferred from its shear-rate map", fontsize=9)
            else:
                if k == 0:
                    why = ("no calibrated impact relation"
                           if data.impact_fit("ball_ball") is None else "no probe shear rates")
                    ax.text(0.5, 0.6, f"no inferred impacts:\n{why}", ha="center",
                            va="center", transform=ax.transAxes, fontsize=9)
                v = data.summary["methods"][name].get("impacts", {}).get(
                    "ball_ball_mean_normal_speed")
                if isinstance(v, (int, float)) and math.isfinite(v):
                    ax.text(0.03, 0.97, f"bed mean (inferred) {v:.3g} m/s", ha="left",
                            va="top", transform=ax.transAxes, fontsize=8)
                ax.set_title(f"{name}: inferred from its shear rate", fontsize=9)
        _outline(ax, data, top)
        _probes(ax, data)
    if mappable is not None:
        fig.colorbar(mappable, ax=axes, shrink=0.8, label="mean normal impact speed (m/s)")
    fig.suptitle("ball-ball impact speed: DEM measured vs continuum inferred "
                 "(v = c0 + c1 d gamma_dot)")
    return png_bytes(fig)


def _upper(values) -> float:
    """The 99th percentile of a map's positive values (0 when it has none)."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v) & (v > 0)]
    return float(np.percentile(v, 99)) if v.size else 0.0


def temperature_maps(data: StudyData, maps: TemperatureMaps) -> bytes:
    """The granular temperature (top row, m^2/s^2) and solid fraction (bottom row) on the
    analysis cells (report.temperature_maps): the DEM's (its phase-resolved T's cycle mean,
    then, when the fields hold it, its thermal T's), then each continuum's that carries the
    temperature beside its difference to the DEM's thermal T (or its phase-resolved T without
    one; continuum minus DEM, a diverging scale centred on 0); cells with no material in a map
    are left blank."""
    plt = pyplot()
    cols = [("DEM, phase-resolved T", maps.dem, None)]
    if maps.dem_thermal is not None:
        cols.append(("DEM, thermal T", maps.dem_thermal, None))
    ref = maps.dem_thermal if maps.dem_thermal is not None else maps.dem
    against = "DEM thermal" if maps.dem_thermal is not None else "DEM"
    for name, m in maps.continua.items():
        cols.append((name, m, None))
        cols.append((name, m, "difference"))
    n = len(cols)
    fig, axes = plt.subplots(2, n, figsize=(4.6 * n, 8.4), squeeze=False, layout="constrained")
    top = _bed_top(data)
    rows = ((T_KEY, "temperature_difference_m2_s2", "granular temperature T (m²/s²)"),
            (PHI_KEY, "solid_fraction_difference", "solid fraction"))
    for r, (key, diff_key, label) in enumerate(rows):
        # the scales end at the 99th percentile: a few hot wall cells would darken the rest
        values = [m[key] for _, m, kind in cols if m is not None and kind is None]
        hi = max([_upper(v) for v in values] + [1e-12])
        norm = Normalize(0.0, hi)
        diffs = [m[diff_key] for _, m, kind in cols if kind and m.get(diff_key) is not None]
        dhi = max([_upper(np.abs(d)) for d in diffs] + [1e-12])
        dnorm = Normalize(-dhi, dhi)
        shown = diff_shown = None
        for ax, (name, m, kind) in zip(axes[r], cols):
            if m is None or (kind and m.get(diff_key) is None):
                ax.text(0.5, 0.5, "no coarse-grained fields\n(calibration/fields.nc)", ha="center",
                        va="center", transform=ax.transAxes)
            elif kind is None:
                empty = (m[T_KEY] <= 0) & (m[PHI_KEY] <= 0)
                shown = ax.pcolormesh(maps.x, maps.z, np.where(empty, np.nan, m[key]),
                                      shading="nearest", cmap="viridis", norm=norm)
            else:
                empty = ((m[T_KEY] <= 0) & (m[PHI_KEY] <= 0)
                         & (ref[T_KEY] <= 0) & (ref[PHI_KEY] <= 0))
                diff_shown = ax.pcolormesh(maps.x, maps.z, np.where(empty, np.nan, m[diff_key]),
                                           shading="nearest", cmap="RdBu_r", norm=dnorm)
            what = f"difference (continuum − {against})" if kind else label.split(" (")[0]
            if kind and r == 0 and m.get("E_thermal") is not None:
                what += f", E = {m['E_thermal']:.2f}"
            ax.set_title(f"{name}: {what}", fontsize=9)
            _outline(ax, data, top)
        if shown is not None:
            fig.colorbar(shown, ax=list(axes[r]), shrink=0.8, label=label, extend="max")
        if diff_shown is not None:
            fig.colorbar(diff_shown, ax=list(axes[r]), shrink=0.8, label="difference",
                         extend="both")
    fig.suptitle("granular temperature (cycle means) and solid fraction")
    return png_bytes(fig)


def floor_cycle(floors: dict) -> bytes:
    """The floor's force over the bed's weight against the phase of the cycle (t f mod 1) of
    each method (name -> its summary's "floor" block, measure.floor_force), with its
    batch-means standard errors as bars, the cycle closed at phase 1, and the take-off
    level."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7.5, 4.2), layout="constrained")
    level = None
    for name, b in floors.items():
        ph = np.asarray(b.get("phases") or [], float)
        f = np.array([np.nan if v is None else v for v in b.get("force_over_weight") or []],
                     float)
        se = np.array([np.nan if v is None else v
                       for v in b.get("force_over_weight_stderr") or []], float)
        if ph.size == 0 or ph.size != f.size or f.size != se.size:
            continue
        ax.errorbar(np.append(ph, 1.0), np.append(f, f[0]), yerr=np.append(se, se[0]),
                    marker="o", ms=4, capsize=3, label=name)
        level = 0.05
    if level is not None:
        ax.axhline(level, color="0.5", lw=0.8, ls="--", label="take-off level")
        ax.legend(fontsize="small")
    ax.axhline(0.0, color="k", lw=0.6)
    ax.set_xlim(0.0, 1.0)
    ax.set_xlabel("phase of the cycle, t f mod 1")
    ax.set_ylabel("floor force / bed weight")
    return png_bytes(fig)
