"""Many MPM steps in one numba call, parallel over a fixed number of point chunks.

The step is mpm.py's (boundaries, p2g, grid update, g2p, volume and stress), made of the same
kernels (boundary.py, p2g.py, grid_update.py, g2p.py, plasticity.py, constitutive.py), but run
as one compiled loop over `nsteps` steps, without a Python step's dispatch per kernel, the
boundaries' Python methods and the frame's pose (~15 % of a tub47-quick step, whose time is
otherwise the scatter and the gather, ~40 % each).

Threads.  The N points are cut into `nchunk` fixed contiguous chunks (`chunk_bounds`); numba's
threads take whole chunks (prange).  Every per-point kernel (walls, partitions, g2p, volume,
stress) writes only its own points, so it gives the same numbers however the chunks are shared
out.  The particle-to-grid scatter writes per-chunk grid buffers, which are then summed node by
node in the fixed order chunk 0, 1, ..., so the grid sums, and with them the whole run, depend on
the number of chunks and never on the number of threads (as the DEM's run.force_chunks:
vibroflow.dem.step).  With one chunk the scatter is the serial p2g's, bit for bit.

Boundaries are packed as numbers (mpm.pack_boundaries): `bseq` (nb, 2) the boundaries in the
system's order as (kind, index) with kind 0 a penalty wall (row `index` of `wpar`, its history
row `index` of wxi, wf, wfn, wft, wst) and kind 1 the partitions' friction (row `index` of
`ppar`: friction, spacing L_y m); a wall row of `wpar` is boundary.py's WALL_FIELDS layout
(each boundary's `packed()`).

The frame (grid_update.frame_body) is a packed array too: FRAME_FIELDS.

numba's cache watches only the file of the function it compiled, and a compiled loop holds its
own copy of every kernel it calls: edited boundary or constitutive kernels would go on running
in a cached loop compiled before.  The package drops its whole kernel cache when any of its
sources changes (vibroflow/_kernel_cache.py), which covers this loop with every other.
"""
from __future__ import annotations

import numba as nb
import numpy as np

from .boundary import (B_PARTITION, B_WALL, W_AX, W_AZ, W_KIND, W_KN, W_KT, W_MU, W_NX, W_NZ,
                       W_PX, W_PZ, W_RADIUS, W_VX, W_VZ, W_ZETA, WALL_U, partition_forces,
                       plane_forces, plane_motion, u_wall_forces)
from .constitutive import P_ETA_BED
from .g2p import g2p
from .grid_update import frame_body, grid_update
from .p2g import p2g
from .plasticity import plasticity_step
from .stress_update import damped_stress
from .transfer_operator import operator_of_points, sum_operator_rows, transfer_rows

#: status of `advance_kernel`
OK, THROUGH_WALL, ESCAPED = 0, 1, 2


def chunk_bounds(n: int, nchunk: int) -> np.ndarray:
    """Bounds (nchunk + 1,) of nchunk contiguous chunks of n points, sizes differing by <= 1."""
    return (np.arange(nchunk + 1, dtype=np.int64) * n) // nchunk


@nb.njit(cache=True)
def _escaped_range(a, b, x, v, xmin, xmax, zmin, zmax):
    """Points of a:b outside the box or with a non-finite velocity."""
    bad = 0
    for p in range(a, b):
        if not (xmin <= x[p, 0] <= xmax and zmin <= x[p, 1] <= zmax):
            bad += 1
        elif not (np.isfinite(v[p, 0]) and np.isfinite(v[p, 1])):
            bad += 1
    return bad


@nb.njit(cache=True)
def sum_chunk_rows(i0, i1, cm, cmv, cf, gm, gmv, gf):
    """Grid rows i0:i1 of mass gm, momentum gmv and force gf: the sums of the per-chunk
    buffers cm, cmv, cf in the fixed order chunk 0, 1, ... (module docstring)."""
    nchunk = cm.shape[0]
    nz = gm.shape[1]
    for i in range(i0, i1):
        for k in range(nz):
            sm = cm[0, i, k]
            s0 = cmv[0, i, k, 0]
            s1 = cmv[0, i, k, 1]
            f0 = cf[0, i, k, 0]
            f1 = cf[0, i, k, 1]
            for c in range(1, nchunk):
                sm += cm[c, i, k]
                s0 += cmv[c, i, k, 0]
                s1 += cmv[c, i, k, 1]
                f0 += cf[c, i, k, 0]
                f1 += cf[c, i, k, 1]
            gm[i, k] = sm
            gmv[i, k, 0] = s0
            gmv[i, k, 1] = s1
            gf[i, k, 0] = f0
            gf[i, k, 1] = f1


@nb.njit(cache=True, parallel=True)
def advance_kernel(nsteps, t, dt, x, v, C, L, mass, volume, density, stress, gamma_dot, phase,
                   fext, bseq, wpar, wxi, wf, wfn, wft, wst, ppar, frame, x0, z0, dx,
                   periodic, params, box, bounds, cm, cmv, cf, gm, gmv, gf, gv,
                   no_slip_rows, flip, axis_cols, transfers, cb, B, gtmp, stress_work):
    """Up to nsteps MPM steps of dt (s) from time t (s), in place (module docstring; the
    state's arrays as mpm.MPMState, the grid's as mpm.MPMSystem.work).  box (4,) the region
    (m) a point may occupy (mpm.step); bounds (nchunk + 1,) chunk_bounds; cm (nchunk, nx, nz),
    cmv, cf (nchunk, nx, nz, 2) per-chunk scatter buffers; no_slip_rows: the grid's lowest
    node rows held still after every grid update (mpm.MPMSystem.no_slip_below, a rough
    floor), 0 for none; axis_cols: an axisymmetric section's node columns on or left of
    the axis r = 0, whose radial velocity is held at 0 after every grid update (mpm.
    MPMSystem.axisymmetric), 0 for a plane-strain section; transfers: the APIC transfers
    a step makes (mpm.MPMSystem.transfers; transfer_operator.py), with cb (nchunk, nx, nz,
    5, 5) the per-chunk operators, B (nx, nz, 5, 5) their sum and gtmp (nx, nz, 2) a work
    grid (unused for one transfer); stress_work (N, 4): the stress scattered when the
    material has a bed viscosity (stress_update.damped_stress; unused without).

    Returns (steps done, t after them, status, boundary): status OK; THROUGH_WALL when points
    went through the boundary `boundary` (the step was not made: t is its start; the
    boundaries' forces and histories were computed); ESCAPED when after the last step made a
    point is off the box or non-finite."""
    nchunk = bounds.shape[0] - 1
    nb_ = bseq.shape[0]
    nx = gm.shape[0]
    deep = np.zeros((nchunk, max(nb_, 1)), np.int64)
    bad = np.zeros(nchunk, np.int64)
    damped = params[P_ETA_BED] > 0.0
    scattered = stress_work if damped else stress
    for s in range(nsteps):
        # 1-2: the boundaries' forces in their order (fext zeroed first; deep: the points
        # through each wall, boundary.py `lost`) and the scatter, per chunk
        for c in nb.prange(nchunk):
            a = bounds[c]
            b = bounds[c + 1]
            fext[a:b] = 0.0
            for j in range(nb_):
                q = bseq[j, 1]
                if bseq[j, 0] == B_PARTITION:
                    partition_forces(v[a:b], mass[a:b], volume[a:b], stress[a:b],
                                     fext[a:b], ppar[q, 0], ppar[q, 1], dt)
                    continue
                w = wpar[q]
                if w[W_KIND] == WALL_U:
                    deep[c, j] = u_wall_forces(
                        x[a:b], v[a:b], mass[a:b], volume[a:b], wxi[q, a:b], fext[a:b],
                        wf[q, a:b], wfn[q, a:b], wft[q, a:b], wst[q, a:b], w[W_RADIUS],
                        w[W_KN], w[W_KT], w[W_ZETA], w[W_MU], dt)
                else:
                    px, pz, wvx, wvz = plane_motion(w[W_PX], w[W_PZ], w[W_VX], w[W_VZ],
                                                    w[W_AX], w[W_AZ], t)
                    deep[c, j] = plane_forces(
                        x[a:b], v[a:b], mass[a:b], volume[a:b], wxi[q, a:b], fext[a:b],
                        wf[q, a:b], wfn[q, a:b], wft[q, a:b], wst[q, a:b], px, pz, w[W_NX],
                        w[W_NZ], wvx, wvz, w[W_KN], w[W_KT], w[W_ZETA], w[W_MU], dt)
            cm[c] = 0.0
            cmv[c] = 0.0
            cf[c] = 0.0
            if damped:
                # the bed's Kelvin-Voigt damping on the rate of the last step, scattered with
                # the stress but not stored in it
                damped_stress(stress[a:b], L[a:b], phase[a:b], params, stress_work[a:b])
            p2g(x[a:b], v[a:b], C[a:b], mass[a:b], volume[a:b], scattered[a:b], fext[a:b], x0,
                z0, dx, periodic, cm[c], cmv[c], cf[c], axis_cols > 0)
            if transfers > 1:
                cb[c] = 0.0
                operator_of_points(x[a:b], mass[a:b], x0, z0, dx, periodic, cb[c])
        for j in range(nb_):
            if bseq[j, 0] == B_WALL:
                n_deep = 0
                for c in range(nchunk):
                    n_deep += deep[c, j]
                if n_deep > 0:
                    return s, t, THROUGH_WALL, j
        for i in nb.prange(nx):
            sum_chunk_rows(i, i + 1, cm, cmv, cf, gm, gmv, gf)
            if transfers > 1:
                sum_operator_rows(i, i + 1, cb, B)
        # 3: the frame's acceleration at mid-step
        a0x, a0z, om, al, pvx, pvz = frame_body(frame, t + 0.5 * dt)
        grid_update(gm, gmv, gf, gv, x0, z0, dx, dt, a0x, a0z, om, al, pvx, pvz, periodic)
        if no_slip_rows > 0:
            gv[:, :no_slip_rows, :] = 0.0
        if axis_cols > 0:
            gv[:axis_cols, :, 0] = 0.0
        # 3b: the step's further transfers (transfer_operator.py), each followed by the
        # grid's conditions as the update was
        # (from gv to gtmp and back, one parallel loop a transfer, the last copied back;
        # the conditions inside transfer_rows: numba's parallel build dropped slice
        # assignments to the alternating buffer)
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
        # 4-5: gather, move, volume and stress, per chunk
        for c in nb.prange(nchunk):
            a = bounds[c]
            b = bounds[c + 1]
            g2p(x[a:b], v[a:b], C[a:b], L[a:b], gv, x0, z0, dx, dt, periodic, gm, gmv,
                flip)
            plasticity_step(L[a:b], mass[a:b], volume[a:b], density[a:b], stress[a:b], dt,
                            params, gamma_dot[a:b], phase[a:b])
            bad[c] = _escaped_range(a, b, x, v, box[0], box[1], box[2], box[3])
        t += dt
        n_bad = 0
        for c in range(nchunk):
            n_bad += bad[c]
        if n_bad > 0:
            return s + 1, t, ESCAPED, -1
    return nsteps, t, OK, -1

