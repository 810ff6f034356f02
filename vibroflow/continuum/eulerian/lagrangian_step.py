"""The Lagrangian step on the fixed mesh: forces, nodal momentum, stress.

With the material at the fixed cells (mesh.py), one explicit step of the elasto-plastic
continuum, the same operations as the material point method's step (vibroflow.continuum.mpm),
with its kernels:

1. forces on the cells: the wall's penalty contact with Coulomb friction (wall.py) and the
   partitions' friction as a body force (boundary.partition_forces, on the cell's material
   volume);
2. cells to nodes: mass, APIC momentum, the stress divergence f_i = -sum_p V_p sigma_p grad w_ip
   (p2g.py; V_p = f h^2 the cell's material volume), quadratic B-splines;
3. node velocity update with gravity and the tub frame's inertial forces (grid_update.py, the
   frame's motion at mid-step);
4. nodes to cells: velocity, APIC affine matrix, velocity gradient L (g2p.py; the cells stay
   where they are: the motion is the remap's business, advection.py); the face velocities of
   the remap, and the trace of L made the finite-volume divergence of those
   (advection.match_divergence: the wall's closed faces); in a partly filled cell the volume
   change goes to its empty part first (void_first);
5. the material's density rho <- rho / det(I + dt L) (the material's own strain: a mixed
   cell's material takes its cell's shear and expansion, and its compression once the void is
   closed) and its stress through the shared constitutive law
   (constitutive.update_stress_points: Jaumann elastic predictor and the mu(I) or
   Drucker-Prager return map): material expanded below the critical density is disconnected
   (stress-free, Dunatunga & Kamrin 2015), which is how the bed's flight works.
"""
from __future__ import annotations

import numba as nb
import numpy as np

from ..boundary import partition_forces
from ..constitutive import update_stress_points
from ..g2p import g2p
from ..grid_update import grid_update
from ..p2g import p2g
from .advection import face_velocities, match_divergence
from .wall import wall_forces


@nb.njit(cache=True)
def material_fraction(mass, density, h, frac, volume):
    """Volume fraction f = min(1, m / (rho h^2)) of each cell, rho its material's density
    (kg/m^3), and its material volume f h^2 (m^2)."""
    area = h * h
    for p in range(mass.shape[0]):
        if mass[p] > 0.0 and density[p] > 0.0:
            f = mass[p] / (density[p] * area)
            if f > 1.0:
                f = 1.0
        else:
            f = 0.0
        frac[p] = f
        volume[p] = f * area


@nb.njit(cache=True)
def void_first(L, frac, dt):
    """A partly filled cell that shrinks closes its empty part first (the void gives way, the
    material does not): with the cell's volumetric strain e = dt tr(L) < 0 and its empty share
    1 - f, the material's volumetric strain over the step is min(0, e + 1 - f) / f; the trace
    of L is replaced by that rate (split equally between L_xx and L_zz), so the stress update
    and the density see only the material's own compression.  A cell that expands expands its
    material too (which unloads its stress and, below the critical density, disconnects it:
    a void that opened without unloading the material would keep pushing its neighbours
    apart).  A full cell (f = 1) is unchanged."""
    for p in range(frac.shape[0]):
        f = frac[p]
        if f >= 1.0 or f <= 0.0:
            continue
        tr = L[p, 0] + L[p, 3]
        if tr >= 0.0:
            continue
        e = dt * tr
        em = e + 1.0 - f
        tr_m = em / (f * dt) if em < 0.0 else 0.0
        d = 0.5 * (tr_m - tr)
        L[p, 0] += d
        L[p, 3] += d


@nb.njit(cache=True)
def end_density(density, L, dt, out):
    """Density (kg/m^3) of each cell's material after the step, rho / det(I + dt L): the
    material's own strain, void_first)."""
    for p in range(density.shape[0]):
        J = (1.0 + dt * L[p, 0]) * (1.0 + dt * L[p, 3]) - dt * dt * L[p, 1] * L[p, 2]
        out[p] = density[p] / J


@nb.njit(cache=True)
def fill_limit(mass, density, h):
    """After the remap: a cell holds no more material than fills it, rho >= m / h^2 (the
    excess mass compresses the cell's material; f <= 1).  A cell the remap found empty has
    density 0 (advection.py) and stays empty (f = 0) whatever round-off mass it keeps."""
    area = h * h
    for p in range(mass.shape[0]):
        full = mass[p] / area
        if mass[p] > 0.0 and 0.0 < density[p] < full:
            density[p] = full


def lagrangian_step(system, state) -> None:
    """Steps 1-5 of the module docstring for system (solver.EulerianSystem) and state
    (solver.EulerianState), in place (the cells' v, C, L, stress, gamma_dot, phase; the
    wall's history)."""
    mesh = system.mesh
    g = mesh.grid
    dt = system.dt
    material_fraction(state.mass, state.density, mesh.h, state.frac, state.volume)
    state.fext[:] = 0.0
    w = system.wall
    if w is not None:
        hist = state.wall
        wall_forces(system.wall_cells, mesh.normal, state.v, state.mass,
                    system.material.critical_density, mesh.h,
                    hist["delta"], hist["xi"], state.fext, hist["fn"], hist["ft"],
                    hist["state"], w.stiffness, w.tangential_stiffness, w.damping_ratio,
                    w.friction, dt)
    if system.partitions is not None:
        pf = system.partitions
        partition_forces(state.v, state.mass, state.volume, state.stress, state.fext,
                         pf.friction, pf.length, dt)
    gm, gmv, gf, gv = system.work
    gm[:] = 0.0
    gmv[:] = 0.0
    gf[:] = 0.0
    # only the cells holding material take part: an empty cell adds exactly nothing to the
    # nodes, and its velocity is never used (the remap gives a filling cell what flows in)
    act = np.flatnonzero(state.mass > 0.0)
    x = system.x[act]
    v, C = state.v[act], state.C[act]
    p2g(x, v, C, state.mass[act], state.volume[act], state.stress[act], state.fext[act],
        g.x0, g.z0, g.dx, g.periodic, gm, gmv, gf)
    a0x, a0z, om, al, px, pz = system.frame.body(state.t + 0.5 * dt)
    grid_update(gm, gmv, gf, gv, g.x0, g.z0, g.dx, dt, a0x, a0z, om, al, px, pz, g.periodic)
    L = state.L[act]
    g2p(x, v, C, L, gv, g.x0, g.z0, g.dx, dt, g.periodic)  # x: a copy, the cells stay put
    state.v[act] = v
    state.C[act] = C
    state.L[act] = L
    face_velocities(gv, g.x0, g.z0, g.dx, g.periodic, mesh.xmin, mesh.zmin, mesh.h,
                    mesh.open_x, mesh.open_z, system.ux, system.uz)
    match_divergence(state.L, system.ux, system.uz, mesh.h, g.periodic)
    void_first(state.L, state.frac, dt)
    end_density(state.density, state.L, dt, system.density)
    update_stress_points(state.stress, state.L, system.density, dt, system.params,
                         state.gamma_dot, state.phase)
    state.density[:] = system.density
