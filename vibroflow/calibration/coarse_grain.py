"""Coarse-grained (CG) continuum fields from DEM snapshots: models.md
"Coarse-graining" (Goldhirsch 2010; Weinhart, Thornton, Luding & Bokhove 2012, Granular Matter
14:289, "From discrete particles to continuum fields near a boundary"; MercuryCG).

Usable on any DEM result (our engine, an imported LIGGGHTS run, a synthetic test): the caller
hands over, per snapshot, the balls' positions and velocities in the tub frame and the contact
forces; `CoarseGrainer` accumulates kernel-weighted sums on a grid and `fields()` turns the
averaged sums into continuum fields.

Frame and grid
--------------
Everything is in the tub frame (tub47.md "Frames"): x across, z up, y along the tub; velocities
are relative to the tub, in tub axes (vibroflow.tub.motion.relative_velocity_tub_axes_np;
`snapshot_from_state` does the conversion for a live DEM state).  The fields are averaged over
y: the kernel W is two-dimensional in (x, z), normalised so that its integral over the x-z plane
is 1, and a per-unit-volume field is the kernel sum divided by the slab depth L_y
(default: the tub's length), e.g. rho(x, z) = sum_i m_i W(x - x_i, z - z_i) / L_y.
The grid is cell-centred with spacing h (default: tub47's 15 mm cells, centres on multiples of
h, as vibroflow.measure.bulk), covering the tub's cross-section (bulk.grid_extent) plus a margin
of cells wide enough to hold the kernel's support, so that no deposited mass, momentum or stress
leaves the grid (the integral identities then hold exactly).  A field value is the smoothed
field at the cell centre (a point value, not a cell average).

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

Definitions (compression positive)
----------------------------------
Sign convention: **compression positive** (a bed at rest has sigma_zz > 0, p > 0).
* density rho = sum_i m_i W_i / L_y; solid fraction phi = sum_i V_i W_i / L_y (V_i ball volume);
  momentum density P = sum_i m_i v_i W_i / L_y; velocity V = P / rho.
* kinetic stress sigma_k = sum_i m_i v'_i (x) v'_i W_i / L_y, v'_i = v_i - V(r), computed as
  K - P (x) P / rho with K = sum_i m_i v_i (x) v_i W_i / L_y.
* contact stress sigma_c = sum_contacts f_ij (x) r_ij  int_0^1 W(r - r_i + s r_ij) ds / L_y,
  each touching pair once, f_ij the force on i by j, r_ij = r_i - r_j (branch), the line
  integral by Gauss-Legendre quadrature (`quadrature` points, default 4); plus every wall
  contact, with f the wall's force on the ball and r = r_i - c (ball centre minus contact point),
  so the stress carries the wall's load up to the wall and the momentum balance
  d sigma_ab / d x_b = rho g_a - (rate of change of momentum) holds right up to the boundary.
  The tensor is kept whole (3 x 3, not symmetrised: f (x) r of a frictional contact is not).
* stress sigma = sigma_k + sigma_c; pressure p = tr(sigma) / 3; deviator tau = sym(sigma) - p 1;
  shear stress tau_eq = sqrt(tau : tau / 2); friction coefficient mu = tau_eq / p.
* velocity gradient L_ab = d V_a / d x_b for b in (x, z) from the kernel gradients,
  L = (grad P - V (x) grad rho) / rho (exact for the CG field; `gradient="grid"` takes central
  differences on the grid instead); its y column is zero (fields are uniform in y).
  Strain rate D = (L + L^T) / 2 (D_yy = D_xy = D_yz = 0 when V_y = 0); shear rate
  gamma_dot = sqrt(2 D' : D'), D' = D - tr(D) / 3 1 (simple shear v_x = g z gives g).
* granular temperature T = tr(sigma_k) / (3 rho) = <|v'|^2> / 3 (m^2/s^2).
* inertial number I = gamma_dot d / sqrt(p / rho_s).

Averaging
---------
Time averages are averages of the *sums* (rho, P, K, grad rho, grad P, sigma_c) over the
snapshots (weighted by `weight`), from which every field is then derived: V = <P>/<rho> is the
mass-weighted (Favre) mean velocity and the kinetic stress <K> - <P><P>/<rho> counts the
fluctuation of each ball about that time-mean velocity, so it includes the local velocity's own
oscillation over the cycle.  Phase-resolved fields (`n_phases`, `phase_bin`) do the same within
each phase bin, and there the kinetic stress is the fluctuation at that phase.  With
`n_batches` >= 2 (batches of whole cycles: vibroflow.measure.stats.batches_of_whole_cycles)
every field also gets `<name>_stderr`, the batch-means standard error of the same derivation
done per batch.

Cost: one pass over the balls and the contacts per snapshot, each deposited on the cells within
the kernel's cut-off by a numba kernel (single-threaded, so results do not depend on the thread
count).  Memory: (n_batches x n_phases x 28 x n_cells) float64.
"""
from __future__ import annotations

import math

import numba as nb
import numpy as np

from vibroflow.measure.bulk import grid_extent
from vibroflow.measure.stats import phase_bins, stderr_of_batches  # noqa: F401 (re-exported)
from vibroflow.errors import InputError
from vibroflow.tub.geometry import TubGeometry
from vibroflow.tub.motion import lab_to_tub_np, pose_np, relative_velocity_tub_axes_np

try:  # optional: fields() returns a plain dict without it
    import xarray as _xr
except ImportError:  # pragma: no cover - exercised only where xarray is absent
    _xr = None

KERNELS = ("gaussian", "lucy")
D_TUB47 = 0.00635          # m, tub47's ball diameter (default kernel width d/2)
LUCY_CUTOFF_PER_WIDTH = math.sqrt(56.0 / 5.0)  # c / w of the 2D Lucy kernel of per-axis std w

# Layout of the per-ball sums (first axis of the ball accumulator).
B_RHO, B_VOL, B_DRHO = 0, 1, 2               # rho; volume; d rho / dx, dz  (2)
B_P = 4                                      # momentum x, y, z  (3)
B_DP = 7                                     # d P_a / d x_b: 7 + 2 a + b, b = 0 (x), 1 (z)  (6)
B_K = 13                                     # K xx yy zz xy xz yz  (6)
N_BALL_Q = 19
N_CONTACT_Q = 9                              # sigma_c ab, 3 a + b
_SYM = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))
_COMP = ["x", "y", "z"]


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
        a0 = max(int(math.ceil((x - rc - x0) / h)), 0)
        a1 = min(int(math.floor((x + rc - x0) / h)), nx - 1)
        b0 = max(int(math.ceil((z - rc - z0) / h)), 0)
        b1 = min(int(math.floor((z + rc - z0) / h)), nz - 1)
        if a0 > a1 or b0 > b1:
            continue
        m = mass[p] * factor
        vo = volume[p] * factor
        vx = vel[p, 0]
        vy = vel[p, 1]
        vz = vel[p, 2]
        for a in range(a0, a1 + 1):
            dx = x0 + a * h - x
            for b in range(b0, b1 + 1):
                dz = z0 + b * h - z
                w, gx, gz = _w_and_grad(dx, dz, kind, amp, inv2w2, shift, rc)
                if w == 0.0 and gx == 0.0 and gz == 0.0:
                    continue
                mw = m * w
                out[0, a, b] += mw
                out[1, a, b] += vo * w
                out[2, a, b] += m * gx
                out[3, a, b] += m * gz
                out[4, a, b] += mw * vx
                out[5, a, b] += mw * vy
                out[6, a, b] += mw * vz
                out[7, a, b] += m * vx * gx
                out[8, a, b] += m * vx * gz
                out[9, a, b] += m * vy * gx
                out[10, a, b] += m * vy * gz
                out[11, a, b] += m * vz * gx
                out[12, a, b] += m * vz * gz
                out[13, a, b] += mw * vx * vx
                out[14, a, b] += mw * vy * vy
                out[15, a, b] += mw * vz * vz
                out[16, a, b] += mw * vx * vy
                out[17, a, b] += mw * vx * vz
                out[18, a, b] += mw * vy * vz


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
            a0 = max(int(math.ceil((x - rc - x0) / h)), 0)
            a1 = min(int(math.floor((x + rc - x0) / h)), nx - 1)
            b0 = max(int(math.ceil((z - rc - z0) / h)), 0)
            b1 = min(int(math.floor((z + rc - z0) / h)), nz - 1)
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


# ----------------------------------------------------------------------------------------------
# Derived fields (numpy, vectorised over any leading axes).

def rheology(velocity_gradient, stress, rho_s: float, diameter: float) -> dict:
    """Strain rate, shear rate, pressure, shear stress, inertial number and friction coefficient
    from a velocity gradient L_ab = dV_a/dx_b (s^-1) and a stress (Pa, compression positive),
    both (..., 3, 3); rho_s (kg/m^3) the solid density, diameter d (m).

    D = (L + L^T)/2; gamma_dot = sqrt(2 D':D'), D' = D - tr(D)/3 1; p = tr(sigma)/3;
    tau = sym(sigma) - p 1; tau_eq = sqrt(tau:tau/2); I = gamma_dot d / sqrt(p / rho_s);
    mu = tau_eq / p.  I and mu are NaN where p <= 0 (no compressive pressure).
    """
    L = np.asarray(velocity_gradient, float)
    s = np.asarray(stress, float)
    eye = np.eye(3)
    D = 0.5 * (L + np.swapaxes(L, -1, -2))
    Dd = D - np.trace(D, axis1=-2, axis2=-1)[..., None, None] / 3.0 * eye
    gamma = np.sqrt(2.0 * np.einsum("...ij,...ij->...", Dd, Dd))
    p = np.trace(s, axis1=-2, axis2=-1) / 3.0
    tau = 0.5 * (s + np.swapaxes(s, -1, -2)) - p[..., None, None] * eye
    tau_eq = np.sqrt(0.5 * np.einsum("...ij,...ij->...", tau, tau))
    with np.errstate(invalid="ignore", divide="ignore"):
        pos = p > 0
        I = np.where(pos, gamma * diameter / np.sqrt(np.where(pos, p, 1.0) / rho_s), np.nan)
        mu = np.where(pos, tau_eq / np.where(pos, p, 1.0), np.nan)
    return {"strain_rate": D, "shear_rate": gamma, "pressure": p, "shear_stress": tau_eq,
            "inertial_number": I, "friction_coefficient": mu}


def velocity_gradient_on_grid(velocity, cell_size: float):
    """Velocity gradient (..., nx, nz, 3, 3) by second-order differences (np.gradient) of a
    grid velocity (..., nx, nz, 3) with spacing cell_size (m); the y column is zero."""
    v = np.asarray(velocity, float)
    L = np.zeros(v.shape + (3,))
    L[..., 0] = np.gradient(v, cell_size, axis=-3)
    L[..., 2] = np.gradient(v, cell_size, axis=-2)
    return L


def _derive(ball, cont, depth, rho_s, diameter, gradient, cell_size):
    """Fields from weight-averaged sums: ball (..., 19, nx, nz), cont (..., 9, nx, nz).
    Returns a dict of arrays (..., nx, nz[, 3[, 3]])."""
    ball = np.moveaxis(ball, -3, -1) / depth          # (..., nx, nz, 19)
    cont = np.moveaxis(cont, -3, -1) / depth
    rho = ball[..., B_RHO]
    P = ball[..., B_P:B_P + 3]
    with np.errstate(invalid="ignore", divide="ignore"):
        inv = np.where(rho > 0, 1.0 / np.where(rho > 0, rho, 1.0), np.nan)
        V = P * inv[..., None]
        K = np.zeros(rho.shape + (3, 3))
        for q, (a, b) in enumerate(_SYM):
            K[..., a, b] = ball[..., B_K + q]
            K[..., b, a] = ball[..., B_K + q]
        # no mass, no kinetic stress (the contact stress reaches a little further than the
        # density: the kernel rides along each branch to the wall's contact point)
        sig_k = np.where((rho > 0)[..., None, None],
                         K - np.einsum("...a,...b->...ab", P, np.nan_to_num(V)), 0.0)
        if gradient == "kernel":
            L = np.zeros(rho.shape + (3, 3))
            grad_rho = ball[..., B_DRHO:B_DRHO + 2]
            for a in range(3):
                for bi, b in enumerate((0, 2)):
                    L[..., a, b] = (ball[..., B_DP + 2 * a + bi]
                                    - V[..., a] * grad_rho[..., bi]) * inv
        else:
            L = velocity_gradient_on_grid(V, cell_size)
        T = np.trace(sig_k, axis1=-2, axis2=-1) / 3.0 * inv
    sig_c = cont.reshape(cont.shape[:-1] + (3, 3))
    sig = sig_k + sig_c
    out = {"density": rho, "solid_fraction": ball[..., B_VOL], "velocity": V,
           "velocity_gradient": L, "kinetic_stress": sig_k, "contact_stress": sig_c,
           "stress": sig, "temperature": T}
    out.update(rheology(L, sig, rho_s, diameter))
    return out


_META = {
    "density": ("kg m-3", "CG mass density rho = sum m_i W_i / L_y"),
    "solid_fraction": ("1", "solid fraction phi = sum V_i W_i / L_y"),
    "velocity": ("m s-1", "V = <P>/<rho>, relative to the tub, tub axes"),
    "velocity_gradient": ("s-1", "L_ij = dV_i/dx_j (y column zero)"),
    "kinetic_stress": ("Pa", "sum m v' (x) v' W / L_y, compression positive"),
    "contact_stress": ("Pa", "sum f_ij (x) r_ij int W ds / L_y incl. walls, compression "
                       "positive"),
    "stress": ("Pa", "kinetic + contact stress, compression positive"),
    "temperature": ("m2 s-2", "granular temperature T = tr(sigma_k) / (3 rho)"),
    "strain_rate": ("s-1", "D = (L + L^T)/2"),
    "shear_rate": ("s-1", "gamma_dot = sqrt(2 D':D')"),
    "pressure": ("Pa", "p = tr(sigma)/3, compression positive"),
    "shear_stress": ("Pa", "tau_eq = sqrt(tau:tau/2), tau = sym(sigma) - p 1"),
    "inertial_number": ("1", "I = gamma_dot d / sqrt(p / rho_s)"),
    "friction_coefficient": ("1", "mu = tau_eq / p"),
}


# ----------------------------------------------------------------------------------------------

class CoarseGrainer:
    """Streaming coarse-graining on a grid of the tub frame's x-z plane (see the module notes).

    Parameters
    ----------
    geometry : TubGeometry or None. Its cross-section sets the grid (bulk.grid_extent) and its
        length the default depth.  None needs `extent` and `depth`.
    cell_size : grid spacing h (m), default 0.015 (tub47's cells); any h > 0 (finer for
        profiles); cell centres are multiples of h.
    kernel : "gaussian" or "lucy".
    width : w (m), the kernel's standard deviation per axis; default d/2 with d = `diameter`.
    cutoff : Gaussian cut-off c / w (default 3); not allowed for "lucy" (c = 3.35 w).
    depth : slab depth L_y (m) that turns x-z kernel sums into per-volume fields; default the
        geometry's length.
    rho_s : solid density (kg/m^3) for the inertial number; default: the mass over the volume of
        the balls added.
    extent : (x_min, x_max, z_min, z_max) (m) of the region the grid must cover, instead of the
        geometry's cross-section.
    margin : extra cells on each side (default: enough to hold the kernel's support, so that
        nothing deposited leaves the grid).
    n_phases : number of phase bins for phase-resolved fields (None: time averages only).
    n_batches : batches of whole cycles for standard errors (1: none).
    quadrature : Gauss-Legendre points of the contact line integral (default 4).
    diameter : ball diameter d (m) for the default width and the inertial number (default
        tub47's 6.35 mm).
    """

    def __init__(self, geometry: TubGeometry | None = None, cell_size: float = 0.015,
                 kernel: str = "gaussian", width: float | None = None,
                 cutoff: float | None = None, depth: float | None = None,
                 rho_s: float | None = None, *, extent=None, margin: int | None = None,
                 n_phases: int | None = None, n_batches: int = 1, quadrature: int = 4,
                 diameter: float = D_TUB47):
        if not (cell_size > 0 and math.isfinite(cell_size)):
            raise InputError(f"cell_size = {cell_size!r}: must be a finite length > 0 m")
        if kernel not in KERNELS:
            raise InputError(f"kernel = {kernel!r}: must be one of {', '.join(KERNELS)}")
        if not (diameter > 0):
            raise InputError(f"diameter = {diameter!r}: must be > 0 m")
        if width is None:
            width = 0.5 * diameter
        if not (width > 0 and math.isfinite(width)):
            raise InputError(f"width = {width!r}: must be a finite length > 0 m")
        if kernel == "lucy" and cutoff is not None:
            raise InputError(f"cutoff = {cutoff!r}: not allowed with kernel = 'lucy' (its "
                             f"support is fixed at {LUCY_CUTOFF_PER_WIDTH:.3f} width)")
        if cutoff is not None and not (cutoff >= 1.0 and math.isfinite(cutoff)):
            raise InputError(f"cutoff = {cutoff!r}: must be a finite number >= 1 (widths)")
        if geometry is None and (extent is None or depth is None):
            raise InputError("geometry = None: give extent = (x_min, x_max, z_min, z_max) and "
                             "depth instead")
        if depth is None:
            depth = float(geometry.length)
        if not (depth > 0 and math.isfinite(depth)):
            raise InputError(f"depth = {depth!r}: must be a finite length > 0 m")
        if rho_s is not None and not (rho_s > 0):
            raise InputError(f"rho_s = {rho_s!r}: must be > 0 kg/m^3")
        if n_phases is not None and int(n_phases) < 1:
            raise InputError(f"n_phases = {n_phases!r}: must be at least 1 (or None)")
        if int(n_batches) < 1:
            raise InputError(f"n_batches = {n_batches!r}: must be at least 1")
        if int(quadrature) < 1:
            raise InputError(f"quadrature = {quadrature!r}: must be at least 1 point")
        self.kernel = kernel
        self.width = float(width)
        self.cutoff = (3.0 if cutoff is None else float(cutoff)) if kernel == "gaussian" \
            else LUCY_CUTOFF_PER_WIDTH
        self._kp = kernel_parameters(kernel, self.width, cutoff)
        self.cutoff_radius = self._kp[4]
        self.h = float(cell_size)
        self.depth = float(depth)
        self.rho_s = None if rho_s is None else float(rho_s)
        self.diameter = float(diameter)
        if extent is None:
            i0, i1, k0, k1 = grid_extent(geometry, self.h)
        else:
            xa, xb, za, zb = (float(v) for v in extent)
            if not (xb > xa and zb > za):
                raise InputError(f"extent = {tuple(extent)!r}: must be (x_min, x_max, z_min, "
                                 f"z_max) with x_max > x_min and z_max > z_min (m)")
            i0, i1 = int(np.ceil(xa / self.h - 0.5)), int(np.floor(xb / self.h + 0.5))
            k0, k1 = int(np.ceil(za / self.h - 0.5)), int(np.floor(zb / self.h + 0.5))
        if margin is None:
            margin = int(math.ceil(self.cutoff_radius / self.h))
        if int(margin) < 0:
            raise InputError(f"margin = {margin!r}: must be >= 0 cells")
        margin = int(margin)
        self.i_min, self.i_max = i0 - margin, i1 + margin
        self.k_min, self.k_max = k0 - margin, k1 + margin
        self.nx = self.i_max - self.i_min + 1
        self.nz = self.k_max - self.k_min + 1
        self.x = np.arange(self.i_min, self.i_max + 1) * self.h
        self.z = np.arange(self.k_min, self.k_max + 1) * self.h
        self.n_phases = None if n_phases is None else int(n_phases)
        self.n_batches = int(n_batches)
        nph = self.n_phases or 1
        self._ball = np.zeros((self.n_batches, nph, N_BALL_Q, self.nx, self.nz))
        self._cont = np.zeros((self.n_batches, nph, N_CONTACT_Q, self.nx, self.nz))
        self._weight = np.zeros((self.n_batches, nph))
        self._snapshots = 0
        self._mass = 0.0
        self._volume = 0.0
        nodes, weights = np.polynomial.legendre.leggauss(int(quadrature))
        self._s_nodes = 0.5 * (nodes + 1.0)
        self._s_weights = 0.5 * weights

    # ------------------------------------------------------------------------------------------
    def add_snapshot(self, positions_tub, velocities_rel_tub, radius, mass,
                     contacts_i=None, contacts_j=None, contact_force=None, contact_branch=None,
                     wall_particle=None, wall_force=None, wall_point=None, weight: float = 1.0,
                     phase_bin: int | None = None, batch: int = 0) -> None:
        """Accumulate one snapshot.

        positions_tub : (N, 3) ball centres in the tub frame (m).
        velocities_rel_tub : (N, 3) velocities relative to the tub, tub axes (m/s).
        radius, mass : (N,) (m, kg), or scalars.
        contacts_i, contacts_j : (C,) ball indices of each touching pair, each pair once.
        contact_force : (C, 3) force on i by j, tub axes (N).
        contact_branch : (C, 3) r_i - r_j (m; minimum image if periodic); default computed
            from the positions (then contacts_j is needed).
        wall_particle : (W,) ball of each wall contact; wall_force : (W, 3) the wall's force on
            the ball, tub axes (N); wall_point : (W, 3) contact point, tub frame (m).
        weight : the snapshot's weight in the averages (>= 0).
        phase_bin : phase bin 0 .. n_phases-1 (required when n_phases is set; see phase_bins).
        batch : batch of whole cycles 0 .. n_batches-1; negative: the snapshot is skipped
            (as stats.batches_of_whole_cycles marks samples outside the window).
        """
        if batch < 0:
            return
        if batch >= self.n_batches:
            raise InputError(f"batch = {batch!r}: must be < n_batches = {self.n_batches}")
        if self.n_phases is None:
            if phase_bin not in (None, 0):
                raise InputError(f"phase_bin = {phase_bin!r}: this CoarseGrainer has no phase "
                                 f"bins (give n_phases)")
            ph = 0
        else:
            if phase_bin is None or not (0 <= int(phase_bin) < self.n_phases):
                raise InputError(f"phase_bin = {phase_bin!r}: must be 0 .. {self.n_phases - 1}")
            ph = int(phase_bin)
        if not (weight >= 0 and math.isfinite(weight)):
            raise InputError(f"weight = {weight!r}: must be a finite number >= 0")
        pos = np.ascontiguousarray(positions_tub, dtype=np.float64)
        vel = np.ascontiguousarray(velocities_rel_tub, dtype=np.float64)
        n = pos.shape[0]
        if pos.shape != (n, 3) or vel.shape != (n, 3):
            raise InputError(f"positions_tub, velocities_rel_tub have shapes {pos.shape}, "
                             f"{vel.shape}: must both be (N, 3)")
        r = np.broadcast_to(np.asarray(radius, dtype=np.float64), (n,))
        m = np.ascontiguousarray(np.broadcast_to(np.asarray(mass, dtype=np.float64), (n,)))
        vol = np.ascontiguousarray(4.0 / 3.0 * math.pi * r**3)
        kind, amp, inv2w2, shift, rc = self._kp
        grid = (self.i_min * self.h, self.k_min * self.h, self.h, self.nx, self.nz)
        deposit_balls(pos[:, 0].copy(), pos[:, 2].copy(), m, vol, vel, float(weight), *grid,
                      kind, amp, inv2w2, shift, rc, self._ball[batch, ph])
        if contacts_i is not None and len(contacts_i):
            ci = np.asarray(contacts_i, dtype=np.int64)
            f = np.ascontiguousarray(contact_force, dtype=np.float64).reshape(-1, 3)
            if contact_branch is None:
                if contacts_j is None:
                    raise InputError("contact_branch = None: give contact_branch or contacts_j")
                b = pos[ci] - pos[np.asarray(contacts_j, dtype=np.int64)]
            else:
                b = np.ascontiguousarray(contact_branch, dtype=np.float64).reshape(-1, 3)
            if f.shape[0] != ci.size or b.shape[0] != ci.size:
                raise InputError(f"contact_force, contact_branch have {f.shape[0]}, "
                                 f"{b.shape[0]} rows: must have one per contact ({ci.size})")
            deposit_contacts(pos[ci], b, f, self._s_nodes, self._s_weights, float(weight),
                             *grid, kind, amp, inv2w2, shift, rc, self._cont[batch, ph])
        if wall_particle is not None and len(wall_particle):
            wi = np.asarray(wall_particle, dtype=np.int64)
            wf = np.ascontiguousarray(wall_force, dtype=np.float64).reshape(-1, 3)
            wp = np.asarray(wall_point, dtype=np.float64).reshape(-1, 3)
            if wf.shape[0] != wi.size or wp.shape[0] != wi.size:
                raise InputError(f"wall_force, wall_point have {wf.shape[0]}, {wp.shape[0]} "
                                 f"rows: must have one per wall contact ({wi.size})")
            start = pos[wi]
            deposit_contacts(start, start - wp, wf, self._s_nodes, self._s_weights,
                             float(weight), *grid, kind, amp, inv2w2, shift, rc,
                             self._cont[batch, ph])
        self._weight[batch, ph] += weight
        self._snapshots += 1
        self._mass += float(m.sum())
        self._volume += float(vol.sum())

    # ------------------------------------------------------------------------------------------
    @property
    def n_snapshots(self) -> int:
        return self._snapshots

    def solid_density(self) -> float:
        """rho_s (kg/m^3): as given, else the mass over the volume of the balls added."""
        if self.rho_s is not None:
            return self.rho_s
        return self._mass / self._volume if self._volume > 0 else float("nan")

    def _fields_of(self, ball, cont, weight, gradient):
        with np.errstate(invalid="ignore", divide="ignore"):
            inv = np.where(weight > 0, 1.0 / np.where(weight > 0, weight, 1.0), np.nan)
        ball = ball * inv[..., None, None, None]
        cont = cont * inv[..., None, None, None]
        return _derive(ball, cont, self.depth, self.solid_density(), self.diameter, gradient,
                       self.h)

    def fields(self, phase_resolved: bool = False, gradient: str = "kernel",
               stderr: bool | None = None, as_xarray: bool | None = None):
        """The averaged fields.

        phase_resolved : False: time averages over every snapshot added, dims (x, z, ...);
            True: one average per phase bin, dims (phase, x, z, ...), phase in rad.
        gradient : "kernel" (exact CG velocity gradient, default) or "grid" (central
            differences of V on the grid).
        stderr : add `<name>_stderr` (batch means) for every field; default when n_batches >= 2.
        as_xarray : return an xarray.Dataset (default when xarray is installed) or a dict
            {"coords": {...}, "attrs": {...}, name: (dims, array, attrs)}.

        Vectors have a last dim `i`, tensors `i`, `j` (coordinates "x", "y", "z").  Where no
        mass reaches a point the velocity, its gradient and the temperature are NaN and the
        kinetic stress is zero (the stress is then the contact stress alone).
        """
        if gradient not in ("kernel", "grid"):
            raise InputError(f"gradient = {gradient!r}: must be 'kernel' or 'grid'")
        if self._weight.sum() <= 0:
            raise InputError("fields(): no snapshot with positive weight was added")
        if phase_resolved and self.n_phases is None:
            raise InputError("phase_resolved = True: this CoarseGrainer has no phase bins "
                             "(give n_phases)")
        if stderr is None:
            stderr = self.n_batches >= 2
        if phase_resolved:
            main = self._fields_of(self._ball.sum(axis=0), self._cont.sum(axis=0),
                                   self._weight.sum(axis=0), gradient)
            per_batch = self._fields_of(self._ball, self._cont, self._weight, gradient) \
                if stderr else None
            lead = ("phase",)
        else:
            main = self._fields_of(self._ball.sum(axis=(0, 1)), self._cont.sum(axis=(0, 1)),
                                   self._weight.sum(), gradient)
            per_batch = self._fields_of(self._ball.sum(axis=1), self._cont.sum(axis=1),
                                        self._weight.sum(axis=1), gradient) if stderr else None
            lead = ()
        coords = {"x": self.x, "z": self.z, "i": _COMP, "j": _COMP}
        if phase_resolved:
            coords["phase"] = 2.0 * np.pi * np.arange(self.n_phases) / self.n_phases
        attrs = {
            "kernel": self.kernel, "width_m": self.width, "cutoff_widths": self.cutoff,
            "cutoff_radius_m": self.cutoff_radius, "cell_size_m": self.h,
            "depth_m": self.depth, "rho_s_kg_m3": self.solid_density(),
            "diameter_m": self.diameter, "n_snapshots": self._snapshots,
            "n_batches": self.n_batches, "sign_convention": "compression positive",
            "frame": "tub frame; velocities relative to the tub, tub axes; averaged over y",
            "averaging": "averages of kernel sums over snapshots, then derived",
            "gradient": gradient,
        }
        out = {}
        for name, arr in main.items():
            extra = ("i", "j")[:arr.ndim - len(lead) - 2]
            dims = lead + ("x", "z") + extra
            unit, desc = _META[name]
            out[name] = (dims, arr, {"units": unit, "long_name": desc})
            if per_batch is not None:
                se = stderr_of_batches(per_batch[name], axis=0)
                out[name + "_stderr"] = (dims, np.asarray(se),
                                         {"units": unit,
                                          "long_name": f"batch-means standard error of {name}"})
        use_xr = (_xr is not None) if as_xarray is None else bool(as_xarray)
        if use_xr:
            if _xr is None:
                raise InputError("as_xarray = True: xarray is not installed")
            ds = _xr.Dataset({k: v for k, v in out.items()}, coords=coords, attrs=attrs)
            ds["x"].attrs["units"] = "m"
            ds["z"].attrs["units"] = "m"
            if phase_resolved:
                ds["phase"].attrs.update(units="rad", long_name="phase of the vibration cycle")
            return ds
        return {"coords": coords, "attrs": attrs, **out}


# ----------------------------------------------------------------------------------------------

def snapshot_from_state(system, state, contacts: bool = True) -> dict:
    """add_snapshot keyword arguments for a live DEM state (vibroflow.dem.simulate):
    positions in the tub frame, velocities relative to the tub in tub axes, ball-ball contacts
    (vibroflow.dem.query.ball_contacts_now) and wall contacts
    (vibroflow.dem.simulate.wall_contacts_now), forces and branches turned into tub axes.

    The tub's pose is the system's motion at the state's time (at rest unless the state is
    vibrating); wall contact points are in the tub frame (wall_contacts_now).
    """
    from vibroflow.dem.query import ball_contacts_now
    from vibroflow.dem.simulate import wall_contacts_now
    from vibroflow.tub.motion import TubMotion

    motion = system.motion if state.vibrating else TubMotion.still()
    pivot = (motion.pivot_x, motion.pivot_z)
    pz = pose_np(motion, state.time(system.dt))
    X, Z, th = float(pz["X"]), float(pz["Z"]), float(pz["theta"])
    Xd, Zd, thd = float(pz["Xdot"]), float(pz["Zdot"]), float(pz["thetadot"])

    def axes(v):  # a lab vector in tub axes: the rotation alone (no translation, pivot 0)
        return lab_to_tub_np(v, 0.0, 0.0, th, (0.0, 0.0))

    out = {
        "positions_tub": lab_to_tub_np(state.pos, X, Z, th, pivot),
        "velocities_rel_tub": relative_velocity_tub_axes_np(state.pos, state.vel, X, Z, th, Xd,
                                                            Zd, thd, pivot),
        "radius": state.radius.copy(), "mass": state.mass.copy(),
    }
    if contacts:
        bc = ball_contacts_now(system, state)
        out.update(contacts_i=bc["i"], contacts_j=bc["j"], contact_force=axes(bc["force"]),
                   contact_branch=axes(bc["branch"]))
        wc = wall_contacts_now(system, state)
        out.update(wall_particle=wc["particle"], wall_force=axes(wc["force"]),
                   wall_point=wc["point_tub"])
    return out
