"""Coarse-grained fields of a whole DEM run: every snapshot of the averaging
window deposited on the tub-frame grid, time-averaged over its whole cycles and phase-resolved
at the scenario's sampling phases, with batch-means standard errors (tub47.md "Procedure" 3).

`coarse_grain_run(run)` returns both Datasets; `write_fields(path, time_avg, phases)` stores
them in one NetCDF-4 file (the time averages at the root, the phase-resolved fields in the group
"phase_resolved"), read back with `read_fields`.  With thermal=True both also hold the thermal
temperature (thermal_temperature.py: the balls' velocities about each snapshot's own
coarse-grained velocity), its phase-resolved field beside the phase-resolved T and its cycle
mean beside the T's.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import xarray as xr

from vibroflow.tub.geometry import geometry_of
from vibroflow.errors import InputError
from vibroflow.io.atomic import atomic_path

from .coarse_grain import CoarseGrainer
from .dem_result import DEMResult
from .energy_flux import EnergyFluxGrainer
from .thermal_temperature import ThermalTemperatureGrainer

_CG_KEYS = ("positions_tub", "velocities_rel_tub", "radius", "mass", "contacts_i",
            "contacts_j", "contact_force", "contact_branch", "wall_particle", "wall_force",
            "wall_point")


def coarse_grain_run(run, kernel: str = "gaussian", width: float | None = None,
                     cutoff: float | None = None, cell_size: float | None = None,
                     n_phases: int | None = None, progress=None, energy_flux: bool = False,
                     thermal: bool = False):
    """Coarse-grain the averaging window of a DEM run.

    run : a DEMResult, a run directory or a dem.h5 path.
    kernel, width, cutoff : the CG kernel (coarse_grain.CoarseGrainer); width default d/2.
    cell_size : grid spacing (m), default a third of the scenario's analysis.cell_size (tub47:
        5 mm, so the 15 mm analysis cells' centres are grid points).  The fields are point values
        of the kernel-smoothed fields at the grid points; a grid spacing below about 1.5 kernel
        widths samples them densely enough that sums over the grid are integrals (the total
        mass and momentum come back to 1e-3), which a 15 mm grid with w = d/2 would not.
    n_phases : phase bins a cycle, default the scenario's run.phases_per_cycle.
    progress : optional callable(done, total) called after each snapshot.
    energy_flux : also coarse-grain the fluctuation-energy flux (energy_flux.EnergyFluxGrainer,
        the same fields bit for bit): info["energy_flux"] holds its phase-resolved Dataset.
    thermal : also the thermal temperature (thermal_temperature.ThermalTemperatureGrainer, the
        same grid, kernel, phases and batches): thermal_temperature (+ _stderr) in the
        phase-resolved Dataset, thermal_temperature_cycle_mean (+ _stderr) in the time averages.

    Returns (time_averaged, phase_resolved, info): two xarray Datasets (coarse_grain.fields) and
    a dict {snapshots, wall_time_s, contact_stress: "ball and wall" | "wall only" | "none",
    phase_batches: {"pressure", "solid_fraction", "velocity", "temperature",
    "inertial_number", "friction_coefficient"}: each batch's phase-resolved field as an array
    (n_batches, n_phases, nx, nz[, 3]), phase_leave_one_out: leave_one_out_dataset's (None with
    fewer than two batches)}.
    """
    own = not isinstance(run, DEMResult)
    res = DEMResult.open(run) if own else run
    try:
        return _coarse_grain(res, kernel, width, cutoff, cell_size, n_phases, progress,
                             energy_flux, thermal)
    finally:
        if own:
            res.close()


def _coarse_grain(res: DEMResult, kernel, width, cutoff, cell_size, n_phases, progress,
                  energy_flux=False, thermal=False):
    t_wall = time.perf_counter()
    sc = res.scenario
    d = res.diameter
    geometry = geometry_of(sc)
    n_phases = int(sc.run.phases_per_cycle if n_phases is None else n_phases)
    grainer = EnergyFluxGrainer if energy_flux else CoarseGrainer
    params = dict(cell_size=float(sc.analysis.cell_size / 3.0 if cell_size is None
                                  else cell_size),
                  kernel=kernel, width=0.5 * d if width is None else float(width),
                  cutoff=cutoff, depth=float(sc.tub.length), rho_s=res.solid_density,
                  diameter=d, n_phases=n_phases, n_batches=int(sc.run.batches))
    cg = grainer(geometry, **params)
    th = ThermalTemperatureGrainer(geometry, **params) if thermal else None
    batch, used, ph = res.window_snapshots(None, n_phases)
    for k, (s, snap) in enumerate(res.iter_snapshots(used)):
        cg.add_snapshot(**{key: snap[key] for key in _CG_KEYS if key in snap},
                        phase_bin=int(ph[s]), batch=int(batch[s]))
        if th is not None:
            th.add_snapshot(snap["positions_tub"], snap["velocities_rel_tub"], snap["radius"],
                            snap["mass"], phase_bin=int(ph[s]), batch=int(batch[s]))
        if progress is not None:
            progress(k + 1, used.size)
    contact = ("ball and wall" if res.has_ball_contacts and res.has_wall_forces else
               "ball only" if res.has_ball_contacts else
               "wall only" if res.has_wall_forces else "none")
    info = {"snapshots": int(used.size), "contact_stress": contact,
            "source": res.source, "run": str(res.path)}
    avg = cg.fields(phase_resolved=False)
    phases = cg.fields(phase_resolved=True)
    add_cycle_means(avg, phases)
    if th is not None:
        th_phase, th_cycle = th.fields()
        phases.update(th_phase.data_vars)
        avg.update(th_cycle.data_vars)
        info["thermal_mean_width_m"] = th.mean_width_m
    for ds in (avg, phases):
        ds.attrs["contact_stress"] = contact
        ds.attrs["case"] = str(sc.case)
        ds.attrs["source"] = res.source
    if energy_flux:
        info["energy_flux"] = cg.energy_flux_fields(phase_resolved=True)
    # each batch's phase-resolved fields: the unloading modulus's batch means
    # (unloading.unloading_bulk_modulus), the [kinetic] fit's jackknife (kinetic.
    # jackknife_errors) and the tub-cell [rheology] fit's (tub_rheology.jackknife_rheology)
    info["phase_batches"] = cg.batch_phase_arrays(("pressure", "solid_fraction", "velocity",
                                                   "temperature", "inertial_number",
                                                   "friction_coefficient"))
    info["phase_leave_one_out"] = leave_one_out_dataset(cg, phases)
    add_cycle_mean_errors(avg, info["phase_leave_one_out"])
    info["wall_time_s"] = time.perf_counter() - t_wall
    return avg, phases, info


#: the fields the impact relations refit without one batch (impacts, impact_temperature)
LEAVE_ONE_OUT_FIELDS = ("shear_rate", "temperature", "solid_fraction")


def leave_one_out_dataset(cg, phases: xr.Dataset) -> xr.Dataset | None:
    """The phase-resolved shear rate (1/s), temperature (m^2/s^2) and solid fraction of every
    batch but one (CoarseGrainer.leave_one_out_phase_arrays), dims (batch, phase, x, z) on the
    phase-resolved Dataset's coordinates: what the impact relations' delete-one-batch
    jackknife refits on.  None with fewer than two batches."""
    if cg.n_batches < 2:
        return None
    arrays = cg.leave_one_out_phase_arrays(LEAVE_ONE_OUT_FIELDS)
    dims = ("batch", "phase", "x", "z")
    ds = xr.Dataset({name: (dims, arrays[name], dict(phases[name].attrs))
                     for name in LEAVE_ONE_OUT_FIELDS},
                    coords={"batch": np.arange(cg.n_batches), "phase": phases["phase"].values,
                            "x": phases["x"].values, "z": phases["z"].values})
    ds.attrs["description"] = "batch b: the fields derived from every batch but b"
    return ds


#: the phase-resolved fields whose value in each batch of whole cycles fields.nc holds
#: (<name>_batches): the report's stress table takes its medians' batch-means errors from them
BATCH_FIELDS = ("pressure", "friction_coefficient")


def with_batch_fields(phases: xr.Dataset, phase_batches: dict) -> xr.Dataset:
    """The phase-resolved Dataset with each batch's BATCH_FIELDS beside their pooled fields,
    <name>_batches, dims (batch, phase, x, z) (coarse_grain_run's info["phase_batches"]; NaN
    where a batch has no snapshot of that phase); as it is with fewer than two batches."""
    first = np.asarray(phase_batches[BATCH_FIELDS[0]])
    if first.shape[0] < 2:
        return phases
    dims = ("batch", "phase", "x", "z")
    new = {f"{name}_batches": (dims, np.asarray(phase_batches[name], float),
                               {**phases[name].attrs,
                                "description": "each batch of whole cycles' own field"})
           for name in BATCH_FIELDS}
    return phases.assign(new).assign_coords(batch=np.arange(first.shape[0]))


def add_cycle_means(time_averaged: xr.Dataset, phase_resolved: xr.Dataset) -> None:
    """Add to the time averages the cycle means of the phase-resolved shear rate, temperature
    and inertial number (mass-weighted over the phase bins).

    Why: relative to the tub the bed oscillates at the vibration frequency (its balls do not
    follow the tub rigidly), so the time-averaged kinetic stress counts that oscillation of the
    local velocity as "temperature", and the time-averaged velocity field (the slow roll) has a
    much smaller shear rate than the bed feels at any instant.  The cycle means of the
    instantaneous fields are what collisions and the continuum's rheology respond to.
    """
    rho = phase_resolved["density"].fillna(0.0)
    w = rho.sum("phase")
    for name, unit, desc in (("shear_rate", "s-1", "cycle mean of the phase-resolved shear rate"),
                             ("temperature", "m2 s-2", "cycle mean of the phase-resolved "
                                                       "granular temperature"),
                             ("inertial_number", "1", "cycle mean of the phase-resolved "
                                                      "inertial number")):
        v = (phase_resolved[name].fillna(0.0) * rho).sum("phase") / w.where(w > 0)
        v.attrs.update(units=unit, long_name=desc + " (mass-weighted over the phase bins)")
        time_averaged[name + "_cycle_mean"] = v


#: the cycle means whose delete-one-batch values and jackknife errors fields.nc holds
CYCLE_MEAN_ERROR_FIELDS = ("shear_rate", "temperature")


def add_cycle_mean_errors(time_averaged: xr.Dataset, leave_one_out: xr.Dataset | None) -> None:
    """Add to the time averages, for the cycle-mean shear rate and temperature (add_cycle_means),
    their values with each batch left out, <name>_cycle_mean_leave_one_out (batch, x, z), and
    their delete-one-batch jackknife standard errors, <name>_cycle_mean_stderr (x, z; NaN where
    a left-out value is not finite): the cycle mean of a phase-resolved field's shear rate is
    not a batch mean (the gradient of a batch's velocity is not the batch's share of the
    window's gradient), so its error is the jackknife's (measure.stats.jackknife_stderr), which
    is the batch-means error for a mean.  A reader that averages the map over a region takes
    the same average of every left-out map and the jackknife of those
    (report.data.StudyData.dem_shear_rate_at).  Nothing is added with fewer than two batches."""
    if leave_one_out is None:
        return
    sf = leave_one_out["solid_fraction"].fillna(0.0)
    w = sf.sum("phase")
    n = leave_one_out.sizes["batch"]
    for name in CYCLE_MEAN_ERROR_FIELDS:
        unit = time_averaged[name + "_cycle_mean"].attrs.get("units", "")
        v = (leave_one_out[name].fillna(0.0) * sf).sum("phase") / w.where(w > 0)
        v = v.transpose("batch", "x", "z")
        v.attrs.update(units=unit, long_name=f"cycle mean of the phase-resolved {name} with "
                                             "batch b left out (solid-fraction-weighted over "
                                             "the phase bins)")
        time_averaged[name + "_cycle_mean_leave_one_out"] = v
        a = v.values
        ok = np.isfinite(a).all(axis=0)
        dev = np.where(ok, a - a.mean(axis=0), 0.0)
        se = np.where(ok, np.sqrt((n - 1) / n * np.sum(dev**2, axis=0)), np.nan)
        time_averaged[name + "_cycle_mean_stderr"] = (
            ("x", "z"), se, {"units": unit, "long_name": "delete-one-batch jackknife standard "
                                                         f"error of {name}_cycle_mean"})


def write_fields(path, time_averaged: xr.Dataset, phase_resolved: xr.Dataset | None) -> Path:
    """Write the fields to one NetCDF-4 file atomically (vibroflow.io.atomic)."""
    path = Path(path)
    with atomic_path(path) as tmp:
        time_averaged.to_netcdf(tmp, mode="w", engine="h5netcdf", invalid_netcdf=False)
        if phase_resolved is not None:
            phase_resolved.to_netcdf(tmp, mode="a", group="phase_resolved", engine="h5netcdf")
    return path


def read_fields(path, phase_resolved: bool = False) -> xr.Dataset:
    """Read fields.nc back (the time averages, or the phase-resolved group)."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"fields = {str(path)!r}: no such file")
    try:
        return xr.load_dataset(path, engine="h5netcdf",
                               group="phase_resolved" if phase_resolved else None)
    except (OSError, ValueError, KeyError) as e:
        raise InputError(f"{path}: not a vibroflow fields file ({e})") from None
