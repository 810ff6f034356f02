"""The bed's damping within the cycle: a DEM of a vibrated strip of balls against the continua,
and the bed viscosity that makes the continuum fly as the DEM does
(docs/decisions/bed-viscosity-off.md).

    python benchmarks/strip_damping.py [--calibration FILE] [--case tub47] [--cycles 20]
        [--methods lagrangian,eulerian] [--viscosities 0,1000,3000] [--skip-dem]

The DEM: a slice of a wide bed, the case's balls (diameter, density, ball-ball contact) in a
box 0.075 m long (about 12 balls) and 3 balls wide (0.01905 m) between frictionless plane side
walls, as deep as the continua's bed (0.2 m at the case's packing: 1279 balls of 6.35 mm), on a
floor of the case's ball-wall contact moved vertically with the case's stroke (frequency,
amplitude_z, phase_z; no horizontal stroke, no rotation).  The balls start on a loose lattice
(spacing 1.06 d) and are shaken for `warm` cycles before `cycles` cycles are sampled at 8
phases a cycle.

The continua: benchmarks/floor_deformation.py's periodic strip (the same bed, 0.2 m deep, four
nodes wide, periodic along x, the calibration's material, each formulation's tub defaults),
with the material's bed viscosity (stress_update.damped_stress) set to each value asked.

The measure, the same for all: at each phase, the bed's vertical velocity vz (mass-weighted)
relative to the floor in 15 mm bands of height above it; its gradient between neighbouring
bands; the mean |dvz/dz| over the bands holding more than 0.3 of the fullest band's mass and
over the phases (1/s).  A bed that flies and lands as a body has none; one that rings through
its depth (its compression waves undamped) has much.  Printed beside it: the profile vz at
phase 2/8 (flight) from the floor up (mm/s), and the fitted viscosity: where |dvz/dz| against
the viscosity crosses the DEM's, interpolated linearly between the values run.
"""
from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import floor_deformation as fd  # noqa: E402

G = 9.81
BAND = 0.015
STRIP_LENGTH = 0.075
STRIP_WIDTH_BALLS = 3
MASS_CUT = 0.3


def gradient_measure(z, vz, mass, top=2 * fd.BED_DEPTH):
    """(sum over bands of m vz, sum of m) by BAND of height z (m) for one phase."""
    nb = int(math.ceil(top / BAND))
    k = np.clip((np.asarray(z) / BAND).astype(int), 0, nb - 1)
    mv = np.bincount(k, weights=mass * vz, minlength=nb)
    m = np.bincount(k, weights=mass, minlength=nb)
    return mv, m


def summarise(MV, M):
    """Mean |dvz/dz| (1/s) and the flight profile from per-phase band sums MV, M (8, nb)."""
    rates = []
    for ph in range(MV.shape[0]):
        m = M[ph]
        held = m > MASS_CUT * m.max()
        vz = np.where(held, MV[ph] / np.maximum(m, 1e-300), np.nan)
        g = np.abs(np.diff(vz)) / BAND
        w = np.minimum(m[:-1], m[1:])
        ok = held[:-1] & held[1:]
        rates.append(float((g[ok] * w[ok]).sum() / w[ok].sum()))
    m2 = M[2]
    held = m2 > MASS_CUT * m2.max()
    profile = 1e3 * MV[2][held] / m2[held]
    return float(np.mean(rates)), profile


def dem_strip(scenario, motion, warm, cycles, seed=1):
    """The DEM strip (module docstring): (mean |dvz/dz|, flight profile, balls, wall s)."""
    from vibroflow.dem import simulate as S
    from vibroflow.scenario.model import (Material, ParticleSpec, Run, Scenario, WallSpec,
                                          find_contact)

    d = scenario.fill.diameter
    r = 0.5 * d
    ball = scenario.materials[scenario.fill.material]
    bb = find_contact(scenario, scenario.fill.material, scenario.fill.material)
    bw = find_contact(scenario, scenario.fill.material, scenario.tub.wall_material)
    W = STRIP_WIDTH_BALLS * d
    vball = math.pi * d**3 / 6
    n = int(round(0.6 * STRIP_LENGTH * W * fd.BED_DEPTH / vball))
    s = 1.06 * d
    nx, ny = int((STRIP_LENGTH - d) // s) + 1, int((W - d) // s) + 1
    xs = r + 0.5 * (STRIP_LENGTH - d - (nx - 1) * s) + np.arange(nx) * s
    ys = r + 0.5 * (W - d - (ny - 1) * s) + np.arange(ny) * s
    zs = r + 0.001 + np.arange(math.ceil(n / (nx * ny))) * s
    pos = np.array([(x, y, z) for z in zs for x in xs for y in ys])[:n]
    rng = np.random.default_rng(seed)
    pos += rng.uniform(-0.45 * (s - d), 0.45 * (s - d), pos.shape)
    # the case's laws under the strip's material names; the sides are the balls' law frictionless
    contacts = [bb.model_copy(update={"pair": ("ball", "ball")}),
                bw.model_copy(update={"pair": ("ball", "floor")}),
                bb.model_copy(update={"pair": ("ball", "side"), "friction": 0.0,
                                      "rolling_friction": 0.0, "rolling_model": "none"})]
    materials = {"ball": Material(density=ball.density), "floor": Material(density=1200.0),
                 "side": Material(density=2500.0)}
    amp = (0.0, 0.0, motion.amplitude_z)
    walls = [WallSpec(point=(0.0, 0.0, 0.0), normal=(0.0, 0.0, 1.0), material="floor",
                      amplitude=amp, frequency=motion.frequency, phase=motion.phase_z),
             WallSpec(point=(0.0, 0.0, 0.0), normal=(1.0, 0.0, 0.0), material="side"),
             WallSpec(point=(STRIP_LENGTH, 0.0, 0.0), normal=(-1.0, 0.0, 0.0), material="side"),
             WallSpec(point=(0.0, 0.0, 0.0), normal=(0.0, 1.0, 0.0), material="side"),
             WallSpec(point=(0.0, W, 0.0), normal=(0.0, -1.0, 0.0), material="side")]
    dt = scenario.run.dt
    period = 1.0 / motion.frequency
    sc = Scenario(case="strip", gravity=(0.0, 0.0, -G), tub=None, fill=None,
                  particles=[ParticleSpec(position=tuple(p), diameter=d, material="ball")
                             for p in pos],
                  walls=walls, contacts=contacts, materials=materials,
                  run=Run(dt=dt, duration=(warm + cycles) * period, average_last=0.0))
    system = S.make_system(sc)
    zero = np.zeros((n, 3))
    st = S.init_state(system, pos, zero, zero.copy(), np.full(n, r), np.full(n, ball.density),
                      np.zeros(n, np.int64))
    omega = 2 * math.pi * motion.frequency
    t0 = time.time()
    S.run_steps(system, st, int(round(warm * period / dt)))
    MV = np.zeros((8, int(math.ceil(2 * fd.BED_DEPTH / BAND))))
    M = np.zeros_like(MV)
    for cyc in range(cycles):
        for ph in range(8):
            target = int(round((warm + cyc + ph / 8) * period / dt))
            S.run_steps(system, st, target - st.step)
            t = st.step * dt
            floor = motion.amplitude_z * (math.sin(omega * t + motion.phase_z)
                                          - math.sin(motion.phase_z))
            # relative to the floor, as the continua's velocities (their frame is the box's)
            v_floor = motion.amplitude_z * omega * math.cos(omega * t + motion.phase_z)
            mv, m = gradient_measure(st.pos[:, 2] - floor, st.vel[:, 2] - v_floor, st.mass)
            MV[ph] += mv
            M[ph] += m
    rate, profile = summarise(MV, M)
    return rate, profile, n, time.time() - t0


def continuum_strip(method, material, motion, warm, cycles):
    """The periodic continuum strip (module docstring): (mean |dvz/dz|, flight profile, s)."""
    system, state, advance = fd.build(method, material, motion, 0.0, True, None)
    period = 1.0 / motion.frequency
    dt = system.dt
    t0 = time.time()
    advance(system, state, int(round(warm * period / dt)))
    MV = np.zeros((8, int(math.ceil(2 * fd.BED_DEPTH / BAND))))
    M = np.zeros_like(MV)
    for cyc in range(cycles):
        for ph in range(8):
            advance(system, state, int(round((warm + cyc + ph / 8) * period / dt)) - state.step)
            has = state.mass > 0
            mv, m = gradient_measure(state.x[has, 1], state.v[has, 1], state.mass[has])
            MV[ph] += mv
            M[ph] += m
    rate, profile = summarise(MV, M)
    return rate, profile, time.time() - t0


def fit_viscosity(etas, rates, target):
    """The viscosity (Pa s) where rates(etas) crosses target, linear between the runs; None if
    it does not cross."""
    for (e0, r0), (e1, r1) in zip(zip(etas, rates), zip(etas[1:], rates[1:])):
        if (r0 - target) * (r1 - target) <= 0 and r0 != r1:
            return e0 + (target - r0) * (e1 - e0) / (r1 - r0)
    return None


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--calibration", default="tests/data/tub47-dem/calibration.toml")
    ap.add_argument("--case", default="tub47")
    ap.add_argument("--warm", type=int, default=14, help="cycles before sampling")
    ap.add_argument("--cycles", type=int, default=20, help="cycles sampled, 8 phases each")
    ap.add_argument("--methods", default="lagrangian,eulerian")
    ap.add_argument("--viscosities", default="0,1000,3000", help="bed viscosities (Pa s)")
    ap.add_argument("--skip-dem", action="store_true")
    a = ap.parse_args(argv)
    scenario, material, full, motion = fd.case_media(a.case, a.calibration)
    etas = [float(v) for v in a.viscosities.split(",")]
    print(f"{a.case}'s media, bed {fd.BED_DEPTH} m deep, vertical stroke {full.frequency:g} Hz "
          f"{1e3 * full.amplitude_z:.3g} mm; {a.warm} cycles, then {a.cycles} sampled at 8 "
          "phases; mean |dvz/dz| over 15 mm bands (1/s)")
    print("| method | bed viscosity (Pa s) | mean abs dvz/dz (1/s) | vz at 2/8, floor up "
          "(mm/s) | wall s |")
    print("|---|---|---|---|---|")
    target = None
    if not a.skip_dem:
        target, prof, n, wall = dem_strip(scenario, motion, a.warm, a.cycles)
        print(f"| DEM ({n} balls) | - | {target:.2f} | {' '.join(f'{v:.0f}' for v in prof)} | "
              f"{wall:.0f} |", flush=True)
    for method in a.methods.split(","):
        rates = []
        for eta in etas:
            mat = dataclasses.replace(material, bed_viscosity=eta)
            rate, prof, wall = continuum_strip(method, mat, motion, a.warm, a.cycles)
            rates.append(rate)
            print(f"| {method} | {eta:g} | {rate:.2f} | {' '.join(f'{v:.0f}' for v in prof)} | "
                  f"{wall:.0f} |", flush=True)
        if target is not None:
            fit = fit_viscosity(etas, rates, target)
            print(f"{method}: the DEM's {target:.2f} 1/s at bed viscosity "
                  + (f"{fit:.0f} Pa s" if fit is not None else "outside the values run"),
                  flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
