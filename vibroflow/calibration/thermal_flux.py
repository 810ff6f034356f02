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

`thermal_velocities` does one snapshot; `ThermalFluxGrainer` accumulates snapshots with these
velocities (thermal_temperature.py's grainer is one); `thermal_energy_flux(run)` coarse-grains
the averaging window of a DEM run as run_fields.coarse_grain_run does, with these velocities,
and returns the phase-resolved energy-flux Dataset.
"""
from __future__ import annotations

import numpy as np
from scipy.interpolate import RegularGridInterpolator

from vibroflow.errors import InputError
from vibroflow.tub.geometry import geometry_of

from .coarse_grain import CoarseGrainer
from .dem_result import DEMResult
from .energy_flux import EnergyFluxGrainer

#: the local mean velocity's Gaussian width, ball diameters
MEAN_WIDTH_D = 2.0
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
    V = np.nan_to_num(np.asarray(mean_field.averaged_arrays()["velocity"], float))
    x, z = np.asarray(mean_field.x, float), np.asarray(mean_field.z, float)
    at = RegularGridInterpolator((x, z), V, bounds_error=False, fill_value=None)
    xz = np.stack([np.clip(pos[:, 0], x[0], x[-1]), np.clip(pos[:, 2], z[0], z[-1])], axis=1)
    return vel - at(xz)


class ThermalFluxGrainer:
    """Accumulates snapshots with each ball's velocity about its snapshot's own coarse-grained
    velocity (thermal_velocities; a Gaussian of mean_width_d diameters): an EnergyFluxGrainer of
    those velocities, of cell_size, depth (m), rho_s (kg/m^3), diameter (m), n_phases, n_batches,
    kernel, width (m, default d / 2), cutoff, extent (m, without a geometry) as the
    CoarseGrainer of the run's fields, so that the grids agree."""

    def __init__(self, geometry, cell_size: float, depth: float, rho_s: float, diameter: float,
                 n_phases: int, n_batches: int, kernel: str = "gaussian",
                 width: float | None = None, cutoff: float | None = None,
                 mean_width_d: float = MEAN_WIDTH_D, extent=None):
        common = dict(cell_size=float(cell_size), depth=float(depth), rho_s=rho_s,
                      diameter=float(diameter), extent=extent)
        self.mean_width_m = float(mean_width_d) * float(diameter)
        # one grid for the local mean, emptied before each snapshot
        self._mean = CoarseGrainer(geometry, kernel="gaussian", width=self.mean_width_m,
                                   **common)
        self._grainer = EnergyFluxGrainer(
            geometry, kernel=kernel, width=0.5 * diameter if width is None else float(width),
            cutoff=cutoff, n_phases=int(n_phases), n_batches=int(n_batches), **common)

    def add_snapshot(self, positions_tub, velocities_rel_tub, radius, mass, phase_bin: int,
                     batch: int, **contacts) -> None:
        """One snapshot (positions m and velocities m/s in the tub frame, radii m, masses kg;
        contacts: EnergyFluxGrainer.add_snapshot's contact arrays, for the collisional flux);
        batch < 0: not used."""
        if batch < 0:
            return
        self._mean.reset()
        c = thermal_velocities(positions_tub, velocities_rel_tub, radius, mass, self._mean)
        self._grainer.add_snapshot(positions_tub=positions_tub, velocities_rel_tub=c,
                                   radius=radius, mass=mass, phase_bin=int(phase_bin),
                                   batch=int(batch), **contacts)

    def energy_flux_fields(self):
        """The phase-resolved Dataset of EnergyFluxGrainer.energy_flux_fields of the thermal
        velocities, its attribute velocity_reference saying about what."""
        ds = self._grainer.energy_flux_fields(phase_resolved=True)
        ds.attrs["velocity_reference"] = (
            f"each snapshot's own coarse-grained velocity (Gaussian, width "
            f"{self.mean_width_m:.6g} m = {self.mean_width_m / ds.attrs['diameter_m']:g} d)")
        return ds


def thermal_energy_flux(run, width_factor: float = MEAN_WIDTH_D, n_phases: int | None = None,
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
        nb = int(sc.run.batches if n_batches is None else n_batches)
        cg = ThermalFluxGrainer(geometry, cell_size=float(sc.analysis.cell_size / 3.0),
                                depth=float(sc.tub.length), rho_s=res.solid_density,
                                diameter=d, n_phases=n_phases, n_batches=nb,
                                mean_width_d=width_factor)
        batch, used, ph = res.window_snapshots(nb, n_phases)
        for s, snap in res.iter_snapshots(used):
            cg.add_snapshot(**{k: snap[k] for k in _KEYS if k in snap}, phase_bin=int(ph[s]),
                            batch=int(batch[s]))
        ds = cg.energy_flux_fields()
        return ds
    finally:
        if own:
            res.close()
