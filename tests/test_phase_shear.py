"""The shear rate of a sampled flow's phase-resolved velocity field
(vibroflow.measure.phase_shear), the measure both the DEM's impact calibration and the continuum
runs use, against flows whose shear rate is known exactly."""
from __future__ import annotations

import math

import numpy as np
import pytest

from vibroflow.measure.phase_shear import (PhaseShearAccumulator, equivalent_shear_rate_2d,
                                            near_wall_nodes)
from vibroflow.tub.motion import rigid_velocity, tub_to_lab

H = 0.015           # node spacing (m), tub47's analysis cells
NXH, NZ = 11, 28    # tub47's node grid
LENGTH = 0.0635     # slice thickness (m)
PIVOT = (0.0, -0.10)


def lattice(spacing=H / 3, x=(-0.09, 0.09), z=(0.03, 0.15)):
    """Tub-frame points on a square lattice filling a box (m), each a sphere of the lattice
    cell's volume (solid fraction 0.6 across the slice)."""
    xs = np.arange(x[0], x[1] + 1e-12, spacing)
    zs = np.arange(z[0], z[1] + 1e-12, spacing)
    X, Z = np.meshgrid(xs, zs)
    p = np.stack([X.ravel(), np.full(X.size, 0.5 * LENGTH), Z.ravel()], axis=1)
    return p, np.full(X.size, 0.6 * spacing * spacing * LENGTH)


def interior(res, x=(-0.09, 0.09), z=(0.03, 0.15)):
    """Nodes two spacings in from the box's edges: their tent supports and their neighbours'
    hold only lattice points, so the tent average of a linear field is exact there."""
    X, Z = np.meshgrid(res.x, res.z)
    return ((X > x[0] + 2 * H - 1e-9) & (X < x[1] - 2 * H + 1e-9)
            & (Z > z[0] + 2 * H - 1e-9) & (Z < z[1] - 2 * H + 1e-9))


def still_pose():
    return np.zeros(6)


def test_equivalent_shear_rate_of_simple_shear_and_of_pure_compression():
    """sqrt(2 D':D') in plane strain: simple shear v_x = G z gives G; a uniaxial compression
    L_zz = -e (D_yy = 0) gives 2 e / sqrt(3)."""
    assert equivalent_shear_rate_2d(0.0, 3.0, 0.0, 0.0) == pytest.approx(3.0, rel=1e-14)
    assert equivalent_shear_rate_2d(0.0, 0.0, 0.0, -2.0) == pytest.approx(4.0 / math.sqrt(3),
                                                                          rel=1e-14)


def test_steady_simple_shear_is_recovered_and_its_noise_averages_out():
    """v_x = G z with a zero-mean random velocity on every point at every sample (five times the
    shear's velocity difference across a node spacing): the phase-resolved field's shear rate is G
    over the interior nodes within 2 % (each node within 12 %: 40 cycles of noise left), where
    one sample's field alone reads more than 1.5 G -- the bias of a fluctuating field's
    |gamma_dot| that the phase average removes (why the continuum's shear rate is measured this
    way)."""
    G = 2.0
    rng = np.random.default_rng(7)
    p, vol = lattice()
    acc = PhaseShearAccumulator(H, NXH, NZ, LENGTH, n_phases=8, n_batches=4, pivot=PIVOT)
    one = PhaseShearAccumulator(H, NXH, NZ, LENGTH, n_phases=1, n_batches=1, pivot=PIVOT)
    noise = 5.0 * G * H
    for j in range(8 * 4 * 40):
        v = np.zeros_like(p)
        v[:, 0] = G * p[:, 2]
        v[:, [0, 2]] += noise * rng.standard_normal((p.shape[0], 2))
        acc.add(p, v, still_pose(), vol, phase=j % 8, batch=(j // 8) % 4)
        if j == 0:
            one.add(p, v, still_pose(), vol, phase=0, batch=0)
    res = acc.result()
    m = interior(res)
    assert m.sum() >= 20
    assert np.all(np.abs(res.shear_rate[m] / G - 1.0) < 0.12)
    assert res.solid_fraction[m] == pytest.approx(np.full(m.sum(), 0.6), rel=1e-9)
    mean, se = res.weighted_mean(m)
    assert mean == pytest.approx(G, rel=0.02) and 0 < se < 0.05 * G
    # steady: the time-averaged field (the roll) shears at G too
    assert res.roll_mean(m) == pytest.approx(G, rel=0.02)
    single = one.result()
    assert single.weighted_mean(m)[0] > 1.5 * G


def test_oscillating_shear_gives_the_cycle_mean_of_its_magnitude():
    """v_x = G z sin(2 pi k / 8) at phase k: each phase's field has shear rate G |sin|, and the
    cycle mean over the 8 phases (equal solid fractions) is G times the mean of |sin(k pi/4)|,
    (2 + 4 / sqrt(2)) / 8 = 0.6036; the time-averaged field is at rest (no roll)."""
    G = 3.0
    p, vol = lattice()
    acc = PhaseShearAccumulator(H, NXH, NZ, LENGTH, n_phases=8, n_batches=2, pivot=PIVOT)
    for j in range(16):
        k = j % 8
        v = np.zeros_like(p)
        v[:, 0] = G * p[:, 2] * math.sin(2 * math.pi * k / 8)
        acc.add(p, v, still_pose(), vol, phase=k, batch=j // 8)
    res = acc.result()
    m = interior(res)
    for k in range(8):
        assert np.allclose(res.phase_shear_rate[k][m], G * abs(math.sin(2 * math.pi * k / 8)),
                           rtol=1e-9, atol=1e-9)
    assert np.allclose(res.shear_rate[m], G * (2 + 4 / math.sqrt(2)) / 8, rtol=1e-9)
    # no slow roll: the time-averaged field is at rest, so all of it is deformation within
    # the cycle
    assert np.allclose(res.roll_shear_rate[m], 0.0, atol=1e-9)


def test_a_bed_carried_rigidly_by_the_moving_tub_has_no_shear():
    """Points fixed in the tub frame while the tub translates and rotates (tub47's motion, lab
    positions and velocities from the shared kinematics of vibroflow.tub.motion): relative to
    the tub nothing moves, so every node's shear rate is zero to round-off -- the accumulator
    takes the tub's rigid motion out before it averages."""
    p, vol = lattice()
    acc = PhaseShearAccumulator(H, NXH, NZ, LENGTH, n_phases=8, n_batches=1, pivot=PIVOT)
    w = 2 * math.pi * 47.0
    for k in range(8):
        t = k / (8 * 47.0)
        X, Z = 1.0e-3 * math.sin(w * t), 1.5e-3 * (math.sin(w * t + math.pi / 2) - 1.0)
        th = 4.0e-3 * math.sin(w * t)
        Xd, Zd, thd = 1.0e-3 * w * math.cos(w * t), 1.5e-3 * w * math.cos(w * t + math.pi / 2), \
            4.0e-3 * w * math.cos(w * t)
        lab = np.zeros_like(p)
        vel = np.zeros_like(p)
        lab[:, 1] = p[:, 1]
        for q in range(p.shape[0]):
            lx, lz = tub_to_lab(p[q, 0], p[q, 2], X, Z, th, *PIVOT)
            lab[q, 0], lab[q, 2] = lx, lz
            vel[q, 0], vel[q, 2] = rigid_velocity(lx, lz, X, Z, Xd, Zd, thd, *PIVOT)
        acc.add(lab, vel, np.array([X, Z, th, Xd, Zd, thd]), vol, phase=k, batch=0)
    res = acc.result()
    ok = np.isfinite(res.shear_rate)
    assert ok.sum() > 50
    assert np.nanmax(res.shear_rate) < 1e-9


def test_near_wall_nodes_line_the_u():
    """The near-wall mask: nodes within a spacing of the U, on the arc and up the sides, none in
    the middle of the bed."""
    acc = PhaseShearAccumulator(H, NXH, NZ, LENGTH, 1, 1, PIVOT)
    res = acc.result()
    m = near_wall_nodes(res, 0.15)
    X, Z = np.meshgrid(res.x, res.z)
    assert m[(np.abs(X) < 1e-9) & (np.abs(Z) < 1e-9)].all()          # the lowest point
    assert m[(np.abs(X - 0.15) < 1e-9) & (np.abs(Z - 0.30) < 1e-9)].all()  # the right side
    assert not m[(np.abs(X) < 1e-9) & (np.abs(Z - 0.15) < 1e-9)].any()     # the centre
