"""Shared helpers of the DEM verification tests (test_dem_collisions.py, test_dem_rolling.py,
test_dem_plates.py): small explicit scenarios driven straight through the engine
(`vibroflow.dem.simulate`), with nothing written to disk.

These systems hold one or two balls, where numba's thread wake-ups cost more than the work, so
every run here is done on one thread (the thread count is put back
afterwards, so other tests are not affected).
"""
from __future__ import annotations

import math
from contextlib import contextmanager

import numba
import numpy as np

from vibroflow.dem import laws as L
from vibroflow.dem import simulate as S
from vibroflow.dem.walls import WALL_PLANE0
from vibroflow.scenario.model import ContactPair, Material, ParticleSpec, Run, Scenario, WallSpec

# the reference case's balls: steel, d = 6.35 mm
D_STEEL = 0.00635
R_STEEL = 0.5 * D_STEEL
RHO_STEEL = 7800.0
G = 9.81


def sphere_mass(radius: float, density: float) -> float:
    return 4.0 / 3.0 * math.pi * radius**3 * density


M_STEEL = sphere_mass(R_STEEL, RHO_STEEL)


def zeta_of(e: float) -> float:
    """Damping ratio of the linear spring-dashpot giving restitution e (models.md; Cundall &
    Strack): e = exp(-pi zeta / sqrt(1 - zeta^2))."""
    if e >= 1.0:
        return 0.0
    ln_e = math.log(e)
    return -ln_e / math.sqrt(math.pi**2 + ln_e**2)


def linear_contact_time(k_n: float, m_eff: float, e: float) -> float:
    """Half period of the damped oscillator: t_c = pi / sqrt(k/m - (gamma/2m)^2), with
    gamma = 2 zeta sqrt(m k), i.e. pi / (w0 sqrt(1 - zeta^2))."""
    zeta = zeta_of(e)
    gamma = 2.0 * zeta * math.sqrt(m_eff * k_n)
    return math.pi / math.sqrt(k_n / m_eff - (gamma / (2.0 * m_eff)) ** 2)


def linear_dt(k_n: float, m_eff: float, steps_per_contact: float) -> float:
    return linear_contact_time(k_n, m_eff, 1.0) / steps_per_contact


def law_row(model: int, roll: int) -> np.ndarray:
    """A steel-like row of contact-law parameters (vibroflow.dem.laws.pair_table's layout):
    linear or Hertz `model`, rolling model `roll`."""
    row = np.zeros(L.N_PARAMS)
    row[L.P_MODEL] = model
    if model == L.MODEL_LINEAR:
        row[L.P_KN], row[L.P_KT], row[L.P_DAMP] = 2.0e5, 2.0 / 7.0, 0.05
    else:
        row[L.P_KN], row[L.P_KT], row[L.P_DAMP] = 1.5e11, 6.4e10, 0.3
    row[L.P_MU], row[L.P_MUR], row[L.P_ROLL] = 0.3, 0.05, roll
    return row


def contact(a="steel", b="steel", model="linear", k_n=1.0e5, e=0.85, mu=0.2, mu_r=0.0,
            rolling="none", kt_ratio=2.0 / 7.0) -> ContactPair:
    kw = dict(pair=(a, b), model=model, restitution=e, friction=mu, rolling_friction=mu_r,
              rolling_model=rolling, k_t_over_k_n=kt_ratio)
    if model == "linear":
        kw["k_n"] = k_n
    return ContactPair(**kw)


def ball(pos, vel=(0.0, 0.0, 0.0), omg=(0.0, 0.0, 0.0), d=D_STEEL, material="steel"):
    return ParticleSpec(position=tuple(pos), velocity=tuple(vel), angular_velocity=tuple(omg),
                        diameter=d, material=material)


def plane(point=(0.0, 0.0, 0.0), normal=(0.0, 0.0, 1.0), material="steel", amplitude=(0, 0, 0),
          frequency=0.0, phase=0.0, velocity=(0.0, 0.0, 0.0)) -> WallSpec:
    return WallSpec(point=tuple(point), normal=tuple(normal), material=material,
                    amplitude=tuple(float(a) for a in amplitude), frequency=frequency,
                    phase=phase, velocity=tuple(velocity))


def scenario(particles, contacts, walls=None, dt=1e-6, gravity=(0.0, 0.0, 0.0),
             materials: dict[str, Material] | None = None, duration=1.0) -> Scenario:
    kw = {}
    if materials is not None:
        kw["materials"] = materials
    return Scenario(case="verification", gravity=tuple(gravity), tub=None, fill=None,
                    particles=list(particles), walls=list(walls) if walls else None,
                    contacts=list(contacts), run=Run(dt=dt, duration=duration, average_last=0.0),
                    **kw)


@contextmanager
def one_thread():
    before = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        yield
    finally:
        numba.set_num_threads(before)


class Sim:
    """An explicit scenario's system and state, stepped in place."""

    def __init__(self, sc: Scenario):
        self.scenario = sc
        self.system = S.make_system(sc)
        names = self.system.material_names
        ps = sc.particles
        with one_thread():
            self.state = S.init_state(
                self.system, [p.position for p in ps], [p.velocity for p in ps],
                [p.angular_velocity for p in ps], [0.5 * p.diameter for p in ps],
                [sc.materials[p.material].density for p in ps],
                [names.index(p.material) for p in ps])

    @property
    def dt(self) -> float:
        return self.system.dt

    @property
    def t(self) -> float:
        return self.state.time(self.system.dt)

    def run(self, nsteps: int) -> None:
        with one_thread():
            S.run_steps(self.system, self.state, int(nsteps))

    def wall_fn(self, ball_index=0, plane_index=0) -> float:
        return float(self.state.wall_fn[ball_index, WALL_PLANE0 + plane_index])

    def wall_touching(self, ball_index=0, plane_index=0) -> bool:
        return bool(self.state.wall_flag[ball_index, WALL_PLANE0 + plane_index])

    def wall_sliding(self, ball_index=0, plane_index=0) -> bool:
        return bool(self.state.wall_slide[ball_index, WALL_PLANE0 + plane_index])

    def momentum(self) -> np.ndarray:
        return (self.state.mass[:, None] * self.state.vel).sum(axis=0)

    def trace(self, nsteps: int, every: int = 1) -> dict[str, np.ndarray]:
        """Run `nsteps` steps, recording every `every` steps (and the start): time, position,
        velocity, angular velocity, and the plane-wall normal force / touching / sliding of
        ball 0 with plane 0 (when there is a plane)."""
        st = self.state
        has_plane = self.system.planes.shape[0] > 0
        rec = {k: [] for k in ("t", "pos", "vel", "omg", "fn", "touch", "slide")}

        def sample():
            rec["t"].append(self.t)
            rec["pos"].append(st.pos.copy())
            rec["vel"].append(st.vel.copy())
            rec["omg"].append(st.omg.copy())
            if has_plane:
                rec["fn"].append(self.wall_fn())
                rec["touch"].append(self.wall_touching())
                rec["slide"].append(self.wall_sliding())

        sample()
        done = 0
        with one_thread():
            while done < nsteps:
                n = min(every, nsteps - done)
                S.run_steps(self.system, st, n)
                done += n
                sample()
        return {k: np.array(v) for k, v in rec.items()}


def plane_displacement(t, amplitude, frequency, phase):
    """The engine's documented plane motion a [sin(w t + phase) - sin(phase)] (walls.py)."""
    w = 2.0 * math.pi * frequency
    return np.multiply.outer(np.sin(w * np.asarray(t) + phase) - math.sin(phase),
                             np.asarray(amplitude, dtype=float))


def fit_quadratic(t, s):
    """Least-squares s = s0 + v0 t + a t^2 / 2; returns (s0, v0, a)."""
    c = np.polyfit(t, s, 2)
    return c[2], c[1], 2.0 * c[0]


def fit_harmonic(t, x, omega):
    """Least-squares x = c0 + c1 t + B cos(w t) + C sin(w t); returns (c0, c1, B, C)."""
    a = np.stack([np.ones_like(t), t, np.cos(omega * t), np.sin(omega * t)], axis=1)
    coef, *_ = np.linalg.lstsq(a, x, rcond=None)
    return tuple(coef)


def rel(a, b) -> float:
    """Relative difference |a - b| / |b|."""
    return abs(a - b) / abs(b)
