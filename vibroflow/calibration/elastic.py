"""Elastic moduli of the packed media from DEM strain steps in a periodic box: the bulk
modulus K = dp / d eps_v and the shear modulus G = d tau / d gamma of a packing at rest under
the pressure p, for the elastic predictor of an elasto-viscoplastic continuum (Dunatunga &
Kamrin 2015).

Protocol (reusing the Lees-Edwards box of vibroflow.dem.periodic_box):

1. a random fill compressed isotropically to p (shear_cell.packed_box, no damping), brought to
   rest at p under the isotropic box control and a light background viscous damping, then
   relaxed with the box fixed under the full damping -c m v, -c I w (c about the lowest
   acoustic frequency of the box, 2 pi c_s / L, so that its slowest modes are near critically
   damped) until the stress no longer changes: the reference state (redone if the pressure
   moved by more than 2% at fixed box);
2. isotropic compression: from the reference state, an affine strain ramp of all three axes
   (over 100 steps, so that the tangential springs register it: the dilation rate enters the
   contacts' relative velocity) by -eps (compression) and, from the reference state again, by
   +eps (extension); each followed by relaxation at fixed box to rest.  K = dp / d eps_v with
   eps_v = -ln(V / V_0);
3. simple shear: from the reference state, a Lees-Edwards shear ramp to the strain +gamma and,
   separately, -gamma, each relaxed; G = d tau / d gamma, tau = -(sigma_xz + sigma_zx) / 2
   (compression-positive stress).

The two signs give the value (their mean, which cancels the quadratic part of the response) and
the uncertainty (half their difference: the stiffness differs between loading and unloading
where contacts open or slide), combined with the residual drift of the relaxed stress.  The
step sizes are set so that the affine stress change is `stress_step` times p (2% by default):
small enough to stay near linear, large beside the residual stress fluctuation.

Affine reference (Walton 1987; affine_moduli_linear below): for linear springs
K_aff = phi Z k_n / (3 pi d), G_aff = phi Z (2 k_n + 3 k_t) / (10 pi d) with Z = 2 C / N.
"""
from __future__ import annotations

import math
import time

import numpy as np

from vibroflow.dem.laws import P_KT, P_MODEL, MODEL_LINEAR
from vibroflow.dem.periodic_box import PeriodicBox
from vibroflow.dem.periodic_step import MODE_FIXED, Q_SXX, Q_SXZ, Q_SYY, Q_SZX, Q_SZZ, S_STRAIN

from .shear_cell import (BallSetup, _check, ball_setup, compress, packed_box,
                         tub_mid_depth_pressure)

DEFAULT_N_BALLS = 400
RAMP_STEPS = 100
STRESS_STEP = 0.02
# packing estimates used only to size the damping and the strain steps before measuring
_PHI_GUESS, _Z_GUESS = 0.62, 4.5


def affine_moduli_linear(phi: float, z: float, k_n: float, k_t: float, d: float):
    """K_aff = phi Z k_n / (3 pi d), G_aff = phi Z (2 k_n + 3 k_t) / (10 pi d) (Pa)."""
    return (phi * z * k_n / (3.0 * math.pi * d),
            phi * z * (2.0 * k_n + 3.0 * k_t) / (10.0 * math.pi * d))


def _tangential_stiffness(setup: BallSetup, pressure: float) -> float:
    """k_t of the contact law (N/m): ratio x k_n (linear), 8 G* sqrt(R_eff delta) (Hertz, at the
    overlap of the force p d^2)."""
    if setup.par[P_MODEL] == MODEL_LINEAR:
        return float(setup.par[P_KT]) * setup.k_eff
    # Hertz: k_eff = 1.5 k_h sqrt(R) sqrt(delta)  ->  sqrt(delta) from k_eff and the force
    r_eff = 0.25 * setup.diameter
    delta = (pressure * setup.diameter**2 * 1.5 / setup.k_eff)
    return float(setup.par[P_KT]) * math.sqrt(r_eff * delta)


def _relax(box: PeriodicBox, damping: float, chunk: int, tol: float, max_chunks: int):
    """Run fixed-box chunks under damping until the chunk-mean stress changes by less than tol
    (Pa) in every component; returns (mean stress of the last chunk (9: xx yy zz xz zx) as a
    dict, its change from the chunk before (Pa), converged)."""
    prev = None
    change = math.inf
    for _ in range(max_chunks):
        s = box.run(chunk, MODE_FIXED, damping=damping, sample_every=max(chunk // 5, 1))
        m = s[:, [Q_SXX, Q_SYY, Q_SZZ, Q_SXZ, Q_SZX]].mean(axis=0)
        if prev is not None:
            change = float(np.abs(m - prev).max())
            if change < tol:
                return m, change, True
        prev = m
    return prev, change, False


def _pressure(m) -> float:
    return float(m[0] + m[1] + m[2]) / 3.0


def _tau(m) -> float:
    return -0.5 * float(m[3] + m[4])


def elastic_moduli(scenario, pressure: float | None = None, n_balls: int = DEFAULT_N_BALLS,
                   seed: int | None = None, stress_step: float = STRESS_STEP,
                   progress=None) -> dict:
    """Bulk and shear moduli of the scenario's balls packed at `pressure` (see module notes).

    pressure: Pa (None: the tub bed's mid-depth pressure); n_balls >= 100; seed of the fill
    (None: scenario.run.seed); stress_step: affine stress change of each strain step / p.

    Returns a dict: bulk_modulus, shear_modulus (Pa) with *_stderr, the moduli of each sign
    (bulk_modulus_compression/_extension, shear_modulus_positive/_negative), pressure (Pa,
    measured in the reference state), solid_fraction, coordination_number (Z = 2C/N, all
    balls), coordination_number_non_rattler (balls with >= 2 contacts), affine_bulk_modulus,
    affine_shear_modulus (Pa, linear law: Walton's formulas with the measured phi and Z),
    volumetric_strain, shear_strain, damping_1_s, converged, n_balls, seed, wall_time_s.
    """
    if pressure is None:
        pressure = tub_mid_depth_pressure(scenario)
    _check("pressure", pressure, 1e-12)
    pressure = float(pressure)
    _check("n_balls", n_balls, 100, integer=True)
    _check("stress_step", stress_step, 1e-6, 0.5)
    seed = scenario.run.seed if seed is None else seed
    _check("seed", seed, 0, integer=True)
    seed = int(seed)
    log = getattr(progress, "log", None)
    t0 = time.perf_counter()

    # damping and rest criterion sized from a guess of the packing (the measurement does not
    # depend on them, only how fast it gets there)
    setup = ball_setup(scenario, pressure)
    d = setup.diameter
    k_n = setup.k_eff
    k_t = _tangential_stiffness(setup, pressure)
    k_guess, g_guess = affine_moduli_linear(_PHI_GUESS, _Z_GUESS, k_n, k_t, d)
    side = (int(n_balls) * math.pi * d**3 / 6.0 / _PHI_GUESS) ** (1.0 / 3.0)
    c_s = math.sqrt((k_guess + 4.0 / 3.0 * g_guess) / (_PHI_GUESS * setup.density))
    damping = 2.0 * math.pi * c_s / side
    f0 = pressure * d * d
    rest_ke = 1e-4 * f0 * f0 / k_n  # J per ball: 1e-4 of a contact's elastic energy
    # compress without damping (a viscous background would freeze a loose, fragile structure
    # in place), then bring to rest at p under light damping with the isotropic control still
    # on, then relax at fixed box under the full damping; repeated while the relaxation at
    # fixed box moves the pressure by more than 2%
    box, setup = packed_box(scenario, pressure, int(n_balls), seed)
    chunk = max(int(round(10.0 / (damping * setup.dt))), 200)
    tol = 1e-3 * stress_step * pressure
    for _ in range(4):
        compress(box, setup, pressure, damping=0.1 * damping, tolerance=0.005, rest_ke=rest_ke)
        ref, ref_drift, ok0 = _relax(box, damping, chunk, tol, 60)
        if abs(_pressure(ref) - pressure) <= 0.02 * pressure:
            break
    p0 = _pressure(ref)
    nc, _ = box.evaluate()
    z_all = 2.0 * nc / box.n
    deg = box.degree
    keep = deg >= 2
    z_nr = float(deg[keep].sum() / max(keep.sum(), 1))
    phi = box.solid_fraction
    K_aff, G_aff = affine_moduli_linear(phi, z_all, k_n, k_t, d)
    if log:
        log(f"elastic: packing at p = {p0:.4g} Pa, phi = {phi:.4f}, Z = {z_all:.3f}")

    eps = stress_step * pressure / (3.0 * K_aff)      # per axis
    gamma = stress_step * pressure / G_aff
    conv = [ok0]
    K = {}
    for sign, name in ((1.0, "compression"), (-1.0, "extension")):
        b = box.copy()
        v0 = b.volume
        rate = sign * eps / (RAMP_STEPS * setup.dt)
        b.run(RAMP_STEPS, MODE_FIXED, dilation=(-rate, -rate, -rate), damping=damping,
              sample_every=RAMP_STEPS)
        m, drift, ok = _relax(b, damping, chunk, tol, 60)
        conv.append(ok)
        eps_v = -math.log(b.volume / v0)
        K[name] = ((_pressure(m) - p0) / eps_v, max(drift, ref_drift) / abs(eps_v))
    G = {}
    for sign, name in ((1.0, "positive"), (-1.0, "negative")):
        b = box.copy()
        b.set_shear_rate(sign * gamma / (RAMP_STEPS * setup.dt))
        b.run(RAMP_STEPS, MODE_FIXED, damping=damping, sample_every=RAMP_STEPS)
        g_done = b.state[S_STRAIN] - box.state[S_STRAIN]  # shear strain since the reference
        b.set_shear_rate(0.0)
        m, drift, ok = _relax(b, damping, chunk, tol, 60)
        conv.append(ok)
        G[name] = ((_tau(m) - _tau(ref)) / g_done, max(drift, ref_drift) / abs(g_done))

    def combine(a, b):
        (va, na), (vb, nb) = a, b
        return 0.5 * (va + vb), math.sqrt((0.5 * (va - vb)) ** 2 + na * na + nb * nb)

    k_val, k_se = combine(K["compression"], K["extension"])
    g_val, g_se = combine(G["positive"], G["negative"])
    if not all(conv):
        if log:
            log("elastic: a relaxation did not converge to the tolerance; the drift is in the "
                "standard errors")
    return {
        "bulk_modulus": k_val, "bulk_modulus_stderr": k_se,
        "shear_modulus": g_val, "shear_modulus_stderr": g_se,
        "bulk_modulus_compression": K["compression"][0],
        "bulk_modulus_extension": K["extension"][0],
        "shear_modulus_positive": G["positive"][0], "shear_modulus_negative": G["negative"][0],
        "pressure": p0, "pressure_target": pressure, "solid_fraction": phi,
        "coordination_number": z_all, "coordination_number_non_rattler": z_nr,
        "affine_bulk_modulus": K_aff, "affine_shear_modulus": G_aff,
        "volumetric_strain": 3.0 * eps, "shear_strain": gamma, "damping_1_s": damping,
        "converged": bool(all(conv)), "n_balls": int(box.n), "seed": seed,
        "wall_time_s": time.perf_counter() - t0,
    }
