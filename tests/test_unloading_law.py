"""The bed's non-linear unloading law K_t = K_ref (p / p_ref)^n (vibroflow.calibration.unloading,
docs/validation.md section 22, "The unloading law"): the fit recovers a known law from
synthetic phase fields, a single cell under the law unloads along the law's closed-form
p(eps_v) integrated by hand, and the continuum's --moduli unloading-law takes the calibration's
keys."""
from __future__ import annotations

import math

import numpy as np
import pytest

from vibroflow.calibration.unloading import tangent_law_of_fields, unloading_law
from vibroflow.continuum.constitutive import ContinuumMaterial
from vibroflow.continuum.material import material_of
from vibroflow.continuum.options import ContinuumOptions, options_record
from vibroflow.continuum.stress_update import update_stress_points
from vibroflow.errors import InputError
from vibroflow.io.calibration_file import read_calibration
from vibroflow.scenario.io import load_scenario

CALIBRATION = "tests/data/tub47-quick-dem/calibration.toml"
H, DT = 5.0e-3, 1.0 / (8 * 47.0)


def _p_of_eps(eps, p0, K_ref, p_ref, n):
    """The law integrated by hand: dp / p^n = K_ref p_ref^-n d eps, so
    p^(1-n) = p0^(1-n) + (1 - n) K_ref p_ref^-n eps (n != 1), p = p0 exp(K_ref eps / p_ref)
    (n = 1)."""
    if n == 1.0:
        return p0 * np.exp(K_ref * eps / p_ref)
    return (p0 ** (1 - n) + (1 - n) * K_ref * p_ref ** -n * eps) ** (1 / (1 - n))


def _branch(K_ref, p_ref, n, steps=2, cells=(6, 5)):
    """Synthetic phase fields (bins 0 .. steps) of cells unloading along the law from their own
    peak pressures (8 - 15 kPa), each step its own strain, at rest."""
    rng = np.random.default_rng(7)
    p0 = rng.uniform(8.0e3, 15.0e3, cells)
    eps = np.cumsum(np.concatenate([np.zeros((1,) + cells),
                                    -rng.uniform(1e-4, 3e-4, (steps,) + cells)]), axis=0)
    p = _p_of_eps(eps, p0[None], K_ref, p_ref, n)
    phi = 0.56 * np.exp(eps)
    return p, phi, np.zeros(p.shape + (3,)), list(zip(range(steps), range(1, steps + 1)))


@pytest.mark.parametrize("n", [1.0 / 3.0, 1.0, 2.0])
@pytest.mark.parametrize("steps", [2, 3])
def test_the_fit_recovers_a_known_law(n, steps):
    K_ref, p_ref = 4.0e6, 2.0e3
    p, phi, v, pairs = _branch(K_ref, p_ref, n, steps)
    dense = np.ones(p.shape[1:], bool)
    K, nn, rms, k = tangent_law_of_fields(p, phi, v, pairs, dense, DT, H, p_ref)
    assert k == steps
    assert K == pytest.approx(K_ref, rel=1e-9)
    assert nn == pytest.approx(n, rel=1e-9)
    assert rms < 1e-9
    # the same law at another reference pressure: K_ref (p' / p_ref)^n
    K2, n2, _, _ = tangent_law_of_fields(p, phi, v, pairs, dense, DT, H, 5.0e3)
    assert K2 == pytest.approx(K_ref * 2.5 ** n, rel=1e-9)
    assert n2 == pytest.approx(n, rel=1e-9)


def test_the_law_takes_its_reference_at_the_branchs_middle():
    p, phi, v, pairs = _branch(4.0e6, 2.0e3, 2.0)
    u = unloading_law(p, phi, v, pairs, np.ones(p.shape[1:], bool), DT, H, 9.0e3, 400.0)
    assert u["law_p_ref"] == pytest.approx(math.sqrt(9.0e3 * 400.0), rel=1e-12)
    assert u["law_K_ref"] == pytest.approx(4.0e6 * (u["law_p_ref"] / 2.0e3) ** 2, rel=1e-9)
    assert u["law_p_min"] < u["law_p_max"]


def test_a_cell_under_the_law_unloads_along_its_closed_form():
    """An isotropic plane-strain expansion (tr D < 0) of a cell at p0 = 9 kPa: its pressure
    follows the law's p(eps_v) down to p_min, below which the tangent is K_t(p_min)
    (linear), against the hand integration (forward Euler's error O(dt), under 1e-3 here)."""
    K_ref, p_ref, n, lo, hi = 3.7e6, 1.9e3, 2.0, 800.0, 13.5e3
    mat = ContinuumMaterial(bulk_modulus=K_ref * (hi / p_ref) ** n, shear_modulus=1.0e6,
                            bulk_law=(K_ref, p_ref, n, lo, hi))
    params = mat.as_array()
    p0, rate, dt, nstep = 9.0e3, 0.5, 2.0e-7, 20000
    stress = np.array([[-p0, -p0, 0.0, -p0]])
    L = np.array([[rate / 2.0, 0.0, 0.0, rate / 2.0]])  # tr D = rate, eps_v = -rate t
    density = np.array([2.0 * mat.critical_density])
    gd, st = np.zeros(1), np.zeros(1, np.int8)
    eps = -rate * dt * np.arange(1, nstep + 1)
    got = np.empty(nstep)
    for i in range(nstep):
        update_stress_points(stress, L, density, dt, params, gd, st)
        got[i] = -(stress[0, 0] + stress[0, 1] + stress[0, 3]) / 3.0
    # the law to p_min, at eps_lo; then linear at K_t(p_min)
    eps_lo = (lo ** (1 - n) - p0 ** (1 - n)) * p_ref ** n / ((1 - n) * K_ref)
    want = np.where(eps > eps_lo, _p_of_eps(np.maximum(eps, eps_lo), p0, K_ref, p_ref, n),
                    lo + K_ref * (lo / p_ref) ** n * (eps - eps_lo))
    live = want > 50.0
    assert live.sum() > 10000 and (eps[live] < eps_lo).any()
    assert np.max(np.abs(got[live] - want[live]) / want[live]) < 1e-3
    # without the law the same cell unloads linearly at bulk_modulus
    lin = ContinuumMaterial(bulk_modulus=3.0e6, shear_modulus=1.0e6).as_array()
    stress = np.array([[-p0, -p0, 0.0, -p0]])
    update_stress_points(stress, L, density, dt, lin, gd, st)
    assert -(stress[0, 0] + stress[0, 1] + stress[0, 3]) / 3.0 == pytest.approx(
        p0 - 3.0e6 * rate * dt, rel=1e-12)


def test_the_unloading_law_option_takes_the_calibrations_keys():
    s = load_scenario("tub47-quick")
    cal = read_calibration(CALIBRATION)
    with pytest.raises(InputError, match="unloading_law_modulus_Pa = missing"):
        material_of(s, cal, moduli="unloading_law")
    keys = {"unloading_law_modulus_Pa": 3.7e6, "unloading_law_reference_pressure_Pa": 1.9e3,
            "unloading_law_exponent": 2.0, "unloading_law_min_pressure_Pa": 240.0,
            "unloading_law_max_pressure_Pa": 1.35e4}
    e = cal.elastic.model_copy(update=keys)
    mat = material_of(s, cal.model_copy(update={"elastic": e}), moduli="unloading_law")
    assert mat.bulk_law == (3.7e6, 1.9e3, 2.0, 240.0, 1.35e4)
    assert mat.bulk_modulus == pytest.approx(3.7e6 * (1.35e4 / 1.9e3) ** 2, rel=1e-12)
    assert mat.shear_modulus == cal.elastic.shear_modulus_small_strain_Pa
    bad = cal.elastic.model_copy(update={**keys, "unloading_law_min_pressure_Pa": 2.0e4})
    with pytest.raises(InputError, match="p_min < p_max"):
        material_of(s, cal.model_copy(update={"elastic": bad}), moduli="unloading_law")
    assert options_record(ContinuumOptions(transfer_cfl=None, moduli="unloading_law")
                          )["moduli"] == "unloading_law"
    # off: no part of the material's record
    assert "bulk_law" not in material_of(s, cal).to_dict()
