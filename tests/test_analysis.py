"""Tests of vibroflow.analysis against known answers (tub47.md "What is measured").

The lab-frame data are built here from the tub47 definition of the tub's motion (a tub point p
sits at P + Rot(theta)(p - P) + (X, Z)), written out independently of vibroflow.tub.motion, so
the analysis's use of the shared kinematics is checked, not just repeated.
"""
from __future__ import annotations

import json
import math
import xml.etree.ElementTree as ET

import h5py
import numpy as np
import pytest

from tests.vtk_reader import read_vtk
from vibroflow.errors import InputError
from vibroflow.analysis import field_difference, fields_agree, strengths_agree
from vibroflow.analysis.impact_maps import cycle_mean, speed_difference, speed_noise
from vibroflow.io import vtk
from vibroflow.measure import (CellTable, batch_means, batches_of_whole_cycles, cell_table,
                               circulation, impact_stats, probe_values, read_csv,
                               stream_function, tub_summary, wall_contact_stats, write_csv)
from vibroflow.analysis.compare import (bed_thirds, difference_by_region, difference_to_seeds,
                                        ensemble_mean, seed_scatter)
from vibroflow.measure.contacts import mean_by_region
from vibroflow.scenario.model import Scenario
from vibroflow.tub.geometry import TubGeometry, cross_section_area, distance_to_wall_np
from vibroflow.tub.motion import TubMotion, pose_np

PIVOT = (0.0, -0.10)


# ----------------------------------------------------------------------------------------------
# helpers: tub-frame state -> lab frame, from tub47.md "Tub motion"

def to_lab(p_tub, v_rel_tub, pose, pivot=PIVOT):
    """Lab position and velocity of balls at tub-frame positions p_tub (N, 3) moving with
    velocity v_rel_tub (N, 3) relative to the tub (tub axes), tub pose (X, Z, th, Xd, Zd, thd)."""
    X, Z, th, Xd, Zd, thd = pose
    c, s = math.cos(th), math.sin(th)
    rx, rz = p_tub[:, 0] - pivot[0], p_tub[:, 2] - pivot[1]
    # r = Rot(theta)(p - P) in lab axes
    Rx, Rz = c * rx - s * rz, s * rx + c * rz
    lab = p_tub.copy()
    lab[:, 0] = pivot[0] + Rx + X
    lab[:, 2] = pivot[1] + Rz + Z
    # d/dt of the above: (Xd, Zd) + thd (-Rz, Rx) + Rot(theta) v_rel
    v = v_rel_tub.copy()
    v[:, 0] = Xd - thd * Rz + c * v_rel_tub[:, 0] - s * v_rel_tub[:, 2]
    v[:, 2] = Zd + thd * Rx + s * v_rel_tub[:, 0] + c * v_rel_tub[:, 2]
    return lab, v


def rotation_velocity(p, omega, centre):
    """Solid-body rotation in x-z, counterclockwise for omega > 0: v = omega (-(z-zc), x-xc)."""
    v = np.zeros_like(p)
    v[:, 0] = -omega * (p[:, 2] - centre[1])
    v[:, 2] = omega * (p[:, 0] - centre[0])
    return v


def disc_lattice(centre, radius, spacing, y):
    """Square lattice of points (x, y, z) inside a disc in x-z, symmetric about the centre."""
    n = int(radius / spacing) + 1
    g = (np.arange(-n, n + 1) + 0.5) * spacing
    gx, gz = np.meshgrid(g, g, indexing="ij")
    inside = gx**2 + gz**2 <= radius**2
    p = np.zeros((inside.sum(), 3))
    p[:, 0] = gx[inside] + centre[0]
    p[:, 1] = y
    p[:, 2] = gz[inside] + centre[1]
    return p


def table_from_cells(x, z, phi, vx, vz, h):
    return CellTable(x=np.asarray(x, float), z=np.asarray(z, float),
                     solid_fraction=np.asarray(phi, float), vx=np.asarray(vx, float),
                     vz=np.asarray(vz, float), samples=np.ones(np.size(x), np.int64),
                     cell_size=h)


# ----------------------------------------------------------------------------------------------
# stats

def test_batches_of_whole_cycles_tub47_window():
    f, p = 47.0, 8
    t_start, t_end = 1.0, 3.0  # tub47: last 2.0 s of 3.0 s = 94 cycles
    # snapshots j/(p f) from t_start, including one exactly at t_end and a few before the window
    j = np.arange(-5, 94 * p + 1)
    t = t_start + j / (p * f)
    b = batches_of_whole_cycles(t, t_start, t_end, f, 4)
    assert np.all(b[j < 0] == -1)
    assert b[-1] == -1  # t_end is phase 0 of the next cycle
    counts = np.bincount(b[b >= 0])
    assert counts.tolist() == [24 * p, 23 * p, 24 * p, 23 * p]
    # every batch is whole cycles: each phase appears equally often within a batch
    phase = (j % p)[b >= 0]
    for k in range(4):
        assert np.all(np.bincount(phase[b[b >= 0] == k]) == counts[k] // p)
    # a window that is not a whole number of cycles drops the incomplete trailing cycle
    b2 = batches_of_whole_cycles(t, t_start, t_start + 10.5 / f, f, 2)
    assert (b2 >= 0).sum() == 10 * p


def test_batch_means_iid_normal_stderr_is_sigma_over_sqrt_n():
    rng = np.random.default_rng(7)
    sigma, S, nb, R = 2.0, 2000, 20, 400
    values = rng.normal(5.0, sigma, size=(S, R))  # R independent experiments side by side
    batch = np.repeat(np.arange(nb), S // nb)
    mean, se = batch_means(values, batch, nb)
    expected = sigma / math.sqrt(S)
    # the average estimated variance of the mean matches sigma^2/S within its sampling scatter
    assert np.sqrt(np.mean(se**2)) == pytest.approx(expected, rel=0.05)
    # and it is the actual scatter of the means across experiments
    assert np.std(mean - 5.0) == pytest.approx(expected, rel=0.1)
    # the grand mean is the plain sample mean
    assert np.allclose(mean, values.mean(axis=0))
    # scalar values
    m1, s1 = batch_means(values[:, 0], batch, nb)
    assert m1 == pytest.approx(values[:, 0].mean()) and s1 == pytest.approx(se[0])


# ----------------------------------------------------------------------------------------------
# bulk: kinematics and solid fraction

@pytest.mark.parametrize("theta", [0.0, 0.3])
def test_relative_velocity_of_solid_body_rotation_in_moving_tub(theta):
    """Balls rotating rigidly in the tub frame, tub translating and turning: the cell velocity
    is exactly the rotation's velocity at the cell centre (tub velocity subtracted, tub axes)."""
    h, L = 0.015, 0.0635
    geo = TubGeometry(length=L)
    centre = (0.0, 0.15)
    omega = 3.0
    # one ball per cell, at the cell centre, in the tub frame
    ii, kk = np.meshgrid(np.arange(-6, 7), np.arange(4, 17), indexing="ij")
    p = np.column_stack([ii.ravel() * h, np.full(ii.size, 0.3 * L), kk.ravel() * h])
    v_rel = rotation_velocity(p, omega, centre)
    rng = np.random.default_rng(3)
    S = 6
    poses = np.column_stack([rng.uniform(-2e-3, 2e-3, S), rng.uniform(-2e-3, 2e-3, S),
                             theta + rng.uniform(-1e-3, 1e-3, S), rng.uniform(-0.5, 0.5, S),
                             rng.uniform(-0.5, 0.5, S), rng.uniform(-2.0, 2.0, S)])
    pos = np.empty((S, len(p), 3))
    vel = np.empty((S, len(p), 3))
    for s in range(S):
        pos[s], vel[s] = to_lab(p, v_rel, poses[s])
    radius = np.full(len(p), 0.003175)
    t = cell_table(pos.astype(np.float32), vel.astype(np.float32), poses, radius, geo,
                   cell_size=h, pivot=PIVOT)
    assert len(t) == len(p)
    assert np.all(t.samples == S)
    exact = rotation_velocity(np.column_stack([t.x, np.zeros(len(t)), t.z]), omega, centre)
    # float32 storage of lab positions/velocities limits the agreement to ~1e-6 m/s
    assert np.allclose(t.vx, exact[:, 0], atol=2e-6)
    assert np.allclose(t.vz, exact[:, 2], atol=2e-6)
    # without subtracting the tub's motion the answer would be wrong by ~0.5 m/s: check that the
    # lab velocities really differ from the relative ones (the test has teeth)
    assert np.abs(vel[..., 0] - v_rel[None, :, 0]).max() > 0.05


def test_solid_fraction_of_simple_cubic_packing():
    """Simple cubic packing of touching balls: phi = pi/6 in every fully packed cell."""
    h = 0.015
    a = h / 3.0  # lattice spacing: 3 x 3 centres per cell in x-z
    ny = 4
    geo = TubGeometry(length=ny * a)
    cx = np.arange(-7, 8) * a  # x: cells -2..2, 3 per cell (cell i holds 3i-1, 3i, 3i+1)
    cz = np.arange(8, 23) * a  # z: cells 3..7
    cy = (np.arange(ny) + 0.5) * a
    X, Y, Z = np.meshgrid(cx, cy, cz, indexing="ij")
    p = np.column_stack([X.ravel(), Y.ravel(), Z.ravel()])[None]
    r = np.full(p.shape[1], a / 2)
    t = cell_table(p, np.zeros_like(p), np.zeros((1, 6)), r, geo, cell_size=h)
    full = t.samples == 9 * ny
    assert full.sum() == 5 * 5
    assert np.allclose(t.solid_fraction[full], np.pi / 6, rtol=1e-12)
    assert np.allclose(t.vx, 0) and np.allclose(t.vz, 0)


def test_chunked_h5_streaming_equals_in_memory(tmp_path):
    rng = np.random.default_rng(11)
    S, N = 9, 500
    geo = TubGeometry(length=0.02)
    p = np.column_stack([rng.uniform(-0.14, 0.14, N), rng.uniform(0, 0.02, N),
                         rng.uniform(0.01, 0.3, N)])
    pos = np.stack([p + rng.normal(0, 1e-3, p.shape) for _ in range(S)]).astype(np.float32)
    vel = rng.normal(0, 0.1, (S, N, 3)).astype(np.float32)
    poses = rng.normal(0, 1e-3, (S, 6))
    batch = np.array([-1, 0, 0, 1, 1, 2, 2, -1, 2])
    r = np.full(N, 0.003)
    ref = cell_table(pos, vel, poses, r, geo, batch_of_sample=batch, n_batches=3,
                     chunk_snapshots=100)
    with h5py.File(tmp_path / "x.h5", "w") as f:
        f["p"], f["v"] = pos, vel
    with h5py.File(tmp_path / "x.h5", "r") as f:
        t = cell_table(f["p"], f["v"], poses, r, geo, batch_of_sample=batch, n_batches=3,
                       chunk_snapshots=2)
    for k in ("x", "z", "solid_fraction", "vx", "vz", "samples"):
        assert np.allclose(getattr(t, k), getattr(ref, k), rtol=1e-12, atol=1e-15)
    assert np.allclose(t.batch_vx, ref.batch_vx, equal_nan=True)
    assert t.n_snapshots == 7
    # the grand mean is the snapshot-weighted mean of the batch solid fractions
    w = np.array([2, 2, 3])
    assert np.allclose(t.solid_fraction, (w[:, None] * t.batch_phi).sum(0) / w.sum())


def test_csv_round_trip_and_probe(tmp_path):
    h = 0.015
    x = np.array([-0.105, 0.0, 0.0, 0.15])
    z = np.array([0.15, 0.15, 0.045, 0.0])
    t = table_from_cells(x, z, [0.5, 0.6, 0.55, 0.1], [0.1, -0.2, 0.3, 0.0],
                         [0.01, 0.02, -0.03, 0.0], h)
    path = tmp_path / "bulk_velocity.csv"
    write_csv(t, path)
    assert path.read_text().splitlines()[0] == "x,z,solid_fraction,vx,vz,samples"
    back = read_csv(path)
    assert back.cell_size == pytest.approx(h)
    order = np.lexsort((x, z))
    for k in ("x", "z", "solid_fraction", "vx", "vz"):
        assert np.allclose(getattr(back, k), getattr(t, k)[order])
    pv = probe_values(back, {"P1": (-0.10, 0.15), "P4": (0.0, 0.05), "far": (0.09, 0.3)})
    assert pv["P1"]["vx"] == pytest.approx(0.1) and pv["P1"]["cell_x"] == pytest.approx(-0.105)
    assert pv["P4"]["vz"] == pytest.approx(-0.03)
    assert math.isnan(pv["far"]["vx"]) and pv["far"]["samples"] == 0
    # read back from the CSV the table has no batches: no error
    assert math.isnan(pv["P1"]["solid_fraction_stderr"])


def test_probe_solid_fraction_error_of_known_batches():
    """Three batches of one cell at solid fraction 0.50, 0.56, 0.59: the error is their sd over
    sqrt(3) = 0.04583 / 1.7321 = 0.02646."""
    one = np.array([0.0])
    t = CellTable(x=one, z=one + 0.15, solid_fraction=np.array([0.55]), vx=one, vz=one,
                  samples=np.array([30]), cell_size=0.015,
                  batch_phi=np.array([[0.50], [0.56], [0.59]]),
                  batch_vx=np.zeros((3, 1)), batch_vz=np.zeros((3, 1)))
    pv = probe_values(t, {"P": (0.0, 0.15)})
    assert pv["P"]["solid_fraction_stderr"] == pytest.approx(
        np.std([0.50, 0.56, 0.59], ddof=1) / math.sqrt(3), rel=1e-12)
    assert pv["P"]["solid_fraction_stderr"] == pytest.approx(0.02646, abs=1e-5)


# ----------------------------------------------------------------------------------------------
# circulation

def test_solid_body_rotation_stream_function():
    """Balls in a disc rotating rigidly: psi = phi Omega (a^2 - r^2) / 2, counterclockwise."""
    h, L = 0.015, 0.01
    geo = TubGeometry(length=L)
    centre, a, omega, phi0 = (0.0, 0.2), 0.09, 2.0, 0.6
    spacing = 1.0e-3
    p = disc_lattice(centre, a, spacing, 0.5 * L)
    r = np.full(len(p), (3 * phi0 * spacing**2 * L / (4 * np.pi)) ** (1 / 3))
    for sign, sense in ((1.0, "counterclockwise"), (-1.0, "clockwise")):
        v = rotation_velocity(p, sign * omega, centre)
        t = cell_table(p[None], v[None], np.zeros((1, 6)), r, geo, cell_size=h)
        c = circulation(t)
        peak = phi0 * omega * a**2 / 2
        assert c.sense == sense
        assert np.sign(c.psi_extreme) == sign
        assert c.strength == pytest.approx(peak, rel=0.03)
        # the extreme is at the cell centre nearest the disc's centre (0, 0.195)
        assert (c.extreme_x, c.extreme_z) == pytest.approx((0.0, 0.195), abs=1e-9)
        X, Z = np.meshgrid(c.x, c.z)
        exact = sign * phi0 * omega * np.clip(a**2 - (X - centre[0]) ** 2
                                             - (Z - centre[1]) ** 2, 0, None) / 2
        # inside, O(h^2) error; the cells the disc's edge cuts smear psi's zero over a cell
        inner = (X - centre[0]) ** 2 + (Z - centre[1]) ** 2 < (a - h) ** 2
        assert np.abs(c.psi - exact)[inner].max() < 0.03 * peak
        assert np.abs(c.psi - exact).max() < 0.1 * peak
        assert c.residual < 0.05


def test_bed_at_rest_and_divergence_free_field():
    h = 0.01
    ii, kk = np.meshgrid(np.arange(0, 21), np.arange(0, 11), indexing="ij")
    x, z = ii.ravel() * h, kk.ravel() * h
    phi = np.full(x.size, 0.6)
    # at rest: psi = 0 everywhere
    xg, zg, psi, bed, res = stream_function(x, z, phi, np.zeros_like(x), np.zeros_like(x), h)
    assert np.all(psi == 0) and bed.sum() == x.size
    assert circulation(table_from_cells(x, z, phi, 0 * x, 0 * x, h)).sense == "none"
    # psi = A sin(pi x / W) sin(pi z / H) on the rectangle of the cells (zero on its edges, half
    # a cell outside the outermost centres, where the bed ends): q_x = dpsi/dz, q_z = -dpsi/dx
    W, H, A = 21 * h, 11 * h, 1e-3
    xs, zs = x + h / 2, z + h / 2
    qx = A * np.pi / H * np.sin(np.pi * xs / W) * np.cos(np.pi * zs / H)
    qz = -A * np.pi / W * np.cos(np.pi * xs / W) * np.sin(np.pi * zs / H)
    t = table_from_cells(x, z, phi, qx / phi, qz / phi, h)
    c = circulation(t)
    exact = (A * np.sin(np.pi * (c.x[None, :] + h / 2) / W)
             * np.sin(np.pi * (c.z[:, None] + h / 2) / H))
    exact[~c.bed] = 0
    assert c.sense == "counterclockwise"
    assert np.abs(c.psi - exact).max() < 0.03 * A
    assert c.strength == pytest.approx(A, rel=0.03)


# ----------------------------------------------------------------------------------------------
# compare

def test_field_difference_known_answers():
    rng = np.random.default_rng(5)
    h = 0.015
    ii, kk = np.meshgrid(np.arange(-8, 9), np.arange(0, 15), indexing="ij")
    x, z = ii.ravel() * h, kk.ravel() * h
    phi = rng.uniform(0.35, 0.6, x.size)
    ang = rng.uniform(0, 2 * np.pi, x.size)
    U = 0.05  # uniform speed, random directions
    b = table_from_cells(x, z, phi, U * np.cos(ang), U * np.sin(ang), h)
    assert field_difference(b, b) == 0.0
    eps = 0.07
    a = table_from_cells(x, z, phi * 0.9, (1 + eps) * b.vx, (1 + eps) * b.vz, h)
    assert field_difference(a, b) == pytest.approx(eps, rel=1e-12)
    # cells below phi 0.3 in either table do not count; extra/missing cells and order neither
    loose = phi.copy()
    loose[:20] = 0.1
    a2 = table_from_cells(x[::-1], z[::-1], loose[::-1], (b.vx + 10 * (loose < 0.3))[::-1],
                          b.vz[::-1], h)
    assert field_difference(a2, b) == pytest.approx(0.0, abs=1e-15)
    with pytest.raises(InputError, match="same grid"):
        field_difference(b, table_from_cells(x, z, phi, b.vx, b.vz, 0.01))


def _noisy_seeds(rng, n_seeds, n_cells, U, sigma, h=0.015):
    """n_seeds tables of one mean field (speed U m/s in a random direction per cell) plus
    independent Gaussian noise of sigma m/s on each component, and the mean field's own table:
    runs that differ only in their random part, as fill seeds do."""
    ii = np.arange(n_cells)
    x, z = (ii % 40 - 20) * h, (ii // 40) * h
    phi = rng.uniform(0.35, 0.6, n_cells)
    ang = rng.uniform(0, 2 * np.pi, n_cells)
    vx, vz = U * np.cos(ang), U * np.sin(ang)
    seeds = [table_from_cells(x, z, phi, vx + rng.normal(0, sigma, n_cells),
                              vz + rng.normal(0, sigma, n_cells), h) for _ in range(n_seeds)]
    return seeds, table_from_cells(x, z, phi, vx, vz, h)


def test_seed_scatter_and_difference_to_seeds_known_answers():
    """Fields that differ only by independent noise of sigma per component: two seeds differ by
    sqrt(2 sigma^2) per component, so E(i, j) = 2 sigma / V with V the reference's mean speed
    (U (1 + sigma^2 / 2U^2) to second order, for a 2D Rician speed); the noise-free mean field
    against the seeds, E = sqrt(2) sigma / V.  Both checked on 4000 cells within 2 %; the pairs
    are all 12 ordered pairs of 4 seeds, and 2 seeds give no jackknife error."""
    rng = np.random.default_rng(21)
    U, sigma = 0.05, 0.005
    seeds, mean_field = _noisy_seeds(rng, 4, 4000, U, sigma)
    V = U * (1 + sigma**2 / (2 * U**2))
    sc = seed_scatter(seeds)
    assert len(sc.pairs) == 12 and sc.runs == 4
    assert sc.mean == pytest.approx(2 * sigma / V, rel=0.02)
    assert sc.stderr is not None and sc.stderr < 0.02 * sc.mean
    d = difference_to_seeds(mean_field, seeds)
    assert len(d.values) == 4
    assert d.mean == pytest.approx(np.sqrt(2) * sigma / V, rel=0.02)
    two = seed_scatter(seeds[:2])
    assert two.stderr is None and len(two.pairs) == 2
    with pytest.raises(ValueError):
        seed_scatter(seeds[:1])


def test_seed_scatter_jackknife_error_matches_the_scatter_of_repeats():
    """The jackknife standard error of the pairs' mean, averaged over 300 repeats of 4 seeds on
    few cells (so one pair's E is noisy), against the standard deviation of the mean over the
    repeats: the error bar means what it says (within 25 %)."""
    rng = np.random.default_rng(3)
    means, errors = [], []
    for _ in range(300):
        seeds, _ = _noisy_seeds(rng, 4, 12, 0.05, 0.02)
        sc = seed_scatter(seeds)
        means.append(sc.mean)
        errors.append(sc.stderr)
    assert np.mean(errors) == pytest.approx(np.std(means, ddof=1), rel=0.25)


def _batched(vx_b, vz_b, phi=0.55, h=0.015, samples=100):
    """A table of 10 cells in a row whose batch k has velocity (vx_b[k], vz_b[k]) m/s in every
    cell, equal samples a batch."""
    nb, nc = len(vx_b), 10
    x = np.arange(nc) * h
    bvx = np.repeat(np.asarray(vx_b, float)[:, None], nc, axis=1)
    bvz = np.repeat(np.asarray(vz_b, float)[:, None], nc, axis=1)
    return CellTable(x=x, z=np.zeros(nc), solid_fraction=np.full(nc, phi), vx=bvx.mean(axis=0),
                     vz=bvz.mean(axis=0), samples=np.full(nc, nb * samples), cell_size=h,
                     batch_phi=np.full((nb, nc), phi), batch_vx=bvx, batch_vz=bvz,
                     batch_samples=np.full((nb, nc), samples))


def test_field_difference_error_over_the_batches_known_answers():
    """Uniform fields.  b at (U, 0) in every batch, a at (U, c_k): E = mean(c) / U is linear in
    a's batches, so its jackknife error is their batch-means error sd(c) / sqrt(n) / U.  a at
    (Ua, 0), b's batches at (U_k, 0): E = Ua / mean(U) - 1, whose error is, to first order,
    Ua / mean(U)^2 sd(U) / sqrt(n) (the delta method; within 1 % at a 2 % spread).  Both
    sides' batches: the variances add."""
    from vibroflow.analysis.compare import field_difference_stderr

    U = 0.05
    c = np.array([0.004, 0.006, 0.005, 0.009, 0.003, 0.007])
    a, b = _batched(np.full(6, U), c), _batched(np.full(6, U), np.zeros(6))
    assert field_difference(a, b) == pytest.approx(c.mean() / U, rel=1e-12)
    se_a = np.std(c, ddof=1) / np.sqrt(6) / U
    assert field_difference_stderr(a, b) == pytest.approx(se_a, rel=1e-9)
    Ub = U * np.array([1.00, 1.02, 0.99, 0.98, 1.01, 1.00])
    a2, b2 = _batched(np.full(6, 0.06), np.zeros(6)), _batched(Ub, np.zeros(6))
    se_b = 0.06 / Ub.mean() ** 2 * np.std(Ub, ddof=1) / np.sqrt(6)
    assert field_difference_stderr(a2, b2) == pytest.approx(se_b, rel=0.01)
    # a with c_k and b with U_k: independent runs, the two variances add (to first order)
    a3 = _batched(np.full(6, U), c)
    both = field_difference_stderr(a3, b2)
    assert both == pytest.approx(np.hypot(field_difference_stderr(a3, _batched(
        np.full(6, Ub.mean()), np.zeros(6))), field_difference_stderr(_batched(
            np.full(6, U), np.full(6, c.mean())), b2)), rel=1e-9)
    # without batches on either side: unknown
    plain = CellTable(x=a.x, z=a.z, solid_fraction=a.solid_fraction, vx=a.vx, vz=a.vz,
                      samples=a.samples, cell_size=a.cell_size)
    assert math.isnan(field_difference_stderr(plain, plain))


def test_rms_difference_and_its_error_over_the_batches_known_answers():
    """The report's plain rms of |v_a - v_b|: cells (0.03, 0.04) m/s apart read 0.05 m/s, a
    cell below the solid fraction limit left out, each cell counted once whatever its solid
    fraction.  b at (U, 0), a's batches at (U, c_k) with every c_k > 0: the rms is mean(c),
    linear in a's batches, so its jackknife error is sd(c) / sqrt(n) (1e-9).  A statistic that
    cannot be formed without some batch has no error."""
    from vibroflow.analysis.compare import batches_stderr, rms_difference

    h = 0.015
    a = CellTable(x=np.arange(3) * h, z=np.zeros(3), solid_fraction=np.array([0.5, 0.9, 0.1]),
                  vx=np.array([0.03, 0.0, 1.0]), vz=np.array([0.04, 0.05, 1.0]),
                  samples=np.full(3, 10), cell_size=h)
    b = CellTable(x=np.arange(3) * h, z=np.zeros(3), solid_fraction=np.array([0.4, 0.6, 0.5]),
                  vx=np.zeros(3), vz=np.zeros(3), samples=np.full(3, 10), cell_size=h)
    assert rms_difference(a, b, 0.3) == pytest.approx(0.05, rel=1e-12)
    with pytest.raises(InputError):
        rms_difference(a, b, 0.95)
    U = 0.05
    c = np.array([0.004, 0.006, 0.005, 0.009, 0.003, 0.007])
    a2, b2 = _batched(np.full(6, U), c), _batched(np.full(6, U), np.zeros(6))
    assert rms_difference(a2, b2) == pytest.approx(c.mean(), rel=1e-12)
    assert batches_stderr(a2, b2, rms_difference) == pytest.approx(
        np.std(c, ddof=1) / np.sqrt(6), rel=1e-9)
    # a statistic that cannot be formed without some batch: unknown, not a number
    def refuses(s, t):
        raise InputError("no cell")
    assert math.isnan(batches_stderr(a2, b2, refuses))


def test_field_difference_error_matches_the_scatter_of_repeats():
    """A continuum whose six batches each carry independent noise of 0.01 m/s per cell and
    component about a field that differs from the reference's: E is nonlinear in the batches,
    and over 300 repeats the rms of the jackknife error matches the sd of E within 15 %, so the
    error bar means what it says."""
    from vibroflow.analysis.compare import field_difference_stderr

    rng = np.random.default_rng(5)
    nb, nc, h = 6, 150, 0.015
    x, z = (np.arange(nc) % 15) * h, (np.arange(nc) // 15) * h
    ang = rng.uniform(0, 2 * np.pi, nc)
    ux, uz = 0.05 * np.cos(ang), 0.05 * np.sin(ang)
    ref = CellTable(x=x, z=z, solid_fraction=np.full(nc, 0.55), vx=ux, vz=uz,
                    samples=np.full(nc, 600), cell_size=h)
    E, se = [], []
    for _ in range(300):
        bvx = (ux + 0.02)[None] + rng.normal(0, 0.01, (nb, nc))
        bvz = uz[None] + rng.normal(0, 0.01, (nb, nc))
        a = CellTable(x=x, z=z, solid_fraction=np.full(nc, 0.55), vx=bvx.mean(0),
                      vz=bvz.mean(0), samples=np.full(nc, 600), cell_size=h,
                      batch_phi=np.full((nb, nc), 0.55), batch_vx=bvx, batch_vz=bvz,
                      batch_samples=np.full((nb, nc), 100))
        E.append(field_difference(a, ref))
        se.append(field_difference_stderr(a, ref))
    assert np.sqrt(np.mean(np.square(se))) == pytest.approx(np.std(E, ddof=1), rel=0.15)


def test_ensemble_mean_pools_the_samples_and_averages_the_noise_down():
    """The mean of n seeds' fields: in a cell, the pooled mean of all the runs' samples (a
    cell with 1 sample of vx = 1 and one with 3 of vx = 3 average to 2.5), the mean solid
    fraction, only the cells every run holds; and on fields with independent noise sigma, the
    mean of 4 seeds differs from the noise-free field by sqrt(2) sigma / 2 / V (the noise over
    sqrt(4)), within 2 %."""
    h = 0.015
    a = CellTable(x=np.array([0.0, h, 2 * h]), z=np.zeros(3), solid_fraction=np.array([.4, .5, .6]),
                  vx=np.array([1.0, 0.0, 7.0]), vz=np.zeros(3), samples=np.array([1, 2, 5]),
                  cell_size=h)
    b = CellTable(x=np.array([h, 0.0]), z=np.zeros(2), solid_fraction=np.array([.3, .6]),
                  vx=np.array([2.0, 3.0]), vz=np.array([1.0, 0.0]), samples=np.array([2, 3]),
                  cell_size=h)
    m = ensemble_mean([a, b])
    assert len(m) == 2 and list(m.ix) == [0, 1]
    np.testing.assert_allclose(m.vx, [2.5, 1.0])
    np.testing.assert_allclose(m.vz, [0.0, 0.5])
    np.testing.assert_allclose(m.solid_fraction, [0.5, 0.4])
    assert list(m.samples) == [4, 4]
    rng = np.random.default_rng(8)
    U, sigma = 0.05, 0.005
    seeds, mean_field = _noisy_seeds(rng, 4, 4000, U, sigma)
    V = U * (1 + sigma**2 / (2 * U**2) / 4)
    assert field_difference(mean_field, ensemble_mean(seeds)) == pytest.approx(
        np.sqrt(2) * sigma / 2 / V, rel=0.02)


def test_difference_by_region_locates_a_known_difference():
    """A field that differs from its reference in one known rectangle only: that region holds
    the whole of E^2, with the difference's mean and the speeds as built; the shares of a
    uniform difference are the regions' phi-weights; and E^2 is the sum over the regions."""
    rng = np.random.default_rng(11)
    h = 0.015
    ii, kk = np.meshgrid(np.arange(-9, 10), np.arange(1, 14), indexing="ij")
    x, z = ii.ravel() * h, kk.ravel() * h
    phi = rng.uniform(0.35, 0.6, x.size)
    vx, vz = rng.normal(0, 0.04, x.size), rng.normal(0, 0.04, x.size)
    b = table_from_cells(x, z, phi, vx, vz, h)
    xe, ze = bed_thirds(b, 0.15)
    np.testing.assert_allclose(xe, [-0.15, -0.05, 0.05, 0.15])
    np.testing.assert_allclose(ze, [0.0075, 0.0725, 0.1375, 0.2025])
    # +0.03 m/s on vx in the top right region only
    top_right = (x >= 0.05) & (z >= ze[2])
    a = table_from_cells(x, z, phi, vx + 0.03 * top_right, vz, h)
    regions = difference_by_region(a, b, xe, ze)
    assert len(regions) == 9 and sum(r.cells for r in regions) == x.size
    hit = regions[-1]  # the last row's last region: top, right
    assert hit.x_range == pytest.approx((0.05, 0.15)) and hit.z_range[0] == ze[2]
    assert hit.share == pytest.approx(1.0, abs=1e-12) and hit.cells == top_right.sum()
    assert hit.dvx == pytest.approx(0.03, rel=1e-12) and hit.dvz == 0.0
    w = phi[top_right]
    assert hit.speed_b == pytest.approx((w * np.hypot(vx, vz)[top_right]).sum() / w.sum())
    assert all(r.share == 0.0 for r in regions[:-1])
    # a uniform difference: each region's share is its share of the phi-weights, and the
    # regions' E^2 add up to E^2
    a2 = table_from_cells(x, z, phi, vx + 0.01, vz - 0.02, h)
    shares = difference_by_region(a2, b, xe, ze)
    for r in shares:
        m = ((x >= r.x_range[0]) & (x < r.x_range[1]) & (z >= r.z_range[0])
             & (z < r.z_range[1]))
        assert r.share == pytest.approx(phi[m].sum() / phi.sum(), rel=1e-12)
        assert (r.dvx, r.dvz) == (pytest.approx(0.01), pytest.approx(-0.02))
    assert sum(r.share for r in shares) == pytest.approx(1.0, rel=1e-12)


def test_agreement_rules():
    # within 10 % of the reference
    assert strengths_agree(1.09e-3, 0.0, 1.0e-3, 0.0)
    assert not strengths_agree(1.11e-3, 0.0, 1.0e-3, 0.0)
    # or within twice the combined standard error (3e-4, 4e-4 -> 5e-4 -> 1e-3)
    assert strengths_agree(1.9e-3, 3e-4, 1.0e-3, 4e-4)
    assert not strengths_agree(2.1e-3, 3e-4, 1.0e-3, 4e-4)
    assert not strengths_agree(1e-3, 0, 1e-3, 0, "clockwise", "counterclockwise")
    assert fields_agree(0.15, 0.1) and not fields_agree(0.151, 0.1)


# ----------------------------------------------------------------------------------------------
# contacts

def test_wall_contact_and_impact_statistics():
    fn = np.array([1.0, 2.0, 4.0, 1.0, -0.5])
    ft = np.array([0.4, 0.4, 0.8, 0.1, 0.2])
    sl = np.array([True, False, False, False, True])
    arc = np.array([-0.1, -0.1, 0.1, 0.1, 0.0])
    w = wall_contact_stats(fn, ft, sl, arc=arc, arc_edges=np.array([-0.2, 0.0, 0.2]))
    assert w.count == 4  # the pulling contact (fn < 0) is left out
    assert w.mean_ft_over_fn == pytest.approx((0.4 + 0.2 + 0.2 + 0.1) / 4)
    assert w.ratio_of_sums == pytest.approx(1.7 / 8.0)
    assert w.sliding_fraction == pytest.approx(0.25)
    assert w.histogram_counts.sum() == 4
    assert w.arc_count.tolist() == [2, 2]
    assert np.allclose(w.arc_mean_ft_over_fn, [0.3, 0.15])
    assert np.allclose(w.arc_sliding_fraction, [0.5, 0.0])

    kind = np.array([0, 0, 1, 1, 1, 2, 0])
    v = np.array([0.1, 0.3, 0.2, 0.4, 0.6, 1.0, 9.0])
    batch = np.array([0, 1, 0, 1, 1, 0, -1])  # the last is outside the window
    im = impact_stats(kind, v, batch=batch, n_batches=2)
    d = im.as_dict()
    assert d["ball_ball_mean_normal_speed"] == pytest.approx(0.2)
    assert d["ball_wall_mean_normal_speed"] == pytest.approx(0.4)
    assert d["count"] == 6 and im.count_by_kind["ball_partition"] == 1
    assert math.isnan(im.mean_normal_speed_by_kind["plane_wall"])
    # batch means of ball-ball: batches 0.1 and 0.3 -> stderr = std([.1,.3], ddof=1)/sqrt 2
    assert d["ball_ball_mean_normal_speed_stderr"] == pytest.approx(0.1)
    x, z, n, m = mean_by_region(np.array([[0.001, 0, 0.002], [0.004, 0, -0.001],
                                          [0.02, 0, 0.0]]), np.array([1.0, 3.0, 5.0]), 0.015)
    assert n.tolist() == [2, 1] and m.tolist() == [2.0, 5.0]
    assert x.tolist() == pytest.approx([0.0, 0.015])


# ----------------------------------------------------------------------------------------------
# summary end to end

def test_tub_summary_end_to_end(tmp_path):
    """A synthetic dem.h5: balls in a disc turning rigidly in the moving tub."""
    f = 47.0
    sc = Scenario().model_copy(update={
        "run": Scenario().run.model_copy(update={"duration": 20 / f, "average_last": 8 / f,
                                                 "batches": 4}),
        "tub": Scenario().tub.model_copy(update={"length": 0.01})})
    motion = TubMotion(frequency=f, pivot_x=PIVOT[0], pivot_z=PIVOT[1])
    centre, a, omega, phi0, spacing = (0.0, 0.15), 0.125, 2.0, 0.55, 2.5e-3
    L = sc.tub.length
    p0 = disc_lattice(centre, a, spacing, 0.5 * L)
    N = len(p0)
    r = np.full(N, (3 * phi0 * spacing**2 * L / (4 * np.pi)) ** (1 / 3))
    t_start, t_end = sc.run.duration - sc.run.average_last, sc.run.duration
    times = t_start + np.arange(-8, 8 * 8 + 1) / (8 * f)  # one cycle before, one sample at end
    S = times.size
    pose = pose_np(motion, times)
    poses = np.column_stack([pose[k] for k in ("X", "Z", "theta", "Xdot", "Zdot", "thetadot")])
    pos = np.empty((S, N, 3), np.float32)
    vel = np.empty((S, N, 3), np.float32)
    for s, t in enumerate(times):
        ang = omega * (t - t_start)
        c, sn = math.cos(ang), math.sin(ang)
        d = p0 - np.array([centre[0], 0, centre[1]])
        p = p0.copy()
        p[:, 0] = centre[0] + c * d[:, 0] - sn * d[:, 2]
        p[:, 2] = centre[1] + sn * d[:, 0] + c * d[:, 2]
        v = rotation_velocity(p, omega, centre)
        if times[s] < t_start or times[s] >= t_end - 1e-9:
            v[:] = 100.0  # garbage outside the window: must not be used
        pos[s], vel[s] = to_lab(p, v, poses[s])
    h5 = tmp_path / "dem.h5"
    in_win = (times >= t_start) & (times < t_end - 1e-9)
    snap = np.repeat(np.arange(S), 3).astype(np.int32)
    nC = snap.size
    wall = np.tile(np.array([0, 0, 1], np.int8), S)
    fn = np.tile(np.array([2.0, 1.0, 5.0], np.float32), S)
    ft = np.tile(np.array([0.8, 0.2, 5.0], np.float32), S)
    sliding = np.tile(np.array([True, False, True]), S)
    ft[~np.repeat(in_win, 3)] = 50.0  # outside the window: must not be used
    imp_t = np.array([t_start - 0.001, t_start + 0.01, t_start + 0.05, t_start + 0.1,
                      t_start + 0.15])
    with h5py.File(h5, "w") as g:
        g.attrs.update(case="synthetic", n_particles=N, dt=1e-5, frequency=f,
                       scenario_toml="")
        g["particles/radius"] = r
        g["snapshots/time"] = times
        g["snapshots/step"] = np.rint(times / 1e-5).astype(np.int64)
        g["snapshots/phase"] = np.mod(times * f, 1.0)
        g["snapshots/tub_pose"] = poses
        g["snapshots/position"] = pos
        g["snapshots/velocity"] = vel
        g["snapshots/angular_velocity"] = np.zeros_like(vel)
        g["wall_contacts/snapshot"] = snap
        g["wall_contacts/particle"] = np.zeros(nC, np.int32)
        g["wall_contacts/wall"] = wall
        g["wall_contacts/position_tub"] = np.zeros((nC, 3), np.float32)
        g["wall_contacts/arc"] = np.where(wall == 0, 0.05, np.nan).astype(np.float32)
        g["wall_contacts/fn"] = fn
        g["wall_contacts/ft"] = ft
        g["wall_contacts/sliding"] = sliding
        g["impacts/time"] = imp_t
        g["impacts/kind"] = np.array([0, 0, 0, 1, 1], np.int8)
        g["impacts/position_tub"] = np.zeros((5, 3), np.float32)
        g["impacts/normal_speed"] = np.array([9.0, 0.2, 0.4, 0.5, 0.7], np.float32)
    out = tub_summary(h5, sc)
    json.dumps(out, allow_nan=False)  # valid JSON
    assert out["window"]["snapshots"] == 64 and out["window"]["cycles"] == 8
    for name, pr in sc.analysis.probes.items():
        rec = out["probes"][name]
        exact = rotation_velocity(np.array([[rec["cell_x"], 0, rec["cell_z"]]]), omega, centre)
        assert rec["vx"] == pytest.approx(exact[0, 0], abs=0.01 * omega * a)
        assert rec["vz"] == pytest.approx(exact[0, 2], abs=0.01 * omega * a)
        assert rec["vx_stderr"] < 0.01 * omega * a
    circ = out["circulation"]
    assert circ["sense"] == "counterclockwise"
    assert circ["strength"] == pytest.approx(phi0 * omega * a**2 / 2, rel=0.05)
    assert circ["strength_stderr"] < 0.02 * circ["strength"]
    wc = out["wall_contacts"]
    assert wc["count"] == 2 * 64
    assert wc["mean_ft_over_fn"] == pytest.approx(0.3, rel=1e-6)
    assert wc["ratio_of_sums"] == pytest.approx(1.0 / 3.0, rel=1e-6)
    assert wc["sliding_fraction"] == pytest.approx(0.5)
    im = out["impacts"]
    assert im["count"] == 4
    assert im["ball_ball_mean_normal_speed"] == pytest.approx(0.3, rel=1e-6)
    assert im["ball_wall_mean_normal_speed"] == pytest.approx(0.6, rel=1e-6)
    # the table was written next to dem.h5 and reads back to the same probe values
    back = read_csv(tmp_path / "bulk_velocity.csv")
    pv = probe_values(back, sc.analysis.probes)
    assert pv["P1"]["vz"] == pytest.approx(out["probes"]["P1"]["vz"], rel=1e-8)
    # the same data as a dict of arrays gives the same summary
    with h5py.File(h5, "r") as g:
        arrays = {k: g[k][()] for k in ("particles/radius", "snapshots/time",
                                        "snapshots/tub_pose", "snapshots/position",
                                        "snapshots/velocity")}
    out2 = tub_summary(arrays, sc)
    assert out2["probes"] == out["probes"]
    assert out2["wall_contacts"]["count"] == 0 and out2["bulk_velocity_csv"] is None


# ----------------------------------------------------------------------------------------------
# vtk

def test_vtk_outputs(tmp_path):
    rng = np.random.default_rng(1)
    N = 50
    pos, vel = rng.random((N, 3)), rng.random((N, 3))
    pth = vtk.write_points_vtu(tmp_path / "snap_0000", pos,
                               {"velocity_lab_m_per_s": vel, "radius_m": np.full(N, 0.003),
                                "id": np.arange(N)}, {"time_s": 0.25})
    assert pth.endswith(".vtu") and open(pth, "rb").read(5) == b"<?xml"
    back = read_vtk(pth)  # an independent reader gives back what was written
    assert np.array_equal(back["Points"]["points"], pos)
    assert np.array_equal(back["PointData"]["velocity_lab_m_per_s"], vel)
    assert np.array_equal(back["PointData"]["id"], np.arange(N))
    assert back["PointData"]["radius_m"].tolist() == [0.003] * N
    assert back["FieldData"]["time_s"].tolist() == [0.25]
    pvd = vtk.write_pvd(tmp_path / "balls.pvd", [(0.0, pth), (0.01, "snap_0001.vtu")])
    root = ET.parse(pvd).getroot()
    ds = root.findall("./Collection/DataSet")
    assert [d.get("file") for d in ds] == ["snap_0000.vtu", "snap_0001.vtu"]
    assert float(ds[1].get("timestep")) == pytest.approx(0.01)
    # the tub mesh: U points on the wall; total area = U area + two cross-sections
    geo = TubGeometry()
    pts, quads, part = vtk.tub_surface_mesh(geo, 400)
    assert np.abs(distance_to_wall_np(pts[:, 0], pts[:, 2], geo.radius)).max() < 1e-12
    q = pts[quads]
    area = 0.5 * (np.linalg.norm(np.cross(q[:, 1] - q[:, 0], q[:, 2] - q[:, 0]), axis=1)
                  + np.linalg.norm(np.cross(q[:, 2] - q[:, 0], q[:, 3] - q[:, 0]), axis=1))
    assert area[part == 0].sum() == pytest.approx(geo.wall_arc_length() * geo.length, rel=1e-4)
    assert area[part == 1].sum() == pytest.approx(cross_section_area(geo.radius, geo.rim_height),
                                                  rel=1e-4)
    assert area[part == 2].sum() == pytest.approx(area[part == 1].sum())
    surf = vtk.write_tub_surface(tmp_path / "tub.vtu", geo)
    assert open(surf, "rb").read(5) == b"<?xml"
    assert not list(tmp_path.glob(".tmp-*"))


def test_part_speed_map_e_its_noise_and_cycle_mean_by_hand():
    """vibroflow.analysis.impact_maps on hand-made maps: E_speed over the patches with speeds in
    both, weighted by the reference's rates 1, 3: sqrt((0.1^2 + 3 x 0.2^2) / 4) / (1 / 4);
    the noise of twice the errors on all three patches (rates 1, 3, 2): sqrt((0.02^2 + 3 x
    0.06^2 + 2 x 0.04^2) / 6) / (2 / 6); the cycle mean of 1, 3 with errors 0.3, 0.4 is 2 +-
    0.5 / 2."""
    a = {"speed": np.array([0.2, 0.1, np.nan])}
    b = {"speed": np.array([0.1, 0.3, 0.5]), "rate": np.array([1.0, 3.0, 2.0]),
         "speed_stderr": np.array([0.01, 0.03, 0.02])}
    assert speed_difference(a, b) == pytest.approx(math.sqrt(0.13 / 4) / 0.25)
    assert speed_noise(b) == pytest.approx(math.sqrt(0.0144 / 6) / (2 / 6))
    m, se = cycle_mean(np.array([[1.0, np.nan], [3.0, np.nan]]),
                       np.array([[0.3, 0.1], [0.4, 0.1]]))
    assert m[0] == pytest.approx(2.0) and se[0] == pytest.approx(0.25)
    assert np.isnan(m[1]) and np.isnan(se[1])
