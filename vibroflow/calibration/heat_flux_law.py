"""Garzo & Dufty's two-term heat flux measured in the DEM's coarse-grained cells, beside the
Fourier fit of conductivity.py:

    q = -A kappa_GD(phi, T, e) grad T - B mu_GD(phi, T, e) grad phi

(vibroflow.continuum.garzo_dufty: Garzo & Dufty 1999, Phys. Rev. E 59, 5895), with q the cells'
fluctuation-energy flux, kinetic + collisional (energy_flux), and A, B the multipliers the DEM
gives the two closures (1, 1: the law as it is).

Which cells: those of the Fourier fit (conductivity.py: phase-resolved, solid fraction in
`phi_range`, T > 0, |grad T| at least `min_gradient_snr` of its batch-means error), with a
finite solid-fraction gradient, so that the two laws are judged on the same cells.

The fit: weighted least squares over the cells' x and z components, the 2 x 2 normal equations
of sum w |q + A g + B h|^2 with g = kappa_GD grad T, h = mu_GD grad phi and w = 1 / (the
batch-means error of q)^2 per component (as conductivity.py).  The standard errors are the
batch means' of the same fit done on each batch's fields alone (cells and weights kept).  The
judges: R^2 = 1 - sum w |q - q_law|^2 / sum w |q|^2, and the share of cells whose flux the law
points the right way (q . q_law > 0), both for the fitted law and for the law as it is; the
same fit by bins of solid fraction.

The cycle-mean fit (`fit_cycle_mean`): the same law on the phases' means of q, kappa_GD grad T
and mu_GD grad phi, in the cells usable at every phase: what a conduction law acting on the
cycle-averaged balance would have to carry, without the flux's oscillation over the cycle.
"""
from __future__ import annotations

import math

import numba as nb
import numpy as np

from vibroflow.continuum.garzo_dufty import gd_conductivity_kg_m_s, gd_density_coefficient_W_m
from vibroflow.continuum.kinetic_theory import KineticParameters
from vibroflow.errors import InputError
from vibroflow.measure.stats import stderr_of_batches

from .conductivity import (MIN_GRADIENT_SNR, MIN_R2, PHI_BIN_EDGES, PHI_RANGE, check_flux_inputs,
                           resolved_cells)
from .kinetic import G0_FORMS

MODEL = ("q = -A kappa(phi, T) grad T - B mu(phi, T) grad phi, kappa and mu Garzo & Dufty's "
         "(1999)")


@nb.njit(cache=True)
def _coefficients(phi, T, prm):
    kappa = np.empty(phi.size)
    mu = np.empty(phi.size)
    for k in range(phi.size):
        kappa[k] = gd_conductivity_kg_m_s(phi[k], T[k], prm)
        mu[k] = gd_density_coefficient_W_m(phi[k], T[k], prm)
    return kappa, mu


def gd_coefficients(phi, T, rho_s: float, diameter: float, restitution: float, phi_rcp: float,
                    g0_form: str = "chialvo_sundaresan"):
    """(kappa_GD (kg/(m s)), mu_GD (W/m)) at solid fractions phi and temperatures T (m^2/s^2),
    arrays of phi's shape; grains of density rho_s (kg/m^3), diameter (m), restitution e, g0
    of form `g0_form` with close packing phi_rcp."""
    phi = np.ascontiguousarray(phi, dtype=float)
    T = np.ascontiguousarray(np.broadcast_to(T, phi.shape), dtype=float)
    prm = KineticParameters(diameter_m=float(diameter), density_kg_m3=float(rho_s),
                            restitution=float(restitution), phi_rcp=float(phi_rcp),
                            g0_form=G0_FORMS[g0_form])
    k, m = _coefficients(phi.ravel(), T.ravel(), prm)
    return k.reshape(phi.shape), m.reshape(phi.shape)


def _solve(q, g, h, w):
    """(A, B) of q = -A g - B h (arrays (n, 2)), weights (n, 2); NaN when singular."""
    M = np.array([[np.sum(w * g * g), np.sum(w * g * h)], [np.sum(w * g * h), np.sum(w * h * h)]])
    r = -np.array([np.sum(w * q * g), np.sum(w * q * h)])
    try:
        return np.linalg.solve(M, r)
    except np.linalg.LinAlgError:
        return np.array([math.nan, math.nan])


def _judge(q, law, w):
    """R^2 and the share of cells the law points the right way."""
    tot = float(np.sum(w * q * q))
    res = q - law
    r2 = 1.0 - float(np.sum(w * res * res)) / tot if tot > 0 else math.nan
    return r2, float(np.mean(np.sum(q * law, axis=1) > 0))


def _fit(q, g, h, w, qb, gb, hb):
    a, b = _solve(q, g, h, w)
    per = np.array([_solve(qb[k], gb[k], hb[k], w) for k in range(qb.shape[0])])
    se = (np.asarray(stderr_of_batches(per, axis=0), float) if per.shape[0] >= 2
          else np.full(2, math.nan))
    r2, right = _judge(q, -a * g - b * h, w)
    r2_1, right_1 = _judge(q, -g - h, w)
    return {"conductivity_multiplier": float(a), "conductivity_multiplier_stderr": float(se[0]),
            "density_multiplier": float(b), "density_multiplier_stderr": float(se[1]),
            "cells": int(q.shape[0]), "r2": r2, "direction_fraction": right,
            "r2_as_is": r2_1, "direction_fraction_as_is": right_1}


def _check(flux, phi_range, rho_s, diameter):
    return check_flux_inputs(flux, phi_range, rho_s, diameter,
                             ("solid_fraction", "solid_fraction_gradient", "temperature",
                              "temperature_gradient", "energy_flux"),
                             " with the solid fraction's gradient")


def _fields(flux):
    """phi, T, grad T, grad phi, q (x, z) and the same of each batch (leading dim batch)."""
    names = ("solid_fraction", "temperature", "temperature_gradient", "solid_fraction_gradient")

    def arr(name):
        return np.asarray(flux[name].values, float)

    main = [arr(n) for n in names] + [arr("energy_flux")[..., (0, 2)]]
    per = [arr(n + "_batches") for n in names] + [arr("energy_flux_batches")[..., (0, 2)]]
    return (*main, *per)


def _usable(phi, T, gT, gp, q, phib, Tb, gTb, gpb, qb, lo, hi, axis):
    """Cells with T > 0, phi in [lo, hi] and every field finite, in the fields and in each batch
    (`axis`: the batches' axis)."""
    ok = np.isfinite(T) & (T > 0) & (phi >= lo) & (phi <= hi)
    for a in (gT, gp, q):
        ok &= np.all(np.isfinite(a), -1)
    for a in (gTb, gpb, qb):
        ok &= np.all(np.isfinite(a), axis=(axis, -1))
    ok &= np.all(np.isfinite(Tb) & (Tb > 0) & np.isfinite(phib) & (phib > 0), axis=axis)
    return ok


def fit_heat_flux_law(flux, rho_s: float, diameter: float, restitution: float, phi_rcp: float,
                      g0_form: str = "chialvo_sundaresan", phi_range=PHI_RANGE,
                      phi_bin_edges=PHI_BIN_EDGES, min_gradient_snr: float = MIN_GRADIENT_SNR,
                      weighted: bool = True, min_cells: int = 10) -> dict:
    """A and B fitted on an energy-flux Dataset (energy_flux.EnergyFluxGrainer.
    energy_flux_fields, with solid_fraction_gradient and the *_batches, *_stderr); rho_s
    (kg/m^3), diameter d (m), restitution e and the g0 closure's phi_rcp; `weighted` False:
    equal weights (the batch-means errors of q from a few batches scatter widely, and weights
    from them favour the quiet cells; equal weights favour the loud ones).

    Returns {model, conductivity_multiplier (A), density_multiplier (B), their *_stderr, cells,
    r2, direction_fraction, r2_as_is, direction_fraction_as_is (A = B = 1), density_share (the
    fitted law's B h part of q . q_law over the whole), solid_fraction_range, by_solid_fraction
    {edges, and each of those keys a list by bin}}.  InputError when fewer than `min_cells`
    cells qualify."""
    lo, hi = _check(flux, phi_range, rho_s, diameter)
    phi, T, gT, gp, q, phib, Tb, gTb, gpb, qb = _fields(flux)
    with np.errstate(invalid="ignore", divide="ignore"):
        ok = _usable(phi, T, gT, gp, q, phib, Tb, gTb, gpb, qb, lo, hi, 0)
        ok, w_all = resolved_cells(flux, ok, gT, q, min_gradient_snr, weighted)
    n = int(ok.sum())
    if n < min_cells:
        raise InputError(f"cells = {n}: the heat-flux law's fit needs at least {min_cells} cells "
                         f"with T > 0, solid fraction in [{lo:g}, {hi:g}] and a resolved "
                         "temperature gradient")
    coef = dict(rho_s=rho_s, diameter=diameter, restitution=restitution, phi_rcp=phi_rcp,
                g0_form=g0_form)
    kap, mu = gd_coefficients(phi[ok], T[ok], **coef)
    kapb, mub = gd_coefficients(phib[:, ok], Tb[:, ok], **coef)
    g, h = kap[:, None] * gT[ok], mu[:, None] * gp[ok]
    gb, hb = kapb[..., None] * gTb[:, ok], mub[..., None] * gpb[:, ok]
    w, qo, qbo = w_all[ok], q[ok], qb[:, ok]
    out = {"model": MODEL, **_fit(qo, g, h, w, qbo, gb, hb),
           "solid_fraction_range": [float(phi[ok].min()), float(phi[ok].max())]}
    law = -out["conductivity_multiplier"] * g - out["density_multiplier"] * h
    tot = float(np.sum(w * qo * law))
    out["density_share"] = (float(np.sum(w * qo * (-out["density_multiplier"] * h))) / tot
                            if tot != 0 else math.nan)
    edges = [float(e) for e in phi_bin_edges]
    keys = ("conductivity_multiplier", "conductivity_multiplier_stderr", "density_multiplier",
            "density_multiplier_stderr", "cells", "r2", "direction_fraction", "r2_as_is",
            "direction_fraction_as_is")
    rows = {k: [] for k in keys}
    for a, b in zip(edges[:-1], edges[1:]):
        sel = (phi[ok] >= a) & (phi[ok] < b)
        if sel.sum() >= min_cells:
            f = _fit(qo[sel], g[sel], h[sel], w[sel], qbo[:, sel], gb[:, sel], hb[:, sel])
        else:
            f = {k: math.nan for k in keys}
            f["cells"] = int(sel.sum())
        for k in keys:
            rows[k].append(f[k])
    out["by_solid_fraction"] = {"edges": edges, **rows}
    return out


def fit_cycle_mean(flux, rho_s: float, diameter: float, restitution: float, phi_rcp: float,
                   g0_form: str = "chialvo_sundaresan", phi_range=PHI_RANGE,
                   min_gradient_snr: float = MIN_GRADIENT_SNR, weighted: bool = True,
                   min_cells: int = 10) -> dict:
    """The same fit on the cycle means: q, kappa_GD grad T and mu_GD grad phi of each phase
    averaged over the phases (the Eulerian balance's cycle mean: div of the mean q), in the
    cells usable at every phase (solid fraction in `phi_range` at each) whose mean
    kappa_GD grad T is at least `min_gradient_snr` of its batch-means error.  Weights
    1 / (the batch-means error of the mean q)^2 (`weighted`) or equal.

    Returns fit_heat_flux_law's overall keys (no bins, no density_share).  InputError when the
    fields are not phase-resolved or fewer than `min_cells` cells qualify."""
    lo, hi = _check(flux, phi_range, rho_s, diameter)
    if "phase" not in flux["temperature"].dims:
        raise InputError("flux: no phase dimension: the cycle-mean fit needs the "
                         "phase-resolved energy flux")
    phi, T, gT, gp, q, phib, Tb, gTb, gpb, qb = _fields(flux)
    with np.errstate(invalid="ignore", divide="ignore"):
        ok = np.all(_usable(phi, T, gT, gp, q, phib, Tb, gTb, gpb, qb, lo, hi, 0), axis=0)
    coef = dict(rho_s=rho_s, diameter=diameter, restitution=restitution, phi_rcp=phi_rcp,
                g0_form=g0_form)
    kap, mu = gd_coefficients(phi[:, ok], T[:, ok], **coef)
    kapb, mub = gd_coefficients(phib[:, :, ok], Tb[:, :, ok], **coef)
    g = (kap[..., None] * gT[:, ok]).mean(axis=0)
    h = (mu[..., None] * gp[:, ok]).mean(axis=0)
    qm = q[:, ok].mean(axis=0)
    gb = (kapb[..., None] * gTb[:, :, ok]).mean(axis=1)
    hb = (mub[..., None] * gpb[:, :, ok]).mean(axis=1)
    qbm = qb[:, :, ok].mean(axis=1)
    if qb.shape[0] >= 2:
        g_se = np.asarray(stderr_of_batches(gb, axis=0), float)
        q_se = np.asarray(stderr_of_batches(qbm, axis=0), float)
        sel = (np.linalg.norm(g, axis=-1) >= min_gradient_snr * np.linalg.norm(g_se, axis=-1))
        sel &= np.all(q_se > 0, axis=-1)
        w = 1.0 / np.where(q_se > 0, q_se, 1.0) ** 2 if weighted else np.ones_like(qm)
    else:
        sel = np.ones(qm.shape[0], bool)
        w = np.ones_like(qm)
    if int(sel.sum()) < min_cells:
        raise InputError(f"cells = {int(sel.sum())}: the cycle-mean fit needs at least "
                         f"{min_cells} cells usable at every phase with a resolved mean "
                         "temperature gradient")
    return {"model": MODEL, **_fit(qm[sel], g[sel], h[sel], w[sel], qbm[:, sel], gb[:, sel],
                                   hb[:, sel])}


def heat_flux_law_table(fit: dict, cycle: dict | None = None,
                        cycle_unweighted: dict | None = None,
                        unweighted: dict | None = None) -> dict:
    """The keys fit_heat_flux_law's (weighted, and `unweighted`) and the cycle-mean fits'
    results add to calibration.toml's [kinetic.conductivity] table
    (io.calibration_file.Conductivity), each prefixed gd_."""
    out = {"gd_model": fit["model"]}
    for k in ("conductivity_multiplier", "conductivity_multiplier_stderr", "density_multiplier",
              "density_multiplier_stderr", "r2", "direction_fraction", "r2_as_is",
              "direction_fraction_as_is", "density_share"):
        out["gd_" + k] = float(fit[k])
    by = fit["by_solid_fraction"]
    for k in ("conductivity_multiplier", "conductivity_multiplier_stderr", "density_multiplier",
              "density_multiplier_stderr", "r2", "direction_fraction"):
        out[f"gd_{k}_by_solid_fraction"] = [float(v) for v in by[k]]
    for tag, c in (("unweighted", unweighted), ("cycle_mean", cycle),
                   ("cycle_mean_unweighted", cycle_unweighted)):
        if c is None:
            continue
        out[f"gd_{tag}_cells"] = int(c["cells"])
        for k in ("conductivity_multiplier", "conductivity_multiplier_stderr",
                  "density_multiplier", "density_multiplier_stderr", "r2",
                  "direction_fraction"):
            out[f"gd_{tag}_{k}"] = float(c[k])
    good = fit["r2"] >= MIN_R2
    out["gd_status"] = "measured" + ("" if good else (
        f"; R^2 = {fit['r2']:.3g}: q is not -A kappa grad T - B mu grad phi in the cells either "
        f"(the law points the flux the right way in {fit['direction_fraction']:.0%} of them, "
        f"B = {fit['density_multiplier']:.3g} against Garzo & Dufty's 1), so A and B are "
        "projections, not transport coefficients"))
    return out
