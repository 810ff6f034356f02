"""The fixed mesh of the tub as a continuum formulation (continuum.formulation.Formulation) of a
tub run and of the column collapse.

The tub (continuum.tub_run's timeline):

1. The settled bed: the DEM's solid mass (bed.bed_area at the critical density) fills the
   mesh's cells inside the U up to the height that holds exactly that mass (the top row
   partly filled), at rest under the lithostatic stress, at the density rho_c exp(p / K) of
   its pressure (bed.lithostatic).
2. The samples: the cells are sampled as pseudo-balls, each of the solid volume
   m_unit L_y / rho_s of a unit mass m_unit = 1.1 rho_c h^2 (a little above a full cell's), and
   a cell is in a sample when its accumulated mass in units, sum m / m_unit, has reached the
   next half unit (error diffusion in time): over the samples a cell then counts its mass to
   within one unit, so the cell table's solid fraction and its ball-averaged velocity are the
   mass-weighted ones to within 1 / samples, with the shared code unchanged.  A pseudo-ball
   sits at its cell's centre shifted by the same offset for every cell of a sample, the
   sample's point of a two-dimensional low-discrepancy sequence over the cell (`cell_offset`):
   over the samples each cell's mass is spread evenly over its square, so the analysis cells
   (15 mm, not a multiple of the mesh's cells) each receive the material of the area they
   cover, where pseudo-balls at the fixed centres would give some analysis cells two rows of
   centres and some one (a striped solid-fraction map).  The offset depends on the sample's
   index only, so a resumed run places the balls as the uninterrupted one.  Wall contacts:
   the wall-layer cells holding at least half a cell of material pressing on the U (wall.py),
   their force over the slice (N).  The summary's "continuum" block holds the shear rates from
   the cells holding at least half a cell of material and the mass error (M_end - M_0) / M_0
   with its largest magnitude over the run.
3. Parts (part_obstacle.py): the mesh leaves out the cells inside each part and gives the cells
   along it a wall layer of the U's law (mesh.py); the U's contacts and near-wall shear rate
   are the U's wall layer's alone, and each sample records the force on each part
   (wall.wall_force_on_material over its wall layer).

The column collapse: eulerian/column.py's set-up.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from vibroflow.errors import InputError
from vibroflow.measure.floor_force import on_floor
from vibroflow.scenario.laws import damping_ratio
from vibroflow.tub.geometry import geometry_of

from ..bed import bed_area, lithostatic
from ..boundary import PartitionFriction
from ..fields import grid_fields
from ..files import early_tag, sample_tag
from ..formulation import Formulation, Sampler
from ..material import boundary_friction
from ..options import ContinuumOptions, default_dx
from ..part_obstacle import continuum_parts, packed_section, torque_on_part
from ..sampling import dithered_cells_to_lab, shear_rate
from ..temperature_field import temperature_model
from ..timestep import run_step
from ..wall_feed import feed_by_region
from . import column
from .mesh import EulerianMesh
from .sample_rates import held_rates, held_rates_work
from .sample_wall import wall_contacts_work, wall_sample
from .solver import EulerianState, EulerianSystem, advance, init_state, state_from_checkpoint
from .wall_feed import EulerianWallFeed
from .wall import MeshWall, wall_force_on_material, wall_forces_by_cell

#: the pseudo-ball's mass in full cells at the critical density (module docstring, 2)
UNIT = 1.1

#: the Courant number of the APIC transfers (options.ContinuumOptions.transfer_cfl):
#: round(0.3 / 0.0375) = 8 transfers a step at the default cfl 0.3.  Fewer than the material
#: point method's because the remap damps the grid-scale motion too.  Chosen on tub47 at
#: amplitude factor 1.0 (E against the DEM, strength over the DEM's): E 0.433, strength 0.99;
#: at factors 0.5 and 1.5 E 0.363 and 0.562, on tub47-quick 0.666; with 6 transfers a step
#: (cfl 0.05) about 0.419, 0.418, 0.582 and 0.632, no clear gain, with 4 (0.075) about 0.474
#: at factor 1.0 and 0.610 on tub47-quick (docs/decisions/transfer-rate.md).
DEFAULT_TRANSFER_CFL = 0.0375

#: the additive recurrence of Roberts' R2 sequence (the plastic number's inverse powers), whose
#: points cover the unit square with the lowest discrepancy of its kind
R2 = (0.7548776662466927, 0.5698402909980532)


def cell_offset(j: int) -> tuple[float, float]:
    """The sample j's offset (-0.5 .. 0.5 of a cell side, x and z) of every pseudo-ball from its
    cell's centre (module docstring, 2): the j-th point of the R2 sequence."""
    return ((0.5 + j * R2[0]) % 1.0 - 0.5, (0.5 + j * R2[1]) % 1.0 - 0.5)


def mesh_dx(radius: float, target: float) -> float:
    """The default node spacing (m): the largest dx <= target (options.default_dx: 3 ball
    diameters) whose cells of dx/2 fill the tub's width 2R exactly (the mesh's requirement;
    tub47: 18.75 mm for 19.05 mm)."""
    n = math.ceil(2.0 * radius / (0.5 * target) - 1e-9)
    return 2.0 * (2.0 * radius / n)


def bed_masses(system: EulerianSystem, area: float, gravity: float):
    """Cell masses (N,) kg/m, material densities (N,) kg/m^3 and lithostatic stresses (N, 4)
    Pa of the settled bed of cross-section `area` (m^2) at the critical density, and its
    height (m) on the mesh (module docstring, 1); gravity (m/s^2)."""
    mesh = system.mesh
    mat = system.material
    rho_c = mat.initial_density  # rho_c unless the bed starts denser (dilatancy)
    c = system.x
    h = mesh.h
    inside = mesh.inside

    def bed(top):
        frac = np.where(inside, np.clip((top - (c[:, 1] - 0.5 * h)) / h, 0.0, 1.0), 0.0)
        stress, density = lithostatic(rho_c, gravity, np.clip(top - c[:, 1], 0.0, None),
                                      mat.mu_s, mat.bulk_modulus, mask=frac > 0)
        return frac * density * h * h, density, stress

    target = rho_c * area  # the bed's mass (kg/m)
    if bed(mesh.zmin + mesh.ncz * h)[0].sum() <= target:
        raise InputError(f"bed area = {area:.4g} m^2: more than the mesh holds below its top")
    lo, hi = mesh.zmin, mesh.zmin + mesh.ncz * h
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        if bed(mid)[0].sum() < target:
            lo = mid
        else:
            hi = mid
    top = 0.5 * (lo + hi)
    mass, density, stress = bed(top)
    return mass, density, stress, top


class CellSampler(Sampler):
    """The mesh's cells as pseudo-balls (module docstring, 2); its dither (each cell's
    accumulated mass in units) goes through the checkpoint."""

    vtk_kinds = ("grid",)

    def __init__(self, scenario, system: EulerianSystem, state: EulerianState, out: Path,
                 vtk):
        self.scenario, self.system, self.state = scenario, system, state
        self.out = out
        self.geo = geometry_of(scenario)
        mesh = system.mesh
        self.cells = cells = np.nonzero(mesh.inside)[0]
        self.xc = xc = np.ascontiguousarray(system.x[cells])
        self.n_points = n = cells.size
        motion = system.frame.motion
        self.pv = (motion.pivot_x, motion.pivot_z)
        cell = scenario.analysis.cell_size
        self.full = system.material.critical_density * mesh.h**2
        self.unit = UNIT * self.full
        probe_cells = [(math.floor(pr.x / cell + 0.5), math.floor(pr.z / cell + 0.5))
                       for pr in scenario.analysis.probes.values()]
        ci = np.floor(xc[:, 0] / cell + 0.5)
        ck = np.floor(xc[:, 1] / cell + 0.5)
        # each probe's cells (ascending, as a mask would pick them)
        self.probe_cells = [np.nonzero((ci == pi) & (ck == pk))[0] for pi, pk in probe_cells]
        # the U's wall layer (a part's is its own: part_of)
        self.near_wall = mesh.wall[cells] if mesh.part_of is None else \
            (mesh.wall & (mesh.part_of < 0))[cells]
        self.wall_cells = cells[self.near_wall]
        # the shear rates' selections of a sample, made in one compiled pass (sample_rates.py)
        self.probe_members = np.concatenate(
            [np.zeros(0, np.int64)] + [np.asarray(m, np.int64) for m in self.probe_cells])
        self.probe_ptr = np.cumsum([0] + [len(m) for m in self.probe_cells]).astype(np.int64)
        self.held = held_rates_work(cells.size, self.probe_cells)
        # the cells do not move in the tub: those of the wall layer nearest the floor
        # (measure.floor_force.on_floor) and the analysis cells of all (Samples.cell_index)
        # are constants of the run
        wc = self.wall_cells
        xw = system.x[wc]
        floor = wc[on_floor(xw[:, 0], xw[:, 1], self.geo.radius)]
        self.floor_cells, self.floor_normal = floor, mesh.normal[floor]
        self.rate_index = None
        # and the wall cells as contacts: their pseudo-balls, arcs and tub positions (m, at
        # the slice's middle in y)
        self.wall_point = np.searchsorted(cells, wc)
        self.wall_arc = np.array(mesh.arc[wc], dtype=np.float64)
        self.wall_position = np.stack([xw[:, 0], np.full(wc.size, 0.5 * self.geo.length),
                                       xw[:, 1]], axis=1)
        self.wall_contacts = wall_contacts_work(wc.size, floor.size)
        self.part_cells = [] if mesh.part_of is None else \
            [np.nonzero(mesh.part_of == k)[0] for k in range(len(scenario.parts or []))]
        self.part_packed = packed_section(continuum_parts(scenario)) if self.part_cells else None
        # with the granular temperature and its walls: the U wall's feed over each sample's
        # step, whose start it keeps (wall_feed.py)
        model = getattr(system, "temperature", None)
        self.feed = EulerianWallFeed(system, state, self.wall_cells) \
            if model is not None and model.walls is not None else None
        self.keeps_sample_step_start = self.feed is not None
        self.buf_p, self.buf_v = np.zeros((n, 3)), np.zeros((n, 3))
        self.far = np.array([0.0, 0.5 * self.geo.length, 1.0e3])  # outside every analysis cell
        self.dither = np.zeros(n)
        self.vtk = None
        if vtk:
            from ..paraview import ContinuumVtk  # noqa: PLC0415  (only with vtk: pyevtk)

            self.vtk = ContinuumVtk(scenario, out, vtk, self.pv, self.vtk_kinds)
            self.vtk_kinds = self.vtk.kinds

    def record(self, j: int, samples) -> None:
        system, state, geo, mesh = self.system, self.state, self.geo, self.system.mesh
        cells, wall_cells, dither = self.cells, self.wall_cells, self.dither
        run = self.scenario.run
        S = samples.pos.shape[0]
        hist = state.wall
        pose6 = np.array(system.frame.pose(state.t))
        ox, oz = cell_offset(j)
        dithered_cells_to_lab(self.xc, ox * mesh.h, oz * mesh.h, cells, state.v, state.mass,
                              self.unit, dither, pose6, self.pv[0], self.pv[1],
                              0.5 * geo.length, self.far, self.buf_p, self.buf_v)
        samples.pos[j], samples.vel[j], samples.poses[j] = self.buf_p, self.buf_v, pose6
        # the wall contacts (the wall layer's cells holding at least half a cell, pressing on
        # the U) and the floor force: the wall layer's penalty force (not the share its closed
        # faces carry), its z component on the floor's cells (sample_wall.py)
        wc = self.wall_contacts
        n_touch, samples.floor_force[j] = wall_sample(
            hist["state"], hist["fn"], hist["ft"], state.mass, 0.5 * self.full, wall_cells,
            self.wall_point, self.wall_arc, self.wall_position, self.floor_cells,
            self.floor_normal, geo.length, wc)
        samples.add_contact_rows(j, n_touch, wc.particle, wc.fn, wc.ft, wc.sliding, wc.arc,
                                 wc.position)
        if samples.n_parts:
            samples.add_part_forces(j, self._part_forces(), self._part_torques(), geo.length)
        if self.vtk and j >= S - run.phases_per_cycle:
            self._frame(sample_tag(j), pose6, shear_rate(state.L), samples)
        if self.rate_index is None:
            self.rate_index = samples.cell_index(self.xc) if samples.cell_grid is not None \
                else np.full(cells.size, -1, np.int64)
        # the cells holding material (at least half a cell), their rates and what the maps
        # take of them, in the cells' order (sample_rates.py)
        sel = self.held
        n_held, _ = held_rates(state.L, state.mass, 0.5 * self.full, cells,
                               self.rate_index, state.volume, state.stress,
                               self.near_wall, self.probe_members, self.probe_ptr, sel)
        held = sel.held
        samples.rate_all[j], samples.rate_wall[j] = sel.means[0], sel.means[1]
        samples.rate_probe[j] = sel.means[2:]
        if n_held:
            samples.add_cell_rates_at(sel.index[:n_held], sel.rate[:n_held])
            samples.add_cell_stresses_at(j, sel.index[:n_held], sel.volume[:n_held],
                                         sel.stress[:n_held])
        if getattr(state, "temperature", None) is not None:
            # the cells that hold material as the shear rates count them
            samples.add_temperatures(j, system.x[cells][held], state.mass[cells][held],
                                     state.temperature[cells][held])
        if self.feed is not None and self.feed.start is not None and samples.temperature:
            samples.wall_feed[j] = feed_by_region(*self.feed.feed(), geo.radius)

    def sample_step_start(self):
        return self.feed.last_step_start()

    def _part_forces(self) -> np.ndarray:
        """(n_parts, 2) the wall law's force (N/m) on the material from each part's wall
        layer (wall.wall_force_on_material)."""
        return np.array([wall_force_on_material(c, self.system.mesh.normal, self.state.wall)
                         for c in self.part_cells]).reshape(-1, 2)

    def _part_torques(self) -> np.ndarray:
        """(n_parts,) the torque (N m/m, about y) on each part of its wall layer's forces
        (part_obstacle.torque_on_part)."""
        y = 0.5 * self.geo.length
        return np.array([torque_on_part(self.part_packed, k, y, self.system.x[c],
                                        wall_forces_by_cell(c, self.system.mesh.normal,
                                                            self.state.wall))
                         for k, c in enumerate(self.part_cells)])

    def _frame(self, tag: str, pose6, rate_all, samples) -> None:
        """The ParaView files of the state now (grid fields, tub) as frame `tag`."""
        system, state = self.system, self.state
        fields = grid_fields(system.mesh.grid, system.x, state.v, state.mass,
                             state.pressure(), rate_all, system.material.solid_density)
        self.vtk.grid(tag, state.t, pose6, system.mesh.grid, fields, samples)
        self.vtk.tub(tag, state.t, pose6, samples)

    def early_frame(self, k: int, samples) -> None:
        self._frame(early_tag(k), np.array(self.system.frame.pose(self.state.t)),
                    shear_rate(self.state.L), samples)

    def radius(self):
        material = self.system.material
        h = self.system.mesh.h
        unit_volume = (UNIT * material.critical_density * h * h * self.geo.length
                       / material.solid_density)
        return np.full(self.n_points, np.cbrt(3.0 * unit_volume / (4.0 * math.pi)))

    def arrays(self) -> dict:
        return {"dither": self.dither}

    def restore(self, arrays: dict) -> None:
        self.dither = arrays["dither"].copy()


class FixedMesh(Formulation):
    """The Eulerian fixed mesh (module docstring; solver.py explains the design)."""

    name = "eulerian"
    description = ("fixed mesh of the tub, volume fraction transport "
                   "(vibroflow.continuum.eulerian)")

    def options(self, **settings) -> ContinuumOptions:
        """No FLIP fraction: the mesh's cells are fresh copies of the fields at every step,
        with no velocity of their own to keep."""
        options = ContinuumOptions(**{"transfer_cfl": DEFAULT_TRANSFER_CFL, **settings})
        if options.flip != 0.0:
            raise InputError(f"flip = {options.flip!r}: the Eulerian formulation has no FLIP "
                             "option (only 0)")
        return options

    def default_grid(self, scenario) -> float:
        """`mesh_dx` of options.default_dx (the mesh's cells must fill the tub's width)."""
        return mesh_dx(geometry_of(scenario).radius, default_dx(scenario))

    def make_system(self, scenario, material, calibration, options, frame) -> EulerianSystem:
        """The U's mesh, the wall (stiffness (K + 4G/3) / (dx/2) unless set) and partitions,
        the time step."""
        geo = geometry_of(scenario)
        dx = self.grid(options, scenario)
        parts = continuum_parts(scenario)
        mesh = EulerianMesh.tub(geo, dx, parts, packed_section(parts))
        wall_pair, mu_w, mu_p = boundary_friction(scenario, calibration,
                                                   options.partition_friction)
        M = material.bulk_modulus + 4.0 * material.shear_modulus / 3.0
        k_wall = options.wall_stiffness if options.wall_stiffness is not None else M / mesh.h
        wall = MeshWall(stiffness=k_wall, friction=mu_w,
                        damping_ratio=damping_ratio(wall_pair.restitution))
        partitions = None
        if mu_p is not None:
            partitions = PartitionFriction(friction=mu_p, length=geo.length)
        dt = run_step(material, dx, mesh.h, [wall], scenario, options)
        return EulerianSystem(mesh, material, dt, frame=frame, wall=wall, partitions=partitions,
                              chunks=scenario.run.force_chunks,
                              transfers=self.transfers_on(options, scenario),
                              temperature=temperature_model(scenario, options, mesh.h,
                                                            calibration))

    def initial_state(self, scenario, system) -> tuple[EulerianState, float]:
        g = math.hypot(float(scenario.gravity[0]), float(scenario.gravity[2]))
        mass, density, stress, top = bed_masses(system, bed_area(scenario, system.material), g)
        return init_state(system, mass, density, stress=stress), top

    def advance(self, system, state, steps: int, keep=None) -> None:
        advance(system, state, steps, keep)

    def restore(self, system, saved, meta: dict) -> EulerianState:
        return state_from_checkpoint(system, saved, meta)

    def checkpoint_meta(self, state) -> dict:
        return {"mass0": state.mass0, "mass_error_max": state.mass_error_max}

    def sampler(self, scenario, system, state, out: Path, vtk) -> CellSampler:
        return CellSampler(scenario, system, state, out, vtk)

    def continuum_block(self, system, state, bed_height: float) -> dict:
        mesh = system.mesh
        h = mesh.h
        n_cells = int(mesh.inside.sum())
        return {
            "method": ("eulerian (fixed mesh in the tub frame, coupled Eulerian-Lagrangian "
                       "split: B-spline Lagrangian step + conservative MUSCL remap, 2D plane "
                       "strain)"),
            "grid_spacing_m": mesh.grid.dx, "cell_size_m": h, "cells": n_cells,
            # the material point method's names: the cells are the fixed integration points
            "point_spacing_m": h, "points": n_cells,
            "wall_friction": system.wall.friction, "wall_stiffness_Pa_m": system.wall.stiffness,
            "partition_friction": (system.partitions.friction if system.partitions is not None
                                   else None),
            "mass_kg_per_m": {"initial": state.mass0, "final": state.total_mass()},
            "mass_error": state.mass_error(), "mass_error_max_abs": state.mass_error_max,
            "max_solid_fraction": float(state.mass.max()
                                        / (h * h * system.material.solid_density)),
        }

    def column_system(self, L0, H0, dx, material, floor_friction, wall_friction, symmetric,
                      reach, cfl, rough_floor, flip, axisymmetric, transfers) -> EulerianSystem:
        """The box's walls share one law: `wall_friction` must be 0 (the wall x = 0 of a
        column against it has the floor's friction); no FLIP option."""
        if wall_friction != 0.0:
            raise InputError(f"wall_friction = {wall_friction!r}: the Eulerian column's walls "
                             "share the floor's friction (floor_friction); only 0")
        if flip != 0.0:
            raise InputError(f"flip = {flip!r}: the Eulerian formulation has no FLIP option "
                             "(only 0)")
        return column.column_system(L0, H0, dx, material, floor_friction, symmetric, reach,
                                    cfl, rough_floor, axisymmetric, transfers)

    def column_state(self, system, L0, H0, symmetric) -> EulerianState:
        return column.column_state(system, L0, H0, symmetric)

    def column_deposit(self, system, state):
        has = state.mass > 0
        return state.x[has, 0], state.mass[has], system.mesh.h


FORMULATION = FixedMesh()
