"""benchmarks/kinetic_fit.py on a calibrated folder of synthetic cells with Lun's plus Johnson &
Jackson's pressure (phi_rcp 0.63, Fr 0.02 Pa, phi_min 0.5) and a 5 % log-normal scatter: the
joint fit's constants come back, and each solid-fraction band's residual has mean 0 and standard
deviation 0.05."""
from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from benchmark_module import load_benchmark
from vibroflow.calibration.kinetic import frictional_pressure, pressure_ratio
from vibroflow.calibration.run_fields import write_fields

RHO_S = 7800.0
E = 0.85
SCATTER = 0.05


def _calibrated_folder(path, n=800, seed=5):
    rng = np.random.default_rng(seed)
    phi = rng.uniform(0.1, 0.6, n)
    T = np.exp(rng.uniform(np.log(1e-4), np.log(2e-2), n))
    p = (RHO_S * phi * T * pressure_ratio(phi, 0.63, E) + frictional_pressure(phi, 0.63, 0.02, 0.5))
    p *= np.exp(SCATTER * rng.standard_normal(n))
    shape, dims = (8, n // 8), ("phase", "x")
    ph = xr.Dataset({name: (dims, v.reshape(shape)) for name, v in (
        ("solid_fraction", phi), ("temperature", T), ("pressure", p),
        ("solid_fraction_stderr", 1e-4 * phi), ("temperature_stderr", 0.01 * T),
        ("pressure_stderr", SCATTER * p))})
    write_fields(path / "fields.nc", xr.Dataset({"solid_fraction": (("x",), phi[:4])}), ph)
    (path / "calibration.toml").write_text(
        f"[media]\nsolid_density_kg_m3 = {RHO_S}\n\n[kinetic]\nrestitution = {E}\n")
    return path


def test_the_benchmark_gives_back_the_joint_constants_and_flat_band_residuals(tmp_path):
    out = load_benchmark("kinetic_fit").one_run(_calibrated_folder(tmp_path))
    j = out["joint"]
    assert j["points"] == 800
    assert j["phi_rcp"] == pytest.approx(0.63, abs=2e-3)
    assert j["frictional_Pa"] == pytest.approx(0.02, rel=0.2)
    assert j["frictional_phi_min"] == pytest.approx(0.5, abs=0.01)
    assert out["lun"]["rms_log_residual"] > 2.0 * j["rms_log_residual"]
    assert sum(b[2] for b in out["bands"]) == j["points"]
    for lo, hi, n, mean, sd in out["bands"]:
        # the scatter's own statistics: mean 0 within 4 standard errors, sd 0.05 within 30 %
        assert abs(mean) < 4.0 * SCATTER / np.sqrt(n), (lo, hi)
        assert sd == pytest.approx(SCATTER, rel=0.3), (lo, hi)
