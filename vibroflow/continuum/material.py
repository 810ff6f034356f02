"""The continuum material of a tub run: the calibration's (calibration.toml), else tub47's
defaults with the scenario's ball diameter and density, with the options' model and switches."""
from __future__ import annotations

import dataclasses
import math

from vibroflow.errors import InputError

from .constitutive import ContinuumMaterial
from .options import ContinuumOptions


def material_of(scenario, calibration: dict | None, model: str = "mu_i",
                dilatancy: bool = False, stiffness_factor: float = 1.0,
                compaction: bool = False) -> ContinuumMaterial:
    """The continuum material: the calibration's, else tub47's defaults with the scenario's
    ball diameter and density; its elastic moduli times stiffness_factor (ContinuumOptions);
    with `dilatancy`, the calibration's [dilatancy] K_dil (measured on DEM,
    vibroflow.calibration.dilatancy) switches the peak-friction option on; with `compaction`,
    the calibration's [compaction] compaction_strain and excess_solid_fraction (measured on DEM,
    vibroflow.calibration.compaction) switch the cyclic compaction option on."""
    if calibration is not None:
        mat = ContinuumMaterial.from_calibration(calibration, model=model)
    else:
        rho_s = scenario.materials[scenario.fill.material].density
        mat = ContinuumMaterial(model=model, diameter=scenario.fill.diameter,
                                solid_density=rho_s)
    if stiffness_factor != 1.0:
        mat = dataclasses.replace(mat, bulk_modulus=mat.bulk_modulus * stiffness_factor,
                                  shear_modulus=mat.shear_modulus * stiffness_factor)
    if compaction:
        c = (calibration or {}).get("compaction", {})
        gc, ex = c.get("compaction_strain"), c.get("excess_solid_fraction")
        if not (isinstance(gc, (int, float)) and math.isfinite(gc) and gc > 0
                and isinstance(ex, (int, float)) and math.isfinite(ex) and ex >= 0):
            raise InputError(f"compaction = true: needs a calibration with a measured "
                             f"[compaction] compaction_strain > 0 and excess_solid_fraction >= 0"
                             f" (vibroflow calibrate --dilatancy); got {gc!r}, {ex!r}")
        mat = dataclasses.replace(mat, compaction_strain=float(gc),
                                  compaction_excess=float(ex))
    if not dilatancy:
        return mat
    k = (calibration or {}).get("dilatancy", {}).get("K_dil")
    if not (isinstance(k, (int, float)) and math.isfinite(k) and k > 0):
        raise InputError(f"dilatancy = true: needs a calibration with a measured [dilatancy] "
                         f"K_dil > 0 (vibroflow calibrate --dilatancy); got {k!r}")
    excess = calibration["dilatancy"].get("initial_excess_solid_fraction", 0.0)
    if not (isinstance(excess, (int, float)) and math.isfinite(excess) and excess >= 0):
        raise InputError(f"calibration [dilatancy] initial_excess_solid_fraction = {excess!r}: "
                         "must be a number >= 0")
    return dataclasses.replace(mat, dilatancy=float(k), initial_solid_fraction=(
        mat.critical_solid_fraction + float(excess)) if excess > 0 else None)



def material_for(scenario, calibration: dict | None, options: ContinuumOptions
                 ) -> ContinuumMaterial:
    """The material a run with these options uses (`material_of` with the options' model,
    dilatancy, compaction and stiffness factor); input errors name the setting."""
    mat = material_of(scenario, calibration, options.model, dilatancy=options.dilatancy,
                      stiffness_factor=options.stiffness_factor,
                      compaction=options.compaction)
    if options.bed_viscosity > 0:
        mat = dataclasses.replace(mat, bed_viscosity=float(options.bed_viscosity))
    return mat
