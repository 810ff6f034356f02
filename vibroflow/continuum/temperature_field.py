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

Production sigma : D is what the stress does on the step's deformation: the plastic work
tau gamma_dot_p (the equivalent shear stress times the plastic shear rate stress_update.py
returns; the elastic part is stored, not dissipated) plus the work of the granular
temperature's own stress sigma_k : D (kinetic_stress.py: Lun's kinetic pressure, whose
-p_k tr D heats in compression and cools in expansion (Lun et al. 1984), and in the gas the
frictional pressure and the kinetic viscosity's 2 eta_k D' : D).  That stress is added to the
stress the grid sees (not stored in the elastic-plastic stress, as the bed viscosity's stress
is not), and the connected material's return map reads its inertial number from T
(kinetic_stress.py).

The grid's edges are zero-flux (a periodic direction included).  The walls feed energy in
through their contacts (wall_energy_flux.py: Johnson & Jackson's slip production and
collision loss, and the landing's inelastic normal jump), each contact's terms summed over its
cell (`point_step`, `cell_step`'s wall_sums) and the loss integrated with the dissipation.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numba as nb
import numpy as np

from vibroflow.scenario.checks import find_contact

from .kinetic_stress import KINETIC_COLUMNS, kinetic_stress, kinetic_stress_cells
from .kinetic_theory import G0_FORMS, KineticParameters
from .temperature_step import TemperatureGrid, step_temperature_pressed
from .timestep import kinetic_temperature_limit
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


def calibrated_kinetic_parameters(prm: KineticParameters, calibration) -> KineticParameters:
    """prm with the constants calibration.toml's [kinetic] measured on the DEM
    (vibroflow.calibration.kinetic): g0's form and phi_rcp, and Johnson & Jackson's frictional
    pressure (Fr, phi_min, n, p) where the cells resolved one (Fr > 0), and the dense sliding
    loss's k_f where the table asks for it (dense_dissipation = true, sliding_coefficient > 0);
    prm itself without a calibration or a [kinetic] table."""
    kin = getattr(calibration, "kinetic", None) if calibration is not None else None
    if kin is None:
        return prm
    k_f = kin.sliding_coefficient
    if kin.dense_dissipation and k_f is not None and math.isfinite(k_f) and k_f > 0:
        prm = prm._replace(sliding_coefficient=float(k_f))
    if kin.phi_rcp is None or not math.isfinite(kin.phi_rcp):
        return prm
    prm = prm._replace(phi_rcp=float(kin.phi_rcp),
                       g0_form=G0_FORMS.get(kin.g0_form or "chialvo_sundaresan", prm.g0_form))
    fr = kin.frictional_Pa
    if fr is not None and math.isfinite(fr) and fr > 0:
        prm = prm._replace(frictional_Pa=float(fr),
                           frictional_phi_min=float(kin.frictional_phi_min),
                           frictional_n=float(kin.frictional_n or 2.0),
                           frictional_p=float(kin.frictional_p or 5.0))
    return prm


def temperature_model(scenario, options, spacing_m: float,
                      calibration=None) -> TemperatureModel | None:
    """The run's TemperatureModel on cells of side spacing_m (m), its walls feeding energy
    in (wall_energy_flux.wall_energy_of, its landing counted along the columns with
    options.landing "columns"), or None when the option is off; the grains' constants from the
    calibration's [kinetic] table where it has one (calibrated_kinetic_parameters)."""
    if not options.temperature:
        return None
    prm = calibrated_kinetic_parameters(kinetic_parameters(scenario), calibration)
    walls = wall_energy_of(scenario)._replace(columns=options.landing == "columns")
    return TemperatureModel(prm, float(spacing_m), float(options.initial_temperature),
                            walls=walls)


@nb.njit(cache=True)
def add_stress(stress, s_kin, a, b):
    """stress[a:b] (Pa, [xx, zz, xz, yy]) plus the granular temperature's stress s_kin[a:b, :4]
    (Pa, kinetic_stress.kinetic_stress)."""
    for q in range(a, b):
        for c in range(4):
            stress[q, c] += s_kin[q, c]


@nb.njit(cache=True)
def production_W_m3(stress, L, gamma_dot, s_kin, out):
    """out = sigma : D (W/m^3) of the step: the plastic work tau gamma_dot_p plus the granular
    temperature's stress working on the step's rate of deformation, s_kin : D (module
    docstring); stress (N, 4) [xx, zz, xz, yy] Pa, L (N, 4 or 5) [xx, xz, zx, zz(, yy)] 1/s,
    gamma_dot (N,) 1/s, s_kin (N, >= 4) [xx, zz, xz, yy] Pa."""
    hoop = L.shape[1] > 4
    for p in range(stress.shape[0]):
        sxx, szz, sxz, syy = stress[p, 0], stress[p, 1], stress[p, 2], stress[p, 3]
        pm = -(sxx + szz + syy) / 3.0
        dxx, dzz, dyy = sxx + pm, szz + pm, syy + pm
        tau = np.sqrt(0.5 * (dxx * dxx + dzz * dzz + dyy * dyy) + sxz * sxz)
        work = (s_kin[p, 0] * L[p, 0] + s_kin[p, 1] * L[p, 3]
                + s_kin[p, 2] * (L[p, 1] + L[p, 2]) + (s_kin[p, 3] * L[p, 4] if hoop else 0.0))
        out[p] = tau * gamma_dot[p] + work


@nb.njit(cache=True)
def pressure_Pa(stress, out):
    """out = the compressive mean stress max(0, -(s_xx + s_zz + s_yy) / 3) (Pa) of stress (N, 4)
    [xx, zz, xz, yy] Pa: what the dense sliding loss reads (kinetic_theory)."""
    for p in range(stress.shape[0]):
        out[p] = max(0.0, -(stress[p, 0] + stress[p, 1] + stress[p, 3]) / 3.0)


def cell_step(T, phi, production, dt: float, model: TemperatureModel, wall_sums=None,
              pressure=None):
    """The cells' T (m^2/s^2, (nx, nz)) after dt (s) of the balance for their solid fraction
    phi (-) and production (W/m^3) (temperature_step.step_temperature_pressed), with the walls'
    heating and loss from the cells' contact sums wall_sums (nx, nz, 4)
    (wall_energy_flux.contact_terms) when the model has walls and they are given, and the
    dense sliding loss of the cells' compressive mean stress pressure (nx, nz) Pa when given."""
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
    pr = zero if pressure is None else np.ascontiguousarray(pressure, dtype=float)
    return step_temperature_pressed(T, phi, np.ascontiguousarray(production, dtype=float), heat,
                                    cool, zero, pr, float(dt), model.grid, model.params)


def point_cells(x, x0: float, z0: float, h: float, shape) -> np.ndarray:
    """The flat index (i nz + k) of the cell of side h (m) from (x0, z0) (m) holding each
    point of x (N, 2) m, clipped to the shape (nx, nz)."""
    nx, nz = shape
    i = np.clip(np.floor((x[:, 0] - x0) / h).astype(np.int64), 0, nx - 1)
    k = np.clip(np.floor((x[:, 1] - z0) / h).astype(np.int64), 0, nz - 1)
    return i * nz + k


def point_step(T, x, mass, volume, power, origin, shape, dt: float, model: TemperatureModel,
               wall_sums=None, pressure=None):
    """The points' T (N,) m^2/s^2, in place, after dt (s) of the balance made on the cells of
    `shape` (nx, nz) from origin (x0, z0) (m) (module docstring): T binned mass-weighted,
    production power (N,) W/m^3 volume-weighted, phi = sum m / (rho_s h^2), each point's T
    scaled by its cell's T_new / T_old (set to T_new where T_old = 0).  mass kg/m, volume
    m^2; wall_sums (N, 4) the points' wall contact terms (wall_energy_flux.contact_terms),
    summed over each cell, or None; pressure (N,) Pa the points' compressive mean stress,
    binned volume-weighted as the production, or None."""
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
    Pr = None if pressure is None else np.bincount(idx, pressure * volume, n) / (h * h)
    T_new = cell_step(T_old.reshape(shape), phi.reshape(shape), P.reshape(shape), dt,
                      model, sums, None if Pr is None else Pr.reshape(shape)).ravel()
    warm = T_old[idx] > 0
    T[warm] *= T_new[idx[warm]] / T_old[idx[warm]]
    T[~warm] = T_new[idx[~warm]]


def advance_with_temperature(state, n, model: TemperatureModel | None, compiled, balance,
                             start=lambda s_kin: None, *, phi_cap: float = 1.0,
                             dt: float = 0.0, wave_speed: float = math.inf,
                             cells: float = 0.0) -> None:
    """n steps of a formulation, the step-by-step path (the solvers' advance_stepwise; their
    advance runs the same balance inside the compiled loops, temperature_balance.py): without
    the temperature (model None), one compiled call of n steps (compiled(n, s_kin) with an
    empty (0, 5) s_kin); with it, one call a step: the
    granular temperature's stress and rate ratio (kinetic_stress.kinetic_stress, phi_cap the
    material's connection packing rho_c / rho_s, dt (s) the step, which with the cells' side
    caps the gas's viscosity, wave_speed (m/s) the elastic wave the step is set for, which caps
    the T of the kinetic pressure: timestep.kinetic_temperature_limit; with cells > 0 (m) the
    side of Eulerian cells, kinetic_stress_cells, at their solid fraction) scattered by that
    step,
    its production (W/m^3), then the formulation's balance of T (balance(power, start(s_kin)),
    start taken before the step, given the stress s_kin the step scatters)."""
    n = int(n)
    if n <= 0:
        return
    if model is None:
        compiled(n, np.empty((0, KINETIC_COLUMNS)))
        return
    s_kin = np.zeros((state.n, KINETIC_COLUMNS))
    power = np.empty(state.n)
    eta_factor = model.spacing_m ** 2 / dt if dt > 0 else np.inf
    T_cap = kinetic_temperature_limit(wave_speed, phi_cap, model.params)
    for _ in range(n):
        if model.coupled and cells > 0:
            kinetic_stress_cells(state.density, state.mass, float(cells),
                                 state.temperature, state.L, state.stress, state.gamma_dot,
                                 state.phase, model.params, float(phi_cap), float(T_cap),
                                 float(eta_factor), s_kin)
        elif model.coupled:
            kinetic_stress(state.density, state.temperature, state.L, state.stress,
                           state.gamma_dot, state.phase, model.params, float(phi_cap),
                           float(T_cap), float(eta_factor), s_kin)
        else:
            s_kin[:, :4] = 0.0
            s_kin[:, 4] = 1.0
        before = start(s_kin)
        compiled(1, s_kin)
        production_W_m3(state.stress, state.L, state.gamma_dot, s_kin, power)
        balance(power, before)


def fluctuation_energy_J_m(mass, T) -> float:
    """(3/2) sum m T (J per metre of thickness) of the points or cells."""
    return float(1.5 * np.sum(np.asarray(mass) * np.asarray(T)))
