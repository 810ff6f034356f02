"""`vibroflow calibrate RUN_DIR [--shear-cell]`: from a DEM run to the continuum's parameters.

Stages:
1. coarse-grain the run's averaging window (run_fields) -> RUN_DIR/fields.nc, with the thermal
   temperature beside the phase-resolved one (thermal_temperature: the balls' velocities about
   each snapshot's own coarse-grained velocity, the continuum's like-for-like target);
2. wall and partition friction from the wall contacts (wall_friction);
3. impact speeds against the coarse-grained shear rate and temperature (impacts), their mean
   and p95 against sqrt(T) and the shear rate side by side, and which the DEM supports better
   (impact_temperature);
4. the media's rheology: with --shear-cell, steady mu(I), phi(I) from Lees-Edwards simple-shear
   cells at the bed's pressure (media_tests.dem_tests: shear_cell) and the packed bed's
   elastic moduli from DEM compression and shear tests (elastic); without it, mu(I) and phi(I)
   fitted to the tub's own dense cells (tub_rheology.fit_tub_cells) and the elastic moduli from
   the affine (effective-medium) estimate with the bed's measured coordination number
   (bed_contacts) -- each result says where it came from;
5. the shear modulus the continuum gets: the secant modulus of the packed media in cyclic simple
   shear at the tub's frequency and at the strain amplitude the DEM's bed sees
   (media_tests.cyclic_modulus: cyclic_shear; the amplitude from the bed's cycle-mean shear
   rate), not the small-strain modulus of step 4, which [elastic] keeps as
   shear_modulus_small_strain_Pa (cyclic=False: the small-strain one); and the bed's bulk
   modulus on its unloading branch after each landing, from the phase-resolved fields of step
   1 (unloading) -> [elastic] unloading_bulk_modulus_Pa, the continuum's `--moduli unloading`;
6. the equivalent Drucker-Prager with viscosity; with dilatancy=True (opt-in, ~1 minute), the
   dilatancy constant K_dil of the continuum's peak-friction option, measured on dense
   sheared packings of the balls at the bed's pressure and the tub's I (dilatancy.py) ->
   [dilatancy], and with it the cyclic compaction of the continuum's compaction option from
   the cyclic cell's per-cycle packing at the tub's amplitude (compaction.py) -> [compaction];
7. kinetic theory's constants (kinetic, wall_energy): phi_rcp of g0 and Johnson & Jackson's
   frictional pressure fitted jointly to the phase-resolved cells' p / (rho_s phi T) with the
   scenario's ball-ball restitution, the walls' energy flux from the wall contacts, and the
   multiplier of Gidaspow's conductivity from the cells' fluctuation-energy flux, and beside
   it Garzo & Dufty's two-term heat flux (energy_flux, conductivity, heat_flux_law) ->
   [kinetic];
8. RUN_DIR/calibration.toml (every parameter with its uncertainty and its provenance, and
   last the [scenario] it was measured on, which the continuum checks its own against; its
   tables built by calibration_tables, checked and written as the record
   vibroflow.io.calibration_file.Calibration, which the continuum solvers read with
   `read_calibration`), with the walls' flux RUN_DIR/wall_feed.csv (the U's feed by region
   and phase, measure.floor_force, as a continuum run with T writes its own),
   RUN_DIR/calibration/ pictures (plots).

Where the files go: by default into RUN_DIR beside the DEM's own (`vibroflow calibrate
RUN_DIR`), the pictures in RUN_DIR/calibration/; given a folder of its own (`out`, a study's
DIR/calibration), the calibration writes all of them, pictures included, into that folder.

This module runs the stages in order; each stage's computation lives in the module named.

All files are written atomically; a stage that fails leaves the files of the stages before it.
"""
from __future__ import annotations

import contextlib
from pathlib import Path

from vibroflow.errors import InputError, Interrupted
from vibroflow.io.calibration_file import CALIBRATION_FILE, Calibration, write_calibration
from vibroflow.io.calibration_source import scenario_source
from vibroflow.io.folder_lock import folder_lock
from vibroflow.measure.floor_force import (WALL_FEED_CSV_NAME, dem_wall_feed_cycle,
                                           write_wall_feed_csv)
from vibroflow.progress import RunProgress
from vibroflow.tub.geometry import geometry_of

from .bed_contacts import contact_pair, contact_stiffness_at, coordination
from .calibration_tables import calibration_tables
from .compaction import compaction_table
from .conductivity import conductivity_table, fit_conductivity
from .heat_flux_law import fit_cycle_mean, fit_heat_flux_law, heat_flux_law_table
from .dem_result import DEMResult
from .elastic import affine_moduli_linear
from .impact_temperature import compare_impact_relations, on_nodes
from .impacts import impact_relations, impact_relations_on_cells
from .kinetic import fit_cells, kinetic_table
from .media_tests import cyclic_modulus, dem_tests, dilatancy_table
from .shear_temperature import sliding_table
from .rheology_fit import drucker_prager_equivalent
from .run_fields import coarse_grain_run, with_batch_fields, write_fields
from .unloading import unloading_of_run
from .tub_rheology import (bed_pressure, check_dense_bed, check_tub_cells, fit_tub_cells,
                           median_dense, tub_mu_i_scatter)
from .wall_energy import wall_flux
from .wall_friction import wall_friction

FIELDS_FILE = "fields.nc"
PICTURES_DIR = "calibration"


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


def heat_flux_law_record(energy_flux, res, e, fit, prog) -> dict:
    """The gd_* keys of [kinetic.conductivity]: Garzo & Dufty's two-term heat flux fitted to
    the cells (heat_flux_law), per phase and on the cycle means; {} when not measurable."""
    args = (energy_flux, res.solid_density, res.diameter, e, fit["phi_rcp"], fit["g0_form"])
    try:
        gd = fit_heat_flux_law(*args)
    except InputError as err:
        prog.log(f"kinetic: Garzo & Dufty's heat flux not measured: {err}")
        return {}
    prog.log(f"kinetic: Garzo & Dufty's heat flux: A = {gd['conductivity_multiplier']:.3g} +- "
             f"{gd['conductivity_multiplier_stderr']:.2g}, B = {gd['density_multiplier']:.3g} "
             f"+- {gd['density_multiplier_stderr']:.2g} ({gd['cells']} cells, R^2 "
             f"{gd['r2']:.3g}, the flux's direction right in {gd['direction_fraction']:.0%})")
    unweighted = fit_heat_flux_law(*args, weighted=False)
    cycle = {}
    for weighted in (True, False):
        try:
            cycle[weighted] = fit_cycle_mean(*args, weighted=weighted)
        except InputError as err:
            prog.log(f"kinetic: the cycle-mean heat flux not fitted: {err}")
            cycle[weighted] = None
    return heat_flux_law_table(gd, cycle[True], cycle[False], unweighted)


def kinetic_record(res, phases, prog, energy_flux=None, batches=None) -> dict | None:
    """The [kinetic] table: phi_rcp fitted to the phase-resolved cells, the walls' energy flux,
    the conductivity's multiplier from the cells' energy flux (`energy_flux`, the
    phase-resolved Dataset of energy_flux; None: not measured), the errors of the fitted
    constants from the coarse-grainer's `batches` (run_fields' info["phase_batches"]: the
    delete-one-batch jackknife, kinetic.jackknife_errors; None: the fit's own); None when the
    run has neither phi_rcp nor wall forces."""
    sc = res.scenario
    e = contact_pair(sc, sc.fill.material, sc.fill.material).restitution
    fit = None
    if res.has_ball_contacts:  # the pressure holds the collisional (contact) part
        try:
            fit = fit_cells(phases, res.solid_density, e, joint=True, batches=batches)
            prog.log(f"kinetic: phi_rcp = {fit['phi_rcp']:.4f} +- {fit['phi_rcp_stderr']:.4f}, "
                     f"frictional Fr = {fit['frictional_Pa']:.3g} Pa, phi_min = "
                     f"{fit['frictional_phi_min']:.4f} ({fit['points']} cells, rms log "
                     f"residual {fit['rms_log_residual']:.3f}, Lun's pressure alone "
                     f"{fit['lun_rms_log_residual']:.3f}; {fit['status']})")
        except InputError as err:
            prog.log(f"kinetic: phi_rcp not measured: {err}")
    cond = None
    if fit is not None and energy_flux is not None:
        try:
            c = fit_conductivity(energy_flux, res.solid_density, res.diameter, e,
                                 fit["phi_rcp"], fit["g0_form"])
            cond = conductivity_table(c)
            prog.log(f"kinetic: conductivity = {c['multiplier']:.3g} +- "
                     f"{c['multiplier_stderr']:.2g} of Gidaspow's ({c['cells']} cells, R^2 "
                     f"{c['r2']:.3g}; {c['status']})")
        except InputError as err:
            prog.log(f"kinetic: conductivity not measured: {err}")
        if cond is not None:
            cond.update(heat_flux_law_record(energy_flux, res, e, fit, prog))
    flux = wall_flux(res, phases)
    if fit is None and flux is None:
        return None
    return kinetic_table(fit, flux, e, "the scenario's ball-ball contact law (normal "
                                       "restitution of a head-on collision)", cond)


# ----------------------------------------------------------------------------------------------

def calibrate(run, shear_cell: bool = False, kernel: str = "gaussian",
              width: float | None = None, progress: bool = True, shear_cell_options=None,
              pictures: bool = True, cyclic: bool = True, dilatancy: bool = False,
              out=None) -> Calibration:
    """Calibrate the continuum on the DEM run in RUN (a run directory with dem.h5).

    out: the calibration's own folder (made when missing), which then holds every file it
    writes; None: RUN, the pictures in RUN/calibration/ (the module's notes).  Returns the
    calibration record (what calibration.toml holds).
    """
    run_dir = Path(run)
    # the run's folder is read first (a missing or foreign dem.h5 is one line and makes no
    # folder), then locked: the calibration writes into it, and a DEM still writing it or a
    # folder that is read-only is one line before anything is written
    with (DEMResult.open(run_dir) as res,
          folder_lock(res.path.parent, "vibroflow calibrate", field="RUN_DIR"),
          interrupted_calibration(res.path.parent),
          RunProgress(progress) as prog):
        run_dir = res.path.parent
        out_dir = run_dir if out is None else Path(out)
        sc = res.scenario
        n_used = int((res.batches() >= 0).sum())
        prog.stage("coarse-grain", n_used, unit="snapshots")
        avg, phases, cg_info = coarse_grain_run(res, kernel=kernel, width=width,
                                                progress=lambda k, n: prog.update(k),
                                                energy_flux=res.has_ball_contacts,
                                                thermal=True)
        scatter = tub_mu_i_scatter(avg, phases)
        # before anything is written: a bed too small is the input's fault
        check_dense_bed(sc, avg, run_dir)
        if not shear_cell:
            check_tub_cells(scatter, sc, avg, run_dir)
        out_dir.mkdir(parents=True, exist_ok=True)
        fields_path = write_fields(out_dir / FIELDS_FILE, avg,
                                   with_batch_fields(phases, cg_info["phase_batches"]))
        prog.log(f"coarse-grained {cg_info['snapshots']} snapshots in "
                 f"{cg_info['wall_time_s']:.1f} s (contact stress: {cg_info['contact_stress']})"
                 f" -> {fields_path}")
        wf = wall_friction(res)
        # every fit's errors the delete-one-batch jackknife: refit on the fields without a batch
        loo = cg_info["phase_leave_one_out"]
        rel = impact_relations(res, phases, avg, leave_one_out=loo)
        rel["cells"] = impact_relations_on_cells(res)
        rel["temperature"] = compare_impact_relations(res, phases, leave_one_out=loo)
        cells = float(sc.analysis.cell_size)
        rel["temperature_cells"] = compare_impact_relations(
            res, on_nodes(phases, cells),
            leave_one_out=None if loo is None else on_nodes(loo, cells))
        for name in ("ball_ball", "ball_wall"):
            r = rel["temperature_cells"].get(name)
            if r is not None:
                ta, sr = r["mean"]["temperature_affine"], r["mean"]["shear_rate"]
                prog.log(f"impacts {name} on the cells: v = {ta['c0']:.3f} + {ta['c1']:.2f} "
                         f"sqrt(T) (R2 = {ta['r2']:.2f}; the coarse-grained shear rate's there "
                         f"{sr['r2']:.2f})")
        p_bed = bed_pressure(avg)
        z = coordination(res)
        phi_bed = median_dense(avg, "solid_fraction")  # NaN without a dense cell
        d = res.diameter
        rho_s = res.solid_density
        k_n, k_t = contact_stiffness_at(sc, p_bed, phi_bed, z["z_non_rattler"], d)

        if shear_cell:
            rheo, elastic, cell_points = dem_tests(sc, p_bed, prog, shear_cell_options or {})
        else:
            rheo = fit_tub_cells(scatter, sc, avg, run_dir, cg_info.get("phase_batches"))
            cell_points = None
            K_aff, G_aff = affine_moduli_linear(phi_bed, z["z_all"], k_n, k_t, d)
            elastic = {"bulk_modulus": K_aff, "shear_modulus": G_aff}
            elastic.update(source="affine (effective-medium, Walton 1987) estimate with the "
                                  "tub's measured solid fraction and coordination number: "
                                  "close for K, an upper bound for G; run --shear-cell for "
                                  "DEM compression and shear tests",
                           bulk_modulus_stderr=float("nan"), shear_modulus_stderr=float("nan"),
                           pressure=p_bed, solid_fraction=phi_bed,
                           coordination_number=z["z_all"])
        # the bed's typical instantaneous shear rate (cycle mean of the phase-resolved field)
        gam_ref = median_dense(avg, "shear_rate_cycle_mean")
        cyclic_rec = cyclic_modulus(sc, p_bed, gam_ref, elastic, prog) if cyclic else None
        dp = drucker_prager_equivalent(rheo["mu_s"], rheo["mu_2"], rheo["I_0"],
                                       rheo["phi_max"], rheo["phi_min"], p_bed, d, rho_s,
                                       gam_ref)
        try:
            unload = unloading_of_run(phases, cg_info.get("phase_batches"),
                                      float(sc.motion.frequency))
            prog.log(f"elastic: the bed's unloading bulk modulus K = "
                     f"{unload['bulk_modulus']:.4g} +- {unload['bulk_modulus_stderr']:.2g} Pa "
                     f"(t f {unload['branch_start']:.3f} - {unload['branch_end']:.3f}, p "
                     f"{unload['start_pressure']:.4g} -> {unload['release_pressure']:.4g} Pa, "
                     f"{unload['cells']} cells; from the divergence "
                     f"{unload['divergence']:.4g} Pa)")
            prog.log(f"elastic: the unloading law K_t = K_ref (p / p_ref)^n: K_ref = "
                     f"{unload['law_K_ref']:.4g} +- {unload['law_K_ref_stderr']:.2g} Pa at "
                     f"p_ref = {unload['law_p_ref']:.4g} Pa, n = {unload['law_exponent']:.3f} "
                     f"+- {unload['law_exponent_stderr']:.2g}, on p {unload['law_p_min']:.4g} "
                     f"- {unload['law_p_max']:.4g} Pa ({unload['law_steps']} steps)")
        except InputError as err:
            prog.log(f"elastic: the unloading bulk modulus not measured: {err}")
            unload = None
        cal = calibration_tables(res, cg_info, wf, rel, rheo, elastic, dp, p_bed, phi_bed, z,
                                 d, rho_s, gam_ref, shear_cell, kernel, width, avg,
                                 unloading=unload)
        if cyclic_rec is not None:
            cal["cyclic_shear"] = cyclic_rec
        if dilatancy:
            cal["dilatancy"] = dilatancy_table(sc, p_bed, dp.get("inertial_number"), prog)
            if cyclic_rec is not None:
                try:
                    cal["compaction"] = compaction_table(cyclic_rec, cal["dilatancy"], rheo)
                    prog.log(f"compaction: gamma_c = {cal['compaction']['compaction_strain']:.3g}"
                             f", dphi_cyc = {cal['compaction']['excess_solid_fraction']:.4f}")
                except InputError as e:
                    prog.log(f"compaction not measured: {e}")
        kin = kinetic_record(res, phases, prog, cg_info.get("energy_flux"),
                             cg_info.get("phase_batches"))
        if kin is not None and cell_points:
            slide = sliding_table(cell_points, d, rho_s, kin["restitution"])
            if slide is not None:
                kin.update(slide)
                prog.log(f"kinetic: the shear cell's sliding loss k_f = "
                         f"{slide['sliding_coefficient']:.4g} +- "
                         f"{slide['sliding_coefficient_stderr']:.2g} (off until "
                         f"dense_dissipation = true)")
        if kin is not None:
            cal["kinetic"] = kin
        cal["scenario"] = scenario_source(sc)  # last: the tables before keep their place
        record = Calibration.from_dict(cal, where=str(out_dir / CALIBRATION_FILE))
        write_calibration(out_dir / CALIBRATION_FILE, record)
        wall = record.kinetic.wall_flux if record.kinetic is not None else None
        if wall is not None and wall.arc_edges_m:
            # the DEM's U wall feed by region and phase (measure.floor_force), as a continuum
            # run with the granular temperature writes its own
            write_wall_feed_csv(out_dir / WALL_FEED_CSV_NAME,
                                dem_wall_feed_cycle(wall, geometry_of(sc).radius))
        if pictures:
            from . import plots  # matplotlib, loaded only when pictures are drawn
            pic = out_dir / PICTURES_DIR if out is None else out_dir
            pic.mkdir(exist_ok=True)
            geometry = geometry_of(sc)
            plots.field_maps(pic / "fields.png", avg, geometry)
            plots.mu_i_plot(pic / "mu_I.png", scatter, cell_points,
                            {**rheo, "source": rheo["source"].split(" ")[0]}, rheo)
            plots.wall_friction_plot(pic / "wall_friction.png", wf)
            plots.impacts_plot(pic / "impacts.png", rel)
            kin_t = cal.get("kinetic") or {}
            plots.temperature_relations_plot(pic / "temperature_relations.png",
                                             rel.get("temperature_cells"),
                                             kin_t.get("conductivity"))
        prog.log(f"calibration in {out_dir / CALIBRATION_FILE}")
        return record
