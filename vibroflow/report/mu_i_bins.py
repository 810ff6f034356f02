"""Binned means over the mu(I) scatter of the tub's cells: the calibration's time-averaged
cells (calibration.tub_rheology.tub_mu_i_scatter of calibration/fields.nc: I = gamma_dot d /
sqrt(p / rho_s), mu = tau_eq / p, cells with solid fraction >= its minimum), binned in log10 I
(BINS_PER_DECADE bins a decade, on whole decades), per bin the mean of mu and its standard error
std(mu, ddof=1) / sqrt(n) over the bin's cells, bins of at least MIN_PER_BIN cells; the dense
cells (solid fraction >= the calibration's dense limit) alone, as the fit uses them.  The
cells are neighbours of a 5 mm grid smoothed by a 3 mm kernel, so they are not quite
independent: the error bars are a lower bound."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vibroflow.calibration.tub_rheology import tub_mu_i_scatter
from vibroflow.continuum.rheology import mu_of_I
from vibroflow.io.pictures import pyplot
from vibroflow.report.figures import png_bytes

BINS_PER_DECADE = 4
MIN_PER_BIN = 3


@dataclass(frozen=True)
class Bins:
    """Per bin: its edges in I (lo, hi), the geometric centre, the mean of I, the mean of mu,
    its standard error and the number of cells."""

    lo: np.ndarray
    hi: np.ndarray
    centre: np.ndarray
    mean_I: np.ndarray
    mean_mu: np.ndarray
    stderr_mu: np.ndarray
    count: np.ndarray


def binned_means(I, mu, bins_per_decade: int = BINS_PER_DECADE,
                 min_per_bin: int = MIN_PER_BIN) -> Bins:
    """mu's mean and standard error in bins of log10 I (module docstring); points with
    I <= 0 or a non-finite value are left out."""
    I, mu = np.asarray(I, dtype=float), np.asarray(mu, dtype=float)
    ok = np.isfinite(I) & np.isfinite(mu) & (I > 0)
    I, mu = I[ok], mu[ok]
    if I.size == 0:
        e = np.zeros(0)
        return Bins(e, e, e, e, e, e, np.zeros(0, np.int64))
    k = np.floor(np.log10(I) * bins_per_decade + 1e-12).astype(np.int64)
    rows = []
    for b in np.unique(k):
        sel = k == b
        n = int(sel.sum())
        if n < min_per_bin:
            continue
        rows.append((10.0 ** (b / bins_per_decade), 10.0 ** ((b + 1) / bins_per_decade),
                     10.0 ** ((b + 0.5) / bins_per_decade), float(I[sel].mean()),
                     float(mu[sel].mean()), float(mu[sel].std(ddof=1) / np.sqrt(n)), n))
    cols = list(zip(*rows)) if rows else [[]] * 7
    return Bins(*(np.asarray(c, dtype=float) for c in cols[:6]),
                np.asarray(cols[6], dtype=np.int64))


def dem_bins(dem_fields) -> tuple[dict, Bins] | None:
    """The time-averaged scatter of the DEM's fields and its dense cells' bins; None without
    fields or cells."""
    if dem_fields is None or "inertial_number" not in dem_fields:
        return None
    sc = tub_mu_i_scatter(dem_fields).get("time")
    if sc is None or sc["I"].size == 0:
        return None
    d = sc["dense"]
    return sc, binned_means(sc["I"][d], sc["mu"][d])


def figure(scatter: dict, bins: Bins, fit: dict | None) -> bytes:
    """The cells' scatter (dense, dilute), the binned means with their errors and the fit."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(8.5, 4.8), layout="constrained")
    d = scatter["dense"]
    ax.scatter(scatter["I"][~d], scatter["mu"][~d], s=5, c="lightgray", alpha=0.6,
               label=f"cells, dilute ({int((~d).sum())})")
    ax.scatter(scatter["I"][d], scatter["mu"][d], s=5, c="tab:blue", alpha=0.35,
               label=f"cells, dense ({int(d.sum())})")
    ax.errorbar(bins.mean_I, bins.mean_mu, yerr=bins.stderr_mu,
                xerr=[bins.mean_I - bins.lo, bins.hi - bins.mean_I], fmt="o", color="tab:red",
                ms=6, capsize=3, label="dense cells binned in log I: mean ± standard error")
    if fit is not None:
        Ic = np.logspace(-4, 0, 200)
        ax.plot(Ic, mu_of_I(Ic, fit["mu_s"], fit["mu_2"], fit["I_0"]), "k-",
                label="calibrated mu(I)")
    ax.set_xscale("log")
    ax.set_xlim(1e-4, 1.0)
    ax.set_ylim(0.0, 1.2)
    ax.set_xlabel("inertial number I = gamma_dot d / sqrt(p / rho_s) (1)")
    ax.set_ylabel("mu = tau_eq / p (1)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title("mu(I) of the DEM's time-averaged cells, binned", fontsize=10)
    return png_bytes(fig)
