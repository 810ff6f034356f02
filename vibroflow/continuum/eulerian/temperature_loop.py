"""Many Eulerian steps with the granular temperature in one numba call.

Each step is the step-by-step path's (temperature_field.advance_with_temperature with
solver.py's balance) made without leaving compiled code: the granular temperature's stress
from the cells' state (temperature_balance.kinetic_stress_of), one step of the fused
mechanical loop (fused.py, parallel or serial as without T), the production sigma : D
(temperature_field.production_W_m3), T carried with the cells' mass by the same transport of
the step's start mass with the step's face velocities as the kernel's remap, the wall layer's
and the partitions' contact terms and the landing in every cell (`cell_wall_sums`,
solver.cell_wall_sums compiled) and the
balance on the cells (temperature_balance.balance_cells).  T is state carried through the
loop as the mechanical fields are.

The balance's part runs serially after the step: its numbers depend on nothing but the state
(the mechanical step's on the cell chunks, never on the threads).  A `StepStart` of n cells
keeps the start of the call's last step (its masses, velocities, densities and the stress it
scatters, the kinetic stress added): what eulerian/wall_feed.py measures that step's landing
from.
"""
from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

from ..column_landing import column_terms
from ..compaction_landing import compaction_terms, x_face_terms
from ..temperature_balance import balance_cells, kinetic_stress_of_cells
from ..temperature_field import pressure_Pa, production_W_m3
from ..wall_energy_flux import contact_terms, landing_terms, partition_terms
from . import fused
from .advection import remap_serial
from .face_impulse import cell_impulse_z


class StepStart(NamedTuple):
    """The start of a compiled call's last step, filled by the loop: mass (n,) kg/m, v (n, 2)
    m/s, density (n,) kg/m^3, stress (n, 4) Pa with the kinetic stress added; of 0 cells: none
    kept."""

    mass: np.ndarray
    v: np.ndarray
    density: np.ndarray
    stress: np.ndarray


def step_start(n: int) -> StepStart:
    """A StepStart of n cells to be filled (0: the loop keeps none)."""
    return StepStart(np.zeros(n), np.zeros((n, 2)), np.zeros(n), np.zeros((n, 4)))


@nb.njit(cache=True)
def cell_wall_sums(boundaries, mesh, grid, work, frame, t_mid, mass, v, volume, stress, fext,
                   rho_c, dt, start_mass, start_v, start_density, start_stress, landing, columns,
                   out):
    """out (N, 4): the cells' wall contact terms of the step just made, the one definition of
    both paths (the compiled loop's and solver.cell_wall_sums'): the wall layer's contacts
    (boundaries a fused.MeshBoundaries; the wall at rest on the mesh (mesh a fused.MeshRecord),
    its inward normal the mesh's, contact length fill h), their landing measured from the
    step's start masses and velocities start_mass (N,) kg/m, start_v (N, 2) m/s when landing
    (wall_energy_flux.landing_terms), the landing of the material stopped by its neighbours
    across the mesh's open faces with the start's densities start_density (N,) kg/m^3 and
    scattered stresses start_stress (N, 4) Pa: by the pairs across the open faces
    (compaction_landing.compaction_terms), or with `columns` along each column by the
    impulse through its z faces that no stress carries (column_landing.column_terms, the
    stress's and the external impulses from the step's grid: face_impulse.cell_impulse_z with
    the grid grid (grid_step.GridSpec) and its work arrays work (GridWork), the step's volumes
    volume (N,) m^2 and external forces fext (N, 2) N/m, the frame at t_mid (s)) and across the
    x faces by the pairs (compaction_landing.x_face_terms); and the partitions'.  mass, v,
    stress: the cells' at the step's end."""
    out[:] = 0.0
    h = mesh.h
    open_x = mesh.open_x
    open_z = mesh.open_z
    normal = mesh.normal
    if landing and columns:
        n = mass.shape[0]
        S = np.empty(n)
        E = np.empty(n)
        cell_impulse_z(start_mass, volume, start_stress, fext, mesh.tables, open_x.shape[1],
                       work.gm, work.gmv, grid.x0, grid.z0, grid.dx, grid.periodic,
                       grid.no_slip_rows, frame, t_mid, dt, S, E)
        column_terms(start_mass, start_v, start_density, mass, v, S, E, h, open_z, rho_c, dt,
                     out)
        x_face_terms(start_mass, start_v, start_density, start_stress, v, h, open_x, rho_c, dt,
                     out)
    elif landing:
        compaction_terms(start_mass, start_v, start_density, start_stress, v, h, open_x, open_z,
                         rho_c, dt, out)
    if boundaries.wall_on:
        c = boundaries.wall_cells
        nc = c.shape[0]
        fn = np.empty(nc)
        ft = np.empty(nc)
        nrm = np.empty((nc, 2))
        vc = np.empty((nc, 2))
        mc = np.empty(nc)
        length = np.empty(nc)
        v0 = np.empty((nc, 2))
        m0 = np.empty(nc)
        for r in range(nc):
            p = c[r]
            fn[r] = boundaries.fn[p]
            ft[r] = boundaries.ft[p]
            mc[r] = mass[p]
            m0[r] = start_mass[p]
            for j in range(2):
                nrm[r, j] = normal[p, j]
                vc[r, j] = v[p, j]
                v0[r, j] = start_v[p, j]
            length[r] = min(1.0, mass[p] / (rho_c * h * h)) * h
        part = np.zeros((nc, 4))
        contact_terms(fn, ft, nrm, vc, mc, length, boundaries.kn, boundaries.zeta, dt, part)
        for r in range(nc):
            part[r, 3] = 0.0
        if landing:
            landing_terms(v0, m0, vc, mc, nrm, fn, dt, part)
        for r in range(nc):
            for j in range(4):
                out[c[r], j] += part[r, j]
    if boundaries.partitions_on:
        partition_terms(v, mass, volume, stress, boundaries.mu_p, boundaries.length, dt, out)


def _make_kernel(parallel: bool):
    """The compiled loop over fused.advance_kernel (`parallel`) or advance_kernel_serial;
    `parallel` is a closure constant, so the two are cached apart."""

    @nb.njit(cache=True)
    def advance_temperature_kernel(nsteps, t, mass_error_max, cells, step, mesh, boundaries,
                                   grid, work, cell_work, T, ts, t_work, keep):
        """Up to nsteps Eulerian steps with the granular temperature T (N,) m^2/s^2 of the
        cells, in place (module docstring); the arguments to t_work as fused.advance_kernel's,
        cells.p_kin (N, 5) the kinetic stress's array; ts a temperature_balance.TemperatureStep;
        t_work the temperature's remap work (advection.remap_work with one field); keep a
        StepStart the last step's start is copied into (of 0 cells: none).

        Returns fused.advance_kernel's (steps done, t, status, lowest cell mass, largest
        |M - M0| / M0): on a status other than OK the step that found it had no balance."""
        mass = cells.mass
        v = cells.v
        p_kin = cells.p_kin
        h = mesh.h
        periodic = grid[3]
        ncx = mesh.open_z.shape[0]
        ncz = mesh.open_x.shape[1]
        n = mass.shape[0]
        power = np.empty(n)
        sums = np.zeros((n, 4))
        production = np.empty(n)
        pressure = np.zeros(n)
        sliding = ts.prm.sliding_coefficient > 0.0
        phi = np.empty(n)
        rho_s = ts.prm.density_kg_m3
        landing = ts.walls and ts.landing
        for s in range(nsteps):
            kinetic_stress_of_cells(cells.density, mass, h, T, cells.L, cells.stress,
                                    cells.gamma_dot, cells.phase, ts, p_kin)
            if s == nsteps - 1 and keep.mass.shape[0] == n:
                keep.mass[:] = mass
                keep.v[:, :] = v
                keep.density[:] = cells.density
                for p in range(n):
                    for c in range(4):
                        keep.stress[p, c] = cells.stress[p, c] + p_kin[p, c]
            m_start = mass.copy()
            v_start = v.copy()
            rho_start = cells.density.copy() if landing else cells.density
            if landing:
                # the stress the step scatters (fused.py: the kinetic stress added)
                sigma_start = cells.stress.copy()
                for p in range(n):
                    for c in range(4):
                        sigma_start[p, c] += p_kin[p, c]
            else:
                sigma_start = cells.stress
            # np.int64(1), not the literal 1: the kernel compiled for the solver's calls serves
            if parallel:
                done, t, status, lowest, mass_error_max = fused.advance_kernel(
                    np.int64(1), t, mass_error_max, cells, step, mesh, boundaries, grid, work,
                    cell_work)
            else:
                done, t, status, lowest, mass_error_max = fused.advance_kernel_serial(
                    np.int64(1), t, mass_error_max, cells, step, mesh, boundaries, grid, work,
                    cell_work)
            if status != fused.OK:
                return s + done, t, status, lowest, mass_error_max
            production_W_m3(cells.stress, cells.L, cells.gamma_dot, p_kin, power)
            if sliding:
                pressure_Pa(cells.stress, pressure)
            if ts.walls:
                cell_wall_sums(boundaries, mesh, grid, work, step.frame, t - 0.5 * ts.dt, mass,
                               v, cells.volume, cells.stress, cells.fext, step.rho_c, ts.dt,
                               m_start, v_start, rho_start, sigma_start, landing, ts.columns,
                               sums)
            # T carried with the mass: the step's start mass moved by the step's face velocities
            m_move = m_start.reshape((ncx, ncz)).copy()
            remap_serial(m_move, T.reshape((1, ncx, ncz)), cell_work.ux, cell_work.uz, h, ts.dt,
                         periodic, t_work)
            density = cells.density
            for p in range(n):
                frac = min(1.0, mass[p] / (density[p] * h * h)) if density[p] > 0.0 else 0.0
                production[p] = power[p] * frac
                if sliding:
                    pressure[p] *= frac
                phi[p] = mass[p] / (rho_s * h * h)
            T_new = balance_cells(T.reshape((ncx, ncz)), phi.reshape((ncx, ncz)),
                                  production.reshape((ncx, ncz)),
                                  pressure.reshape((ncx, ncz)), sums.reshape((ncx, ncz, 4)),
                                  ts).ravel()
            T[:] = T_new
        return nsteps, t, fused.OK, 0.0, mass_error_max

    return advance_temperature_kernel


advance_temperature_kernel = _make_kernel(True)
advance_temperature_kernel_serial = _make_kernel(False)
