"""The granular temperature's balance after each step, compiled: the pieces the formulations'
fused loops with the temperature (mpm/temperature_loop.py, eulerian/temperature_loop.py) run
between their mechanical steps, so that many steps with T make one compiled call.

They are temperature_field.py's step-by-step path (`point_step`, `cell_step`,
`advance_with_temperature`'s kinetic stress) in numba, term for term in the same order of
operations: the points binned to the balance's cells in point order (np.bincount's order), the
cells' balance (temperature_step.step_temperature_walls with wall_energy_flux.cell_wall_terms),
each point's T scaled by its cell's T_new / T_old.  They run serially, so the numbers do not
depend on the number of threads (docs/decisions/granular-temperature-closures.md, "Cost", for
what they cost).

`TemperatureStep` is a run's TemperatureModel (temperature_field.py) as a numba record, with the
caps of the kinetic stress that advance_with_temperature derives.
"""
from __future__ import annotations

import math
from collections import namedtuple

import numba as nb
import numpy as np

from .kinetic_stress import KINETIC_COLUMNS, RATE_RATIO, kinetic_stress, kinetic_stress_cells
from .temperature_step import TemperatureGrid, step_temperature_pressed
from .timestep import kinetic_temperature_limit
from .wall_energy_flux import cell_wall_terms

#: the balance's constants: prm (kinetic_theory.KineticParameters), grid (temperature_step.
#: TemperatureGrid), phi_cap (-) the connection packing rho_c / rho_s, T_cap (m^2/s^2) the
#: highest T the kinetic pressure reads, eta_factor (m^2/s) h^2 / dt of the gas viscosity's cap
#: (kinetic_stress.py), coupled (the kinetic stress on), walls (the walls' feed on),
#: restitution e_w (-), specularity (-), landing and columns (wall_energy_flux.WallEnergy),
#: dt (s)
TemperatureStep = namedtuple("TemperatureStep", [
    "prm", "grid", "phi_cap", "T_cap", "eta_factor", "coupled", "walls", "restitution",
    "specularity", "landing", "columns", "dt"])


def phi_cap_of(material) -> float:
    """The material's connection packing rho_c / rho_s (-), where the temperature's closures
    cap the solid fraction."""
    return material.critical_density / material.solid_density


def loop_arguments(system, n: int) -> tuple:
    """What a formulation's compiled multi-step call takes for the temperature, for a system
    (MPMSystem or EulerianSystem) of n points or cells: the kinetic stress's buffer (n,
    KINETIC_COLUMNS), and the TemperatureStep when the system carries T; without T an empty
    buffer alone (the loop without the balance)."""
    if system.temperature is None:
        return (np.empty((0, KINETIC_COLUMNS)),)
    return (np.zeros((n, KINETIC_COLUMNS)),
            temperature_step(system.temperature, phi_cap_of(system.material), system.dt,
                             system.material.p_wave_speed()))


def temperature_step(model, phi_cap: float, dt: float, wave_speed: float) -> TemperatureStep:
    """The TemperatureStep of a temperature_field.TemperatureModel for a material of
    connection packing phi_cap (-), the step dt (s) and the elastic wave speed (m/s) the step
    is set for (temperature_field.advance_with_temperature's caps)."""
    w = model.walls
    return TemperatureStep(
        model.params, TemperatureGrid(spacing_m=float(model.spacing_m)), float(phi_cap),
        float(kinetic_temperature_limit(wave_speed, phi_cap, model.params)),
        float(model.spacing_m ** 2 / dt if dt > 0 else math.inf), bool(model.coupled),
        w is not None, float(w.restitution) if w is not None else 0.0,
        float(w.specularity) if w is not None else 0.0,
        bool(w.landing) if w is not None else False,
        bool(w.columns) if w is not None else False, float(dt))


@nb.njit(cache=True)
def kinetic_stress_of(density, T, L, stress, gamma_dot, phase, ts, out):
    """out (N, 5): the granular temperature's stress and rate ratio before a step
    (kinetic_stress.kinetic_stress), or none (zero stress, ratio 1) when T is passive."""
    if ts.coupled:
        kinetic_stress(density, T, L, stress, gamma_dot, phase, ts.prm, ts.phi_cap, ts.T_cap,
                       ts.eta_factor, out)
        return
    _passive(out)


@nb.njit(cache=True)
def kinetic_stress_of_cells(density, mass, h, T, L, stress, gamma_dot, phase, ts, out):
    """`kinetic_stress_of` for Eulerian cells of side h (m) holding mass (N,) kg/m
    (kinetic_stress.kinetic_stress_cells: at the cell's solid fraction)."""
    if ts.coupled:
        kinetic_stress_cells(density, mass, h, T, L, stress, gamma_dot, phase,
                             ts.prm, ts.phi_cap, ts.T_cap, ts.eta_factor, out)
        return
    _passive(out)


@nb.njit(cache=True)
def _passive(out):
    """out (N, 5): no kinetic stress and the rate ratio 1 (T passive)."""
    for p in range(out.shape[0]):
        for c in range(4):
            out[p, c] = 0.0
        out[p, RATE_RATIO] = 1.0


@nb.njit(cache=True)
def balance_cells(T, phi, production, pressure, sums, ts):
    """The cells' T (m^2/s^2, (nx, nz)) after the step's balance for their solid fraction phi
    (-), production (W/m^3) and compressive mean stress pressure (Pa, the dense sliding loss's,
    read when ts.prm.sliding_coefficient > 0), with the walls' heating and loss from the cells'
    contact sums (nx, nz, 4) when ts.walls (temperature_field.cell_step).  Returns a new
    array."""
    zero = np.zeros_like(T)
    heat = zero
    cool = zero
    if ts.walls:
        heat, cool = cell_wall_terms(phi, T, sums, ts.grid.spacing_m, ts.restitution,
                                     ts.specularity, ts.landing, ts.grid.void_solid_fraction,
                                     ts.prm)
    return step_temperature_pressed(T, phi, production, heat, cool, zero, pressure, ts.dt,
                                    ts.grid, ts.prm)


@nb.njit(cache=True)
def balance_points(T, x, mass, volume, power, pressure, sums, x0, z0, nx, nz, ts):
    """The points' T (N,) m^2/s^2, in place, after the step's balance on the cells (nx, nz) of
    side ts.grid.spacing_m from (x0, z0) (m) (temperature_field.point_step): T binned
    mass-weighted, production power (N,) W/m^3 and compressive mean stress pressure (N,) Pa
    volume-weighted, phi = sum m / (rho_s h^2), each
    point's T scaled by its cell's T_new / T_old (T_new where T_old = 0).  mass kg/m, volume
    m^2; sums (N, 4) the points' wall contact terms (wall_energy_flux.contact_terms), read
    when ts.walls."""
    h = ts.grid.spacing_m
    n = nx * nz
    npt = T.shape[0]
    idx = np.empty(npt, np.int64)
    M = np.zeros(n)
    E = np.zeros(n)
    P = np.zeros(n)
    Pr = np.zeros(n)
    S = np.zeros((n, 4))
    for p in range(npt):
        i = min(max(np.int64(math.floor((x[p, 0] - x0) / h)), 0), nx - 1)
        k = min(max(np.int64(math.floor((x[p, 1] - z0) / h)), 0), nz - 1)
        c = i * nz + k
        idx[p] = c
        M[c] += mass[p]
        E[c] += mass[p] * T[p]
        P[c] += power[p] * volume[p]
        Pr[c] += pressure[p] * volume[p]
        if ts.walls:
            for j in range(4):
                S[c, j] += sums[p, j]
    hh = h * h
    rho = ts.prm.density_kg_m3
    T_old = np.zeros(n)
    phi = np.empty(n)
    for c in range(n):
        P[c] /= hh
        Pr[c] /= hh
        if M[c] > 0.0:
            T_old[c] = E[c] / M[c]
        phi[c] = M[c] / (rho * h * h)
    T_new = balance_cells(T_old.reshape((nx, nz)), phi.reshape((nx, nz)),
                          P.reshape((nx, nz)), Pr.reshape((nx, nz)), S.reshape((nx, nz, 4)),
                          ts).ravel()
    for p in range(npt):
        c = idx[p]
        if T_old[c] > 0.0:
            T[p] *= T_new[c] / T_old[c]
        else:
            T[p] = T_new[c]
