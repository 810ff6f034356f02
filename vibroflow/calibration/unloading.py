"""The bed's unloading bulk modulus, measured in the DEM tub run itself
(docs/decisions/unloading-stiffness.md).

After each landing the bed's pressure falls from its peak to near zero within a fraction of a
cycle, and its solid fraction with it.  Over that branch of the phase-resolved coarse-grained
fields (run_fields: the pressure p and the solid fraction phi of each cell and phase bin),

    K_unload = dp / d eps_v,   eps_v = ln(phi / phi_ref)   (compression positive; mass
    conservation: d ln phi / dt = -div v for the solid)

fitted by least squares within each cell (each cell its own intercept: the lithostatic
pressure and the packing differ from cell to cell, the slope is the material's) and pooled over
the dense cells.  The branch is the bed's: the phase of the largest bed-mean pressure (the
landing's peak) and the phases after it while the bed-mean pressure falls, up to the first one
at or below RELEASE_FRACTION of the peak (the release: beyond it the bed is in flight and
dilates without stress, which is no elastic response).  The standard error is the batch means'
(the same fit on each batch of whole cycles, measure.stats.stderr_of_batches).
"""
from __future__ import annotations

import math

import numpy as np

from vibroflow.errors import InputError
from vibroflow.measure.stats import stderr_of_batches

#: a dense cell: its time-averaged solid fraction at least this (tub_rheology's dense cells)
DENSE_SOLID_FRACTION = 0.5
#: the release: the branch ends at the first phase whose bed-mean pressure is at most this
#: fraction of the landing's peak
RELEASE_FRACTION = 0.1
#: the phases a branch needs for a slope
MIN_BRANCH_PHASES = 2


def unloading_branch(bed_pressure) -> list[int]:
    """The unloading branch's phase bins: from the largest of `bed_pressure` (the bed-mean
    pressure of each phase bin, Pa, cyclic) through the phases after it while it falls, up to
    the first at or below RELEASE_FRACTION of the peak (included)."""
    p = np.asarray(bed_pressure, float)
    n = p.size
    k = int(np.nanargmax(p))
    peak = p[k]
    branch = [k]
    for step in range(1, n):
        j = (k + step) % n
        if not p[j] < p[branch[-1]]:
            break
        branch.append(j)
        if p[j] <= RELEASE_FRACTION * peak:
            break
    return branch


def _within_cell_slope(p, eps):
    """The pooled within-cell least-squares slope of p on eps: arrays (n_branch, n_cells);
    (slope, R^2 of the within-cell fit, number of cells)."""
    ok = np.all(np.isfinite(p) & np.isfinite(eps), axis=0)
    p, eps = p[:, ok], eps[:, ok]
    if p.shape[1] == 0:
        return math.nan, math.nan, 0
    dp = p - p.mean(axis=0)
    de = eps - eps.mean(axis=0)
    sxx = float((de * de).sum())
    if not sxx > 0:
        return math.nan, math.nan, int(p.shape[1])
    slope = float((de * dp).sum()) / sxx
    syy = float((dp * dp).sum())
    r2 = 1.0 - float(((dp - slope * de) ** 2).sum()) / syy if syy > 0 else math.nan
    return slope, r2, int(p.shape[1])


def unloading_bulk_modulus(pressure, solid_fraction, batch_pressure=None,
                           batch_solid_fraction=None, frequency: float | None = None) -> dict:
    """K_unload (module notes) from the phase-resolved pressure (Pa) and solid fraction, arrays
    (n_phases, nx, nz) (NaN where no material), with each batch's the same (n_batches,
    n_phases, nx, nz) for the standard error (None: NaN); frequency (Hz) for the branch's
    duration and strain rate.

    Returns a dict: bulk_modulus (Pa), bulk_modulus_stderr (Pa), r2 (the within-cell fit's),
    cells, branch_phases (bins), branch_start and branch_end (t f of the bins), peak_pressure
    and release_pressure (bed-mean, Pa), volumetric_strain (bed-mean eps_v across the branch),
    strain_rate (1/s; NaN without frequency), batch_moduli.
    """
    p = np.asarray(pressure, float)
    phi = np.asarray(solid_fraction, float)
    if p.ndim != 3 or phi.shape != p.shape:
        raise InputError(f"pressure, solid_fraction have shapes {p.shape}, {phi.shape}: must be "
                         "one (n_phases, nx, nz)")
    n_phases = p.shape[0]
    with np.errstate(invalid="ignore"):
        dense = (np.nanmean(phi, axis=0) >= DENSE_SOLID_FRACTION) & np.all(phi > 0, axis=0)
    if not dense.any():
        raise InputError(f"unloading modulus: no cell with solid fraction >= "
                         f"{DENSE_SOLID_FRACTION} in every phase")
    bed = np.array([np.nanmean(p[k][dense]) for k in range(n_phases)])
    branch = unloading_branch(bed)
    if len(branch) < MIN_BRANCH_PHASES:
        raise InputError(f"unloading modulus: the bed's pressure does not fall after its peak "
                         f"(phase bin {branch[0]} of {n_phases}); no unloading branch")

    def fit(pk, phik):
        pb = pk[branch][:, dense]
        with np.errstate(invalid="ignore", divide="ignore"):
            eb = np.log(phik[branch][:, dense])
        return _within_cell_slope(pb, eb)

    K, r2, cells = fit(p, phi)
    batch_moduli = []
    if batch_pressure is not None and batch_solid_fraction is not None:
        bp = np.asarray(batch_pressure, float)
        bphi = np.asarray(batch_solid_fraction, float)
        batch_moduli = [fit(bp[b], bphi[b])[0] for b in range(bp.shape[0])]
    se = float(stderr_of_batches(np.array(batch_moduli))) if len(batch_moduli) >= 2 \
        else math.nan
    with np.errstate(invalid="ignore", divide="ignore"):
        eps_bed = np.array([np.nanmean(np.log(phi[k][dense])) for k in branch])
    d_eps = float(eps_bed[0] - eps_bed[-1])
    duration = (len(branch) - 1) / (n_phases * frequency) if frequency else math.nan
    return {
        "bulk_modulus": K, "bulk_modulus_stderr": se, "r2": r2, "cells": cells,
        "branch_phases": [int(k) for k in branch],
        "branch_start": branch[0] / n_phases, "branch_end": branch[-1] / n_phases,
        "peak_pressure": float(bed[branch[0]]), "release_pressure": float(bed[branch[-1]]),
        "volumetric_strain": d_eps,
        "strain_rate": d_eps / duration if duration and duration > 0 else math.nan,
        "batch_moduli": [float(v) for v in batch_moduli],
    }


def unloading_of_run(phases, batches: dict | None, frequency: float) -> dict:
    """unloading_bulk_modulus of a run's phase-resolved Dataset (run_fields: pressure,
    solid_fraction) and its info["phase_batches"] (None: no standard error)."""
    batches = batches or {}
    return unloading_bulk_modulus(phases["pressure"].values, phases["solid_fraction"].values,
                                  batches.get("pressure"), batches.get("solid_fraction"),
                                  frequency)
