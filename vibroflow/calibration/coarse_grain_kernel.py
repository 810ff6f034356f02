"""The coarse-graining kernel W of the x-z plane and its numba deposits of balls and contacts on
the grid (vibroflow.calibration.coarse_grain says what the sums are and how they are averaged;
Weinhart, Thornton, Luding & Bokhove 2012, Granular Matter 14:289).

Kernel (choice and why)
-----------------------
* "gaussian" (default): W = A [exp(-r^2 / 2 w^2) - exp(-c^2 / 2 w^2)] for r < c = cutoff * w
  (cutoff 3 by default), zero beyond.  The constant is subtracted so that W is continuous at the
  cut-off: the gradient of the CG fields is then exactly the sum of the kernel gradients (with a
  plain truncated Gaussian the jump at r = c would leave out a ring term and under-read every
  gradient by ~5 % at c = 3 w).  A normalises W to unit integral over the plane.
  (The shift narrows it slightly: its standard deviation per axis is 0.94 w at c = 3 w.)
* "lucy": W = 5 / (pi c^2) (1 + 3 s)(1 - s)^3, s = r / c < 1 (the 2D Lucy polynomial).  `width`
  is its standard deviation per axis (the uncut Gaussian's w), so c = sqrt(56 / 5) w ~ 3.35 w;
  it has compact support by construction and takes no `cutoff`.
* Default width w = d / 2 with d = 6.35 mm, i.e. 3.2 mm, cut off at 9.5 mm.  Weinhart et al.
  2012 find the CG fields independent of w over a plateau from about d/4 to d/2 (below it the
  fields show the single-particle layering, above it real gradients are smeared); we take the
  upper end because the fields here are averaged over y and a 15 mm grid and the shear-rate
  field (a gradient) is the noisiest quantity, while d/2 still resolves the ~1-2 d boundary
  layer at the wall.  Pass width = d/4 for near-wall profiles on a fine grid.


Layout of the sums: per ball (N_BALL_Q rows: B_RHO, B_VOL, B_DRHO, B_P, B_DP, B_K) and per
contact (N_CONTACT_Q rows: sigma_c ab at 3 a + b), on (nx, nz) grids.
"""
from __future__ import annotations

import math

import numba as nb
import numpy as np

KERNELS = ("gaussian", "lucy")
LUCY_CUTOFF_PER_WIDTH = math.sqrt(56.0 / 5.0)  # c / w of the 2D Lucy kernel of per-axis std w

# Layout of the per-ball sums (first axis of the ball accumulator).
B_RHO, B_VOL, B_DRHO = 0, 1, 2               # rho; volume; d rho / dx, dz  (2)
B_P = 4                                      # momentum x, y, z  (3)
B_DP = 7                                     # d P_a / d x_b: 7 + 2 a + b, b = 0 (x), 1 (z)  (6)
B_K = 13                                     # K xx yy zz xy xz yz  (6)
K_PAIRS = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))  # the axes of B_K + q
N_BALL_Q = 19
N_CONTACT_Q = 9                              # sigma_c ab, 3 a + b


# ----------------------------------------------------------------------------------------------
# numba kernels: pure functions over flat arrays.

@nb.njit(cache=True, inline="always")
def _w_and_grad(dx, dz, kind, amp, inv2w2, shift, rc):
    """Kernel value and gradient (d/dx, d/dz of W(r - r_p)) at offset (dx, dz) = r - r_p."""
    r2 = dx * dx + dz * dz
    if r2 >= rc * rc:
        return 0.0, 0.0, 0.0
    if kind == 0:
        e = math.exp(-r2 * inv2w2)
        g = -2.0 * inv2w2 * amp * e
        return amp * (e - shift), g * dx, g * dz
    s = math.sqrt(r2) / rc
    om = 1.0 - s
    g = -12.0 * amp * om * om / (rc * rc)
    return amp * (1.0 + 3.0 * s) * om * om * om, g * dx, g * dz


@nb.njit(cache=True, inline="always")
def _cells_within(x, z, rc, x0, z0, h, nx, nz):
    """(a0, a1, b0, b1): the first and last cells along x and z of the grid (cell (a, b) centred
    at (x0 + a h, z0 + b h), nx by nz) whose centres lie within rc (m) of (x, z) along each axis
    (a0 > a1 or b0 > b1: none)."""
    return (max(int(math.ceil((x - rc - x0) / h)), 0),
            min(int(math.floor((x + rc - x0) / h)), nx - 1),
            max(int(math.ceil((z - rc - z0) / h)), 0),
            min(int(math.floor((z + rc - z0) / h)), nz - 1))


@nb.njit(cache=True)
def deposit_balls(px, pz, mass, volume, vel, factor, x0, z0, h, nx, nz, kind, amp, inv2w2,
                  shift, rc, out):
    """Add factor x the per-ball kernel sums of one snapshot to out (N_BALL_Q, nx, nz).

    px, pz : (N,) tub-frame x, z (m); mass (kg), volume (m^3) : (N,); vel : (N, 3) (m/s);
    the grid's cell (a, b) is centred at (x0 + a h, z0 + b h).  Sums are per unit area (the
    kernel is 2D); the caller divides by the depth.
    """
    n = px.shape[0]
    for p in range(n):
        x = px[p]
        z = pz[p]
        a0, a1, b0, b1 = _cells_within(x, z, rc, x0, z0, h, nx, nz)
        if a0 > a1 or b0 > b1:
            continue
        m = mass[p] * factor
        vo = volume[p] * factor
        v = (vel[p, 0], vel[p, 1], vel[p, 2])
        for a in range(a0, a1 + 1):
            dx = x0 + a * h - x
            for b in range(b0, b1 + 1):
                dz = z0 + b * h - z
                w, gx, gz = _w_and_grad(dx, dz, kind, amp, inv2w2, shift, rc)
                if w == 0.0 and gx == 0.0 and gz == 0.0:
                    continue
                mw = m * w
                out[B_RHO, a, b] += mw
                out[B_VOL, a, b] += vo * w
                out[B_DRHO, a, b] += m * gx
                out[B_DRHO + 1, a, b] += m * gz
                for c in range(3):
                    mv = m * v[c]
                    out[B_P + c, a, b] += mw * v[c]
                    out[B_DP + 2 * c, a, b] += mv * gx
                    out[B_DP + 2 * c + 1, a, b] += mv * gz
                for q in range(6):
                    c, e = K_PAIRS[q]
                    out[B_K + q, a, b] += mw * v[c] * v[e]


@nb.njit(cache=True)
def deposit_contacts(start, branch, force, s_nodes, s_weights, factor, x0, z0, h, nx, nz, kind,
                     amp, inv2w2, shift, rc, out):
    """Add factor x sum_c f_c (x) b_c int_0^1 W(r - start_c + s b_c) ds to out (9, nx, nz).

    start : (C, 3) r_i, the ball's centre (tub frame, m); branch : (C, 3) b = r_i - r_j (or
    r_i - contact point for a wall), m; force : (C, 3) on ball i (N, tub axes).  The line
    integral from r_i to r_i - b is done with the quadrature nodes s_nodes in [0, 1] and weights
    s_weights (summing to 1).
    """
    nc = start.shape[0]
    nq = s_nodes.shape[0]
    t = np.empty(9)
    for c in range(nc):
        for i in range(3):
            for j in range(3):
                t[3 * i + j] = force[c, i] * branch[c, j] * factor
        for q in range(nq):
            x = start[c, 0] - s_nodes[q] * branch[c, 0]
            z = start[c, 2] - s_nodes[q] * branch[c, 2]
            wq = s_weights[q]
            a0, a1, b0, b1 = _cells_within(x, z, rc, x0, z0, h, nx, nz)
            for a in range(a0, a1 + 1):
                dx = x0 + a * h - x
                for b in range(b0, b1 + 1):
                    dz = z0 + b * h - z
                    w, _gx, _gz = _w_and_grad(dx, dz, kind, amp, inv2w2, shift, rc)
                    if w == 0.0:
                        continue
                    ww = wq * w
                    for k in range(9):
                        out[k, a, b] += ww * t[k]


# ----------------------------------------------------------------------------------------------
# Kernel parameters.

def kernel_parameters(kernel: str, width: float, cutoff: float | None):
    """(kind, amplitude, 1/(2 w^2), shift, cut-off radius) of the 2D kernel (SI)."""
    if kernel == "gaussian":
        c = 3.0 if cutoff is None else float(cutoff)
        rc = c * width
        shift = math.exp(-0.5 * c * c)
        # integral over the disc r < rc of [exp(-r^2/2w^2) - shift]
        norm = 2.0 * math.pi * width**2 * (1.0 - shift) - math.pi * rc**2 * shift
        return 0, 1.0 / norm, 1.0 / (2.0 * width**2), shift, rc
    rc = LUCY_CUTOFF_PER_WIDTH * width
    return 1, 5.0 / (math.pi * rc**2), 0.0, 0.0, rc


def kernel_value(kernel: str, width: float, cutoff: float | None, dx, dz):
    """W at offsets (dx, dz) (m), vectorised; for checks and plots (1/m^2)."""
    kind, amp, inv2w2, shift, rc = kernel_parameters(kernel, width, cutoff)
    r2 = np.asarray(dx, float) ** 2 + np.asarray(dz, float) ** 2
    if kind == 0:
        w = amp * (np.exp(-r2 * inv2w2) - shift)
    else:
        s = np.sqrt(r2) / rc
        w = amp * (1.0 + 3.0 * s) * (1.0 - s) ** 3
    return np.where(r2 < rc * rc, w, 0.0)


