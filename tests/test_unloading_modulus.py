"""The bed's unloading bulk modulus (vibroflow.calibration.unloading, docs/validation.md section
22, "The unloading stiffness, measured"): the branch and the secant on synthetic
phase-resolved fields whose K is known, the material change of a field carried by the flow,
the batch-means standard error against a hand value, and the continuum's --moduli unloading
that takes it."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from vibroflow.calibration.unloading import (material_changes, unloading_branch,
                                             unloading_bulk_modulus)
from vibroflow.continuum.material import material_of
from vibroflow.continuum.options import ContinuumOptions, options_record
from vibroflow.errors import InputError
from vibroflow.io.calibration_file import read_calibration
from vibroflow.scenario.io import load_scenario

CALIBRATION = "tests/data/tub47-quick-dem/calibration.toml"

#: one cycle in 8 phase bins: the volumetric strain eps_v (from the landing's peak) and the
#: bed's pressure factor; the landing peaks at bin 0, unloads at 1 - 2 (0.05 of the peak, the
#: release), flies at 3 - 5 (no stress, dilating further) and loads at 6 - 7
EPS = np.array([0.0, -0.6e-3, -1.2e-3, -3.0e-3, -4.0e-3, -3.0e-3, -2.0e-3, -1.0e-3])


def _fields(K, k_load=6.0e6, cells=(3, 4), peak_first=False):
    """Synthetic phase-resolved pressure, solid fraction and velocity (zero) (8, nx, nz[, 3]):
    each cell its own packing phi_0 and peak pressure p_0; on the unloading branch (bins 0 -
    2) p = p_0 + K eps_v, elsewhere p follows a stiffer loading line or is zero in flight; a
    loose column (phi 0.3) beside them, which the fit leaves out.  peak_first: the pressure
    peaks a bin before the largest compaction (bin 7 at 1.1 p_0), as the contacts' dashpots
    make it in the DEM."""
    nx, nz = cells
    phi0 = 0.58 + 0.01 * np.arange(nx * nz).reshape(nx, nz) / (nx * nz)
    p0 = 2400.0 + 20.0 * np.arange(nx * nz).reshape(nx, nz)
    phi = phi0[None] * np.exp(EPS)[:, None, None]
    p = np.empty_like(phi)
    for k, e in enumerate(EPS):
        if k <= 2:
            p[k] = p0 + K * e
        elif k <= 5:
            p[k] = 0.0
        else:
            p[k] = p0 + k_load * e
    if peak_first:
        p[7] = 1.1 * p0
    p = np.concatenate([p, np.zeros((8, 1, nz))], axis=1)
    phi = np.concatenate([phi, np.full((8, 1, nz), 0.3)], axis=1)
    return p, phi, np.zeros(p.shape + (3,))


H, F = 0.005, 47.0
DT = 1.0 / (8 * F)


def test_the_branch_runs_from_the_largest_compaction_to_the_release():
    assert unloading_branch([1.0, 5.0, 3.0, 0.4, 0.2, 0.3, 0.6, 0.8]) == [1, 2, 3]
    # cyclic, and it stops where the pressure rises again before the release
    assert unloading_branch([2.0, 3.0, 1.0, 4.0, 9.0, 6.0, 5.0, 3.5]) == [4, 5, 6, 7, 0]
    # the pressure peaks at 1, the bed compacts most at 2: the branch starts there
    assert unloading_branch([1.0, 5.0, 3.0, 0.4, 0.2, 0.3, 0.6, 0.8],
                            [0.0, 1.0, 2.0, 1.0, 0.0, 0.0, 0.0, 0.0]) == [2, 3]


def test_the_fit_recovers_a_known_unloading_modulus():
    K = 1.9e6  # the mean peak 2510 Pa falls by K 1.2e-3 = 2280 Pa: 0.09 of it at bin 2
    p, phi, v = _fields(K, peak_first=True)
    # the divergence that carries the same strain: eps falls 0.6e-3 a bin at bins 0 - 2
    D = np.zeros(p.shape + (3, 3))
    D[:3, ..., 0, 0] = 0.6e-3 / DT
    u = unloading_bulk_modulus(p, phi, v, H, F, strain_rate=D)
    assert u["branch_phases"] == [0, 1, 2]
    assert u["bulk_modulus"] == pytest.approx(K, rel=1e-9)
    assert u["divergence"] == pytest.approx(K, rel=1e-9)
    assert u["eulerian"] == pytest.approx(K, rel=1e-9)
    assert u["tangent_start"] == pytest.approx(K, rel=1e-9)
    assert u["tangent_end"] == pytest.approx(K, rel=1e-9)
    assert u["cells"] == 12  # the loose column left out
    assert u["volumetric_strain"] == pytest.approx(1.2e-3, rel=1e-9)
    # 1.2e-3 over 2/8 of a 47 Hz cycle
    assert u["strain_rate"] == pytest.approx(1.2e-3 / (2.0 * DT), rel=1e-9)
    assert math.isnan(u["bulk_modulus_stderr"])


def test_a_field_carried_by_the_flow_has_no_material_change():
    # q = 3 x - 2 z (per m) translated at v = (0.1, 0, 0.4) m/s: q_(k+1) = q_k - (v . grad q) dt
    x, z = np.meshgrid(np.arange(6) * H, np.arange(5) * H, indexing="ij")
    q0 = 3.0 * x - 2.0 * z
    q = np.stack([q0 - k * (0.1 * 3.0 - 0.4 * 2.0) * DT for k in range(3)])
    v = np.broadcast_to(np.array([0.1, 0.0, 0.4]), q.shape + (3,))
    for d in material_changes(q, v, [(0, 1), (1, 2)], DT, H):
        assert np.abs(d).max() < 1e-15
    # at rest the change is the fixed point's: 0.5 m/s x 1 1/m x DT
    d = material_changes(q, np.zeros_like(v), [(0, 1)], DT, H)[0]
    assert d == pytest.approx(np.full(d.shape, 0.5 * DT), rel=1e-12)


def test_the_standard_error_is_the_batch_means():
    moduli = (1.8e6, 2.0e6, 1.9e6, 1.9e6)
    fields = [_fields(k) for k in moduli]
    batches = {name: np.stack([f[i] for f in fields])
               for i, name in enumerate(("pressure", "solid_fraction", "velocity"))}
    u = unloading_bulk_modulus(*_fields(1.9e6), H, F, batches)
    assert u["batch_moduli"] == pytest.approx(list(moduli), rel=1e-9)
    # std(ddof=1) of (-1, 1, 0, 0) x 1e5 Pa over sqrt(4): sqrt(2/3) 1e5 / 2
    assert u["bulk_modulus_stderr"] == pytest.approx(math.sqrt(2.0 / 3.0) * 1e5 / 2.0, rel=1e-9)


def test_a_bed_without_dense_cells_or_unloading_is_refused():
    p, phi, v = _fields(1.9e6)
    with pytest.raises(InputError, match="no cell with solid fraction"):
        unloading_bulk_modulus(p, np.full_like(phi, 0.3), v, H, F)
    with pytest.raises(InputError, match="does not fall"):
        unloading_bulk_modulus(np.ones_like(p), phi, v, H, F)


def test_the_unloading_moduli_option_takes_the_calibrations_keys():
    s = load_scenario("tub47-quick")
    cal = read_calibration(CALIBRATION)
    with pytest.raises(InputError, match="unloading_bulk_modulus_Pa = missing"):
        material_of(s, cal, moduli="unloading")
    with pytest.raises(InputError, match="needs a calibration"):
        material_of(s, None, moduli="unloading")
    e = cal.elastic.model_copy(update={"unloading_bulk_modulus_Pa": 3.0e6})
    cal2 = cal.model_copy(update={"elastic": e})
    base = material_of(s, cal)
    mat = material_of(s, cal2, moduli="unloading")
    assert mat.bulk_modulus == 3.0e6
    assert mat.shear_modulus == cal.elastic.shear_modulus_small_strain_Pa
    assert dataclasses.replace(mat, bulk_modulus=base.bulk_modulus,
                               shear_modulus=base.shear_modulus) == base
    with pytest.raises(InputError, match="moduli = 'soft'"):
        ContinuumOptions(transfer_cfl=None, moduli="soft")
    # at its default the option is no part of a run's record (its fingerprint)
    assert "moduli" not in options_record(ContinuumOptions(transfer_cfl=None))
    assert options_record(ContinuumOptions(transfer_cfl=None, moduli="unloading")
                          )["moduli"] == "unloading"
