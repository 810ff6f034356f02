"""Circulation: the stream function of the cell-averaged solid-volume flux (tub47.md).

tub47.md, "What is measured": the stream function psi of q = phi v (phi the cell's solid
fraction, v its bulk velocity relative to the tub), with q_x = d psi/dz, q_z = -d psi/dx and
psi = 0 outside the bed.  Its extreme value is the circulation strength (m^2/s); psi > 0 at the
extreme means counterclockwise seen with x to the right and z up.  (Check: a solid-body rotation
v = Omega (-(z - z_c), x - x_c) with Omega > 0 is counterclockwise and has
psi = phi Omega (a^2 - r^2)/2 > 0 inside a disc of radius a.)

Method.  The time-averaged flux of a steady roll is divergence-free only up to noise, so psi is
the least-squares fit of the discrete relations between neighbouring cell centres,

    psi(i, k+1) - psi(i, k) =  h (q_x(i, k) + q_x(i, k+1)) / 2      (vertical neighbours)
    psi(i+1, k) - psi(i, k) = -h (q_z(i, k) + q_z(i+1, k)) / 2      (horizontal neighbours)

over every pair with at least one bed cell, with psi = 0 fixed on cells outside the bed.  The
normal equations are a 5-point Poisson problem lap psi = d q_x/dz - d q_z/dx with psi = 0
around the bed, solved directly with scipy.sparse.  The grid is padded with a ring of empty cells
so every bed is surrounded by psi = 0.

"Outside the bed" = cells whose solid fraction is below `bed_threshold` (default 0.05, i.e.
below about a twelfth of a dense packing: only a few flying balls).  The per-batch stream
functions (for the standard error by batch means) use the same bed as the whole window, so that
their extremes differ only by the flux; a batch's strength is the extreme of its psi in the
overall sense, and strength_stderr = std(batch strengths, ddof=1)/sqrt(n_batches) (stats.py).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from vibroflow.measure.bulk import CellTable
from vibroflow.measure.stats import stderr_of_batches

#: solid fraction below which a cell is outside the bed (psi = 0 there)
BED_THRESHOLD = 0.05


@dataclass
class Circulation:
    """Stream function and circulation strength (tub frame, SI).

    x (nx,), z (nz,) : cell-centre coordinates of the grid (m); psi (nz, nx) : stream function
    (m^2/s); bed (nz, nx) : cells inside the bed.  psi_extreme : psi at its largest |psi| (m^2/s,
    signed); strength = |psi_extreme| (m^2/s); sense : "counterclockwise" if psi_extreme > 0,
    "clockwise" if < 0 (x right, z up), "none" for no flow at all; extreme_x, extreme_z :
    where (m).  strength_stderr : batch-means standard error of the strength (m^2/s, NaN
    without batches); batch_strengths : (n_batches,) strengths of the batches.  residual : rms
    misfit of the least-squares relations over rms q (-): ~0 for a divergence-free flux, larger
    for a noisy or unsteady one.
    """

    x: np.ndarray
    z: np.ndarray
    psi: np.ndarray
    bed: np.ndarray
    psi_extreme: float
    strength: float
    sense: str
    extreme_x: float
    extreme_z: float
    strength_stderr: float
    batch_strengths: np.ndarray
    residual: float

    def as_dict(self) -> dict:
        """The summary keys: sense, strength, strength_stderr (m^2/s), plus psi_extreme."""
        return {"sense": self.sense, "strength": self.strength,
                "strength_stderr": self.strength_stderr, "psi_extreme": self.psi_extreme,
                "x": self.extreme_x, "z": self.extreme_z}


def _grid(ix, iz):
    """Padded dense grid covering integer cell indices; returns (i0, k0, nx, nz)."""
    i0, k0 = int(ix.min()) - 1, int(iz.min()) - 1
    nx, nz = int(ix.max()) - i0 + 2, int(iz.max()) - k0 + 2
    return i0, k0, nx, nz


def _scatter(values, ix, iz, i0, k0, nx, nz):
    g = np.zeros((nz, nx))
    g[iz - k0, ix - i0] = np.nan_to_num(np.asarray(values, dtype=float))
    return g


class _Solver:
    """Factorised least-squares operator for one bed mask on one grid."""

    def __init__(self, bed: np.ndarray, h: float):
        nz, nx = bed.shape
        self.bed, self.h = bed, h
        self.unknown = -np.ones(bed.shape, dtype=np.int64)
        self.unknown[bed] = np.arange(int(bed.sum()))
        n = int(bed.sum())
        rows, cols, vals = [], [], []
        # edges: (a, b) neighbour pairs with at least one bed end; relation psi_b - psi_a = g
        ka, ia = np.mgrid[0:nz, 0:nx - 1]
        horiz = (ka.ravel(), ia.ravel(), ka.ravel(), ia.ravel() + 1)
        ka, ia = np.mgrid[0:nz - 1, 0:nx]
        vert = (ka.ravel(), ia.ravel(), ka.ravel() + 1, ia.ravel())
        self.edges = []
        e0 = 0
        for kind, (k1, i1, k2, i2) in (("h", horiz), ("v", vert)):
            keep = bed[k1, i1] | bed[k2, i2]
            k1, i1, k2, i2 = k1[keep], i1[keep], k2[keep], i2[keep]
            m = k1.size
            e = np.arange(e0, e0 + m)
            u1, u2 = self.unknown[k1, i1], self.unknown[k2, i2]
            for u, sgn in ((u2, 1.0), (u1, -1.0)):
                ok = u >= 0
                rows.append(e[ok]); cols.append(u[ok]); vals.append(np.full(ok.sum(), sgn))
            self.edges.append((kind, k1, i1, k2, i2))
            e0 += m
        self.n_edges = e0
        self.D = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows),
                                                         np.concatenate(cols))),
                               shape=(e0, n))
        self.n = n
        self.solve_normal = spla.factorized(sp.csc_matrix(self.D.T @ self.D)) if n else None

    def rhs(self, qx: np.ndarray, qz: np.ndarray) -> np.ndarray:
        g = []
        for kind, k1, i1, k2, i2 in self.edges:
            if kind == "h":
                g.append(-0.5 * self.h * (qz[k1, i1] + qz[k2, i2]))
            else:
                g.append(0.5 * self.h * (qx[k1, i1] + qx[k2, i2]))
        return np.concatenate(g) if g else np.zeros(0)

    def psi(self, qx, qz):
        psi = np.zeros(self.bed.shape)
        g = self.rhs(qx, qz)
        if self.n == 0:
            return psi, 0.0
        sol = self.solve_normal(self.D.T @ g)
        psi[self.bed] = sol[self.unknown[self.bed]]
        misfit = self.D @ sol - g
        qrms = np.sqrt(np.mean(qx[self.bed] ** 2 + qz[self.bed] ** 2))
        res = float(np.sqrt(np.mean(misfit**2)) / self.h / qrms) if qrms > 0 else 0.0
        return psi, res


def stream_function(x, z, phi, vx, vz, cell_size: float,
                    bed_threshold: float = BED_THRESHOLD):
    """Stream function of q = phi v on cells (tub frame).

    x, z : (n,) cell centres (m), multiples of cell_size; phi (n,) solid fraction (-);
    vx, vz (n,) bulk velocity (m/s; NaN treated as 0).  Returns (xg (nx,), zg (nz,),
    psi (nz, nx) in m^2/s, bed (nz, nx) bool, residual).  Cells missing from the input count as
    empty (phi = 0).
    """
    h = float(cell_size)
    ix = np.rint(np.asarray(x) / h).astype(np.int64)
    iz = np.rint(np.asarray(z) / h).astype(np.int64)
    i0, k0, nx, nz = _grid(ix, iz)
    phig = _scatter(phi, ix, iz, i0, k0, nx, nz)
    qx = _scatter(np.asarray(phi) * np.nan_to_num(vx), ix, iz, i0, k0, nx, nz)
    qz = _scatter(np.asarray(phi) * np.nan_to_num(vz), ix, iz, i0, k0, nx, nz)
    bed = phig >= bed_threshold
    psi, res = _Solver(bed, h).psi(qx, qz)
    return (np.arange(i0, i0 + nx) * h, np.arange(k0, k0 + nz) * h, psi, bed, res)


def circulation(table: CellTable, bed_threshold: float = BED_THRESHOLD) -> Circulation:
    """Circulation strength, sense and batch-means standard error of a cell table.

    See the module docstring (tub47.md "Circulation").  strength_stderr is NaN when the table
    has fewer than two batches (e.g. read back from CSV).
    """
    if len(table) == 0:
        raise ValueError("cell table is empty: no ball was counted in any cell")
    h = table.cell_size
    ix, iz = table.ix, table.iz
    i0, k0, nx, nz = _grid(ix, iz)
    phig = _scatter(table.solid_fraction, ix, iz, i0, k0, nx, nz)
    bed = phig >= bed_threshold
    solver = _Solver(bed, h)

    def flux(phi, vx, vz):
        phi = np.nan_to_num(np.asarray(phi, dtype=float))
        return (_scatter(phi * np.nan_to_num(vx), ix, iz, i0, k0, nx, nz),
                _scatter(phi * np.nan_to_num(vz), ix, iz, i0, k0, nx, nz))

    psi, res = solver.psi(*flux(table.solid_fraction, table.vx, table.vz))
    j = int(np.argmax(np.abs(psi)))
    kx, jx = np.unravel_index(j, psi.shape)
    ext = float(psi[kx, jx])
    sign = 1.0 if ext > 0 else -1.0
    batch_strengths = np.zeros(0)
    se = float("nan")
    if table.batch_vx is not None and table.n_batches >= 2:
        vals = []
        for b in range(table.n_batches):
            if not np.isfinite(table.batch_phi[b]).any():
                vals.append(np.nan)
                continue
            pb, _ = solver.psi(*flux(table.batch_phi[b], table.batch_vx[b], table.batch_vz[b]))
            vals.append(float(np.max(sign * pb)))
        batch_strengths = np.array(vals)
        se = float(stderr_of_batches(batch_strengths))
    xg = np.arange(i0, i0 + nx) * h
    zg = np.arange(k0, k0 + nz) * h
    return Circulation(x=xg, z=zg, psi=psi, bed=bed, psi_extreme=ext, strength=abs(ext),
                       sense=("counterclockwise" if ext > 0 else "clockwise" if ext < 0
                              else "none"),
                       extreme_x=float(xg[jx]), extreme_z=float(zg[kx]), strength_stderr=se,
                       batch_strengths=batch_strengths, residual=res)
