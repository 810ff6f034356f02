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
grid's and the remap's momentum exchange: the continuum's contact impulse), E_k the external
impulse on cell k: the frame's body force m_k^0 a_z dt (gravity less the tub's acceleration,
with the rotating frame's terms, grid_update.grid_update), the wall's and the partitions'
forces (the step's f_ext) and the shear stress on the cell's side faces, h (sigma_xz,right -
sigma_xz,left) dt (Pa, the step's start, each face the mean of its two cells; a closed side
face's force is the wall's).  Summed from the top of the column down, the impulse through a face
is the momentum change of all the material above it less the external impulse on that material:

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

Of that the face's compressive normal stress p_f takes p_f h (-wbar_f) dt: stored
elastically, or the kinetic pressure's work, already the temperature's production (counted
again, it makes energy: compaction_landing.py).  The grid's transfers spread a cell's stress
over its neighbours' nodes, and an impact raises it within the step, so the stress a face
carries is no one cell's at one time: p_f is the largest of its two cells' -sigma_zz at the
step's start (Pa, the scattered stress: elastic-plastic plus the temperature's kinetic
pressure) and at its end (the elastic-plastic), the most it can have carried.  With the mean
of the two at the start, the part of the stress's work the face does not carry is counted as
landing wherever the layer compresses: on the shaken layer (docs/validation.md section 22)
the faces then count several times the DEM's feed.  The face's landing is what remains,

    E_f = -J_f wbar_f + F_f (q_{k+1} - q_k) / 2 - max(p_f, 0) h max(-wbar_f, 0) dt,
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
from .grid_update import frame_body


@nb.njit(cache=True)
def body_acceleration_z(frame, t, x0, z0, h, ncx, ncz, v0, out):
    """The frame's body acceleration's z component (m/s^2) on each cell centre (N,) at time t (s)
    (grid_update.grid_update's: a0 - alpha J q + w^2 q - 2 w J v, v the cell's velocity v0
    (N, 2) m/s), into out (N,); cells of side h (m) from (x0, z0) (m), p = i ncz + k."""
    a0x, a0z, w, alpha, pvx, pvz = frame_body(frame, t)
    for i in range(ncx):
        qx = x0 + (i + 0.5) * h - pvx
        for k in range(ncz):
            p = i * ncz + k
            qz = z0 + (k + 0.5) * h - pvz
            out[p] = a0z - alpha * qx + w * w * qz - 2.0 * w * v0[p, 0]


@nb.njit(cache=True)
def _side_shear_N_m(i, k, ncx, ncz, sigma0, open_x, h):
    """The z force (N/m) of the start's shear stress on cell (i, k)'s two side faces; a
    periodic mesh's face 0 is its face ncx."""
    f = 0.0
    p = i * ncz + k
    right = i + 1
    if right == ncx:
        if ncx > 1 and open_x[0, k]:
            f += 0.5 * (sigma0[p, 2] + sigma0[k, 2]) * h
    elif right < ncx and open_x[right, k]:
        f += 0.5 * (sigma0[p, 2] + sigma0[right * ncz + k, 2]) * h
    if i == 0:
        if ncx > 1 and open_x[0, k]:
            f -= 0.5 * (sigma0[p, 2] + sigma0[(ncx - 1) * ncz + k, 2]) * h
    elif open_x[i, k]:
        f -= 0.5 * (sigma0[p, 2] + sigma0[(i - 1) * ncz + k, 2]) * h
    return f


@nb.njit(cache=True)
def column_terms(m0, v0, rho0, sigma0, m1, v1, sigma1, body_z, fext_z, h, open_x, open_z, rho_c,
                 dt, out):
    """Adds the cells' column landing power (W/m) of a step of dt (s) to out[:, 3] (module
    docstring), over every open z face of an Eulerian mesh (eulerian/mesh.py: open_x
    (ncx + 1, ncz), open_z (ncx, ncz + 1), cell p = i ncz + k; plane strain).  m0 (N,) kg/m,
    v0 (N, 2) m/s, rho0 (N,) kg/m^3 and sigma0 (N, 4) the stress the step scatters (Pa,
    [xx, zz, xz, yy], tension positive) at the step's start; m1 (N,) kg/m, v1 (N, 2) m/s and
    sigma1 (N, 4) the elastic-plastic stress (Pa) at its end; body_z (N,) the frame's body
    acceleration (m/s^2, `body_acceleration_z` at mid-step), fext_z (N,) the wall's and
    partitions' z force of the step (N/m); h (m) the cells' side, rho_c (kg/m^3) the critical
    density."""
    ncx = open_z.shape[0]
    ncz = open_x.shape[1]
    full0 = FULL * h * h
    for i in range(ncx):
        # from the top down: the impulse J (N s/m) through the face below the cells passed,
        # and the material's sums m, m v, m v^2 (start) above it
        J = 0.0
        dm = 0.0
        s0 = 0.0
        s1 = 0.0
        s2 = 0.0
        for k in range(ncz - 1, 0, -1):
            b = i * ncz + k
            if m0[b] > 0.0 or m1[b] > 0.0:
                ext = (m0[b] * body_z[b] + fext_z[b]
                       + _side_shear_N_m(i, k, ncx, ncz, sigma0, open_x, h)) * dt
                J += m1[b] * v1[b, 1] - m0[b] * v0[b, 1] - ext
                dm += m1[b] - m0[b]
                s0 += m0[b]
                s1 += m0[b] * v0[b, 1]
                s2 += m0[b] * v0[b, 1] * v0[b, 1]
            if not open_z[i, k]:
                # a closed face holds what is above it: the column starts again below
                J = 0.0
                dm = 0.0
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
            # the most the stress can have carried through the face: the largest of its two
            # cells' compressive normal stresses at the step's start and end
            p_face = max(max(-sigma0[a, 1], -sigma0[b, 1]), max(-sigma1[a, 1], -sigma1[b, 1]))
            stored = max(p_face, 0.0) * h * max(-wbar, 0.0) * dt
            va = v0[a, 1]
            cap = 0.5 * (s2 - 2.0 * va * s1 + va * va * s0)
            # the mass dm carried up through the face: its part of the remap's loss
            moved = 0.5 * dm * (v0[b, 1] * v1[b, 1] - v0[a, 1] * v1[a, 1])
            lost = min(max(-J * wbar + moved - stored, 0.0), cap) / dt
            m = ma + mb
            out[a, 3] += lost * mb / m
            out[b, 3] += lost * ma / m


def column_landing(m0, v0, rho0, sigma0, m1, v1, sigma1, fext, frame, t_mid, x0, z0, h, open_x,
                   open_z, rho_c, dt, out):
    """`column_terms` with the body acceleration of the packed frame (grid_update.
    FRAME_FIELDS) at the step's middle t_mid (s) and the step's external forces fext (N, 2)
    (N/m), cells from (x0, z0) (m)."""
    ncx, ncz = open_z.shape[0], open_x.shape[1]
    body = np.empty(m0.shape[0])
    body_acceleration_z(frame, t_mid, x0, z0, h, ncx, ncz, v0, body)
    column_terms(m0, v0, rho0, sigma0, m1, v1, sigma1, body, np.ascontiguousarray(fext[:, 1]),
                 h, open_x, open_z, rho_c, dt, out)
