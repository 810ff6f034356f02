"""The Lees-Edwards periodic box: its images, its neighbour search and its wrap (the geometry of
the DEM's simple-shear variant; the step is vibroflow.dem.periodic_step, the orchestration
vibroflow.dem.periodic_box).

Kinematics
----------
Box [0, L_x) x [0, L_y) x [0, L_z), periodic in x and y.  Across z the boundaries are those of
Lees & Edwards (1972) for the simple shear v_x = gamma_dot z: the image of ball j one box above
(k = +1) or below (k = -1) sits at r_j + k (Delta, 0, L_z) and moves at v_j + k gamma_dot L_z x,
with the accumulated offset Delta = int gamma_dot L_z dt (mod L_x).  A ball leaving through the
top re-enters at the bottom shifted by -Delta in x and with v_x - gamma_dot L_z (and the reverse
through the bottom); `image` counts these crossings, so sum m (v_x + image_z gamma_dot L_z) (the
momentum of the unwrapped balls) is conserved by the pair forces.

Neighbours: cell list -> half Verlet list with a skin; each pair's minimum image (including the
LE shift) is found again at every step, so the list holds only j > i.  It is rebuilt when
2 max |non-affine displacement| + (accumulated shear + dilation strain) x cut-off could exceed
the skin (the displacement measured relative to the streaming profile, so the shear flow itself
does not force rebuilds).  Each list entry carries its contact's history (tangential spring and
rolling torque) keyed by the pair (i, j): `vibroflow.dem.neighbours.transfer_history` carries it
over rebuilds, and a contact that crosses the LE boundary keeps it.
"""
from __future__ import annotations

import numba as nb
import numpy as np

from .neighbours import INDEX

# box array: lengths (m) and the Lees-Edwards offset (m)
B_LX, B_LY, B_LZ, B_OFFSET = range(4)


@nb.njit(cache=True, inline="always")
def le_branch(pos, i, j, box):
    """Branch vector r_i - r_j(image) (m) to the nearest Lees-Edwards image of j, and the image
    index k: the image sits at r_j + k (Delta, 0, L_z).  Positions must lie in the box and
    0 <= Delta < L_x (comparisons rather than rint: this is the innermost loop)."""
    lx = box[B_LX]
    ly = box[B_LY]
    lz = box[B_LZ]
    dz = pos[i, 2] - pos[j, 2]
    k = 0.0
    if dz > 0.5 * lz:
        k = 1.0
        dz -= lz
    elif dz < -0.5 * lz:
        k = -1.0
        dz += lz
    dx = pos[i, 0] - pos[j, 0] - k * box[B_OFFSET]
    # |dx| < 2 L_x here
    if dx > 0.5 * lx:
        dx -= lx
        if dx > 0.5 * lx:
            dx -= lx
    elif dx < -0.5 * lx:
        dx += lx
        if dx < -0.5 * lx:
            dx += lx
    dy = pos[i, 1] - pos[j, 1]
    if dy > 0.5 * ly:
        dy -= ly
    elif dy < -0.5 * ly:
        dy += ly
    return dx, dy, dz, k


@nb.njit(cache=True)
def _cell_index(x, length, n):
    c = int(x / length * n)
    if c < 0:
        c = 0
    elif c >= n:
        c = n - 1
    return c


@nb.njit(cache=True)
def build_le_list(pos, radius, box, skin, dims):
    """Half Verlet list (CSR: start (N+1,), nbr (M,), j > i) of the pairs whose surfaces are
    closer than `skin` at their nearest Lees-Edwards image.  `dims` = cells per axis, each at
    least 3 (so the 27 cells scanned are distinct) and each cell at least the cut-off wide.

    Cells across the z boundary are scanned around x_i - k Delta, where the images of that
    layer sit; positions must be wrapped into the box."""
    n = pos.shape[0]
    nx, ny, nz = dims[0], dims[1], dims[2]
    lx, ly, lz, off = box[B_LX], box[B_LY], box[B_LZ], box[B_OFFSET]
    ncell = nx * ny * nz
    counts = np.zeros(ncell + 1, np.int64)
    flat = np.empty(n, np.int64)
    for i in range(n):
        f = ((_cell_index(pos[i, 0], lx, nx) * ny + _cell_index(pos[i, 1], ly, ny)) * nz
             + _cell_index(pos[i, 2], lz, nz))
        flat[i] = f
        counts[f + 1] += 1
    for c in range(ncell):
        counts[c + 1] += counts[c]
    fill = counts[:-1].copy()
    members = np.empty(n, np.int64)
    for i in range(n):  # members of a cell in index order: the list is reproducible
        members[fill[flat[i]]] = i
        fill[flat[i]] += 1
    start = np.zeros(n + 1, np.int64)
    cap = 16 * n + 64
    nbr = np.empty(cap, INDEX)
    m = 0
    for i in range(n):
        cy = _cell_index(pos[i, 1], ly, ny)
        cz = _cell_index(pos[i, 2], lz, nz)
        for dzc in range(-1, 2):
            az = cz + dzc
            k = 0
            if az < 0:
                az += nz
                k = -1
            elif az >= nz:
                az -= nz
                k = 1
            xs = pos[i, 0] - k * off
            xs -= lx * np.floor(xs / lx)
            cx = _cell_index(xs, lx, nx)
            for dxc in range(-1, 2):
                ax = (cx + dxc) % nx
                for dyc in range(-1, 2):
                    ay = (cy + dyc) % ny
                    f = (ax * ny + ay) * nz + az
                    for q in range(counts[f], counts[f + 1]):
                        j = members[q]
                        if j <= i:
                            continue
                        dx, dy, dz, _k = le_branch(pos, i, j, box)
                        cut = radius[i] + radius[j] + skin
                        if dx * dx + dy * dy + dz * dz < cut * cut:
                            if m == cap:
                                grown = np.empty(2 * cap, INDEX)
                                grown[:m] = nbr[:m]
                                nbr = grown
                                cap *= 2
                            nbr[m] = j
                            m += 1
        start[i + 1] = m
    # the scan visits cells in a fixed order but not by j: sort each i's entries so the list
    # (and the order of force summation) depends on the configuration alone
    for i in range(n):
        nbr[start[i]:start[i + 1]] = np.sort(nbr[start[i]:start[i + 1]])
    return start, nbr[:m].copy()


@nb.njit(cache=True)
def wrap(pos, vel, image, box, gamma_dot):
    """Put every ball back in the box: across z with the Lees-Edwards shift -k Delta in x and
    velocity jump -k gamma_dot L_z (k = +1 leaving through the top), then x and y periodic."""
    lz, off = box[B_LZ], box[B_OFFSET]
    for i in range(pos.shape[0]):
        k = np.floor(pos[i, 2] / lz)
        if k != 0.0:
            pos[i, 2] -= k * lz
            pos[i, 0] -= k * off
            vel[i, 0] -= k * gamma_dot * lz
            image[i, 2] += int(k)
            if pos[i, 2] >= lz:  # round-off of a ball a hair below the top
                pos[i, 2] -= lz
        for a in range(2):  # x and y: box[B_LX], box[B_LY]
            length = box[a]
            k = np.floor(pos[i, a] / length)
            if k != 0.0:
                pos[i, a] -= k * length
                image[i, a] += int(k)
                if pos[i, a] >= length:
                    pos[i, a] -= length
