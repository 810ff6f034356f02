"""Many Eulerian steps in one numba call, parallel over fixed chunks of cells.

The step is solver.py's (lagrangian_step.py's Lagrangian step, then advection.py's remap) with
the same kernels, but run as one compiled loop over `nsteps` steps: a Python step spent about a
third of its time in its own bookkeeping (gathering the cells that hold material with fancy
indexing, packing the remap's fields, dispatching a dozen kernels, the frame's pose).

Threads, as the Lagrangian step's (vibroflow.continuum.fused): the per-cell kernels write only
their own cells and the remap works field by field (advection.remap), so they give the serial
numbers whatever the threads; the cells holding material are scattered to the nodes in `nchunk`
fixed chunks of per-chunk buffers summed in a fixed order, so the run depends on the number of
chunks, never on the number of threads (one chunk: the serial p2g's numbers).  On one thread,
and on a small mesh (solver.SERIAL_BELOW), the loop is compiled without numba's parallel loops
(`advance_kernel_serial`, the same code): on tub47's ~1000 cells a parallel loop's launch,
even with one thread, cost ~1.5 us, and a step has seven of them.

The cells' B-spline weights on the grid are the mesh's constant tables (transfer.py), and the
cells holding material are scattered and gathered in place through their indices (no compact
copies of their fields).

An edit to any kernel the loop calls drops the package's numba cache (vibroflow/_kernel_cache.py),
so the cached loop never keeps an old copy of them.
"""
from __future__ import annotations

import numba as nb
import numpy as np

from ..boundary import partition_forces
from ..constitutive import P_ETA_BED
from ..fused import sum_chunk_rows
from ..grid_update import frame_body, grid_update
from .advection import remap, remap_serial
from .face_velocity import face_velocity_rows, match_divergence
from .lagrangian_step import (end_density, fill_limit, material_fraction,
                              update_stress_cells, void_first)
from ..stress_update import damped_stress
from ..transfer_operator import sum_operator_rows, transfer_rows
from .transfer import g2p_cells, operator_of_cells, p2g_cells
from .wall import wall_forces

#: status of `advance_kernel`
OK, NEGATIVE_MASS, NON_FINITE = 0, 1, 2


def _make_advance_kernel(parallel: bool):
    """The compiled loop: numba's parallel loops, or the same loops run serially (`parallel`
    False: the one-thread loop, module docstring); `parallel` is a closure constant, so the two
    are cached apart."""

    @nb.njit(cache=True, parallel=parallel)
    def advance_kernel(nsteps, t, dt, mass0, mass_error_max, mass, v, C, L, stress, gamma_dot,
                       phase, frac, volume, density, fext, wall_on, wall_cells, normal, rho_c,
                       delta, xi, wfn, wft, wst, kn, kt, zeta, mu_w, part_on, mu_p, length,
                       frame, x0, z0, dx, periodic, h, open_x, open_z, params,
                       tables, ux, uz, work, q, end_rho, act,
                       cm, cmv, cf, gm, gmv, gf, gv, no_slip_rows, transfers, cb, B, gtmp,
                       weight, inv_r, axis_cols, stress_work):
        """Up to nsteps steps of dt (s) from time t (s) of the state's arrays
        (solver.EulerianState, flat per cell; q (NQ, N), end_rho (N,) work arrays), in place;
        the mesh's faces, its weight tables (transfer.WeightTables as a tuple (cx, cz, fx, fz))
        and the remap's work arrays (advection.remap_work) as solver.EulerianSystem's; act (N,)
        int64 a work array for the cells holding material; cm (nchunk, nx, nz), cmv, cf
        (nchunk, nx, nz, 2) per-chunk scatter buffers; no_slip_rows: the grid's lowest node rows
        held still after every grid update (solver.EulerianSystem.no_slip_below, a rough floor;
        the Lagrangian loop's), 0 for none; transfers, cb, B, gtmp: the APIC transfers a step
        makes and their operator's buffers (solver.EulerianSystem.transfers, the Lagrangian
        loop's: vibroflow.continuum.fused); weight, inv_r (N,) and axis_cols: an axisymmetric
        section's cell radii, their reciprocals and the node columns on the axis whose radial
        velocity is held at 0 (solver.EulerianSystem.axisymmetric); 1, 0 and 0 in plane
        strain; stress_work (N, 4): the stress scattered when the material has a bed
        viscosity (stress_update.damped_stress, on every cell; unused without).

        Returns (steps done, t, status, lowest cell mass kg/m, largest |M - M0| / M0 so far):
        status OK, NEGATIVE_MASS (a cell lost more mass than it held) or NON_FINITE (a velocity),
        found at the end of the last step made."""
        _ = parallel
        n = mass.shape[0]
        tcx, tcz = tables[0], tables[1]
        ncx = open_z.shape[0]
        ncz = open_x.shape[1]
        nq = q.shape[0]
        nchunk = cm.shape[0]
        nx = gm.shape[0]
        mtol = -1e-9 * rho_c * h * h
        m2 = mass.reshape((ncx, ncz))
        q3 = q.reshape((nq, ncx, ncz))
        damped = params[P_ETA_BED] > 0.0
        scattered = stress_work if damped else stress
        for s in range(nsteps):
            # lagrangian_step.lagrangian_step: forces, the cells holding material to the nodes
            material_fraction(mass, density, h, weight, frac, volume)
            fext[:] = 0.0
            if wall_on:
                wall_forces(wall_cells, normal, v, mass, rho_c, h, weight, delta, xi, fext, wfn,
                            wft, wst, kn, kt, zeta, mu_w, dt)
            if part_on:
                partition_forces(v, mass, volume, stress, fext, mu_p, length, dt)
            na = 0
            for p in range(n):
                if mass[p] > 0.0:
                    act[na] = p
                    na += 1
            if damped:
                # the bed's Kelvin-Voigt damping on the rate of the last step, scattered with
                # the stress but not stored in it (the Lagrangian loop's)
                for c in nb.prange(nchunk):
                    a = (c * n) // nchunk
                    b = ((c + 1) * n) // nchunk
                    damped_stress(stress[a:b], L[a:b], phase[a:b], params, stress_work[a:b])
            for c in nb.prange(nchunk):
                a = (c * na) // nchunk
                b = ((c + 1) * na) // nchunk
                cm[c] = 0.0
                cmv[c] = 0.0
                cf[c] = 0.0
                p2g_cells(act[a:b], ncz, tcx, tcz, v, C, mass, volume, scattered, fext, dx,
                          periodic, inv_r, cm[c], cmv[c], cf[c])
                if transfers > 1:
                    cb[c] = 0.0
                    operator_of_cells(act[a:b], ncz, tcx, tcz, mass, dx, periodic, cb[c])
            for i in nb.prange(nx):
                sum_chunk_rows(i, i + 1, cm, cmv, cf, gm, gmv, gf)
                if transfers > 1:
                    sum_operator_rows(i, i + 1, cb, B)
            a0x, a0z, om, al, pvx, pvz = frame_body(frame, t + 0.5 * dt)
            grid_update(gm, gmv, gf, gv, x0, z0, dx, dt, a0x, a0z, om, al, pvx, pvz, periodic)
            if no_slip_rows > 0:
                gv[:, :no_slip_rows, :] = 0.0
            if axis_cols > 0:
                gv[:axis_cols, :, 0] = 0.0
            # the step's further transfers (vibroflow.continuum.transfer_operator)
            # (from gv to gtmp and back, one parallel loop a transfer, the last copied back;
            # the floor's rows held inside transfer_rows, as the Lagrangian loop's)
            for j in range(transfers - 1):
                if j % 2 == 0:
                    for i in nb.prange(nx):
                        transfer_rows(i, i + 1, B, gm, gv, gtmp, periodic, no_slip_rows,
                                      axis_cols)
                else:
                    for i in nb.prange(nx):
                        transfer_rows(i, i + 1, B, gm, gtmp, gv, periodic, no_slip_rows,
                                      axis_cols)
            if transfers % 2 == 0:
                for i in nb.prange(nx):
                    gv[i] = gtmp[i]
            for c in nb.prange(nchunk):
                a = (c * na) // nchunk
                b = ((c + 1) * na) // nchunk
                g2p_cells(act[a:b], ncz, tcx, tcz, v, C, L, gv, dx, periodic)
                # and the remap's face velocities, which need only the grid's velocities: in
                # the same parallel loop, one launch fewer
                face_velocity_rows((c * (ncx + 1)) // nchunk, ((c + 1) * (ncx + 1)) // nchunk,
                                   gv, tables, periodic, open_x, open_z, m2, ux, uz)
            match_divergence(L, ux, uz, h, periodic, v, normal, mass, open_x, open_z, inv_r)
            void_first(L, frac, density, rho_c, dt)
            end_density(density, L, dt, end_rho)
            for c in nb.prange(nchunk):
                update_stress_cells((c * n) // nchunk, ((c + 1) * n) // nchunk, stress, L,
                                    end_rho, dt, params, gamma_dot, phase)
            # solver.step: the remap of mass and of the fields it carries
            for p in range(n):
                q[0, p] = v[p, 0]
                q[1, p] = v[p, 1]
                for c in range(4):
                    q[2 + c, p] = C[p, c]
                    q[6 + c, p] = stress[p, c]
                q[10, p] = end_rho[p]
            if parallel:
                lowest = remap(m2, q3, ux, uz, h, dt, periodic, work)
            else:
                lowest = remap_serial(m2, q3, ux, uz, h, dt, periodic, work)
            finite = True
            for p in range(n):
                v[p, 0] = q[0, p]
                v[p, 1] = q[1, p]
                for c in range(4):
                    C[p, c] = q[2 + c, p]
                    stress[p, c] = q[6 + c, p]
                density[p] = q[10, p]
                if not (np.isfinite(v[p, 0]) and np.isfinite(v[p, 1])):
                    finite = False
            fill_limit(mass, density, h, weight)
            t += dt
            if lowest < mtol or not np.isfinite(lowest):
                return s + 1, t, NEGATIVE_MASS, lowest, mass_error_max
            if not finite:
                return s + 1, t, NON_FINITE, lowest, mass_error_max
            if mass0 > 0.0:
                err = abs(mass.sum() - mass0) / mass0
                if err > mass_error_max:
                    mass_error_max = err
        return nsteps, t, OK, 0.0, mass_error_max

    return advance_kernel


advance_kernel = _make_advance_kernel(True)
advance_kernel_serial = _make_advance_kernel(False)
