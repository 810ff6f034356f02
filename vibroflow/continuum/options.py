"""The numerical options of a continuum tub run, one record for every formulation.

Each formulation supplies its own defaults where they differ (vibroflow.continuum.formulation:
the default transfer Courant number and the default grid) and its own checks (the Eulerian has
no FLIP option); the fields, their checks and the grid-independent damping rule are shared.

The default grid, time step and APIC transfers of a tub run: dx = DEFAULT_DX_DIAMETERS ball
diameters (19 mm in tub47; the Eulerian mesh's nearest spacing whose cells fill the tub's
width), steps of Courant number DEFAULT_CFL, and round(DEFAULT_CFL / transfer_cfl) APIC
transfers a step (transfer_operator.py; 20 for the material point method's default 0.015).  The
grid and the transfers' rate are model choices, not only numerical ones, and are stated as
such:

* each APIC transfer filters the velocities through the grid, a damping of the grid-scale
  motion, and it is this damping that brings the tub's field to the DEM's; a Newtonian shear
  or bulk viscosity in the stress does not: the dissipation the continuum lacks is at the
  grid's scale, not the roll's (its physical form would be the collisional decay of the
  bed's agitation, which is not modelled).  The transfers' rate is given as the Courant
  number of the equivalent one-transfer step, transfer_cfl, and the step is set by
  stability alone (timestep.py), so a run hardly depends on its step (to within the
  rounding of the transfers' count; tests/test_transfer_operator.py).  Each formulation's
  default rate is the one whose field is closest to the DEM's on tub47:
  docs/decisions/transfer-rate.md;
* the grid: the mu(I) law needs no length of its own here, the field is the same on 19, 12.7
  and 9.5 mm grids once the transfers' damping is held the same on each (below), and a
  nonlocal fluidity (Kamrin & Koval 2012) changes nothing: docs/decisions/grid-spacing.md.

The options are named in a run's fingerprint and a study stage's inputs (options_record), so
that runs made under different damping rules are never taken for one another.

The transfers' damping is a fourth-order one, held the same on every grid.  One APIC
transfer leaves a velocity mode of wavenumber k the fraction 1 - alpha (k dx)^4 of its
amplitude (APIC keeps affine fields exactly, so the loss starts at fourth order; alpha =
0.024 on a lattice of 2 x 2 points a cell, tests/test_transfer_operator.py), and a run
makes n / dt = c / (transfer_cfl dx) of them a second (c the wave speed the step is set
by), so the transfers damp the flow as a hyperviscosity nu_4 = alpha c dx^3 /
transfer_cfl (m^4/s): dv/dt = -nu_4 lap^2 v.  Held at a fixed transfer_cfl it would fall
eightfold with each halving of the grid, and the field would move away from the DEM's: the
grid would be part of the model.  transfer_cfl is therefore the Courant number of the
transfers on a grid of spacing `damping_length` (default: the formulation's default grid,
on which the rate was chosen), and a run on spacing dx makes them at transfer_cfl (dx /
damping_length)^3: the same nu_4 on every grid.  tub47 reads E 0.347, 0.331, 0.346
(strength 0.98, 0.97, 0.92 of the DEM's) with the material point method on 19, 12.7 and
9.5 mm (20, 67, 161 transfers a step), four settling times each
(benchmarks/continuum_sensitivity.py): converged in the grid, at eight times the transfers a
step for each halving of it (docs/decisions/grid-spacing.md).  The Eulerian formulation's
field settles on finer grids under this rule (E 0.493, 0.506 on 12.5 and 9.4 mm) but not at
its default grid's 0.432, and more damping does not bring it there: something else in its
step depends on the grid.
"""
from __future__ import annotations

import dataclasses
import math
import typing
from dataclasses import dataclass
from typing import ClassVar

from vibroflow.errors import InputError

from .constitutive import MODELS, check_bed_viscosity
from .landing_choices import LANDINGS
from .timestep import transfers_per_step

DEFAULT_DX_DIAMETERS = 3.0
DEFAULT_CFL = 0.3
#: the smallest Courant number a run takes: below it the step, a hundredth of the default
#: stability bound or less, only multiplies the cost
MIN_CFL = 1.0e-3
DEFAULT_GRID = f"{DEFAULT_DX_DIAMETERS:g} ball diameters"
DEFAULT_DAMPING = "the default grid's spacing"
#: the partitions' friction mu_p of the body force -2 mu_p p / L_y (material.boundary_friction):
#: the calibration's [partitions] friction (the contacts' ratio of sums, the default) or its
#: friction_along_flow (the part of it along the mean flow; docs/decisions/wall-friction.md)
PARTITION_FRICTIONS = ("contacts", "along_flow")
#: the elastic moduli (material.material_of): the calibration's bulk_modulus_Pa and
#: shear_modulus_Pa (the default), or the bed's unloading bulk modulus with the small-strain
#: shear modulus, or that branch's tangent law K_t(p) with it
#: (docs/decisions/unloading-stiffness.md)
MODULI = ("calibrated", "unloading", "unloading_law")


def damping_transfer_cfl(transfer_cfl: float | None, dx: float, damping_length: float
                         ) -> float | None:
    """The Courant number of the transfers on a grid of spacing dx (m) that damps the flow as
    `transfer_cfl` does on one of spacing damping_length (m): transfer_cfl (dx /
    damping_length)^3 (the hyperviscosity alpha c dx^3 / transfer_cfl held fixed; module
    docstring).  None or 0 (one transfer a step) pass through."""
    if not transfer_cfl:
        return transfer_cfl
    return transfer_cfl * (dx / damping_length) ** 3


def default_dx(scenario) -> float:
    """The default grid spacing (m) of a tub run: DEFAULT_DX_DIAMETERS fill.diameter (a
    formulation's default grid is this, or the nearest its mesh allows)."""
    return DEFAULT_DX_DIAMETERS * scenario.fill.diameter


@dataclass(frozen=True, kw_only=True)
class ContinuumOptions:
    """Numerical options (SI) of a continuum tub run; a formulation makes them with its own
    defaults (Formulation.options): grid spacing dx (m; default the formulation's default
    grid, about 3 ball diameters), Courant number of the step (default DEFAULT_CFL), Courant
    number of the APIC transfers transfer_cfl (each step makes round(cfl / transfer_cfl)
    transfers, timestep.transfers_per_step; 0 or None: one a step, as a FLIP blend always
    makes; no default here: each formulation's own, chosen with the grid to match the DEM,
    module docstring), rheology model ("mu_i" or "drucker_prager"), settling time in the
    still tub (s), wall stiffness (Pa/m; default (K + 4G/3) / point or cell spacing),
    stiffness factor (-); dilatancy: the mu_i model's peak-friction option with the
    calibration's [dilatancy] K_dil (constitutive.py); compaction: the cyclic compaction
    option with the calibration's [compaction] gamma_c and dphi_cyc (constitutive.py,
    vibroflow.calibration.compaction); flip: the FLIP fraction of the points' velocity update
    (mpm.MPMSystem.flip; the material point method's only); bed_viscosity (Pa s): the bed's
    Kelvin-Voigt damping on connected material (stress_update.damped_stress), 0 = off
    (default); benchmarks/strip_damping.py fits it on a DEM of a vibrated strip of the same
    balls; damping_length (m): the grid spacing on which transfer_cfl is the transfers'
    Courant number (default None: the formulation's default grid's spacing); on another grid
    they are made at damping_transfer_cfl, so that their damping of the flow does not depend on
    the grid (module docstring); damping_length = dx makes them at transfer_cfl on every grid
    (their damping then falls with the grid); temperature: the granular temperature T
    (m^2/s^2) carried by the material, with its balance and its stress (temperature_field.py,
    kinetic_stress.py; default False: not carried, the step as without it),
    initial_temperature (m^2/s^2, >= 0): T of the material at the start (default 0);
    landing (LANDINGS): how the Eulerian formulation counts the landing above the wall row
    (wall_energy_flux.WallEnergy.columns; default "pairs"; "columns" only with the
    temperature, and the Eulerian formulation's check refuses it elsewhere);
    partition_friction (PARTITION_FRICTIONS): which of the calibration's partition frictions
    the partitions' body force takes (material.boundary_friction; default "contacts");
    moduli (MODULI): the elastic moduli, the calibration's K and G ("calibrated", default) or
    its [elastic] unloading_bulk_modulus_Pa and shear_modulus_small_strain_Pa ("unloading":
    the bed's stiffness as it unloads after a landing, material.material_of), or the tangent
    law K_t = K_ref (p / p_ref)^n of that branch with the same G ("unloading_law": its
    [elastic] unloading_law_* keys, material.unloading_law_moduli).

    stiffness_factor s < 1 is the continuum's counterpart of the DEM's reduced Young's modulus:
    the elastic moduli K and G (and with them the default wall stiffness) are multiplied by s,
    so the P-wave speed, and the stable time step's inverse (timestep.py), by sqrt(s), and a
    run takes sqrt(s) times the steps.  It is a physics change, not a numerical one: the elastic
    strains grow as 1/s and the bed's elastic waves slow down; its effect on the flow must be
    checked against the DEM (benchmarks/continuum_speed.py prints E for it).  On tub47-quick
    on a 7.5 mm grid at cfl 0.3 with one transfer a step (four settling times each;
    docs/validation.md) the material point method's E against the DEM is
    0.89 +- 0.09 at s = 1, 1.07 +- 0.01 at s = 0.5 and 0.68 +- 0.01 at s = 0.25, whose
    circulation, though, is 0.62 of the DEM's (s = 1: 1.14): not monotonic, so no default
    other than 1.  Default 1: the calibrated moduli."""

    #: options left out of a study stage's inputs (its hash) while at their defaults, so that
    #: stages hashed without them stay up to date (vibroflow.study.stages)
    LATER_OPTIONS: ClassVar[tuple[str, ...]] = ("dilatancy", "stiffness_factor", "compaction",
                                                "flip", "bed_viscosity", "damping_length",
                                                "temperature", "initial_temperature", "landing",
                                                "partition_friction", "moduli")

    transfer_cfl: float | None
    dx: float | None = None
    cfl: float = DEFAULT_CFL
    model: str = "mu_i"
    settle_time: float = 0.05
    wall_stiffness: float | None = None
    dilatancy: bool = False
    stiffness_factor: float = 1.0
    compaction: bool = False
    flip: float = 0.0
    bed_viscosity: float = 0.0
    damping_length: float | None = None
    temperature: bool = False
    initial_temperature: float = 0.0
    landing: str = "pairs"
    partition_friction: str = "contacts"
    moduli: str = "calibrated"

    def __post_init__(self):
        hints = typing.get_type_hints(type(self))
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            hint = hints[f.name]
            if value is not None and (hint is float or float in typing.get_args(hint)) and (
                    isinstance(value, bool) or not isinstance(value, (int, float))
                    or not math.isfinite(value)):
                raise InputError(f"{f.name} = {value!r}: must be a finite number")
        if not (isinstance(self.flip, (int, float)) and 0.0 <= self.flip <= 1.0):
            raise InputError(f"flip = {self.flip!r}: must be in [0, 1] (0: APIC, 1: FLIP)")
        if self.dx is not None and not self.dx > 0:
            raise InputError(f"dx = {self.dx!r}: must be a length > 0 m")
        if not MIN_CFL <= self.cfl <= 1:
            raise InputError(f"cfl = {self.cfl!r}: must be in [{MIN_CFL:g}, 1]")
        if self.model not in MODELS:
            raise InputError(f"model = {self.model!r}: must be one of {', '.join(MODELS)}")
        transfers_per_step(self.cfl, self.transfer_cfl)  # its checks
        if not self.settle_time >= 0:
            raise InputError(f"settle_time = {self.settle_time!r}: must be >= 0 s")
        if self.wall_stiffness is not None and not self.wall_stiffness > 0:
            raise InputError(f"wall_stiffness = {self.wall_stiffness!r}: must be > 0 Pa/m")
        if not isinstance(self.dilatancy, bool):
            raise InputError(f"dilatancy = {self.dilatancy!r}: must be true or false")
        if not isinstance(self.compaction, bool):
            raise InputError(f"compaction = {self.compaction!r}: must be true or false")
        if not (math.isfinite(self.stiffness_factor) and 0 < self.stiffness_factor <= 1):
            raise InputError(f"stiffness_factor = {self.stiffness_factor!r}: must be in (0, 1]")
        check_bed_viscosity(self.bed_viscosity)
        if self.damping_length is not None and not (
                isinstance(self.damping_length, (int, float))
                and not isinstance(self.damping_length, bool)
                and math.isfinite(self.damping_length) and self.damping_length > 0):
            raise InputError(f"damping_length = {self.damping_length!r}: must be a length > 0 m "
                             "(or unset: the default grid's spacing)")
        if not isinstance(self.temperature, bool):
            raise InputError(f"temperature = {self.temperature!r}: must be true or false")
        if not (isinstance(self.initial_temperature, (int, float))
                and not isinstance(self.initial_temperature, bool)
                and math.isfinite(self.initial_temperature) and self.initial_temperature >= 0):
            raise InputError(f"initial_temperature = {self.initial_temperature!r}: must be a "
                             "temperature >= 0 m^2/s^2")
        if self.initial_temperature > 0 and not self.temperature:
            raise InputError(f"initial_temperature = {self.initial_temperature!r}: only with "
                             "the temperature (--temperature, in a study "
                             "METHOD.temperature=true)")
        if self.landing not in LANDINGS:
            raise InputError(f"landing = {self.landing!r}: must be {' or '.join(LANDINGS)}")
        if self.landing != "pairs" and not self.temperature:
            raise InputError(f"landing = {self.landing!r}: only with the temperature "
                             "(--temperature, in a study METHOD.temperature=true); without it "
                             "only pairs")
        for name in ("partition_friction", "moduli"):  # the command line's spelling, along-flow
            value = getattr(self, name)
            if isinstance(value, str) and "-" in value:
                object.__setattr__(self, name, value.replace("-", "_"))
        if self.partition_friction not in PARTITION_FRICTIONS:
            raise InputError(f"partition_friction = {self.partition_friction!r}: must be "
                             f"{' or '.join(PARTITION_FRICTIONS)}")
        if self.moduli not in MODULI:
            raise InputError(f"moduli = {self.moduli!r}: must be {' or '.join(MODULI)}")

    def transfers(self, dx: float | None = None, default_length: float | None = None) -> int:
        """The APIC transfers a step makes on a grid of spacing dx (m): timestep.
        transfers_per_step of cfl and `grid_transfer_cfl`; without dx, of transfer_cfl as
        given.  One with a FLIP blend (flip > 0), which keeps the sub-grid motion the
        transfers exist to damp: a FLIP run is the step-converged, undamped reference
        (mpm.MPMSystem.flip)."""
        if self.flip > 0.0:
            return 1
        return transfers_per_step(self.cfl, self.grid_transfer_cfl(dx, default_length))

    def grid_transfer_cfl(self, dx: float | None, default_length: float | None = None
                          ) -> float | None:
        """The transfers' Courant number on a grid of spacing dx (m): damping_transfer_cfl of
        transfer_cfl from a grid of damping_length, or of `default_length` (m) when that is
        unset (the formulation's default grid, Formulation.default_grid).  Without dx,
        transfer_cfl as given."""
        if dx is None:
            return self.transfer_cfl
        length = self.damping_length if self.damping_length is not None else default_length
        if length is None:
            raise ValueError("grid_transfer_cfl: the damping length is unset and no default "
                             "length was given")
        return damping_transfer_cfl(self.transfer_cfl, dx, length)


def options_record(options: ContinuumOptions) -> dict:
    """The options as a plain dict for a fingerprint or a study's inputs, an unset dx spelled
    out as the rule that sets it (DEFAULT_GRID).  The temperature's options are left out while
    the field is not carried, the landing at its default (pairs), the partition friction at its
    default (contacts) and the moduli at theirs (calibrated), so that the record (and a run's
    fingerprint) is the one of a run made without them."""
    record = dataclasses.asdict(options)
    if not record.get("temperature", False):
        record.pop("temperature", None)
        record.pop("initial_temperature", None)
    if record.get("landing") == "pairs" or not record.get("temperature", False):
        record.pop("landing", None)
    if record.get("partition_friction") == "contacts":
        record.pop("partition_friction", None)
    if record.get("moduli") == "calibrated":
        record.pop("moduli", None)
    if record.get("dx") is None:
        record["dx"] = DEFAULT_GRID
    elif record.get("damping_length") is None:
        # a grid of its own: its transfers follow the damping_length rule, which sets their
        # rate on any grid but the default one (docs/decisions/grid-spacing.md)
        record["damping_length"] = DEFAULT_DAMPING
    return record
