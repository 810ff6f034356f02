"""The bed's unloading bulk modulus, measured in the DEM tub run itself
(docs/decisions/unloading-stiffness.md).

After each landing the bed's pressure falls from its peak to near zero within a fraction of a
cycle, and its solid fraction with it.  Over that branch of the phase-resolved coarse-grained
fields (run_fields: the pressure p and the solid fraction phi of each cell and phase bin), with
the volumetric strain eps_v = ln(phi / phi_ref) (compression positive; mass conservation:
d ln phi / dt = -div v for the solid):

* the branch is the bed's (the bed-mean over the dense cells): from the phase of the largest
  compaction (eps_v) among those from the landing's peak pressure on, through the phases after
  it while the pressure falls, up to the first at or below RELEASE_FRACTION of the peak (the
  release: beyond it the bed is in flight and dilates without stress, which is no elastic
  response).  The branch starts at the largest compaction, not at the peak pressure: the
  contacts' dashpots put the peak force before the largest overlap, and between the two the
  bed still compacts while its pressure falls;
* the changes are the material's, following the coarse-grained velocity v (relative to the
  tub), not those at a cell fixed in the tub: as the bed rises off the floor a fixed cell near
  the floor empties and one near the surface fills, by advection, not by strain.  Over each
  phase step, Delta q = q_(k+1) - q_k + dt (v . grad q)_(k+1/2) (the trapezoid; grad q by
  central differences on the grid, dt a phase bin) for q = p and q = eps_v;
* K_unload = -sum_c Delta p_c / -sum_c Delta eps_c over the branch, the secant from its start
  to its release pooled over the dense cells (each cell its own lithostatic pressure and
  packing; the ratio of sums weights the cells by their pressure drop): the stiffness that
  releases the landing's pressure over the strain the DEM takes to release it.  The response
  is far from linear (tangent_start, tangent_end: the first and the last step's pooled
  moduli).  Beside it: the same with the strain from the velocity's divergence,
  Delta eps_v = -dt tr(D)_(k+1/2) (divergence), which mass conservation makes the same
  quantity measured independently, and the secant at the fixed cells (eulerian);
* the standard error is the batch means' (the secant of each batch of whole cycles,
  measure.stats.stderr_of_batches).
"""
from __future__ import annotations

import math

import numpy as np

from vibroflow.errors import InputError
from vibroflow.measure.stats import stderr_of_batches

# a dense cell: its time-averaged solid fraction at least the tub's mu(I) cells' threshold
from .tub_rheology import DENSE_SOLID_FRACTION

#: the release: the branch ends at the first phase whose bed-mean pressure is at most this
#: fraction of the landing's peak
RELEASE_FRACTION = 0.1


def unloading_branch(bed_pressure, bed_strain=None) -> list[int]:
    """The unloading branch's phase bins (cyclic; module notes) of the bed-mean pressure (Pa)
    and volumetric strain of each phase bin (None: the branch starts at the peak pressure)."""
    p = np.asarray(bed_pressure, float)
    n = p.size
    k = int(np.nanargmax(p))
    peak = p[k]
    falling = [k]
    for step in range(1, n):
        j = (k + step) % n
        if not p[j] < p[falling[-1]]:
            break
        falling.append(j)
        if p[j] <= RELEASE_FRACTION * peak:
            break
    if bed_strain is None:
        return falling
    eps = np.asarray(bed_strain, float)
    start = int(np.argmax([eps[j] for j in falling]))
    return falling[start:]


def _pooled(dp, de):
    """-sum dp / -sum de over the cells where both are finite (Pa); NaN unless sum de < 0."""
    ok = np.isfinite(dp) & np.isfinite(de)
    d = float(de[ok].sum())
    return float(dp[ok].sum()) / d if d < 0 else math.nan


def _advection(q, v, h):
    """v . grad q (per s) on the grid: q (nx, nz), v (nx, nz, 3) (x, z components used), grid
    spacing h (m); NaN where a neighbour is missing."""
    return (v[..., 0] * np.gradient(q, h, axis=0) + v[..., 2] * np.gradient(q, h, axis=1))


def material_changes(q, velocity, steps, dt: float, h: float):
    """The material change of a field q (n_phases, nx, nz) over the phase steps (k, k+1) in
    `steps`, following `velocity` (n_phases, nx, nz, 3): a list of (nx, nz) arrays (module
    notes)."""
    out = []
    with np.errstate(invalid="ignore"):
        for k, k1 in steps:
            out.append(q[k1] - q[k] + 0.5 * dt * (_advection(q[k], velocity[k], h)
                                                  + _advection(q[k1], velocity[k1], h)))
    return out


def unloading_bulk_modulus(pressure, solid_fraction, velocity, cell_size: float,
                           frequency: float, batches: dict | None = None,
                           strain_rate=None) -> dict:
    """K_unload (module notes) from the phase-resolved pressure (Pa), solid fraction and
    velocity (m/s, relative to the tub), arrays (n_phases, nx, nz[, 3]) (NaN where no
    material), on a grid of spacing cell_size (m), the cycle's frequency (Hz); batches: each
    batch's pressure, solid_fraction and velocity (n_batches, n_phases, ...) for the standard
    error (None: NaN); strain_rate (n_phases, nx, nz, 3, 3) (1/s) for the divergence's
    cross-check (None: NaN).

    Returns a dict: bulk_modulus (Pa, the secant), bulk_modulus_stderr (Pa), divergence and
    eulerian (Pa, the cross-checks), tangent_start and tangent_end (Pa), cells, branch_phases
    (bins), branch_start and branch_end (t f of the bins), peak_pressure (the cycle's largest
    bed-mean, Pa), start_pressure and release_pressure (bed-mean, Pa), volumetric_strain (the
    material's bed-mean eps_v across the branch), strain_rate (1/s), batch_moduli; and the
    tangent law's keys (`unloading_law`).
    """
    p = np.asarray(pressure, float)
    phi = np.asarray(solid_fraction, float)
    v = np.asarray(velocity, float)
    if p.ndim != 3 or phi.shape != p.shape or v.shape != p.shape + (3,):
        raise InputError(f"pressure, solid_fraction, velocity have shapes {p.shape}, "
                         f"{phi.shape}, {v.shape}: must be (n_phases, nx, nz) and the velocity "
                         "(n_phases, nx, nz, 3)")
    if not (frequency > 0 and cell_size > 0):
        raise InputError(f"frequency = {frequency!r}, cell_size = {cell_size!r}: must be > 0")
    n_phases = p.shape[0]
    dt = 1.0 / (n_phases * frequency)
    with np.errstate(invalid="ignore"):
        dense = (np.nanmean(phi, axis=0) >= DENSE_SOLID_FRACTION) & np.all(phi > 0, axis=0)
    if not dense.any():
        raise InputError(f"unloading modulus: no cell with solid fraction >= "
                         f"{DENSE_SOLID_FRACTION} in every phase")

    def strain(phik):
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.log(np.where(phik > 0, phik, np.nan))

    eps = strain(phi)
    bed = np.array([np.nanmean(p[k][dense]) for k in range(n_phases)])
    bed_eps = np.array([np.nanmean(eps[k][dense]) for k in range(n_phases)])
    branch = unloading_branch(bed, bed_eps)
    if len(branch) < 2:
        raise InputError(f"unloading modulus: the bed's pressure does not fall after its "
                         f"largest compaction (phase bin {branch[0]} of {n_phases}); no "
                         "unloading branch")
    steps = list(zip(branch[:-1], branch[1:]))

    def changes(pk, phik, vk):
        dp = material_changes(pk, vk, steps, dt, h=cell_size)
        de = material_changes(strain(phik), vk, steps, dt, h=cell_size)
        return [a[dense] for a in dp], [a[dense] for a in de]

    dp, de = changes(p, phi, v)
    K = _pooled(sum(dp), sum(de))
    batch_moduli = []
    if batches is not None:
        bp, bphi, bv = (np.asarray(batches[k], float)
                        for k in ("pressure", "solid_fraction", "velocity"))
        for b in range(bp.shape[0]):
            bdp, bde = changes(bp[b], bphi[b], bv[b])
            batch_moduli.append(_pooled(sum(bdp), sum(bde)))
    se = float(stderr_of_batches(np.array(batch_moduli))) if len(batch_moduli) >= 2 \
        else math.nan
    div = math.nan
    if strain_rate is not None:
        tr = np.trace(np.asarray(strain_rate, float), axis1=-2, axis2=-1)
        div = _pooled(sum(dp), sum(-0.5 * dt * (tr[k] + tr[k1])[dense] for k, k1 in steps))
    eul = _pooled((p[branch[-1]] - p[branch[0]])[dense], (eps[branch[-1]] - eps[branch[0]])[dense])
    ok = np.isfinite(sum(de))
    d_eps = -float(np.mean(sum(de)[ok]))
    law = unloading_law(p, phi, v, steps, dense, dt, cell_size, bed[branch[0]],
                        bed[branch[-1]], batches)
    duration = (len(branch) - 1) * dt
    return {
        "bulk_modulus": K, "bulk_modulus_stderr": se, "divergence": div, "eulerian": eul,
        "tangent_start": _pooled(dp[0], de[0]), "tangent_end": _pooled(dp[-1], de[-1]),
        "cells": int(ok.sum()),
        "branch_phases": [int(k) for k in branch],
        "branch_start": branch[0] / n_phases, "branch_end": branch[-1] / n_phases,
        "peak_pressure": float(np.nanmax(bed)), "start_pressure": float(bed[branch[0]]),
        "release_pressure": float(bed[branch[-1]]),
        "volumetric_strain": d_eps, "strain_rate": d_eps / duration,
        "batch_moduli": [float(x) for x in batch_moduli],
        **law,
    }


def unloading_of_run(phases, batches: dict | None, frequency: float) -> dict:
    """unloading_bulk_modulus of a run's phase-resolved Dataset (run_fields: pressure,
    solid_fraction, velocity, strain_rate) and its info["phase_batches"] (None: no standard
    error)."""
    return unloading_bulk_modulus(phases["pressure"].values, phases["solid_fraction"].values,
                                  phases["velocity"].values, float(phases.attrs["cell_size_m"]),
                                  frequency, batches, phases["strain_rate"].values)


# ---- the non-linear unloading law (docs/decisions/unloading-stiffness.md, models.md 4.3) ----
#
# The tangent bulk modulus a power of the pressure, K_t = dp/d eps_v = K_ref (p / p_ref)^n.
# With P = p / p_ref and q_n(P) = (P^(1-n) - 1) / (1 - n) (ln P at n = 1), dq_n = P^-n dP, so
# along the law q_n(P) = (K_ref / p_ref) eps_v + const: over any step of any cell
# Delta q_n = A Delta eps_v with A = K_ref / p_ref.  Pooled over the dense cells by step g of
# the branch, Q_g(n) = sum_c Delta q_n and S_g = sum_c Delta eps_v (material changes, as for
# the secant), the law holds where ln(Q_g / S_g) = ln A for every step; n and ln A are the
# least squares of r_g = ln(Q_g / S_g) - ln A (Gauss-Newton; exact for two steps).

#: the pressure range of the law's cells: these percentiles of the dense cells' positive
#: pressures over the branch (the continuum clamps p to it: the law is measured there only)
LAW_PRESSURE_PERCENTILES = (5.0, 95.0)

#: the fit gives up (NaN) where the exponent leaves (-N_LIMIT, N_LIMIT): no law of the branch
N_LIMIT = 50.0


def _q_law(P, n: float):
    """q_n(P) = (P^(1-n) - 1) / (1 - n) (ln P at n = 1) and its derivative in n, P > 0."""
    lnP = np.log(P)
    x = (1.0 - n) * lnP
    small = np.abs(x) < 1e-4
    xs = np.where(small, 1.0, x)
    f = np.where(small, 1.0 + x / 2.0 + x * x / 6.0, np.expm1(xs) / xs)
    df = np.where(small, 0.5 + x / 3.0 + x * x / 8.0, (xs * np.exp(xs) - np.expm1(xs)) / xs ** 2)
    return lnP * f, -lnP * lnP * df


def fit_tangent_law(step_changes, n0: float = 0.0):
    """K_ref / p_ref (1/...: A, Pa/Pa) and n of K_t = K_ref (p / p_ref)^n (module notes) from
    the branch's steps: step_changes(n) returns, one a step, (Delta q_n, d Delta q_n / dn,
    Delta eps_v), arrays over the cells (NaN: left out).  Returns (A, n, rms of r_g, steps);
    NaN where fewer than two steps unload (S_g < 0)."""
    def groups(n):
        out = []
        for dq, ddq, de in step_changes(n):
            dq, ddq, de = (np.asarray(a, float).ravel() for a in (dq, ddq, de))
            ok = np.isfinite(dq) & np.isfinite(ddq) & np.isfinite(de)
            if ok.any() and de[ok].sum() < 0:
                out.append((float(dq[ok].sum()), float(ddq[ok].sum()), float(de[ok].sum())))
        return out

    nan = (math.nan, math.nan, math.nan, 0)
    n = float(n0)
    for _ in range(100):
        g = groups(n)
        if len(g) < 2 or not all(Q / S > 0 for Q, _, S in g):
            return nan
        r = np.array([math.log(Q / S) for Q, _, S in g])
        J = np.array([dQ / Q for Q, dQ, _ in g])
        # ln A = mean r at each n: the residual r - mean r, its Jacobian J - mean J
        rc, Jc = r - r.mean(), J - J.mean()
        if not (Jc @ Jc) > 0:
            break
        dn = -float(rc @ Jc) / float(Jc @ Jc)
        n += dn
        if not abs(n) < N_LIMIT:
            return nan
        if abs(dn) < 1e-14 * max(1.0, abs(n)):
            break
    g = groups(n)
    if len(g) < 2 or not all(Q / S > 0 for Q, _, S in g):
        return nan
    r = np.array([math.log(Q / S) for Q, _, S in g])
    if not abs(r.mean()) < 700.0:
        return nan
    return math.exp(float(r.mean())), n, float(np.sqrt(np.mean((r - r.mean()) ** 2))), len(g)


def tangent_law_of_fields(p, phi, v, steps, dense, dt: float, h: float, p_ref: float):
    """fit_tangent_law on phase fields p (Pa), phi, v (n_phases, nx, nz[, 3]) over the phase
    steps `steps` (pairs of bins), the cells `dense` (nx, nz bool), grid spacing h (m), phase
    step dt (s): the material changes of q_n(p / p_ref) and of eps_v = ln phi (module notes).
    Returns (K_ref (Pa), n, rms, steps)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        P = np.where(p > 0, p / p_ref, np.nan)
        eps = np.log(np.where(phi > 0, phi, np.nan))
    de = [a[dense] for a in material_changes(eps, v, steps, dt, h)]

    def changes(n):
        with np.errstate(invalid="ignore", divide="ignore"):
            q, dq = _q_law(P, n)
        a = material_changes(q, v, steps, dt, h)
        b = material_changes(dq, v, steps, dt, h)
        return [(x[dense], y[dense], e) for x, y, e in zip(a, b, de)]

    A, n, rms, k = fit_tangent_law(changes)
    return A * p_ref, n, rms, k


def unloading_law(p, phi, v, steps, dense, dt: float, h: float, start_pressure: float,
                  release_pressure: float, batches: dict | None = None) -> dict:
    """The tangent law K_t = K_ref (p / p_ref)^n fitted on the branch's steps (module notes):
    p_ref the geometric mean of the branch's start and release bed-mean pressures (the
    middle of the range on a log scale, where K_ref and n are least correlated); the batch
    means' standard errors from each batch's fit; p_min, p_max the LAW_PRESSURE_PERCENTILES of
    the dense cells' positive pressures over the branch.  Returns a dict: law_K_ref,
    law_K_ref_stderr, law_p_ref, law_exponent, law_exponent_stderr, law_rms (rms of the steps'
    ln residuals, 0 for two steps), law_steps, law_p_min, law_p_max (Pa or -)."""
    nan = math.nan
    p_ref = math.sqrt(start_pressure * release_pressure) if (
        start_pressure > 0 and release_pressure > 0) else nan
    out = {"law_K_ref": nan, "law_K_ref_stderr": nan, "law_p_ref": p_ref, "law_exponent": nan,
           "law_exponent_stderr": nan, "law_rms": nan, "law_steps": 0, "law_p_min": nan,
           "law_p_max": nan}
    if not math.isfinite(p_ref):
        return out
    K, n, rms, k = tangent_law_of_fields(p, phi, v, steps, dense, dt, h, p_ref)
    bins = sorted({b for s in steps for b in s})
    cells = np.concatenate([p[b][dense] for b in bins])
    cells = cells[np.isfinite(cells) & (cells > 0)]
    lo, hi = (np.percentile(cells, LAW_PRESSURE_PERCENTILES) if cells.size else (nan, nan))
    out.update(law_K_ref=K, law_exponent=n, law_rms=rms, law_steps=k, law_p_min=float(lo),
               law_p_max=float(hi))
    if batches is not None:
        bp, bphi, bv = (np.asarray(batches[x], float)
                        for x in ("pressure", "solid_fraction", "velocity"))
        fits = [tangent_law_of_fields(bp[b], bphi[b], bv[b], steps, dense, dt, h, p_ref)
                for b in range(bp.shape[0])]
        if len(fits) >= 2:
            out["law_K_ref_stderr"] = float(stderr_of_batches(np.array([f[0] for f in fits])))
            out["law_exponent_stderr"] = float(stderr_of_batches(np.array([f[1] for f in fits])))
    return out
