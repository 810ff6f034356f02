"""Steady simple shear of the media at imposed pressure and shear rate: the mu(I), phi(I)
rheology from DEM (GDR MiDi 2004, da Cruz et al. 2005 PRE 72:021309).

A Lees-Edwards periodic box of the scenario's balls (vibroflow.dem.periodic_box) is

1. filled at random without overlap at solid fraction 0.3 (reproducible from the seed),
2. compressed affinely at a fixed strain rate to solid fraction 0.5 (a gas: nothing jams below
   it), then isotropically under the box control to the pressure p,
3. sheared at gamma_dot = I sqrt(p / rho_s) / d for each inertial number I, from the smallest I
   up, with L_x, L_y fixed and L_z under the barostat on sigma_zz = p.  Each point starts from
   the steady state of the one before: going up in I the bed must dilate, which shear does
   within a fraction of a strain unit, whereas compacting a flowing bed takes many strain units
   at small I.  The first point starts from the isotropically packed state (whose density is
   close to the quasi-static one) and is pre-sheared by 1 strain unit more, not counted, to
   build up its shear fabric.

Polydispersity: monodisperse spheres sheared in a small periodic cell order into sliding
layers (Peyneau & Roux 2008, appendix on crystallisation under shear), most readily at large I,
which shows as a dense (phi ~ 0.62), weak (mu ~ 0.35) flow at I = 0.3; the usual remedy, kept
here, is a slight polydispersity: diameters uniform in d (1 +- 0.1) by default, mean d (I uses
the mean d).  polydispersity = 0 gives the scenario's monodisperse balls.

Barostat (vibroflow.dem.periodic_step): eps_dot_zz = (sigma_zz - p) / (K_ref t_b) with K_ref =
k_eff / d, k_eff the contact's normal stiffness at the force p d^2 (linear law: k_n). The time
t_b sets how fast the box follows:
* a jammed packing (uniaxial stiffness M ~ 0.5 K_ref) relaxes sigma_zz - p with the time
  t_b K_ref / M ~ 2 t_b, so t_b >= t_c / 4 keeps the control stable and well resolved;
* a flowing packing has the much lower stiffness of its steady state, M_flow = phi dp/dphi at
  fixed gamma_dot = 2 p phi / ((phi_max - phi_min) I) from phi(I) and I ~ p^(-1/2), about
  6 p / I with phi / (phi_max - phi_min) ~ 3; so that the pressure relaxes within a strain of
  0.1 at every I, t_b = 0.1 M_flow / (gamma_dot K_ref);
* and no faster than needed: t_b <= 4 t_c, so that at small I the box's breathing
  (eps_dot ~ (sigma_zz - p) / (K_ref t_b)) stays a few per cent of the shear rate.
So t_b = clip(0.6 p / (I gamma_dot K_ref), t_c / 4, 4 t_c): for tub47 at 5 kPa, t_c / 4 at
I >= 0.2, 0.7 t_c at I = 0.1, 4 t_c at I <= 0.04.  Over the steady window
<sigma_zz> = p to within K_ref t_b ln(L_z,end / L_z,start) / T, since the control has no
steady-state error.  The preparation uses t_b = t_c / 4.

Transient and steady state: of the `strain` units sheared at each I, the first
`transient_strain` are discarded; the rest is split into batches (batch means give every
standard error).  The point is called steady when the means of mu and of phi over the first
and the second half of the kept window differ by less than three standard errors of that
difference (twice the window's batch-means error) plus 0.01 in mu and 0.002 in phi (below
what the fit resolves); otherwise `steady` is False and `reason` says which drifted.

Cost: steps per strain unit 1 / (gamma_dot dt) = d / (I sqrt(p / rho_s) dt): for tub47 at
4.5 kPa 167 000 / (I / 0.005), so the smallest I dominates; the default sweep (400 balls,
I = 0.005 to 0.3, 2 strain units each) takes about 1.5 minutes on one core.

Measured (compression positive stress): mu = tau / sigma_zz with tau = -(sigma_xz + sigma_zx)/2,
I = gamma_dot d / sqrt(sigma_zz / rho_s), phi = N v_ball / V; also mu_eq = tau_eq / p_mean
(tau_eq = sqrt(s:s / 2), p_mean = tr sigma / 3, the invariants the continuum uses), the
coordination number and sqrt(T) / (d gamma_dot) with T the granular temperature.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from vibroflow.dem.laws import MODEL_LINEAR, P_KN, P_MODEL, material_index, pair_table
from vibroflow.dem.periodic_box import PeriodicBox, random_fill
from vibroflow.dem.periodic_step import (MODE_FIXED, MODE_ISO, MODE_Z, Q_KE, Q_LX, Q_LY, Q_LZ,
                                         Q_SXX, Q_SXY, Q_SXZ, Q_SYY, Q_SYZ, Q_SZX, Q_SZZ, Q_Z,
                                         Q_ZNR)
from vibroflow.errors import InputError
from vibroflow.scenario.laws import contact_time

from .shear_temperature import profile_shear_rate, shear_rate_record

DEFAULT_INERTIAL_NUMBERS = (0.005, 0.01, 0.03, 0.1, 0.3)
DEFAULT_N_BALLS = 400
DEFAULT_STRAIN = 2.0            # shear strain per point
DEFAULT_TRANSIENT = 0.5         # strain discarded at the start of each point
DEFAULT_POLYDISPERSITY = 0.1   # diameters uniform in d (1 +- 0.1): see the module notes
PRESHEAR_STRAIN = 1.0           # extra strain before the first (smallest) I, from the packing
FILL_SOLID_FRACTION = 0.3
GAS_SOLID_FRACTION = 0.5
FAST_COMPRESSION_RATE = 5.0     # 1/s per axis, from the fill to GAS_SOLID_FRACTION
BAROSTAT_TB_MIN = 0.25         # t_b / t_c, bounds of the barostat time (module notes)
BAROSTAT_TB_MAX = 4.0
BAROSTAT_RELAX_STRAIN = 0.1    # shear strain over which a flowing cell finds its pressure
FLOW_STIFFNESS_I = 6.0         # M_flow I / p, from phi(I) with phi / (phi_max - phi_min) ~ 3
STEPS_PER_CONTACT = 15          # the time step is reduced below t_c / 15 if it is larger
MIN_BALLS = 100


@dataclass(frozen=True)
class BallSetup:
    """The balls of a scenario and the numbers the periodic box needs (SI units)."""

    material: str
    diameter: float          # m
    density: float           # kg/m^3
    mass: float              # kg
    par: np.ndarray          # contact-law row of the ball-ball pair (laws.pair_table)
    pair: object             # the scenario's ContactPair
    dt: float                # s, time step used
    contact_time: float      # s
    k_eff: float             # N/m, normal contact stiffness at the force p d^2
    skin: float              # m
    max_overlap: float       # m, blow-up bound

    def gain(self, t_b: float) -> float:
        """Barostat gain 1 / (K_ref t_b), K_ref = k_eff / d (1/(Pa s))."""
        return self.diameter / (self.k_eff * t_b)

    def barostat_time(self, pressure: float, inertial_number: float | None) -> float:
        """t_b (s) of the barostat in steady shear at I (None: the preparation), see the
        module notes: clip(0.1 M_flow / (gamma_dot K_ref), t_c / 4, 4 t_c)."""
        lo = BAROSTAT_TB_MIN * self.contact_time
        if inertial_number is None:
            return lo
        gd = inertial_number * math.sqrt(pressure / self.density) / self.diameter
        m_flow = FLOW_STIFFNESS_I * pressure / inertial_number
        t_b = BAROSTAT_RELAX_STRAIN * m_flow * self.diameter / (gd * self.k_eff)
        return min(max(t_b, lo), BAROSTAT_TB_MAX * self.contact_time)


def ball_setup(scenario, pressure: float) -> BallSetup:
    """The ball material, diameter and ball-ball contact law of a scenario (the fill; in
    explicit mode the first particle's), the time step and the stiffness scale at `pressure`.
    """
    if scenario.fill is not None:
        mat, d = scenario.fill.material, float(scenario.fill.diameter)
    else:
        mat, d = scenario.particles[0].material, float(scenario.particles[0].diameter)
    pair = None
    for c in scenario.contacts:
        if tuple(c.pair) == (mat, mat):
            pair = c
    if pair is None:
        raise InputError(f"contacts: no [[contacts]] entry with pair = [\"{mat}\", \"{mat}\"]: "
                         f"the shear cell needs the ball-ball contact law")
    idx = material_index(scenario)[mat]
    par = pair_table(scenario)[idx, idx].copy()
    rho = float(scenario.materials[mat].density)
    m = rho * math.pi * d**3 / 6.0
    r = 0.5 * d
    if par[P_MODEL] == MODEL_LINEAR:
        k_eff = float(par[P_KN])
    else:
        # Hertz F = k_h sqrt(R_eff) delta^(3/2): the tangent stiffness at F = p d^2
        kh = float(par[P_KN]) * math.sqrt(0.5 * r)
        delta = (pressure * d * d / kh) ** (2.0 / 3.0)
        k_eff = 1.5 * kh * math.sqrt(delta)
    # contact time: the collision at the inertial speed sqrt(p / rho) (Hertz contacts shorten
    # with speed; the linear law does not care), or the oscillation of a loaded contact
    t_c = contact_time(pair, scenario.materials, 0.5 * m, 0.5 * r,
                       impact_speed=max(math.sqrt(pressure / rho), 1e-3))
    t_c = min(t_c, math.pi * math.sqrt(0.5 * m / k_eff))
    dt = min(float(scenario.run.dt), t_c / STEPS_PER_CONTACT)
    return BallSetup(material=mat, diameter=d, density=rho, mass=m, par=par, pair=pair, dt=dt,
                     contact_time=t_c, k_eff=k_eff, skin=float(scenario.run.skin) * d,
                     max_overlap=float(scenario.run.max_overlap) * d)


def tub_mid_depth_pressure(scenario, solid_fraction: float = 0.6) -> float:
    """Hydrostatic pressure (Pa) at mid-depth of the settled bed of a tub scenario:
    p = phi rho_s g h / 2, with the bed depth h that holds the fill's balls at solid fraction
    phi in the U cross-section (half disc of radius R, then a rectangle 2R wide) over the
    length L_y.  tub47: h = 0.196 m, p = 4.5 kPa."""
    if scenario.tub is None or scenario.fill is None:
        raise InputError("pressure = None: required for a scenario without a tub and a fill "
                         "(give the shear cell's pressure in Pa)")
    d = scenario.fill.diameter
    R, Ly = scenario.tub.radius, scenario.tub.length
    area = scenario.fill.count * math.pi * d**3 / 6.0 / solid_fraction / Ly
    half_disc = 0.5 * math.pi * R * R
    if area >= half_disc:
        h = R + (area - half_disc) / (2.0 * R)
    else:
        # circular segment of depth h: A = R^2 acos((R-h)/R) - (R-h) sqrt(2Rh - h^2)
        lo, hi = 0.0, R
        for _ in range(100):
            h = 0.5 * (lo + hi)
            a = R * R * math.acos((R - h) / R) - (R - h) * math.sqrt(2 * R * h - h * h)
            lo, hi = (h, hi) if a < area else (lo, h)
    g = math.sqrt(sum(c * c for c in scenario.gravity))
    rho = scenario.materials[scenario.fill.material].density
    return solid_fraction * rho * g * h / 2.0


def check_values(name: str, values, hi: float) -> list[float]:
    """A non-empty list of numbers in (0, hi] from `values` (an InputError naming `name`)."""
    try:
        out = [float(x) for x in values]
    except (TypeError, ValueError):
        raise InputError(f"{name} = {values!r}: must be a list of numbers in (0, {hi:g}]") \
            from None
    if not out:
        raise InputError(f"{name} = []: give at least one value")
    for x in out:
        if not (math.isfinite(x) and 0.0 < x <= hi):
            raise InputError(f"{name}: {x!r}: each must be in (0, {hi:g}]")
    return out


def _check(name: str, value, lo: float, hi: float = math.inf, integer: bool = False):
    ok = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)
    if ok and integer:
        ok = float(value) == int(value)
    if not ok or not math.isfinite(float(value)) or not lo <= float(value) <= hi:
        kind = "an integer" if integer else "a number"
        rng = f">= {lo}" if hi == math.inf else f"in [{lo}, {hi}]"
        raise InputError(f"{name} = {value!r}: must be {kind} {rng}")


def compress(box: PeriodicBox, setup: BallSetup, pressure: float, damping: float = 0.0,
             tolerance: float = 0.05, rest_ke: float | None = None,
             max_steps: int = 2_000_000) -> np.ndarray:
    """Bring the box to the pressure p (Pa): a fixed-rate affine compression to solid fraction
    0.5, then the isotropic box control (tr sigma / 3 -> p) until the mean pressure of the last
    ten samples is within `tolerance` of p (and, given `rest_ke` (J per ball), the balls' mean
    kinetic energy is below it).  Returns the samples of the controlled stage."""
    phi0 = box.solid_fraction
    if phi0 < GAS_SOLID_FRACTION:
        eps = math.log(GAS_SOLID_FRACTION / phi0) / 3.0
        steps = int(math.ceil(eps / (FAST_COMPRESSION_RATE * setup.dt)))
        rate = eps / (steps * setup.dt)
        box.run(steps, MODE_FIXED, dilation=(-rate, -rate, -rate), damping=damping,
                sample_every=max(steps, 1))
    gain = setup.gain(setup.barostat_time(pressure, None))
    every = 100

    def stop(s):
        if s.shape[0] < 10:
            return False
        last = s[-10:]
        p = (last[:, Q_SXX] + last[:, Q_SYY] + last[:, Q_SZZ]).mean() / 3.0
        ok = abs(p - pressure) <= tolerance * pressure
        if rest_ke is not None:
            ok = ok and last[:, Q_KE].mean() / box.n <= rest_ke
        return ok

    samples = box.run(max_steps, MODE_ISO, pressure=pressure, gain=gain, damping=damping,
                      rate_max=FAST_COMPRESSION_RATE, sample_every=every, stop=stop)
    if not stop(samples):
        raise InputError(f"pressure = {pressure!r} Pa: the periodic box did not reach it in "
                         f"{max_steps} steps of compression")
    return samples


def packed_box(scenario, pressure: float, n_balls: int, seed: int, damping: float = 0.0,
               tolerance: float = 0.05, rest_ke: float | None = None,
               polydispersity: float = 0.0):
    """A cubic periodic box of `n_balls` balls filled at random (seed) and compressed to the
    pressure (see `compress`).  Diameters are the scenario's, or with `polydispersity` w > 0
    uniform in d (1 - w, 1 + w) (drawn from the seed; mean d).  Returns (box, setup)."""
    setup = ball_setup(scenario, pressure)
    n = int(n_balls)
    rng = np.random.default_rng(int(seed))
    diam = setup.diameter * (1.0 + polydispersity * (2.0 * rng.random(n) - 1.0)) \
        if polydispersity > 0 else np.full(n, setup.diameter)
    side = ((math.pi / 6.0 * diam**3).sum() / FILL_SOLID_FRACTION) ** (1.0 / 3.0)
    radius = 0.5 * diam
    pos = random_fill(n, radius, (side, side, side), rng)
    box = PeriodicBox(pos, radius, setup.density * math.pi / 6.0 * diam**3, setup.par,
                      (side, side, side), setup.dt, setup.skin, setup.max_overlap)
    try:
        compress(box, setup, pressure, damping=damping, tolerance=tolerance, rest_ke=rest_ke)
    except FloatingPointError as e:
        raise InputError(f"run.dt = {scenario.run.dt!r}: the periodic box blew up while "
                         f"compressing ({e}); use a smaller time step") from None
    return box, setup


def batch_means(values: np.ndarray, batches: int) -> tuple[np.ndarray, float, float]:
    """Split a series into `batches` equal consecutive batches: (batch means, mean of the
    batch means, its standard error std(batch means) / sqrt(batches))."""
    k = len(values) // batches
    b = np.asarray(values[: k * batches], float).reshape(batches, k).mean(axis=1)
    return b, float(b.mean()), float(b.std(ddof=1) / math.sqrt(batches))


def _observables(s: np.ndarray, solid_volume: float, total_mass: float
                 ) -> dict[str, np.ndarray]:
    """Per-sample observables from block means (see the module notes)."""
    szz = s[:, Q_SZZ]
    tau = -0.5 * (s[:, Q_SXZ] + s[:, Q_SZX])
    p_mean = (s[:, Q_SXX] + s[:, Q_SYY] + szz) / 3.0
    sym = np.stack([s[:, Q_SXX], s[:, Q_SYY], szz, s[:, Q_SXY],
                    0.5 * (s[:, Q_SXZ] + s[:, Q_SZX]), s[:, Q_SYZ]], axis=1)
    dev = sym.copy()
    dev[:, :3] -= p_mean[:, None]
    tau_eq = np.sqrt(0.5 * (dev[:, 0] ** 2 + dev[:, 1] ** 2 + dev[:, 2] ** 2)
                     + dev[:, 3] ** 2 + dev[:, 4] ** 2 + dev[:, 5] ** 2)
    vol = s[:, Q_LX] * s[:, Q_LY] * s[:, Q_LZ]
    T = 2.0 * s[:, Q_KE] / (3.0 * total_mass)
    return {"szz": szz, "tau": tau, "p_mean": p_mean, "tau_eq": tau_eq, "sxx": s[:, Q_SXX],
            "syy": s[:, Q_SYY], "phi": solid_volume / vol, "Z": s[:, Q_Z], "Znr": s[:, Q_ZNR],
            "T": T}


def _point_record(s: np.ndarray, I_target: float, gamma_dot: float, pressure: float,
                  setup: BallSetup, box: PeriodicBox, batches: int) -> dict:
    d, rho = setup.diameter, setup.density
    ob = _observables(s, float((4.0 / 3.0 * math.pi * box.radius**3).sum()),
                      float(box.mass.sum()))
    k = len(s) // batches
    if k < 1:
        raise InputError(f"strain: the steady window holds {len(s)} samples, fewer than "
                         f"{batches} batches; give more strain")

    def bm(x):
        return np.asarray(x[: k * batches], float).reshape(batches, k).mean(axis=1)

    B = {name: bm(v) for name, v in ob.items()}
    derived = {
        "mu": B["tau"] / B["szz"],
        "mu_eq": B["tau_eq"] / B["p_mean"],
        "I": gamma_dot * d / np.sqrt(B["szz"] / rho),
        "phi": B["phi"],
        "pressure": B["szz"],
        "mean_pressure": B["p_mean"],
        "normal_stress_ratio_xx": B["sxx"] / B["szz"],
        "normal_stress_ratio_yy": B["syy"] / B["szz"],
        "coordination_number": B["Z"],
        "coordination_number_non_rattler": B["Znr"],
        "sqrtT_over_d_gamma_dot": np.sqrt(B["T"]) / (d * gamma_dot),
        "granular_temperature": B["T"],
    }
    rec = {"I_target": float(I_target), "shear_rate": float(gamma_dot),
           "pressure_target": float(pressure)}
    whole = {  # the value from the whole window (ratio of means), the error from the batches
        "mu": ob["tau"].mean() / ob["szz"].mean(),
        "mu_eq": ob["tau_eq"].mean() / ob["p_mean"].mean(),
        "I": gamma_dot * d / math.sqrt(ob["szz"].mean() / rho),
        "pressure": ob["szz"].mean(), "mean_pressure": ob["p_mean"].mean(),
        "normal_stress_ratio_xx": ob["sxx"].mean() / ob["szz"].mean(),
        "normal_stress_ratio_yy": ob["syy"].mean() / ob["szz"].mean(),
        "sqrtT_over_d_gamma_dot": math.sqrt(ob["T"].mean()) / (d * gamma_dot),
        "granular_temperature": ob["T"].mean(),
    }
    for name, b in derived.items():
        rec[name] = float(whole.get(name, b.mean()))
        rec[name + "_stderr"] = float(b.std(ddof=1) / math.sqrt(batches))
    # steadiness: the means over the two halves of the window differ by no more than three
    # standard errors of their difference (each half's is sqrt(2) times the window's batch
    # error, so the difference's is twice it), plus the floor
    h = len(s) // 2
    reasons = []
    for name, x, floor in (("mu", ob["tau"] / ob["szz"], 0.01), ("phi", ob["phi"], 0.002)):
        diff = abs(x[:h].mean() - x[h: 2 * h].mean())
        limit = 3.0 * 2.0 * rec[name + "_stderr"] + floor
        if not diff <= limit:
            reasons.append(f"{name} drifted by {diff:.3g} between the halves of the window "
                           f"(more than {limit:.3g})")
    rec["steady"] = not reasons
    rec["reason"] = "; ".join(reasons)
    return rec


class _Progress:
    """Adapter: a RunProgress-like object (stage/update/log), a callable f(done, total) or
    None."""

    def __init__(self, progress):
        self.p = progress

    def stage(self, desc, total, unit):
        if hasattr(self.p, "stage"):
            self.p.stage(desc, total, unit=unit)

    def update(self, done, total, particle_steps=None):
        if hasattr(self.p, "update"):
            self.p.update(done, particle_steps)
        elif callable(self.p):
            self.p(done, total)

    def log(self, msg):
        if hasattr(self.p, "log"):
            self.p.log(msg)


def run_shear_cell(scenario, inertial_numbers=DEFAULT_INERTIAL_NUMBERS,
                   pressure: float | None = None, n_balls: int = DEFAULT_N_BALLS,
                   seed: int | None = None, strain: float = DEFAULT_STRAIN,
                   transient_strain: float = DEFAULT_TRANSIENT, batches: int | None = None,
                   polydispersity: float = DEFAULT_POLYDISPERSITY, progress=None) -> list[dict]:
    """Steady simple shear at imposed pressure for each inertial number (see the module notes).

    scenario: a vibroflow Scenario (its ball-ball contact law, ball diameter and density,
        run.dt (reduced below t_c/15 if larger), run.skin, run.max_overlap; run.batches is the
        default number of batches);
    inertial_numbers: the target I of each point (-);
    pressure: imposed sigma_zz (Pa); None: the tub bed's mid-depth hydrostatic pressure
        (`tub_mid_depth_pressure`, tub47: 4.5 kPa);
    n_balls: balls in the box (>= 100); seed: of the random fill (None: scenario.run.seed);
    strain: shear strain per point; transient_strain: the part of it discarded;
    polydispersity: w, diameters uniform in d (1 +- w) (0: the scenario's monodisperse balls;
        the default 0.1 keeps the small periodic cell from crystallising under shear);
    progress: None, a RunProgress (stage/update/log) or a callable f(done_strain, total).

    Returns one dict per I (in the order given): I_target; I, mu, mu_eq, phi, pressure
    (sigma_zz, Pa), mean_pressure (tr sigma / 3, Pa), normal_stress_ratio_xx/_yy,
    coordination_number(_non_rattler), sqrtT_over_d_gamma_dot, granular_temperature (T =
    <m |v - u(z)|^2> / (3 <m>) about the imposed profile u_x = gamma_dot (z - L_z/2), m^2/s^2),
    shear_rate_measured (the slope of the balls' mean profile, 1/s), each with *_stderr (batch
    means over the steady window); shear_rate (imposed, 1/s), pressure_target (Pa), strain,
    transient_strain, steps, dt (s), wall_time_s, n_balls, seed, steady, reason,
    box_L_z (m, mean).  Deterministic for a given seed.
    """
    if pressure is None:
        pressure = tub_mid_depth_pressure(scenario)
    _check("pressure", pressure, 1e-12)
    pressure = float(pressure)
    _check("n_balls", n_balls, MIN_BALLS, integer=True)
    _check("strain", strain, 1e-6)
    _check("transient_strain", transient_strain, 0.0)
    if transient_strain >= strain:
        raise InputError(f"transient_strain = {transient_strain!r}: must be less than strain = "
                         f"{strain!r}")
    if batches is None:
        batches = max(int(scenario.run.batches), 4)
    _check("batches", batches, 2, integer=True)
    I_list = check_values("inertial_numbers", inertial_numbers, 1.0)
    seed = scenario.run.seed if seed is None else seed
    _check("seed", seed, 0, integer=True)
    seed = int(seed)
    prog = _Progress(progress)
    t0 = time.perf_counter()
    _check("polydispersity", polydispersity, 0.0, 0.3)
    box, setup = packed_box(scenario, pressure, n_balls, seed,
                            polydispersity=float(polydispersity))
    prep_time = time.perf_counter() - t0
    prog.log(f"shear cell: {n_balls} balls packed at p = {pressure:.4g} Pa, phi = "
             f"{box.solid_fraction:.3f} in {prep_time:.1f} s (dt = {setup.dt:.3g} s)")
    d, rho = setup.diameter, setup.density
    order = sorted(range(len(I_list)), key=lambda k: I_list[k])
    total = strain * len(I_list)
    prog.stage("shear cell", total, unit="strain")
    records: dict[int, dict] = {}
    done_strain = 0.0
    for k in order:
        I = I_list[k]
        gd = I * math.sqrt(pressure / rho) / d
        steps = int(math.ceil(strain / (gd * setup.dt)))
        skip = int(math.floor(transient_strain / (gd * setup.dt)))
        every = max(1, min(200, steps // 400))
        t_b = setup.barostat_time(pressure, I)
        gain = setup.gain(t_b)
        box.set_shear_rate(gd)
        t1 = time.perf_counter()
        base = done_strain

        slopes: list[tuple[int, float]] = []

        def stop(s, base=base, gd=gd, every=every, slopes=slopes):
            slopes.append((len(s), profile_shear_rate(box)))
            if progress is not None:
                prog.update(base + len(s) * every * gd * setup.dt, total,
                            len(s) * every * box.n)
            return False

        try:
            if k == order[0]:
                box.run(int(math.ceil(PRESHEAR_STRAIN / (gd * setup.dt))), MODE_Z,
                        pressure=pressure, gain=gain, sample_every=1000)
            s = box.run(steps, MODE_Z, pressure=pressure, gain=gain, sample_every=every,
                        stop=stop)
        except FloatingPointError as e:
            raise InputError(f"run.dt = {scenario.run.dt!r}: the shear cell blew up at I = "
                             f"{I:.3g} ({e}); use a smaller time step") from None
        wall = time.perf_counter() - t1
        done_strain += strain
        first = (skip + every - 1) // every
        kept = s[first:]
        rec = _point_record(kept, I, gd, pressure, setup, box, int(batches))
        rec.update(shear_rate_record([g for n, g in slopes if n > first], int(batches)))
        rec.update(strain=float(strain), transient_strain=float(transient_strain),
                   steps=int(steps), dt=float(setup.dt), wall_time_s=float(wall),
                   n_balls=int(box.n), seed=seed, polydispersity=float(polydispersity),
                   box_L_z=float(kept[:, Q_LZ].mean()), box_L_x=float(box.box[0]),
                   barostat_time_s=float(t_b))
        records[k] = rec
        prog.log(f"  I = {I:.3g}: mu = {rec['mu']:.3f} +- {rec['mu_stderr']:.3f}, phi = "
                 f"{rec['phi']:.3f} +- {rec['phi_stderr']:.3f}, I measured {rec['I']:.3g}, "
                 f"{steps} steps in {wall:.1f} s" + ("" if rec["steady"] else
                                                     f" (not steady: {rec['reason']})"))
    return [records[k] for k in range(len(I_list))]
