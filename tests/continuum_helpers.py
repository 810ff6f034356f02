"""Set-ups the continuum's tests share: point lattices, the spinning disc, the Eulerian layer
on a floor, the short tub47-quick runs."""
from __future__ import annotations

import math

import numpy as np

from vibroflow.continuum.constitutive import ContinuumMaterial
from vibroflow.continuum.grid import Grid
from vibroflow.continuum.grid_update import LabFrame
from vibroflow.continuum.mpm.solver import MPMSystem, init_state
from vibroflow.continuum.timestep import stable_dt

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

