"""`vibroflow calibrate RUN_DIR [--shear-cell]`: from a DEM run to the continuum's parameters.

Stages:
1. coarse-grain the run's averaging window (run_fields) -> RUN_DIR/fields.nc;
2. wall and partition friction from the wall contacts (wall_friction);
3. impact speeds against the coarse-grained shear rate and temperature (impacts);
4. the media's rheology: with --shear-cell, steady mu(I), phi(I) from Lees-Edwards simple-shear
   cells at the bed's pressure (shear_cell) and the packed bed's elastic moduli from DEM
   compression and shear tests (elastic); without it, mu(I) and phi(I) fitted to the tub's own
   dense cells and the elastic moduli from the affine (effective-medium) estimate with the
   bed's measured coordination number -- each result says where it came from;
5. the shear modulus the continuum gets: the secant modulus of the packed media in cyclic simple
   shear at the tub's frequency and at the strain amplitude the DEM's bed sees (cyclic_shear;
   the amplitude from the bed's cycle-mean shear rate), not the small-strain modulus of step 4,
   which [elastic] keeps as shear_modulus_small_strain_Pa (cyclic=False: the small-strain one);
6. the equivalent Drucker-Prager with viscosity; with dilatancy=True (opt-in, ~1 minute), the
   dilatancy constant K_dil of the continuum's peak-friction option, measured on dense
   sheared packings of the balls at the bed's pressure and the tub's I (dilatancy.py) ->
   [dilatancy], and with it the cyclic compaction of the continuum's compaction option from
   the cyclic cell's per-cycle packing at the tub's amplitude (compaction.py) -> [compaction];
7. RUN_DIR/calibration.toml (every parameter with its uncertainty and its provenance, read by
   the continuum solvers with `read_calibration`), RUN_DIR/calibration/ pictures.

All files are written atomically; a stage that fails leaves the files of the stages before it.
"""
from __future__ import annotations

import contextlib
import datetime as _dt
import math
from pathlib import Path

import numpy as np

from vibroflow import __version__
from vibroflow.errors import InputError, Interrupted
from vibroflow.io.calibration_file import CALIBRATION_FILE, Calibration, write_calibration
from vibroflow.io.folder_lock import folder_lock
from vibroflow.scenario.checks import find_contact
from vibroflow.tub.geometry import geometry_of

from .dem_result import DEMResult
from .impacts import impact_relations, impact_relations_on_cells
from .run_fields import coarse_grain_run, write_fields
from .tub_rheology import DENSE_SOLID_FRACTION, bed_pressure, tub_mu_i_scatter
from .wall_friction import wall_friction

FIELDS_FILE = "fields.nc"
PICTURES_DIR = "calibration"


def _f(x) -> float:
    """A plain float for TOML (NaN stays NaN: TOML 1.0 has nan)."""
    try:
        return float(x)
    except (TypeError, ValueError):
        return float("nan")


def _pair(scenario, a: str, b: str):
    """The contact law of materials a and b; an InputError when the scenario lacks it."""
    c = find_contact(scenario, a, b)
    if c is not None:
        return c
    raise InputError(f"contacts: no pair for materials {a!r} and {b!r}")


def coordination(res: DEMResult) -> dict:
    """Mean ball-ball coordination number of the sampled snapshots: Z = 2 C / N over all balls,
    and Z_nr = 2 C / N' over the balls with at least two ball contacts (rattlers out)."""
    if not res.has_ball_contacts or not res.has("ball_contacts/i"):
        return {"z_all": float("nan"), "z_non_rattler": float("nan")}
    f = res.file
    batch = res.batches()
    snap = f["ball_contacts/snapshot"][()]
    i = f["ball_contacts/i"][()]
    j = f["ball_contacts/j"][()]
    n = res.n_particles
    used = np.nonzero(batch >= 0)[0]
    rows = np.searchsorted(snap, np.arange(snap.max(initial=0) + 2))
    za, zn = [], []
    for s in used[:: max(1, used.size // 64)]:  # 64 snapshots are plenty for a mean
        a, b = rows[s], rows[s + 1]
        if b <= a:
            continue
        deg = np.bincount(i[a:b], minlength=n) + np.bincount(j[a:b], minlength=n)
        za.append(2.0 * (b - a) / n)
        keep = deg >= 2
        zn.append(deg[keep].sum() / max(keep.sum(), 1))
    return {"z_all": float(np.mean(za)) if za else float("nan"),
            "z_non_rattler": float(np.mean(zn)) if zn else float("nan")}


def contact_stiffness_at(scenario, pressure: float, phi: float, z: float, d: float):
    """Normal and tangential stiffness (N/m) of a ball-ball contact of the bed at `pressure`.

    Linear law: k_n and k_t as given.  Hertz-Mindlin: the tangent stiffnesses at the mean
    contact force f = pi d^2 p / (phi Z) (Rothenburg & Bathurst: p = phi Z <f> / (pi d^2)):
    delta = (3 f / (4 E* sqrt(R)))^(2/3), k_n = 2 E* sqrt(R delta), k_t = 8 G* sqrt(R delta)
    (Johnson, Contact Mechanics; Mindlin), R = d/4 for two equal balls.
    """
    pair = _pair(scenario, scenario.fill.material, scenario.fill.material)
    if pair.model == "linear":
        k_n = float(pair.k_n)
        return k_n, k_n * float(pair.k_t_over_k_n)
    mat = scenario.materials[scenario.fill.material]
    E, nu = float(mat.youngs_modulus), float(mat.poisson_ratio)
    e_star = E / (2.0 * (1.0 - nu**2))
    g_star = (E / (2.0 * (1.0 + nu))) / (2.0 * (2.0 - nu))
    R = 0.25 * d
    f = math.pi * d**2 * pressure / (phi * z)
    delta = (3.0 * f / (4.0 * e_star * math.sqrt(R))) ** (2.0 / 3.0)
    return 2.0 * e_star * math.sqrt(R * delta), 8.0 * g_star * math.sqrt(R * delta)


def young_poisson(K: float, G: float) -> tuple[float, float]:
    """Young's modulus (Pa) and Poisson ratio of an isotropic solid with moduli K, G (3D)."""
    E = 9.0 * K * G / (3.0 * K + G)
    nu = (3.0 * K - 2.0 * G) / (2.0 * (3.0 * K + G))
    return E, nu


@contextlib.contextmanager
def interrupted_calibration(run_dir: Path):
    """A Ctrl-C in a calibration: Interrupted, one line.  Every file is written atomically, so
    none is half written; the calibration has no checkpoint, so it is run again."""
    try:
        yield
    except KeyboardInterrupt:
        raise Interrupted(f"interrupted while calibrating {run_dir}; nothing to resume (every "
                          f"file written is whole): run `vibroflow calibrate {run_dir}` "
                          "again") from None


# ----------------------------------------------------------------------------------------------

def calibrate(run, shear_cell: bool = False, kernel: str = "gaussian",
              width: float | None = None, progress: bool = True, shear_cell_options=None,
              pictures: bool = True, cyclic: bool = True, dilatancy: bool = False
              ) -> Calibration:
    """Calibrate the continuum on the DEM run in RUN (a run directory with dem.h5).

    Returns the calibration record (what calibration.toml holds).  See the module notes.
    """
    from vibroflow.progress import RunProgress

    run_dir = Path(run)
    # the run's folder is read first (a missing or foreign dem.h5 is one line and makes no
    # folder), then locked: the calibration writes into it, and a DEM still writing it or a
    # folder that is read-only is one line before anything is written
    with (DEMResult.open(run_dir) as res,
          folder_lock(res.path.parent, "vibroflow calibrate", field="RUN_DIR"),
          interrupted_calibration(res.path.parent),
          RunProgress(progress) as prog):
        out_dir = res.path.parent
        sc = res.scenario
        n_used = int((res.batches() >= 0).sum())
        prog.stage("coarse-grain", n_used, unit="snapshots")
        avg, phases, cg_info = coarse_grain_run(res, kernel=kernel, width=width,
                                                progress=lambda k, n: prog.update(k))
        scatter = tub_mu_i_scatter(avg, phases)
        if not shear_cell:  # before anything is written: a bed too small is the input's fault
            check_tub_cells(scatter, sc, avg, out_dir)
        fields_path = write_fields(out_dir / FIELDS_FILE, avg, phases)
        prog.log(f"coarse-grained {cg_info['snapshots']} snapshots in "
                 f"{cg_info['wall_time_s']:.1f} s (contact stress: {cg_info['contact_stress']})"
                 f" -> {fields_path}")
        wf = wall_friction(res)
        rel = impact_relations(res, phases, avg)
        rel["cells"] = impact_relations_on_cells(res)
        p_bed = bed_pressure(avg)
        z = coordination(res)
        phi_bed = _median_dense(avg, "solid_fraction")  # NaN without a dense cell
        d = res.diameter
        rho_s = res.solid_density
        k_n, k_t = contact_stiffness_at(sc, p_bed, phi_bed, z["z_non_rattler"], d)

        if shear_cell:
            rheo, elastic, cell_points = _dem_tests(sc, p_bed, prog, shear_cell_options or {})
        else:
            rheo = _fit_tub_cells(scatter, sc, avg, out_dir)
            cell_points = None
            from .elastic import affine_moduli_linear
            K_aff, G_aff = affine_moduli_linear(phi_bed, z["z_all"], k_n, k_t, d)
            elastic = {"bulk_modulus": K_aff, "shear_modulus": G_aff}
            elastic.update(source="affine (effective-medium, Walton 1987) estimate with the "
                                  "tub's measured solid fraction and coordination number: "
                                  "close for K, an upper bound for G; run --shear-cell for "
                                  "DEM compression and shear tests",
                           bulk_modulus_stderr=float("nan"), shear_modulus_stderr=float("nan"),
                           pressure=p_bed, solid_fraction=phi_bed,
                           coordination_number=z["z_all"])
        from .rheology_fit import drucker_prager_equivalent
        # the bed's typical instantaneous shear rate (cycle mean of the phase-resolved field)
        gam_ref = _median_dense(avg, "shear_rate_cycle_mean")
        cyclic_rec = _cyclic_modulus(sc, p_bed, gam_ref, elastic, prog) if cyclic else None
        dp = drucker_prager_equivalent(rheo["mu_s"], rheo["mu_2"], rheo["I_0"],
                                       rheo["phi_max"], rheo["phi_min"], p_bed, d, rho_s,
                                       gam_ref)
        cal = _calibration_record(res, cg_info, wf, rel, rheo, elastic, dp, p_bed, phi_bed, z,
                                  d, rho_s, gam_ref, shear_cell, kernel, width, avg)
        if cyclic_rec is not None:
            cal["cyclic_shear"] = cyclic_rec
        if dilatancy:
            cal["dilatancy"] = _dilatancy(sc, p_bed, dp.get("inertial_number"), prog)
            if cyclic_rec is not None:
                from .compaction import compaction_table
                try:
                    cal["compaction"] = compaction_table(cyclic_rec, cal["dilatancy"], rheo)
                    prog.log(f"compaction: gamma_c = {cal['compaction']['compaction_strain']:.3g}"
                             f", dphi_cyc = {cal['compaction']['excess_solid_fraction']:.4f}")
                except InputError as e:
                    prog.log(f"compaction not measured: {e}")
        record = Calibration.from_dict(cal, where=str(out_dir / CALIBRATION_FILE))
        write_calibration(out_dir / CALIBRATION_FILE, record)
        if pictures:
            from . import plots
            pic = out_dir / PICTURES_DIR
            pic.mkdir(exist_ok=True)
            geometry = geometry_of(sc)
            plots.field_maps(pic / "fields.png", avg, geometry)
            plots.mu_i_plot(pic / "mu_I.png", scatter, cell_points,
                            {**rheo, "source": rheo["source"].split(" ")[0]}, rheo)
            plots.wall_friction_plot(pic / "wall_friction.png", wf)
            plots.impacts_plot(pic / "impacts.png", rel)
        prog.log(f"calibration in {out_dir / CALIBRATION_FILE}")
        return record


def _cyclic_modulus(sc, pressure: float, shear_rate: float, elastic: dict, prog) -> dict | None:
    """Run the cyclic shear cell (cyclic_shear) at the bed's pressure and the tub's frequency over
    the default amplitudes and the tub's own strain amplitude; replace elastic["shear_modulus"]
    (in place) by the secant modulus at the tub's amplitude, keeping the small-strain one.
    Returns the [cyclic_shear] table, or None when the bed has no measured shear rate."""
    from .cyclic_shear import DEFAULT_AMPLITUDES, run_cyclic_shear, tub_strain_amplitude

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
    return {"frequency_Hz": f, "pressure_Pa": _f(pressure),
            "amplitude_factor": _f(sc.motion.amplitude_factor),
            "tub_shear_rate_cycle_mean_1_s": _f(shear_rate), "tub_strain_amplitude": _f(g_tub),
            "secant_shear_modulus_at_tub_amplitude_Pa": _f(at["secant_shear_modulus"]),
            "damping_ratio_at_tub_amplitude": _f(at["damping_ratio"]),
            "n_balls": int(at["n_balls"]), "cycles_kept": int(at["cycles_kept"]),
            # how the packing shakes down at the tub's amplitude (calibration.compaction)
            "solid_fraction_start_at_tub_amplitude": _f(at["solid_fraction_start"]),
            "solid_fraction_cycle_end_at_tub_amplitude": [
                _f(v) for v in at["solid_fraction_cycle_end"]],
            "units": "strain_amplitude -, secant_shear_modulus Pa, damping_ratio -, "
                     "peak_stress_ratio -, solid_fraction -",
            **{c: [_f(r[c]) for r in recs] for c in cols}}


def _dilatancy(sc, pressure: float, inertial_number, prog) -> dict:
    """The [dilatancy] table: K_dil of mu = mu(I) + K_dil (phi - phi_eq(I)) measured on a dense
    packing of the scenario's balls sheared at the bed's pressure and the tub's inertial number
    (vibroflow.calibration.dilatancy; I clipped to [0.005, 0.1], the dense regime the test
    resolves; 0.02 when the tub gave none)."""
    from .dilatancy import DEFAULT_INERTIAL_NUMBER, run_dilatancy

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
            "K_dil": _f(r["K_dil"]), "K_dil_stderr": _f(r["K_dil_stderr"]),
            "excess_solid_fraction_dense": _f(r["excess_solid_fraction"]),
            "pressure_Pa": _f(r["pressure_Pa"]), "inertial_number": _f(r["inertial_number"]),
            "n_balls": int(r["n_balls"]), "strain": _f(r["strain"]), "seeds": r["seeds"],
            "K_dil_per_seed": [_f(v) for v in r["K_dil_per_seed"]],
            "mu_peak": [_f(v) for v in r["mu_peak"]], "mu_ss": [_f(v) for v in r["mu_ss"]],
            "phi_start": [_f(v) for v in r["phi_start"]],
            "phi_ss": [_f(v) for v in r["phi_ss"]]}


def _median_dense(ds, name: str) -> float:
    v = np.asarray(ds[name].values, float)
    phi = np.asarray(ds["solid_fraction"].values, float)
    sel = np.isfinite(v) & (phi >= DENSE_SOLID_FRACTION)
    return float(np.median(v[sel])) if sel.any() else float("nan")


#: the points the tub-cell fits need: mu(I) has three parameters (rheology_fit.fit_mu_i), phi(I)
#: two (fit_phi_i)
MU_I_POINTS = 3


def _dense_points(scatter: dict) -> dict:
    """The phase-resolved (else time-averaged) scatter's dense points, which the fits use."""
    ph = scatter.get("phase") or scatter["time"]
    d = ph["dense"]
    return {k: ph[k][d] for k in ("I", "mu", "phi")}


def too_small(run_dir: Path, scenario, avg, what: str) -> InputError:
    """The one-line InputError of a DEM run too small for the tub-cell calibration: `what`
    failed, and what to change."""
    return InputError(
        f"RUN_DIR = {str(run_dir)!r}: the bed is too small to calibrate on: {what}; give the "
        f"DEM more balls (fill.count = {scenario.fill.count}) or a longer averaging window "
        f"(run.average_last = {scenario.run.average_last:g} s), coarse-grain with a wider "
        f"kernel (--width, now {float(avg.attrs['width_m']) * 1e3:.3g} mm), or measure mu(I) "
        "in shear cells (--shear-cell)")


def check_tub_cells(scatter: dict, scenario, avg, run_dir: Path) -> None:
    """InputError (too_small) when the tub's coarse-grained cells hold fewer dense points
    (solid fraction >= DENSE_SOLID_FRACTION, finite mu, I > 0, over the cells and phases) than
    the mu(I) fit needs: a bed too thin or too agitated has none, and the calibration cannot
    be completed without --shear-cell."""
    n = int(_dense_points(scatter)["I"].size)
    if n < MU_I_POINTS:
        raise too_small(run_dir, scenario, avg, (
            f"the mu(I) fit to the tub's cells has {n} dense cell value(s) (coarse-grained "
            f"cells x phases with solid fraction >= {DENSE_SOLID_FRACTION:g} and I > 0) and "
            f"needs at least {MU_I_POINTS}"))


def _fit_tub_cells(scatter: dict, scenario=None, avg=None, run_dir: Path | None = None
                   ) -> dict:
    """mu(I), phi(I) fitted to the tub's dense phase-resolved cells (no shear cell); a fit
    that fails (too few points, no convergence) is an InputError (too_small): the run is too
    small to calibrate on, and no number is invented for it."""
    from .rheology_fit import fit_mu_i, fit_phi_i

    pts = _dense_points(scatter)
    out = {"source": "tub cells (dense phase-resolved coarse-grained cells; run --shear-cell "
                     "for the Lees-Edwards simple-shear fit)", "points": int(pts["I"].size)}
    try:
        mu = fit_mu_i(pts["I"], pts["mu"])
        phi = fit_phi_i(pts["I"], pts["phi"])
    except InputError as e:
        if scenario is None:
            raise
        raise too_small(run_dir, scenario, avg, e.message.rstrip(".")) from None
    out.update(_mu_phi_keys(mu, phi))
    out["status"] = "measured"
    return out


def _mu_phi_keys(mu: dict, phi: dict) -> dict:
    out = {}
    for k in ("mu_s", "mu_2", "I_0"):
        out[k] = _f(mu[k])
        out[k + "_stderr"] = _f(mu.get(k + "_stderr"))
    for k in ("phi_max", "phi_min"):
        out[k] = _f(phi[k])
        out[k + "_stderr"] = _f(phi.get(k + "_stderr"))
    out["mu_fit_chi2_per_dof"] = _f(mu.get("chi2_per_dof"))
    return out


def _dem_tests(sc, pressure: float, prog, options: dict):
    """Shear cells over a range of I and the elastic tests, at the bed's pressure."""
    from .elastic import elastic_moduli
    from .rheology_fit import fit_mu_i, fit_phi_i
    from .shear_cell import run_shear_cell

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
    rheo.update(_mu_phi_keys(mu, phi))
    rheo["stress_ratio"] = "tau_eq / p (invariant); *_simple_shear: sigma_xz / sigma_zz"
    for k in ("mu_s", "mu_2", "I_0"):
        rheo[k + "_simple_shear"] = _f(mu_ss[k])
        rheo[k + "_simple_shear_stderr"] = _f(mu_ss[k + "_stderr"])
    prog.log("elastic tests (isotropic compression, simple shear)")
    el = elastic_moduli(sc, pressure=pressure)
    elastic = {"bulk_modulus": _f(el["bulk_modulus"]),
               "bulk_modulus_stderr": _f(el.get("bulk_modulus_stderr")),
               "shear_modulus": _f(el["shear_modulus"]),
               "shear_modulus_stderr": _f(el.get("shear_modulus_stderr")),
               "pressure": _f(el.get("pressure", pressure)),
               "solid_fraction": _f(el.get("solid_fraction")),
               "coordination_number": _f(el.get("coordination_number_non_rattler")),
               "source": "DEM compression and shear tests of a packed periodic bed"}
    return rheo, elastic, rows


def _calibration_record(res, cg_info, wf, rel, rheo, elastic, dp, p_bed, phi_bed, z, d, rho_s,
                        gam_ref, shear_cell, kernel, width, avg) -> dict:
    sc = res.scenario
    t0, t1 = res.window()
    tw = wf["tub_wall"]
    E, nu = young_poisson(elastic["bulk_modulus"], elastic["shear_modulus"])
    wall_pair = _pair(sc, sc.fill.material, sc.tub.wall_material)
    cal = {
        "source": {
            "run": str(res.path.parent.resolve()), "case": str(sc.case),
            "dem_code": res.source, "snapshots": int(cg_info["snapshots"]),
            "window_s": [t0, t1], "shear_cell": bool(shear_cell),
            "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
            "vibroflow_version": __version__,
            "coarse_graining": {"kernel": kernel, "width_m": _f(avg.attrs["width_m"]),
                                "cell_size_m": _f(avg.attrs["cell_size_m"]),
                                "contact_stress": cg_info["contact_stress"]},
        },
        "media": {"diameter_m": d, "solid_density_kg_m3": rho_s,
                  "bed_solid_fraction": phi_bed, "bed_pressure_Pa": p_bed,
                  "coordination_number": _f(z["z_non_rattler"]),
                  "coordination_number_all_balls": _f(z["z_all"])},
        "rheology": {
            "model": "mu(I): mu = mu_s + (mu_2 - mu_s) / (1 + I_0 / I); "
                     "phi(I) = phi_max - (phi_max - phi_min) I",
            **{k: (v if isinstance(v, (str, int)) else _f(v)) for k, v in rheo.items()},
            # Dunatunga & Kamrin 2015: below the critical density the material is disconnected
            # (stress-free); the steady quasi-static packing phi(I -> 0) = phi_max
            "critical_solid_fraction": _f(rheo["phi_max"]),
        },
        "elastic": {
            "bulk_modulus_Pa": _f(elastic["bulk_modulus"]),
            "bulk_modulus_stderr_Pa": _f(elastic.get("bulk_modulus_stderr")),
            "shear_modulus_Pa": _f(elastic["shear_modulus"]),
            "shear_modulus_stderr_Pa": _f(elastic.get("shear_modulus_stderr")),
            **({"shear_modulus_small_strain_Pa": _f(elastic["shear_modulus_small_strain"]),
                "shear_modulus_small_strain_stderr_Pa":
                    _f(elastic["shear_modulus_small_strain_stderr"])}
               if "shear_modulus_small_strain" in elastic else {}),
            "youngs_modulus_Pa": _f(E), "poisson_ratio": _f(nu),
            "pressure_Pa": _f(elastic.get("pressure", p_bed)),
            "solid_fraction": _f(elastic.get("solid_fraction", phi_bed)),
            "coordination_number": _f(elastic.get("coordination_number")),
            "source": str(elastic.get("source", "")),
        },
        "drucker_prager": {k: (v if isinstance(v, str) else _f(v)) for k, v in dp.items()},
        "wall": {
            "friction": _f(tw["effective_friction"]),
            "friction_stderr": _f(tw["effective_friction_stderr"]),
            "choice": tw["choice"],
            "contact_friction": _f(tw["contact_friction"]),
            "mean_ft_over_fn": _f(tw["mean_ft_over_fn"]),
            "mean_ft_over_fn_stderr": _f(tw["mean_ft_over_fn_stderr"]),
            "ratio_of_sums": _f(tw["ratio_of_sums"]),
            "sliding_fraction": _f(tw["sliding_fraction"]),
            "sliding_fraction_stderr": _f(tw["sliding_fraction_stderr"]),
            "rolling_or_sticking_fraction": _f(tw["rolling_or_sticking_fraction"]),
            "coherent_slip_friction": _f(tw["coherent_slip_friction"]),
            "coherent_slip_friction_stderr": _f(tw["coherent_slip_friction_stderr"]),
            "contacts": int(tw["count"]),
            "dem_normal_stiffness_N_m": _f(wall_pair.k_n) if wall_pair.model == "linear"
            else float("nan"),
        },
        "impacts": {"shear_rate_model": "v = c0 + c1 d gamma_dot (m/s), fitted over cells",
                    "temperature_model": "v = a sqrt(T)"},
    }
    pw = wf["partitions"]
    if pw is not None:
        cal["partitions"] = {
            "friction": _f(pw["effective_friction"]),
            "friction_stderr": _f(pw["effective_friction_stderr"]),
            "contact_friction": _f(pw["contact_friction"]),
            "mean_ft_over_fn": _f(pw["mean_ft_over_fn"]),
            "sliding_fraction": _f(pw["sliding_fraction"]),
            "contacts": int(pw["count"]),
            "body_force": "-2 friction p / L_y along the velocity (Jop, Forterre & Pouliquen "
                          "2005)",
            "spacing_m": _f(sc.tub.length)}
    for name in ("ball_ball", "ball_wall"):
        r = rel.get(name)
        if r is None:
            continue
        g, t = r["fit_shear_rate"], r["fit_temperature"]
        cal["impacts"][name] = {
            "count": int(r["count"]), "mean_normal_speed_m_s": _f(r["mean_normal_speed"]),
            "c0_m_s": _f(g["c0"]), "c0_stderr_m_s": _f(g["c0_stderr"]),
            "c1": _f(g["c1"]), "c1_stderr": _f(g["c1_stderr"]),
            "r2": _f(g["r2"]), "relative_rms_error": _f(g["relative_rms_error"]),
            "cells": int(g["points"]),
            "a_temperature": _f(t["c1"]), "a_temperature_stderr": _f(t["c1_stderr"]),
            "r2_temperature": _f(t["r2"]), "a_maxwellian": _f(t["maxwell"]),
        }
    rel_cells = rel.get("cells")
    for name in ("ball_ball", "ball_wall"):
        g = (rel_cells or {}).get(name)
        if g is None or name not in cal["impacts"]:
            continue
        # the same relation fitted on the continuum's measure of the shear rate
        # (impacts.impact_relations_on_cells): what a continuum run uses
        cal["impacts"][name].update({
            "c0_cells_m_s": _f(g["c0"]), "c0_cells_stderr_m_s": _f(g["c0_stderr"]),
            "c1_cells": _f(g["c1"]), "c1_cells_stderr": _f(g["c1_stderr"]),
            "r2_cells": _f(g["r2"]), "relative_rms_error_cells": _f(g["relative_rms_error"]),
            "points_cells": int(g["points"])})
    if rel_cells:
        cal["impacts"].update({
            "cells_shear_rate_model": (
                "v = c0_cells + c1_cells d gamma_dot, gamma_dot the cycle mean of the "
                "phase-resolved velocity field on the analysis cells' centres "
                "(vibroflow.measure.phase_shear: the continuum's measure, so a continuum "
                "run uses these)"),
            "cell_size_m": _f(rel_cells["cell_size_m"]),
            "dem_bed_shear_rate_cells_1_s": _f(rel_cells["bed_mean_shear_rate_1_s"]),
            "dem_bed_shear_rate_cells_stderr_1_s": _f(
                rel_cells["bed_mean_shear_rate_1_s_stderr"]),
            "dem_bed_roll_shear_rate_cells_1_s": _f(rel_cells["bed_roll_shear_rate_1_s"]),
            "dem_near_wall_shear_rate_cells_1_s": _f(rel_cells["near_wall_shear_rate_1_s"]),
            "dem_near_wall_shear_rate_cells_stderr_1_s": _f(
                rel_cells["near_wall_shear_rate_1_s_stderr"])})
    b = rel.get("bagnold")
    if b is not None:
        cal["impacts"]["bagnold_sqrtT_over_d_gamma_dot"] = _f(b["c1"])
        cal["impacts"]["bagnold_r2"] = _f(b["r2"])
    cal["impacts"]["reference_shear_rate_1_s"] = _f(gam_ref)
    return cal


