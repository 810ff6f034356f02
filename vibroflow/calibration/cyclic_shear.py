"""Cyclic simple shear of the packed media at the tub's frequency: the strain-dependent secant
shear modulus and damping the continuum's elastic part should have (soil dynamics'
modulus reduction, Hardin & Drnevich 1972, J. Soil Mech. Found. Div. 98(7), 667-692).

Why.  The continuum's elastic shear modulus sets how its bed deforms under the tub's 47 Hz
loading.  The small-strain modulus of a packed bed (elastic.py, or the affine estimate) is the
tangent at zero strain; under cycles of a strain amplitude gamma_0 a granular packing is much
softer (contacts slide and the fabric rearranges every cycle), the classic modulus-reduction
curve G_sec / G_max = 1 / (1 + gamma_0 / gamma_r) (Hardin & Drnevich 1972), and its cyclic loop
dissipates energy (hysteretic damping ratio D).  Soil dynamics gives a continuum the secant
modulus at the strain amplitude it will see; so does vibroflow: the tub's strain amplitude is
measured on the DEM (`tub_strain_amplitude`: from the bed's cycle-mean shear rate) and the
continuum gets G_sec at that amplitude (calibrate.py).  docs/decisions/cyclic-shear-modulus.md
shows what this does to the continuum against the DEM.

The test. A Lees-Edwards periodic box of the scenario's balls (vibroflow.dem.periodic_box; the
same packing as the steady shear cell, shear_cell.packed_box) at the pressure p with sigma_zz
held at p by the barostat, sheared with gamma(t) = gamma_0 sin(omega t), omega = 2 pi f: the
shear rate gamma_0 omega cos(omega t) is imposed piecewise constant over `segments` parts of a
cycle (the stress is the mean over each part, taken at its mid-strain). The first
`discard_cycles` cycles (the packing shakes down to its cyclic state) are dropped; over each
later cycle:

* secant modulus G_sec = (tau_max - tau_min) / (gamma_max - gamma_min) (Pa), tau = shear stress
  -(sigma_xz + sigma_zx) / 2 with compression positive (as the steady shear cell);
* damping ratio D = W_loop / (4 pi W_el), W_loop the area of the tau-gamma loop (J/m^3),
  W_el = G_sec gamma_0^2 / 2 (the usual definition, e.g. Kramer 1996 section 6.4);
* peak stress ratio max |tau| / sigma_zz;
each reported as the mean over the kept cycles with its standard error (cycle to cycle scatter),
together with the solid fraction.  Amplitudes are run from the smallest up, each from the state
the previous one left, as a strain-controlled cyclic test in the laboratory is.
"""
from __future__ import annotations

import math
import time

import numpy as np

from vibroflow.dem.periodic_step import MODE_Z, Q_SXZ, Q_SZX, Q_SZZ
from vibroflow.errors import InputError

from .shear_cell import (DEFAULT_POLYDISPERSITY, _check, check_values, packed_box,
                         tub_mid_depth_pressure)

DEFAULT_AMPLITUDES = (1.0e-4, 1.0e-3, 3.0e-3, 1.0e-2, 3.0e-2)
DEFAULT_N_BALLS = 300
DEFAULT_CYCLES = 6
DEFAULT_DISCARD = 3
DEFAULT_SEGMENTS = 40
#: the barostat time of the cyclic test, in contact times: slow enough that the box does not
#: breathe at the loading frequency (a 47 Hz cycle is ~ 90 contact times of tub47's balls)
BAROSTAT_TB_CONTACT_TIMES = 1.0


def tub_strain_amplitude(shear_rate_cycle_mean: float, frequency: float) -> float:
    """Shear strain amplitude gamma_0 (-) of a sinusoidal cycle whose mean |shear rate| is
    `shear_rate_cycle_mean` (1/s) at `frequency` (Hz): the mean of |gamma_0 omega cos(omega t)|
    is 2 gamma_0 omega / pi, so gamma_0 = pi gamma_dot_mean / (2 omega)."""
    _check("shear_rate_cycle_mean", shear_rate_cycle_mean, 0.0)
    _check("frequency", frequency, 1e-12)
    return math.pi * float(shear_rate_cycle_mean) / (2.0 * 2.0 * math.pi * float(frequency))


def cycle_measures(gamma: np.ndarray, tau: np.ndarray, szz: np.ndarray) -> dict:
    """Secant modulus (Pa), damping ratio (-) and peak stress ratio (-) of one closed cycle of
    strain gamma (-), shear stress tau (Pa) and normal stress szz (Pa) samples (module notes)."""
    g = np.asarray(gamma, float)
    t = np.asarray(tau, float)
    dg = g.max() - g.min()
    if not dg > 0:
        raise ValueError("cycle_measures: the strain does not vary over the cycle")
    G = (t.max() - t.min()) / dg
    # loop area: the closed trapezoid integral of tau dgamma around the cycle
    gc = np.append(g, g[0])
    tc = np.append(t, t[0])
    w_loop = abs(float(np.sum(0.5 * (tc[1:] + tc[:-1]) * np.diff(gc))))
    g0 = 0.5 * dg
    D = w_loop / (4.0 * math.pi * 0.5 * G * g0 * g0) if G > 0 else float("nan")
    ratio = float(np.max(np.abs(t) / np.maximum(np.asarray(szz, float), 1e-300)))
    return {"secant_shear_modulus": float(G), "damping_ratio": float(D),
            "peak_stress_ratio": ratio, "loop_energy_J_m3": w_loop}


def _mean_se(values) -> tuple[float, float]:
    v = np.asarray(values, float)
    if v.size < 2:
        return float(v.mean()) if v.size else float("nan"), float("nan")
    return float(v.mean()), float(v.std(ddof=1) / math.sqrt(v.size))


def run_cyclic_shear(scenario, strain_amplitudes=DEFAULT_AMPLITUDES,
                     frequency: float | None = None, pressure: float | None = None,
                     n_balls: int = DEFAULT_N_BALLS, seed: int | None = None,
                     cycles: int = DEFAULT_CYCLES, discard_cycles: int = DEFAULT_DISCARD,
                     segments: int = DEFAULT_SEGMENTS,
                     polydispersity: float = DEFAULT_POLYDISPERSITY, progress=None) -> list[dict]:
    """Strain-controlled cyclic simple shear at imposed sigma_zz (module notes).

    strain_amplitudes: gamma_0 of each test (-), run from the smallest up; frequency (Hz; None:
    the scenario's motion.frequency); pressure (Pa; None: the tub bed's mid-depth pressure);
    n_balls, seed (None: run.seed), polydispersity: the packing (shear_cell.packed_box);
    cycles per amplitude, of which the first discard_cycles are dropped; segments: parts of a
    cycle with a constant shear rate.  progress: None or an object with .log(str).

    Returns one dict per amplitude in the order given: strain_amplitude, frequency_Hz,
    pressure_Pa, secant_shear_modulus (Pa), damping_ratio, peak_stress_ratio, each with
    *_stderr, solid_fraction (mean over the kept cycles), solid_fraction_start,
    solid_fraction_cycle_end (the packing at the end of each cycle, discarded ones included),
    cycles_kept,
    n_balls, seed, dt, wall_time_s.  Deterministic for a given seed.
    """
    if frequency is None:
        if scenario.motion is None:
            raise InputError("frequency = None: required for a scenario without [motion]")
        frequency = scenario.motion.frequency
    _check("frequency", frequency, 1e-12)
    if pressure is None:
        pressure = tub_mid_depth_pressure(scenario)
    _check("pressure", pressure, 1e-12)
    _check("n_balls", n_balls, 100, integer=True)
    _check("cycles", cycles, 2, integer=True)
    _check("discard_cycles", discard_cycles, 0, integer=True)
    if discard_cycles > cycles - 2:
        raise InputError(f"discard_cycles = {discard_cycles!r}: must leave at least two of the "
                         f"{cycles} cycles")
    _check("segments", segments, 8, integer=True)
    amps = check_values("strain_amplitudes", strain_amplitudes, 0.5)
    seed = scenario.run.seed if seed is None else seed
    _check("seed", seed, 0, integer=True)
    f, p = float(frequency), float(pressure)
    log = getattr(progress, "log", None)
    t0 = time.perf_counter()
    box, setup = packed_box(scenario, p, int(n_balls), int(seed),
                            polydispersity=float(polydispersity))
    if log:
        log(f"cyclic shear: {n_balls} balls packed at p = {p:.4g} Pa, phi = "
            f"{box.solid_fraction:.3f} in {time.perf_counter() - t0:.1f} s")
    omega = 2.0 * math.pi * f
    seg_steps = max(1, int(round(1.0 / (f * segments * setup.dt))))
    seg_time = seg_steps * setup.dt  # the cycle is segments * seg_time (~ 1/f)
    gain = setup.gain(BAROSTAT_TB_CONTACT_TIMES * setup.contact_time)
    out: dict[int, dict] = {}
    for k in sorted(range(len(amps)), key=lambda i: amps[i]):
        g0 = amps[k]
        t1 = time.perf_counter()
        phi_start = box.solid_fraction
        gamma = 0.0
        rows = []  # (cycle, strain at the segment's middle, tau, sigma_zz, phi)
        period = segments * seg_time
        w = 2.0 * math.pi / period  # the cycle as discretised (within dt of 1/f)
        for c in range(int(cycles)):
            for j in range(int(segments)):
                # the exact strain change of this segment of gamma_0 sin(w t), as a constant rate
                ta, tb = j * seg_time, (j + 1) * seg_time
                dgam = g0 * (math.sin(w * tb) - math.sin(w * ta))
                box.set_shear_rate(dgam / seg_time)
                try:
                    s = box.run(seg_steps, MODE_Z, pressure=p, gain=gain,
                                sample_every=seg_steps)
                except FloatingPointError as e:
                    raise InputError(f"run.dt = {scenario.run.dt!r}: the cyclic shear cell blew "
                                     f"up at gamma_0 = {g0:.3g} ({e}); use a smaller time "
                                     "step") from None
                mid = gamma + 0.5 * dgam
                gamma += dgam
                tau = -0.5 * (s[-1, Q_SXZ] + s[-1, Q_SZX])
                rows.append((c, mid, tau, s[-1, Q_SZZ], box.solid_fraction))
        box.set_shear_rate(0.0)
        r = np.array(rows)
        per_cycle = [cycle_measures(r[r[:, 0] == c, 1], r[r[:, 0] == c, 2],
                                    r[r[:, 0] == c, 3])
                     for c in range(int(discard_cycles), int(cycles))]
        rec = {"strain_amplitude": g0, "frequency_Hz": f, "pressure_Pa": p,
               "angular_frequency_rad_s": omega}
        for key in ("secant_shear_modulus", "damping_ratio", "peak_stress_ratio"):
            m, se = _mean_se([pc[key] for pc in per_cycle])
            rec[key], rec[key + "_stderr"] = m, se
        kept = r[r[:, 0] >= discard_cycles]
        # the packing at the end of every cycle, discarded ones included: how fast the box shakes
        # down to its cyclic packing (calibration.compaction fits the compaction rate to it)
        ends = [float(r[r[:, 0] == c, 4][-1]) for c in range(int(cycles))]
        rec.update(solid_fraction=float(kept[:, 4].mean()), solid_fraction_start=phi_start,
                   solid_fraction_cycle_end=ends,
                   mean_sigma_zz_Pa=float(kept[:, 3].mean()),
                   cycles_kept=int(cycles) - int(discard_cycles), n_balls=int(box.n),
                   seed=int(seed), dt=float(setup.dt),
                   wall_time_s=float(time.perf_counter() - t1))
        out[k] = rec
        if log:
            log(f"  gamma_0 = {g0:.3g}: G_sec = {rec['secant_shear_modulus'] / 1e6:.3f} +- "
                f"{rec['secant_shear_modulus_stderr'] / 1e6:.3f} MPa, D = "
                f"{rec['damping_ratio']:.3f}, peak tau/sigma_zz = "
                f"{rec['peak_stress_ratio']:.3f}, phi = {rec['solid_fraction']:.4f}")
    return [out[k] for k in range(len(amps))]


def secant_modulus_at(records: list[dict], strain_amplitude: float) -> tuple[float, float]:
    """G_sec (Pa) and its standard error at `strain_amplitude` (-), interpolated linearly in
    log(gamma_0) between the measured amplitudes (the nearest end beyond them)."""
    recs = sorted(records, key=lambda r: r["strain_amplitude"])
    a = np.log([r["strain_amplitude"] for r in recs])
    G = np.array([r["secant_shear_modulus"] for r in recs])
    se = np.array([r["secant_shear_modulus_stderr"] for r in recs])
    x = math.log(max(float(strain_amplitude), 1e-300))
    return float(np.interp(x, a, G)), float(np.interp(x, a, se))

