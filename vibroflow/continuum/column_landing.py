"""The landing counted along each column of Eulerian cells: the impulse through each face times
the face's mean relative velocity, compiled.

A loose layer landing on a floor is stopped by a compaction front running up from the floor
(compaction_landing.py).  On the grid the front is smeared over several cells: the transfers
spread the velocity jump, and a pair of neighbouring cells sees only its share of the jump.
Its own loss mu (w_0^2 - w_1^2) / 2 (mu the pair's reduced mass) is the square of a share, and
the pairs together count a fraction of what the mean motion loses (0.18 on a loose block,
docs/validation.md section 22).  The impulse through a face is not its pair's own: it is what
stops all the material beyond it.

Along a column of cells k = 0, 1, ... (z up: gravity and the floor's normal), the z momentum
of cell k changes over a step of dt by

    m_k^1 v_k^1 - m_k^0 v_k^0 = J_{k-1/2} - J_{k+1/2} + E_k,

J_{k+1/2} the impulse through the face between k and k + 1 on the material above it (the
grid's and the remap's momentum exchange and the stress: the continuum's contact impulse), E_k
the external impulse on cell k as the grid delivers it: the frame's body force (gravity less
the tub's acceleration, with the rotating frame's terms, grid_update.grid_update) and the
wall's and the partitions' forces (the step's f_ext), each a nodal force gathered
(eulerian/face_impulse.py).  The stress on the cell's side faces is the stress's, counted in
S below.  Summed from the top of the column down, the impulse through a face is the momentum
change of all the material above it less the external impulse on that material:

    J_{k+1/2} = sum_{j > k} (m_j^1 v_j^1 - m_j^0 v_j^0 - E_j),

the column's top (or a closed face above) carrying none.  Multiplying each cell's balance by
its mean velocity vbar_k = (v_k^0 + v_k^1) / 2 and summing by parts,

    sum_k (m_k^1 v_k^1 - m_k^0 v_k^0 - E_k) vbar_k = -sum_faces J_f wbar_f,

wbar_f = vbar_{k+1} - vbar_k the face's mean relative velocity.  Since (m^1 v^1 - m^0 v^0) vbar
= (m^1 (v^1)^2 - m^0 (v^0)^2) / 2 + (m^1 - m^0) v^0 v^1 / 2, the left side is the kinetic
energy's change less the external forces' work plus the remap's term sum_k Delta m_k q_k / 2,
q = v^0 v^1; with Delta m_k = F_{k-1/2} - F_{k+1/2}, F_f = sum_{j > k} Delta m_j the mass
carried up through face f, that term is sum_f F_f (q_{k+1} - q_k) / 2 by parts.  So

    -J_f wbar_f + F_f (q_{k+1} - q_k) / 2

is the kinetic energy of the mean motion that the momentum exchange through face f destroys,
and the faces' terms sum to the column's whole loss above its lowest cell (as Eulerian
hydrocodes return the remap's kinetic-energy loss to the internal energy).  For one pair
alone, masses unmoved, J = mu (w_1 - w_0) and -J (w_0 + w_1) / 2 = mu (w_0^2 - w_1^2) / 2:
the pair's own loss (compaction_landing.py) is the special case.

Of that the stress carries its own part: its work is elastic (stored) or the kinetic
pressure's and the plastic flow's (already the temperature's production: counted again, it
makes energy, compaction_landing.py).  The Lagrangian step's momentum change of a cell splits
exactly, the gather being linear (eulerian/face_impulse.py), into the stress's impulse S_k
(its nodal forces, the divergence of the cells' stresses over the B-spline stencil, gathered),
the external forces' and the frame's E_k (the wall's, the partitions' and the body forces'
nodal shares, gathered), and the transfer's exchange (the APIC round trip, which moves momentum
between neighbours without a force); the remap then moves momentum with the mass.  So the
impulse through a face, with E_k the external impulse as the grid delivers it, is

    J_{k+1/2} = S_{k+1/2} + X_{k+1/2},   S_{k+1/2} = sum_{j > k} S_j,

the stress's impulse through the face (for a block at rest, the weight above it less what
the floor's nodal force gives the cells above directly) and X the rest: the transfers' and
the remap's exchange, the grid's completely inelastic contact.  Summed by parts, -S_f wbar_f
is the stress's work on the mean motion; the face's landing is the rest's,

    E_f = -X_f wbar_f + F_f (q_{k+1} - q_k) / 2,
          clipped to [0, sum_{j > k} m_j^0 (v_j^0 - v_k^0)^2 / 2],

never more than the normal kinetic energy the material above the face had relative to the cell
below it (what stopping all of it on that cell destroys).  It counts where the pairwise form
counts: a face whose two cells approach at the step's start (w_0 < 0) and one of them holds a
void or disconnected material (compaction_landing.py); two full, connected cells compress
elastically, a block resting, sliding or falling as a body has w_0 = 0 across every face and
feeds nothing, and the term is Galilean: a uniform velocity u adds u F_f to J_f and
u F_f wbar_f to the remap's term, which cancel.  Each cell of the face gets its centre-of-mass
share, m_b / (m_a + m_b) of E_f for the lower cell a and m_a / (m_a + m_b) for the upper b.

It is determined along a column, the 1D landing: the exchange between columns through the side
faces other than their shear stress (the transfers' share, the remap's side fluxes) is counted
in the column's faces.  The exchange across the side faces is the pairs' (compaction_landing.
x_face_terms).  Per cell the kernel adds the power E / dt (W/m) to the landing column out[:, 3]
of the cells' wall contact sums, as compaction_landing.py does.
"""
from __future__ import annotations

import numba as nb
import numpy as np

from .compaction_landing import FULL


@nb.njit(cache=True)
def face_impulses(m0, v0, m1, v1, S, E, open_z):
    """The z faces' impulses over a step (N s/m, (ncx, ncz + 1), face k between cells k - 1
    and k of a column; module docstring): J the whole impulse on the material above the face,
    S_f the stress's (the sum above it of the cells' stress impulses S (N,), eulerian/
    face_impulse.py), and the mass F (kg/m) carried up through it; m0, v0 and m1, v1 the cells'
    masses (N,) kg/m and velocities (N, 2) m/s at the step's start and end, E (N,) the
    external impulse the grid gave each cell (N s/m), open_z (ncx, ncz + 1) the open z faces.
    A closed face holds what is above it: the column starts again below it (the faces' values
    there 0)."""
    ncx = open_z.shape[0]
    ncz = open_z.shape[1] - 1
    J = np.zeros((ncx, ncz + 1))
    Sf = np.zeros((ncx, ncz + 1))
    F = np.zeros((ncx, ncz + 1))
    for i in range(ncx):
        j = 0.0
        s = 0.0
        dm = 0.0
        for k in range(ncz - 1, 0, -1):
            b = i * ncz + k
            if m0[b] > 0.0 or m1[b] > 0.0:
                j += m1[b] * v1[b, 1] - m0[b] * v0[b, 1] - E[b]
                s += S[b]
                dm += m1[b] - m0[b]
            if not open_z[i, k]:
                j = 0.0
                s = 0.0
                dm = 0.0
                continue
            J[i, k] = j
            Sf[i, k] = s
            F[i, k] = dm
    return J, Sf, F


@nb.njit(cache=True)
def column_terms(m0, v0, rho0, m1, v1, S, E, h, open_z, rho_c, dt, out):
    """Adds the cells' column landing power (W/m) of a step of dt (s) to out[:, 3] (module
    docstring), over every open z face of an Eulerian mesh (eulerian/mesh.py: open_z
    (ncx, ncz + 1), cell p = i ncz + k; plane strain).  m0 (N,) kg/m, v0 (N, 2) m/s and rho0
    (N,) kg/m^3 at the step's start, m1 (N,) kg/m and v1 (N, 2) m/s at its end; S, E (N,) the
    stress's and the external z impulses (N s/m) the step's grid gave each cell
    (eulerian/face_impulse.cell_impulse_z); h (m) the cells' side, rho_c (kg/m^3) the critical
    density."""
    ncx = open_z.shape[0]
    ncz = open_z.shape[1] - 1
    full0 = FULL * h * h
    J, Sf, F = face_impulses(m0, v0, m1, v1, S, E, open_z)
    for i in range(ncx):
        # from the top down: the start's sums m, m v, m v^2 of the material above each face
        s0 = 0.0
        s1 = 0.0
        s2 = 0.0
        for k in range(ncz - 1, 0, -1):
            b = i * ncz + k
            if m0[b] > 0.0:
                s0 += m0[b]
                s1 += m0[b] * v0[b, 1]
                s2 += m0[b] * v0[b, 1] * v0[b, 1]
            if not open_z[i, k]:
                s0 = 0.0
                s1 = 0.0
                s2 = 0.0
                continue
            a = b - 1
            ma = m0[a]
            mb = m0[b]
            if not (ma > 0.0 and mb > 0.0):
                continue
            w0 = v0[b, 1] - v0[a, 1]
            if not w0 < 0.0:
                continue
            if ma >= full0 * rho0[a] and mb >= full0 * rho0[b] and rho0[a] >= rho_c \
                    and rho0[b] >= rho_c:
                continue
            wbar = 0.5 * (w0 + v1[b, 1] - v1[a, 1])
            va = v0[a, 1]
            cap = 0.5 * (s2 - 2.0 * va * s1 + va * va * s0)
            # the mass carried up through the face: its part of the remap's loss
            moved = 0.5 * F[i, k] * (v0[b, 1] * v1[b, 1] - v0[a, 1] * v1[a, 1])
            # the exchange no stress carries, on the face's mean relative velocity
            lost = min(max(-(J[i, k] - Sf[i, k]) * wbar + moved, 0.0), cap) / dt
            m = ma + mb
            out[a, 3] += lost * mb / m
            out[b, 3] += lost * ma / m
