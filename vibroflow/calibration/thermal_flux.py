"""The fluctuation-energy flux of the thermal agitation alone: each ball's velocity taken about
its own snapshot's coarse-grained velocity, not about the phase's mean over the cycles.

Why: a phase-resolved cell (energy_flux.py) counts as temperature every departure of a ball's
velocity from that phase's mean over all cycles.  In the tub that includes the cycle-to-cycle
scatter of the bed's collective motion: on tub47-quick the bed's mean vertical velocity at one
phase scatters by 0.07 - 0.19 m/s from cycle to cycle, as much as sqrt(T) of the cells (0.065 -
0.096 m/s), and most at the landing (phases 6/8, 7/8).  Carried through the contact network,
that coherent scatter is a wave, not conduction.  Here the fluctuation is c_i = v_i - V_s(r_i),
V_s the snapshot's own velocity field coarse-grained with a Gaussian of width `width` (default
two diameters: several balls, so V_s is a local mean, not the ball itself), interpolated
bilinearly to the ball; the flux, temperature and gradients are then energy_flux.py's, of c.

`thermal_velocities` does one snapshot; `thermal_energy_flux(run)` coarse-grains the averaging
window of a DEM run as run_fields.coarse_grain_run does, with these velocities, and returns the
phase-resolved energy-flux Dataset.
"""
from __future__ import annotations

import numpy as np
from scipy.interpolate import RegularGridInterpolator

from vibroflow.errors import InputError
from vibroflow.measure.stats import phase_bins
from vibroflow.tub.geometry import geometry_of

from .coarse_grain import CoarseGrainer
from .dem_result import DEMResult
from .energy_flux import EnergyFluxGrainer

_KEYS = ("positions_tub", "velocities_rel_tub", "radius", "mass", "contacts_i", "contacts_j",
         "contact_force", "contact_branch", "wall_particle", "wall_force", "wall_point")


def thermal_velocities(positions, velocities, radius, mass, mean_field: CoarseGrainer):
    """velocities (N, 3) m/s minus the snapshot's own coarse-grained velocity at each ball
    (positions (N, 3) m, tub frame), the field made by `mean_field` (an empty CoarseGrainer
    without phases, whose kernel width sets the local mean's scale); empty cells count as at
    rest, and a ball outside the grid takes the nearest edge's value."""
    if mean_field.n_snapshots != 0:
        raise InputError(f"mean_field holds {mean_field.n_snapshots} snapshots: must be empty")
    pos = np.asarray(positions, float)
    vel = np.asarray(velocities, float)
    mean_field.add_snapshot(pos, vel, radius, mass)
    f = mean_field.fields()
    V = np.nan_to_num(np.asarray(f["velocity"].values, float))
    x, z = np.asarray(f.x.values, float), np.asarray(f.z.values, float)
    at = RegularGridInterpolator((x, z), V, bounds_error=False, fill_value=None)
    xz = np.stack([np.clip(pos[:, 0], x[0], x[-1]), np.clip(pos[:, 2], z[0], z[-1])], axis=1)
    return vel - at(xz)


def thermal_energy_flux(run, width_factor: float = 2.0, n_phases: int | None = None,
                        n_batches: int | None = None):
    """The phase-resolved energy-flux Dataset (energy_flux.EnergyFluxGrainer.
    energy_flux_fields) of a DEM run's averaging window with each ball's velocity taken about
    its snapshot's coarse-grained velocity (kernel width width_factor diameters); the grid, the
    kernel of the fields (d/2), the phases and batches as run_fields.coarse_grain_run's, or
    n_batches batches of whole cycles (measure.stats) when given.
    run: a DEMResult, a run directory or a dem.h5 path."""
    if not (width_factor > 0):
        raise InputError(f"width_factor = {width_factor!r}: must be > 0 (diameters)")
    own = not isinstance(run, DEMResult)
    res = DEMResult.open(run) if own else run
    try:
        sc = res.scenario
        d = res.diameter
        geometry = geometry_of(sc)
        n_phases = int(sc.run.phases_per_cycle if n_phases is None else n_phases)
        common = dict(cell_size=float(sc.analysis.cell_size / 3.0), kernel="gaussian",
                      depth=float(sc.tub.length), rho_s=res.solid_density, diameter=d)
        nb = int(sc.run.batches if n_batches is None else n_batches)
        cg = EnergyFluxGrainer(geometry, width=0.5 * d, n_phases=n_phases, n_batches=nb,
                               **common)
        batch = res.batches(nb)
        used = np.nonzero(batch >= 0)[0]
        if used.size == 0:
            raise InputError(f"{res.path}: no snapshot in the averaging window")
        ph = phase_bins(res.times, float(sc.motion.frequency), n_phases)
        for s, snap in res.iter_snapshots(used):
            snap = {k: snap[k] for k in _KEYS if k in snap}
            snap["velocities_rel_tub"] = thermal_velocities(
                snap["positions_tub"], snap["velocities_rel_tub"], snap["radius"], snap["mass"],
                CoarseGrainer(geometry, width=width_factor * d, **common))
            cg.add_snapshot(**snap, phase_bin=int(ph[s]), batch=int(batch[s]))
        ds = cg.energy_flux_fields(phase_resolved=True)
        ds.attrs["velocity_reference"] = (f"each snapshot's own coarse-grained velocity, "
                                          f"Gaussian width {width_factor:g} d")
        return ds
    finally:
        if own:
            res.close()
