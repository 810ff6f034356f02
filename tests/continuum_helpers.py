"""Set-ups the continuum's tests share: point lattices, the spinning disc, the Eulerian block
on a floor, the MPM layer shaken on a floor, the short tub47-quick runs."""
from __future__ import annotations

import math

import numpy as np

from vibroflow.continuum.constitutive import ContinuumMaterial
from vibroflow.continuum.eulerian import solver as eulerian
from vibroflow.continuum.eulerian.mesh import EulerianMesh
from vibroflow.continuum.eulerian.wall import MeshWall
from vibroflow.continuum.grid import Grid
from vibroflow.continuum.boundary import Plane
from vibroflow.continuum.grid_update import LabFrame, TubFrame
from vibroflow.continuum.kinetic_theory import KineticParameters
from vibroflow.continuum.mpm.solver import MPMSystem, advance, init_state
from vibroflow.continuum.temperature_field import TemperatureModel
from vibroflow.continuum.timestep import stable_dt
from vibroflow.continuum.wall_energy_flux import WallEnergy
from vibroflow.tub.motion import TubMotion

G_ACC = 9.81

#: the formulations' registry names (vibroflow.continuum.formulation.FORMULATIONS)
METHODS = ("lagrangian", "eulerian")

#: tub47-quick, three cycles, the last two averaged in two batches
THREE_CYCLES = ["run.duration=0.0639", "run.average_last=0.0426", "run.batches=2"]


def lattice(x0, x1, z0, z1, spacing):
    """Points on a square lattice of the given spacing filling [x0, x1] x [z0, z1] (m)."""
    xs = np.arange(x0 + spacing / 2, x1, spacing)
    zs = np.arange(z0 + spacing / 2, z1, spacing)
    X, Z = np.meshgrid(xs, zs, indexing="ij")
    return np.stack([X.ravel(), Z.ravel()], axis=1)


def spinning_compressed_disc(flip: float, transfers: int = 1):
    """A disc of radius 6 cm (dx = 5 mm, 2 x 2 points a cell) in free space, translating at
    (0.3, 0.1) m/s and spinning at 15 rad/s, pre-compressed to p0 = 20 kPa, elastic (mu_s = 2);
    returns (system, state, p0) with the system's FLIP fraction `flip` and its transfers a
    step."""
    mat = ContinuumMaterial(mu_s=2.0, mu_2=2.5)
    dx = 0.005
    sp = dx / 2
    grid = Grid.covering(-0.12, 0.12, -0.12, 0.12, dx)
    x = lattice(-0.06, 0.06, -0.06, 0.06, sp)
    x = x[np.hypot(x[:, 0], x[:, 1]) < 0.06]
    p0 = 2.0e4
    rho = mat.critical_density * math.exp(p0 / mat.bulk_modulus)
    omega = 15.0
    v = np.stack([0.3 - omega * x[:, 1], 0.1 + omega * x[:, 0]], axis=1)
    stress = np.zeros((len(x), 4))
    stress[:, [0, 1, 3]] = -p0
    system = MPMSystem(grid, mat, stable_dt(mat, dx, sp), frame=LabFrame((0.0, 0.0)), flip=flip,
                       transfers=transfers)
    return system, init_state(system, x, sp * sp, rho, v=v, stress=stress), p0



def eulerian_block(v, height, looseness=1.0, settled=False, mu_w=0.0, box_height=0.08,
                   dx=0.01, columns=False):
    """(system, state): an Eulerian block `height` (m) deep over a 4 cm x-periodic floor
    (cells of side dx / 2 in a box `box_height` (m) tall, the wall's friction mu_w), the
    default media made elastic (mu_s = 10: no plastic work), its T passive from 0 with no
    dissipation (e = e_w = 1, a smooth wall: specularity 0), moving at v (m/s): its material
    at `looseness` times the critical density, stress-free (below 1: voids to close), or
    settled at its lithostatic stress and density; columns: its landing counted along the
    columns (wall_energy_flux.WallEnergy), otherwise by the pairs."""
    mat = ContinuumMaterial(mu_s=10.0, mu_2=20.0)
    mesh = EulerianMesh.box(0.0, 0.04, 0.0, box_height, dx, periodic=True)
    h = mesh.h
    wall = MeshWall((mat.bulk_modulus + 4 * mat.shear_modulus / 3) / h, mu_w)
    prm = KineticParameters(diameter_m=mat.diameter, density_kg_m3=mat.solid_density,
                            restitution=1.0)
    model = TemperatureModel(prm, h, 0.0, False, WallEnergy(restitution=1.0, specularity=0.0,
                                                            columns=columns))
    system = eulerian.EulerianSystem(mesh, mat, stable_dt(mat, dx, h, [wall]),
                                     frame=LabFrame((0.0, -G_ACC)), wall=wall,
                                     temperature=model)
    z = system.x[:, 1]
    fill = mesh.inside & (z < height)
    rho = np.full(mesh.n, looseness * mat.critical_density)
    stress = np.zeros((mesh.n, 4))
    if settled:
        p = mat.critical_density * G_ACC * np.clip(height - z, 0.0, None) * fill
        rho = mat.critical_density * np.exp(p / mat.bulk_modulus)
        stress[:, 0] = stress[:, 1] = stress[:, 3] = -p
    state = eulerian.init_state(system, np.where(fill, rho * h * h, 0.0), rho, stress=stress)
    state.v[fill] = v
    return system, state


def shaken_mpm_layer(gamma, walls=(), temperature=None, cycles=1, frequency=47.0, dx=0.01):
    """A 3 cm MPM layer of the default media at its critical density, 4 cm wide (x-periodic),
    settled 20 ms on a floor (friction 0.4) beside the boundaries `walls`, then shaken
    vertically from t = 0 in the floor's frame, z_w = A sin(omega t), A omega^2 = gamma g, with
    the TemperatureModel `temperature` or none. Yields (phase, state, floor) after every step
    of the last of `cycles` cycles (phase = t f mod 1); the floor's normal forces (N/m) are
    state.history[floor.slot]["fn"]."""
    mat = ContinuumMaterial()
    omega = 2.0 * math.pi * frequency
    motion = TubMotion(frequency=frequency, amplitude_x=0.0, amplitude_z=gamma * G_ACC / omega**2,
                       phase_z=0.0, amplitude_theta=0.0)
    sp = dx / 2
    floor = Plane((0.0, 0.0), (0.0, 1.0), (mat.bulk_modulus + 4 * mat.shear_modulus / 3) / sp,
                  friction=0.4)
    bounds = [floor, *walls]
    grid = Grid.periodic_strip(0.04, 0.0, 0.12, dx)
    dt = stable_dt(mat, dx, sp, bounds)
    rest = MPMSystem(grid, mat, dt, frame=LabFrame((0.0, -G_ACC)), boundaries=bounds,
                     temperature=temperature)
    state = init_state(rest, lattice(0.0, 0.04, 0.0, 0.03, sp), sp * sp, mat.critical_density)
    advance(rest, state, int(round(0.02 / dt)))
    state.t = 0.0
    system = MPMSystem(grid, mat, dt, frame=TubFrame(motion), boundaries=bounds,
                       temperature=temperature)
    per_cycle = int(round(1.0 / (frequency * dt)))
    advance(system, state, per_cycle * (cycles - 1))
    for _ in range(per_cycle):
        advance(system, state, 1)
        yield (state.t * frequency) % 1.0, state, floor
