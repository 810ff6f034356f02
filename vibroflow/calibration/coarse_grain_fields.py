"""Continuum fields derived from the averaged coarse-graining sums
(vibroflow.calibration.coarse_grain): numpy, vectorised over any leading axes.

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

"""
from __future__ import annotations

import numpy as np

from .coarse_grain_kernel import B_DP, B_DRHO, B_K, B_P, B_RHO, B_VOL

SYM = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))
COMPONENTS = ["x", "y", "z"]



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


def derive_fields(ball, cont, depth, rho_s, diameter, gradient, cell_size):
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
        for q, (a, b) in enumerate(SYM):
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


FIELD_META = {
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


