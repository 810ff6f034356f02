"""Many MPM steps with the granular temperature in one numba call.

Each step is the step-by-step path's (temperature_field.advance_with_temperature with
solver.py's balance) made without leaving compiled code: the granular temperature's stress
from the points' state (temperature_balance.kinetic_stress_of), one step of the fused
mechanical loop (fused.advance_kernel, its point chunks and threads as without T), the
production sigma : D (temperature_field.production_W_m3), the walls' contact terms
(`point_wall_sums`, solver.point_wall_sums compiled) and the balance on the grid's cells
(temperature_balance.balance_points).  T is state carried through the loop as the mechanical
fields are, so a call of n steps costs n mechanical steps and n balances, without the Python
round trip per step that made T cost 3 times the step on tub47-quick.

The balance's part runs serially after the step's parallel loops: its numbers depend on
nothing but the state (the mechanical step's depend on the point chunks, never on the threads).
"""
from __future__ import annotations

import numba as nb
import numpy as np

from ..boundary import PARTITIONS, PLANE_WALL, plane_motion
from ..fused import OK, advance_kernel
from ..temperature_balance import balance_points, kinetic_stress_of
from ..temperature_field import pressure_Pa, production_W_m3
from ..wall_energy_flux import contact_terms, partition_terms


@nb.njit(cache=True)
def point_wall_sums(records, hist, v, mass, volume, stress, t, dt, out, normal, v_rel, length):
    """out (N, 4): the points' wall contact terms of the step ending at t (s)
    (solver.point_wall_sums): each penalty wall's contacts (boundary records and stacked
    histories hist = (xi, f, fn, ft, state) of fused.Boundaries), the velocity relative to
    that wall, contact length sqrt(V_p), and the partitions'; normal, v_rel (N, 2) and length
    (N,) are scratch."""
    _, f, fn, ft, _ = hist
    out[:] = 0.0
    for p in range(volume.shape[0]):
        length[p] = np.sqrt(volume[p])
    for j in range(records.shape[0]):
        b = records[j]
        if b.kind == PARTITIONS:
            partition_terms(v, mass, volume, stress, b.friction, b.length, dt, out)
            continue
        q = b.hist
        wvx = 0.0
        wvz = 0.0
        if b.kind == PLANE_WALL:
            _, _, wvx, wvz = plane_motion(b.px, b.pz, b.vx, b.vz, b.ax, b.az, t)
        for p in range(volume.shape[0]):
            # the wall's unit normal from its force f = fn n + ft t (wall_energy_flux.
            # normal_of_force)
            a = fn[q, p]
            c = ft[q, p]
            if a > 0.0:
                r2 = a * a + c * c
                normal[p, 0] = (a * f[q, p, 0] - c * f[q, p, 1]) / r2
                normal[p, 1] = (c * f[q, p, 0] + a * f[q, p, 1]) / r2
            else:
                normal[p, 0] = 0.0
                normal[p, 1] = 0.0
            v_rel[p, 0] = v[p, 0] - wvx
            v_rel[p, 1] = v[p, 1] - wvz
        contact_terms(fn[q], ft[q], normal, v_rel, mass, length, b.kn, b.zeta, dt, out)


@nb.njit(cache=True)
def advance_temperature_kernel(nsteps, t, points, step, boundaries, grid, work, T, ts,
                               cells):
    """Up to nsteps MPM steps with the granular temperature T (N,) m^2/s^2 of the points, in
    place (module docstring); points, step, boundaries, grid, work as fused.advance_kernel's,
    points.p_kin (N, 5) the kinetic stress's array; ts a temperature_balance.TemperatureStep;
    cells = (x0, z0, nx, nz) the balance's cells (m, m, counts).

    Returns fused.advance_kernel's (steps done, t, status, boundary): on a status other than
    OK the step that found it had no balance made."""
    x = points.x
    v = points.v
    mass = points.mass
    volume = points.volume
    p_kin = points.p_kin
    x0, z0, nx, nz = cells
    npt = T.shape[0]
    power = np.empty(npt)
    pressure = np.zeros(npt)
    sliding = ts.prm.sliding_coefficient > 0.0
    sums = np.zeros((npt, 4))
    normal = np.zeros((npt, 2))
    v_rel = np.zeros((npt, 2))
    length = np.zeros(npt)
    hist = (boundaries.xi, boundaries.f, boundaries.fn, boundaries.ft, boundaries.state)
    for s in range(nsteps):
        kinetic_stress_of(points.density, T, points.L, points.stress, points.gamma_dot,
                          points.phase, ts, p_kin)
        # np.int64(1), not the literal 1: the kernel compiled for the solver's calls serves
        done, t, status, which = advance_kernel(np.int64(1), t, points, step, boundaries, grid,
                                                work)
        if status != OK:
            return s + done, t, status, which
        production_W_m3(points.stress, points.L, points.gamma_dot, p_kin, power)
        if sliding:
            pressure_Pa(points.stress, pressure)
        if ts.walls:
            point_wall_sums(boundaries.records, hist, v, mass, volume, points.stress, t, ts.dt,
                            sums, normal, v_rel, length)
        balance_points(T, x, mass, volume, power, pressure, sums, x0, z0, nx, nz, ts)
    return nsteps, t, OK, -1
