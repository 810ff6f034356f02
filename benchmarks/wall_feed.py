"""The vibrating floor's feed of fluctuation energy: the landing source against a flux in U_w
and T, and both against the DEM's measured wall flux (docs/validation.md, section 22).

    python benchmarks/wall_feed.py [--cycles 35] [--skip 5] [--depth 0.05]
        [--method lagrangian|eulerian] [--columns] [--calibration CALIBRATION_TOML]

A layer of the default continuum material, `--depth` (m) deep and 4 cm wide (x-periodic),
rests on a frictional floor moved vertically as tub47's tub is, z = A (sin(omega t + pi/2) - 1),
A = 1.5 mm at 47 Hz (U_w = A omega = 0.44 m/s, 13.3 g), its granular temperature on and coupled
(temperature_field.py), the material point method (`--method lagrangian`, default) or the
Eulerian formulation on cells of the same side (`--method eulerian`).  Over the cycles after the first `--skip`,
it prints by eighth of the cycle (the tub's phase convention) and over the cycle, with the
batch-means standard error over five batches of whole cycles:

* the floor force over the layer's weight (zero: the layer is off the floor);
* the landing source (W/m^2 of floor): the inelastic normal jump's energy, which the run puts
  into T (wall_energy_flux.py): the penalty dashpot's power c v_n^2 at the floor (Lagrangian),
  the normal kinetic energy the step took from the floor cells approaching it and from the
  pairs of cells stopping each other where voids close, in the whole layer (Eulerian:
  wall_energy_flux.landing_terms, compaction_landing.py; with `--columns` the impulse through
  each z face along the columns, column_landing.py), the floor row's part printed apart;
* the flux form, Johnson & Jackson's wall law with the wall's mean squared normal velocity
  U_w^2 / 2 as the slip and phi' = 1, at the floor row's phi and T (Kumaran 1998's
  leading-order scaling rho_s phi g0 sqrt(T) U_w^2, net of the collision loss, e_w 0.8);
* the DEM's U-wall fluctuation flux: `--calibration`'s [kinetic.wall_flux]
  u_fluctuation_flux_W_m2, or tub47-quick's 274 +- 12 W/m^2 (issue 29) without one.
"""
from __future__ import annotations

import argparse
import math

import numpy as np

from vibroflow.continuum.boundary import Plane
from vibroflow.continuum.constitutive import ContinuumMaterial
from vibroflow.continuum.eulerian import solver as eulerian
from vibroflow.continuum.eulerian.mesh import EulerianMesh
from vibroflow.continuum.eulerian.wall import MeshWall
from vibroflow.continuum.grid import Grid
from vibroflow.continuum.grid_update import TubFrame
from vibroflow.continuum.kinetic_stress import KINETIC_COLUMNS
from vibroflow.continuum.kinetic_theory import KineticParameters
from vibroflow.continuum.mpm import solver as mpm
from vibroflow.continuum.temperature_balance import kinetic_stress_of_cells, temperature_step
from vibroflow.continuum.temperature_field import TemperatureModel
from vibroflow.continuum.timestep import stable_dt
from vibroflow.continuum.wall_energy_flux import (WallEnergy, collision_loss_W_m2,
                                                  slip_production_W_m2)
from vibroflow.io.calibration_file import read_calibration
from vibroflow.measure.stats import stderr_of_batches
from vibroflow.tub.motion import TubMotion

WIDTH, DX, FREQUENCY, AMPLITUDE, E_WALL = 0.04, 0.01, 47.0, 1.5e-3, 0.8


def lattice(depth, spacing):
    """Points on a square lattice filling [0, WIDTH] x [0, depth] (m)."""
    xs = np.arange(0.5 * spacing, WIDTH, spacing)
    zs = np.arange(0.5 * spacing, depth, spacing)
    X, Z = np.meshgrid(xs, zs, indexing="ij")
    return np.column_stack([X.ravel(), Z.ravel()])


def run(depth, cycles, method="lagrangian", columns=False):
    """Per step of the shaken layer: time (s), floor force (N/m), landing power per floor
    width (W/m^2), the floor row's T (m^2/s^2) and phi (-) (Eulerian: and the floor row's part
    of the landing, W/m^2); the layer's weight (N/m).  columns: the Eulerian landing along the
    columns (wall_energy_flux.WallEnergy)."""
    mat = ContinuumMaterial()
    sp = DX / 2
    kn = (mat.bulk_modulus + 4 * mat.shear_modulus / 3) / sp
    motion = TubMotion(frequency=FREQUENCY, amplitude_x=0.0, amplitude_z=AMPLITUDE,
                       phase_z=0.5 * math.pi, amplitude_theta=0.0)
    prm = KineticParameters(diameter_m=mat.diameter, density_kg_m3=mat.solid_density)
    if method == "eulerian":
        return run_eulerian(depth, cycles, mat, kn, motion, prm, columns)
    floor = Plane((0.0, 0.0), (0.0, 1.0), kn, friction=0.4)
    model = TemperatureModel(prm, DX, 1e-4, True, WallEnergy(restitution=E_WALL))
    system = mpm.MPMSystem(Grid.periodic_strip(WIDTH, 0.0, 3 * depth + 0.03, DX), mat,
                           stable_dt(mat, DX, sp, [floor]), frame=TubFrame(motion),
                           boundaries=[floor], temperature=model)
    state = mpm.init_state(system, lattice(depth, sp), sp * sp, mat.critical_density)
    rows = []
    for _ in range(cycles * int(round(1.0 / (FREQUENCY * system.dt)))):
        mpm.advance(system, state, 1)
        low = state.x[:, 1] < DX
        m = state.mass[low].sum()
        T = float((state.mass[low] * state.temperature[low]).sum() / m) if m > 0 else 0.0
        sums = mpm.point_wall_sums(system, state)
        rows.append((state.t, state.history[floor.slot]["fn"].sum(), sums[:, 3].sum() / WIDTH,
                     T, m / (mat.solid_density * WIDTH * DX)))
    return np.array(rows), 9.81 * state.mass.sum(), prm


def run_eulerian(depth, cycles, mat, kn, motion, prm, columns=False):
    """`run` in the Eulerian formulation: the layer on cells of side DX / 2 filled at the
    critical density, the mesh's floor wall (stiffness kn Pa/m, friction 0.4), its landing
    measured (eulerian.cell_wall_sums).  The floor force is the layer's momentum balance in the
    floor's frame, M (dv_z/dt + g + a_w), a_w the floor's acceleration at mid-step: the wall
    layer's penalty force is not the whole of it (its closed faces hold the material too)."""
    omega = 2.0 * math.pi * FREQUENCY
    mesh = EulerianMesh.box(0.0, WIDTH, 0.0, 3 * depth + 0.03, DX, periodic=True)
    wall = MeshWall(kn, friction=0.4)
    model = TemperatureModel(prm, mesh.h, 1e-4, True,
                             WallEnergy(restitution=E_WALL, columns=columns))
    system = eulerian.EulerianSystem(mesh, mat, stable_dt(mat, DX, mesh.h, [wall]),
                                     frame=TubFrame(motion), wall=wall, temperature=model)
    z = system.x[:, 1]
    fill = mesh.inside & (z < depth)
    state = eulerian.init_state(system, np.where(fill, mat.critical_density * mesh.h ** 2, 0.0))
    floor = system.wall_cells[mesh.normal[system.wall_cells, 1] > 0.5]
    low = z < DX
    ts = temperature_step(model, mat.critical_density / mat.solid_density, system.dt,
                          mat.p_wave_speed())
    p_kin = np.zeros((state.n, KINETIC_COLUMNS))
    rows = []
    for _ in range(cycles * int(round(1.0 / (FREQUENCY * system.dt)))):
        # the stress the step scatters, the kinetic one as the run's loop computes it
        kinetic_stress_of_cells(state.density, state.mass, mesh.h, state.temperature,
                                state.L, state.stress, state.gamma_dot, state.phase, ts, p_kin)
        start = (state.mass.copy(), state.v.copy(), state.density.copy(),
                 state.stress + p_kin[:, :4])
        p0 = float(state.mass @ state.v[:, 1])
        eulerian.advance(system, state, 1)
        t_mid = state.t - 0.5 * system.dt
        a_w = -AMPLITUDE * omega ** 2 * math.sin(omega * t_mid + 0.5 * math.pi)
        force = (float(state.mass @ state.v[:, 1]) - p0) / system.dt \
            + state.mass.sum() * (9.81 + a_w)
        m = state.mass[low].sum()
        T = float((state.mass[low] * state.temperature[low]).sum() / m) if m > 0 else 0.0
        sums = eulerian.cell_wall_sums(system, state, start)
        rows.append((state.t, force, sums[:, 3].sum() / WIDTH,
                     T, m / (mat.solid_density * WIDTH * DX), sums[floor, 3].sum() / WIDTH))
    return np.array(rows), 9.81 * state.mass.sum(), prm


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cycles", type=int, default=35)
    ap.add_argument("--skip", type=int, default=5)
    ap.add_argument("--depth", type=float, default=0.05)
    ap.add_argument("--method", choices=("lagrangian", "eulerian"), default="lagrangian")
    ap.add_argument("--columns", action="store_true",
                    help="the Eulerian landing along the columns (column_landing.py)")
    ap.add_argument("--calibration")
    a = ap.parse_args(argv)
    r, weight, prm = run(a.depth, a.cycles, a.method, a.columns)
    u_w = AMPLITUDE * 2 * math.pi * FREQUENCY
    flux_form = np.array([slip_production_W_m2(1.0, f, T, u_w / math.sqrt(2), prm)
                          - collision_loss_W_m2(E_WALL, f, T, prm) for T, f in r[:, 3:5]])
    cycle = np.floor(r[:, 0] * FREQUENCY + 1e-9).astype(int)
    eighth = np.floor((r[:, 0] * FREQUENCY % 1.0) * 8).astype(int)
    used = np.arange(a.skip, cycle.max() + 1)
    batch = np.array_split(used, 5)

    def cycle_mean(values, sel=None):
        keep = np.ones(len(values), bool) if sel is None else sel
        per = np.array([values[keep & np.isin(cycle, b)].mean() for b in batch])
        return per.mean(), float(stderr_of_batches(per))

    print(f"{a.method}: {len(used)} cycles, layer {a.depth} m, U_w = {u_w:.3f} m/s")
    shown = [("floor force / weight", r[:, 1] / weight), ("landing source W/m^2", r[:, 2]),
             ("flux form W/m^2", flux_form)]
    if r.shape[1] > 5:
        shown.append(("floor row's landing W/m^2", r[:, 5]))
    for name, v in shown:
        by = [cycle_mean(v, eighth == k) for k in range(8)]
        m, s = cycle_mean(v)
        print(f"{name:22s} mean {m:8.3g} +- {s:.2g}; by eighth: "
              + " ".join(f"{x:.3g}" for x, _ in by))
    dem, dem_se = 274.0, 12.0
    if a.calibration:
        wf = read_calibration(a.calibration).kinetic.wall_flux
        dem, dem_se = wf.u_fluctuation_flux_W_m2, wf.u_fluctuation_flux_stderr_W_m2
    print(f"DEM U-wall fluctuation flux {dem:.4g} +- {dem_se:.2g} W/m^2")


if __name__ == "__main__":
    main()
