"""Many Eulerian steps in one numba call, parallel over fixed chunks of cells.

The step is solver.py's (lagrangian_step.py's Lagrangian step, then advection.py's remap) with
the same kernels, but run as one compiled loop over `nsteps` steps: a Python step spent about a
third of its time in its own bookkeeping (gathering the cells that hold material with fancy
indexing, packing the remap's fields, dispatching a dozen kernels, the frame's pose).

Threads, as the Lagrangian step's (vibroflow.continuum.fused): the per-cell kernels write only
their own cells and the remap works on whole rows and columns (advection.advect), so they give
the serial numbers whatever the threads; the cells holding material are scattered to the nodes
in `nchunk` fixed chunks of per-chunk buffers summed in a fixed order, so the run depends on the
number of chunks, never on the number of threads (one chunk: the serial p2g's numbers).

The loop's numba cache is keyed on the source of every kernel it calls, as the Lagrangian's
(vibroflow.continuum.fused, `sources_key`).
"""
from __future__ import annotations

import numba as nb
import numpy as np

from ..boundary import partition_forces
from ..constitutive import update_stress_points
from ..fused import KERNEL_MODULES, sources_key, sum_chunk_rows
from ..g2p import g2p
from ..grid_update import frame_body, grid_update
from ..p2g import p2g
from .advection import advect, face_velocities, match_divergence
from .lagrangian_step import end_density, fill_limit, material_fraction, void_first
from .wall import wall_forces

#: status of `advance_kernel`
OK, NEGATIVE_MASS, NON_FINITE = 0, 1, 2


@nb.njit(cache=True)
def _gather(act, x, v, C, mass, volume, stress, fext, cx, cv, cC, cmass, cvol, cstress,
            cfext):
    """The cells `act` (indices) of the per-cell arrays into the first act.size rows of the
    compact ones."""
    for j in range(act.shape[0]):
        p = act[j]
        cx[j, 0] = x[p, 0]
        cx[j, 1] = x[p, 1]
        cv[j, 0] = v[p, 0]
        cv[j, 1] = v[p, 1]
        for c in range(4):
            cC[j, c] = C[p, c]
            cstress[j, c] = stress[p, c]
        cmass[j] = mass[p]
        cvol[j] = volume[p]
        cfext[j, 0] = fext[p, 0]
        cfext[j, 1] = fext[p, 1]


def _make_advance_kernel(sources: int):
    """The compiled loop, its cache keyed on `sources` (module docstring)."""

    @nb.njit(cache=True, parallel=True)
    def advance_kernel(nsteps, t, dt, mass0, mass_error_max, x, mass, v, C, L, stress, gamma_dot,
                       phase, frac, volume, density, fext, wall_on, wall_cells, normal, rho_c,
                       delta, xi, wfn, wft, wst, kn, kt, zeta, mu_w, part_on, mu_p, length,
                       frame, x0, z0, dx, periodic, xmin, zmin, h, open_x, open_z, params,
                       ux, uz, adv_rho, srx, srz, sqx, sqz, dm, dq, q, end_rho, act, cx, cv,
                       cC, cL, cmass, cvol, cstress, cfext, cm, cmv, cf, gm, gmv, gf, gv,
                       no_slip_rows):
        """Up to nsteps steps of dt (s) from time t (s) of the state's arrays (solver.EulerianState,
        flat per cell; q (N, NQ), end_rho (N,) work arrays), in place; the mesh's faces and the
        remap's work arrays as solver.EulerianSystem's; act (N,) int64 and the compact c* arrays
        (N, ...) work arrays for the cells holding material; cm (nchunk, nx, nz), cmv, cf
        (nchunk, nx, nz, 2) per-chunk scatter buffers; no_slip_rows: the grid's lowest node rows
        held still after every grid update (solver.EulerianSystem.no_slip_below, a rough floor;
        the Lagrangian loop's), 0 for none.

        Returns (steps done, t, status, lowest cell mass kg/m, largest |M - M0| / M0 so far):
        status OK, NEGATIVE_MASS (a cell lost more mass than it held) or NON_FINITE (a velocity),
        found at the end of the last step made."""
        _ = sources
        n = mass.shape[0]
        ncx = open_z.shape[0]
        ncz = open_x.shape[1]
        nq = q.shape[1]
        nchunk = cm.shape[0]
        nx = gm.shape[0]
        mtol = -1e-9 * rho_c * h * h
        m2 = mass.reshape((ncx, ncz))
        q3 = q.reshape((ncx, ncz, nq))
        nblk = (n + 1023) // 1024
        for s in range(nsteps):
            # lagrangian_step.lagrangian_step: forces, the cells holding material to the nodes
            material_fraction(mass, density, h, frac, volume)
            fext[:] = 0.0
            if wall_on:
                wall_forces(wall_cells, normal, v, mass, rho_c, h, delta, xi, fext, wfn, wft, wst,
                            kn, kt, zeta, mu_w, dt)
            if part_on:
                partition_forces(v, mass, volume, stress, fext, mu_p, length, dt)
            na = 0
            for p in range(n):
                if mass[p] > 0.0:
                    act[na] = p
                    na += 1
            _gather(act[:na], x, v, C, mass, volume, stress, fext, cx, cv, cC, cmass, cvol,
                    cstress, cfext)
            for c in nb.prange(nchunk):
                a = (c * na) // nchunk
                b = ((c + 1) * na) // nchunk
                cm[c] = 0.0
                cmv[c] = 0.0
                cf[c] = 0.0
                p2g(cx[a:b], cv[a:b], cC[a:b], cmass[a:b], cvol[a:b], cstress[a:b], cfext[a:b],
                    x0, z0, dx, periodic, cm[c], cmv[c], cf[c])
            for i in nb.prange(nx):
                sum_chunk_rows(i, i + 1, cm, cmv, cf, gm, gmv, gf)
            a0x, a0z, om, al, pvx, pvz = frame_body(frame, t + 0.5 * dt)
            grid_update(gm, gmv, gf, gv, x0, z0, dx, dt, a0x, a0z, om, al, pvx, pvz, periodic)
            if no_slip_rows > 0:
                gv[:, :no_slip_rows, :] = 0.0
            for c in nb.prange(nchunk):
                a = (c * na) // nchunk
                b = ((c + 1) * na) // nchunk
                # cx: a copy, the cells stay put
                g2p(cx[a:b], cv[a:b], cC[a:b], cL[a:b], gv, x0, z0, dx, dt, periodic, gm, gmv,
                    0.0)
            for j in range(na):
                p = act[j]
                v[p, 0] = cv[j, 0]
                v[p, 1] = cv[j, 1]
                for c in range(4):
                    C[p, c] = cC[j, c]
                    L[p, c] = cL[j, c]
            face_velocities(gv, x0, z0, dx, periodic, xmin, zmin, h, open_x, open_z, m2, ux, uz)
            match_divergence(L, ux, uz, h, periodic)
            void_first(L, frac, dt)
            end_density(density, L, dt, end_rho)
            for blk in nb.prange(nblk):
                a = blk * 1024
                b = min(n, a + 1024)
                update_stress_points(stress[a:b], L[a:b], end_rho[a:b], dt, params,
                                     gamma_dot[a:b], phase[a:b])
            # solver.step: the remap of mass and of the fields it carries
            for p in range(n):
                q[p, 0] = v[p, 0]
                q[p, 1] = v[p, 1]
                for c in range(4):
                    q[p, 2 + c] = C[p, c]
                    q[p, 6 + c] = stress[p, c]
                q[p, 10] = end_rho[p]
            lowest = advect(m2, q3, ux, uz, h, dt, open_x, open_z, periodic, adv_rho, srx, srz,
                            sqx, sqz, dm, dq)
            finite = True
            for p in range(n):
                v[p, 0] = q[p, 0]
                v[p, 1] = q[p, 1]
                for c in range(4):
                    C[p, c] = q[p, 2 + c]
                    stress[p, c] = q[p, 6 + c]
                density[p] = q[p, 10]
                if not (np.isfinite(v[p, 0]) and np.isfinite(v[p, 1])):
                    finite = False
            fill_limit(mass, density, h)
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


advance_kernel = _make_advance_kernel(sources_key(
    *KERNEL_MODULES, "vibroflow.continuum.fused", "vibroflow.continuum.eulerian.advection",
    "vibroflow.continuum.eulerian.lagrangian_step", "vibroflow.continuum.eulerian.wall"))
