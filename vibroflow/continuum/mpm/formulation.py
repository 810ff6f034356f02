"""The material point method as a continuum formulation (continuum.formulation.Formulation) of a
tub run and of the column collapse.

The tub (continuum.tub_run's timeline): the settled bed's material points on a square lattice
of side dx/2 (4 a grid cell) inside the U below the bed's height h (bed.py), at rest under the
lithostatic stress, their densities those the elastic law gives that pressure; the points
share the bed's area (their lattice misses a sliver along the curved wall).  Each point is
sampled as a "ball" of the point's solid volume m_p L_y / rho_s at its centre, with its lab
position and velocity; its wall contacts are the points touching the U.  The wall's normal
stiffness is constant: (K + 4G/3) / l0 with l0 the point spacing (the bed's elastic stiffness
over one point), its damping ratio that of the scenario's ball-wall restitution.  Each part of
the scenario's [[parts]] is a wall of the same law (boundary.PartWall, part_obstacle.py), the
bed's points filled around it, and each sample records the force on it.  With vtk,
ParaView files of the points and of the grid fields over the last cycle (continuum.paraview).

The column collapse: mpm/column.py's set-up.
"""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numba as nb
import numpy as np

from vibroflow.errors import InputError
from vibroflow.scenario.laws import damping_ratio
from vibroflow.tub.geometry import distance_to_wall_np, geometry_of, u_wall_nearest

from ..bed import bed_area, bed_height, lithostatic
from ..boundary import PartitionFriction, PartWall, UWall
from ..fields import grid_fields
from ..files import early_tag, sample_tag
from ..formulation import Formulation, Sampler
from ..grid import Grid
from ..material import boundary_friction
from ..options import ContinuumOptions, default_dx
from ..part_obstacle import (bed_height_around, continuum_parts, packed_section, section_gaps,
                             torque_on_part)
from ..sampling import shear_rate, to_lab
from ..temperature_field import temperature_model
from ..timestep import run_step
from ..wall_feed import LagrangianWallFeed, feed_by_region
from . import column
from .solver import MPMState, MPMSystem, advance, init_state

#: the Courant number of the APIC transfers (options.ContinuumOptions.transfer_cfl):
#: round(0.3 / 0.015) = 20 transfers a step at the default cfl 0.3.  The rate whose field is
#: closest to the DEM's on tub47 (E 0.347 +- 0.006 against the DEM's seed-to-seed 0.135,
#: strength 0.98 of the DEM's): docs/decisions/transfer-rate.md.
DEFAULT_TRANSFER_CFL = 0.015


@nb.njit(cache=True)
def _wall_gap_arc(x, radius, gap_out, arc_out):
    """Distance (m) of each point from the U wall and the arc-length coordinate (m) of its
    nearest wall point (tub.geometry)."""
    for p in range(x.shape[0]):
        r = u_wall_nearest(x[p, 0], x[p, 1], radius)
        gap_out[p] = r[0]
        arc_out[p] = r[5]


def _part_torque(wall: PartWall, state) -> float:
    """The torque (N m/m, about y) on the part of `wall` of its contact forces on the points
    touching it (part_obstacle.torque_on_part)."""
    f = state.history[wall.slot]["f"]
    touching = np.nonzero(state.history[wall.slot]["state"] > 0)[0]
    return torque_on_part(wall.packed, wall.index, wall.y, state.x[touching], f[touching])


def settled_bed(scenario, material, spacing: float):
    """Points of the settled bed (tub frame): positions (N, 2) m, volumes (N,) m^2, densities
    (N,) kg/m^3, stresses (N, 4) Pa, and the bed height h (m) (module docstring).  Around parts
    (part_obstacle.py) the bed rises by their sections below it and no point's square reaches
    into one."""
    geo = geometry_of(scenario)
    area = bed_area(scenario, material)
    parts = continuum_parts(scenario)
    packed = packed_section(parts)
    y = 0.5 * geo.length
    h = bed_height_around(lambda a: bed_height(geo.radius, a, geo.rim_height), area, parts,
                          packed, y) if parts else bed_height(geo.radius, area, geo.rim_height)
    xs = np.arange(-geo.radius + spacing / 2, geo.radius, spacing)
    zs = np.arange(spacing / 2, h, spacing)
    X, Z = np.meshgrid(xs, zs, indexing="ij")
    X, Z = X.ravel(), Z.ravel()
    keep = distance_to_wall_np(X, Z, geo.radius) >= 0.5 * spacing  # the square inside the U
    if parts:
        keep &= section_gaps(parts, packed, y, X, Z) >= 0.5 * spacing
    x = np.stack([X[keep], Z[keep]], axis=1)
    n = x.shape[0]
    if n == 0:
        raise InputError(f"dx = {2.0 * spacing!r}: the bed ({h:.3g} m deep) is thinner than one "
                         f"point ({spacing:.3g} m); refine dx")
    g = math.hypot(scenario.gravity[0], scenario.gravity[2])
    rho_c = material.initial_density  # rho_c unless the bed starts denser (dilatancy)
    stress, density = lithostatic(rho_c, g, np.clip(h - x[:, 1], 0.0, None), material.mu_s,
                                  material.bulk_modulus)
    # the points share the bed's area (their lattice misses a sliver along the curved wall)
    volume = np.full(n, area / n) * rho_c / density
    return x, volume, density, stress, h


def _write_points_vtu(vtk, tag: str, t: float, pose6, state: MPMState, rate: np.ndarray,
                      solid_density: float, samples) -> None:
    """The material points as a ParaView point cloud (continuum.paraview, y = the slice's
    middle), radius half the side of a point's square."""
    vtk.points(tag, t, pose6, state.x, state.v, 0.5 * np.sqrt(state.volume),
               {"pressure_Pa": state.pressure(), "shear_rate_per_s": rate,
                "solid_fraction": state.density / solid_density,
                "state": state.phase.astype(np.float64)}, samples)


class PointSampler(Sampler):
    """The material points as the DEM's balls (module docstring)."""

    vtk_kinds = ("points", "grid")

    def __init__(self, scenario, system: MPMSystem, state: MPMState, out: Path, vtk):
        self.scenario, self.system, self.state = scenario, system, state
        self.out = out
        self.geo = geometry_of(scenario)
        self.n_points = n = state.n
        motion = system.frame.motion
        self.pv = (motion.pivot_x, motion.pivot_z)
        self.cell = cell = scenario.analysis.cell_size
        self.probe_cells = [(math.floor(pr.x / cell + 0.5), math.floor(pr.z / cell + 0.5))
                            for pr in scenario.analysis.probes.values()]
        self.buf_p, self.buf_v = np.zeros((n, 3)), np.zeros((n, 3))
        self.arc, self.gap = np.zeros(n), np.zeros(n)
        # with the granular temperature and its walls: the U wall's feed (wall_feed.py)
        model = system.temperature
        self.feed = LagrangianWallFeed(system, state) \
            if model is not None and model.walls is not None else None
        self.vtk = None
        if vtk:
            from ..paraview import ContinuumVtk  # noqa: PLC0415  (only with vtk: pyevtk)

            self.vtk = ContinuumVtk(scenario, out, vtk, self.pv, self.vtk_kinds)
            self.vtk_kinds = self.vtk.kinds

    def record(self, j: int, samples) -> None:
        system, state, geo = self.system, self.state, self.geo
        run = self.scenario.run
        S = samples.pos.shape[0]
        wall_hist = state.history[0]
        pose6 = np.array(system.frame.pose(state.t))
        to_lab(state.x, state.v, pose6, self.pv[0], self.pv[1], self.buf_p, self.buf_v,
               0.5 * geo.length)
        samples.pos[j], samples.vel[j], samples.poses[j] = self.buf_p, self.buf_v, pose6
        touching = np.nonzero(wall_hist["state"] > 0)[0]
        _wall_gap_arc(state.x, geo.radius, self.gap, self.arc)
        samples.add_contacts(j, touching, wall_hist["fn"][touching], wall_hist["ft"][touching],
                             wall_hist["state"][touching], self.arc[touching],
                             state.x[touching], geo.length)
        samples.add_floor_force(j, wall_hist["f"][touching, 1], state.x[touching], geo.radius,
                                geo.length)
        if samples.n_parts:
            walls = [b for b in system.boundaries if isinstance(b, PartWall)]
            samples.add_part_forces(j, np.array([state.history[b.slot]["f"].sum(axis=0)
                                                 for b in walls]),
                                    np.array([_part_torque(b, state) for b in walls]),
                                    geo.length)
        rate = shear_rate(state.L)
        if self.vtk and j >= S - run.phases_per_cycle:
            self._frame(sample_tag(j), pose6, rate, samples)
        samples.rate_all[j] = rate.mean()
        samples.add_cell_rates(state.x, rate)
        samples.add_cell_stresses(j, state.x, state.volume, state.stress)
        if state.temperature is not None:
            samples.add_temperatures(j, state.x, state.mass, state.temperature)
        if self.feed is not None and samples.temperature:
            samples.wall_feed[j] = feed_by_region(*self.feed.feed(), geo.radius)
        near = self.gap < 0.5 * self.cell
        if near.any():
            samples.rate_wall[j] = rate[near].mean()
        ci = np.floor(state.x[:, 0] / self.cell + 0.5)
        ck = np.floor(state.x[:, 1] / self.cell + 0.5)
        for q, (pi, pk) in enumerate(self.probe_cells):
            inside = (ci == pi) & (ck == pk)
            if inside.any():
                samples.rate_probe[j, q] = rate[inside].mean()

    def _frame(self, tag: str, pose6, rate, samples) -> None:
        """The ParaView files of the state now (points, grid fields, tub) as frame `tag`."""
        system, state = self.system, self.state
        material = system.material
        _write_points_vtu(self.vtk, tag, state.t, pose6, state, rate, material.solid_density,
                          samples)
        fields = grid_fields(system.grid, state.x, state.v, state.mass,
                             state.pressure(), rate, material.solid_density)
        self.vtk.grid(tag, state.t, pose6, system.grid, fields, samples)
        self.vtk.tub(tag, state.t, pose6, samples)

    def early_frame(self, k: int, samples) -> None:
        self._frame(early_tag(k), np.array(self.system.frame.pose(self.state.t)),
                    shear_rate(self.state.L), samples)

    def radius(self):
        return np.cbrt(3.0 * self.state.mass * self.geo.length
                       / (4.0 * math.pi * self.system.material.solid_density))


class MaterialPointMethod(Formulation):
    """The material point method (module docstring)."""

    name = "lagrangian"
    description = "material point method (vibroflow.continuum.mpm)"

    def options(self, **settings) -> ContinuumOptions:
        """No column landing: the points' landing is the wall dashpot's (wall_energy_flux.py),
        with no columns of cells to count it along."""
        options = ContinuumOptions(**{"transfer_cfl": DEFAULT_TRANSFER_CFL, **settings})
        if options.landing != "pairs":
            raise InputError(f"landing = {options.landing!r}: the Lagrangian formulation's "
                             "landing is its wall contacts' (only pairs); columns is Eulerian "
                             "only")
        return options

    def default_grid(self, scenario) -> float:
        """options.default_dx: 3 ball diameters."""
        return default_dx(scenario)

    def make_system(self, scenario, material, calibration, options, frame) -> MPMSystem:
        geo = geometry_of(scenario)
        dx = self.grid(options, scenario)
        spacing = 0.5 * dx
        grid = Grid.covering(-geo.radius, geo.radius, 0.0, geo.rim_height, dx)
        wall_pair, mu_w, mu_p = boundary_friction(scenario, calibration,
                                                   options.partition_friction)
        M = material.bulk_modulus + 4.0 * material.shear_modulus / 3.0
        k_wall = options.wall_stiffness if options.wall_stiffness is not None else M / spacing
        zeta = damping_ratio(wall_pair.restitution)
        boundaries: list = [UWall(radius=geo.radius, stiffness=k_wall, friction=mu_w,
                                  damping_ratio=zeta)]
        parts = continuum_parts(scenario)
        packed = packed_section(parts)
        # each part with the U wall's law (part_obstacle.py), after the U, before the
        # partitions
        boundaries += [PartWall(name=p.name, packed=packed, index=k, y=0.5 * geo.length,
                                stiffness=k_wall, friction=mu_w, damping_ratio=zeta)
                       for k, p in enumerate(parts)]
        if mu_p is not None:
            boundaries.append(PartitionFriction(friction=mu_p, length=geo.length))
        dt = run_step(material, dx, spacing, boundaries, scenario, options)
        return MPMSystem(grid, material, dt, frame=frame, boundaries=boundaries,
                         chunks=scenario.run.force_chunks, flip=float(options.flip),
                         transfers=self.transfers_on(options, scenario),
                         temperature=temperature_model(scenario, options, dx, calibration))

    def initial_state(self, scenario, system: MPMSystem) -> tuple[MPMState, float]:
        x, volume, density, stress, h = settled_bed(scenario, system.material,
                                                    0.5 * system.grid.dx)
        return init_state(system, x, volume, density, stress=stress), h

    def advance(self, system, state, steps: int, keep=None) -> None:
        advance(system, state, steps)  # its samplers keep no step's start

    def restore(self, system, saved, meta: dict) -> MPMState:
        # a run without the temperature stores none
        return MPMState(**{f.name: getattr(saved, f.name) for f in dataclasses.fields(MPMState)
                           if f.name != "temperature" or hasattr(saved, f.name)})

    def sampler(self, scenario, system, state, out: Path, vtk) -> PointSampler:
        return PointSampler(scenario, system, state, out, vtk)

    def continuum_block(self, system, state, bed_height: float) -> dict:
        walls = system.boundaries
        return {
            "method": "lagrangian (material point method, APIC, 2D plane strain, tub frame)",
            "grid_spacing_m": system.grid.dx, "point_spacing_m": 0.5 * system.grid.dx,
            "points": state.n,
            "wall_friction": walls[0].friction, "wall_stiffness_Pa_m": walls[0].stiffness,
            "partition_friction": next((b.friction for b in walls
                                        if isinstance(b, PartitionFriction)), None),
        }

    def column_system(self, L0, H0, dx, material, floor_friction, wall_friction, symmetric,
                      reach, cfl, rough_floor, flip, axisymmetric, transfers) -> MPMSystem:
        return column.column_system(L0, H0, dx, material, floor_friction, wall_friction,
                                    symmetric, reach, cfl, rough_floor, flip, axisymmetric,
                                    transfers)

    def column_state(self, system, L0, H0, symmetric) -> MPMState:
        return column.column_state(system, L0, H0, symmetric)

    def column_deposit(self, system, state):
        return state.x[:, 0], state.mass, 0.5 * system.grid.dx


FORMULATION = MaterialPointMethod()
