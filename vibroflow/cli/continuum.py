"""`vibroflow continuum`: a continuum model of a tub scenario.  The solver is imported inside the
command, so that `--help` stays quick."""
from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import Annotated, Optional

import typer

from vibroflow.continuum.formulation import FORMULATIONS
from vibroflow.continuum.landing_choices import LANDINGS
from vibroflow.errors import InputError

from .apps import app
from .failures import blown_up, input_errors
from .options import (OptionalScenarioArg, OutOption, ResumeOption, SetOption, VtkEveryOption,
                      VtkFrameOption, VtkFromOption, load)


@app.command("continuum")
@input_errors
def continuum(
    scenario: OptionalScenarioArg = None,
    out: OutOption = ...,
    method: Annotated[str, typer.Option(
        "--method", help="Formulation: lagrangian (material point method) or eulerian (fixed "
                         "mesh of the tub); continuum/formulation.py.")] = "lagrangian",
    calibration: Annotated[Optional[Path], typer.Option(
        "--calibration", help="calibration.toml, or a folder holding one (a calibrated DEM "
                              "run, a study's DIR/calibration); default: --like's "
                              "calibration.toml, else tub47's parameters.")] = None,
    like: Annotated[Optional[Path], typer.Option(
        "--like", metavar="RUN_DIR", help="Run the scenario of the DEM run in RUN_DIR (its "
                                          "dem.h5's, --set on top) with its calibration.toml "
                                          "when it has one (a study's DIR/dem: the study's "
                                          "DIR/calibration/calibration.toml); instead of "
                                          "SCENARIO.")] = None,
    allow_other_calibration: Annotated[bool, typer.Option(
        "--allow-other-calibration", help="Use a calibration measured on other media or "
                                          "another tub than the scenario's (its [scenario] "
                                          "differs): a warning, not an error.")] = False,
    rheology: Annotated[str, typer.Option(
        "--rheology", help="mu_i (Dunatunga & Kamrin) or drucker_prager.")] = "mu_i",
    dilatancy: Annotated[bool, typer.Option(
        "--dilatancy", help="mu_i with peak friction and dilation (Pailha & Pouliquen 2009), "
                            "K_dil from the calibration's [dilatancy] (vibroflow calibrate "
                            "--dilatancy).")] = False,
    compaction: Annotated[bool, typer.Option(
        "--compaction", help="Cyclic compaction of the connected bed towards the cyclic shear "
                             "cell's packing (Sawicki & Swidzinski 1989), from the calibration's "
                             "[compaction] (vibroflow calibrate --dilatancy).")] = False,
    dx: Annotated[Optional[float], typer.Option(
        "--dx", help="Grid spacing (m); default 3 ball diameters (why: continuum/options.py, "
                    "DEFAULT_DX_DIAMETERS).")] = None,
    cfl: Annotated[Optional[float], typer.Option(
        "--cfl", help="Courant number of the time step in [0.001, 1]; default 0.3 "
                      "(continuum/options.py DEFAULT_CFL).")] = None,
    transfer_cfl: Annotated[Optional[float], typer.Option(
        "--transfer-cfl", help="Courant number of the APIC transfers (> 0): each step makes "
                               "round(cfl / transfer_cfl) of them, so their damping of the "
                               "grid-scale motion does not depend on the step; default 0.015 "
                               "(Lagrangian) and 0.0375 (Eulerian), chosen with the grid to "
                               "match the DEM (continuum/options.py), on a "
                               "grid of --damping-length; 0: one transfer a step (always so "
                               "with --flip > 0).")] = None,
    damping_length: Annotated[Optional[float], typer.Option(
        "--damping-length", help="The grid spacing (m) on which --transfer-cfl holds; on "
                                 "another grid the transfers are made at transfer_cfl (dx / "
                                 "damping_length)^3, so that their damping of the flow (a "
                                 "hyperviscosity) is the same on every grid; default the "
                                 "default grid's spacing (continuum/options.py).")] = None,
    stiffness_factor: Annotated[float, typer.Option(
        "--stiffness-factor", help="Multiply the elastic moduli (and the default wall "
                                   "stiffness) by this factor in (0, 1]: sqrt(factor) times "
                                   "the steps, a physics change like the DEM's reduced "
                                   "Young's modulus (ContinuumOptions).")] = 1.0,
    flip: Annotated[float, typer.Option(
        "--flip", help="Lagrangian only: the FLIP fraction in [0, 1] of the points' velocity "
                       "update (0: APIC, whose transfers damp the flow at every step; "
                       "ContinuumOptions).")] = 0.0,
    bed_viscosity: Annotated[float, typer.Option(
        "--bed-viscosity", help="The bed's Kelvin-Voigt damping on connected material (Pa s, "
                                ">= 0; 0 = off, the default): the continuum's counterpart of "
                                "the DEM's contact dashpots, fitted on a DEM of a vibrated "
                                "strip by benchmarks/strip_damping.py.")] = 0.0,
    temperature: Annotated[bool, typer.Option(
        "--temperature", help="Carry the granular temperature T (m^2/s^2) with its balance "
                              "and its stress (continuum/kinetic_stress.py), and "
                              "write its map temperature.csv; default off.")] = False,
    initial_temperature: Annotated[float, typer.Option(
        "--initial-temperature", help="With --temperature: T of the bed at the start "
                                      "(m^2/s^2, >= 0); default 0.")] = 0.0,
    landing: Annotated[str, typer.Option(
        "--landing", help="With --temperature, Eulerian only: where the wall cells' landing "
                          "above the wall row becomes T: pairs (the pairs of cells across each "
                          "z face, compaction_landing.py) or columns (along each column by the "
                          "impulse through its z faces, column_landing.py); default "
                          "pairs.")] = "pairs",
    partition_friction: Annotated[str, typer.Option(
        "--partition-friction", help="The partitions' friction of their body force: contacts "
                                     "(the calibration's [partitions] friction, the contacts' "
                                     "ratio of sums; default) or along-flow (its "
                                     "friction_along_flow, the part along the mean "
                                     "flow).")] = "contacts",
    moduli: Annotated[str, typer.Option(
        "--moduli", help="The bed's elastic moduli: calibrated (the calibration's "
                         "bulk_modulus_Pa and shear_modulus_Pa; default) or unloading (its "
                         "unloading_bulk_modulus_Pa, the bed's stiffness as it unloads after a "
                         "landing in the DEM, and shear_modulus_small_strain_Pa) or "
                         "unloading-law (the tangent law K_t = K_ref (p / p_ref)^n of that "
                         "branch, its unloading_law_* keys, with the same G).")
    ] = "calibrated",
    set_: SetOption = None,
    vtk: Annotated[bool, typer.Option("--vtk", help="Also write ParaView files of the material "
                                                    "points and the grid fields over the last "
                                                    "cycle (and before it with "
                                                    "--vtk-every).")] = False,
    vtk_frame: VtkFrameOption = None,
    vtk_every: VtkEveryOption = None,
    vtk_from: VtkFromOption = None,
    resume: ResumeOption = False,
    stop_after_steps: Annotated[Optional[int], typer.Option(
        "--stop-after-steps", help="Write a checkpoint and stop after this many vibration "
                                   "steps (to split a run; go on with --resume).")] = None,
) -> None:
    """Run a continuum model of a tub scenario: --out/summary.json, bulk_velocity.csv."""
    if method not in FORMULATIONS:
        *rest, last = FORMULATIONS
        raise InputError(f"--method = {method!r}: must be {', '.join(rest)} or {last}")
    from vibroflow.io.vtk_frame import check_vtk_window, cli_vtk_options
    from vibroflow.scenario.checks import require_tub_mode

    paraview = cli_vtk_options(vtk, vtk_frame, vtk_every, vtk_from)
    check_landing(landing, method, temperature)
    if partition_friction not in ("contacts", "along-flow"):
        raise InputError(f"--partition-friction = {partition_friction!r}: must be contacts or "
                         "along-flow")
    if moduli not in ("calibrated", "unloading", "unloading-law"):
        raise InputError(f"--moduli = {moduli!r}: must be calibrated, unloading or "
                         "unloading-law")
    if stop_after_steps is not None and stop_after_steps < 0:
        raise InputError(f"--stop-after-steps = {stop_after_steps}: must be >= 0")
    if scenario is not None and like is not None:
        raise InputError(f"SCENARIO = {scenario!r} and --like = {str(like)!r}: give one of them")
    if scenario is None and like is None:
        raise InputError("SCENARIO is missing: give a preset, a TOML file or --like RUN_DIR")
    # before anything is written: bad input leaves --out untouched
    if like is not None:
        from vibroflow.calibration.dem_result import run_scenario

        s = run_scenario(like, set_ or [], field="--like")
        if calibration is None:
            from vibroflow.study.folder import calibration_of_run

            calibration = calibration_of_run(like)
    else:
        s = load(scenario, set_)
    require_tub_mode(s, "the continuum", where=str(like or scenario))
    check_vtk_window(paraview, s)
    from vibroflow.continuum.formulation import formulation
    from vibroflow.continuum.material import boundary_friction, material_for
    from vibroflow.continuum.mpm.solver import ContinuumBlowUp
    from vibroflow.continuum.tub_run import run_continuum

    form = formulation(method)
    cal = None
    if calibration is not None:
        from vibroflow.io.calibration_file import read_calibration
        from vibroflow.io.calibration_source import check_calibration_source

        cal = read_calibration(calibration)
        warning = check_calibration_source(cal, s, where=f"--calibration {calibration}",
                                           allow=allow_other_calibration)
        if warning:
            sys.stderr.write(warning + "\n")
    # an unset --cfl or --transfer-cfl takes the formulation's own default
    # (Formulation.options), kept in one place; --transfer-cfl 0: one transfer a step
    step = {} if cfl is None else {"cfl": cfl}
    if transfer_cfl is not None:
        if not (math.isfinite(transfer_cfl) and transfer_cfl >= 0):
            raise InputError(f"--transfer-cfl = {transfer_cfl!r}: must be a Courant number > 0, "
                             "or 0 for one transfer a step")
        step["transfer_cfl"] = transfer_cfl
    options = form.options(dx=dx, model=rheology, dilatancy=dilatancy,
                           stiffness_factor=stiffness_factor, compaction=compaction, flip=flip,
                           bed_viscosity=bed_viscosity, damping_length=damping_length,
                           temperature=temperature, initial_temperature=initial_temperature,
                           landing=landing, partition_friction=partition_friction, moduli=moduli,
                           **step)
    material_for(s, cal, options)  # validates the parameters before --out is made
    boundary_friction(s, cal, options.partition_friction)
    try:
        summary = run_continuum(s, out, method, calibration=cal, options=options,
                                progress=True, vtk=paraview, resume=resume,
                                stop_after_steps=stop_after_steps)
    except ContinuumBlowUp as exc:
        blown_up(exc)
    if summary is None:
        typer.echo(f"stopped after {stop_after_steps} steps; checkpoint in {out}, go on with "
                   "--resume")
        return
    c = summary["circulation"]
    typer.echo(f"circulation {c['sense']}, strength {c['strength']:.4g} m^2/s; "
               f"{summary['n_particles']} points, {summary['wall_time_s']:.1f} s")
    typer.echo(f"results in {out}")


def check_landing(landing: str, method: str, temperature: bool) -> None:
    """--landing's checks, named by its flag: one of LANDINGS, and columns only for the
    Eulerian formulation with --temperature."""
    if landing not in LANDINGS:
        raise InputError(f"--landing = {landing!r}: must be {' or '.join(LANDINGS)}")
    if landing == "pairs":
        return
    if method != "eulerian":
        raise InputError(f"--landing = {landing!r}: columns is Eulerian only (--method "
                         f"eulerian); with --method {method} only pairs")
    if not temperature:
        raise InputError(f"--landing = {landing!r}: only with --temperature; without it only "
                         "pairs")
