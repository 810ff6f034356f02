"""The vibrated layer: the DEM strip of tub47's balls on tub47's vertical stroke
(Gamma 13.3), stored in tests/data/vibrated-layer-dem (its README says the command), against
both continua's strip with the granular temperature on.

The stored DEM is checked against known answers (the floor carries the weight over a cycle;
the bands hold the layer's mass at every phase).  The continua are judged, as the project asks,
within the DEM's seed scatter: the cycle-mean temperature and solid-fraction profiles in the
bands the DEM's bed fills (cycle-mean solid fraction above FILLED) within 2 seed standard
deviations, and the take-off phase within 2 seed standard deviations plus the force's bin.
Targets missed are strict xfails, each with a guard on its measured miss
(docs/validation.md, "The vibrated layer").
"""
from __future__ import annotations

import json
import math
import warnings
from pathlib import Path

import numpy as np
import pytest

DATA = Path(__file__).parent / "data" / "vibrated-layer-dem" / "layer.json"
G = 9.81
#: the DEM bands compared: cycle-mean solid fraction above this
FILLED = 0.1


@pytest.fixture(scope="module")
def dem():
    return json.loads(DATA.read_text())


def _cycle_means(r, key):
    # NaN for a band that no phase filled (above the layer), without numpy's warning for it
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanmean(np.array(r[key], float), axis=0)


def dem_targets(dem):
    """The DEM's seed means and seed standard deviations of the compared measures."""
    out = {}
    for key in ("temperature_m2_s2", "solid_fraction"):
        a = np.array([_cycle_means(r, key) for r in dem["seeds"]])
        out[key] = (a.mean(0), a.std(0, ddof=1))
    phi = out["solid_fraction"][0]
    out["bands"] = np.nonzero(phi > FILLED)[0]
    off = np.array([r["take_off_phase"] for r in dem["seeds"]])
    c = dem["summary"]["take_off_phase"]
    out["take_off_phase"] = (c, np.std(np.mod(off - c + 0.5, 1.0) - 0.5, ddof=1))
    return out


def misses(dem, c):
    """Per measure: the continuum's largest |difference| / (2 seed standard deviations) over
    the filled bands (> 1: missed), and the take-off's |difference| / its allowance."""
    t = dem_targets(dem)
    out = {}
    for key in ("temperature_m2_s2", "solid_fraction"):
        mean, sd = t[key]
        cm = np.nan_to_num(_cycle_means(c, key)[: mean.size])
        b = t["bands"][t["bands"] < cm.size]
        out[key] = float(np.max(np.abs(cm[b] - mean[b]) / (2 * sd[b])))
    off, sd = t["take_off_phase"]
    d = abs(np.mod(c["take_off_phase"] - off + 0.5, 1.0) - 0.5)
    out["take_off_phase"] = float(d / (2 * sd + 1.0 / len(c["force_phase"])))
    return out


def test_the_dem_floor_carries_the_layers_weight_over_a_cycle(dem):
    # momentum balance: the layer's momentum is bounded, so the floor's mean force is M g
    for r in dem["seeds"]:
        mean, se = r["floor_force_cycle_mean_over_weight"], r["floor_force_cycle_mean_stderr"]
        assert abs(mean - 1.0) < 3 * se + 0.01


def test_the_dem_bands_hold_the_layers_mass_at_every_phase(dem):
    strip = dem["strip"]
    band = dem["setup"]["band_m"]
    for r in dem["seeds"]:
        phi = np.array(r["solid_fraction"])
        held = phi.sum(1) * band * strip["length_m"] * strip["width_m"] * strip["density_kg_m3"]
        # the stored fractions carry 4 significant digits
        assert held == pytest.approx(np.full(phi.shape[0], r["mass_kg"]), rel=1e-3)


def test_the_dem_layer_flies_each_cycle_after_the_block_would(dem):
    # Gamma 13.3: a block would leave at sin(psi) = 1 / Gamma; the deep compliant bed leaves
    # later, and is off the floor (force below a twentieth of its weight) for part of a cycle
    block = math.asin(1.0 / dem["stroke"]["gamma"]) / (2 * math.pi)
    s = dem["summary"]
    assert s["take_off_phase"] > block
    assert np.min(s["floor_force_over_weight"]) < 0.05
    assert np.max(s["floor_force_over_weight"]) > 2.0


_RUNS: dict = {}


def continuum(method, dem):
    """The continuum's strip with T on, the DEM's setup and mass per floor area (one run a
    formulation per session)."""
    if method not in _RUNS:
        from vibroflow.calibration.vibrated_layer import LayerSetup
        from vibroflow.calibration.vibrated_layer_continuum import continuum_layer
        from vibroflow.io.calibration_file import read_calibration
        from vibroflow.scenario.io import load_scenario

        setup = LayerSetup(**{k: (tuple(v) if k == "seeds" else v)
                              for k, v in dem["setup"].items()})
        cal = read_calibration(Path(__file__).parent / "data" / "tub47-dem"
                               / "calibration.toml")
        strip = dem["strip"]
        mass = dem["seeds"][0]["mass_kg"] / (strip["length_m"] * strip["width_m"])
        c = continuum_layer(method, load_scenario("tub47", []), cal, setup, mass)
        _RUNS[method] = (c, misses(dem, c))
    return _RUNS[method]


def _xfail(why):
    return pytest.mark.xfail(strict=True, reason=why)


_COLD = ("the walls' feed heats the floor band, but the core stays 4.5 - 32 (Lagrangian) and "
         "10 - 44 times (Eulerian) colder than the DEM's 0.002 - 0.003 m^2/s^2: Gidaspow's "
         "conduction does not carry the landing's energy up, where the DEM's flux is "
         "collisional and phase-locked to the landing (validation 23)")
_DENSE = ("the core packs at up to 0.59 - 0.60 (Lagrangian) and 0.62 (Eulerian) against the "
          "DEM's 0.53 - 0.56: the kinetic pressure of a core that cold cannot hold it open")
#: the measured misses (docs/validation.md section 23): (formulation, measure) -> why
MISSED = {("lagrangian", "temperature_m2_s2"): _COLD,
          ("eulerian", "temperature_m2_s2"): _COLD,
          ("lagrangian", "solid_fraction"): _DENSE,
          ("eulerian", "solid_fraction"): _DENSE}

#: the guards on the measured misses: the largest |difference| / allowance each may reach
#: (measured: T 11.1 and 12.2, solid fraction 6.7 and 7.7)
GUARD = {("lagrangian", "temperature_m2_s2"): 12.0, ("eulerian", "temperature_m2_s2"): 13.0,
         ("lagrangian", "solid_fraction"): 7.5, ("eulerian", "solid_fraction"): 8.5}
#: the floor force's lowest value over the cycle / weight may reach (measured: 0.01 and -0.003)
FLOOR_GUARD = 0.1

CASES = [pytest.param(m, k, marks=[pytest.mark.slow]
                      + ([_xfail(MISSED[(m, k)])] if (m, k) in MISSED else []),
                      id=f"{m}-{k}")
         for m in ("lagrangian", "eulerian")
         for k in ("temperature_m2_s2", "solid_fraction", "take_off_phase")]


@pytest.mark.parametrize("method, measure", CASES)
def test_the_continuum_layer_is_the_dems_within_its_seed_scatter(dem, method, measure):
    c, miss = continuum(method, dem)
    assert miss[measure] <= 1.0, f"{method} {measure}: {miss[measure]:.2f} x the allowance"


@pytest.mark.slow
@pytest.mark.parametrize("method", ["lagrangian", "eulerian"])
def test_the_continuum_layers_misses_stay_within_their_guards(dem, method):
    c, miss = continuum(method, dem)
    assert np.all(np.isfinite(np.array(c["floor_force_over_weight"])))
    # the continuum's momentum balance: over whole cycles the floor carries the weight (the
    # Eulerian's to 2 %, the Lagrangian's to 3 %: docs/validation.md 23)
    assert abs(c["floor_force_cycle_mean_over_weight"] - 1.0) < 0.08
    T = np.array(c["temperature_m2_s2"], float)
    assert np.all(T[np.isfinite(T)] >= 0.0)
    assert np.nanmin(np.array(c["floor_force_over_weight"], float)) < FLOOR_GUARD
    for (m, key), bound in GUARD.items():
        if m == method:
            assert miss[key] <= bound, f"{method} {key}: {miss[key]:.2f} > {bound}"


@pytest.mark.parametrize("field, value", [("cycles", 3), ("n_phases", 1), ("band_m", 0.0),
                                          ("gamma", -1.0), ("seeds", ()),
                                          ("thermal_width_d", 0.0)])
def test_a_bad_layer_setup_is_named(field, value):
    from vibroflow.calibration.vibrated_layer import LayerSetup
    from vibroflow.errors import InputError

    with pytest.raises(InputError, match=field):
        LayerSetup(**{field: value}).check()


def _calibration_with_kinetic(tmp_path, table):
    from vibroflow.io.calibration_file import read_calibration

    src = (Path(__file__).parent / "data" / "tub47-dem" / "calibration.toml").read_text()
    path = tmp_path / "calibration.toml"
    path.write_text(src + "\n[kinetic]\n" + table)
    return read_calibration(path)


def test_the_continuum_layer_takes_the_calibrated_kinetic_constants(tmp_path):
    from vibroflow.calibration.vibrated_layer_continuum import kinetic_constants
    from vibroflow.continuum.kinetic_theory import LUN_SAVAGE
    from vibroflow.errors import InputError
    from vibroflow.io.calibration_file import read_calibration
    from vibroflow.scenario.io import load_scenario

    sc = load_scenario("tub47", [])
    stored = read_calibration(Path(__file__).parent / "data" / "tub47-dem" / "calibration.toml")
    prm, source = kinetic_constants(sc, stored)
    assert prm.restitution == 0.85 and "no calibrated" in source  # tub47's ball-ball e
    cal = _calibration_with_kinetic(tmp_path, 'phi_rcp = 0.62\nrestitution = 0.8\n'
                                    'g0_form = "lun_savage"\n')
    prm, source = kinetic_constants(sc, cal)
    assert (prm.phi_rcp, prm.restitution, prm.g0_form) == (0.62, 0.8, LUN_SAVAGE)
    assert source == "calibration [kinetic]"
    bad = _calibration_with_kinetic(tmp_path, 'phi_rcp = 0.62\ng0_form = "hard"\n')
    with pytest.raises(InputError, match="g0_form"):
        kinetic_constants(sc, bad)
