"""The Lagrangian step on the fixed mesh: forces, nodal momentum, stress.

With the material at the fixed cells (mesh.py), one explicit step of the elasto-plastic
continuum, the same operations as the material point method's step (vibroflow.continuum.mpm),
with its kernels (run, with the remap, by fused.advance_kernel; this module holds the kernels
proper to the fixed mesh):

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
   (face_velocity.match_divergence: the wall's closed faces, which move with the material where it
   leaves the wall); a cell's volume change goes to its empty part first, both ways
   (void_first);
5. the material's density rho <- rho / det(I + dt L) (the material's own strain: a cell's
   material takes its cell's shear, its expansion down to the critical density and its
   compression once the void is closed) and its stress through the shared constitutive law
   (stress_update.update_stress_points: Jaumann elastic predictor and the mu(I) or
   Drucker-Prager return map): material below the critical density is disconnected
   (stress-free, Dunatunga & Kamrin 2015), which is how the bed's flight works.
"""
from __future__ import annotations

import numba as nb

from ..constitutive import P_RHO_C
from ..stress_update import update_stress_points_rated


@nb.njit(cache=True)
def material_fraction(mass, density, h, weight, frac, volume):
    """Volume fraction f = min(1, m / (rho h^2 w)) of each cell, rho its material's density
    (kg/m^3), and its material volume f h^2 w (m^2 per metre; m^3 per radian); w (N,) the
    cells' weights: 1 in plane strain, the radius of the cell's centre (m) in an axisymmetric
    section (solver.EulerianSystem.cell_weight)."""
    area = h * h
    for p in range(mass.shape[0]):
        cell = area * weight[p]
        if mass[p] > 0.0 and density[p] > 0.0:
            f = mass[p] / (density[p] * cell)
            if f > 1.0:
                f = 1.0
        else:
            f = 0.0
        frac[p] = f
        volume[p] = f * cell


#: the relative dilation below the critical density (-) of material whose cell opens a void
#: (void_first): far above round-off (1e-16), far below anything physical
OPEN_MARGIN = 1.0e-12


@nb.njit(cache=True)
def void_first(L, frac, density, rho_c, dt):
    """A cell's volume change goes to its empty part first, both ways.

    A cell's volumetric strain over the step is e = dt tr(L) (the finite-volume divergence,
    face_velocity.match_divergence); f its volume fraction, 1 - f its empty share, rho its
    material's density (kg/m^3), rho_c the critical density.  In a cell holding material
    (f > 0) the material's own volumetric strain e_m is

    * shrinking (e < 0): the void closes first, e_m = min(0, e + 1 - f) / f (the void gives
      way, the material does not; a full cell's material takes all of it, e_m = e);
    * growing (e > 0): the material unloads elastically down to the critical density, no
      further, e_m = min(e, rho / rho_c - 1 + OPEN_MARGIN) (>= 0); the rest opens the void.

    The trace of L is replaced by e_m / dt (split equally between L_xx and L_zz), so the stress
    update and the density see only the material's own strain (an axisymmetric section's
    hoop rate L[:, 4] counts in e and is left as it is).  Material that has opened a
    void sits a hair below rho_c (OPEN_MARGIN): disconnected, stress-free (Dunatunga & Kamrin
    2015), as dilated material is, until the void has closed and it is compressed again.

    Why both ways.  With the void closed first on shrinking but the material dilated first on
    growing, every cycle of the vibration would ratchet the partly filled cells' material
    looser: it would be dilated as the bed lifts off the floor or swells at its surface, and
    the next landing would close the cells' empty part without compacting it back.  In tub47
    (the vertical stroke alone) such a rule leaves the floor's cells at 0.6 and the surface's
    at 0.45 of the critical density, a stress-free cushion and skin that the bed's load
    bypasses through the nodes (tests/test_continuum_conservation.py, the vibrated bed's volume).
    A dilated state and a void are the same stress-free state of a cell's content (its mass
    over the volume m / rho_c it would fill at the critical density); one rule for every cell,
    full or not, keeps the step continuous as a cell fills (a rule that switches at f = 1 makes
    the run's round-off grow a thousand times faster: tests/test_continuum_threads.py)."""
    hoop = L.shape[1] > 4
    for p in range(frac.shape[0]):
        f = frac[p]
        if f <= 0.0:
            continue
        tr = L[p, 0] + L[p, 3]
        if hoop:
            # an axisymmetric section's hoop rate (face_velocity.match_divergence) is part of the
            # cell's volume change; the correction goes to the section's own two rates
            tr += L[p, 4]
        e = dt * tr
        if e < 0.0:
            em = e + 1.0 - f
            em = em / f if em < 0.0 else 0.0
        else:
            # down to a hair below rho_c (OPEN_MARGIN): material that has opened a void is
            # disconnected, not left on the knife-edge rho = rho_c where a round-off would
            # decide whether it is stressed (update_stress_cells)
            room = density[p] / rho_c - 1.0 + OPEN_MARGIN
            em = e if e < room else (room if room > 0.0 else 0.0)
        d = 0.5 * (em / dt - tr)
        L[p, 0] += d
        L[p, 3] += d


@nb.njit(cache=True)
def end_density(density, L, dt, out):
    """Density (kg/m^3) of each cell's material after the step, rho / det(I + dt L): the
    material's own strain, void_first; an axisymmetric section's with its hoop stretch
    1 + dt L[:, 4])."""
    hoop = L.shape[1] > 4
    for p in range(density.shape[0]):
        J = (1.0 + dt * L[p, 0]) * (1.0 + dt * L[p, 3]) - dt * dt * L[p, 1] * L[p, 2]
        if hoop:
            J *= 1.0 + dt * L[p, 4]
        out[p] = density[p] / J


@nb.njit(cache=True)
def fill_limit(mass, density, h, weight):
    """After the remap: a cell holds no more material than fills it, rho >= m / (h^2 w) (the
    excess mass compresses the cell's material; f <= 1; w the cells' weights, as
    material_fraction's).  A cell the remap found empty has density 0 (advection.py) and
    stays empty (f = 0) whatever round-off mass it keeps."""
    area = h * h
    for p in range(mass.shape[0]):
        full = mass[p] / (area * weight[p])
        if mass[p] > 0.0 and 0.0 < density[p] < full:
            density[p] = full


@nb.njit(cache=True)
def update_stress_cells(a, b, stress, L, density, dt, params, gamma_dot, state, rate_ratio):
    """stress_update.update_stress_points_rated (the arguments as there) on the cells a:b, with the
    cells whose end-of-step density is below the critical one (the empty cells, density 0, and
    the disconnected ones) given that kernel's result for them directly: stress 0, plastic
    rate 0, state 0 (stress_update.return_map's first branch, which discards the elastic
    predictor's trial stress).  A quarter of tub47's cells are empty at any time; the others
    go to the shared kernel in runs of consecutive cells."""
    rho_c = params[P_RHO_C]
    p = a
    while p < b:
        if density[p] < rho_c:
            for c in range(4):
                stress[p, c] = 0.0
            gamma_dot[p] = 0.0
            state[p] = 0
            p += 1
            continue
        e = p + 1
        while e < b and not density[e] < rho_c:
            e += 1
        update_stress_points_rated(stress[p:e], L[p:e], density[p:e], dt, params,
                                   gamma_dot[p:e], state[p:e], rate_ratio[p:e])
        p = e
