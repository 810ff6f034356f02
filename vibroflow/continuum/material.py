"""The continuum material of a tub run: the calibration's (calibration.toml), else tub47's
defaults with the scenario's ball diameter and density, with the options' model and switches;
and the Coulomb friction of its wall and partitions (`boundary_friction`)."""
from __future__ import annotations

import dataclasses
import math

from vibroflow.errors import InputError
from vibroflow.io.calibration_file import Calibration
from vibroflow.scenario.checks import find_contact

from .constitutive import ContinuumMaterial, bulk_law_tangent, check_bulk_law
from .options import ContinuumOptions


def material_of(scenario, calibration: Calibration | None, model: str = "mu_i",
                dilatancy: bool = False, stiffness_factor: float = 1.0,
                compaction: bool = False, moduli: str = "calibrated") -> ContinuumMaterial:
    """The continuum material: the calibration's, else tub47's defaults with the scenario's
    ball diameter and density; its elastic moduli times stiffness_factor (ContinuumOptions);
    with `dilatancy`, the calibration's [dilatancy] K_dil (measured on DEM,
    vibroflow.calibration.dilatancy) switches the peak-friction option on; with `compaction`,
    the calibration's [compaction] compaction_strain and excess_solid_fraction (measured on DEM,
    vibroflow.calibration.compaction) switch the cyclic compaction option on; moduli
    "unloading" takes the calibration's [elastic] unloading_bulk_modulus_Pa (the bed's
    unloading branch in the DEM, vibroflow.calibration.unloading) and
    shear_modulus_small_strain_Pa (docs/decisions/unloading-stiffness.md); "unloading_law" the
    tangent law of the same branch (unloading_law_moduli)."""
    if calibration is not None:
        mat = ContinuumMaterial.from_calibration(calibration, model=model)
    elif moduli != "calibrated":
        raise InputError(f"moduli = {moduli!r}: needs a calibration (--calibration) with "
                         "[elastic] unloading_bulk_modulus_Pa (unloading) or unloading_law_* "
                         "(unloading_law)")
    else:
        rho_s = scenario.materials[scenario.fill.material].density
        mat = ContinuumMaterial(model=model, diameter=scenario.fill.diameter,
                                solid_density=rho_s)
    if moduli == "unloading":
        mat = dataclasses.replace(mat, **unloading_moduli(calibration))
    elif moduli == "unloading_law":
        mat = dataclasses.replace(mat, **unloading_law_moduli(calibration))
    if stiffness_factor != 1.0:
        law = mat.bulk_law
        if law is not None:
            law = (law[0] * stiffness_factor,) + tuple(law[1:])
        mat = dataclasses.replace(mat, bulk_modulus=mat.bulk_modulus * stiffness_factor,
                                  shear_modulus=mat.shear_modulus * stiffness_factor,
                                  bulk_law=law)
    if compaction:
        c = calibration.compaction if calibration is not None else None
        gc, ex = (None, None) if c is None else (c.compaction_strain, c.excess_solid_fraction)
        if not (gc is not None and math.isfinite(gc) and gc > 0
                and ex is not None and math.isfinite(ex) and ex >= 0):
            raise InputError(f"compaction = true: needs a calibration with a measured "
                             f"[compaction] compaction_strain > 0 and excess_solid_fraction >= 0"
                             f" (vibroflow calibrate --dilatancy); got {gc!r}, {ex!r}")
        mat = dataclasses.replace(mat, compaction_strain=float(gc),
                                  compaction_excess=float(ex))
    if not dilatancy:
        return mat
    dil = calibration.dilatancy if calibration is not None else None
    k = dil.K_dil if dil is not None else None
    if not (k is not None and math.isfinite(k) and k > 0):
        raise InputError(f"dilatancy = true: needs a calibration with a measured [dilatancy] "
                         f"K_dil > 0 (vibroflow calibrate --dilatancy); got {k!r}")
    excess = dil.initial_excess_solid_fraction
    excess = 0.0 if excess is None else excess
    if not (math.isfinite(excess) and excess >= 0):
        raise InputError(f"calibration [dilatancy] initial_excess_solid_fraction = {excess!r}: "
                         "must be a number >= 0")
    return dataclasses.replace(mat, dilatancy=float(k), initial_solid_fraction=(
        mat.critical_solid_fraction + float(excess)) if excess > 0 else None)


def unloading_moduli(calibration: Calibration) -> dict:
    """{bulk_modulus, shear_modulus} (Pa) of moduli = "unloading": the calibration's [elastic]
    unloading_bulk_modulus_Pa and shear_modulus_small_strain_Pa; InputError where either is
    missing or not > 0."""
    k = _elastic_key(calibration, "unloading", "unloading_bulk_modulus_Pa", "a modulus > 0 Pa",
                     _BRANCH)
    return {"bulk_modulus": k, "shear_modulus": _small_strain_shear(calibration, "unloading")}


_BRANCH = "vibroflow calibrate measures it on the DEM run's unloading branch"


def _elastic_key(calibration: Calibration, moduli: str, name: str, must: str, how: str,
                 positive: bool = True) -> float:
    """The calibration's [elastic] `name` (finite, and > 0 when positive) for --moduli
    `moduli`; else a one-line InputError saying what it must be (`must`) and what measures it
    (`how`)."""
    v = getattr(calibration.elastic, name, None)
    if v is None or not (math.isfinite(v) and (v > 0 or not positive)):
        raise InputError(f"moduli = {moduli!r}: the calibration's [elastic] {name} = "
                         f"{'missing' if v is None else repr(v)}; it must be {must} ({how})")
    return float(v)


def _small_strain_shear(calibration: Calibration, moduli: str) -> float:
    """shear_modulus_small_strain_Pa (Pa), what both unloading moduli take for G."""
    return _elastic_key(calibration, moduli, "shear_modulus_small_strain_Pa", "a modulus > 0 Pa",
                        "vibroflow calibrate with the cyclic shear test")


#: the unloading law's [elastic] keys: K_ref, p_ref, n, p_min, p_max (ContinuumMaterial.bulk_law)
UNLOADING_LAW_KEYS = ("unloading_law_modulus_Pa", "unloading_law_reference_pressure_Pa",
                      "unloading_law_exponent", "unloading_law_min_pressure_Pa",
                      "unloading_law_max_pressure_Pa")


def unloading_law_moduli(calibration: Calibration) -> dict:
    """{bulk_law, bulk_modulus, shear_modulus} of moduli = "unloading_law": the calibration's
    [elastic] UNLOADING_LAW_KEYS (K_t = K_ref (p / p_ref)^n on [p_min, p_max], measured on the
    DEM run's unloading branch, vibroflow.calibration.unloading.unloading_law), bulk_modulus
    its largest tangent K_t(p_max) (the time step's), shear_modulus_small_strain_Pa as
    "unloading" takes it; InputError naming the first key missing or out of range."""
    vals = [_elastic_key(calibration, "unloading_law", name,
                         "finite" if name == "unloading_law_exponent" else "> 0", _BRANCH,
                         positive=name != "unloading_law_exponent")
            for name in UNLOADING_LAW_KEYS]
    check_bulk_law(vals)
    return {"bulk_law": tuple(vals), "bulk_modulus": bulk_law_tangent(vals[4], vals),
            "shear_modulus": _small_strain_shear(calibration, "unloading_law")}


def material_for(scenario, calibration: Calibration | None, options: ContinuumOptions
                 ) -> ContinuumMaterial:
    """The material a run with these options uses (`material_of` with the options' model,
    dilatancy, compaction, stiffness factor and moduli); input errors name the setting."""
    mat = material_of(scenario, calibration, options.model, dilatancy=options.dilatancy,
                      stiffness_factor=options.stiffness_factor,
                      compaction=options.compaction, moduli=options.moduli)
    if options.bed_viscosity > 0:
        mat = dataclasses.replace(mat, bed_viscosity=float(options.bed_viscosity))
    return mat


def boundary_friction(scenario, calibration: Calibration | None, partitions: str = "contacts"):
    """(wall contact law, wall friction, partition friction) of a tub run: the calibration's
    [wall] and [partitions] friction (the media's effective Coulomb friction measured on the
    DEM), else the scenario's contact laws' friction of the fill on the wall and partition
    materials; the partition friction is None for a periodic tub (no partitions).
    partitions="along_flow" (ContinuumOptions.partition_friction) takes [partitions]
    friction_along_flow instead, the part of the contacts' friction along the mean flow
    (calibration.wall_friction); InputError where the calibration has none."""
    wall_pair = find_contact(scenario, scenario.fill.material, scenario.tub.wall_material)
    mu_w = float(calibration.wall.friction if calibration is not None else wall_pair.friction)
    if scenario.tub.periodic:
        return wall_pair, mu_w, None
    part_pair = find_contact(scenario, scenario.fill.material, scenario.tub.partition_material)
    if partitions == "along_flow":
        mu = None if calibration is None or calibration.partitions is None else \
            calibration.partitions.friction_along_flow
        if mu is None or not (math.isfinite(mu) and mu >= 0):
            raise InputError(f"partition_friction = 'along_flow': the calibration's [partitions] "
                             f"friction_along_flow = {'missing' if mu is None else repr(mu)}; "
                             "it must be a friction >= 0 (vibroflow calibrate measures it on a "
                             "DEM run with its wall forces)")
        return wall_pair, mu_w, float(mu)
    mu_p = float(calibration.partitions.friction
                 if calibration is not None and calibration.partitions is not None
                 else part_pair.friction)
    return wall_pair, mu_w, mu_p
