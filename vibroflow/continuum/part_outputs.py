"""What a continuum run infers at its parts: parts.nc (vibroflow.io.parts_file's schema).

Normal impact speed by patch.  The continuum sees no impact; it infers the mean normal impact
speed at a surface from its shear rate through the calibrated relation the run uses for the
tub's wall (calibration.toml [impacts.ball_wall]: v = c0 + c1 d gamma_dot, shear_outputs.
impact_relation), or from its granular temperature where the calibration prefers it
(v = max(b0 + b1 sqrt(T), 0), temperature_impacts.temperature_relation) and the run carries
T.  At a part, each patch takes the field of the analysis cells' centres (the nodes of the
phase-resolved field, measure.phase_shear) near its surface: the patch's trace in the slice's
middle plane (the nearest surface points of a fine grid of points just outside the part, each
given its patch by tub.parts.patch_of) weights each node by its solid fraction times the tent
max(0, 1 - r / (2 h)) of its distance r to the trace, averaged over the trace's points (nodes
deeper in the part than h/2 left out).  Per patch: the weighted mean shear rate, its batch-means
error from each batch's field weighted alike, put through the relation (error |c1| d se); from
T, the nodes' speeds' weighted mean with the bed-mean T's error carried through, as
temperature_impacts does.  The stderr adds the calibrated relation's own error at the patch's
shear rate or T in quadrature (measure.stats.affine_prediction_stderr,
temperature_impacts.temperature_prediction_stderr): parts.nc has one error a patch, and the
comparison with the DEM's speed needs both.  Every patch with material within two node
spacings gets a value; a patch with none (above the free surface, a box's faces at the slice's
ends, which the plane does not cut) is NaN.  Impact rates, the speed distribution and the
energy flux are NaN: the continuum infers no impact count.

Force and torque by phase: the wall law's force on each part at each sample (sampling.Samples.
part_force: the reaction of the contact forces on the material, N over the slice, tub axes) and
its torque about the part's centre (part_torque, N m: each reaction acting at its contact's
nearest surface point, part_obstacle.torque_on_part; only the y component, the depth average's
forces having no moment about x or z), averaged over the window's samples in each phase bin of
the cycle (measure.stats.phase_bins) with its batch-means error over whole cycles.
"""
from __future__ import annotations

import math

import numpy as np
import xarray as xr

from vibroflow.io.parts_file import empty_parts_dataset
from vibroflow.measure.phase_shear import PhaseShear
from vibroflow.measure.stats import (affine_prediction_stderr, batch_means, phase_bins,
                                     quadrature_stderr)
from vibroflow.tub.parts import Part, part_nearest, patch_layout, patch_of

from .sampling import Samples
from .shear_outputs import impact_relation, impact_relation_errors
from .temperature_impacts import RELATION, temperature_prediction_stderr, temperature_relation
from .temperature_outputs import temperature_map

#: a patch's value takes the nodes within REACH node spacings of its surface (module docstring)
REACH = 2.0
#: grid points across a part when tracing its surface in the plane (surface_trace)
TRACE_STEPS = 100


def surface_trace(part: Part, packed, k: int, y: float) -> tuple[np.ndarray, np.ndarray]:
    """The part's surface in the plane at y (m): points (m, 2) (x, z) m, the nearest surface
    points of a fine grid's points (TRACE_STEPS across the part) lying just outside it, and
    the patch of each (m,)."""
    if part.shape == "stl":
        tri = packed.tri[packed.tri_start[k]:packed.tri_start[k + 1]]
        ext = float(np.max(np.abs(tri[..., [0, 2]] - np.array(part.center)[[0, 2]])))
    elif part.shape == "box":
        ext = float(np.hypot(part.half_size[0], part.half_size[2]))
    else:
        ext = part.radius
    step = 2.0 * ext / TRACE_STEPS
    cx, cz = part.center[0], part.center[2]
    pts, patch = [], []
    for x in cx + np.arange(-TRACE_STEPS // 2 - 2, TRACE_STEPS // 2 + 3) * step:
        for z in cz + np.arange(-TRACE_STEPS // 2 - 2, TRACE_STEPS // 2 + 3) * step:
            gap, nx, ny, nz, sx, _, sz, feat = part_nearest(
                packed.shape, packed.prm, packed.tri, packed.tri_normal, packed.tri_start, k,
                float(x), y, float(z))
            if 0.0 <= gap < step:
                pts.append((sx, sz))
                patch.append(patch_of(packed.shape[k], packed.tri_group, nx, ny, nz, feat))
    return np.array(pts, float).reshape(-1, 2), np.array(patch, np.int64)


def patch_weights(part: Part, packed, k: int, y: float, phase: PhaseShear,
                  n_patches: int) -> np.ndarray:
    """(n_patches, nz, nx) weight of each node of `phase` in each patch's value (module
    docstring): the tent max(0, 1 - r / (REACH h)) of the node's distance r to the patch's
    trace in the plane at y, averaged over the trace's points; zero for nodes deeper in the
    part than h/2 and for patches the plane does not cut."""
    X, Z = np.meshgrid(phase.x, phase.z)
    outside = np.zeros(X.shape, bool)
    for a in range(X.shape[0]):
        for b in range(X.shape[1]):
            gap = part_nearest(packed.shape, packed.prm, packed.tri, packed.tri_normal,
                               packed.tri_start, k, float(X[a, b]), y, float(Z[a, b]))[0]
            outside[a, b] = gap > -0.5 * phase.h
    pts, patch = surface_trace(part, packed, k, y)
    w = np.zeros((n_patches,) + X.shape)
    nodes = np.stack([X.ravel(), Z.ravel()], axis=1)
    for j in range(n_patches):
        s = pts[patch == j]
        if s.size == 0:
            continue
        r = np.linalg.norm(nodes[:, None, :] - s[None, :, :], axis=2)
        tent = np.maximum(1.0 - r / (REACH * phase.h), 0.0).mean(axis=1)
        w[j] = tent.reshape(X.shape) * outside
    return w


def _weighted(field: np.ndarray, solid: np.ndarray, w: np.ndarray) -> float:
    """Sum of w solid field over sum of w solid on the finite nodes with material (NaN with
    none)."""
    m = np.isfinite(field) & (np.nan_to_num(solid) > 0) & (w > 0)
    return float(np.sum(w[m] * solid[m] * field[m]) / np.sum(w[m] * solid[m])) if m.any() \
        else float("nan")


def inferred_speeds(weights: np.ndarray, phase: PhaseShear, diameter: float, calibration,
                    samples: Samples, batch_se_T: tuple[float, float] | None
                    ) -> tuple[np.ndarray, np.ndarray, str]:
    """(mean, stderr) (n_patches,) m/s of the normal impact speed by patch from the nodes'
    weights (patch_weights; module docstring) and what it was inferred from ("" with no
    relation)."""
    n_patches = weights.shape[0]
    mean, se = np.full(n_patches, np.nan), np.full(n_patches, np.nan)
    im = calibration.impacts if calibration is not None else None
    rel = getattr(im, "ball_wall", None) if im is not None else None
    T = temperature_map(samples)
    trel = temperature_relation(rel)
    phi = np.asarray(phase.solid_fraction, float)
    where = (f"at each patch's trace in the slice's middle plane, the nodes within {REACH:g} "
             "node spacings weighted by solid fraction and a tent in distance")
    if trel is not None and T is not None and batch_se_T is not None:
        b0, b1 = trel
        T_bed, T_se = batch_se_T
        v = np.where(T > 0, np.maximum(b0 + b1 * np.sqrt(np.where(T > 0, T, 0.0)), 0.0),
                     np.nan)
        for j in range(n_patches):
            mean[j] = _weighted(v, phi, weights[j])
            if np.isfinite(mean[j]):
                run = abs(b1) * T_se / (2.0 * math.sqrt(T_bed)) if T_bed > 0 else np.nan
                on = np.isfinite(v) & (np.nan_to_num(phi) > 0) & (weights[j] > 0)
                se[j] = quadrature_stderr(run, temperature_prediction_stderr(
                    rel, np.sqrt(T[on]), weights[j][on] * phi[on]))
        return mean, se, (RELATION + " (calibration.toml [impacts.ball_wall], preferred_relation"
                          " = \"temperature\"), T the time-averaged map " + where)
    c0, c1, which = impact_relation(rel)
    if c0 is None:
        return mean, se, ""
    errors = impact_relation_errors(rel)
    for j in range(n_patches):
        g = _weighted(phase.shear_rate, phi, weights[j])
        if not np.isfinite(g):
            continue
        per = [_weighted(gb, fb, weights[j])
               for gb, fb in zip(phase.batch_shear_rate, phase.batch_solid_fraction)]
        per = [p for p in per if np.isfinite(p)]
        g_se = float(np.std(per, ddof=1) / math.sqrt(len(per))) if len(per) >= 2 else np.nan
        mean[j] = c0 + c1 * diameter * g
        se[j] = quadrature_stderr(abs(c1) * diameter * g_se,
                                  affine_prediction_stderr(diameter * g, *errors))
    return mean, se, (f"v = c0 + c1 d gamma_dot (calibration.toml [impacts.ball_wall] {which}), "
                      "gamma_dot the phase-resolved field's cycle mean " + where)


def part_dataset(method: str, scenario, parts: tuple[Part, ...], packed, calibration,
                 diameter: float, phase: PhaseShear | None, samples: Samples, times: np.ndarray,
                 batch: np.ndarray, window_s: float, bed_T: tuple[float, float] | None
                 ) -> xr.Dataset:
    """parts.nc of a continuum run (module docstring): `packed` tub.parts.pack(parts); phase
    the run's phase-resolved field; times (S,) s and batch (S,) its samples' instants and
    batches; bed_T (mean, stderr) m^2/s^2 of the bed's T (None without)."""
    run = scenario.run
    L = scenario.tub.length
    layouts = [patch_layout(p, L) for p in parts]
    speeds, how = [], set()
    for k, p in enumerate(parts):
        n = len(layouts[k][0])
        if phase is None:
            speeds.append((np.full(n, np.nan), np.full(n, np.nan)))
            continue
        w = patch_weights(p, packed, k, 0.5 * L, phase, n)
        v, se, text = inferred_speeds(w, phase, diameter, calibration, samples, bed_T)
        speeds.append((v, se))
        if text:
            how.add(text)
    inferred = ("normal_speed_mean and its stderr by patch: " + "; ".join(sorted(how))
                + "; the stderr: the run's batch-means error through the relation and the "
                "calibrated relation's own, in quadrature"
                if how else "normal_speed_mean: NaN, the run has no calibrated impact relation")
    inferred += ("; force and torque: the wall law's contact forces on the part (their "
                 "reaction on the material summed; the torque about the part's centre, each "
                 "reaction at its contact's surface point, about y only), by phase bin over "
                 "the window's samples; impact rates, "
                 "speed median and p95, energy flux: NaN, a continuum sees no impacts")
    ds = empty_parts_dataset([p.name for p in parts], [lay[0] for lay in layouts],
                             [lay[1] for lay in layouts], run.phases_per_cycle, method,
                             window_s, run.batches, inferred)
    ds.attrs["shapes"] = ", ".join(p.shape for p in parts)
    for k, (v, se) in enumerate(speeds):
        ds["normal_speed_mean"].values[k, :v.size] = v
        ds["normal_speed_mean_stderr"].values[k, :se.size] = se
    j = min(samples.j, times.size)
    if j and samples.n_parts:
        bins = phase_bins(times[:j], scenario.motion.frequency, run.phases_per_cycle)
        for var, values in (("force", samples.part_force[:j]),
                            ("torque", samples.part_torque[:j])):
            for ph in range(run.phases_per_cycle):
                sel = bins == ph
                if not sel.any():
                    continue
                m, se = batch_means(values[sel], batch[:j][sel], run.batches)
                ds[var].values[:, ph, :] = m
                ds[var + "_stderr"].values[:, ph, :] = se
    return ds

