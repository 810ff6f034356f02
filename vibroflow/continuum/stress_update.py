"""The compiled constitutive update: elasto-visco-plastic stress of a point or a cell.

One module for the Lagrangian (material point) and the Eulerian solvers: both call
`update_stress_points` (`elastic_predictor` then `return_map`) on a material point's (or a
cell's) stress, with the material's packed parameters (constitutive.ContinuumMaterial.as_array,
its P_* layout).

Conventions (SI): Cauchy stress sigma (Pa) with tension positive; pressure p = -tr(sigma)/3
(compression positive); plane strain in the tub's x-z plane, so a stress is the four components
(xx, zz, xz, yy): the out-of-plane normal stress yy is kept (D_yy = 0 but sigma_yy != 0).
Deviatoric stress s = sigma + p I, equivalent shear stress tau = sqrt(s:s / 2), equivalent plastic
shear rate gamma_dot_p = sqrt(2 D^p:D^p) (1/s), inertial number I = gamma_dot_p d / sqrt(p / rho_s).

The model (Dunatunga & Kamrin 2015, J. Fluid Mech. 779, 483-513, "Continuum modelling and
simulation of granular flows through their many phases", section 2):

1. Disconnected state: where the density is below the critical density rho_c = rho_s phi_c the
   grains are not in contact and the stress is zero (their eq. 2.9); so is any state whose trial
   pressure is tensile (the media carries no tension).
2. Elastic predictor: sigma_trial = sigma + dt (K tr(D) I + 2 G D' + W sigma - sigma W), a
   hypoelastic (Jaumann) form of their elastic law with bulk modulus K and shear modulus G; D, W
   the symmetric and skew parts of the velocity gradient L.  (Dunatunga & Kamrin use a Hencky
   hyperelastic law; at the elastic strains of the tub, < 1 %, the two agree to O(strain^2).)
3. Yield: tau_trial <= mu_s p (pressure-sensitive, their eq. 2.6): the trial stress stands.
4. Flow (mu(I), GDR MiDi 2004; Jop, Forterre & Pouliquen 2006): otherwise the deviator is returned
   radially, isochorically (p unchanged) to tau = mu(I) p with
   mu(I) = mu_s + (mu_2 - mu_s) / (1 + I_0 / I) and tau = tau_trial - G dt gamma_dot_p.  With
   xi = I_0 sqrt(p / rho_s) / d this is the quadratic (their eq. 3.7)
       G dt gp^2 - B gp - C = 0,  B = tau_tr - mu_2 p - G dt xi,  C = (tau_tr - mu_s p) xi,
   whose positive root is taken (in the cancellation-free form).

Option: Drucker-Prager with viscosity (what a commercial finite element code would use):
tau <= mu_dp p with mu_dp = tan(beta) / sqrt(3) and the plane-strain match (models.md)
tan(beta) = 3 sqrt(3) tan(phi_f) / sqrt(9 + 12 tan^2 phi_f), phi_f = atan(mu_s); above yield a
Bingham-like flow tau = mu_dp p + eta gamma_dot_p, i.e. gp = (tau_tr - mu_dp p) / (G dt + eta).

Option: dilatancy (peak friction; `dilatancy` = K_dil > 0, mu(I) model only).  Pailha &
Pouliquen (2009, J. Fluid Mech. 633, 115-135, eqs. 2.4-2.6), after Roux & Radjai (1998) and
Rowe's stress-dilatancy: the friction of a bed depends on how far its solid fraction phi is from
the steady one phi_eq(I) of the phi(I) law,
    mu = mu(I) + tan(psi),  tan(psi) = K_dil (phi - phi_eq(I)),  phi_eq(I) = phi_c - a I,
with a = phi_max - phi_min (the calibrated phi(I) slope) and psi the dilatancy angle; and the
plastic flow carries the matching volume change (non-associated: the yield surface's slope in
p is mu, the flow's is tan psi), tr D^p = tan(psi) gamma_dot_p, so that a dense bed sheared
under a free surface dilates towards phi_eq(I) (d phi / dt = -phi tan(psi) gamma_dot_p) and
relaxes to mu(I), and a confined one builds pressure (Reynolds dilatancy).  phi is the point's
own density (det F in the MPM, the transported density in the Eulerian solver) over rho_s,
less its elastic compression: phi = rho exp(-p / K) / rho_s, the packing of the unloaded
skeleton that the disconnection threshold rho_c also refers to (the DEM measures phi_c and
phi(I) at the bed's pressure, where its stiff contacts compress the packing by ~1e-4 only).
In the return map (Dunatunga & Kamrin's quadratic with the pressure held at the trial one, the
dilation's pressure change applied after it, first order in dt):
    mu_y = mu_s + K_dil dphi  (dphi = phi - phi_c; the static yield),
    tau = mu_y p + (mu_2 - mu_s) p gp / (gp + xi) + K_dil a I p   (I = I_0 gp / xi),
the last term linear in gp (a viscosity K_dil a I_0 p / xi); so the quadratic keeps its form
with mu_s -> mu_y, mu_2 -> mu_2 + K_dil dphi and S -> S + K_dil a I_0 p / xi in B and in
gp^2's coefficient, while tau_new = tau_tr - G dt gp.  Then p_new = p + K ln(phi / phi_1) (the
plastic dilation is isotropic, so it changes only the pressure), phi_1 the packing after the
step's plastic shear gp dt by the exact solution of d phi / d gamma = -K_dil phi (phi - phi_eq)
(to first order K dt tan(psi) gp; the exact form cannot overshoot phi_eq).  K_dil = 0 is the
plain law, bit for bit.

Option: compaction under cyclic loading (`compaction_strain` = gamma_c > 0; any model).  Under
the tub's vibration a connected granular bed shakes down towards a packing denser than its
steady-shear one: soil mechanics' cyclic densification (Youd 1972; Sawicki & Swidzinski 1989,
"Mechanics of a sandy subsoil subjected to cyclic loadings", Int. J. Numer. Anal. Meth.
Geomech. 13, 273-285: the compaction per cycle proportional to the distance from the cyclic
limit packing; Bauer 1996; for tapped beads Knight et al. 1995).  D&K's law has no such
mechanism (every landing reconnects at rho_c with zero stress and stays at phi_c), so its bed
is never dense and the dilatancy option's peak friction K_dil (phi - phi_eq) never engages.
Here, in the rate form of Sawicki & Swidzinski's law with the cycle count replaced by the
accumulated shear strain (a cycle of amplitude gamma_0 is 4 gamma_0 of it):
    d phi / d gamma = (phi_cyc - phi) / gamma_c   for phi < phi_cyc,  phi_cyc = phi_c + dphi_cyc,
gamma the equivalent total shear strain (rate sqrt(2 D':D') from the velocity gradient,
elastic and plastic: the cyclic cell compacts below yield too), phi = rho exp(-p / K) / rho_s the
unloaded packing as in the dilatancy option.  The densification is plastic and isotropic: over a
step phi goes to phi_1 = phi_cyc - (phi_cyc - phi) exp(-gamma_dot dt / gamma_c) (exact) and the
pressure drops by K ln(phi_1 / phi) (the skeleton is denser, so the same density carries less
elastic compression; the loading then squeezes the point to a higher density), the deviator
scaled with it (the stress ratio kept, so the yield condition still holds); the drop stops at
p = 0 (a stress-free packing does not compact).  Only connected points (state 1 or 2), after
the return map.  dphi_cyc and gamma_c are measured in the cyclic shear cell at the tub's strain
amplitude (vibroflow.calibration.compaction; calibration.toml [compaction]); dphi_cyc is the
cyclic packing's excess over the same balls' steady-shear packing phi_ss (the dilatancy cell),
both referred to I = 0, so that the continuum's phi_c (the tub cells' phi(I -> 0)) carries it.
gamma_c = 0 (default) is the law without compaction, bit for bit.

Option: the unloading law (`bulk_law`, K_ref > 0; any model).  The bulk part of the elastic
predictor takes the tangent of the bed's measured unloading branch, K_t = K_ref (p / p_ref)^n
with p the point's pressure at the step's start, clamped to [p_min, p_max], the range the law is
measured over (vibroflow.calibration.unloading, models.md 4.3): a pressure-dependent bulk
modulus as in the swelling line of critical-state soil mechanics (K = v p / kappa, Schofield &
Wroth 1968: n = 1) or Hertzian contacts (n = 1/3, Goddard 1990).  The shear part keeps G; the
options that read K (dilatancy, compaction, the unloaded packing) keep bulk_modulus, the law's
largest tangent.  K_ref = 0 (default) is the linear law, bit for bit.

The mu(I) law is ill-posed at very small and very large I (Barker et al. 2015); nothing here
regularises it, so results must be checked for grid convergence.
"""
from __future__ import annotations

import numba as nb
import numpy as np

from .constitutive import (DRUCKER_PRAGER, P_D, P_DPHI_CYC, P_ETA, P_ETA_BED, P_G, P_GAMMA_C,
                           P_I0, P_K, P_KDIL, P_KLAW_N, P_KLAW_P_MAX, P_KLAW_P_MIN,
                           P_KLAW_P_REF, P_KLAW_REF, P_MODEL, P_MU_2, P_MU_DP, P_MU_S,
                           P_PHI_SLOPE, P_RHO_C, P_RHO_S)


@nb.njit(cache=True, inline="always")
def elastic_predictor(sxx, szz, sxz, syy, lxx, lxz, lzx, lzz, lyy, dt, K, G):
    """Trial stress (Pa) after dt (s) of elastic deformation at velocity gradient L (1/s),
    L_ab = d v_a / d x_b, Jaumann-rotated (see the module docstring).  lyy = D_yy (1/s): 0 in
    plane strain; the hoop rate v_r / r in an axisymmetric section (x = r, y = theta; the
    rotation W has no theta part there either, so the hoop stress is not rotated)."""
    dxx = lxx
    dzz = lzz
    dxz = 0.5 * (lxz + lzx)
    w = 0.5 * (lxz - lzx)  # W_xz
    tr = dxx + dzz + lyy
    lam = K - 2.0 * G / 3.0
    nxx = sxx + dt * (lam * tr + 2.0 * G * dxx + 2.0 * w * sxz)
    nzz = szz + dt * (lam * tr + 2.0 * G * dzz - 2.0 * w * sxz)
    nxz = sxz + dt * (2.0 * G * dxz + w * (szz - sxx))
    nyy = syy + dt * (lam * tr + 2.0 * G * lyy)
    return nxx, nzz, nxz, nyy


@nb.njit(cache=True, inline="always")
def bulk_tangent(p, params):
    """K_t = K_ref (p / p_ref)^n (Pa) of the unloading law at pressure p (Pa) clamped to
    [p_min, p_max] (module docstring, "Option: the unloading law")."""
    lo = params[P_KLAW_P_MIN]
    hi = params[P_KLAW_P_MAX]
    pc = lo if p < lo else (hi if p > hi else p)
    return params[P_KLAW_REF] * (pc / params[P_KLAW_P_REF]) ** params[P_KLAW_N]


@nb.njit(cache=True, inline="always")
def return_map(sxx, szz, sxz, syy, density, dt, params, rate):
    """Plastic correction of a trial stress (Pa) of a point of density `density` (kg/m^3) over a
    step dt (s); params = `ContinuumMaterial.as_array()`; rate the ratio r (-) of the inertial
    number read from the granular temperature (mu(r I), kinetic_stress.py; 1: the plain mu(I)
    law, 0: mu_s at any rate; the mu(I) model without dilatancy only).

    Returns (sxx, szz, sxz, syy, gamma_dot_p, state) with gamma_dot_p the equivalent plastic
    shear rate (1/s) and state 0 = disconnected (stress-free), 1 = elastic, 2 = flowing.
    Dunatunga & Kamrin (2015) eqs. 2.6-2.9 and 3.7 (module docstring).
    """
    if density < params[P_RHO_C]:
        return 0.0, 0.0, 0.0, 0.0, 0.0, 0
    p = -(sxx + szz + syy) / 3.0
    if p <= 0.0:
        return 0.0, 0.0, 0.0, 0.0, 0.0, 0
    dxx = sxx + p
    dzz = szz + p
    dyy = syy + p
    tau = np.sqrt(0.5 * (dxx * dxx + dzz * dzz + dyy * dyy + 2.0 * sxz * sxz))
    S = params[P_G] * dt
    if params[P_MODEL] == DRUCKER_PRAGER:
        excess = tau - params[P_MU_DP] * p
        if excess <= 0.0:
            return sxx, szz, sxz, syy, 0.0, 1
        gp = excess / (S + params[P_ETA])
    elif params[P_KDIL] > 0.0:
        return _dilatant_return(dxx, dzz, sxz, dyy, p, tau, density, dt, params)
    else:
        mu_s = params[P_MU_S]
        excess = tau - mu_s * p
        if excess <= 0.0:
            return sxx, szz, sxz, syy, 0.0, 1
        xi = params[P_I0] * np.sqrt(p / params[P_RHO_S]) / params[P_D]
        if rate == 1.0:
            gp = _mu_i_flow_rate(tau, excess, params[P_MU_2] * p, S, xi)
        elif rate > 0.0:
            # mu(r I) = mu_s + (mu_2 - mu_s) gp / (gp + xi / r)
            gp = _mu_i_flow_rate(tau, excess, params[P_MU_2] * p, S, xi / rate)
        else:
            # r = 0: mu = mu_s at any rate, tau_tr - S gp = mu_s p
            gp = excess / S
    tau_new = tau - S * gp
    if tau_new < 0.0:
        tau_new = 0.0
    f = tau_new / tau
    return (f * dxx - p, f * dzz - p, f * sxz, f * dyy - p, gp, 2)


@nb.njit(cache=True, inline="always")
def _mu_i_flow_rate(tau, excess, mu_2p, S, xi):
    """The plastic shear rate gp (1/s) of Dunatunga & Kamrin's mu(I) return map: the positive
    root of S gp^2 - B gp - excess xi = 0 with B = tau - mu_2p - S xi, i.e. of
    tau - S gp = mu_y p + (mu_2 - mu_y) p gp / (gp + xi) (excess = tau - mu_y p > 0; mu_2p the
    term mu_2 p, Pa; S = G dt (+ the dilatancy's viscosity), Pa s; xi = I_0 sqrt(p/rho_s) / d,
    1/s).  The root is taken in the form that does not cancel for either sign of B."""
    B = tau - mu_2p - S * xi
    C = excess * xi
    disc = np.sqrt(B * B + 4.0 * S * C)
    if B > 0.0:
        return (B + disc) / (2.0 * S)
    return 2.0 * C / (disc - B) if disc - B > 0.0 else 0.0


@nb.njit(cache=True, inline="always")
def unloaded_packing(density, p, K, rho_s):
    """phi = rho exp(-p / K) / rho_s (-): the solid fraction of a point of density rho (kg/m^3)
    with its elastic compression under pressure p (Pa, bulk modulus K) removed, the packing the
    disconnection threshold rho_c, the dilatancy and the compaction options refer to."""
    return density * np.exp(-p / K) / rho_s


@nb.njit(cache=True)
def equivalent_shear_rate(lxx, lxz, lzx, lzz):
    """gamma_dot = sqrt(2 D':D') (1/s) of the velocity gradient [[lxx, lxz], [lzx, lzz]] (1/s),
    plane strain (D_yy = 0) (models.md); scalars or arrays alike."""
    third = (lxx + lzz) / 3.0
    exx = lxx - third
    ezz = lzz - third
    exz = 0.5 * (lxz + lzx)
    return np.sqrt(2.0 * (exx * exx + ezz * ezz + third * third + 2.0 * exz * exz))


@nb.njit(cache=True, inline="always")
def _dilatant_return(dxx, dzz, sxz, dyy, p, tau, density, dt, params):
    """The mu(I) return map with dilatancy (module docstring, "Option: dilatancy"), from the
    trial deviator (dxx, dzz, sxz, dyy) (Pa), pressure p > 0 (Pa) and tau (Pa) of a connected
    point of density `density` (kg/m^3).  Same returns as `return_map`."""
    K = params[P_K]
    S = params[P_G] * dt
    kd = params[P_KDIL]
    # packing of the unloaded skeleton over the critical one (the elastic compression removed)
    phi0 = unloaded_packing(density, p, K, params[P_RHO_S])
    dphi = phi0 - params[P_RHO_C] / params[P_RHO_S]
    mu_y = params[P_MU_S] + kd * dphi
    if mu_y < 0.0:
        mu_y = 0.0
    excess = tau - mu_y * p
    if excess <= 0.0:
        return dxx - p, dzz - p, sxz, dyy - p, 0.0, 1
    xi = params[P_I0] * np.sqrt(p / params[P_RHO_S]) / params[P_D]
    # K_dil a I p = (K_dil a I_0 p / xi) gp: a viscosity added to G dt in the quadratic
    S2 = S + kd * params[P_PHI_SLOPE] * params[P_I0] * p / xi
    gp = _mu_i_flow_rate(tau, excess, (params[P_MU_2] + kd * dphi) * p, S2, xi)
    tau_new = tau - S * gp
    if tau_new < 0.0:
        tau_new = 0.0
    f = tau_new / tau
    # the plastic dilation tr D^p = tan(psi) gp, isotropic: only the pressure changes.  Over
    # the step's plastic shear dg = gp dt the packing relaxes by d phi / d g = -K_dil phi
    # (phi - phi_eq) towards phi_eq, a logistic equation solved exactly (an explicit
    # tan(psi) gp dt overshoots phi_eq once K_dil phi dg > 1, which the Eulerian solver's
    # thin surface cells reach at once); I in phi_eq is capped at 1, where the phi(I) fit
    # reaches phi_min (the dense-flow law says nothing beyond)
    I = params[P_I0] * gp / xi
    if I > 1.0:
        I = 1.0
    phi_eq = params[P_RHO_C] / params[P_RHO_S] - params[P_PHI_SLOPE] * I
    phi1 = phi_eq / (1.0 - (1.0 - phi_eq / phi0) * np.exp(-kd * phi_eq * gp * dt))
    p_new = p + K * np.log(phi0 / phi1)
    if p_new < 0.0:
        p_new = 0.0
    return f * dxx - p_new, f * dzz - p_new, f * sxz, f * dyy - p_new, gp, 2


@nb.njit(cache=True, inline="always")
def compact(sxx, szz, sxz, syy, density, gamma_dot, dt, params):
    """Cyclic compaction (module docstring, "Option: compaction") of the stress (Pa) of a
    connected point of density `density` (kg/m^3) sheared at the total equivalent shear rate
    gamma_dot (1/s) over dt (s): the unloaded packing relaxes towards phi_cyc by
    d phi / d gamma = (phi_cyc - phi) / gamma_c (exact over the step), the pressure dropping by
    K ln(phi_1 / phi), not below 0, the deviator scaled with it.  Returns the stress."""
    p = -(sxx + szz + syy) / 3.0
    if p <= 0.0 or gamma_dot <= 0.0:
        return sxx, szz, sxz, syy
    K = params[P_K]
    rho_s = params[P_RHO_S]
    phi0 = unloaded_packing(density, p, K, rho_s)
    phi_cyc = params[P_RHO_C] / rho_s + params[P_DPHI_CYC]
    if phi0 >= phi_cyc:
        return sxx, szz, sxz, syy
    phi1 = phi_cyc - (phi_cyc - phi0) * np.exp(-gamma_dot * dt / params[P_GAMMA_C])
    p_new = p - K * np.log(phi1 / phi0)
    if p_new < 0.0:
        p_new = 0.0
    f = p_new / p
    return (f * (sxx + p) - p_new, f * (szz + p) - p_new, f * sxz, f * (syy + p) - p_new)


@nb.njit(cache=True)
def update_stress_points(stress, L, density, dt, params, gamma_dot, state):
    """`update_stress_points_rated` with the plain mu(I) law (no rate ratio)."""
    update_stress_points_rated(stress, L, density, dt, params, gamma_dot, state,
                               np.empty(0))


@nb.njit(cache=True)
def update_stress_points_rated(stress, L, density, dt, params, gamma_dot, state, rate_ratio):
    """Elastic predictor and return map for every point (and the cyclic compaction where its
    option is on, `compact`); rate_ratio (N,) the ratio r of each point's inertial number read
    from the granular temperature (return_map, kinetic_stress.py), or (0,): none (r = 1).

    stress (N, 4) [xx, zz, xz, yy] (Pa, updated in place); L (N, 4) [xx, xz, zx, zz] velocity
    gradient (1/s), or (N, 5) with the out-of-plane rate D_yy (the hoop rate v_r / r of an
    axisymmetric run, vibroflow.continuum.mpm.MPMSystem.axisymmetric) last; density (N,)
    (kg/m^3, at the end of the step); gamma_dot (N,) plastic shear rate out (1/s); state (N,)
    int8 out (0 disconnected, 1 elastic, 2 flowing).
    """
    K = params[P_K]
    G = params[P_G]
    compaction = params[P_GAMMA_C] > 0.0
    law = params[P_KLAW_REF] > 0.0
    hoop = L.shape[1] > 4
    rated = rate_ratio.shape[0] > 0
    for p in range(stress.shape[0]):
        lyy = L[p, 4] if hoop else 0.0
        Kp = K
        if law:
            Kp = bulk_tangent(-(stress[p, 0] + stress[p, 1] + stress[p, 3]) / 3.0, params)
        txx, tzz, txz, tyy = elastic_predictor(stress[p, 0], stress[p, 1], stress[p, 2],
                                               stress[p, 3], L[p, 0], L[p, 1], L[p, 2], L[p, 3],
                                               lyy, dt, Kp, G)
        sxx, szz, sxz, syy, gp, st = return_map(txx, tzz, txz, tyy, density[p], dt, params,
                                                rate_ratio[p] if rated else 1.0)
        if compaction and st != 0:
            gd = equivalent_shear_rate(L[p, 0], L[p, 1], L[p, 2], L[p, 3])
            sxx, szz, sxz, syy = compact(sxx, szz, sxz, syy, density[p], gd, dt, params)
        stress[p, 0] = sxx
        stress[p, 1] = szz
        stress[p, 2] = sxz
        stress[p, 3] = syy
        gamma_dot[p] = gp
        state[p] = st


@nb.njit(cache=True)
def damped_stress(stress, L, phase, params, out):
    """out = the stress the grid sees: the stored (elastic-plastic) stress plus the bed's
    Kelvin-Voigt viscous stress on connected material,

        sigma_v = eta_b tr(D) I + 2 eta_b (D - tr(D) I / 3),

    eta_b = params[P_ETA_BED] (Pa s; the same coefficient for the volumetric and the deviatoric
    rate), D the symmetric part of the velocity gradient L (N, 4) [xx, xz, zx, zz] (1/s) of the
    last step, with the out-of-plane rate L[:, 4] of an axisymmetric section (N, 5; 0 in plane
    strain).  stress, out (N, 4) [xx, zz, xz, yy] Pa; phase (N,) int8: disconnected material
    (phase 0, below the critical density) carries none, as it carries no elastic stress.

    Why.  The DEM's bed loses the energy of its compression waves in its contacts' dashpots
    (restitution 0.85 between balls) within a cycle, and flies nearly as a body; the
    elasto-plastic continuum has nothing to damp those waves below yield but its transfers,
    and rings through its depth (without it a vibrated strip stretches three times as far as
    the DEM's: benchmarks/strip_damping.py, docs/validation.md).  A Kelvin-Voigt viscosity is
    the continuum's dashpot: it is not stored in the stress (the elastic predictor and the
    return map see the elastic-plastic stress only), it adds eta_b (7/3) of damping to the
    P-wave and eta_b to the shear wave, which decay as exp(-eta k^2 t / (2 rho))
    (tests/test_rheology.py), and it does nothing to a body moving rigidly (D = 0).  Its value is
    fitted on a DEM of the same strip (benchmarks/strip_damping.py)."""
    eta = params[P_ETA_BED]
    hoop = L.shape[1] > 4
    for p in range(stress.shape[0]):
        if phase[p] == 0:
            for c in range(4):
                out[p, c] = stress[p, c]
            continue
        dxx = L[p, 0]
        dzz = L[p, 3]
        dxz = 0.5 * (L[p, 1] + L[p, 2])
        dyy = L[p, 4] if hoop else 0.0
        tr = dxx + dzz + dyy
        iso = eta * tr - 2.0 * eta * tr / 3.0
        out[p, 0] = stress[p, 0] + iso + 2.0 * eta * dxx
        out[p, 1] = stress[p, 1] + iso + 2.0 * eta * dzz
        out[p, 2] = stress[p, 2] + 2.0 * eta * dxz
        out[p, 3] = stress[p, 3] + iso + 2.0 * eta * dyy
