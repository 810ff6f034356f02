"""Many Eulerian steps in one numba call, parallel over fixed chunks of cells.

The step is solver.py's (lagrangian_step.py's Lagrangian step, then advection.py's remap) with
the same kernels, but run as one compiled loop over `nsteps` steps: a Python step spent about a
third of its time in its own bookkeeping (gathering the cells that hold material with fancy
indexing, packing the remap's fields, dispatching a dozen kernels, the frame's pose).

Threads: every loop writes only what is its own, so the numbers are the serial loop's whatever
the threads.  The per-cell kernels write their own cells in fixed chunks of cells; the scatter,
the gather and the transfer operator (column_scatter.py, column_gather.py, operator_build.py)
are a pass along the cell columns in fixed chunks of columns and one across them, each node row
summed by one thread in a fixed order, so no per-chunk buffers are summed (the grid's part of
the step, grid_step.grid_phase, then has no chunks to add); the remap's fluxes are made field
by field (advection.remap_fluxes) over the rows that can hold material (remap_rows.py) and
its renewal cell by cell in chunks of columns (advection.renewed, field by field in the packed
fields, which are then unpacked into the cells' arrays).  On one thread, and on a small mesh
while other processes hold the cores (solver.parallel_loop), the loop is compiled without
numba's parallel loops (`advance_kernel_serial`, the same code): a parallel loop's launch, even
with one thread, costs ~1.5 us, a step has eight of its own and one a further transfer (fifteen
with tub47's eight transfers), and a barrier on a busy machine waits for the scheduler.

The cells' B-spline weights on the grid are the mesh's constant tables (transfer.py), and the
cells' fields are read and written in place; only the remap packs its fields, on its own rows.

Records (numba named tuples): `Cells` the state's arrays (solver.EulerianState), `CellStep` the
step's constants, `MeshRecord` the mesh's, `MeshBoundaries` the wall and the partitions,
`CellWork` the remap's work arrays, and the grid's GridSpec and GridWork (grid_step.py).

An edit to any kernel the loop calls drops the package's numba cache (vibroflow/_kernel_cache.py),
so the cached loop never keeps an old copy of them.
"""
from __future__ import annotations

from collections import namedtuple

import numba as nb
import numpy as np

from ..boundary import partition_forces
from ..constitutive import P_ETA_BED
from ..grid_step import grid_phase, grid_phase_serial
from ..stress_update import damped_stress
from ..kinetic_stress import RATE_RATIO
from ..temperature_field import add_stress
from .advection import remap_fluxes, remap_fluxes_serial
from .column_gather import gather_columns, gather_rows
from .column_scatter import scatter_columns, scatter_rows
from .face_velocity import face_velocity_rows, match_divergence_cells
from .lagrangian_step import (end_density, fill_limit, material_fraction,
                              update_stress_cells, void_first)
from .operator_build import operator_columns, operator_rows
from .remap_rows import bed_top, fit_rows, pack_cells, pack_faces, renew_columns
from .wall import wall_forces

#: status of `advance_kernel`
OK, NEGATIVE_MASS, NON_FINITE = 0, 1, 2

#: the cells' arrays (solver.EulerianState's, units there), stress_work (N, 4) the stress
#: scattered when the material has a bed viscosity (stress_update.damped_stress, on every
#: cell) or a kinetic stress ((0, 4) without either), p_kin (N, 5) the granular temperature's
#: stress (Pa) added to the scattered one and its return map's rate ratio (kinetic_stress.py;
#: (0, 5) without the temperature)
Cells = namedtuple("Cells", ["mass", "v", "C", "L", "stress", "gamma_dot", "phase", "frac",
                             "volume", "density", "fext", "stress_work", "p_kin"])
#: the step's constants: dt (s), the material's params (constitutive.ContinuumMaterial.
#: as_array), the frame (grid_update.FRAME_FIELDS), the critical density rho_c (kg/m^3) and
#: the initial total mass mass0 (kg/m; 0: not tracked), and the cells' chunks (the
#: per-cell loops' fixed chunks of cells and of columns: the numbers do not depend on them)
CellStep = namedtuple("CellStep", ["dt", "params", "frame", "rho_c", "mass0", "chunks"])
#: the mesh (mesh.EulerianMesh): cell side h (m), open faces open_x (ncx + 1, ncz) and open_z
#: (ncx, ncz + 1), the wall cells' inward normals normal (N, 2), the weight tables
#: (transfer.WeightTables as a tuple (cx, cz, fx, fz)), weight, inv_r (N,) an
#: axisymmetric section's cell radii and their reciprocals (1 and 0 in plane strain;
#: solver.EulerianSystem.axisymmetric), the node rows' cell columns (transfer.NodeRowColumns)
#: and the tables of the cells' transfer operator (operator_build.OperatorTables; empty with
#: one transfer a step)
MeshRecord = namedtuple("MeshRecord", ["h", "open_x", "open_z", "normal", "tables", "weight",
                                       "inv_r", "columns", "operator"])
#: the mesh's wall (wall.MeshWall; wall_on False without): its cells (int64 indices), its
#: history (wall.empty_history: delta, xi, fn, ft, state), stiffnesses kn, kt (Pa/m), damping
#: ratio zeta and friction mu; the partitions' friction (boundary.PartitionFriction;
#: partitions_on False without): mu_p (-), spacing length (m)
MeshBoundaries = namedtuple("MeshBoundaries", [
    "wall_on", "wall_cells", "delta", "xi", "fn", "ft", "state", "kn", "kt", "zeta", "mu",
    "partitions_on", "mu_p", "length"])
#: the remap's work arrays: face velocities ux (ncx + 1, ncz), uz (ncx, ncz + 1) (m/s),
#: the remap's on the rows that can hold material (remap_rows.RowsWork), the end-of-step
#: density end_rho (N,), the scatter's column sums zscat (column_scatter.scatter_work), the
#: gather's node row sums zgath (column_gather.gather_work) and the transfer operator's build
#: arrays (operator_build.operator_work: the columns' sums S, the node rows' sums rows; empty
#: with one transfer a step)
CellWork = namedtuple("CellWork", ["ux", "uz", "remap", "end_rho", "zscat", "zgath", "S",
                                   "rows"])


def _make_advance_kernel(parallel: bool):
    """The compiled loop: numba's parallel loops, or the same loops run serially (`parallel`
    False: the one-thread loop, module docstring); `parallel` is a closure constant, so the two
    are cached apart."""

    @nb.njit(cache=True, parallel=parallel)
    def advance_kernel(nsteps, t, mass_error_max, cells, step, mesh, boundaries, grid, work,
                       cell_work):
        """Up to nsteps steps of step.dt (s) from time t (s) of the cells' arrays, in place
        (module docstring): cells (Cells), step (CellStep), mesh (MeshRecord), boundaries
        (MeshBoundaries), grid (grid_step.GridSpec), work (grid_step.GridWork), cell_work
        (CellWork); mass_error_max the largest |M - M0| / M0 so far.

        Returns (steps done, t, status, lowest cell mass kg/m, largest |M - M0| / M0 so far):
        status OK, NEGATIVE_MASS (a cell lost more mass than it held) or NON_FINITE (a velocity),
        found at the end of the last step made."""
        _ = parallel
        (mass, v, C, L, stress, gamma_dot, phase, frac, volume, density, fext, stress_work,
         p_kin) = cells
        dt, params, frame, rho_c, mass0, nchunk = step
        h, open_x, open_z, normal, tables, weight, inv_r, row_columns, op_tables = mesh
        (wall_on, wall_cells, delta, xi, wfn, wft, wst, kn, kt, zeta, mu_w, part_on, mu_p,
         length) = boundaries
        x0, z0, dx, periodic, no_slip_rows, axis_cols = grid
        cm, cmv, cf, gm, gmv, gf, gv, transfers, cb, B, gtmp = work
        ux, uz, rw, end_rho, zscat, zsums, col_S, op_rows = cell_work
        n = mass.shape[0]
        tcx, tcz, tcfz = tables[0], tables[1], tables[3]
        ncx = open_z.shape[0]
        ncz = open_x.shape[1]
        rwork = rw.work
        nq = rwork[9].shape[0]
        # the remap's inflows and renewal modes (advection.remap_work), named here: a parallel
        # loop takes arrays, not the tuples that hold them
        r_dm, r_inv, r_mode, r_dq, r_ux = rwork[0][3], rwork[0][4], rwork[6], rwork[9], rw.ux
        nxg = gm.shape[0]
        rcols, rcol_a, rncols = row_columns
        op_xf, op_zf = op_tables
        mtol = -1e-9 * rho_c * h * h
        m2 = mass.reshape((ncx, ncz))
        damped = params[P_ETA_BED] > 0.0
        kinetic = p_kin.shape[0] > 0
        scattered = stress_work if damped or kinetic else stress
        chunk_finite = np.ones(nchunk, np.bool_)
        chunk_lowest = np.empty(nchunk)
        for s in range(nsteps):
            # lagrangian_step.lagrangian_step: forces, the cells holding material to the nodes
            fext[:] = 0.0
            if wall_on:
                wall_forces(wall_cells, normal, v, mass, rho_c, h, weight, delta, xi, fext, wfn,
                            wft, wst, kn, kt, zeta, mu_w, dt)
            # the cell rows up to the highest cell with any mass (every such cell gathered, so
            # that no cell the temperature's conduction reaches keeps an old rate)
            ktop = 0
            for ic in range(ncx):
                for kc in range(ncz - 1, ktop - 1, -1):
                    if mass[ic * ncz + kc] > 0.0:
                        ktop = kc + 1
                        break
            # the remap's rows (remap_rows.py): up to one above the highest that is not empty,
            # on their own layout
            kr = min(bed_top(mass, ncx, ncz, h, rw.weights[0]) + 1, ncz)
            nr = ncx * kr
            fit_rows(rw, kr, ncx, ncz)
            mr = rw.mass[:nr]
            qr = rw.q[:nq * nr].reshape((nq, nr))
            # cell by cell, in chunks of cells: the volume fractions, the partitions' friction
            # (after the wall's force, as in the step by step path), the bed's Kelvin-Voigt
            # damping on the rate of the last step and the kinetic pressure
            # (temperature_field.py), both scattered with the stress but not stored in it
            for c in nb.prange(nchunk):
                a = (c * n) // nchunk
                b = ((c + 1) * n) // nchunk
                material_fraction(mass[a:b], density[a:b], h, weight[a:b], frac[a:b],
                                  volume[a:b])
                if part_on:
                    partition_forces(v[a:b], mass[a:b], volume[a:b], stress[a:b], fext[a:b],
                                     mu_p, length, dt)
                if damped:
                    damped_stress(stress[a:b], L[a:b], phase[a:b], params, stress_work[a:b])
                if kinetic:
                    if not damped:
                        stress_work[a:b] = stress[a:b]
                    add_stress(stress_work, p_kin, a, b)
            # the cells to the nodes (column_scatter.py) and, with further transfers, the
            # transfer operator (operator_build.py): each a pass along the cell columns, in
            # chunks of columns, then one across them, node row by node row
            for c in nb.prange(nchunk):
                c0 = (c * ncx) // nchunk
                c1 = ((c + 1) * ncx) // nchunk
                scatter_columns(c0, c1, ktop, tcz, dx, mass, volume, v, C, scattered, fext,
                                inv_r, zscat)
                if transfers > 1:
                    operator_columns(c0, c1, ktop, m2, tcz, op_zf, col_S)
            if parallel:
                for i in nb.prange(nxg):
                    scatter_rows(i, i + 1, ktop, tcx, tcz, dx, rcols, rcol_a, rncols, zscat,
                                 gm, gmv, gf)
                    if transfers > 1:
                        operator_rows(i, i + 1, ktop, tcz, col_S, op_xf, rcols, rcol_a,
                                      rncols, op_rows, B)
            else:
                scatter_rows(0, nxg, ktop, tcx, tcz, dx, rcols, rcol_a, rncols, zscat, gm, gmv,
                             gf)
                if transfers > 1:
                    operator_rows(0, nxg, ktop, tcz, col_S, op_xf, rcols, rcol_a, rncols,
                                  op_rows, B)
            # the grid's part (grid_step.py): the chunks' sums, the update with the frame's
            # acceleration at mid-step, the grid's conditions and the further transfers
            # (the gather below reads the returned grid velocity, so it stays after the call)
            if parallel:
                gv = grid_phase(grid, work, frame, t, dt)
            else:
                gv = grid_phase_serial(grid, work, frame, t, dt)
            # the gather (column_gather.py): the node rows' sums along z, then across the
            # columns
            if parallel:
                for i in nb.prange(nxg):
                    gather_rows(i, i + 1, ktop, tcz, tcfz, dx, gv, zsums)
            else:
                gather_rows(0, nxg, ktop, tcz, tcfz, dx, gv, zsums)
            for c in nb.prange(nchunk):
                gather_columns((c * ncx) // nchunk, ((c + 1) * ncx) // nchunk, ktop, ncz, tcx,
                               dx, periodic, zsums, mass, v, C, L)
                # and the remap's face velocities, which need only the node rows' sums: in
                # the same parallel loop, one launch fewer
                face_velocity_rows((c * (ncx + 1)) // nchunk, ((c + 1) * (ncx + 1)) // nchunk,
                                   zsums, tables, periodic, open_x, open_z, m2, ux, uz)
            # each cell's divergence, void, end density and stress, then the fields the remap
            # carries (solver.py, step 2) and the masses packed on the remap's rows: cell by
            # cell, in chunks of cells (the face velocities above are every chunk's, so this
            # loop comes after that one)
            for c in nb.prange(nchunk):
                a = (c * n) // nchunk
                b = ((c + 1) * n) // nchunk
                pack_faces((c * (ncx + 1)) // nchunk, ((c + 1) * (ncx + 1)) // nchunk, ux, kr,
                           r_ux)
                match_divergence_cells(a, b, L, ux, uz, h, v, normal, mass, open_x, open_z,
                                       inv_r)
                void_first(L[a:b], frac[a:b], density[a:b], rho_c, dt)
                end_density(density[a:b], L[a:b], dt, end_rho[a:b])
                update_stress_cells(a, b, stress, L, end_rho, dt, params, gamma_dot, phase,
                                    p_kin[:, RATE_RATIO])
                pack_cells(a, b, kr, ncz, v, C, stress, end_rho, mass, qr, mr)
            if parallel:
                remap_fluxes(mr.reshape((ncx, kr)), qr.reshape((nq, ncx, kr)),
                             r_ux[:(ncx + 1) * kr].reshape((ncx + 1, kr)), uz, h, dt,
                             periodic, rwork)
            else:
                remap_fluxes_serial(mr.reshape((ncx, kr)), qr.reshape((nq, ncx, kr)),
                                    r_ux[:(ncx + 1) * kr].reshape((ncx + 1, kr)), uz, h,
                                    dt, periodic, rwork)
            # the remap's end (its fields renewed, the masses moved), the fields unpacked and
            # each cell filled no further than full, in chunks of columns
            for c in nb.prange(nchunk):
                c0 = (c * ncx) // nchunk
                c1 = ((c + 1) * ncx) // nchunk
                # advection.renew_cells on the remap's rows, the fields unpacked
                low, finite_c = renew_columns(c0, c1, kr, ncz, qr, mr, r_dq, r_mode, r_inv,
                                              r_dm, v, C, stress, density, mass)
                chunk_lowest[c] = low
                chunk_finite[c] = finite_c
                fill_limit(mass[c0 * ncz:c1 * ncz], density[c0 * ncz:c1 * ncz], h,
                           weight[c0 * ncz:c1 * ncz])
            finite = True
            lowest = np.inf
            for c in range(nchunk):
                finite = finite and chunk_finite[c]
                if chunk_lowest[c] < lowest:
                    lowest = chunk_lowest[c]
            t += dt
            if lowest < mtol or not np.isfinite(lowest):
                return s + 1, t, NEGATIVE_MASS, lowest, mass_error_max
            if not finite:
                return s + 1, t, NON_FINITE, lowest, mass_error_max
            if mass0 > 0.0:
                # summed in order: in the parallel loop `mass.sum()` is a parallel reduction,
                # whose rounding would differ from the one-thread loop's
                total = 0.0
                for icell in range(n):
                    total += mass[icell]
                err = abs(total - mass0) / mass0
                if err > mass_error_max:
                    mass_error_max = err
        return nsteps, t, OK, 0.0, mass_error_max

    return advance_kernel


advance_kernel = _make_advance_kernel(True)
advance_kernel_serial = _make_advance_kernel(False)
