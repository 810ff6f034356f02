"""The granular temperature carried by a continuum run (ContinuumOptions.temperature), the
part both formulations share.

T (m^2/s^2) lives where the formulation's mass lives: on each material point (mpm/solver.py)
or each Eulerian cell, advected with the cells' mass (eulerian/solver.py).  After each
mechanical step the balance of docs/models.md 5.7,

    (3/2) rho_s phi dT/dt = sigma : D - div (kappa grad T) - Gamma,

is made by temperature_step.step_temperature on a regular grid of square cells: the
points' mass and fluctuation energy binned to the grid's cells (mass-weighted) and brought
back by the ratio of the cell's new to its old temperature, which keeps each point's T >= 0
and the binned energy (3/2) sum m T exactly; the Eulerian cells are that grid already.

Production sigma : D is what the stress update's stress does on the step's deformation:
the plastic work tau gamma_dot_p (the equivalent shear stress times the plastic shear rate
stress_update.py returns; the elastic part is stored, not dissipated) plus the kinetic
pressure's work -p_k tr D (compression heats, expansion cools: Lun et al. 1984).  The
kinetic pressure, Lun's p_k = rho_s phi T (1 + 2 (1 + e) phi g0) at the material's own
solid fraction phi = rho / rho_s, is added to the mean stress the grid sees where T > 0
(not stored in the elastic-plastic stress, as the bed viscosity's stress is not).

The grid's edges are zero-flux (a periodic direction included).  The walls feed energy in
through their contacts (wall_energy_flux.py: Johnson & Jackson's slip production and
collision loss, and the landing's inelastic normal jump), each contact's terms summed over its
cell (`point_step`, `cell_step`'s wall_sums) and the loss integrated with the dissipation.
"""
from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

from vibroflow.scenario.checks import find_contact

from .kinetic_theory import KineticParameters, pressure_Pa
from .temperature_step import TemperatureGrid, step_temperature_walls
from .wall_energy_flux import WallEnergy, cell_wall_terms, wall_energy_of


@dataclass(frozen=True)
class TemperatureModel:
    """What a run's temperature needs (SI): the grains' kinetic parameters, the cells'
    side spacing_m (m) of the balance's grid, the initial temperature initial_T (m^2/s^2),
    coupled: the kinetic pressure in the stress (default True; False carries T as a passive
    field, the balance alone, for its checks), and walls: the walls' feed of fluctuation
    energy (wall_energy_flux.WallEnergy; None: the walls are adiabatic)."""

    params: KineticParameters
    spacing_m: float
    initial_T: float = 0.0
    coupled: bool = True
    walls: WallEnergy | None = None

    @property
    def grid(self) -> TemperatureGrid:
        return TemperatureGrid(spacing_m=float(self.spacing_m))


def kinetic_parameters(scenario) -> KineticParameters:
    """The fill's balls as kinetic theory's grains: diameter (m), density (kg/m^3) and the
    ball-ball normal restitution of the scenario's contact law."""
    fill = scenario.fill
    pair = find_contact(scenario, fill.material, fill.material)
    return KineticParameters(diameter_m=float(fill.diameter),
                             density_kg_m3=float(scenario.materials[fill.material].density),
                             restitution=float(pair.restitution))


def temperature_model(scenario, options, spacing_m: float) -> TemperatureModel | None:
    """The run's TemperatureModel on cells of side spacing_m (m), its walls feeding energy
    in (wall_energy_flux.wall_energy_of), or None when the option is off."""
    if not options.temperature:
        return None
    return TemperatureModel(kinetic_parameters(scenario), float(spacing_m),
                            float(options.initial_temperature), walls=wall_energy_of(scenario))


@nb.njit(cache=True)
def kinetic_pressure(density, T, prm, coupled, out):
    """out = Lun's pressure (Pa) at phi = density / rho_s where T > 0, else 0 (everywhere 0
    when not coupled); density (N,) kg/m^3, T (N,) m^2/s^2."""
    for p in range(T.shape[0]):
        if coupled and T[p] > 0.0 and density[p] > 0.0:
            out[p] = pressure_Pa(density[p] / prm.density_kg_m3, T[p], prm)
        else:
            out[p] = 0.0


@nb.njit(cache=True)
def add_pressure(stress, p, a, b):
    """stress[a:b] (Pa, [xx, zz, xz, yy]) minus the pressure p[a:b] (Pa) on its normal parts."""
    for q in range(a, b):
        stress[q, 0] -= p[q]
        stress[q, 1] -= p[q]
        stress[q, 3] -= p[q]


@nb.njit(cache=True)
def production_W_m3(stress, L, gamma_dot, p_kin, out):
    """out = sigma : D (W/m^3) of the step: the plastic work tau gamma_dot_p plus the kinetic
    pressure's -p_k tr D (module docstring); stress (N, 4) [xx, zz, xz, yy] Pa, L (N, 4 or 5)
    [xx, xz, zx, zz(, yy)] 1/s, gamma_dot (N,) 1/s, p_kin (N,) Pa."""
    hoop = L.shape[1] > 4
    for p in range(stress.shape[0]):
        sxx, szz, sxz, syy = stress[p, 0], stress[p, 1], stress[p, 2], stress[p, 3]
        pm = -(sxx + szz + syy) / 3.0
        dxx, dzz, dyy = sxx + pm, szz + pm, syy + pm
        tau = np.sqrt(0.5 * (dxx * dxx + dzz * dzz + dyy * dyy) + sxz * sxz)
        tr = L[p, 0] + L[p, 3] + (L[p, 4] if hoop else 0.0)
        out[p] = tau * gamma_dot[p] - p_kin[p] * tr


def cell_step(T, phi, production, dt: float, model: TemperatureModel, wall_sums=None):
    """The cells' T (m^2/s^2, (nx, nz)) after dt (s) of the balance for their solid fraction
    phi (-) and production (W/m^3) (temperature_step.step_temperature_walls), with the walls'
    heating and loss from the cells' contact sums wall_sums (nx, nz, 4)
    (wall_energy_flux.contact_terms) when the model has walls and they are given."""
    T = np.ascontiguousarray(T, dtype=float)
    phi = np.ascontiguousarray(phi, dtype=float)
    zero = np.zeros_like(T)
    heat, cool = zero, zero
    w = model.walls
    if w is not None and wall_sums is not None:
        heat, cool = cell_wall_terms(phi, T, np.ascontiguousarray(wall_sums, dtype=float),
                                     float(model.spacing_m), float(w.restitution),
                                     float(w.specularity), bool(w.landing),
                                     model.grid.void_solid_fraction, model.params)
    return step_temperature_walls(T, phi, np.ascontiguousarray(production, dtype=float), heat,
                                  cool, zero, float(dt), model.grid, model.params)


def point_cells(x, x0: float, z0: float, h: float, shape) -> np.ndarray:
    """The flat index (i nz + k) of the cell of side h (m) from (x0, z0) (m) holding each
    point of x (N, 2) m, clipped to the shape (nx, nz)."""
    nx, nz = shape
    i = np.clip(np.floor((x[:, 0] - x0) / h).astype(np.int64), 0, nx - 1)
    k = np.clip(np.floor((x[:, 1] - z0) / h).astype(np.int64), 0, nz - 1)
    return i * nz + k


def point_step(T, x, mass, volume, power, origin, shape, dt: float, model: TemperatureModel,
               wall_sums=None):
    """The points' T (N,) m^2/s^2, in place, after dt (s) of the balance made on the cells of
    `shape` (nx, nz) from origin (x0, z0) (m) (module docstring): T binned mass-weighted,
    production power (N,) W/m^3 volume-weighted, phi = sum m / (rho_s h^2), each point's T
    scaled by its cell's T_new / T_old (set to T_new where T_old = 0).  mass kg/m, volume
    m^2; wall_sums (N, 4) the points' wall contact terms (wall_energy_flux.contact_terms),
    summed over each cell, or None."""
    h = model.spacing_m
    n = shape[0] * shape[1]
    idx = point_cells(x, origin[0], origin[1], h, shape)
    M = np.bincount(idx, mass, n)
    E = np.bincount(idx, mass * T, n)
    P = np.bincount(idx, power * volume, n) / (h * h)
    T_old = np.divide(E, M, out=np.zeros(n), where=M > 0)
    phi = M / (model.params.density_kg_m3 * h * h)
    sums = None
    if wall_sums is not None:
        sums = np.stack([np.bincount(idx, wall_sums[:, j], n) for j in range(4)], axis=1)
        sums = sums.reshape(tuple(shape) + (4,))
    T_new = cell_step(T_old.reshape(shape), phi.reshape(shape), P.reshape(shape), dt,
                      model, sums).ravel()
    warm = T_old[idx] > 0
    T[warm] *= T_new[idx[warm]] / T_old[idx[warm]]
    T[~warm] = T_new[idx[~warm]]


def advance_with_temperature(state, n, model: TemperatureModel | None, compiled, balance,
                             start=lambda: None) -> None:
    """n steps of a formulation: without the temperature (model None), one compiled call of n
    steps (compiled(n, p_kin) with an empty p_kin); with it, one call a step: the kinetic
    pressure (Pa) of the state's T scattered by that step, its production (W/m^3), then the
    formulation's balance of T (balance(power, start()), start() taken before the step)."""
    n = int(n)
    if n <= 0:
        return
    if model is None:
        compiled(n, np.empty(0))
        return
    p_kin = np.empty(state.n)
    power = np.empty(state.n)
    for _ in range(n):
        kinetic_pressure(state.density, state.temperature, model.params, model.coupled, p_kin)
        before = start()
        compiled(1, p_kin)
        production_W_m3(state.stress, state.L, state.gamma_dot, p_kin, power)
        balance(power, before)


def fluctuation_energy_J_m(mass, T) -> float:
    """(3/2) sum m T (J per metre of thickness) of the points or cells."""
    return float(1.5 * np.sum(np.asarray(mass) * np.asarray(T)))
