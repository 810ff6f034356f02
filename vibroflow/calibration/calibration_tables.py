"""The tables of calibration.toml (vibroflow.io.calibration_file.Calibration) from the results
of the calibration's stages (calibrate.py): each value a plain float (NaN where none could be
estimated) with its standard error, units in the keys."""
from __future__ import annotations

import datetime as _dt

from vibroflow import __version__

from .bed_contacts import contact_pair, young_poisson
from .impact_temperature import AFFINE_MODEL, temperature_relation_keys


def toml_float(x) -> float:
    """A plain float for TOML (NaN stays NaN: TOML 1.0 has nan)."""
    try:
        return float(x)
    except (TypeError, ValueError):
        return float("nan")


def mu_phi_keys(mu: dict, phi: dict) -> dict:
    """The [rheology] keys of a mu(I) and a phi(I) fit (rheology_fit.fit_mu_i, fit_phi_i): each
    constant with its standard error, and the mu(I) fit's chi^2 per degree of freedom."""
    out = {}
    for k in ("mu_s", "mu_2", "I_0"):
        out[k] = toml_float(mu[k])
        out[k + "_stderr"] = toml_float(mu.get(k + "_stderr"))
    for k in ("phi_max", "phi_min"):
        out[k] = toml_float(phi[k])
        out[k + "_stderr"] = toml_float(phi.get(k + "_stderr"))
    out["mu_fit_chi2_per_dof"] = toml_float(mu.get("chi2_per_dof"))
    return out


def _friction_keys(w: dict, measures, **text) -> dict:
    """The keys of a wall's friction (a wall_friction table w): its effective friction and
    standard error, the text keys given, the named measures (floats) and the contact count."""
    return {"friction": toml_float(w["effective_friction"]),
            "friction_stderr": toml_float(w["effective_friction_stderr"]), **text,
            **{k: toml_float(w[k]) for k in measures}, "contacts": int(w["count"])}


def _speed_fit_keys(g: dict, tag: str, points_key: str) -> dict:
    """The keys of an impact speed's fit v = c0 + c1 d gamma_dot (impacts.py's fit g): c0 (m/s)
    and c1 with their standard errors and covariance (m/s; what a prediction's error needs,
    measure.stats.affine_prediction_stderr), each one's covariance with the DEM's measured mean
    speed (m^2/s^2, m/s; what a comparison with that mean needs), c0 and c1 with each batch left
    out (the jackknife's refits, batch order: what a comparison with another statistic of the
    same run needs), r^2, the relative rms error (tag after each name) and the number of points
    fitted (points_key)."""
    nan = float("nan")
    return {f"c0{tag}_m_s": toml_float(g["c0"]), f"c0{tag}_stderr_m_s": toml_float(g["c0_stderr"]),
            f"c1{tag}": toml_float(g["c1"]), f"c1{tag}_stderr": toml_float(g["c1_stderr"]),
            f"c0_c1{tag}_covariance_m_s": toml_float(g.get("c0_c1_covariance", nan)),
            f"c0{tag}_measured_covariance_m2_s2": toml_float(g.get("c0_measured_covariance", nan)),
            f"c1{tag}_measured_covariance_m_s": toml_float(g.get("c1_measured_covariance", nan)),
            f"c0{tag}_left_out_m_s": [toml_float(v) for v in g.get("c0_left_out", [])],
            f"c1{tag}_left_out": [toml_float(v) for v in g.get("c1_left_out", [])],
            f"r2{tag}": toml_float(g["r2"]),
            f"relative_rms_error{tag}": toml_float(g["relative_rms_error"]),
            points_key: int(g["points"])}


def unloading_keys(u: dict | None) -> dict:
    """The [elastic] unloading_* keys of the bed's unloading bulk modulus (unloading.py's
    unloading_bulk_modulus u; None: none measured, no keys)."""
    if u is None:
        return {}
    return {
        "unloading_bulk_modulus_Pa": toml_float(u["bulk_modulus"]),
        "unloading_bulk_modulus_stderr_Pa": toml_float(u["bulk_modulus_stderr"]),
        "unloading_bulk_modulus_divergence_Pa": toml_float(u["divergence"]),
        "unloading_bulk_modulus_fixed_cells_Pa": toml_float(u["eulerian"]),
        "unloading_tangent_start_Pa": toml_float(u["tangent_start"]),
        "unloading_tangent_end_Pa": toml_float(u["tangent_end"]),
        "unloading_cells": int(u["cells"]),
        "unloading_branch_start_cycles": toml_float(u["branch_start"]),
        "unloading_branch_end_cycles": toml_float(u["branch_end"]),
        "unloading_peak_pressure_Pa": toml_float(u["peak_pressure"]),
        "unloading_start_pressure_Pa": toml_float(u["start_pressure"]),
        "unloading_release_pressure_Pa": toml_float(u["release_pressure"]),
        "unloading_volumetric_strain": toml_float(u["volumetric_strain"]),
        "unloading_strain_rate_1_s": toml_float(u["strain_rate"]),
        # the tangent law K_t = K_ref (p / p_ref)^n (unloading.unloading_law)
        "unloading_law_modulus_Pa": toml_float(u["law_K_ref"]),
        "unloading_law_modulus_stderr_Pa": toml_float(u["law_K_ref_stderr"]),
        "unloading_law_reference_pressure_Pa": toml_float(u["law_p_ref"]),
        "unloading_law_exponent": toml_float(u["law_exponent"]),
        "unloading_law_exponent_stderr": toml_float(u["law_exponent_stderr"]),
        "unloading_law_min_pressure_Pa": toml_float(u["law_p_min"]),
        "unloading_law_max_pressure_Pa": toml_float(u["law_p_max"]),
    }


def calibration_tables(res, cg_info, wf, rel, rheo, elastic, dp, p_bed, phi_bed, z, d, rho_s,
                       gam_ref, shear_cell, kernel, width, avg, unloading=None) -> dict:
    """The tables of calibration.toml (what `Calibration.from_dict` takes) from the stages'
    results: [source], [media], [rheology], [elastic], [drucker_prager], [wall], [impacts] and,
    when measured, [partitions] and [impacts.ball_ball], [impacts.ball_wall]; `unloading`:
    the bed's unloading bulk modulus (unloading.py), its keys last in [elastic]."""
    sc = res.scenario
    t0, t1 = res.window()
    tw = wf["tub_wall"]
    E, nu = young_poisson(elastic["bulk_modulus"], elastic["shear_modulus"])
    wall_pair = contact_pair(sc, sc.fill.material, sc.tub.wall_material)
    cal = {
        "source": {
            "run": str(res.path.parent.resolve()), "case": str(sc.case),
            "dem_code": res.source, "snapshots": int(cg_info["snapshots"]),
            "window_s": [t0, t1], "shear_cell": bool(shear_cell),
            "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
            "vibroflow_version": __version__,
            "coarse_graining": {"kernel": kernel, "width_m": toml_float(avg.attrs["width_m"]),
                                "cell_size_m": toml_float(avg.attrs["cell_size_m"]),
                                "contact_stress": cg_info["contact_stress"]},
        },
        "media": {"diameter_m": d, "solid_density_kg_m3": rho_s,
                  "bed_solid_fraction": phi_bed, "bed_pressure_Pa": p_bed,
                  "coordination_number": toml_float(z["z_non_rattler"]),
                  "coordination_number_all_balls": toml_float(z["z_all"])},
        "rheology": {
            "model": "mu(I): mu = mu_s + (mu_2 - mu_s) / (1 + I_0 / I); "
                     "phi(I) = phi_max - (phi_max - phi_min) I",
            **{k: (v if isinstance(v, (str, int)) else toml_float(v)) for k, v in rheo.items()},
            # Dunatunga & Kamrin 2015: below the critical density the material is disconnected
            # (stress-free); the steady quasi-static packing phi(I -> 0) = phi_max
            "critical_solid_fraction": toml_float(rheo["phi_max"]),
        },
        "elastic": {
            "bulk_modulus_Pa": toml_float(elastic["bulk_modulus"]),
            "bulk_modulus_stderr_Pa": toml_float(elastic.get("bulk_modulus_stderr")),
            "shear_modulus_Pa": toml_float(elastic["shear_modulus"]),
            "shear_modulus_stderr_Pa": toml_float(elastic.get("shear_modulus_stderr")),
            **({"shear_modulus_small_strain_Pa": toml_float(elastic["shear_modulus_small_strain"]),
                "shear_modulus_small_strain_stderr_Pa":
                    toml_float(elastic["shear_modulus_small_strain_stderr"])}
               if "shear_modulus_small_strain" in elastic else {}),
            "youngs_modulus_Pa": toml_float(E), "poisson_ratio": toml_float(nu),
            "pressure_Pa": toml_float(elastic.get("pressure", p_bed)),
            "solid_fraction": toml_float(elastic.get("solid_fraction", phi_bed)),
            "coordination_number": toml_float(elastic.get("coordination_number")),
            "source": str(elastic.get("source", "")),
            **unloading_keys(unloading),
        },
        "drucker_prager": {k: (v if isinstance(v, str) else toml_float(v)) for k, v in dp.items()},
        "wall": {
            **_friction_keys(tw, ("contact_friction", "mean_ft_over_fn", "mean_ft_over_fn_stderr",
                                  "ratio_of_sums", "sliding_fraction", "sliding_fraction_stderr",
                                  "rolling_or_sticking_fraction", "coherent_slip_friction",
                                  "coherent_slip_friction_stderr"), choice=tw["choice"]),
            "dem_normal_stiffness_N_m": toml_float(wall_pair.k_n) if wall_pair.model == "linear"
            else float("nan"),
        },
        "impacts": {"shear_rate_model": "v = c0 + c1 d gamma_dot (m/s), fitted over cells",
                    "temperature_model": "v = a sqrt(T)"},
    }
    pw = wf["partitions"]
    if pw is not None:
        cal["partitions"] = {
            **_friction_keys(pw, ("contact_friction", "mean_ft_over_fn", "sliding_fraction",
                                  "friction_along_flow", "friction_along_flow_stderr")),
            "body_force": "-2 friction p / L_y along the velocity (Jop, Forterre & Pouliquen "
                          "2005)",
            "spacing_m": toml_float(sc.tub.length)}
    for name in ("ball_ball", "ball_wall"):
        r = rel.get(name)
        if r is None:
            continue
        g, t = r["fit_shear_rate"], r["fit_temperature"]
        cal["impacts"][name] = {
            "count": int(r["count"]), "mean_normal_speed_m_s": toml_float(r["mean_normal_speed"]),
            **_speed_fit_keys(g, "", "cells"),
            "a_temperature": toml_float(t["c1"]),
            "a_temperature_stderr": toml_float(t["c1_stderr"]),
            "r2_temperature": toml_float(t["r2"]), "a_maxwellian": toml_float(t["maxwell"]),
        }
    for name, r in (rel.get("temperature") or {}).items():
        if name in cal["impacts"] and isinstance(r, dict):
            # the temperature's relations beside the shear rate's (impact_temperature)
            rc = (rel.get("temperature_cells") or {}).get(name)
            g = (rel.get("cells") or {}).get(name)
            keys = temperature_relation_keys(r, rc, g["r2"] if g else None)
            cal["impacts"][name].update({k: v if isinstance(v, (str, int)) else toml_float(v)
                                         for k, v in keys.items()})
            cal["impacts"]["temperature_affine_model"] = AFFINE_MODEL
    rel_cells = rel.get("cells")
    for name in ("ball_ball", "ball_wall"):
        g = (rel_cells or {}).get(name)
        if g is None or name not in cal["impacts"]:
            continue
        # the same relation fitted on the continuum's measure of the shear rate
        # (impacts.impact_relations_on_cells): what a continuum run uses
        cal["impacts"][name].update(_speed_fit_keys(g, "_cells", "points_cells"))
    if rel_cells:
        cal["impacts"].update({
            "cells_shear_rate_model": (
                "v = c0_cells + c1_cells d gamma_dot, gamma_dot the cycle mean of the "
                "phase-resolved velocity field on the analysis cells' centres "
                "(vibroflow.measure.phase_shear: the continuum's measure, so a continuum "
                "run uses these)"),
            "cell_size_m": toml_float(rel_cells["cell_size_m"]),
            "dem_bed_shear_rate_cells_1_s": toml_float(rel_cells["bed_mean_shear_rate_1_s"]),
            "dem_bed_shear_rate_cells_stderr_1_s": toml_float(
                rel_cells["bed_mean_shear_rate_1_s_stderr"]),
            "dem_bed_roll_shear_rate_cells_1_s": toml_float(rel_cells["bed_roll_shear_rate_1_s"]),
            "dem_near_wall_shear_rate_cells_1_s": toml_float(rel_cells["near_wall_shear_rate_1_s"]),
            "dem_near_wall_shear_rate_cells_stderr_1_s": toml_float(
                rel_cells["near_wall_shear_rate_1_s_stderr"])})
    b = rel.get("bagnold")
    if b is not None:
        cal["impacts"]["bagnold_sqrtT_over_d_gamma_dot"] = toml_float(b["c1"])
        cal["impacts"]["bagnold_r2"] = toml_float(b["r2"])
    cal["impacts"]["reference_shear_rate_1_s"] = toml_float(gam_ref)
    return cal
