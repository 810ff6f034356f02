"""The remap on the rows that can hold material (remap_rows.py) against the whole mesh's.

The compiled loop transports the material over the rows up to one above the bed's top, on a
layout of their own; the cells above receive nothing in a step whose Courant numbers are below
one, so the numbers must be the whole mesh's remap's (advection.remap, itself checked against
the scheme's face-by-face loop in test_eulerian_kernels.py) bit for bit: on a closed box, a
mesh periodic along x and an axisymmetric section, for beds of several heights up to the lid
under round-off masses (empty cells, which give nothing), with the rows' layout refitted from
one height to the next, in one chunk of columns and in three.
"""
from __future__ import annotations

import numpy as np
import pytest

from vibroflow.continuum.eulerian.advection import remap, remap_fluxes_serial, remap_work
from vibroflow.continuum.eulerian.mesh import EulerianMesh
from vibroflow.continuum.eulerian.remap_rows import (bed_top, fit_rows, pack_cells,
                                                     pack_faces, renew_columns, rows_work)

NQ = 11


def _whole(mesh, radius, m, fields, ux, uz, dt):
    """advection.remap on every cell: the fields packed cell after cell, p = i ncz + k."""
    v, C, stress, rho = (f.copy() for f in fields)
    q = np.concatenate([v.T, C.T, stress.T, rho[None]]).reshape(NQ, mesh.ncx, mesh.ncz).copy()
    m2 = m.reshape(mesh.ncx, mesh.ncz).copy()
    work = remap_work(mesh.open_x, mesh.open_z, NQ, radius)
    lowest = remap(m2, q, ux, uz, mesh.h, dt, mesh.periodic, work)
    q = q.reshape(NQ, -1)
    return lowest, m2.ravel(), q[:2].T, q[2:6].T, q[6:10].T, q[10]


def _rows(mesh, rw, kc, m, fields, ux, uz, dt, chunks):
    """The compiled loop's remap: packed on the rows 0:kc, transported, renewed and unpacked in
    `chunks` chunks of columns."""
    ncx, ncz = mesh.ncx, mesh.ncz
    v, C, stress, rho = (f.copy() for f in fields)
    mass = m.copy()
    fit_rows(rw, kc, ncx, ncz)
    nr = ncx * kc
    qr = rw.q[:NQ * nr].reshape(NQ, nr)
    mr = rw.mass[:nr]
    pack_faces(0, ncx + 1, ux, kc, rw.ux)
    for c in range(chunks):
        pack_cells(c * mesh.n // chunks, (c + 1) * mesh.n // chunks, kc, ncz, v, C, stress,
                   rho.copy(), mass, qr, mr)
    work = rw.work
    remap_fluxes_serial(mr.reshape(ncx, kc), qr.reshape(NQ, ncx, kc),
                        rw.ux[:(ncx + 1) * kc].reshape(ncx + 1, kc), uz, mesh.h, dt,
                        mesh.periodic, work)
    lowest, finite = np.inf, True
    for c in range(chunks):
        low, ok = renew_columns(c * ncx // chunks, (c + 1) * ncx // chunks, kc, ncz, qr, mr,
                                work[9], work[6], work[0][4], work[0][3], v, C, stress, rho,
                                mass)
        lowest, finite = min(lowest, low), finite and ok
    assert finite
    return lowest, mass, v, C, stress, rho


@pytest.mark.parametrize("kind", ["closed", "periodic", "axisymmetric"])
def test_the_rows_remap_gives_the_whole_meshs_numbers(kind):
    mesh = EulerianMesh.box(0.02 if kind == "axisymmetric" else 0.0, 0.16, 0.0, 0.12, 0.01,
                            periodic=kind == "periodic")
    radius = None
    if kind == "axisymmetric":
        radius = (mesh.xmin + (np.arange(mesh.ncx) + 0.5) * mesh.h,
                  mesh.xmin + np.arange(mesh.ncx + 1) * mesh.h)
    ncx, ncz, h = mesh.ncx, mesh.ncz, mesh.h
    rng = np.random.default_rng(7)
    rw = rows_work(mesh.open_x, mesh.open_z, NQ, radius)
    dt = 2e-3
    for top in (5, ncz - 3, 2, ncz - 1, ncz, 7):
        # a bed whose highest row holding material is top - 1, some cells empty inside it,
        # and above it round-off masses: negative ones (the remap allows -1e-9 of a full cell)
        # and positive ones below EMPTY (1e-12) of a full cell, which count as empty
        m = np.where(rng.random((ncx, ncz)) > 0.2, rng.random((ncx, ncz)) * 2000 * h * h, 0.0)
        m[:, top - 1] = rng.random(ncx) * 2000 * h * h + 1e-3
        u = rng.random((ncx, ncz))
        m[u < 0.1] *= 1e-14
        m[:, top:] = np.where(u[:, top:] > 0.6, -1e-12, np.where(u[:, top:] > 0.3, 1e-16, 0.0))
        m = m.ravel()
        wc = np.repeat(radius[0], ncz) if radius is not None else np.ones(mesh.n)
        assert bed_top(m, ncx, ncz, h, wc) == top
        live = m > 0.0
        fields = (rng.normal(size=(mesh.n, 2)) * live[:, None] * 0.3,
                  rng.normal(size=(mesh.n, 4)) * live[:, None],
                  rng.normal(size=(mesh.n, 4)) * live[:, None] * 1e3,
                  (1500.0 + 500.0 * rng.random(mesh.n)) * live)
        ux = np.where(mesh.open_x, rng.normal(size=mesh.open_x.shape) * 0.3, 0.0)
        uz = np.where(mesh.open_z, rng.normal(size=mesh.open_z.shape) * 0.3, 0.0)
        want = _whole(mesh, radius, m, fields, ux, uz, dt)
        kc = min(top + 1, ncz)
        for chunks in (1, 3):
            got = _rows(mesh, rw, kc, m, fields, ux, uz, dt, chunks)
            assert got[0] == want[0]
            for g, w, name in zip(got[1:], want[1:], ("mass", "v", "C", "stress", "density")):
                np.testing.assert_array_equal(g, w, err_msg=f"{name}, bed top {top}")
        # the material moved, into row top too where the bed is not at the lid
        assert np.abs(got[1] - m).max() > 1e-3 * m.max()
        if top < ncz:
            assert (got[1].reshape(ncx, ncz)[:, top] > 0.0).any()
