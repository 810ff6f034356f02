"""The conductivity of the fluctuation energy measured in the DEM's coarse-grained cells,
against the continuum's closure (Gidaspow 1994, vibroflow.continuum.kinetic_theory):

    q = -C kappa_G(phi, T) grad T,   kappa_G = K(phi; g0, e) rho_s d sqrt(T),

with q the cells' fluctuation-energy flux, kinetic + collisional (energy_flux), and C the
multiplier the DEM gives the closure (1: the closure as it is).

Which cells: the phase-resolved ones (T the fluctuation about each phase's mean velocity, as
for the phi_rcp fit), with solid fraction in `phi_range`, T > 0, and a temperature gradient
resolved by the window (|grad T| at least `min_gradient_snr` of its batch-means error).

The fit: least squares over the cells' x and z components, C = -sum w q . g / sum w |g|^2,
g = kappa_G grad T, weights w = 1 / (the batch-means error of q)^2 per component (equal weights
where the fields carry none).  Its standard error is the batch means' of the same fit done on
each batch's fields alone (the cells and weights kept), so it counts the window's correlated
noise; the scatter is that of the per-cell ratio -q . g / |g|^2 (weighted median, 16 and 84 %
quantiles), with R^2 = 1 - sum w |q + C g|^2 / sum w |q|^2 and the share of cells where the flux
runs down the gradient.  The same fit is done on bins of solid fraction.
"""
from __future__ import annotations

import math

import numba as nb
import numpy as np

from vibroflow.continuum.kinetic_theory import KineticParameters, conductivity_kg_m_s
from vibroflow.errors import InputError
from vibroflow.measure.stats import stderr_of_batches

from .kinetic import G0_FORMS

PHI_RANGE = (0.05, 0.6)
PHI_BIN_EDGES = (0.05, 0.2, 0.3, 0.4, 0.5, 0.55, 0.6)
MIN_GRADIENT_SNR = 2.0
#: below this R^2 the status says that Fourier's law with the closure does not describe the cells
MIN_R2 = 0.3
MODEL = "q = -C kappa(phi, T) grad T, kappa Gidaspow's (1994) conductivity"


#: the energy-flux Dataset's fields (`measure.heat_flux`) that the conductivity's fit reads
FLUX_FIELDS = ("solid_fraction", "temperature", "temperature_gradient", "energy_flux")


def check_flux_inputs(flux, phi_range, rho_s, diameter, fields, what="") -> tuple[float, float]:
    """(lo, hi) of phi_range after checking a fit's inputs: 0 < lo < hi < 1, rho_s and the
    diameter > 0, and each of `fields` and its batches in the energy-flux Dataset `flux`
    (`what`: what else the Dataset must hold).  InputError naming the first bad one."""
    lo, hi = (float(v) for v in phi_range)
    if not (0.0 < lo < hi < 1.0):
        raise InputError(f"phi_range = {tuple(phi_range)!r}: must be (lo, hi) with "
                         "0 < lo < hi < 1")
    if not (rho_s > 0 and diameter > 0):
        raise InputError(f"rho_s = {rho_s!r}, diameter = {diameter!r}: must both be > 0")
    for name in fields:
        if name not in flux or name + "_batches" not in flux:
            raise InputError(f"flux: no {name!r} (or its batches): not an energy-flux Dataset"
                             + what)
    return lo, hi


@nb.njit(cache=True)
def _factor(phi, prm):
    out = np.empty(phi.size)
    for k in range(phi.size):
        out[k] = conductivity_kg_m_s(phi[k], 1.0, prm)
    return out


def conductivity_factor(phi, restitution: float, phi_rcp: float,
                        g0_form: str = "chialvo_sundaresan") -> np.ndarray:
    """K(phi) (-) of Gidaspow's kappa = K rho_s d sqrt(T), the continuum's closure with g0 of
    form `g0_form` and close packing phi_rcp, ball-ball restitution e."""
    phi = np.ascontiguousarray(phi, dtype=float)
    prm = KineticParameters(diameter_m=1.0, density_kg_m3=1.0, restitution=float(restitution),
                            phi_rcp=float(phi_rcp), g0_form=G0_FORMS[g0_form])
    return _factor(phi.ravel(), prm).reshape(phi.shape)


def _multiplier(q, g, w):
    """C of q = -C g (arrays (n, 2)), weights (n, 2)."""
    den = float(np.sum(w * g * g))
    return -float(np.sum(w * q * g)) / den if den > 0 else float("nan")


def _weighted_quantiles(x, w, qs):
    o = np.argsort(x)
    cw = np.cumsum(w[o])
    return [float(np.interp(q * cw[-1], cw, x[o])) for q in qs]


def _fit(q, g, w, qb, gb):
    """The multiplier, its batch-means error and the scatter on the selected cells."""
    C = _multiplier(q, g, w)
    per = np.array([_multiplier(qb[b], gb[b], w) for b in range(qb.shape[0])])
    se = float(stderr_of_batches(per)) if per.size >= 2 else float("nan")
    res = q + C * g
    tot = float(np.sum(w * q * q))
    g2 = np.sum(g * g, axis=1)
    ratio = -np.sum(q * g, axis=1) / np.where(g2 > 0, g2, np.nan)
    cw = np.sum(w, axis=1) * g2      # a cell's weight in C
    ok = np.isfinite(ratio)
    lo, med, hi = _weighted_quantiles(ratio[ok], cw[ok], (0.16, 0.5, 0.84))
    return {"multiplier": C, "multiplier_stderr": se, "cells": int(q.shape[0]),
            "r2": 1.0 - float(np.sum(w * res * res)) / tot if tot > 0 else float("nan"),
            "cell_ratio_median": med, "cell_ratio_p16": lo, "cell_ratio_p84": hi,
            "down_gradient_fraction": float(np.mean(np.sum(q * g, axis=1) < 0))}


def resolved_cells(flux, ok, gT, q, min_gradient_snr: float, weighted: bool):
    """(ok narrowed to the cells whose temperature gradient is at least min_gradient_snr
    times its batch-means error and whose flux has a positive error, the fit's weights
    1 / se_q^2 (ones when not weighted or without errors)) of the flux dataset's cells."""
    if "temperature_gradient_stderr" in flux:
        se = np.asarray(flux["temperature_gradient_stderr"].values, float)
        ok = ok & (np.linalg.norm(gT, axis=-1) >= min_gradient_snr * np.linalg.norm(se, axis=-1))
    if "energy_flux_stderr" not in flux:
        return ok, np.ones_like(q)
    qse = np.asarray(flux["energy_flux_stderr"].values, float)[..., (0, 2)]
    ok = ok & np.all(qse > 0, axis=-1)
    return ok, (1.0 / np.where(qse > 0, qse, 1.0) ** 2 if weighted else np.ones_like(q))


def fit_conductivity(flux, rho_s: float, diameter: float, restitution: float, phi_rcp: float,
                     g0_form: str = "chialvo_sundaresan", phi_range=PHI_RANGE,
                     phi_bin_edges=PHI_BIN_EDGES, min_gradient_snr: float = MIN_GRADIENT_SNR,
                     min_cells: int = 10) -> dict:
    """C fitted on an energy-flux Dataset (energy_flux.EnergyFluxGrainer.energy_flux_fields:
    solid_fraction, temperature, temperature_gradient, energy_flux and their *_batches,
    *_stderr); rho_s (kg/m^3), diameter d (m), restitution e and the g0 closure's phi_rcp.

    Returns {model, multiplier, multiplier_stderr, cells, r2, cell_ratio_median, cell_ratio_p16,
    cell_ratio_p84, down_gradient_fraction, flux_magnitude_ratio_median (|q| / |kappa_G grad
    T|), solid_fraction_range, by_solid_fraction {edges, multiplier, multiplier_stderr, cells,
    r2}, kinetic_share (the kinetic part of q . g over the total), status ("measured", and
    what R^2 below MIN_R2 means)}.  InputError when fewer than `min_cells` cells qualify."""
    lo, hi = check_flux_inputs(flux, phi_range, rho_s, diameter, FLUX_FIELDS)

    def arr(name):
        return np.asarray(flux[name].values, float)

    phi, T, gT = arr("solid_fraction"), arr("temperature"), arr("temperature_gradient")
    q = arr("energy_flux")[..., (0, 2)]
    qk = arr("kinetic_energy_flux")[..., (0, 2)] if "kinetic_energy_flux" in flux else None
    Tb, gTb = arr("temperature_batches"), arr("temperature_gradient_batches")
    qb = arr("energy_flux_batches")[..., (0, 2)]
    with np.errstate(invalid="ignore", divide="ignore"):
        ok = np.isfinite(T) & (T > 0) & (phi >= lo) & (phi <= hi) & np.all(np.isfinite(gT), -1)
        ok &= np.all(np.isfinite(q), -1) & np.all(np.isfinite(gTb), axis=(0, -1))
        ok &= np.all(np.isfinite(Tb) & (Tb > 0), axis=0) & np.all(np.isfinite(qb), axis=(0, -1))
        ok, w_all = resolved_cells(flux, ok, gT, q, min_gradient_snr, weighted=True)
    n = int(ok.sum())
    if n < min_cells:
        raise InputError(f"cells = {n}: the conductivity fit needs at least {min_cells} cells "
                         f"with T > 0, solid fraction in [{lo:g}, {hi:g}] and a resolved "
                         "temperature gradient")
    K = conductivity_factor(phi[ok], restitution, phi_rcp, g0_form)
    scale = K * rho_s * diameter
    g = (scale * np.sqrt(T[ok]))[:, None] * gT[ok]
    gb = (scale * np.sqrt(Tb[:, ok]))[..., None] * gTb[:, ok]
    w, qo, qbo = w_all[ok], q[ok], qb[:, ok]
    out = {"model": MODEL, **_fit(qo, g, w, qbo, gb),
           "solid_fraction_range": [float(phi[ok].min()), float(phi[ok].max())]}
    if qk is not None:
        tot = float(np.sum(w * qo * g))
        out["kinetic_share"] = float(np.sum(w * qk[ok] * g)) / tot if tot != 0 else math.nan
    edges = [float(e) for e in phi_bin_edges]
    rows = {"multiplier": [], "multiplier_stderr": [], "cells": [], "r2": []}
    for a, b in zip(edges[:-1], edges[1:]):
        sel = (phi[ok] >= a) & (phi[ok] < b)
        if sel.sum() >= min_cells:
            f = _fit(qo[sel], g[sel], w[sel], qbo[:, sel], gb[:, sel])
        else:
            f = {"multiplier": math.nan, "multiplier_stderr": math.nan,
                 "cells": int(sel.sum()), "r2": math.nan}
        for key in rows:
            rows[key].append(f[key])
    out["by_solid_fraction"] = {"edges": edges, **rows}
    mag = np.linalg.norm(qo, axis=1) / np.linalg.norm(g, axis=1)
    out["flux_magnitude_ratio_median"] = float(np.median(mag[np.isfinite(mag)]))
    out["status"] = "measured"
    if not out["r2"] >= MIN_R2:
        out["status"] += (f"; R^2 = {out['r2']:.3g}: q is not -C kappa grad T in the cells (the "
                          f"flux runs down the gradient in {out['down_gradient_fraction']:.0%} "
                          f"of them, and its size is {out['flux_magnitude_ratio_median']:.3g} "
                          "times the closure's, median), so C is a projection, not a "
                          "conductivity")
    return out


def conductivity_table(fit: dict) -> dict:
    """The [kinetic.conductivity] table of calibration.toml (io.calibration_file.Conductivity)
    from fit_conductivity's result."""
    keys = ("model", "multiplier", "multiplier_stderr", "r2", "cells", "status",
            "cell_ratio_median", "cell_ratio_p16", "cell_ratio_p84", "down_gradient_fraction",
            "flux_magnitude_ratio_median", "kinetic_share", "solid_fraction_range")
    out = {k: fit[k] for k in keys if k in fit}
    by = fit["by_solid_fraction"]
    out.update(solid_fraction_edges=list(by["edges"]),
               multiplier_by_solid_fraction=[float(v) for v in by["multiplier"]],
               multiplier_by_solid_fraction_stderr=[float(v) for v in by["multiplier_stderr"]],
               cells_by_solid_fraction=[int(v) for v in by["cells"]],
               r2_by_solid_fraction=[float(v) for v in by["r2"]])
    return out
