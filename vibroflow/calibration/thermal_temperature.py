"""The DEM's thermal temperature: the granular temperature of each ball's velocity about its own
snapshot's coarse-grained velocity, the agitation that a continuum's T models, as a
phase-resolved field beside the phase-resolved T of coarse_grain_run.

Why (validation.md sections 26, 28): the phase-resolved T counts each ball's departure from the
phase's mean velocity over all cycles, and in the tub that is mostly the bed's collective motion
scattering from cycle to cycle, not agitation.  Here each snapshot's velocity field V_s is
coarse-grained first with a Gaussian of width `mean_width_d` diameters (default two: several
balls, so V_s is a local mean, not the ball itself) and interpolated to each ball
(thermal_flux.thermal_velocities); the fluctuations c_i = v_i - V_s(r_i) are then coarse-grained
as the velocities are in coarse_grain_run (the same grid, kernel, phases and batches), and

    T_th = (tr K_c - P_c . V_c) / (3 rho)

of them (coarse_grain_fields' kinetic temperature of c; V_c, the phase's mean of c, is small).
A uniform flow, a rigid translation and a rigid rotation (a linear field, which a symmetric
kernel reproduces exactly away from the body's edges) have T_th = 0; Maxwellian noise of
temperature T about any of them has T_th = T (1 - 3 / N_eff), N_eff = 4 pi w^2 n the effective
number of balls under the local mean's Gaussian (width w, n balls per x-z area; measure.thermal
derives it) (tests/test_thermal_temperature.py).

The fields (SI): "thermal_temperature" (phase, x, z) m^2/s^2 with its batch-means standard
error, and its cycle mean over the phase bins (mass-weighted, as run_fields.add_cycle_means
takes the phase-resolved T's) with the standard error of the per-batch cycle means.
"""
from __future__ import annotations

import numpy as np
import xarray as xr

from vibroflow.measure.stats import stderr_of_batches

from .thermal_flux import ThermalFluxGrainer

NAME = "thermal_temperature"


class ThermalTemperatureGrainer(ThermalFluxGrainer):
    """Accumulates the thermal temperature of snapshots (module docstring; add_snapshot and
    the arguments as thermal_flux.ThermalFluxGrainer's, mean_width_d: the local mean's
    Gaussian width in diameters, thermal_flux.MEAN_WIDTH_D by default)."""

    def fields(self) -> tuple[xr.Dataset, xr.Dataset]:
        """(phase-resolved, cycle mean) Datasets: thermal_temperature (phase, x, z) and
        thermal_temperature_cycle_mean (x, z), m^2/s^2, each with <name>_stderr (batch means,
        when n_batches >= 2)."""
        ds = self.energy_flux_fields()
        ref = ds.attrs["velocity_reference"]
        attrs = {"units": "m2 s-2", "velocity_reference": ref,
                 "mean_velocity_width_m": self.mean_width_m}
        phase = xr.Dataset(attrs={"kernel": ds.attrs["kernel"], "width_m": ds.attrs["width_m"]})
        phase[NAME] = ds["temperature"].assign_attrs(
            long_name="thermal granular temperature: velocities about " + ref, **attrs)
        # cycle means: mass-weighted over the phase bins, all batches and each batch alone
        rho = ds["solid_fraction"].fillna(0.0)
        rho_b = ds["solid_fraction_batches"].fillna(0.0)
        w, w_b = rho.sum("phase"), rho_b.sum("phase")
        cm = (ds["temperature"].fillna(0.0) * rho).sum("phase") / w.where(w > 0)
        cm_b = (ds["temperature_batches"].fillna(0.0) * rho_b).sum("phase") / w_b.where(w_b > 0)
        cycle = xr.Dataset()
        cycle[NAME + "_cycle_mean"] = cm.assign_attrs(
            long_name="cycle mean of the phase-resolved thermal granular temperature "
                      "(mass-weighted over the phase bins)", **attrs)
        if "temperature_stderr" in ds:
            phase[NAME + "_stderr"] = ds["temperature_stderr"].assign_attrs(
                long_name="batch-means standard error of " + NAME, units="m2 s-2")
            cycle[NAME + "_cycle_mean_stderr"] = (
                cm.dims, np.asarray(stderr_of_batches(cm_b.values, axis=0)),
                {"units": "m2 s-2",
                 "long_name": f"batch-means standard error of {NAME}_cycle_mean"})
        return phase, cycle
