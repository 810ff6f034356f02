"""The vibrated layer in the DEM: a strip of a case's balls on a floor vibrated vertically, its
temperature and solid-fraction profiles by height, its floor force and take-off phase
(issue 29's check of the continuum's temperature; measure.layer_profiles defines the measures).

The strip (benchmarks/strip_damping.py's, its depth set in layers): the case's balls (diameter,
density, ball-ball law) in a box STRIP_LENGTH_M long and STRIP_WIDTH_BALLS diameters wide
between frictionless plane side walls (the DEM's only periodic direction is the tub's length),
on a floor of the case's ball-wall law moved vertically with the case's vertical stroke
(frequency, amplitude_z, phase_z: tub47 47 Hz, 1.5 mm, Gamma = A omega^2 / g = 13.3) or a given
Gamma.  The layer holds `layers` diameters of balls at solid fraction 0.6, filled on a loose
lattice (spacing 1.06 d) jittered by the fill seed; it is shaken `warm_cycles` cycles, then
sampled for `cycles` whole cycles in `batches` batches: the profiles at n_phases phases of the
floor's cycle, the floor's force every FORCE_EVERY steps (the ball-floor contacts' vertical
force, summed).  Beside the temperature about each band's mean velocity, the thermal
temperature: the same profile of each ball's velocity about its snapshot's own Gaussian mean
velocity over the x-z plane (measure.thermal, width thermal_width_d diameters), the agitation a
continuum's T models.  Over the seeds, the profiles' mean and their seed scatter (the standard
deviation over seeds) are what a continuum is judged against.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import asdict, dataclass

import numpy as np

from vibroflow.dem import simulate as S
from vibroflow.dem.walls import WALL_PLANE0
from vibroflow.errors import InputError
from vibroflow.measure.layer_profiles import LayerProfiles, floor_phase, take_off_phase
from vibroflow.measure.thermal import thermal_velocities
from vibroflow.scenario.checks import find_contact
from vibroflow.scenario.model import Material, ParticleSpec, Run, Scenario, WallSpec

G = 9.81
STRIP_LENGTH_M = 0.075
STRIP_WIDTH_BALLS = 3
#: steps between the floor force's samples (8e-5 s at tub47's step: a fifth of a ball-floor
#: contact's duration, pi sqrt(m / k_n) = 0.45 ms)
FORCE_EVERY = 8
#: solid fraction of the fill: the strip holds layers x d x area x FILL_FRACTION of balls
FILL_FRACTION = 0.6


@dataclass(frozen=True)
class LayerSetup:
    """The strip's run (module docstring): layers (ball diameters of bed at FILL_FRACTION;
    default 31.5, tub47's 0.2 m deep bed), warm and sampled cycles, batches, phases a cycle,
    band_m (m) the profiles' band of height (default the continuum's node spacing on tub47,
    three diameters), gamma: the floor's peak acceleration / g (None: the case's amplitude_z),
    the fill seeds, thermal_width_d: the thermal temperature's local-mean kernel width in ball
    diameters."""

    layers: float = 31.5
    warm_cycles: int = 20
    cycles: int = 48
    batches: int = 4
    n_phases: int = 16
    band_m: float = 0.01875
    gamma: float | None = None
    seeds: tuple[int, ...] = (1, 2, 3, 4, 5)
    thermal_width_d: float = 2.0

    def check(self) -> None:
        for name in ("warm_cycles", "cycles", "batches", "n_phases"):
            v = getattr(self, name)
            if not isinstance(v, int) or v < (2 if name != "warm_cycles" else 0):
                raise InputError(f"{name} = {v!r}: must be a whole number >= 2 "
                                 "(warm_cycles >= 0)")
        if self.cycles < self.batches:
            raise InputError(f"cycles = {self.cycles}: must be at least batches = "
                             f"{self.batches}")
        if not self.layers > 0 or not self.band_m > 0:
            raise InputError(f"layers = {self.layers}, band_m = {self.band_m}: must be > 0")
        if not self.thermal_width_d > 0:
            raise InputError(f"thermal_width_d = {self.thermal_width_d}: must be > 0 "
                             "(ball diameters)")
        if self.gamma is not None and not self.gamma > 0:
            raise InputError(f"gamma = {self.gamma}: must be > 0 (or None: the case's)")
        if len(self.seeds) < 1:
            raise InputError("seeds: at least one fill seed")


def stroke(scenario, gamma: float | None) -> tuple[float, float, float]:
    """(frequency Hz, amplitude_z m, phase_z rad) of the case's vertical stroke, its amplitude
    set to gamma g / omega^2 when gamma is given."""
    m = scenario.motion
    f = float(m.frequency)
    amp = float(m.amplitude_z) * float(m.amplitude_factor)
    if gamma is not None:
        amp = gamma * G / (2 * math.pi * f) ** 2
    return f, amp, float(m.phase_z)


def strip_scenario(scenario, setup: LayerSetup, seed: int):
    """(Scenario of the strip, initial positions (N, 3) m, ball radius m, density kg/m^3)."""
    d = float(scenario.fill.diameter)
    r = 0.5 * d
    ball = scenario.materials[scenario.fill.material]
    bb = find_contact(scenario, scenario.fill.material, scenario.fill.material)
    bw = find_contact(scenario, scenario.fill.material, scenario.tub.wall_material)
    L, W = STRIP_LENGTH_M, STRIP_WIDTH_BALLS * d
    n = int(round(FILL_FRACTION * L * W * setup.layers * d / (math.pi * d**3 / 6)))
    s = 1.06 * d
    nx, ny = int((L - d) // s) + 1, int((W - d) // s) + 1
    xs = r + 0.5 * (L - d - (nx - 1) * s) + np.arange(nx) * s
    ys = r + 0.5 * (W - d - (ny - 1) * s) + np.arange(ny) * s
    zs = r + 0.001 + np.arange(math.ceil(n / (nx * ny))) * s
    pos = np.array([(x, y, z) for z in zs for x in xs for y in ys])[:n]
    pos += np.random.default_rng(seed).uniform(-0.45 * (s - d), 0.45 * (s - d), pos.shape)
    contacts = [bb.model_copy(update={"pair": ("ball", "ball")}),
                bw.model_copy(update={"pair": ("ball", "floor")}),
                bb.model_copy(update={"pair": ("ball", "side"), "friction": 0.0,
                                      "rolling_friction": 0.0, "rolling_model": "none"})]
    materials = {"ball": Material(density=ball.density), "floor": Material(density=1200.0),
                 "side": Material(density=2500.0)}
    f, amp, phase = stroke(scenario, setup.gamma)
    walls = [WallSpec(point=(0.0, 0.0, 0.0), normal=(0.0, 0.0, 1.0), material="floor",
                      amplitude=(0.0, 0.0, amp), frequency=f, phase=phase),
             WallSpec(point=(0.0, 0.0, 0.0), normal=(1.0, 0.0, 0.0), material="side"),
             WallSpec(point=(L, 0.0, 0.0), normal=(-1.0, 0.0, 0.0), material="side"),
             WallSpec(point=(0.0, 0.0, 0.0), normal=(0.0, 1.0, 0.0), material="side"),
             WallSpec(point=(0.0, W, 0.0), normal=(0.0, -1.0, 0.0), material="side")]
    run = Run(dt=scenario.run.dt, duration=(setup.warm_cycles + setup.cycles) / f,
              average_last=0.0)
    sc = Scenario(case="vibrated-layer", gravity=(0.0, 0.0, -G), tub=None, fill=None,
                  particles=[ParticleSpec(position=tuple(p), diameter=d, material="ball")
                             for p in pos],
                  walls=walls, contacts=contacts, materials=materials, run=run)
    return sc, pos, r, float(ball.density)


def run_seed(scenario, setup: LayerSetup, seed: int) -> dict:
    """One fill seed's profiles (LayerProfiles.result) and the strip's size."""
    sc, pos, r, rho = strip_scenario(scenario, setup, seed)
    f, amp, phase = stroke(scenario, setup.gamma)
    omega = 2 * math.pi * f
    system = S.make_system(sc)
    n = pos.shape[0]
    zero = np.zeros((n, 3))
    st = S.init_state(system, pos, zero, zero.copy(), np.full(n, r), np.full(n, rho),
                      np.zeros(n, np.int64))
    dt = system.dt
    weight = float(st.mass.sum()) * G
    volume = st.mass / rho
    P = setup.n_phases
    area = STRIP_LENGTH_M * STRIP_WIDTH_BALLS * 2 * r
    n_bands = int(math.ceil(3 * setup.layers * 2 * r / setup.band_m)) + 1
    acc = LayerProfiles(P, n_bands, setup.band_m, setup.batches, area)
    thermal = LayerProfiles(P, n_bands, setup.band_m, setup.batches, area)
    width = setup.thermal_width_d * 2 * r
    # sample times: the floor's phase psi / (2 pi) = c + k / P, c counted from its first cycle
    c0 = math.floor(phase / (2 * math.pi)) + 1

    def step_of(c, k):
        return int(round(((c0 + c + k / P) * 2 * math.pi - phase) / omega / dt))

    S.run_steps(system, st, step_of(setup.warm_cycles, 0) - st.step)
    for c in range(setup.cycles):
        batch = c * setup.batches // setup.cycles
        for k in range(P):
            end = step_of(setup.warm_cycles + c, k + 1)
            t = st.step * dt
            zf = amp * (math.sin(omega * t + phase) - math.sin(phase))
            acc.add_grains(batch, k, st.pos[:, 2] - zf, st.vel, st.mass, volume)
            thermal.add_grains(batch, k, st.pos[:, 2] - zf,
                               thermal_velocities(st.pos, st.vel, st.mass, width), st.mass,
                               volume)
            while st.step < end:
                S.run_steps(system, st, min(FORCE_EVERY, end - st.step))
                on = st.wall_flag[:, WALL_PLANE0] != 0
                fz = float(st.wall_force[on, WALL_PLANE0, 2].sum())
                acc.add_force(batch, float(floor_phase(st.step * dt, f, phase)), fz / weight)
    out = acc.result()
    th = thermal.result()
    out.update(seed=int(seed), balls=int(n), mass_kg=float(st.mass.sum()),
               thermal_temperature_m2_s2=th["temperature_m2_s2"],
               thermal_temperature_stderr_m2_s2=th["temperature_stderr_m2_s2"],
               thermal_width_m=float(width))
    return out


def seed_summary(results: list[dict]) -> dict:
    """The seeds' mean of each profile and its seed scatter (standard deviation over seeds,
    ddof 1; NaN with one seed)."""
    out = {}
    keys = ("temperature_m2_s2", "solid_fraction", "floor_force_over_weight")
    if all("thermal_temperature_m2_s2" in r for r in results):
        keys += ("thermal_temperature_m2_s2",)
    for key in keys:
        a = np.array([r[key] for r in results], float)
        with warnings.catch_warnings():  # bands no seed's bed reaches stay NaN
            warnings.simplefilter("ignore", RuntimeWarning)
            out[key] = np.nanmean(a, axis=0).tolist()
            out[key + "_seed_scatter"] = (np.nanstd(a, axis=0, ddof=1).tolist()
                                          if len(results) > 1
                                          else np.full(a.shape[1:], np.nan).tolist())
    offs = np.array([r["take_off_phase"] for r in results], float)
    mean_force = np.nanmean([r["floor_force_over_weight"] for r in results], axis=0)
    out["take_off_phase"] = take_off_phase(mean_force)
    dev = np.mod(offs - out["take_off_phase"] + 0.5, 1.0) - 0.5
    out["take_off_phase_seed_scatter"] = (float(np.std(dev, ddof=1)) if len(results) > 1
                                          else math.nan)
    return out


def vibrated_layer(scenario, setup: LayerSetup = LayerSetup()) -> dict:
    """The strip over setup.seeds (module docstring): the setup, the stroke, each seed's
    profiles and their seeds' summary (SI; phases are the floor's psi / (2 pi))."""
    setup.check()
    f, amp, phase = stroke(scenario, setup.gamma)
    seeds = [run_seed(scenario, setup, s) for s in setup.seeds]
    return {"case": scenario.case, "setup": asdict(setup),
            "stroke": {"frequency_hz": f, "amplitude_z_m": amp, "phase_z_rad": phase,
                       "gamma": amp * (2 * math.pi * f) ** 2 / G},
            "strip": {"length_m": STRIP_LENGTH_M,
                      "width_m": STRIP_WIDTH_BALLS * float(scenario.fill.diameter),
                      "diameter_m": float(scenario.fill.diameter),
                      "density_kg_m3": float(
                          scenario.materials[scenario.fill.material].density),
                      "dt_s": float(scenario.run.dt), "force_every_steps": FORCE_EVERY},
            "seeds": seeds, "summary": seed_summary(seeds)}
