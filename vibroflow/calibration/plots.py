"""Pictures of a calibration (PNG, matplotlib's Agg backend, no display needed): the field maps
over the tub's cross-section, the mu(I) fit with the tub scatter, the wall friction, and the
impact speeds against the shear rate and temperature.  Each function writes one file atomically
and returns its path.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.colors import LogNorm

from vibroflow.continuum.rheology import mu_of_I, phi_of_I
from vibroflow.io.atomic import atomic_path
from vibroflow.io.pictures import pyplot


def _save(fig, path) -> Path:
    path = Path(path)
    try:
        with atomic_path(path) as tmp:  # its name ends with path's: savefig picks the format
            fig.savefig(tmp, dpi=110, bbox_inches="tight")
    finally:
        pyplot().close(fig)
    return path


def _outline(ax, geometry) -> None:
    prof = geometry.profile(300)
    ax.plot(prof[:, 0], prof[:, 1], "k-", lw=1.2)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("z (m)")


def field_maps(path, fields, geometry, min_solid_fraction: float = 0.05) -> Path:
    """Solid fraction, velocity relative to the tub (arrows on its magnitude), shear rate and
    granular temperature over the cross-section, from the time-averaged fields."""
    plt = pyplot()

    x = fields["x"].values
    z = fields["z"].values
    phi = fields["solid_fraction"].values
    bed = phi >= min_solid_fraction
    vel = fields["velocity"].values
    vx = np.where(bed, vel[..., 0], np.nan)
    vz = np.where(bed, vel[..., 2], np.nan)
    speed = np.hypot(vx, vz)
    # the cycle means of the instantaneous fields (run_fields.add_cycle_means: the time-averaged
    # temperature would count the bed's oscillation relative to the tub)
    gname = "shear_rate_cycle_mean" if "shear_rate_cycle_mean" in fields else "shear_rate"
    tname = "temperature_cycle_mean" if "temperature_cycle_mean" in fields else "temperature"
    gam = np.where(bed, fields[gname].values, np.nan)
    T = np.where(bed, fields[tname].values, np.nan)
    X, Z = np.meshgrid(x, z, indexing="ij")
    fig, axes = plt.subplots(2, 2, figsize=(11, 9))
    panels = [
        (axes[0, 0], np.where(bed, phi, np.nan), "solid fraction", None, "viridis"),
        (axes[0, 1], speed, "|v| relative to the tub (m/s)", None, "magma"),
        (axes[1, 0], gam, "shear rate, cycle mean (1/s)", "log", "plasma"),
        (axes[1, 1], T, "granular temperature, cycle mean (m$^2$/s$^2$)", "log", "inferno"),
    ]
    for ax, data, title, scale, cmap in panels:
        norm = None
        if scale == "log":
            good = data[np.isfinite(data) & (data > 0)]
            if good.size:
                norm = LogNorm(vmin=max(good.min(), good.max() * 1e-4), vmax=good.max())
            data = np.where(data > 0, data, np.nan)
        m = ax.pcolormesh(X, Z, data, shading="nearest", cmap=cmap, norm=norm)
        fig.colorbar(m, ax=ax, shrink=0.8)
        _outline(ax, geometry)
        ax.set_title(title)
    ax = axes[0, 1]
    # arrows about every 15 mm, so that they can be read on a fine grid
    step = max(1, int(round(0.015 / max(float(x[1] - x[0]), 1e-12)))) if x.size > 1 else 1
    sub = np.zeros_like(bed)
    sub[::step, ::step] = True
    sel = bed & sub
    ax.quiver(X[sel], Z[sel], vx[sel], vz[sel], color="white", scale=None, width=0.004)
    case = fields.attrs.get("case", "")
    fig.suptitle(f"{case}: coarse-grained fields, time-averaged over the window "
                 f"({fields.attrs.get('n_snapshots', '?')} snapshots, kernel "
                 f"{fields.attrs.get('kernel', '?')} w = {1e3 * fields.attrs.get('width_m', 0):.2f}"
                 f" mm)")
    return _save(fig, path)


def mu_i_plot(path, scatter: dict, shear_cell_points=None, fit=None, phi_fit=None) -> Path:
    """mu(I) and phi(I): the tub's phase-resolved cells (dense and dilute marked), the shear
    cell's steady points with error bars, and the fitted curves."""
    plt = pyplot()
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(12, 4.8))
    ph = scatter.get("phase") or scatter.get("time")
    if ph is not None and ph["I"].size:
        d = ph["dense"]
        a1.scatter(ph["I"][d], ph["mu"][d], s=6, c="tab:blue", alpha=0.4,
                   label=f"tub cells, dense (phi >= 0.5), {int(d.sum())}")
        a1.scatter(ph["I"][~d], ph["mu"][~d], s=6, c="lightgray", alpha=0.5,
                   label=f"tub cells, dilute, {int((~d).sum())}")
        a2.scatter(ph["I"][d], ph["phi"][d], s=6, c="tab:blue", alpha=0.4, label="tub, dense")
        a2.scatter(ph["I"][~d], ph["phi"][~d], s=6, c="lightgray", alpha=0.5,
                   label="tub, dilute")
    Ilo, Ihi = 1e-4, 1.0
    if shear_cell_points:
        I = np.array([p["I"] for p in shear_cell_points])
        a1.errorbar(I, [p.get("mu_eq", p["mu"]) for p in shear_cell_points],
                    xerr=[p.get("I_stderr", 0.0) for p in shear_cell_points],
                    yerr=[p.get("mu_eq_stderr", p.get("mu_stderr", 0.0))
                          for p in shear_cell_points], fmt="o",
                    color="tab:red", ms=6, capsize=3, label="shear cell (steady)")
        a2.errorbar(I, [p["phi"] for p in shear_cell_points],
                    yerr=[p.get("phi_stderr", 0.0) for p in shear_cell_points], fmt="o",
                    color="tab:red", ms=6, capsize=3, label="shear cell")
    Ic = np.logspace(np.log10(Ilo), np.log10(Ihi), 200)
    if fit is not None and np.isfinite(fit.get("mu_s", np.nan)):
        a1.plot(Ic, mu_of_I(Ic, fit["mu_s"], fit["mu_2"], fit["I_0"]), "k-",
                label=(f"fit: mu_s={fit['mu_s']:.3f}, mu_2={fit['mu_2']:.3f}, "
                       f"I_0={fit['I_0']:.3g} ({fit.get('source', '')})"))
    if phi_fit is not None and np.isfinite(phi_fit.get("phi_max", np.nan)):
        a2.plot(Ic, phi_of_I(Ic, phi_fit["phi_max"], phi_fit["phi_min"]), "k-",
                label=f"fit: phi_max={phi_fit['phi_max']:.3f}, phi_min={phi_fit['phi_min']:.3f}")
    for ax, lab in ((a1, "mu = tau_eq / p"), (a2, "solid fraction phi")):
        ax.set_xscale("log")
        ax.set_xlim(Ilo, Ihi)
        ax.set_xlabel("inertial number I")
        ax.set_ylabel(lab)
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
    a1.set_ylim(0.0, 1.0)
    a2.set_ylim(0.3, 0.7)
    fig.suptitle("rheology: mu(I) and phi(I)")
    return _save(fig, path)


def wall_friction_plot(path, wf: dict) -> Path:
    """Histogram of |F_t|/F_n (tub wall, partitions) and its profile along the U wall."""
    plt = pyplot()
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(12, 4.6))
    h = wf["histogram"]
    e = np.asarray(h["edges"])
    c = 0.5 * (e[1:] + e[:-1])
    w = e[1] - e[0]
    tw = wf["tub_wall"]
    cw = np.asarray(h["counts_wall"], float)
    if cw.sum() > 0:
        a1.bar(c, cw / (cw.sum() * w), width=w, alpha=0.6, color="tab:blue",
               label=f"tub wall ({tw['count']} contacts)")
    cp = np.asarray(h["counts_partitions"], float)
    if cp.sum() > 0:
        a1.bar(c, cp / (cp.sum() * w), width=w, alpha=0.4, color="tab:green",
               label="partitions")
    for val, style, lab in ((tw["contact_friction"], "k--", "contact mu"),
                            (tw["ratio_of_sums"], "r-", "ratio of sums (effective)"),
                            (tw["mean_ft_over_fn"], "b:", "mean of ratios"),
                            (tw["coherent_slip_friction"], "m-.", "coherent, slipping patches")):
        if val is not None and np.isfinite(val):
            a1.axvline(val, color=style[0], ls=style[1:], label=f"{lab}: {val:.3f}")
    a1.set_xlabel("|F_t| / F_n")
    a1.set_ylabel("probability density")
    a1.legend(fontsize=7)
    pr = wf["profile"]
    edges = np.asarray(pr["arc_edges_m"])
    s = 0.5 * (edges[1:] + edges[:-1])
    a2.plot(s, pr["mean_ft_over_fn"], "b.-", label="mean |F_t|/F_n")
    a2.plot(s, pr["ratio_of_sums"], "r.-", label="sum|F_t| / sum F_n")
    a2.plot(s, pr["mobilised_friction"], "m.-", label="sum F_s / sum F_n (signed, along s)")
    a2.plot(s, pr["sliding_fraction"], "k.--", label="sliding fraction")
    a2.axhline(0.0, color="gray", lw=0.5)
    a2.set_xlabel("arc position s along the U from the bottom, + towards +x (m)")
    a2.set_ylabel("friction ratio F_t / F_n, sliding fraction (1)")
    a2.legend(fontsize=7)
    a2.grid(alpha=0.3)
    fig.suptitle("ball-tub wall contacts at the sampled instants")
    return _save(fig, path)


def impacts_plot(path, rel: dict) -> Path:
    """Mean impact speed by cell against d gamma_dot and sqrt(T), with the fits; the
    distributions of the normal approach speed."""
    plt = pyplot()
    fig, axes = plt.subplots(1, 3, figsize=(16, 4.6))
    d = rel["diameter"]
    colors = {"ball_ball": "tab:blue", "ball_wall": "tab:red"}
    for name, col in colors.items():
        r = rel.get(name)
        if r is None:
            continue
        cells = r["cells"]
        x = d * np.asarray(cells["shear_rate"])
        axes[0].scatter(x, cells["mean_speed"], s=10, c=col, alpha=0.6, label=name)
        fg = r["fit_shear_rate"]
        if np.isfinite(fg["c1"]) and x.size:
            xx = np.linspace(0, x.max(), 50)
            axes[0].plot(xx, fg["c0"] + fg["c1"] * xx, "-", color=col,
                         label=f"v = {fg['c0']:.3f} + {fg['c1']:.2f} d gamma_dot, "
                               f"R2 = {fg['r2']:.2f}")
        sT = np.sqrt(np.asarray(cells["temperature"]))
        axes[1].scatter(sT, cells["mean_speed"], s=10, c=col, alpha=0.6, label=name)
        ft = r["fit_temperature"]
        if np.isfinite(ft["c1"]) and sT.size:
            xx = np.linspace(0, sT.max(), 50)
            axes[1].plot(xx, ft["c1"] * xx, "-", color=col,
                         label=f"v = {ft['c1']:.2f} sqrt(T), R2 = {ft['r2']:.2f}")
            axes[1].plot(xx, ft["maxwell"] * xx, ":", color=col,
                         label=f"Maxwellian {ft['maxwell']:.2f} sqrt(T)")
        h = r["histogram"]
        e = np.asarray(h["edges"])
        cnt = np.asarray(h["counts"], float)
        axes[2].step(0.5 * (e[1:] + e[:-1]), cnt / max(cnt.sum() * (e[1] - e[0]), 1e-300),
                     where="mid", color=col,
                     label=f"{name}: mean {r['mean_normal_speed']:.3f} m/s, {r['count']} impacts")
    axes[0].set_xlabel("d gamma_dot (m/s)")
    axes[0].set_ylabel("mean normal approach speed (m/s)")
    axes[1].set_xlabel("sqrt(T) (m/s)")
    axes[1].set_ylabel("mean normal approach speed (m/s)")
    axes[2].set_xlabel("normal approach speed (m/s)")
    axes[2].set_ylabel("probability density")
    axes[2].set_yscale("log")
    for ax in axes:
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
    fig.suptitle("impacts by cell against the coarse-grained shear rate and temperature")
    return _save(fig, path)


def temperature_relations_plot(path, rel_T: dict | None, conductivity: dict | None) -> Path:
    """Left, middle: the mean and p95 impact speeds of each (phase, cell) against sqrt(T), with
    the affine fit, the Maxwellian line and the shear rate's R^2 beside the temperature's
    (impact_temperature); right: the conductivity's multiplier of Gidaspow's closure by
    solid-fraction bin with batch-means errors ([kinetic.conductivity])."""
    plt = pyplot()
    fig, axes = plt.subplots(1, 3, figsize=(16, 4.6))
    colors = {"ball_ball": "tab:blue", "ball_wall": "tab:red"}
    for name, col in colors.items():
        r = (rel_T or {}).get(name)
        if not isinstance(r, dict):
            continue
        c = r["cells"]
        for ax, stat, maxwell in ((axes[0], "mean", r["maxwell_mean"]),
                                  (axes[1], "p95", r["maxwell_p95"])):
            ax.scatter(c["sqrt_T"], c[stat], s=4, c=col, alpha=0.25, label=name)
            f, g = r[stat]["temperature_affine"], r[stat]["shear_rate"]
            xx = np.linspace(0.0, float(np.max(c["sqrt_T"])), 50)
            ax.plot(xx, np.maximum(f["c0"] + f["c1"] * xx, 0.0), "-", color=col,
                    label=f"{f['c0']:.3f} + {f['c1']:.2f} sqrt(T): R2 {f['r2']:.2f} "
                          f"(shear rate's {g['r2']:.2f})")
            ax.plot(xx, maxwell * xx, ":", color=col, label=f"Maxwellian {maxwell:.2f} sqrt(T)")
    for ax, stat in ((axes[0], "mean"), (axes[1], "95th percentile")):
        ax.set_xlabel("sqrt(T) (m/s)")
        ax.set_ylabel(f"{stat} normal impact speed (m/s)")
    ax = axes[2]
    if conductivity is not None:
        e = np.asarray(conductivity["solid_fraction_edges"])
        m = np.asarray(conductivity["multiplier_by_solid_fraction"], float)
        se = np.asarray(conductivity["multiplier_by_solid_fraction_stderr"], float)
        ax.errorbar(0.5 * (e[1:] + e[:-1]), m, yerr=se, xerr=0.5 * np.diff(e), fmt="o",
                    label="multiplier C by solid fraction")
        ax.axhline(conductivity["multiplier"], color="k",
                   label=f"all cells: C = {conductivity['multiplier']:.3g} +- "
                         f"{conductivity['multiplier_stderr']:.2g}, R2 "
                         f"{conductivity['r2']:.3g}")
        ax.axhline(1.0, color="k", ls=":", label="Gidaspow (1994) as it is")
    ax.set_xlabel("solid fraction")
    ax.set_ylabel("q = -C kappa grad T: C")
    for a in axes:
        a.legend(fontsize=7)
        a.grid(alpha=0.3)
    fig.suptitle("the DEM's impacts against the granular temperature, and its energy flux "
                 "against the conductivity closure")
    return _save(fig, path)
