"""The APIC transfer pair as an operator on the grid's velocities, and the extra transfers a step
can make with it.

Why.  An APIC step (p2g.py, g2p.py; Jiang et al. 2015) replaces every point's velocity by the
grid's smooth field: whatever the points' velocities held below the grid's resolution (beyond
each point's affine part) is lost at every transfer.  That loss is a damping of the grid-scale
motion whose rate is the number of transfers per second.  With one transfer a step that rate
is 1/dt, and the tub's continuum fields depend on the time step through it (E(continuum, DEM)
0.82, 0.71, 0.55, 0.42 as the step halves from cfl 0.3; a FLIP blend, which keeps the
sub-grid motion, is step-converged and does not improve: docs/decisions/transfer-rate.md):
the step would be the model's dissipation parameter.  Here the two are parted: a step of any
size can make n transfers, so the damping is set by the transfers' rate n/dt, a model
parameter of its own (the tub drivers' `transfer_cfl`: the Courant number of the equivalent
one-transfer APIC step), and the step only by stability.

What a transfer is.  With the point velocities v_p = sum_j w_jp v_j and affine matrices
C_p = (4/dx^2) sum_j w_jp v_j (x_j - x_p)^T that g2p gives from grid velocities v_j, the next
p2g's grid momentum is m_i v_i' = sum_p m_p w_ip (v_p + C_p (x_i - x_p)), so

    v_i' = (1/m_i) sum_j B_ij v_j,   B_ij = sum_p m_p w_ip w_jp (1 + (4/dx^2) r_ip . r_jp),

with r_ip = x_i - x_p and m_i = sum_p m_p w_ip (Jiang et al. 2015's transfer pair with no force
and no motion in between).  Each velocity component is transferred alone.  B is symmetric, and
its rows sum to m_i (sum_j w_jp = 1 and sum_j w_jp r_jp = 0 for the quadratic B-spline), so a
transfer keeps a uniform velocity; it keeps every affine velocity field exactly (APIC's
property), and the grid's momentum sum_i m_i v_i exactly (sum_i w_ip r_ip = 0).  The points'
neighbourhoods span 5 x 5 nodes.  B is symmetric, so each node stores the half of its 5 x 5
couplings that points forward (`HALF` = 13 of them: offsets (0, 0..2), then (1..2, -2..2);
`half_slot`), as (nx, nz, HALF): the coupling of node (i, k) with node (i + da, k + db) is
B[i, k, half_slot(da, db)] when the offset points forward, else the neighbour's
B[i + da, k + db, half_slot(-da, -db)].  A point adds each unordered pair of its 3 x 3
stencil's nodes once (45 products, not 81), the per-chunk buffers and their sums are half as
large, and the matrix is symmetric bit for bit (`expand` gives the full 5 x 5 form, for
checks).

Built once a step from the points' positions before they move (the positions p2g used), it is
applied n - 1 times to the updated grid velocities before the gather: the step then makes n
transfers, the last one g2p's own.  Building costs about one p2g; an application, a few
microseconds on a tub grid, against a whole p2g and g2p for a transfer made with the points.
The operator is built per chunk of points into per-chunk buffers summed in a fixed order (as
p2g's scatter, fused.py), so the numbers do not depend on the number of threads.
"""
from __future__ import annotations

import numba as nb
import numpy as np

from .grid_update import idle_node
from .stencil import bspline_weights

#: couplings stored per node: the forward half of the 5 x 5 neighbourhood (module docstring)
HALF = 13


@nb.njit(cache=True, inline="always")
def half_slot(da, db):
    """The slot of the forward offset (da, db) (da = 0 and db = 0..2, or da = 1, 2 and
    db = -2..2) in a node's HALF stored couplings."""
    if da == 0:
        return db
    return 3 + (da - 1) * 5 + db + 2


@nb.njit(cache=True, inline="always")
def pair_factor(a, b, c, d, wx, wz, rx, rz, inv):
    """w_ip w_jp (1 + 4/dx^2 r_ip . r_jp) of the stencil's nodes (a, b) and (c, d) of a point,
    from its weights wx, wz and offsets rx, rz (m) (3-tuples along x and z) and inv = 4/dx^2:
    split by axis, (w_a w_c)(w_b w_d)((1 + inv r_a r_c) + inv r_b r_d) (the split that the
    fixed Eulerian cells' build makes in two passes: eulerian/operator_build.py)."""
    return ((wx[a] * wx[c]) * (wz[b] * wz[d])) * (
        (1.0 + inv * (rx[a] * rx[c])) + inv * (rz[b] * rz[d]))


@nb.njit(cache=True, inline="always")
def stencil_tuples(fx, wx0, wx1, wx2, fz, wz0, wz1, wz2, dx):
    """A point's weights and node offsets (m) along x and z as 3-tuples (`pair_factor`)."""
    return ((wx0, wx1, wx2), (wz0, wz1, wz2),
            ((0.0 - fx) * dx, (1.0 - fx) * dx, (2.0 - fx) * dx),
            ((0.0 - fz) * dx, (1.0 - fz) * dx, (2.0 - fz) * dx))


@nb.njit(cache=True)
def add_point(B, m, bx, fx, wx0, wx1, wx2, bz, fz, wz0, wz1, wz2, dx, periodic):
    """Add a point's part m w_ip w_jp (1 + 4/dx^2 r_ip . r_jp) to the operator B (nx, nz,
    HALF) (module docstring), each unordered pair of its stencil's nodes once, the factors
    (`pair_factor`) made in registers as they are added (made into a work array first, they
    cost the Lagrangian step 11 %: tub47, 207 against 186 us): mass m (kg/m), base nodes bx,
    bz, offsets fx, fz and three weights per axis as stencil.bspline_weights returns them,
    spacing dx (m)."""
    nxg = B.shape[0]
    inv = 4.0 / (dx * dx)
    wx, wz, rx, rz = stencil_tuples(fx, wx0, wx1, wx2, fz, wz0, wz1, wz2, dx)
    for a in range(3):
        i = bx + a
        if periodic:
            i = i % nxg
        for b in range(3):
            k = bz + b
            for c in range(a, 3):
                for d in range(b if c == a else 0, 3):
                    B[i, k, half_slot(c - a, d - b)] += m * pair_factor(a, b, c, d, wx, wz, rx,
                                                                        rz, inv)


@nb.njit(cache=True)
def operator_of_points(x, mass, x0, z0, dx, periodic, B):
    """Accumulate the transfer operator of the points x (N, 2) (m) of masses mass (N,) (kg/m)
    into B (nx, nz, HALF) (zero it first), on the grid of origin (x0, z0) and spacing dx (m)."""
    for p in range(x.shape[0]):
        bx, fx, wx0, wx1, wx2, _, _, _ = bspline_weights(x[p, 0], x0, dx)
        bz, fz, wz0, wz1, wz2, _, _, _ = bspline_weights(x[p, 1], z0, dx)
        add_point(B, mass[p], bx, fx, wx0, wx1, wx2, bz, fz, wz0, wz1, wz2, dx, periodic)


@nb.njit(cache=True)
def sum_operator_rows(i0, i1, cb, B):
    """Grid rows i0:i1 of B: the sums of the per-chunk operators cb (nchunk, nx, nz, HALF) in
    the fixed order chunk 0, 1, ... (module docstring)."""
    nchunk = cb.shape[0]
    m = B.shape[1] * B.shape[2]
    for i in range(i0, i1):
        # each entry's sum cb[0] + cb[1] + ... in that order, made chunk after chunk over the
        # row's flat entries: a long loop the compiler vectorises, with the same roundings
        out = B[i].reshape(m)
        first = cb[0, i].reshape(m)
        for e in range(m):
            out[e] = first[e]
        for c in range(1, nchunk):
            part = cb[c, i].reshape(m)
            for e in range(m):
                out[e] += part[e]


@nb.njit(cache=True)
def coupling(B, i, k, da, db, nx):
    """B's coupling of node (i, k) with node (i + da, k + db) (|da|, |db| <= 2; the neighbour
    wrapped along x when it lies off a periodic grid of nx node rows, `nx` > 0; 0: not
    wrapped): its own stored half when the offset points forward, else the neighbour's."""
    if da > 0 or (da == 0 and db >= 0):
        return B[i, k, half_slot(da, db)]
    j = i + da
    if nx > 0:
        j = j % nx
    return B[j, k + db, half_slot(-da, -db)]


def expand(B):
    """The full operator (nx, nz, 5, 5) of a stored half B (nx, nz, HALF), element [i, k, a, b]
    coupling node (i, k) with node (i + a - 2, k + b - 2) (0 where that node is off the grid;
    not wrapped): for checks."""
    nx, nz = B.shape[:2]
    out = np.zeros((nx, nz, 5, 5))
    for i in range(nx):
        for k in range(nz):
            for a in range(5):
                for b in range(5):
                    j, l = i + a - 2, k + b - 2
                    if 0 <= j < nx and 0 <= l < nz:
                        out[i, k, a, b] = coupling(B, i, k, a - 2, b - 2, 0)
    return out


@nb.njit(cache=True)
def transfer_rows(i0, i1, B, gm, gv, out, periodic, no_slip_rows, axis_cols):
    """One transfer of the grid velocities gv (nx, nz, 2) (m/s) for the node rows i0:i1, into
    out: v_i' = sum_j B_ij v_j / m_i at nodes holding mass (gm > MASS_EPS, kg/m) and off the
    grid's edge, 0 elsewhere (as grid_update leaves them); then the grid's conditions as after
    the update: the lowest no_slip_rows node rows held still (a rough floor), the radial
    velocity of the first axis_cols columns 0 (an axisymmetric section's axis).  B is the
    stored half (nx, nz, HALF): a backward coupling is read from the neighbour's half.

    The sums are in the written order (no fastmath).  Reassociated (fastmath reassoc, a third
    less time here), their compiled order depends on how this kernel is compiled into its
    callers: a process that loads it from numba's cache before compiling the Eulerian loops
    gives the serial and the parallel loop numbers 1e-12 apart (tests/test_transfer_operator.py
    run a second time, from the cache), where the loops must agree bit for bit whatever the
    threads (docs/decisions/reproducibility.md)."""
    nx, nz = gm.shape
    for i in range(i0, i1):
        for k in range(nz):
            if idle_node(gm, i, k, periodic, out):
                continue
            m = gm[i, k]
            sx = 0.0
            sz = 0.0
            if 2 <= i < nx - 2 and 2 <= k < nz - 2:
                # the whole 5 x 5 neighbourhood on the grid: no index checks (most nodes);
                # the forward half from this node's slots, the backward from the neighbours'
                for db in range(3):
                    bij = B[i, k, db]
                    sx += bij * gv[i, k + db, 0]
                    sz += bij * gv[i, k + db, 1]
                for da in range(1, 3):
                    for db in range(-2, 3):
                        bij = B[i, k, 3 + (da - 1) * 5 + db + 2]
                        sx += bij * gv[i + da, k + db, 0]
                        sz += bij * gv[i + da, k + db, 1]
                for db in range(1, 3):
                    bij = B[i, k - db, db]
                    sx += bij * gv[i, k - db, 0]
                    sz += bij * gv[i, k - db, 1]
                for da in range(1, 3):
                    for db in range(-2, 3):
                        bij = B[i - da, k - db, 3 + (da - 1) * 5 + db + 2]
                        sx += bij * gv[i - da, k - db, 0]
                        sz += bij * gv[i - da, k - db, 1]
            else:
                for a in range(5):
                    j = i + a - 2
                    if periodic:
                        j = j % nx
                    elif j < 0 or j >= nx:
                        continue
                    for b in range(5):
                        l = k + b - 2
                        if l < 0 or l >= nz:
                            continue
                        bij = coupling(B, i, k, a - 2, b - 2, nx if periodic else 0)
                        sx += bij * gv[j, l, 0]
                        sz += bij * gv[j, l, 1]
            out[i, k, 0] = sx / m
            out[i, k, 1] = sz / m
            if k < no_slip_rows:
                out[i, k, 0] = 0.0
                out[i, k, 1] = 0.0
            if i < axis_cols:
                out[i, k, 0] = 0.0
