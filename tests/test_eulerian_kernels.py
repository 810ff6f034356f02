"""The Eulerian formulation's own kernels against the generic ones they stand in for.

The cells' scatter and gather (column_scatter.py, column_gather.py) and transfer operator
(operator_build.py) are each a pass along one axis and one along the other, with the B-spline
weights of the fixed cell centres read from tables made once a run; on any field they must give
what the material point method's p2g, g2p and operator_of_points give for points at those
centres, to roundoff (the sums are made in another order).  The face velocities are
the nodal field interpolated at the face midpoints, which g2p's velocity of a point there is.
The remap (advection.remap, flat and field by field) must give the numbers of the scheme's
face-by-face loop, written out plainly here (the module docstring of advection.py).  Random
fields on a closed box and on a mesh periodic along x, whose wrapped faces have their own code.
And the compiled loop with numba's parallel loops gives the serial loop's numbers.
"""
from __future__ import annotations

import dataclasses
import math

import numba
import numpy as np
import pytest

from vibroflow.continuum.bed import bed_area
from vibroflow.continuum.eulerian import solver as eul
from vibroflow.continuum.eulerian.advection import remap, remap_work
from vibroflow.continuum.eulerian.face_velocity import face_velocities
from vibroflow.continuum.eulerian.formulation import bed_masses
from vibroflow.continuum.eulerian.mesh import EulerianMesh
from vibroflow.continuum.eulerian.operator_build import (operator_columns, operator_rows,
                                                         operator_tables, operator_work)
from vibroflow.continuum.eulerian.column_gather import gather, gather_work
from vibroflow.continuum.eulerian.column_scatter import scatter, scatter_work
from vibroflow.continuum.eulerian.transfer import WeightTables, node_row_columns
from vibroflow.continuum.formulation import formulation
from vibroflow.continuum.g2p import g2p
from vibroflow.continuum.grid_update import TubFrame
from vibroflow.continuum.material import material_of
from vibroflow.continuum.p2g import p2g
from vibroflow.continuum.transfer_operator import HALF, expand, operator_of_points
from vibroflow.scenario.io import load_scenario
from vibroflow.tub.motion import TubMotion

NQ = 11


def _mesh(periodic):
    return EulerianMesh.box(0.0, 0.16, 0.0, 0.12, 0.02, periodic=periodic)


def _fields(mesh, seed):
    """Random cell fields; a third of the cells empty, as above a bed."""
    rng = np.random.default_rng(seed)
    n = mesh.n
    mass = np.where(rng.random(n) > 0.33, rng.random(n), 0.0)
    return (mass, rng.normal(size=(n, 2)), rng.normal(size=(n, 4)), rng.random(n) * 1e-4,
            rng.normal(size=(n, 4)) * 1e3, rng.normal(size=(n, 2)))


def _tables(mesh):
    t = WeightTables.of_mesh(mesh, mesh.centres())
    return (t.cx, t.cz, t.fx, t.fz)


def _ktop(mesh, mass):
    """The cell rows up to the highest cell holding material."""
    rows = np.flatnonzero((mass.reshape(mesh.ncx, mesh.ncz) > 0).any(axis=0))
    return int(rows[-1]) + 1 if rows.size else 0


def _close(a, b):
    scale = max(np.abs(b).max(), 1e-300)
    assert np.abs(a - b).max() <= 1e-14 * scale


@pytest.mark.parametrize("periodic", [False, True])
def test_cells_to_nodes_and_back_as_the_generic_transfers(periodic):
    mesh = _mesh(periodic)
    g = mesh.grid
    x = mesh.centres()
    mass, v, C, volume, stress, fext = _fields(mesh, 1)
    mass.reshape(mesh.ncx, mesh.ncz)[:, -3:] = 0.0  # the passes stop at the bed's top
    cells = np.flatnonzero(mass > 0)
    tx, tz = _tables(mesh)[:2]
    got, want = [np.full_like(a, np.nan) for a in g.zeros()[:3]], g.zeros()[:3]
    ktop = _ktop(mesh, mass)
    scatter(ktop, tx, tz, g.dx, node_row_columns(tx, g.nx, g.periodic), mass, volume, v, C,
            stress, fext, np.zeros(mesh.n), scatter_work(mesh.ncx, g.nz), *got)
    p2g(x[cells], v[cells], C[cells], mass[cells], volume[cells], stress[cells], fext[cells],
        g.x0, g.z0, g.dx, g.periodic, *want)
    for a, b in zip(got, want):
        _close(a, b)
    assert want[0].sum() == pytest.approx(mass.sum())  # the check is not vacuous
    gv = np.random.default_rng(2).normal(size=(g.nx, g.nz, 2))
    vg, Cg, Lg = np.zeros((mesh.n, 2)), np.zeros((mesh.n, 4)), np.zeros((mesh.n, 4))
    gather(ktop, tx, tz, _tables(mesh)[3], g.dx, g.periodic, gv, gather_work(g.nx, mesh.ncz),
           mass, vg, Cg, Lg)
    xw, vw, Cw, Lw = x[cells].copy(), v[cells].copy(), C[cells].copy(), np.zeros((cells.size, 4))
    g2p(xw, vw, Cw, Lw, gv, g.x0, g.z0, g.dx, 0.0, g.periodic, want[0], want[1], 0.0)
    _close(vg[cells], vw)
    _close(Cg[cells], Cw)
    _close(Lg[cells], Lw)
    empty = mass == 0
    assert not vg[empty].any() and not Cg[empty].any() and not Lg[empty].any()


@pytest.mark.parametrize("periodic", [False, True])
def test_transfer_operator_of_the_cells_is_that_of_points_at_their_centres(periodic):
    """The cells' transfer operator, built as a pass along the mesh's columns and one across
    them (operator_build.py), is transfer_operator.operator_of_points of points at the cell
    centres to roundoff, on a bed whose top cells are empty (the build stops at each column's
    top); and on the closed grid its rows sum to the node masses of the cells' scatter (the
    operator keeps a uniform velocity)."""
    mesh = _mesh(periodic)
    g = mesh.grid
    x = mesh.centres()
    mass = _fields(mesh, 4)[0]
    mass.reshape(mesh.ncx, mesh.ncz)[:, -3:] = 0.0
    cells = np.flatnonzero(mass > 0)
    tx, tz = _tables(mesh)[:2]
    op = operator_tables(tx, tz, g.dx)
    S, rows = operator_work(mesh.ncx, g.nx, g.nz)
    ktop = _ktop(mesh, mass)
    got, want = np.full((g.nx, g.nz, HALF), np.nan), np.zeros((g.nx, g.nz, HALF))
    operator_columns(0, mesh.ncx, ktop, mass.reshape(mesh.ncx, mesh.ncz), tz, op.zf, S)
    operator_rows(0, g.nx, ktop, tz, S, op.xf, *node_row_columns(tx, g.nx, g.periodic), rows,
                  got)
    operator_of_points(x[cells], mass[cells], g.x0, g.z0, g.dx, g.periodic, want)
    assert np.abs(want).max() > 0.1 * mass.max()  # the check is not vacuous
    _close(got, want)
    gm = g.zeros()[:3]
    scatter(_ktop(mesh, mass), tx, tz, g.dx, node_row_columns(tx, g.nx, g.periodic), mass,
            np.zeros(mesh.n), np.zeros((mesh.n, 2)), np.zeros((mesh.n, 4)),
            np.zeros((mesh.n, 4)), np.zeros((mesh.n, 2)), np.zeros(mesh.n),
            scatter_work(mesh.ncx, g.nz), *gm)
    if not periodic:  # (expand does not wrap the couplings across a periodic grid's ends)
        _close(expand(got).sum(axis=(2, 3)), gm[0])


@pytest.mark.parametrize("periodic", [False, True])
def test_face_velocities_are_the_nodal_field_at_the_face_midpoints(periodic):
    mesh = _mesh(periodic)
    g = mesh.grid
    gv = np.random.default_rng(3).normal(size=(g.nx, g.nz, 2))
    m = np.ones((mesh.ncx, mesh.ncz))  # every cell holds material: every open face counts
    ux, uz = np.zeros(mesh.open_x.shape), np.zeros(mesh.open_z.shape)
    face_velocities(gv, _tables(mesh), g.dx, g.periodic, mesh.open_x, mesh.open_z, m, ux, uz)

    def at(xs, zs, comp):
        pts = np.stack(np.broadcast_arrays(xs, zs), axis=-1).reshape(-1, 2).copy()
        v = np.zeros_like(pts)
        n = len(pts)
        g2p(pts, v, np.zeros((n, 4)), np.zeros((n, 4)), gv, g.x0, g.z0, g.dx, 0.0, g.periodic,
            np.zeros((g.nx, g.nz)), np.zeros((g.nx, g.nz, 2)), 0.0)
        return v[:, comp].reshape(np.broadcast_shapes(np.shape(xs), np.shape(zs)))

    h = mesh.h
    xf = mesh.xmin + np.arange(mesh.ncx + 1)[:, None] * h
    zc = mesh.zmin + (np.arange(mesh.ncz)[None, :] + 0.5) * h
    want_x = np.where(mesh.open_x, at(xf % (g.nx * g.dx) if periodic else xf, zc, 0), 0.0)
    xc = mesh.xmin + (np.arange(mesh.ncx)[:, None] + 0.5) * h
    zf = mesh.zmin + np.arange(mesh.ncz + 1)[None, :] * h
    want_z = np.where(mesh.open_z, at(xc, zf, 1), 0.0)
    _close(ux, want_x)
    _close(uz, want_z)
    assert np.abs(ux).max() > 0 and np.abs(uz).max() > 0


def _mc(a, b):
    """The monotonised-central limited slope of the one-sided differences a, b."""
    if a * b <= 0.0:
        return 0.0
    return math.copysign(min(abs(0.5 * (a + b)), 2.0 * min(abs(a), abs(b))), a + b)


def _remap_face_by_face(m, q, ux, uz, h, dt, open_x, open_z, periodic):
    """The scheme face by face (advection.py's module docstring), q (ncx, ncz, nq)."""
    ncx, ncz, nq = q.shape
    rho = m / (h * h)
    rho_empty = 1e-12 * rho.max()
    m_empty = rho_empty * h * h
    srx, srz = np.zeros_like(rho), np.zeros_like(rho)
    sqx, sqz = np.zeros_like(q), np.zeros_like(q)
    for i in range(ncx):
        il, ir = ((i - 1) % ncx, (i + 1) % ncx) if periodic else (i - 1, i + 1)
        for k in range(ncz):
            if rho[i, k] <= 0.0:
                continue
            okl, okr, okd, oku = open_x[i, k], open_x[i + 1, k], open_z[i, k], open_z[i, k + 1]
            srx[i, k] = _mc(rho[i, k] - rho[il, k] if okl else 0.0,
                            rho[ir, k] - rho[i, k] if okr else 0.0)
            srz[i, k] = _mc(rho[i, k] - rho[i, k - 1] if okd else 0.0,
                            rho[i, k + 1] - rho[i, k] if oku else 0.0)
            okl = okl and rho[il, k] > rho_empty
            okr = okr and rho[ir, k] > rho_empty
            okd = okd and rho[i, k - 1] > rho_empty
            oku = oku and rho[i, k + 1] > rho_empty
            for j in range(nq):
                sqx[i, k, j] = _mc(q[i, k, j] - q[il, k, j] if okl else 0.0,
                                   q[ir, k, j] - q[i, k, j] if okr else 0.0)
                sqz[i, k, j] = _mc(q[i, k, j] - q[i, k - 1, j] if okd else 0.0,
                                   q[i, k + 1, j] - q[i, k, j] if oku else 0.0)
    dm, dq = np.zeros_like(m), np.zeros_like(q)

    def flux(u, lo, hi, r, sr, sq):
        if u == 0.0:
            return
        c = abs(u) * dt / h
        up, sgn = (lo, 1.0) if u > 0.0 else (hi, -1.0)
        if r[up] <= rho_empty:
            return
        F = u * dt * h * (r[up] + sgn * 0.5 * (1.0 - c) * sr[up])
        dm[lo] -= F
        dm[hi] += F
        for j in range(nq):
            qf = q[up + (j,)] + sgn * 0.5 * (1.0 - c) * sq[up + (j,)]
            dq[lo + (j,)] -= F * qf
            dq[hi + (j,)] += F * qf

    for i in range(0 if periodic else 1, ncx):
        for k in range(ncz):
            flux(ux[i, k], ((i - 1) % ncx, k), (i, k), rho, srx, sqx)
    for i in range(ncx):
        for k in range(1, ncz):
            flux(uz[i, k], (i, k - 1), (i, k), rho, srz, sqz)
    lowest = np.inf
    for i in range(ncx):
        for k in range(ncz):
            mo, mn = m[i, k], m[i, k] + dm[i, k]
            lowest = min(lowest, mn)
            if mn > m_empty and mo > m_empty:
                q[i, k] = (mo * q[i, k] + dq[i, k]) * (1.0 / mn)
            elif mn > m_empty:
                q[i, k] = dq[i, k] * (1.0 / dm[i, k])
            else:
                q[i, k] = 0.0
            m[i, k] = mn
    return lowest


@pytest.mark.parametrize("periodic", [False, True])
def test_remap_gives_the_face_by_face_numbers(periodic):
    mesh = _mesh(periodic)
    rng = np.random.default_rng(4)
    s2 = (mesh.ncx, mesh.ncz)
    h = mesh.h
    m = np.where(rng.random(s2) > 0.3, rng.random(s2) * 4000 * h * h, 0.0)
    m[:, -2:] = 0.0  # an empty top, as above a bed
    m[rng.random(s2) < 0.1] *= 1e-13  # round-off masses: empty cells, which give nothing
    q = rng.normal(size=s2 + (NQ,)) * (m > 0)[..., None]
    ux = np.where(mesh.open_x & (rng.random(mesh.open_x.shape) > 0.2),
                  rng.normal(size=mesh.open_x.shape) * 0.3, 0.0)
    uz = np.where(mesh.open_z, rng.normal(size=mesh.open_z.shape) * 0.3, 0.0)
    work = remap_work(mesh.open_x, mesh.open_z, NQ)
    m_got, q_got = m.copy(), np.ascontiguousarray(np.moveaxis(q, 2, 0))
    m_want, q_want = m.copy(), q.copy()
    for _ in range(3):
        low = remap(m_got, q_got, ux, uz, h, 2e-3, periodic, work)
        low_want = _remap_face_by_face(m_want, q_want, ux, uz, h, 2e-3, mesh.open_x,
                                       mesh.open_z, periodic)
        assert low == low_want
    np.testing.assert_array_equal(m_got, m_want)
    np.testing.assert_array_equal(np.moveaxis(q_got, 0, 2), q_want)
    assert m_got.sum() == pytest.approx(m.sum(), rel=1e-13)
    assert np.abs(m_got - m).max() > 1e-3 * m.max()  # the material moved


@pytest.mark.slow
def test_parallel_loop_gives_the_serial_loops_numbers_on_one_thread_and_on_two():
    """The compiled loop with numba's parallel loops (forced on tub47-quick's small mesh,
    serial_below = 0) against the serial loop that small meshes use (solver.SERIAL_BELOW)."""
    scenario = load_scenario("tub47-quick", [])
    mat = material_of(scenario, None)
    frame = TubFrame(TubMotion.of_scenario(scenario))
    mesh_formulation = formulation("eulerian")
    base = mesh_formulation.make_system(scenario, mat, None, mesh_formulation.options(), frame)

    def run(threads, serial_below):
        if numba.config.NUMBA_NUM_THREADS < threads:
            pytest.skip(f"numba has fewer than {threads} threads here")
        system = dataclasses.replace(base, serial_below=serial_below)
        mass, density, stress, _ = bed_masses(system, bed_area(scenario, mat), 9.81)
        state = eul.init_state(system, mass, density, stress=stress)
        numba.set_num_threads(threads)
        try:
            eul.run_steps(system, state, 150)
        finally:
            numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
        return state

    serial = run(1, eul.SERIAL_BELOW)
    assert np.abs(serial.v).max() > 1e-3  # the bed moved: the check is not vacuous
    for threads in (1, 2):
        par = run(threads, 0)
        for f in ("mass", "v", "C", "L", "stress", "density", "gamma_dot", "phase"):
            np.testing.assert_array_equal(getattr(par, f), getattr(serial, f), err_msg=f)
