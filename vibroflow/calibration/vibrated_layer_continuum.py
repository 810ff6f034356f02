"""The vibrated layer in a continuum: the DEM strip of calibration.vibrated_layer as a periodic
plane strip of either formulation, with the granular temperature on, measured as the DEM is.

The strip (benchmarks/floor_deformation.py's periodic strip): four nodes wide, periodic along x,
a penalty floor (stiffness (K + 4 G / 3) / (dx / 2), friction 0.2, damping ratio 0.16, as
that benchmark's) and no other wall, in the floor's own frame (continuum.grid_update.TubFrame
with the strip's vertical stroke alone), the calibration's material at the formulation's
defaults, node spacing dx (default the tub's, three ball diameters).  The bed holds the DEM
strip's mass per floor area: its depth is that mass / (rho_c x area), at rest and lithostatic
at the start.  The temperature (ContinuumOptions.temperature, temperature_field.py) starts at
`initial_T` and runs with the kinetic constants of the calibration's [kinetic] table (e,
phi_rcp, g0 form) where it has one, else the scenario's ball-ball restitution and kinetic
theory's default phi_rcp (continuum.kinetic_theory.KineticParameters): `kinetic_source` says
which.  The floor feeds T as the tub's wall does (continuum.wall_energy_flux.wall_energy_of:
Johnson & Jackson's slip terms and the landing).  Whatever balance of T the continuum carries (its production, conduction, dissipation,
walls) is what is measured.

The measures are measure.layer_profiles', sampled at the DEM's phases: the points' (cells')
T mass-weighted and their solid fraction (mass / rho_s over the band's width x height); the
floor force by the layer's momentum balance, F = M g + dP/dt with P = sum m (v_rel + v_floor)
the lab momentum (the floor is the strip's only wall), the mean over each step, binned by
the step's mid-phase (on tub47 a step is 1/72 of a cycle, a force bin 1/64).
"""
from __future__ import annotations

import math

import numpy as np

from vibroflow.continuum.boundary import Plane
from vibroflow.continuum.formulation import formulation
from vibroflow.continuum.grid import Grid
from vibroflow.continuum.grid_update import TubFrame
from vibroflow.continuum.kinetic_theory import KineticParameters
from vibroflow.continuum.material import material_for
from vibroflow.continuum.options import default_dx
from vibroflow.continuum.temperature_field import TemperatureModel
from vibroflow.continuum.timestep import stable_dt
from vibroflow.continuum.wall_energy_flux import wall_energy_of
from vibroflow.errors import InputError
from vibroflow.measure.layer_profiles import FORCE_BINS_PER_PHASE, LayerProfiles, floor_phase
from vibroflow.tub.motion import TubMotion

from .kinetic import G0_FORMS
from .vibrated_layer import G, LayerSetup, stroke

#: the strip's width in nodes
WIDTH_NODES = 4


def kinetic_constants(scenario, calibration) -> tuple[KineticParameters, str]:
    """(KineticParameters, source): the calibration's [kinetic] e, phi_rcp and g0 form where
    given, else the scenario's ball-ball restitution and the default phi_rcp."""
    from vibroflow.continuum.temperature_field import kinetic_parameters

    prm = kinetic_parameters(scenario)
    kin = getattr(calibration, "kinetic", None) if calibration is not None else None
    if kin is None or kin.phi_rcp is None:
        return prm, ("scenario ball-ball restitution, default phi_rcp "
                     f"{prm.phi_rcp:g} (no calibrated [kinetic])")
    upd = {"phi_rcp": float(kin.phi_rcp)}
    if kin.restitution is not None:
        upd["restitution"] = float(kin.restitution)
    if kin.g0_form is not None:
        if kin.g0_form not in G0_FORMS:
            raise InputError(f"[kinetic] g0_form = {kin.g0_form!r}: must be one of "
                             f"{', '.join(G0_FORMS)}")
        upd["g0_form"] = G0_FORMS[kin.g0_form]
    return prm._replace(**upd), "calibration [kinetic]"


def build(method: str, scenario, calibration, motion: TubMotion, bed_mass_kg_m2: float,
          dx: float, initial_T: float = 0.0):
    """(system, state, advance, rho_s, kinetic source) of one formulation's strip at rest."""
    opts = formulation(method).options(temperature=True, initial_temperature=float(initial_T))
    material = material_for(scenario, calibration, opts)
    prm, source = kinetic_constants(scenario, calibration)
    model = TemperatureModel(prm, float(dx), float(initial_T), walls=wall_energy_of(scenario))
    frame = TubFrame(motion, (0.0, -G))
    period = 1.0 / motion.frequency
    h = dx / 2
    width = WIDTH_NODES * dx
    depth = bed_mass_kg_m2 / material.critical_density
    kn = (material.bulk_modulus + 4.0 * material.shear_modulus / 3.0) / h
    top = 2.0 * depth + 2 * dx
    if method == "eulerian":
        from vibroflow.continuum.eulerian.mesh import EulerianMesh
        from vibroflow.continuum.eulerian.solver import EulerianSystem, advance, init_state
        from vibroflow.continuum.eulerian.wall import MeshWall

        mesh = EulerianMesh.box(0.0, width, 0.0, top, dx, periodic=True)
        wall = MeshWall(kn, friction=0.2, damping_ratio=0.16)
        dt = stable_dt(material, dx, h, [wall], v_max=2.0, cfl=opts.cfl)
        dt = period / (8 * math.ceil(period / 8 / dt))
        system = EulerianSystem(mesh, material, dt, frame=frame, wall=wall,
                                transfers=opts.transfers(), temperature=model)
        z = system.x[:, 1]
        filled = (z < depth) & mesh.inside
        rho_c = material.critical_density
        p = rho_c * G * np.clip(depth - z, 0.0, None)
        rho = rho_c * np.exp(p / material.bulk_modulus)
        stress = np.zeros((mesh.n, 4))
        stress[:, [0, 1, 3]] = -(p * filled)[:, None]
        state = init_state(system, np.where(filled, rho * h * h, 0.0), rho, stress=stress)
    else:
        from vibroflow.continuum.mpm.column import column_points, lithostatic_state
        from vibroflow.continuum.mpm.solver import MPMSystem, advance

        walls = [Plane((0.0, 0.0), (0.0, 1.0), kn, friction=0.2, damping_ratio=0.16)]
        grid = Grid.periodic_strip(width, -dx, top, dx)
        dt = stable_dt(material, dx, h, walls, v_max=2.0, cfl=opts.cfl)
        dt = period / (8 * math.ceil(period / 8 / dt))
        system = MPMSystem(grid, material, dt, frame=frame, boundaries=walls,
                           transfers=opts.transfers(), temperature=model)
        x = column_points(0.0, width, depth, h)
        state = lithostatic_state(system, x, np.full(len(x), depth))
    return system, state, advance, float(prm.density_kg_m3), source


def continuum_layer(method: str, scenario, calibration, setup: LayerSetup,
                    bed_mass_kg_m2: float, dx: float | None = None,
                    initial_T: float = 0.0) -> dict:
    """The strip's profiles (LayerProfiles.result, phases of the floor's cycle) for one
    formulation, with the run's dt, node spacing and the kinetic constants' source."""
    setup.check()
    if method not in ("lagrangian", "eulerian"):
        raise InputError(f"method = {method!r}: must be lagrangian or eulerian")
    f, amp, phase = stroke(scenario, setup.gamma)
    motion = TubMotion(frequency=f, amplitude_x=0.0, amplitude_z=amp, phase_z=phase,
                       amplitude_theta=0.0)
    dx = float(dx) if dx is not None else default_dx(scenario)
    system, state, advance, rho_s, source = build(method, scenario, calibration, motion,
                                                  bed_mass_kg_m2, dx, initial_T)
    dt = system.dt
    omega = 2 * math.pi * f
    P = setup.n_phases
    width = WIDTH_NODES * dx
    depth = bed_mass_kg_m2 / system.material.critical_density
    n_bands = int(math.ceil(3 * depth / setup.band_m)) + 1
    acc = LayerProfiles(P, n_bands, setup.band_m, setup.batches, width)
    c0 = math.floor(phase / (2 * math.pi)) + 1
    sub = FORCE_BINS_PER_PHASE

    def step_of(c, k):
        return int(round(((c0 + c + k / (P * sub)) * 2 * math.pi - phase) / omega / dt))

    def momentum():
        t = state.step * dt
        m = state.mass
        return float(np.sum(m * state.v[:, 1]) + m.sum() * amp * omega
                     * math.cos(omega * t + phase)), float(m.sum())

    advance(system, state, step_of(setup.warm_cycles, 0) - state.step)
    for c in range(setup.cycles):
        batch = c * setup.batches // setup.cycles
        for k in range(P * sub):
            if k % sub == 0:
                has = state.mass > 0
                acc.add_field(batch, k // sub, state.x[has, 1], state.mass[has],
                              state.mass[has] / rho_s, state.temperature[has])
            end = step_of(setup.warm_cycles + c, k + 1)
            while state.step < end:
                p0, m0 = momentum()
                advance(system, state, 1)
                p1, _ = momentum()
                t_mid = (state.step - 0.5) * dt
                acc.add_force(batch, float(floor_phase(t_mid, f, phase)),
                              1.0 + (p1 - p0) / (dt * m0 * G))
    out = acc.result()
    out.update(method=method, dt_s=float(dt), dx_m=dx, bed_depth_m=float(depth),
               kinetic_source=source)
    return out
