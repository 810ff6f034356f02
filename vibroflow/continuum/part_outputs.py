"""What a continuum run infers at its parts: parts.nc (vibroflow.io.parts_file's schema).

Normal impact speed by patch.  The continuum sees no impact; it infers the mean normal impact
speed at a surface from its shear rate through the calibrated relation the run uses for the
tub's wall (calibration.toml [impacts.ball_wall]: v = c0 + c1 d gamma_dot, shear_outputs.
impact_relation), or from its granular temperature where the calibration prefers it
(v = max(b0 + b1 sqrt(T), 0), temperature_impacts.temperature_relation) and the run carries
T.  At a part, the field is that of the analysis cells' centres (the nodes of the phase-resolved
field, measure.phase_shear) within a node spacing of the part's surface (signed distance from
-h/2 to h, as the U's near-wall nodes, measure.phase_shear.near_wall_nodes), each node given to
the patch of its nearest surface point (tub.parts.patch_of on the part's section at the slice's
middle): per patch the solid-fraction weighted mean shear rate with its batch-means error,
put through the relation (error |c1| d se); from T, the nodes' speeds' weighted mean with the
bed-mean T's error carried through, as temperature_impacts does.  A patch with no such node
holding material (the cylinder's sectors finer than the nodes, the slice's ends of a box) is
NaN.  Impact rates, the speed distribution and the energy flux are NaN: the continuum infers no
impact count.

Force by phase: the wall law's force on each part at each sample (sampling.Samples.part_force:
the reaction of the contact forces on the material, N over the slice, tub axes), averaged over
the window's samples in each phase bin of the cycle (measure.stats.phase_bins) with its
batch-means error over whole cycles.
"""
from __future__ import annotations

import math

import numpy as np
import xarray as xr

from vibroflow.io.parts_file import empty_parts_dataset
from vibroflow.measure.phase_shear import PhaseShear
from vibroflow.measure.stats import batch_means, phase_bins
from vibroflow.tub.parts import Part, part_nearest, patch_layout, patch_of

from .sampling import Samples
from .shear_outputs import impact_relation
from .temperature_impacts import RELATION, temperature_relation
from .temperature_outputs import temperature_map


def surface_nodes(part: Part, packed, k: int, y: float, phase: PhaseShear) -> np.ndarray:
    """(nz, nx) patch index of each node of `phase` within a node spacing of part k's surface
    (gap in (-h/2, h), module docstring); -1 elsewhere.  packed: tub.parts.pack of the run's
    parts."""
    out = np.full((phase.z.size, phase.x.size), -1, np.int64)
    shape = packed.shape[k]
    for a, z in enumerate(phase.z):
        for b, x in enumerate(phase.x):
            gap, nx, ny, nz, _, _, _, feat = part_nearest(
                packed.shape, packed.prm, packed.tri, packed.tri_normal, packed.tri_start, k,
                float(x), y, float(z))
            if -0.5 * phase.h < gap < phase.h:
                if gap < 0.0:  # the normal points inwards there; the patch is the outward one's
                    nx, ny, nz = -nx, -ny, -nz
                out[a, b] = patch_of(shape, packed.tri_group, nx, ny, nz, feat)
    return out


def inferred_speeds(patches: np.ndarray, n_patches: int, phase: PhaseShear, diameter: float,
                    calibration, samples: Samples, batch_se_T: tuple[float, float] | None
                    ) -> tuple[np.ndarray, np.ndarray, str]:
    """(mean, stderr) (n_patches,) m/s of the normal impact speed by patch (module docstring)
    and what it was inferred from ("" with no relation)."""
    mean, se = np.full(n_patches, np.nan), np.full(n_patches, np.nan)
    im = calibration.impacts if calibration is not None else None
    rel = getattr(im, "ball_wall", None) if im is not None else None
    T = temperature_map(samples)
    trel = temperature_relation(rel)
    if trel is not None and T is not None and batch_se_T is not None:
        b0, b1 = trel
        phi = np.nan_to_num(np.asarray(phase.solid_fraction, float))
        T_bed, T_se = batch_se_T
        for j in range(n_patches):
            m = (patches == j) & (phi > 0) & (T > 0)
            if m.any():
                v = np.maximum(b0 + b1 * np.sqrt(T[m]), 0.0)
                mean[j] = float(np.sum(phi[m] * v) / np.sum(phi[m]))
                se[j] = abs(b1) * T_se / (2.0 * math.sqrt(T_bed)) if T_bed > 0 else np.nan
        return mean, se, (RELATION + " (calibration.toml [impacts.ball_wall], preferred_relation"
                          " = \"temperature\"), T the time-averaged map at the analysis cells' "
                          "centres within a node spacing of the part")
    c0, c1, which = impact_relation(rel)
    if c0 is None:
        return mean, se, ""
    for j in range(n_patches):
        g, g_se = phase.weighted_mean(patches == j)
        mean[j] = c0 + c1 * diameter * g
        se[j] = abs(c1) * diameter * g_se
    return mean, se, (f"v = c0 + c1 d gamma_dot (calibration.toml [impacts.ball_wall] {which}), "
                      "gamma_dot of the phase-resolved field at the analysis cells' centres "
                      "within a node spacing of the part")


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
        patches = surface_nodes(p, packed, k, 0.5 * L, phase)
        v, se, text = inferred_speeds(patches, n, phase, diameter, calibration, samples, bed_T)
        speeds.append((v, se))
        if text:
            how.add(text)
    inferred = ("normal_speed_mean and its stderr by patch: " + "; ".join(sorted(how))
                if how else "normal_speed_mean: NaN, the run has no calibrated impact relation")
    inferred += ("; force: the wall law's contact forces on the part (their reaction on the "
                 "material summed), by phase bin over the window's samples; impact rates, "
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
        force = samples.part_force[:j]
        for ph in range(run.phases_per_cycle):
            sel = bins == ph
            if not sel.any():
                continue
            m, se = batch_means(force[sel], batch[:j][sel], run.batches)
            ds["force"].values[:, ph, :] = m
            ds["force_stderr"].values[:, ph, :] = se
    return ds

