"""Orchestration of a Lagrangian continuum (material point method) run of a tub scenario.

Timeline (tub47.md "Procedure", the DEM's clock: t = 0 when the vibration starts):

1. The settled bed: the DEM's solid volume (fill.count balls of fill.diameter, over the slice
   L_y) at the critical solid fraction fills the U to the height h that holds it; material
   points on a square lattice of side dx/2 (4 a grid cell) inside the U, at rest, with the
   lithostatic stress sigma_zz = -rho_c g (h - z) and sigma_xx = sigma_yy = K0 sigma_zz,
   K0 = 1 - sin(atan mu_s) (Jaky), so its weight is carried from the start; their densities
   rho_c exp(p / K) are those the elastic law gives that pressure.  It then settles for
   `settle_time` in the still tub, where the walls take up the load.
2. Vibrate for run.duration in the tub frame (grid_update.py: the tub's motion from
   vibroflow.tub.motion enters as the frame's inertial force), sampling `run.phases_per_cycle`
   instants a cycle over the whole cycles of the last run.average_last seconds, at exactly the
   DEM's sample phases (m / (P f)); the time step divides the sampling interval.
3. Results, through vibroflow.analysis (the DEM's own code): each point is a "ball" of the
   point's solid volume m_p L_y / rho_s at its centre, with its lab position and velocity at the
   sample; bulk_velocity.csv (CellTable / write_csv on the scenario's cells) and summary.json
   with the DEM's keys (probes, circulation, wall_contacts from the points touching the U,
   impacts: none, window, cells), plus a "continuum" block: the method, numerics, material,
   and the shear rate with the impact speed and granular temperature it implies through the
   calibrated relations (calibration.toml [impacts]), when a calibration is given.

Parameters come from calibration.toml (vibroflow.io.calibration_file.read_calibration) or the
tub47 defaults (ContinuumMaterial): the wall friction [wall] friction (default: the scenario's
ball-wall contact friction), the partitions' [partitions] friction (default: the scenario's
ball-partition friction), the diameter and solid density (default: the scenario's fill).
The wall's normal stiffness is constant: (K + 4G/3) / l0 with l0 the point spacing (the bed's
elastic stiffness over one point), its damping ratio that of the scenario's ball-wall
restitution.  With vtk, ParaView files of the points and of the grid fields (fields.py) over
the last cycle (run_lagrangian).

Checkpoints (checkpoint.py) every run.checkpoint_every wall seconds of the vibration; a resumed
run gives the numbers of an uninterrupted one bit for bit; results are written atomically and
summary.json last (run_lagrangian).  A blow-up (mpm.ContinuumBlowUp: a point non-finite, off the
grid or through the wall) ends the run with the points' ids and the likely cause, and removes
the checkpoint.
"""
from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import math
import os
import signal
import threading
import time
from dataclasses import dataclass
from typing import ClassVar
from pathlib import Path

import numba as nb
import numpy as np

from vibroflow.measure.phase_shear import (PhaseShear, near_wall_nodes, node_grid,
                                            phase_shear_of_snapshots)
from vibroflow.measure.stats import batch_means, batches_of_whole_cycles
from vibroflow.measure.summary import json_safe, tub_summary
from vibroflow.tub.geometry import geometry_of
from vibroflow.errors import InputError, Interrupted
# write_json_atomic: also imported from here by the Eulerian run
from vibroflow.io.atomic import write_json_atomic, write_text_atomic
from vibroflow.io.calibration_file import Calibration, ImpactRelation
from vibroflow.io.folder_lock import folder_lock
from vibroflow.progress import RunProgress
from vibroflow.run_clock import RunClock
from vibroflow.tub.geometry import cross_section_area, distance_to_wall_np, u_wall_nearest
from vibroflow.tub.motion import TubMotion, rigid_velocity, tub_to_lab

from .boundary import PartitionFriction, UWall, damping_ratio_of_restitution
from .checkpoint import load_checkpoint, save_checkpoint
from .constitutive import ContinuumMaterial, check_bed_viscosity
from .fields import grid_fields, write_grid_vtr
from .grid import Grid
from .grid_update import LabFrame, TubFrame
from .mpm import ContinuumBlowUp, MPMState, MPMSystem, advance, init_state
from .stress_update import equivalent_shear_rate
from .timestep import stable_dt, transfers_per_step

SUMMARY_NAME = "summary.json"
BULK_CSV_NAME = "bulk_velocity.csv"
VTK_DIR = "vtk"
CHECKPOINT_NAME = "checkpoint.npz"


#: The default grid, time step and APIC transfers of a tub run: dx = DEFAULT_DX_DIAMETERS ball
#: diameters (19 mm in tub47), steps of Courant number DEFAULT_CFL, and round(DEFAULT_CFL /
#: DEFAULT_TRANSFER_CFL) = 20 APIC transfers a step (transfer_operator.py).  The grid and the
#: transfers' rate are model choices, not only numerical ones, and are stated as such:
#:
#: * each APIC transfer filters the velocities through the grid, a damping of the grid-scale
#:   motion, and it is this damping that brings the tub's field to the DEM's; a Newtonian shear
#:   or bulk viscosity in the stress does not: the dissipation the continuum lacks is at the
#:   grid's scale, not the roll's (its physical form would be the collisional decay of the
#:   bed's agitation, which is not modelled).  The transfers' rate is given as the Courant
#:   number of the equivalent one-transfer step, DEFAULT_TRANSFER_CFL, and the step is set by
#:   stability alone (timestep.py), so a run hardly depends on its step (to within the
#:   rounding of the transfers' count; tests/test_transfer_operator.py).  The rate is the one
#:   whose field is closest to the DEM's on tub47 (E 0.347 +- 0.006 against the DEM's
#:   seed-to-seed 0.135, strength 0.98 of the DEM's): docs/decisions/transfer-rate.md;
#: * the grid: the mu(I) law needs no length of its own here, the field is the same on 19, 12.7
#:   and 9.5 mm grids once the transfers' damping is held the same on each (below), and a
#:   nonlocal fluidity (Kamrin & Koval 2012) changes nothing: docs/decisions/grid-spacing.md.
#:
#: Named in a run's fingerprint and a study stage's inputs (options_record), so that runs made
#: under different damping rules are never taken for one another.
#:
#: The transfers' damping is a fourth-order one, held the same on every grid.  One APIC
#: transfer leaves a velocity mode of wavenumber k the fraction 1 - alpha (k dx)^4 of its
#: amplitude (APIC keeps affine fields exactly, so the loss starts at fourth order; alpha =
#: 0.024 on a lattice of 2 x 2 points a cell, tests/test_transfer_operator.py), and a run
#: makes n / dt = c / (transfer_cfl dx) of them a second (c the wave speed the step is set
#: by), so the transfers damp the flow as a hyperviscosity nu_4 = alpha c dx^3 /
#: transfer_cfl (m^4/s): dv/dt = -nu_4 lap^2 v.  Held at a fixed transfer_cfl it would fall
#: eightfold with each halving of the grid, and the field would move away from the DEM's: the
#: grid would be part of the model.  transfer_cfl is therefore the Courant number of the
#: transfers on a grid of spacing `damping_length` (default: the formulation's default grid,
#: 3 ball diameters, on which the rate was chosen), and a run on spacing dx makes them at
#: transfer_cfl (dx / damping_length)^3: the same nu_4 on every grid.  tub47 reads E 0.347,
#: 0.331, 0.346 (strength 0.98, 0.97, 0.92 of the DEM's) on 19, 12.7 and 9.5 mm (20, 67, 161
#: transfers a step), four settling times each (benchmarks/continuum_sensitivity.py): converged
#: in the grid, at eight times the transfers a step for each halving of it
#: (docs/decisions/grid-spacing.md).  The Eulerian formulation's field settles on finer grids
#: under this rule (E 0.493, 0.506 on 12.5 and 9.4 mm) but not at its default grid's 0.432, and
#: more damping does not bring it there: something else in its step depends on the grid.
DEFAULT_DX_DIAMETERS = 3.0
DEFAULT_CFL = 0.3
DEFAULT_TRANSFER_CFL = 0.015
DEFAULT_GRID = f"{DEFAULT_DX_DIAMETERS:g} ball diameters"
DEFAULT_DAMPING = "the default grid's spacing"


def damping_transfer_cfl(transfer_cfl: float | None, dx: float, damping_length: float
                         ) -> float | None:
    """The Courant number of the transfers on a grid of spacing dx (m) that damps the flow as
    `transfer_cfl` does on one of spacing damping_length (m): transfer_cfl (dx /
    damping_length)^3 (the hyperviscosity alpha c dx^3 / transfer_cfl held fixed; the comment
    above DEFAULT_DX_DIAMETERS).  None or 0 (one transfer a step) pass through."""
    if not transfer_cfl:
        return transfer_cfl
    return transfer_cfl * (dx / damping_length) ** 3


def default_dx(scenario) -> float:
    """The default grid spacing (m) of a tub run: DEFAULT_DX_DIAMETERS fill.diameter."""
    return DEFAULT_DX_DIAMETERS * scenario.fill.diameter


@dataclass(frozen=True)
class LagrangianOptions:
    """Numerical options (SI): grid spacing dx (m; default `default_dx`, 3 ball diameters),
    Courant number of the step (default DEFAULT_CFL), Courant number of the APIC transfers
    transfer_cfl (each step makes round(cfl / transfer_cfl) transfers, timestep.
    transfers_per_step; 0 or None: one a step, as a FLIP blend always makes; default
    DEFAULT_TRANSFER_CFL; the grid and the transfers' rate are model choices, see there),
    rheology
    model ("mu_i" or "drucker_prager"), settling time in the still tub (s), wall stiffness
    (Pa/m; default (K + 4G/3) / point spacing), stiffness factor (-); dilatancy: the mu_i
    model's peak-friction option with the calibration's [dilatancy] K_dil
    (constitutive.py); compaction: the cyclic compaction option with the calibration's
    [compaction] gamma_c and dphi_cyc (constitutive.py, vibroflow.calibration.compaction);
    bed_viscosity (Pa s): the bed's Kelvin-Voigt damping on connected material
    (stress_update.damped_stress), 0 = off (default); benchmarks/strip_damping.py fits it on
    a DEM of a vibrated strip of the same balls; damping_length (m): the grid spacing on which
    transfer_cfl is the transfers' Courant number (default None: the default grid's spacing,
    `default_dx`); on another grid they are made at damping_transfer_cfl, so that their
    damping of the flow does not depend on the grid (the comment above DEFAULT_DX_DIAMETERS);
    damping_length = dx makes them at transfer_cfl on every grid (their damping then falls
    with the grid).

    stiffness_factor s < 1 is the continuum's counterpart of the DEM's reduced Young's modulus:
    the elastic moduli K and G (and with them the default wall stiffness) are multiplied by s,
    so the P-wave speed, and the stable time step's inverse (timestep.py), by sqrt(s), and a
    run takes sqrt(s) times the steps.  It is a physics change, not a numerical one: the elastic
    strains grow as 1/s and the bed's elastic waves slow down; its effect on the flow must be
    checked against the DEM (benchmarks/continuum_speed.py prints E for it).  On tub47-quick
    on a 7.5 mm grid at cfl 0.3 with one transfer a step (four settling times each;
    docs/validation.md) E against the DEM is
    0.89 +- 0.09 at s = 1, 1.07 +- 0.01 at s = 0.5 and 0.68 +- 0.01 at s = 0.25, whose
    circulation, though, is 0.62 of the DEM's (s = 1: 1.14): not monotonic, so no default
    other than 1.  Default 1: the calibrated moduli."""

    #: options left out of a study stage's inputs (its hash) while at their defaults, so that
    #: stages hashed without them stay up to date (vibroflow.study.stages)
    LATER_OPTIONS: ClassVar[tuple[str, ...]] = ("dilatancy", "stiffness_factor", "compaction",
                                                "flip", "bed_viscosity", "damping_length")

    dx: float | None = None
    cfl: float = DEFAULT_CFL
    model: str = "mu_i"
    settle_time: float = 0.05
    wall_stiffness: float | None = None
    dilatancy: bool = False
    stiffness_factor: float = 1.0
    compaction: bool = False
    flip: float = 0.0
    transfer_cfl: float | None = DEFAULT_TRANSFER_CFL
    bed_viscosity: float = 0.0
    damping_length: float | None = None

    def __post_init__(self):
        if not (isinstance(self.flip, (int, float)) and 0.0 <= self.flip <= 1.0):
            raise InputError(f"flip = {self.flip!r}: must be in [0, 1] (0: APIC, 1: FLIP)")
        if self.dx is not None and not self.dx > 0:
            raise InputError(f"dx = {self.dx!r}: must be a length > 0 m")
        if not 0 < self.cfl <= 1:
            raise InputError(f"cfl = {self.cfl!r}: must be in (0, 1]")
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
        unset (the formulation's default grid: `default_dx` for the material point method,
        eulerian.run.default_dx's for the fixed mesh).  Without dx,
        transfer_cfl as given."""
        if dx is None:
            return self.transfer_cfl
        length = self.damping_length if self.damping_length is not None else default_length
        if length is None:
            raise ValueError("grid_transfer_cfl: the damping length is unset and no default "
                             "length was given")
        return damping_transfer_cfl(self.transfer_cfl, dx, length)

    def default_grid(self, scenario) -> float:
        """The formulation's default grid spacing (m) for this scenario: `default_dx`, 3 ball
        diameters (EulerianOptions: its mesh's)."""
        return default_dx(scenario)

    def grid(self, scenario) -> float:
        """The grid spacing (m) a run of this scenario uses: dx, or the default grid's."""
        return self.dx if self.dx is not None else self.default_grid(scenario)

    def transfers_on(self, scenario) -> int:
        """The transfers a step of a run of this scenario makes (`transfers` on its grid, the
        damping length defaulting to the default grid's spacing)."""
        return self.transfers(self.grid(scenario), self.default_grid(scenario))


def _contact(scenario, a: str, b: str):
    from vibroflow.scenario.checks import find_contact

    return find_contact(scenario, a, b)


def material_of(scenario, calibration: Calibration | None, model: str = "mu_i",
                dilatancy: bool = False, stiffness_factor: float = 1.0,
                compaction: bool = False) -> ContinuumMaterial:
    """The continuum material: the calibration's, else tub47's defaults with the scenario's
    ball diameter and density; its elastic moduli times stiffness_factor (LagrangianOptions);
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


def material_for(scenario, calibration: dict | None, options: LagrangianOptions
                 ) -> ContinuumMaterial:
    """The material a run with these options uses (`material_of` with the options' model,
    dilatancy, compaction and stiffness factor); input errors name the setting."""
    mat = material_of(scenario, calibration, options.model, dilatancy=options.dilatancy,
                      stiffness_factor=options.stiffness_factor,
                      compaction=options.compaction)
    if options.bed_viscosity > 0:
        mat = dataclasses.replace(mat, bed_viscosity=float(options.bed_viscosity))
    return mat


def bed_height(radius: float, area: float, rim: float) -> float:
    """Height h (m) whose U cross-section below it has the given area (m^2)."""
    if area >= cross_section_area(radius, rim):
        raise InputError(f"bed area = {area:.4g} m^2: more than the tub holds below its rim")
    lo, hi = 0.0, rim
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        if cross_section_area(radius, mid) < area:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def bed_area(scenario, material: ContinuumMaterial) -> float:
    """Cross-section (m^2) of the settled bed: the DEM's solid volume (fill.count balls of
    fill.diameter) over the slice L_y, at the critical solid fraction (or the material's
    initial_solid_fraction)."""
    fill = scenario.fill
    solid = fill.count * math.pi * fill.diameter**3 / 6.0 / geometry_of(scenario).length
    return solid * material.solid_density / material.initial_density


def settled_bed(scenario, material: ContinuumMaterial, spacing: float):
    """Points of the settled bed (tub frame): positions (N, 2) m, volumes (N,) m^2, densities
    (N,) kg/m^3, stresses (N, 4) Pa, and the bed height h (m) (module docstring, step 1)."""
    geo = geometry_of(scenario)
    area = bed_area(scenario, material)
    h = bed_height(geo.radius, area, geo.rim_height)
    xs = np.arange(-geo.radius + spacing / 2, geo.radius, spacing)
    zs = np.arange(spacing / 2, h, spacing)
    X, Z = np.meshgrid(xs, zs, indexing="ij")
    X, Z = X.ravel(), Z.ravel()
    keep = distance_to_wall_np(X, Z, geo.radius) >= 0.5 * spacing  # the square inside the U
    x = np.stack([X[keep], Z[keep]], axis=1)
    n = x.shape[0]
    if n == 0:
        raise InputError(f"fill.count = {scenario.fill.count}: the bed is thinner than one point "
                         f"({spacing:.3g} m); refine dx")
    g = math.hypot(scenario.gravity[0], scenario.gravity[2])
    rho_c = material.initial_density  # rho_c unless the bed starts denser (dilatancy)
    szz = -rho_c * g * np.clip(h - x[:, 1], 0.0, None)
    k0 = 1.0 - math.sin(math.atan(material.mu_s))
    stress = np.zeros((n, 4))
    stress[:, 1] = szz
    stress[:, 0] = stress[:, 3] = k0 * szz
    p = -(stress[:, 0] + stress[:, 1] + stress[:, 3]) / 3.0
    density = rho_c * np.exp(p / material.bulk_modulus)
    # the points share the bed's area (their lattice misses a sliver along the curved wall)
    volume = np.full(n, area / n) * rho_c / density
    return x, volume, density, stress, h


def make_system(scenario, material: ContinuumMaterial, calibration: Calibration | None,
                options: LagrangianOptions, frame) -> tuple[MPMSystem, float]:
    """The MPM system of a tub scenario in `frame`; returns (system, point spacing m)."""
    geo = geometry_of(scenario)
    dx = options.grid(scenario)
    spacing = 0.5 * dx
    grid = Grid.covering(-geo.radius, geo.radius, 0.0, geo.rim_height, dx)
    wall_pair = _contact(scenario, scenario.fill.material, scenario.tub.wall_material)
    mu_w = float(calibration.wall.friction if calibration is not None else wall_pair.friction)
    M = material.bulk_modulus + 4.0 * material.shear_modulus / 3.0
    k_wall = options.wall_stiffness if options.wall_stiffness is not None else M / spacing
    boundaries: list = [UWall(radius=geo.radius, stiffness=k_wall, friction=mu_w,
                              damping_ratio=damping_ratio_of_restitution(wall_pair.restitution))]
    if not geo.periodic:
        part_pair = _contact(scenario, scenario.fill.material, scenario.tub.partition_material)
        mu_p = float(calibration.partitions.friction
                     if calibration is not None and calibration.partitions is not None
                     else part_pair.friction)
        boundaries.append(PartitionFriction(friction=mu_p, length=geo.length))
    dt = stable_dt(material, dx, spacing, boundaries, v_max=2.0, cfl=options.cfl)
    # a whole number of steps between samples, so every sample falls on a step
    f, per = scenario.motion.frequency, scenario.run.phases_per_cycle
    interval = 1.0 / (f * per)
    dt = interval / math.ceil(interval / dt)
    return MPMSystem(grid, material, dt, frame=frame, boundaries=boundaries,
                     chunks=scenario.run.force_chunks, flip=float(options.flip),
                     transfers=options.transfers_on(scenario)), spacing


def sample_times(scenario) -> tuple[np.ndarray, float, float]:
    """The DEM's sample instants (s): phases m / (P f) over the whole cycles of the window
    [duration - average_last, ...) (as vibroflow.dem.run.sample_steps, before its rounding to
    the DEM's step), and the window (t0, t1)."""
    run, f = scenario.run, scenario.motion.frequency
    t0 = run.duration - run.average_last
    n_cycles = int(math.floor(run.average_last * f + 1e-9))
    per = run.phases_per_cycle
    m0 = math.ceil(t0 * f * per - 1e-9)
    return (m0 + np.arange(n_cycles * per)) / (f * per), t0, t0 + n_cycles / f


@nb.njit(cache=True)
def to_lab(x, v, pose6, pivx, pivz, pos_out, vel_out, y):
    """Lab positions and velocities (3D, y = the slice's middle) of tub-frame points (x, v) at
    the tub pose (X, Z, theta, Xdot, Zdot, thetadot), through vibroflow.tub.motion."""
    X, Z, th, Xd, Zd, thd = pose6[0], pose6[1], pose6[2], pose6[3], pose6[4], pose6[5]
    c = np.cos(th)
    s = np.sin(th)
    for p in range(x.shape[0]):
        lx, lz = tub_to_lab(x[p, 0], x[p, 1], X, Z, th, pivx, pivz)
        rvx, rvz = rigid_velocity(lx, lz, X, Z, Xd, Zd, thd, pivx, pivz)
        pos_out[p, 0] = lx
        pos_out[p, 1] = y
        pos_out[p, 2] = lz
        vel_out[p, 0] = rvx + c * v[p, 0] - s * v[p, 1]
        vel_out[p, 1] = 0.0
        vel_out[p, 2] = rvz + s * v[p, 0] + c * v[p, 1]


_to_lab = to_lab  # the name tests/test_mpm.py imports


@nb.njit(cache=True)
def _wall_gap_arc(x, radius, gap_out, arc_out):
    """Distance (m) of each point from the U wall and the arc-length coordinate (m) of its
    nearest wall point (tub.geometry)."""
    for p in range(x.shape[0]):
        r = u_wall_nearest(x[p, 0], x[p, 1], radius)
        gap_out[p] = r[0]
        arc_out[p] = r[5]


def shear_rate(L: np.ndarray) -> np.ndarray:
    """gamma_dot = sqrt(2 D':D') (1/s) of velocity gradients L (N, 4) [xx, xz, zx, zz], plane
    strain (D_yy = 0) (models.md)."""
    L = np.ascontiguousarray(L, dtype=np.float64)
    return equivalent_shear_rate(L[:, 0], L[:, 1], L[:, 2], L[:, 3])


def _write_points_vtu(path: Path, state: MPMState, rate: np.ndarray, length: float,
                      solid_density: float) -> str:
    """The material points as a ParaView point cloud (tub frame, y = the slice's middle)."""
    from vibroflow.io.vtk import write_snapshot_vtu

    n = state.n
    pos = np.stack([state.x[:, 0], np.full(n, 0.5 * length), state.x[:, 1]], axis=1)
    vel = np.stack([state.v[:, 0], np.zeros(n), state.v[:, 1]], axis=1)
    side = np.sqrt(state.volume)
    return write_snapshot_vtu(path, pos, vel, np.zeros((n, 3)), 0.5 * side,
                              extra={"pressure": state.pressure(), "shear_rate": rate,
                                     "solid_fraction": state.density / solid_density,
                                     "state": state.phase.astype(np.float64)})


def options_record(options: LagrangianOptions) -> dict:
    """The options as a plain dict for a fingerprint or a study's inputs, an unset dx spelled
    out as the rule that sets it (DEFAULT_GRID)."""
    record = dataclasses.asdict(options)
    if record.get("dx") is None:
        record["dx"] = DEFAULT_GRID
    elif record.get("damping_length") is None:
        # a grid of its own: its transfers follow the damping_length rule, which sets their
        # rate on any grid but the default one (docs/decisions/grid-spacing.md)
        record["damping_length"] = DEFAULT_DAMPING
    return record


def run_fingerprint(scenario, calibration: Calibration | None, options: LagrangianOptions,
                    vtk: bool) -> str:
    """A hash of everything that fixes a run's numbers (the scenario but for
    run.checkpoint_every, the calibration, the options, vtk): a checkpoint resumes only the run
    that wrote it."""
    s = scenario.model_dump(mode="json")
    s.get("run", {}).pop("checkpoint_every", None)
    cal = calibration.to_toml_dict() if calibration is not None else None
    text = json.dumps({"scenario": s, "calibration": cal,
                       "options": options_record(options), "vtk": bool(vtk)},
                      sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()


class Samples:
    """What the samples of the vibration have recorded so far: the points as the DEM's
    snapshots (lab position and velocity, tub pose), the wall contacts, the shear rates and the
    ParaView files written; `arrays` / `from_arrays` carry it through a checkpoint unchanged."""

    CONTACTS = {"snapshot": ((), np.int32), "particle": ((), np.int32), "fn": ((), np.float64),
                "ft": ((), np.float64), "sliding": ((), np.bool_), "arc": ((), np.float64),
                "position_tub": ((3,), np.float64)}

    def __init__(self, n_samples: int, n_points: int, n_probes: int, cell_grid=None):
        self.j = 0
        # the shear-rate map on the analysis cells: cell_grid = (cell size h m, cells either
        # side of x = 0, cells up from z = 0); per cell the sum over samples of the sample's
        # mean shear rate there, and the number of samples that held material there
        self.cell_grid = cell_grid
        if cell_grid is not None:
            h, nxh, nz = cell_grid
            self.rate_cell_sum = np.zeros((nz, 2 * nxh + 1))
            self.rate_cell_n = np.zeros((nz, 2 * nxh + 1))
        self.pos = np.zeros((n_samples, n_points, 3), np.float32)
        self.vel = np.zeros((n_samples, n_points, 3), np.float32)
        self.poses = np.zeros((n_samples, 6))
        self.contacts: dict[str, list] = {k: [] for k in self.CONTACTS}
        self.rate_all = np.full(n_samples, np.nan)
        self.rate_wall = np.full(n_samples, np.nan)
        self.rate_probe = np.full((n_samples, n_probes), np.nan)
        self.vtk: dict[str, list] = {"points": [], "grid": []}  # (t s, file name)

    def contact_arrays(self) -> dict[str, np.ndarray]:
        return {k: (np.concatenate(v) if v else np.zeros((0, *shape), dtype))
                for (k, (shape, dtype)), v in zip(self.CONTACTS.items(),
                                                  self.contacts.values())}

    def arrays(self) -> dict[str, np.ndarray]:
        j = self.j
        out = {"pos": self.pos[:j], "vel": self.vel[:j], "poses": self.poses[:j],
               "rate_all": self.rate_all, "rate_wall": self.rate_wall,
               "rate_probe": self.rate_probe}
        out.update({"contact_" + k: v for k, v in self.contact_arrays().items()})
        if self.cell_grid is not None:
            out["rate_cell_sum"], out["rate_cell_n"] = self.rate_cell_sum, self.rate_cell_n
        for kind, entries in self.vtk.items():
            out[f"vtk_{kind}_t"] = np.array([t for t, _ in entries], dtype=np.float64)
            out[f"vtk_{kind}_name"] = np.array([name for _, name in entries], dtype=np.str_)
        return out

    @classmethod
    def from_arrays(cls, a: dict, n_samples: int, n_points: int, n_probes: int,
                    cell_grid=None) -> "Samples":
        s = cls(n_samples, n_points, n_probes, cell_grid)
        if cell_grid is not None and "rate_cell_sum" in a:
            s.rate_cell_sum[:], s.rate_cell_n[:] = a["rate_cell_sum"], a["rate_cell_n"]
        j = s.j = int(a["pos"].shape[0])
        s.pos[:j], s.vel[:j], s.poses[:j] = a["pos"], a["vel"], a["poses"]
        s.rate_all[:], s.rate_wall[:], s.rate_probe[:] = (a["rate_all"], a["rate_wall"],
                                                          a["rate_probe"])
        s.contacts = {k: [a["contact_" + k]] for k in cls.CONTACTS}
        for kind in s.vtk:
            s.vtk[kind] = [(float(t), str(name)) for t, name in
                           zip(a[f"vtk_{kind}_t"], a[f"vtk_{kind}_name"])]
        return s


    def add_contacts(self, j: int, particle: np.ndarray, fn: np.ndarray, ft: np.ndarray,
                     state: np.ndarray, arc: np.ndarray, x: np.ndarray, length: float) -> None:
        """Add sample j's wall contacts: the touching points' (or cells') indices, their normal
        and tangential forces per metre of thickness (N/m; times `length`, the slice L_y in m,
        they are over the slice, the DEM's unit), state (1 stick, 2 slide), arc-length
        coordinate (m) and tub-frame positions x (n, 2) (m, set at the slice's middle in y)."""
        c = self.contacts
        c["snapshot"].append(np.full(particle.size, j, np.int32))
        c["particle"].append(particle.astype(np.int32))
        c["fn"].append(fn * length)
        c["ft"].append(np.abs(ft) * length)
        c["sliding"].append(state == 2)
        c["arc"].append(np.array(arc, dtype=np.float64))
        c["position_tub"].append(np.stack(
            [x[:, 0], np.full(particle.size, 0.5 * length), x[:, 1]], axis=1))

    def add_cell_rates(self, x: np.ndarray, rate: np.ndarray) -> None:
        """Add one sample's shear rates (1/s) at tub-frame positions x (N, 2) m to the map: the
        mean over the points (or cells) in each analysis cell."""
        if self.cell_grid is None:
            return
        h, nxh, nz = self.cell_grid
        ix = np.floor(x[:, 0] / h + 0.5).astype(np.int64) + nxh
        iz = np.floor(x[:, 1] / h + 0.5).astype(np.int64)
        ok = (ix >= 0) & (ix <= 2 * nxh) & (iz >= 0) & (iz < nz) & np.isfinite(rate)
        flat = iz[ok] * (2 * nxh + 1) + ix[ok]
        size = nz * (2 * nxh + 1)
        total = np.bincount(flat, weights=rate[ok], minlength=size).reshape(nz, -1)
        count = np.bincount(flat, minlength=size).reshape(nz, -1)
        held = count > 0
        self.rate_cell_sum[held] += total[held] / count[held]
        self.rate_cell_n[held] += 1


def cell_grid_of(geo, cell_size: float) -> tuple[float, int, int]:
    """The analysis cells covering a tub (see Samples): (h m, cells either side, cells up);
    the nodes of analysis.phase_shear.node_grid, so the two maps are the same cells."""
    return node_grid(geo, cell_size)


SHEAR_RATE_CSV_NAME = "shear_rate.csv"


def write_shear_rate_csv(path: Path, samples: Samples, phase: PhaseShear | None,
                         calibration: Calibration | None, diameter: float) -> None:
    """The continuum's cycle-mean shear-rate map on the analysis cells (the DEM's cells), with
    the impact speeds it implies by the calibrated v = c0 + c1 d gamma_dot ([impacts.ball_ball],
    [impacts.ball_wall] by impact_relation; empty without a calibration), atomically: columns x, z
    (m, cell centres), shear_rate (1/s, the phase-resolved field's cycle mean at the cell's
    centre, as the DEM's; shear_rate_outputs), solid_fraction (of that field),
    instantaneous_shear_rate (1/s, mean over the samples that held material in the cell of the
    points' mean there), samples (those samples), impact_ball_ball, impact_ball_wall (m/s, from
    shear_rate).  A cell is written when either rate is known there."""
    if samples.cell_grid is None:
        return
    h, nxh, nz = samples.cell_grid
    im = calibration.impacts if calibration is not None else None
    fits = [impact_relation(getattr(im, k) if im is not None else None)[:2]
            for k in ("ball_ball", "ball_wall")]
    lines = ["x,z,shear_rate,solid_fraction,instantaneous_shear_rate,samples,"
             "impact_ball_ball,impact_ball_wall"]

    def num(v):
        return repr(float(v)) if np.isfinite(v) else ""

    for k in range(nz):
        for i in range(2 * nxh + 1):
            n = samples.rate_cell_n[k, i]
            inst = float(samples.rate_cell_sum[k, i] / n) if n > 0 else float("nan")
            g = float(phase.shear_rate[k, i]) if phase is not None else float("nan")
            f = float(phase.solid_fraction[k, i]) if phase is not None else float("nan")
            if not (np.isfinite(g) or n > 0):
                continue
            v = ["" if c0 is None or not np.isfinite(g) else repr(float(c0 + c1 * diameter * g))
                 for c0, c1 in fits]
            lines.append(f"{(i - nxh) * h!r},{k * h!r},{num(g)},{num(f)},{num(inst)},{int(n)},"
                         f"{v[0]},{v[1]}")
    write_text_atomic(path, "\n".join(lines) + "\n")


def samples_source(scenario, samples: Samples, times: np.ndarray, radius: np.ndarray) -> dict:
    """The samples as the dem.h5 layout that analysis.summary.tub_summary reads: snapshots of
    "balls" of the given radii (m), the wall contacts on the tub's U."""
    source = {"attrs": {"frequency": scenario.motion.frequency},
              "snapshots/time": times, "snapshots/position": samples.pos,
              "snapshots/velocity": samples.vel, "snapshots/tub_pose": samples.poses,
              "particles/radius": radius}
    if times.size:
        source.update({"wall_contacts/" + k: v for k, v in samples.contact_arrays().items()})
        source["wall_contacts/wall"] = np.zeros(source["wall_contacts/fn"].size, np.int8)
    return source


def run_lagrangian(scenario, out_dir, calibration: dict | None = None,
                   options: LagrangianOptions | None = None, progress: bool = False,
                   vtk: bool = False, resume: bool = False,
                   stop_after_steps: int | None = None,
                   keep_samples: list | None = None) -> dict | None:
    """Run the Lagrangian continuum of a tub scenario into out_dir (module docstring); returns
    the summary (also written to out_dir/summary.json with out_dir/bulk_velocity.csv).

    vtk: also write ParaView files in out_dir/vtk at the samples of the last vibration cycle:
    the material points (tub frame, velocity relative to the tub, pressure, shear rate, solid
    fraction, state; points_NNNNN.vtu, points.pvd), the grid fields of fields.py (velocity
    relative to the tub, solid fraction, density, pressure, shear rate on the background grid;
    grid_NNNNN.vtr, grid.pvd) and the tub's surface (tub.vtu).

    Checkpoints: every run.checkpoint_every wall seconds of the vibration the whole state and
    what has been sampled go to out_dir/checkpoint.npz (checkpoint.py, atomic); resume=True
    continues from it (a run killed while settling starts afresh) and gives the same numbers,
    bit for bit, as a run never interrupted; the checkpoint of another scenario, calibration or
    options is an input error.  stop_after_steps: write a checkpoint and return None after that
    many vibration steps of this call (to split a run; go on with resume=True).  A fresh run
    first removes the folder's summary.json and bulk_velocity.csv, so a run killed before its
    end never leaves results that look complete; summary.json is written last.

    keep_samples: a list that receives the run's `Samples` (every point at every sample
    instant, the wall contacts) for an analysis beyond the summary's (benchmarks/wall_layer.py).
    """
    if scenario.tub is None or scenario.fill is None:
        raise InputError("scenario: the continuum needs a tub-mode scenario (with [tub] and "
                         "[fill]), not explicit particles")
    if sample_times(scenario)[0].size == 0:
        raise InputError(f"run.average_last = {scenario.run.average_last!r}: must hold at least "
                         "one whole vibration cycle to average over")
    if stop_after_steps is not None and not int(stop_after_steps) >= 0:
        raise InputError(f"stop_after_steps = {stop_after_steps!r}: must be >= 0")
    options = options or LagrangianOptions()
    system, material, spacing = tub_system(scenario, calibration, options)
    geo = geometry_of(scenario)
    x, volume, density, stress, h = settled_bed(scenario, material, spacing)
    times, t0, t1 = sample_times(scenario)
    S = times.size
    probes = scenario.analysis.probes
    out = Path(out_dir)
    ckpt = out / CHECKPOINT_NAME
    fingerprint = run_fingerprint(scenario, calibration, options, vtk)
    # the folder's lock first: nothing is written into a folder another run is writing, and a
    # --out that is a file or read-only is a one-line error before anything is made
    with folder_lock(out, "vibroflow continuum"):
        clock = RunClock()   # the solver's time, numba's compilation apart
        with clock, RunProgress(progress) as prog:
            if resume and ckpt.exists():
                state, arrays, meta = load_checkpoint(ckpt)
                if meta.get("fingerprint") != fingerprint:
                    raise InputError(f"--resume: {ckpt} is the checkpoint of another scenario, "
                                     "calibration or options; run without --resume to start "
                                     "afresh")
                samples = Samples.from_arrays(arrays, S, state.n, len(probes),
                                              cell_grid_of(geo, scenario.analysis.cell_size))
                clock.resume_from(float(meta["wall_time_s"]))
                prog.log(f"resuming from {ckpt} at t = {state.t:.4f} s")
            else:
                if resume:
                    prog.log(f"no checkpoint in {out}: starting afresh")
                for name in (SUMMARY_NAME, BULK_CSV_NAME, CHECKPOINT_NAME, SHEAR_RATE_CSV_NAME):
                    (out / name).unlink(missing_ok=True)
                with interrupted_while_settling():
                    state = settle(scenario, material, calibration, options, x, volume,
                                   density, stress, prog)
                state.t = 0.0
                state.step = 0
                samples = Samples(S, state.n, len(probes),
                                  cell_grid_of(geo, scenario.analysis.cell_size))
            try:
                done = _vibrate(scenario, system, state, samples, geo, material, times, out,
                                vtk, prog, ckpt, fingerprint, clock, stop_after_steps)
            except ContinuumBlowUp:
                ckpt.unlink(missing_ok=True)  # a blown-up run has nothing to resume
                raise
            except VibrationInterrupted as e:
                raise interrupted(out, e) from None
        if keep_samples is not None:
            keep_samples.append(samples)
        if not done:
            return None
        with interrupted_while_writing(out):
            summary = _lagrangian_results(scenario, out, calibration, options, vtk, system,
                                          material, spacing, geo, h, times, state, samples,
                                          clock)
        ckpt.unlink(missing_ok=True)
        return summary


def _lagrangian_results(scenario, out: Path, calibration, options, vtk, system, material,
                        spacing, geo, h, times, state, samples: Samples, clock: RunClock
                        ) -> dict:
    """Write a finished Lagrangian run's results into out (summary.json last); the summary."""
    S = times.size
    probes = scenario.analysis.probes
    wall_time = clock.solver_s()
    n = state.n
    n_steps = state.step
    if vtk:
        from vibroflow.io.vtk import write_pvd

        write_pvd(out / VTK_DIR / "points.pvd", samples.vtk["points"])
        write_pvd(out / VTK_DIR / "grid.pvd", samples.vtk["grid"])

    radius = np.cbrt(3.0 * state.mass * geo.length / (4.0 * math.pi * material.solid_density))
    source = samples_source(scenario, samples, times, radius)
    # the DEM's top-level keys (vibroflow.dem.run), with the points as its particles
    summary = {"case": scenario.case, "source": "vibroflow continuum", "method": "lagrangian",
               "n_particles": n, "steps": n_steps, "dt": system.dt,
               "simulated_time_s": n_steps * system.dt, "wall_time_s": wall_time,
               "compile_time_s": clock.compile_s(),
               "particle_steps_per_s": n * n_steps / wall_time if wall_time > 0 else None}
    summary.update(tub_summary(source, scenario, bulk_csv=out / BULK_CSV_NAME))
    batch = batches_of_whole_cycles(times, scenario.run.duration - scenario.run.average_last,
                                    scenario.run.duration, scenario.motion.frequency,
                                    scenario.run.batches) if S else np.zeros(0, np.int64)
    summary["continuum"] = _continuum_block(material, system, state, spacing, h, n_steps,
                                            wall_time, options)
    phase = phase_shear_of_samples(scenario, samples, times, radius)
    summary["continuum"].update(shear_rate_outputs(
        material, calibration, probes, batch, scenario.run.batches, samples, phase, geo.radius,
        summary["impacts"]))
    write_shear_rate_csv(out / SHEAR_RATE_CSV_NAME, samples, phase, calibration,
                         material.diameter)
    summary = json_safe(summary)
    write_json_atomic(out / SUMMARY_NAME, summary)
    return summary


def _vibrate(scenario, system, state, samples: Samples, geo, material, times, out: Path,
             vtk: bool, prog: RunProgress, ckpt: Path, fingerprint: str, clock: RunClock,
             stop_after_steps: int | None) -> bool:
    """Vibrate from state.step to the end of run.duration, sampling at `times` and writing a
    checkpoint every run.checkpoint_every wall seconds; False when stopped by
    stop_after_steps (after its checkpoint)."""
    run = scenario.run
    S = times.size
    n = state.n
    motion = system.frame.motion
    pv = (motion.pivot_x, motion.pivot_z)
    cell = scenario.analysis.cell_size
    probe_cells = [(math.floor(pr.x / cell + 0.5), math.floor(pr.z / cell + 0.5))
                   for pr in scenario.analysis.probes.values()]
    sample_step = np.rint(times / system.dt).astype(np.int64)
    n_steps = int(round(run.duration / system.dt))
    buf_p, buf_v = np.zeros((n, 3)), np.zeros((n, 3))
    arc, gap = np.zeros(n), np.zeros(n)
    if vtk:
        from vibroflow.io.vtk import write_tub_surface

        (out / VTK_DIR).mkdir(exist_ok=True)
        write_tub_surface(out / VTK_DIR / "tub.vtu", geo)
    wall_hist = state.history[0]

    def checkpoint():
        save_checkpoint(ckpt, state, samples.arrays(), {
            "fingerprint": fingerprint,
            "wall_time_s": clock.solver_s()})

    prog.stage("continuum (lagrangian)", run.duration)

    def record(j):
        """Sample j, at step sample_step[j]."""
        pose6 = np.array(system.frame.pose(state.t))
        to_lab(state.x, state.v, pose6, pv[0], pv[1], buf_p, buf_v, 0.5 * geo.length)
        samples.pos[j], samples.vel[j], samples.poses[j] = buf_p, buf_v, pose6
        touching = np.nonzero(wall_hist["state"] > 0)[0]
        _wall_gap_arc(state.x, geo.radius, gap, arc)
        samples.add_contacts(j, touching, wall_hist["fn"][touching], wall_hist["ft"][touching],
                             wall_hist["state"][touching], arc[touching], state.x[touching],
                             geo.length)
        rate = shear_rate(state.L)
        if vtk and j >= S - run.phases_per_cycle:
            name = f"points_{j:05d}.vtu"
            _write_points_vtu(out / VTK_DIR / name, state, rate, geo.length,
                              material.solid_density)
            samples.vtk["points"].append((state.t, name))
            name = f"grid_{j:05d}.vtr"
            fields = grid_fields(system.grid, state.x, state.v, state.mass,
                                 state.pressure(), rate, material.solid_density)
            write_grid_vtr(out / VTK_DIR / name, system.grid, fields, 0.5 * geo.length)
            samples.vtk["grid"].append((state.t, name))
        samples.rate_all[j] = rate.mean()
        samples.add_cell_rates(state.x, rate)
        near = gap < 0.5 * cell
        if near.any():
            samples.rate_wall[j] = rate[near].mean()
        ci = np.floor(state.x[:, 0] / cell + 0.5)
        ck = np.floor(state.x[:, 1] / cell + 0.5)
        for q, (pi, pk) in enumerate(probe_cells):
            inside = (ci == pi) & (ck == pk)
            if inside.any():
                samples.rate_probe[j, q] = rate[inside].mean()

    return vibration_timeline(state, n_steps, sample_step, samples, record,
                              lambda m: advance(system, state, m), checkpoint, prog, n,
                              run.checkpoint_every, stop_after_steps)


def vibration_timeline(state, n_steps: int, sample_step: np.ndarray, samples: Samples,
                       record, advance_steps, checkpoint, prog: RunProgress, per_step: int,
                       checkpoint_every: float, stop_after_steps: int | None) -> bool:
    """The vibration's timeline, the same for both formulations: from state.step to n_steps,
    record(j) at each sample step sample_step[j] (samples.j counts them, so a resumed run goes
    on where it stopped), checkpoint() every checkpoint_every wall seconds, the steps between
    two events (next_event) in one advance_steps(m) call, progress reported as simulated time
    and per_step particle-steps a step.  False when stopped by stop_after_steps (after its
    checkpoint), True at the end.

    A Ctrl-C (SIGINT) stops the timeline at its next look, between two steps and two samples,
    where state and samples agree: checkpoint() and VibrationInterrupted(t, checkpointed=True),
    which the runners turn into Interrupted (`interrupted`).  A second Ctrl-C before that, or
    one outside the main thread's handler, stops it where it is: VibrationInterrupted(t,
    checkpointed=False), no checkpoint of a state that may be half-way through a sample (the
    last periodic one, if any, stays)."""
    S = sample_step.size
    k0 = k = state.step
    last_ckpt = time.perf_counter()
    fault = FaultSigint(k0)
    with sigint_flag() as stop:
        try:
            while True:
                while samples.j < S and sample_step[samples.j] == k:
                    record(samples.j)
                    samples.j += 1
                if stop.requested:
                    break
                if k == n_steps:
                    break
                if stop_after_steps is not None and k - k0 >= stop_after_steps:
                    checkpoint()
                    prog.log(f"stopped at t = {state.t:.4f} s (step {k}); go on with --resume")
                    return False
                if time.perf_counter() - last_ckpt > checkpoint_every:
                    checkpoint()
                    last_ckpt = time.perf_counter()
                # the steps up to the next sample, stop or progress report, in one compiled
                # call
                nxt = next_event(k, n_steps, sample_step, samples.j, k0, stop_after_steps)
                advance_steps(nxt - k)
                k = nxt
                prog.update(state.t, (k - k0) * per_step)
                fault.check(k)
            if stop.requested:
                checkpoint()
                raise VibrationInterrupted(state.t, True)
        except KeyboardInterrupt:
            raise VibrationInterrupted(state.t, False) from None
    prog.update(state.t, (n_steps - k0) * per_step)
    return True


class VibrationInterrupted(Exception):
    """A Ctrl-C stopped the vibration at simulated time t (s); checkpointed: whether the state
    at t was written to the checkpoint (vibration_timeline)."""

    def __init__(self, t: float, checkpointed: bool):
        super().__init__(f"interrupted at t = {t:.4f} s")
        self.t, self.checkpointed = float(t), bool(checkpointed)


def resume_hint(out: Path) -> str:
    return f"resume with --resume (vibroflow continuum ... --out {out} --resume)"


def interrupted(out: Path, e: VibrationInterrupted) -> Interrupted:
    """The one-line Interrupted of a vibration stopped by Ctrl-C: the time and how to go on."""
    if e.checkpointed:
        return Interrupted(f"interrupted at t = {e.t:.4f} s; {resume_hint(out)}")
    if (Path(out) / CHECKPOINT_NAME).exists():
        return Interrupted(f"interrupted at t = {e.t:.4f} s, before its checkpoint was "
                           f"written; {resume_hint(out)} goes on from the last checkpoint")
    return Interrupted(f"interrupted at t = {e.t:.4f} s, before a first checkpoint; nothing "
                       "to resume, run again")


@contextlib.contextmanager
def interrupted_while_settling():
    """A Ctrl-C while the bed settles: Interrupted (one line); nothing is checkpointed before
    the vibration, so there is nothing to resume."""
    try:
        yield
    except KeyboardInterrupt:
        raise Interrupted("interrupted while settling; nothing to resume, run again") from None


@contextlib.contextmanager
def interrupted_while_writing(out: Path):
    """A Ctrl-C while a finished run writes its results: Interrupted (one line).  Every file is
    written atomically and summary.json last, so the folder holds no half file and no summary
    that looks complete; the checkpoint, when there is one, stays to resume from."""
    try:
        yield
    except KeyboardInterrupt:
        if (Path(out) / CHECKPOINT_NAME).exists():
            raise Interrupted(f"interrupted while writing the results; {resume_hint(out)} "
                              "goes on from the last checkpoint") from None
        raise Interrupted("interrupted while writing the results, before a checkpoint; "
                          "nothing to resume, run again") from None


class _StopFlag:
    requested = False


@contextlib.contextmanager
def sigint_flag():
    """While the block runs, a SIGINT (Ctrl-C) sets flag.requested instead of raising
    KeyboardInterrupt at an arbitrary bytecode (which could leave a sample half recorded); a
    second one raises KeyboardInterrupt as usual.  Only in the main thread (Python's signal
    handlers run there) and when SIGINT is not ignored; otherwise the flag stays unset."""
    flag = _StopFlag()
    previous = signal.getsignal(signal.SIGINT)
    if (threading.current_thread() is not threading.main_thread()
            or previous in (signal.SIG_IGN, None)):
        yield flag
        return

    def handler(signum, frame):
        if flag.requested:
            raise KeyboardInterrupt
        flag.requested = True

    signal.signal(signal.SIGINT, handler)
    try:
        yield flag
    finally:
        signal.signal(signal.SIGINT, previous)


#: the fault-injection hook of the Ctrl-C tests (FaultSigint)
FAULT_SIGINT_ENV = "VIBROFLOW_FAULT_SIGINT_AFTER_STEPS"


class FaultSigint:
    """Fault injection for the Ctrl-C tests: with VIBROFLOW_FAULT_SIGINT_AFTER_STEPS=N in the
    environment the process sends itself SIGINT, once, at the vibration loop's first look after
    N steps of this call (from step k0): the deterministic version of a user's Ctrl-C (a test
    that signals from outside races the run).  The DEM has the same hook
    (vibroflow.dem.run)."""

    def __init__(self, k0: int):
        value = os.environ.get(FAULT_SIGINT_ENV)
        self.k0 = k0
        self.after = int(value) if value and value.strip().isdigit() else None

    def check(self, k: int) -> None:
        if self.after is not None and k - self.k0 >= self.after:
            self.after = None
            os.kill(os.getpid(), signal.SIGINT)


#: steps between progress reports (and the checks for a checkpoint's wall time)
REPORT_EVERY = 200


def next_event(k: int, n_steps: int, sample_step, j: int, k0: int,
               stop_after_steps: int | None) -> int:
    """The step after k at which a vibration loop must look again: the next sample (sample
    steps sample_step[j:]), the end n_steps, the stop after stop_after_steps steps from k0, or
    the next multiple of REPORT_EVERY."""
    nxt = min(n_steps, (k // REPORT_EVERY + 1) * REPORT_EVERY)
    if j < len(sample_step):
        nxt = min(nxt, int(sample_step[j]))
    if stop_after_steps is not None:
        nxt = min(nxt, k0 + int(stop_after_steps))
    return max(nxt, k + 1)


def tub_system(scenario, calibration: dict | None, options: LagrangianOptions
               ) -> tuple[MPMSystem, ContinuumMaterial, float]:
    """What a run vibrates: the MPM system of the scenario in the vibrating tub's frame, its
    material (material_for) and the point spacing (m)."""
    material = material_for(scenario, calibration, options)
    gravity = (float(scenario.gravity[0]), float(scenario.gravity[2]))
    system, spacing = make_system(scenario, material, calibration, options,
                                  TubFrame(TubMotion.of_scenario(scenario), gravity))
    return system, material, spacing


def vibration_start(scenario, calibration: dict | None, options: LagrangianOptions,
                    prog: RunProgress | None = None) -> tuple[MPMSystem, MPMState]:
    """The system in the vibrating tub's frame and the bed it starts vibrating from: settled
    for options.settle_time in the still tub, its clock set to t = 0, step 0 (run_lagrangian's
    first two steps, for a diagnostic that drives the run itself: benchmarks/)."""
    system, material, spacing = tub_system(scenario, calibration, options)
    x, volume, density, stress, _ = settled_bed(scenario, material, spacing)
    state = settle(scenario, material, calibration, options, x, volume, density, stress, prog)
    state.t, state.step = 0.0, 0
    return system, state


def settle(scenario, material, calibration, options, x, volume, density, stress,
           prog: RunProgress | None = None) -> MPMState:
    """The bed after options.settle_time in the still tub (module docstring, step 1)."""
    gravity = (float(scenario.gravity[0]), float(scenario.gravity[2]))
    system, _ = make_system(scenario, material, calibration, options, LabFrame(gravity))
    state = init_state(system, x, volume, density, stress=stress)
    steps = int(math.ceil(options.settle_time / system.dt))
    if prog is not None:
        prog.stage("continuum: settle (still tub)", options.settle_time)
    for k in range(0, steps, REPORT_EVERY):
        advance(system, state, min(REPORT_EVERY, steps - k))
        if prog is not None:
            prog.update(state.t, state.step * state.n)
    return state


def _continuum_block(material, system, state, spacing, h, n_steps, wall_time,
                     options: LagrangianOptions) -> dict:
    return {
        "method": "lagrangian (material point method, APIC, 2D plane strain, tub frame)",
        "rheology": material.model,
        "material": material.to_dict(),
        "grid_spacing_m": system.grid.dx, "point_spacing_m": spacing,
        "points": state.n, "bed_height_m": h, "dt_s": system.dt, "steps": n_steps,
        "transfers_per_step": system.transfers, "transfer_cfl": options.transfer_cfl,
        "wall_time_s": wall_time, "stiffness_factor": options.stiffness_factor,
        "wall_friction": system.boundaries[0].friction,
        "wall_stiffness_Pa_m": system.boundaries[0].stiffness,
        "partition_friction": (system.boundaries[1].friction if len(system.boundaries) > 1
                               else None),
    }


def phase_shear_of_samples(scenario, samples: Samples, times: np.ndarray,
                           radius: np.ndarray) -> PhaseShear:
    """The cycle-mean shear rate of the run's phase-resolved velocity field on the analysis
    cells' centres (analysis.phase_shear.phase_shear_of_snapshots, as the DEM calibration
    measures it): each sampled point standing for the solid volume of a ball of its `radius`
    (m)."""
    j = min(samples.j, times.size)
    return phase_shear_of_snapshots(scenario, samples.pos[:j], samples.vel[:j],
                                    samples.poses[:j],
                                    4.0 / 3.0 * math.pi * np.asarray(radius, float) ** 3,
                                    times[:j])


def impact_relation(rel: ImpactRelation | None) -> tuple[float | None, float | None, str]:
    """(c0 m/s, c1, which) of a calibration's [impacts.KIND] table: the relation fitted on the
    continuum's own measure of the shear rate (c0_cells_m_s, c1_cells;
    calibration.impacts.impact_relations_on_cells) when the calibration has it, else the one
    fitted on the DEM's 5 mm coarse-grained field (c0_m_s, c1; older calibrations); (None,
    None, "") without either."""
    if rel is None:
        return None, None, ""
    for c0, c1, which in ((rel.c0_cells_m_s, rel.c1_cells, "c0_cells, c1_cells"),
                          (rel.c0_m_s, rel.c1, "c0, c1")):
        if all(c is not None and math.isfinite(c) for c in (c0, c1)):
            return float(c0), float(c1), which
    return None, None, ""


def shear_rate_outputs(material, calibration: Calibration | None, probes: dict, batch,
                       n_batches, samples: Samples, phase: PhaseShear, radius_tub: float,
                       impacts: dict) -> dict:
    """Shear rate (1/s) over the bed, near the wall and in the probe cells, with batch-means
    standard errors; with a calibration, the granular temperature sqrt(T) = a d gamma_dot
    (models.md, Bagnold scaling; a from [impacts] bagnold_sqrtT_over_d_gamma_dot) and the mean
    impact speeds v = c0 + c1 d gamma_dot ([impacts.ball_ball] over the bed,
    [impacts.ball_wall] near the wall), written into the DEM's impact keys (`impacts` is
    updated in place; its counts stay 0: no impact is seen), by impact_relation.

    The shear rate is that of the phase-resolved velocity field (`phase`, the DEM
    calibration's definition, on which its impact relation was fitted; analysis.phase_shear
    says why), solid-fraction weighted over the analysis cells' centres: the bed (every node
    with material), near the wall (nodes less than a cell from the U) and each probe's cell.
    The mean of the points' instantaneous shear rates (their velocity gradients at the sampled
    instants, fluctuations included) is kept beside it as instantaneous_*."""
    d = material.diameter

    def mean_se(values):
        ok = np.isfinite(values)
        if not ok.any():
            return float("nan"), float("nan")
        return batch_means(values[ok], batch[ok], n_batches)

    near = near_wall_nodes(phase, radius_tub)
    m, se = phase.weighted_mean()
    mw, sew = phase.weighted_mean(near)
    im_, ise = mean_se(samples.rate_all)
    iw, iwse = mean_se(samples.rate_wall)
    out: dict = {"shear_rate": {
        "mean_1_s": m, "mean_1_s_stderr": se, "near_wall_1_s": mw, "near_wall_1_s_stderr": sew,
        # the slow roll's share: the shear rate of the time-averaged field (the rest of mean_1_s
        # is the bed's deformation within each cycle)
        "roll_mean_1_s": phase.roll_mean(),
        "definition": ("cycle mean of the shear rate of the phase-resolved velocity field "
                       "(averaged at each sampling phase over the window's cycles, on the "
                       "analysis cells' centres), as the DEM calibration measures it; "
                       "solid-fraction weighted"),
        "instantaneous_mean_1_s": im_, "instantaneous_mean_1_s_stderr": ise,
        "instantaneous_near_wall_1_s": iw, "instantaneous_near_wall_1_s_stderr": iwse}}
    im = calibration.impacts if calibration is not None else None
    a = im.bagnold_sqrtT_over_d_gamma_dot if im is not None else None
    out_probes = {}
    for q, (name, pr) in enumerate(probes.items()):
        k, i = phase.node_of(pr.x, pr.z)
        inside = np.zeros(phase.shear_rate.shape, bool)
        if 0 <= k < inside.shape[0] and 0 <= i < inside.shape[1]:
            inside[k, i] = True
        pm, pse = phase.weighted_mean(inside)
        qm, qse = mean_se(samples.rate_probe[:, q])
        out_probes[name] = {"shear_rate_1_s": pm, "shear_rate_1_s_stderr": pse,
                            "instantaneous_shear_rate_1_s": qm,
                            "instantaneous_shear_rate_1_s_stderr": qse,
                            "granular_temperature_m2_s2": (a * d * pm) ** 2 if a else None}
    out["probes"] = out_probes
    inferred = {}
    which = set()
    for name, rate, rate_se in (("ball_ball", m, se), ("ball_wall", mw, sew)):
        c0, c1, key = impact_relation(getattr(im, name) if im is not None else None)
        if c0 is None:
            continue
        v = c0 + c1 * d * rate
        impacts[name + "_mean_normal_speed"] = v
        impacts[name + "_mean_normal_speed_stderr"] = abs(c1) * d * rate_se
        inferred[name + "_mean_normal_speed_m_s"] = v
        which.add(key)
    if inferred:
        impacts["inferred_from_shear_rate"] = (
            "v = c0 + c1 d gamma_dot (calibration.toml [impacts] " + ", ".join(sorted(which))
            + "), gamma_dot of the phase-resolved field on the analysis cells; count = 0: no "
            "impact is seen")
        inferred["relation"] = ", ".join(sorted(which))
    if a:
        inferred["granular_temperature_m2_s2"] = (a * d * m) ** 2
    out["impacts_from_shear_rate"] = inferred or None
    return out
