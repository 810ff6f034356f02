"""The bulk velocity's batches beside bulk_velocity.csv (measure.bulk_batches): the batch-means
standard errors of a synthetic signal of known scatter, the files' layout and units, the
table's batches read back bit for bit, and the turnover time's standard error from them."""
from __future__ import annotations

import math

import numpy as np
import pytest

from vibroflow.measure.bulk import CellTable, read_csv, write_csv
from vibroflow.measure.bulk_batches import (BATCHES_COLUMNS, BATCHES_CSV_NAME, STDERR_COLUMNS,
                                            STDERR_CSV_NAME, with_batches, write_batch_csvs)
from vibroflow.measure.summary import tub_summary
from vibroflow.report.bed_state import turnover_time
from vibroflow.scenario.model import Scenario

F = 47.0
H = 0.015


def _scenario(batches: int = 4) -> Scenario:
    sc = Scenario()
    return sc.model_copy(update={
        "run": sc.run.model_copy(update={"duration": 20 / F, "average_last": 8 / F,
                                         "batches": batches}),
        "tub": sc.tub.model_copy(update={"length": 0.01})})


def test_batch_stderr_of_a_steady_field_with_alternating_batches(tmp_path):
    """Two balls in a still tub over 8 cycles in 4 batches of 2.  Ball A (cell x = 0,
    z = 0.03 m) moves at v0 + s_b a with s_b = +1, -1, +1, -1 by batch, plus +-d alternating
    from sample to sample inside a batch (zero in each batch's mean): the batch means are
    v0 +- a, so SE = sqrt(sum (a)^2 / (n - 1) / n) = a / sqrt(3) exactly with n = 4.  Ball B
    (cell x = 0.015, z = 0.045 m) moves steadily and leaves the grid in the last batch: its
    velocity's SE is 0 over 3 batches, its solid fraction's (p, p, p, 0 by batch) is p / 4."""
    sc = _scenario()
    t0 = sc.run.duration - sc.run.average_last
    P = 8
    times = t0 + np.arange(8 * P) / (F * P)
    batch = np.arange(times.size) // (2 * P)
    sign = np.where(batch % 2 == 0, 1.0, -1.0)
    wiggle = np.where(np.arange(times.size) % 2 == 0, 1.0, -1.0)
    v0, a, d = np.array([0.05, -0.02]), np.array([0.004, 0.010]), np.array([0.03, 0.07])
    y = 0.005
    pos = np.zeros((times.size, 2, 3), np.float32)
    vel = np.zeros((times.size, 2, 3), np.float32)
    pos[:, 0] = (0.0, y, 0.03)
    pos[:, 1] = (H, y, 0.045)
    pos[batch == 3, 1, 2] = 5.0  # above the grid: not counted
    vel[:, 0, 0] = v0[0] + sign * a[0] + wiggle * d[0]
    vel[:, 0, 2] = v0[1] + sign * a[1] + wiggle * d[1]
    vel[:, 1] = (0.02, 0.0, 0.01)
    radius = np.full(2, 0.002)
    source = {"attrs": {"frequency": F}, "snapshots/time": times,
              "snapshots/position": pos, "snapshots/velocity": vel,
              "snapshots/tub_pose": np.zeros((times.size, 6)), "particles/radius": radius}
    tub_summary(source, sc, bulk_csv=tmp_path / "bulk_velocity.csv", batch_csvs=True)

    lines = (tmp_path / STDERR_CSV_NAME).read_text().splitlines()
    assert lines[0] == "x,z,vx_stderr_m_s,vz_stderr_m_s,solid_fraction_stderr,batches"
    assert STDERR_COLUMNS["vx_stderr_m_s"] == "m s-1" and STDERR_COLUMNS["x"] == "m"
    rows = {(round(float(r[0]) / H), round(float(r[1]) / H)): r
            for r in (ln.split(",") for ln in lines[1:])}
    assert set(rows) == {(0, 2), (1, 3)}
    A, B = rows[(0, 2)], rows[(1, 3)]
    assert float(A[2]) == pytest.approx(a[0] / math.sqrt(3), rel=1e-5)
    assert float(A[3]) == pytest.approx(a[1] / math.sqrt(3), rel=1e-5)
    assert float(A[4]) == pytest.approx(0.0, abs=1e-15) and A[5] == "4"
    p = 4 / 3 * math.pi * 0.002**3 / (H * H * 0.01)
    assert float(B[2]) == pytest.approx(0.0, abs=1e-9) and B[5] == "3"
    assert float(B[4]) == pytest.approx(p / 4, rel=1e-12)

    # the batches file: a row per cell and batch that held a ball, numbers read back exactly
    blines = (tmp_path / BATCHES_CSV_NAME).read_text().splitlines()
    assert blines[0] == ",".join(BATCHES_COLUMNS) == \
        "batch,x,z,solid_fraction,vx_m_s,vz_m_s,samples"
    assert len(blines) == 1 + 4 + 3
    table = with_batches(read_csv(tmp_path / "bulk_velocity.csv", cell_size=H),
                         tmp_path / BATCHES_CSV_NAME)
    j = int(np.flatnonzero(table.ix == 0)[0])
    k = 1 - j
    assert table.batch_vx[:, j] == pytest.approx(v0[0] + np.array([1, -1, 1, -1]) * a[0],
                                                 rel=1e-5)
    assert np.isnan(table.batch_vx[3, k]) and table.batch_phi[3, k] == 0.0
    assert table.batch_samples[:, j].tolist() == [2 * P] * 4
    assert table.vx_stderr[j] == pytest.approx(a[0] / math.sqrt(3), rel=1e-5)
    assert table.solid_fraction_stderr[k] == pytest.approx(p / 4, rel=1e-12)


def test_with_batches_refuses_a_file_that_is_not_the_tables(tmp_path):
    """A batches file of another header, or of a cell the table lacks: one-line ValueError."""
    table = CellTable(x=np.array([0.0]), z=np.array([0.03]), solid_fraction=np.array([0.5]),
                      vx=np.array([0.1]), vz=np.array([0.0]), samples=np.array([3]),
                      cell_size=H)
    path = tmp_path / BATCHES_CSV_NAME
    path.write_text("batch,x,z,phi\n0,0,0.03,0.5\n")
    with pytest.raises(ValueError, match="header batch,x,z,phi: must be"):
        with_batches(table, path)
    path.write_text(",".join(BATCHES_COLUMNS) + "\n0,0.015,0.03,0.5,0.1,0.0,3\n")
    with pytest.raises(ValueError, match="row 1: cell x = 0.015, z = 0.03 m is not a cell"):
        with_batches(table, path)


def test_turnover_time_of_rigid_rotation_batches_has_the_hand_computed_stderr(tmp_path):
    """A bed turning rigidly about (0, 0.06 m) at Omega_b = Omega (1 + e s_b) in batch b
    (s = +1, -1, +1, -1), written and read back as a continuum's: every batch's vorticity is
    2 Omega_b exactly (linear field), so its turnover time is 2 pi / Omega_b and the standard
    error is std(2 pi / Omega_b, ddof=1) / 2."""
    omega, e = 2.0, 0.1
    s = np.array([1.0, -1.0, 1.0, -1.0])
    ii, kk = np.meshgrid(np.arange(-5, 6), np.arange(0, 9))
    x, z = ii.ravel() * H, kk.ravel() * H
    zc = 0.06
    wb = omega * (1 + e * s)[:, None]
    bvx, bvz = -wb * (z - zc), wb * x
    n = x.size
    cnt = np.full((4, n), 10)
    table = CellTable(x=x, z=z, solid_fraction=np.full(n, 0.6), vx=bvx.mean(axis=0),
                      vz=bvz.mean(axis=0), samples=cnt.sum(axis=0), cell_size=H,
                      batch_phi=np.full((4, n), 0.6), batch_vx=bvx, batch_vz=bvz,
                      batch_samples=cnt)
    write_csv(table, tmp_path / "bulk_velocity.csv")
    write_batch_csvs(table, tmp_path)
    back = with_batches(read_csv(tmp_path / "bulk_velocity.csv", cell_size=H),
                        tmp_path / BATCHES_CSV_NAME)
    t = turnover_time(back, 0.3)
    Tb = 2 * math.pi / (omega * (1 + e * s))
    assert t.time_s == pytest.approx(2 * math.pi / omega, rel=1e-9)
    assert t.stderr_s == pytest.approx(np.std(Tb, ddof=1) / 2, rel=1e-9)
