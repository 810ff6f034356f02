"""Dilatancy of the packed media from DEM: the constant K_dil of the peak-friction law
mu = mu(I) + K_dil (phi - phi_eq(I)) (the continuum's dilatancy option, constitutive.py).

Why.  The steady-state mu(I), phi(I) rheology is the friction of a bed at its critical state.
A bed denser than its steady solid fraction phi_eq(I) resists more: it has to dilate before it
can shear, and the work against the pressure shows up as extra friction.  Pailha & Pouliquen
(2009, J. Fluid Mech. 633, 115-135, eqs. 2.4-2.6; after Roux & Radjai 1998 and Rowe's
stress-dilatancy) write it

    mu = mu(I) + tan(psi),   tan(psi) = K_dil (phi - phi_eq(I)),   d phi / d gamma = -phi tan psi,

with psi the dilatancy angle.  K_dil is a property of the media; Pailha & Pouliquen measured 4.09
for glass beads in a viscous fluid.  Here it is measured on the scenario's own balls, never on
the tub's flow.

The test (the Lees-Edwards box of vibroflow.dem.periodic_box, the shear cell's polydisperse
balls): a dense packing, made as dense random packings are made in simulation (compressed
isotropically to the pressure p with the friction switched off, then switched on: Silbert,
Ertas, Grest, Halsey & Levine 2002; frictional compression alone leaves a packing looser than
its steady shear state, which then compacts instead of dilating), is sheared at constant
inertial number I with sigma_zz held at p by the barostat, over `strain` units.
Every `segment_strain` the mean stress ratio mu = tau / sigma_zz and solid fraction phi are
recorded.  The stress ratio climbs to a peak while the packing dilates, then softens to its
steady value; the last `steady_fraction` of the strain gives the steady mu_ss = mu(I) and
phi_ss = phi_eq(I) of this box.  From the peak on, Pailha & Pouliquen's law says
mu - mu_ss = K_dil (phi - phi_ss): K_dil is the least-squares slope through the origin of
(phi - phi_ss, mu - mu_ss) over the post-peak segments, its standard error from the residuals
(segments correlate over a few hundredths of strain, so the error is scaled by the square root
of the number of segments per correlation strain, `CORRELATION_STRAIN`).  Independent packings
(`seeds`) give independent slopes; their mean and standard error are reported.
"""
from __future__ import annotations

import math
import time

import numpy as np

from vibroflow.dem.laws import P_MU
from vibroflow.dem.periodic_box import PeriodicBox, random_fill
from vibroflow.dem.periodic_step import MODE_Z, Q_LX, Q_LY, Q_LZ, Q_SXZ, Q_SZX, Q_SZZ
from vibroflow.errors import InputError

from .shear_cell import (DEFAULT_POLYDISPERSITY, FILL_SOLID_FRACTION, _check, ball_setup,
                         compress, tub_mid_depth_pressure)

DEFAULT_INERTIAL_NUMBER = 0.02
DEFAULT_N_BALLS = 300
DEFAULT_STRAIN = 1.5
DEFAULT_SEGMENT_STRAIN = 0.01
DEFAULT_STEADY_FRACTION = 0.4
DEFAULT_SEEDS = (1, 2, 3, 4)
#: shear strain over which the stress-ratio fluctuations of a 300-ball box stay correlated
CORRELATION_STRAIN = 0.05


def fit_dilatancy(strain, mu, phi, steady_fraction: float = DEFAULT_STEADY_FRACTION,
                  segment_strain: float | None = None) -> dict:
    """K_dil (-) from one shear transient: strain (-), stress ratio mu (-) and solid fraction phi
    (-) per segment (module notes).  Returns K_dil, K_dil_stderr, mu_ss, phi_ss, mu_peak,
    phi_start, strain_at_peak, points (post-peak segments used)."""
    g = np.asarray(strain, float)
    m = np.asarray(mu, float)
    f = np.asarray(phi, float)
    if not (g.shape == m.shape == f.shape) or g.size < 10:
        raise InputError(f"fit_dilatancy: {g.size} strains, {m.size} stress ratios, {f.size} "
                         "solid fractions: must be as many, at least 10")
    if not 0.0 < steady_fraction < 1.0:
        raise InputError(f"steady_fraction = {steady_fraction!r}: must be in (0, 1)")
    steady = g >= g[-1] - steady_fraction * (g[-1] - g[0])
    mu_ss, phi_ss = float(m[steady].mean()), float(f[steady].mean())
    k_peak = int(np.argmax(m[~steady])) if (~steady).any() else 0
    use = np.arange(g.size) >= k_peak
    x = f[use] - phi_ss
    y = m[use] - mu_ss
    sxx = float((x * x).sum())
    if not sxx > 0:
        raise InputError("fit_dilatancy: the solid fraction does not change after the peak")
    K = float((x * y).sum() / sxx)
    res = y - K * x
    n = int(use.sum())
    se = math.sqrt(float((res * res).sum()) / max(n - 1, 1) / sxx)
    if segment_strain is not None and segment_strain > 0:
        se *= math.sqrt(max(1.0, CORRELATION_STRAIN / segment_strain))
    return {"K_dil": K, "K_dil_stderr": se, "mu_ss": mu_ss, "phi_ss": phi_ss,
            "mu_peak": float(m[k_peak]), "phi_start": float(f[0]),
            "strain_at_peak": float(g[k_peak]), "points": n}


def dense_box(scenario, pressure: float, n_balls: int, seed: int,
              polydispersity: float = DEFAULT_POLYDISPERSITY):
    """A cubic periodic box of `n_balls` balls (diameters uniform in d (1 +- polydispersity),
    drawn from the seed) filled at random, compressed to the pressure (Pa) without friction,
    and given back its friction (module notes).  Returns (box, setup)."""
    setup = ball_setup(scenario, pressure)
    n = int(n_balls)
    rng = np.random.default_rng(int(seed))
    diam = setup.diameter * (1.0 + polydispersity * (2.0 * rng.random(n) - 1.0))
    side = ((math.pi / 6.0 * diam**3).sum() / FILL_SOLID_FRACTION) ** (1.0 / 3.0)
    radius = 0.5 * diam
    pos = random_fill(n, radius, (side, side, side), rng)
    frictionless = setup.par.copy()
    frictionless[P_MU] = 0.0
    box = PeriodicBox(pos, radius, setup.density * math.pi / 6.0 * diam**3, frictionless,
                      (side, side, side), setup.dt, setup.skin, setup.max_overlap)
    try:
        compress(box, setup, pressure)
    except FloatingPointError as e:
        raise InputError(f"run.dt = {scenario.run.dt!r}: the periodic box blew up while "
                         f"compressing ({e}); use a smaller time step") from None
    box.par[:] = setup.par
    return box, setup


def shear_transient(scenario, pressure: float, inertial_number: float, n_balls: int,
                    seed: int, strain: float, segment_strain: float,
                    polydispersity: float = DEFAULT_POLYDISPERSITY) -> dict:
    """Shear a dense packing (dense_box) at constant I and sigma_zz = p (Pa) over `strain`
    units; returns strain, mu, phi arrays (one value per segment: the segment's mean) and the
    packing's solid fraction before shear, with the box size and the time step used."""
    box, setup = dense_box(scenario, pressure, int(n_balls), int(seed),
                           polydispersity=float(polydispersity))
    phi0 = box.solid_fraction
    solid = float((4.0 / 3.0 * math.pi * box.radius**3).sum())
    gd = inertial_number * math.sqrt(pressure / setup.density) / setup.diameter
    seg_steps = max(1, int(round(segment_strain / (gd * setup.dt))))
    n_seg = int(math.ceil(strain / (gd * setup.dt * seg_steps)))
    gain = setup.gain(setup.barostat_time(pressure, inertial_number))
    box.set_shear_rate(gd)
    every = max(1, seg_steps // 10)
    gam, mus, phis = [], [], []
    for k in range(n_seg):
        try:
            s = box.run(seg_steps, MODE_Z, pressure=pressure, gain=gain, sample_every=every)
        except FloatingPointError as e:
            raise InputError(f"run.dt = {scenario.run.dt!r}: the dilatancy shear cell blew up "
                             f"({e}); use a smaller time step") from None
        tau = -0.5 * (s[:, Q_SXZ] + s[:, Q_SZX])
        gam.append((k + 0.5) * seg_steps * setup.dt * gd)
        mus.append(float(tau.mean() / s[:, Q_SZZ].mean()))
        phis.append(float((solid / (s[:, Q_LX] * s[:, Q_LY] * s[:, Q_LZ])).mean()))
    return {"strain": np.array(gam), "mu": np.array(mus), "phi": np.array(phis),
            "solid_fraction_packed": phi0, "shear_rate_1_s": gd, "dt": setup.dt,
            "n_balls": int(box.n)}


def run_dilatancy(scenario, pressure: float | None = None,
                  inertial_number: float = DEFAULT_INERTIAL_NUMBER,
                  n_balls: int = DEFAULT_N_BALLS, seeds=DEFAULT_SEEDS,
                  strain: float = DEFAULT_STRAIN, segment_strain: float = DEFAULT_SEGMENT_STRAIN,
                  steady_fraction: float = DEFAULT_STEADY_FRACTION, progress=None) -> dict:
    """Measure K_dil on the scenario's balls (module notes): one dense packing per seed, sheared
    at `inertial_number` under `pressure` (Pa; None: the tub bed's mid-depth pressure).

    Returns K_dil (mean over the seeds) and K_dil_stderr (their scatter, or the one fit's error
    with one seed), the per-seed fits (lists), the excess packing of the dense state over the
    steady one (phi_start - phi_ss, mean), and the test's parameters."""
    if pressure is None:
        pressure = tub_mid_depth_pressure(scenario)
    _check("pressure", pressure, 1e-12)
    _check("inertial_number", inertial_number, 1e-6, 1.0)
    _check("n_balls", n_balls, 100, integer=True)
    _check("strain", strain, 0.2)
    _check("segment_strain", segment_strain, 1e-4, 0.1 * strain)
    seeds = [int(s) for s in seeds]
    if not seeds:
        raise InputError("seeds = []: give at least one packing seed")
    log = getattr(progress, "log", None)
    fits = []
    t0 = time.perf_counter()
    for seed in seeds:
        tr = shear_transient(scenario, float(pressure), float(inertial_number), int(n_balls),
                             seed, float(strain), float(segment_strain))
        fit = fit_dilatancy(tr["strain"], tr["mu"], tr["phi"], steady_fraction,
                            segment_strain=segment_strain)
        fit.update(seed=seed, solid_fraction_packed=tr["solid_fraction_packed"])
        fits.append(fit)
        if log:
            log(f"dilatancy seed {seed}: phi {fit['phi_start']:.4f} -> {fit['phi_ss']:.4f}, "
                f"mu peak {fit['mu_peak']:.3f} at strain {fit['strain_at_peak']:.2f} -> "
                f"{fit['mu_ss']:.3f}; K_dil = {fit['K_dil']:.2f} +- {fit['K_dil_stderr']:.2f}")
    K = np.array([f["K_dil"] for f in fits])
    if K.size > 1:
        se = float(K.std(ddof=1) / math.sqrt(K.size))
    else:
        se = fits[0]["K_dil_stderr"]
    return {"K_dil": float(K.mean()), "K_dil_stderr": se,
            "excess_solid_fraction": float(np.mean([f["phi_start"] - f["phi_ss"]
                                                    for f in fits])),
            "pressure_Pa": float(pressure), "inertial_number": float(inertial_number),
            "shear_rate_1_s": float(tr["shear_rate_1_s"]), "n_balls": int(tr["n_balls"]),
            "strain": float(strain), "segment_strain": float(segment_strain),
            "steady_fraction": float(steady_fraction), "seeds": seeds,
            "K_dil_per_seed": [f["K_dil"] for f in fits],
            "K_dil_stderr_per_seed": [f["K_dil_stderr"] for f in fits],
            "mu_peak": [f["mu_peak"] for f in fits], "mu_ss": [f["mu_ss"] for f in fits],
            "phi_start": [f["phi_start"] for f in fits], "phi_ss": [f["phi_ss"] for f in fits],
            "strain_at_peak": [f["strain_at_peak"] for f in fits],
            "wall_time_s": time.perf_counter() - t0}
