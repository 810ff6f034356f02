"""The cyclic compaction option of the shared constitutive law (vibroflow.continuum.constitutive,
"Option: compaction") against the rate form of Sawicki & Swidzinski's (1989) compaction law
integrated by hand,

    d phi / d gamma = (phi_cyc - phi) / gamma_c
        ->  phi(gamma) = phi_cyc - (phi_cyc - phi_0) e^(-gamma / gamma_c),

for one point cycled in simple shear below yield at constant pressure (gamma the accumulated
|shear strain|, 4 gamma_0 a cycle); and the calibration's fit (vibroflow.calibration.compaction)
against per-cycle packings of a known law.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from vibroflow.calibration.compaction import compaction_table, fit_compaction
from vibroflow.continuum.constitutive import ContinuumMaterial
from vibroflow.continuum.stress_update import update_stress_points
from vibroflow.errors import InputError
from tests.test_constitutive_dilatancy import barostat_point, barostat_step

MAT = dict(bulk_modulus=2.0e6, shear_modulus=1.0e6, critical_solid_fraction=0.60)
P0 = 5.0e3       # Pa
RATE = 1.0       # 1/s, |shear rate| of the triangular strain cycle
DT = 1.0e-5      # s
GAMMA_0 = 1.0e-3  # strain amplitude: G gamma_0 = 1 kPa < mu_s p = 1.9 kPa, elastic throughout


def cycled_point(mat, phi0, cycles, p0=P0):
    """One point at the unloaded packing phi0 and isotropic pressure p0, sheared in triangular
    cycles of amplitude GAMMA_0 (strain 0 -> gamma_0 -> -gamma_0 -> 0) with a perfect barostat
    (an isotropic strain rate that brings the trial pressure back to p0 every step, as in
    test_constitutive_dilatancy).  Returns the accumulated equivalent shear strain of the
    imposed motion (sqrt(2 D':D') dt summed: the shear RATE and the barostat's in-plane
    isotropic rate e, which plane strain makes partly deviatoric, sqrt(RATE^2 + 4 e^2 / 3)), the
    unloaded packing rho exp(-p / K) / rho_s and the state at the end of each cycle."""
    K, stress, rho, gd, st, params = barostat_point(mat, phi0, p0)
    quarter = int(round(GAMMA_0 / (RATE * DT)))
    signs = [1.0] * quarter + [-1.0] * (2 * quarter) + [1.0] * quarter
    out = []
    gamma = 0.0
    for c in range(cycles):
        for sgn in signs:
            e = barostat_step(stress, rho, sgn * RATE, p0, K, DT, params, gd, st)
            gamma += math.sqrt(RATE**2 + 4.0 * e * e / 3.0) * DT
        pr = -(stress[0, 0] + stress[0, 1] + stress[0, 3]) / 3.0
        out.append((gamma, rho[0] * math.exp(-pr / K) / mat.solid_density,
                    int(st[0])))
    return out


def test_cycled_point_follows_the_compaction_law():
    gamma_c, excess = 0.02, 0.01
    mat = ContinuumMaterial(**MAT, compaction_strain=gamma_c, compaction_excess=excess)
    phi0 = 0.601
    phi_cyc = 0.60 + excess
    for gamma, phi, state in cycled_point(mat, phi0, 8):
        assert state == 1  # connected and elastic: the compaction does not need yield
        expected = phi_cyc - (phi_cyc - phi0) * math.exp(-gamma / gamma_c)
        # gamma > 4 gamma_0 N by ~2 %: the barostat recompresses the compacted point in plane
        # strain; the law holds to the step's first order (the barostat lags a step)
        assert phi == pytest.approx(expected, abs=1e-7)
    assert phi > phi0 + 0.8 * (phi_cyc - phi0)  # 1.6 e-folds: it did compact


def test_no_compaction_beyond_the_cyclic_packing_and_off_by_default():
    # a packing already denser than phi_cyc stays where it is (dilation is the dilatancy's job)
    mat = ContinuumMaterial(**MAT, compaction_strain=0.02, compaction_excess=0.005)
    for _, phi, _ in cycled_point(mat, 0.61, 2):
        assert phi == pytest.approx(0.61, abs=1e-9)
    # gamma_c = 0: the plain law, whose elastic cycles leave the packing unchanged
    plain = ContinuumMaterial(**MAT)
    for _, phi, _ in cycled_point(plain, 0.601, 2):
        assert phi == pytest.approx(0.601, abs=1e-9)


def test_stress_free_point_does_not_compact():
    mat = ContinuumMaterial(**MAT, compaction_strain=0.02, compaction_excess=0.01)
    stress = np.zeros((1, 4))
    rho = np.array([0.605 * mat.solid_density])
    gd, st = np.zeros(1), np.zeros(1, np.int8)
    update_stress_points(stress, np.array([[0.0, 1.0, 0.0, 0.0]]), rho, DT, mat.as_array(),
                         gd, st)
    # the shear's trial stress has p = 0: no compression, nothing to carry, nothing compacts
    assert stress[0, 0] + stress[0, 1] + stress[0, 3] == 0.0


def test_fit_recovers_a_known_law():
    phi_inf, phi_start, nc, g0 = 0.6124, 0.5992, 2.5, 0.0093
    n = np.arange(1, 7)
    ends = phi_inf - (phi_inf - phi_start) * np.exp(-n / nc)
    fit = fit_compaction(phi_start, ends, g0)
    assert fit["phi_inf"] == pytest.approx(phi_inf, abs=1e-7)
    assert fit["cycles"] == pytest.approx(nc, rel=1e-4)
    assert fit["gamma_c"] == pytest.approx(4.0 * g0 * nc, rel=1e-4)
    with pytest.raises(InputError):
        fit_compaction(0.61, [0.605, 0.604, 0.603], g0)  # a packing that loosened


def test_compaction_table_refers_the_excess_to_phi_c():
    # cyclic packing 0.612, steady-shear packing 0.600 at I = 0.02, phi(I) slope 0.2: the steady
    # packing at I = 0 is 0.604, so the continuum's phi_cyc is phi_c + 0.008
    n = np.arange(1, 7)
    ends = 0.612 - (0.612 - 0.599) * np.exp(-n / 2.0)
    t = compaction_table({"tub_strain_amplitude": 0.01,
                          "solid_fraction_start_at_tub_amplitude": 0.599,
                          "solid_fraction_cycle_end_at_tub_amplitude": list(ends)},
                         {"phi_ss": [0.599, 0.601], "inertial_number": 0.02},
                         {"phi_max": 0.57, "phi_min": 0.37})
    assert t["excess_solid_fraction"] == pytest.approx(0.008, abs=1e-6)
    assert t["compaction_strain"] == pytest.approx(0.08, rel=1e-4)
