"""The z impulse the Lagrangian step's nodal forces give each Eulerian cell, the stress's apart
from the external forces', as the grid's operators make it, compiled.

The Lagrangian step (lagrangian_step.py, fused.py) scatters each cell q's mass, APIC momentum
and force to the nodes i of its quadratic B-spline stencil (stencil.scatter_point):

    m_i = sum_q w_iq m_q,    f_i = -sum_q V_q sigma_q . grad w_iq + sum_q w_iq f_q^ext,

updates the nodes, v_i' = v_i* + dt (f_i / m_i + a_i) with v_i* = (m v)_i / m_i and a_i the
frame's body acceleration at the node (grid_update.grid_update, the frame at mid-step, its
Coriolis term on v_i*), and gathers, v_p = sum_i w_ip v_i' (g2p.py).  The gather is linear, so
a cell's momentum after the Lagrangian step is

    m_p v_p = m_p sum_i w_ip v_i*  +  S_p + E_p,
    S_p = dt m_p sum_i w_ip f_i^sigma / m_i,     (the stress's impulse on the cell)
    E_p = dt m_p sum_i w_ip (f_i^ext / m_i + a_i),  (the external forces' and the frame's)

f_i^sigma = -sum_q V_q sigma_q . grad w_iq the stress's nodal force (its divergence, the cell's
own and its neighbours' stresses over the stencil) and f_i^ext the wall's and the partitions'
forces spread over the same nodes.  The first term is the transfer's own exchange: the APIC
round trip m_p (sum_i w_ip v_i* - v_p^0) moves momentum between neighbouring cells without any
force (it is zero for a rigid motion, whose affine field the round trip reproduces), the
grid's share of a completely inelastic contact.  Further transfers (grid_step.py) and the
remap (advection.py) move momentum without force too.  A node that gets no velocity (no mass,
the grid's edge) or is held (the no-slip rows) passes no force: its terms are left out.

`cell_impulse_z` computes S_p and E_p (N s/m, z components) from the same arrays the step used:
the step's start masses, volumes and scattered stress (the elastic-plastic plus the
temperature's kinetic stress), the step's external forces, the node masses and momenta the
step's scatter left in the grid's work arrays, the B-spline weight tables, and the frame at
mid-step.  The sums over nodes are the scatter's and the gather's in another order: S_p and
E_p are the step's to round-off.  A bed viscosity's Kelvin-Voigt stress (constitutive.
ContinuumMaterial.bed_viscosity, 0 by default), scattered but not stored, is not in the
stress given here: its impulse counts with the exchange.
"""
from __future__ import annotations

import numba as nb
import numpy as np

from ..grid_update import MASS_EPS, frame_body
from ..stencil import axis_node
from .transfer import table_row


@nb.njit(cache=True)
def cell_impulse_z(m0, volume0, sigma0, fext, tables, ncz, gm, gmv, x0, z0, dx, periodic,
                   no_slip_rows, frame, t_mid, dt, S, E):
    """The stress's impulse S (N,) and the external forces' and the frame's E (N,) (N s/m, z)
    on each cell over the step of dt (s) (module docstring): m0 (N,) kg/m, volume0 (N,) m^2,
    sigma0 (N, >= 3) Pa [xx, zz, xz, ...] the stress the step scattered and fext (N, 2) N/m
    its external forces, at the step's start; tables (cx, cz, fx, fz) the mesh's weight tables
    (transfer.WeightTables), ncz the cells per column (p = i ncz + k); gm (nx, nz) kg/m and gmv
    (nx, nz, 2) kg/s the step's node masses and momenta, the grid from (x0, z0) (m) of spacing
    dx (m), periodic along x, its lowest no_slip_rows rows held; frame the packed frame
    (grid_update.FRAME_FIELDS) at t_mid (s), the step's middle.  Plane strain."""
    tcx = tables[0]
    tcz = tables[1]
    nx, nz = gm.shape
    fs = np.zeros((nx, nz))
    fe = np.zeros((nx, nz))
    n = m0.shape[0]
    for p in range(n):
        if not m0[p] > 0.0:
            continue
        ic = p // ncz
        wx = table_row(tcx, ic)
        wz = table_row(tcz, p - ic * ncz)
        vol = volume0[p]
        sxz = sigma0[p, 2]
        szz = sigma0[p, 1]
        fz = fext[p, 1]
        for a in range(3):
            i, _, wa, ga = axis_node(wx, a, dx, periodic, nx)
            for b in range(3):
                k, _, wb, gb = axis_node(wz, b, dx, False, 0)
                fs[i, k] += -vol * (sxz * ga * wb + szz * wa * gb)
                fe[i, k] += wa * wb * fz
    a0x, a0z, w, alpha, pvx, pvz = frame_body(frame, t_mid)
    # the per-unit-mass nodal accelerations: the stress's and the rest's (grid_update's)
    for i in range(nx):
        for k in range(nz):
            m = gm[i, k]
            edge = k < 1 or k >= nz - 1 or (not periodic and (i < 1 or i >= nx - 1))
            if m <= MASS_EPS or edge or k < no_slip_rows:
                fs[i, k] = 0.0
                fe[i, k] = 0.0
                continue
            qx = x0 + i * dx - pvx
            qz = z0 + k * dx - pvz
            fs[i, k] = fs[i, k] / m
            fe[i, k] = (fe[i, k] / m + a0z - alpha * qx + w * w * qz
                        - 2.0 * w * gmv[i, k, 0] / m)
    for p in range(n):
        S[p] = 0.0
        E[p] = 0.0
        if not m0[p] > 0.0:
            continue
        ic = p // ncz
        wx = table_row(tcx, ic)
        wz = table_row(tcz, p - ic * ncz)
        s = 0.0
        e = 0.0
        for a in range(3):
            i, _, wa, _ = axis_node(wx, a, dx, periodic, nx)
            for b in range(3):
                k, _, wb, _ = axis_node(wz, b, dx, False, 0)
                s += wa * wb * fs[i, k]
                e += wa * wb * fe[i, k]
        S[p] = dt * m0[p] * s
        E[p] = dt * m0[p] * e
