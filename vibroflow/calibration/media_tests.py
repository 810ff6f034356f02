"""DEM tests of the media at the bed's pressure, for the calibration (calibrate.py): mu(I) and
phi(I) from Lees-Edwards simple-shear cells and the elastic moduli from compression and shear
tests (dem_tests), the secant shear modulus in cyclic shear at the tub's strain amplitude
(cyclic_modulus -> [cyclic_shear]) and the dilatancy constant K_dil (dilatancy_table ->
[dilatancy])."""
from __future__ import annotations

import math

import numpy as np

from vibroflow.errors import InputError

from .calibration_tables import mu_phi_keys, toml_float
from .cyclic_shear import DEFAULT_AMPLITUDES, run_cyclic_shear, tub_strain_amplitude
from .dilatancy import DEFAULT_INERTIAL_NUMBER, run_dilatancy
from .elastic import elastic_moduli
from .rheology_fit import fit_mu_i, fit_phi_i
from .shear_cell import run_shear_cell


def dem_tests(sc, pressure: float, prog, options: dict):
    """Shear cells over a range of I and the elastic tests, at the bed's pressure."""
    if not (pressure > 0 and math.isfinite(pressure)):
        raise InputError(f"bed pressure = {pressure!r} Pa: the coarse-grained run has no dense "
                         f"cell with a positive pressure to run the shear cell at")
    prog.log(f"shear cells at the bed's pressure p = {pressure:.0f} Pa")
    rows = run_shear_cell(sc, pressure=pressure, progress=prog, **options)
    steady = [r for r in rows if r.get("steady", True)]
    for r in rows:
        if not r.get("steady", True):
            prog.log(f"shear cell at I = {r['I_target']:.3g} did not reach a steady state "
                     f"({r.get('reason', '')}): left out of the fit")
    if len(steady) < 3:
        raise InputError(f"shear cell: {len(steady)} of {len(rows)} points reached a steady "
                         f"state: need at least 3 for the mu(I) fit (give more strain)")
    I = np.array([r["I"] for r in steady])
    # the invariant stress ratio tau_eq / p (p = tr sigma / 3), the one the continuum's yield
    # surface and the tub's coarse-grained cells use; the simple-shear ratio sigma_xz/sigma_zz
    # is 0.03-0.04 lower (sigma_yy < sigma_zz) and is kept beside it
    mu = fit_mu_i(I, np.array([r["mu_eq"] for r in steady]),
                  np.array([r.get("mu_eq_stderr", np.nan) for r in steady]))
    mu_ss = fit_mu_i(I, np.array([r["mu"] for r in steady]),
                     np.array([r.get("mu_stderr", np.nan) for r in steady]))
    phi = fit_phi_i(I, np.array([r["phi"] for r in steady]),
                    np.array([r.get("phi_stderr", np.nan) for r in steady]))
    rheo = {"source": "shear cell (Lees-Edwards simple shear at imposed pressure)",
            "points": len(steady), "pressure": pressure, "status": "measured",
            "points_not_steady": len(rows) - len(steady)}
    rheo.update(mu_phi_keys(mu, phi))
    rheo["stress_ratio"] = "tau_eq / p (invariant); *_simple_shear: sigma_xz / sigma_zz"
    for k in ("mu_s", "mu_2", "I_0"):
        rheo[k + "_simple_shear"] = toml_float(mu_ss[k])
        rheo[k + "_simple_shear_stderr"] = toml_float(mu_ss[k + "_stderr"])
    prog.log("elastic tests (isotropic compression, simple shear)")
    el = elastic_moduli(sc, pressure=pressure)
    elastic = {"bulk_modulus": toml_float(el["bulk_modulus"]),
               "bulk_modulus_stderr": toml_float(el.get("bulk_modulus_stderr")),
               "shear_modulus": toml_float(el["shear_modulus"]),
               "shear_modulus_stderr": toml_float(el.get("shear_modulus_stderr")),
               "pressure": toml_float(el.get("pressure", pressure)),
               "solid_fraction": toml_float(el.get("solid_fraction")),
               "coordination_number": toml_float(el.get("coordination_number_non_rattler")),
               "source": "DEM compression and shear tests of a packed periodic bed"}
    return rheo, elastic, rows


def cyclic_modulus(sc, pressure: float, shear_rate: float, elastic: dict, prog) -> dict | None:
    """Run the cyclic shear cell (cyclic_shear) at the bed's pressure and the tub's frequency over
    the default amplitudes and the tub's own strain amplitude; replace elastic["shear_modulus"]
    (in place) by the secant modulus at the tub's amplitude, keeping the small-strain one.
    Returns the [cyclic_shear] table, or None when the bed has no measured shear rate."""
    if not (math.isfinite(shear_rate) and shear_rate > 0) or sc.motion is None:
        prog.log("cyclic shear skipped: no cycle-mean shear rate measured in the bed")
        return None
    f = float(sc.motion.frequency)
    g_tub = tub_strain_amplitude(shear_rate, f)
    amps = sorted({*DEFAULT_AMPLITUDES, g_tub})
    prog.log(f"cyclic shear at {f:g} Hz, p = {pressure:.4g} Pa; the tub's strain amplitude "
             f"{g_tub:.3g} (cycle-mean shear rate {shear_rate:.3g} 1/s)")
    recs = run_cyclic_shear(sc, amps, frequency=f, pressure=pressure, progress=prog)
    at = next(r for r in recs if r["strain_amplitude"] == g_tub)
    small = (elastic["shear_modulus"], elastic.get("shear_modulus_stderr", float("nan")),
             elastic.get("source", ""))
    elastic["shear_modulus_small_strain"], elastic["shear_modulus_small_strain_stderr"] = \
        small[0], small[1]
    elastic["shear_modulus"] = at["secant_shear_modulus"]
    elastic["shear_modulus_stderr"] = at["secant_shear_modulus_stderr"]
    elastic["source"] = (f"bulk modulus: {small[2]}; shear modulus: secant modulus of cyclic "
                         f"simple shear at {f:g} Hz and the tub's strain amplitude {g_tub:.3g} "
                         "(vibroflow.calibration.cyclic_shear; the small-strain one is "
                         "shear_modulus_small_strain_Pa)")
    cols = ("strain_amplitude", "secant_shear_modulus", "secant_shear_modulus_stderr",
            "damping_ratio", "damping_ratio_stderr", "peak_stress_ratio", "solid_fraction")
    return {"frequency_Hz": f, "pressure_Pa": toml_float(pressure),
            "amplitude_factor": toml_float(sc.motion.amplitude_factor),
            "tub_shear_rate_cycle_mean_1_s": toml_float(shear_rate),
            "tub_strain_amplitude": toml_float(g_tub),
            "secant_shear_modulus_at_tub_amplitude_Pa": toml_float(at["secant_shear_modulus"]),
            "damping_ratio_at_tub_amplitude": toml_float(at["damping_ratio"]),
            "n_balls": int(at["n_balls"]), "cycles_kept": int(at["cycles_kept"]),
            # how the packing shakes down at the tub's amplitude (calibration.compaction)
            "solid_fraction_start_at_tub_amplitude": toml_float(at["solid_fraction_start"]),
            "solid_fraction_cycle_end_at_tub_amplitude": [
                toml_float(v) for v in at["solid_fraction_cycle_end"]],
            "units": "strain_amplitude -, secant_shear_modulus Pa, damping_ratio -, "
                     "peak_stress_ratio -, solid_fraction -",
            **{c: [toml_float(r[c]) for r in recs] for c in cols}}


def dilatancy_table(sc, pressure: float, inertial_number, prog) -> dict:
    """The [dilatancy] table: K_dil of mu = mu(I) + K_dil (phi - phi_eq(I)) measured on a dense
    packing of the scenario's balls sheared at the bed's pressure and the tub's inertial number
    (vibroflow.calibration.dilatancy; I clipped to [0.005, 0.1], the dense regime the test
    resolves; 0.02 when the tub gave none)."""
    I = inertial_number if (isinstance(inertial_number, float) and math.isfinite(inertial_number)
                            and inertial_number > 0) else DEFAULT_INERTIAL_NUMBER
    I = min(max(I, 0.005), 0.1)
    prog.log(f"dilatancy: dense packings sheared at p = {pressure:.4g} Pa, I = {I:.3g}")
    r = run_dilatancy(sc, pressure=pressure, inertial_number=I, progress=prog)
    prog.log(f"dilatancy: K_dil = {r['K_dil']:.2f} +- {r['K_dil_stderr']:.2f}")
    return {"model": "mu = mu(I) + K_dil (phi - phi_eq(I)), phi_eq(I) = phi_c - (phi_max - "
                     "phi_min) I, d phi / d gamma = -phi K_dil (phi - phi_eq(I)) (Pailha & "
                     "Pouliquen 2009)",
            "source": "post-peak stress ratio against solid fraction of dense (frictionless-"
                      "compressed) Lees-Edwards packings sheared at constant I and sigma_zz "
                      "(vibroflow.calibration.dilatancy)",
            "K_dil": toml_float(r["K_dil"]), "K_dil_stderr": toml_float(r["K_dil_stderr"]),
            "excess_solid_fraction_dense": toml_float(r["excess_solid_fraction"]),
            "pressure_Pa": toml_float(r["pressure_Pa"]),
            "inertial_number": toml_float(r["inertial_number"]),
            "n_balls": int(r["n_balls"]), "strain": toml_float(r["strain"]), "seeds": r["seeds"],
            "K_dil_per_seed": [toml_float(v) for v in r["K_dil_per_seed"]],
            "mu_peak": [toml_float(v) for v in r["mu_peak"]],
            "mu_ss": [toml_float(v) for v in r["mu_ss"]],
            "phi_start": [toml_float(v) for v in r["phi_start"]],
            "phi_ss": [toml_float(v) for v in r["phi_ss"]]}
