"""The `vibroflow` command line.

    vibroflow scenario show tub47                     # the scenario as TOML
    vibroflow scenario check my.toml --set run.dt=2e-5
    vibroflow dem tub47-quick --out runs/tub47-quick  # the DEM (the main job)
    vibroflow export liggghts tub47-quick deck/
    vibroflow import liggghts deck/post --out runs/liggghts --scenario tub47-quick
    vibroflow calibrate runs/tub47-quick [--shear-cell]   # continuum parameters from a DEM run
    vibroflow compare runs/mpm -r runs/dem-seed1 -r runs/dem-seed2   # judged as tub47.md does

Bad input (a missing file, malformed TOML, a value out of range, an unknown key) prints one line
"error: FIELD = VALUE: what is allowed" on stderr and exits with code 2, without a traceback and
before anything is written.  Heavy modules (the DEM, numba) are imported inside the commands so
that `--help` and the scenario commands stay quick.
"""
from __future__ import annotations

import errno
import math
import sys
import tomllib
from collections.abc import Callable
from functools import wraps
from pathlib import Path
from typing import Annotated, Any, Optional

import typer
from pydantic import ValidationError

from vibroflow import __version__
from vibroflow.continuum.formulation import FORMULATIONS
from vibroflow.errors import InputError, Interrupted

EXIT_INPUT = 2
EXIT_BLOWUP = 3
EXIT_FAILED = 1
EXIT_INTERRUPTED = 130  # 128 + SIGINT, as a shell reports a command stopped by Ctrl-C

# operating-system errors that a user's path or machine causes, said in one line: the path, the
# reason; a full disk is not bad input (exit 1), a path that cannot be written is (exit 2)
_PATH_ERRNOS = (errno.EACCES, errno.EPERM, errno.EROFS, errno.ENOTDIR, errno.EISDIR,
                errno.EEXIST, errno.ENAMETOOLONG, errno.ELOOP)
_MACHINE_ERRNOS = (errno.ENOSPC, errno.EDQUOT, errno.EMFILE, errno.ENFILE, errno.EIO)

app = typer.Typer(
    name="vibroflow",
    help="Media flow in vibratory tub finishers: DEM, continuum models, comparisons.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
scenario_app = typer.Typer(help="Show and check scenarios.", no_args_is_help=True)
export_app = typer.Typer(help="Write input decks for other codes.", no_args_is_help=True)
import_app = typer.Typer(help="Read other codes' results.", no_args_is_help=True)
app.add_typer(scenario_app, name="scenario")
app.add_typer(export_app, name="export")
app.add_typer(import_app, name="import")

# repeatable --set; typer wants a list default of None
SetOption = Annotated[
    Optional[list[str]],
    typer.Option("--set", "-s", metavar="KEY=VALUE",
                 help="Override a scenario field, e.g. --set run.duration=0.2 "
                      "--set contacts.0.friction=0.3 (repeatable; the value is read as TOML)."),
]
ScenarioArg = Annotated[
    str, typer.Argument(metavar="SCENARIO", help="A preset (tub47, tub47-quick) or a TOML file.")
]


def input_error_message(exc: BaseException) -> str | None:
    """The one-line message of an input error, or None if `exc` is not one (a bug)."""
    if isinstance(exc, InputError):
        return exc.message
    if isinstance(exc, ValidationError):
        from vibroflow.scenario.io import format_validation_error

        return format_validation_error(exc)
    if isinstance(exc, tomllib.TOMLDecodeError):
        return f"malformed TOML: {exc}"
    if isinstance(exc, FileNotFoundError):
        what = (exc.strerror or "no such file or directory").lower()
        return f"{exc.filename}: {what}" if exc.filename else str(exc)
    return None


def _fail(message: str, code: int = EXIT_INPUT, prefix: str = "error: ") -> None:
    # plain write, not rich: rich would wrap a long line and eat [brackets] as markup
    sys.stderr.write(prefix + " ".join(message.split()) + "\n")
    sys.stderr.flush()
    raise typer.Exit(code)


def _os_error_line(exc: OSError) -> str:
    what = (exc.strerror or type(exc).__name__).lower()
    where = exc.filename if exc.filename is not None else ""
    return f"{where}: {what}" if where else what


def input_errors(fn: Callable[..., Any]) -> Callable[..., Any]:
    """Run a command, turning input errors into one line on stderr and exit code 2, a Ctrl-C
    into one line saying where the run stopped and exit code 130, and an operating-system error
    (a path that cannot be written, a full disk) into one line naming the path."""

    @wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except (InputError, ValidationError, tomllib.TOMLDecodeError, FileNotFoundError) as e:
            message = input_error_message(e)
            assert message is not None
            _fail(message)
        except Interrupted as e:
            _fail(e.message, EXIT_INTERRUPTED, prefix="")
        except KeyboardInterrupt:
            _fail("interrupted", EXIT_INTERRUPTED, prefix="")
        except OSError as e:
            if e.errno in _PATH_ERRNOS:
                _fail(_os_error_line(e))
            if e.errno in _MACHINE_ERRNOS:
                _fail(_os_error_line(e), EXIT_FAILED)
            raise

    return wrapper


def _load(source: str | Path, overrides: list[str] | None):
    from vibroflow.scenario.io import load_scenario

    return load_scenario(source, overrides or [])


def _version(value: bool) -> None:
    if value:
        typer.echo(f"vibroflow {__version__}")
        raise typer.Exit()


@app.callback()
def _main(
    version: Annotated[bool, typer.Option("--version", callback=_version, is_eager=True,
                                          help="Print the version and exit.")] = False,
) -> None:
    """Media flow in vibratory tub finishers: DEM, continuum models, comparisons."""


# ----------------------------------------------------------------------------------------------
# scenario

@scenario_app.command("show")
@input_errors
def scenario_show(scenario: ScenarioArg, set_: SetOption = None) -> None:
    """Print a scenario (preset or file, with overrides) as complete TOML."""
    from vibroflow.scenario.io import dump_scenario

    typer.echo(dump_scenario(_load(scenario, set_)), nl=False)


def summary_line(s) -> str:
    """One line describing a valid scenario."""
    from vibroflow.scenario.checks import contact_times

    if s.explicit:
        what = (f"explicit mode, particles: {len(s.particles)}, plane walls: "
                f"{len(s.walls or [])}, simulate {s.run.duration:g} s")
    else:
        what = (f"{s.fill.count} {s.fill.material} balls d = {s.fill.diameter * 1e3:g} mm in a "
                f"tub of length {s.tub.length:g} m, settle {s.fill.settle_time:g} s, vibrate "
                f"{s.run.duration:g} s at {s.motion.frequency:g} Hz x{s.motion.amplitude_factor:g}"
                f", average the last {s.run.average_last:g} s")
    steps = round(s.run.duration / s.run.dt)
    line = f"{s.case}: ok: {what}; dt = {s.run.dt:g} s ({steps} steps)"
    times = contact_times(s)
    if times:
        tp, t_c = times[0]
        line += f", 1/{t_c / s.run.dt:.1f} of the {tp.label} contact time {t_c:.3g} s"
    return line


@scenario_app.command("check")
@input_errors
def scenario_check(scenario: ScenarioArg, set_: SetOption = None) -> None:
    """Validate a scenario and print a one-line summary (exit code 2 if it is invalid)."""
    typer.echo(summary_line(_load(scenario, set_)))


# ----------------------------------------------------------------------------------------------
# dem

@app.command("dem")
@input_errors
def dem(
    scenario: ScenarioArg,
    out: Annotated[Path, typer.Option("--out", "-o", help="Output folder.")],
    set_: SetOption = None,
    vtk: Annotated[bool, typer.Option("--vtk", help="Also write VTK snapshots.")] = False,
    resume: Annotated[bool, typer.Option("--resume", help="Go on from the last checkpoint "
                                                          "in --out.")] = False,
) -> None:
    """Run the DEM of a scenario (fill, settle, vibrate, average) into --out."""
    s = _load(scenario, set_)  # before anything is written: bad input leaves --out untouched
    from vibroflow.dem.run import run_dem
    from vibroflow.dem.simulate import BlowUp

    try:
        run_dem(s, out_dir=out, vtk=vtk, resume=resume, progress=True)
    except BlowUp as exc:
        # a numerical blow-up is not bad input: its own exit code, the balls and the cause
        sys.stderr.write("error: " + str(exc) + "\n")
        raise typer.Exit(EXIT_BLOWUP)
    typer.echo(f"results in {out}")


# ----------------------------------------------------------------------------------------------
# calibrate

@app.command("calibrate")
@input_errors
def calibrate(
    run_dir: Annotated[Path, typer.Argument(metavar="RUN_DIR",
                                            help="A DEM run folder (with dem.h5).")],
    shear_cell: Annotated[bool, typer.Option(
        "--shear-cell", help="Measure mu(I), phi(I) in Lees-Edwards simple-shear cells and the "
                             "elastic moduli in DEM compression/shear tests at the bed's "
                             "pressure (minutes); without it they come from the tub's own "
                             "cells and the affine estimate.")] = False,
    kernel: Annotated[str, typer.Option("--kernel", help="Coarse-graining kernel: gaussian "
                                                         "or lucy.")] = "gaussian",
    width: Annotated[Optional[float], typer.Option(
        "--width", help="Kernel width w (m); default d/2.")] = None,
    cyclic: Annotated[bool, typer.Option(
        "--cyclic/--no-cyclic", help="Give the continuum the secant shear modulus of cyclic "
                                     "simple shear at the tub's frequency and strain amplitude "
                                     "(default; seconds), or the small-strain one.")] = True,
    dilatancy: Annotated[bool, typer.Option(
        "--dilatancy", help="Also measure the dilatancy constant K_dil of the continuum's "
                            "peak-friction option on dense sheared DEM packings (about a "
                            "minute) -> \\[dilatancy].")] = False,
) -> None:
    """Calibrate the continuum on a DEM run: RUN_DIR/calibration.toml, fields.nc, pictures."""
    if not run_dir.is_dir():
        raise InputError(f"RUN_DIR = {str(run_dir)!r}: no such folder")
    if kernel not in ("gaussian", "lucy"):
        raise InputError(f"--kernel = {kernel!r}: must be gaussian or lucy")
    if width is not None and not width > 0:
        raise InputError(f"--width = {width!r}: must be a length > 0 m")
    from vibroflow.calibration.calibrate import calibrate as run_calibration

    cal = run_calibration(run_dir, shear_cell=shear_cell, kernel=kernel, width=width,
                          cyclic=cyclic, dilatancy=dilatancy)
    r, w, e = cal.rheology, cal.wall, cal.elastic
    if (r.status or "measured") != "measured":
        sys.stderr.write(f"warning: rheology {r.status}\n")
    typer.echo(f"mu_s = {r.mu_s:.3f} +- {r.mu_s_stderr:.3f}, mu_2 = {r.mu_2:.3f} +- "
               f"{r.mu_2_stderr:.3f}, I_0 = {r.I_0:.3g} +- {r.I_0_stderr:.2g} "
               f"({r.source.split(' (')[0]})")
    typer.echo(f"K = {e.bulk_modulus_Pa / 1e6:.3g} MPa, "
               f"G = {e.shear_modulus_Pa / 1e6:.3g} MPa"
               + (f" (cyclic secant at strain {cal.cyclic_shear.tub_strain_amplitude:.3g};"
                  f" small-strain {e.shear_modulus_small_strain_Pa / 1e6:.3g} MPa)"
                  if cal.cyclic_shear is not None else ""))
    typer.echo(f"wall friction (effective) = {w.friction:.3f} +- {w.friction_stderr:.3f}"
               f", sliding fraction {w.sliding_fraction:.2f}")
    for name in ("ball_ball", "ball_wall"):
        im = getattr(cal.impacts, name)
        if im is not None:
            typer.echo(f"impacts {name}: v = {im.c0_m_s:.3f} + {im.c1:.2f} d gamma_dot "
                       f"(R2 = {im.r2:.2f}), mean {im.mean_normal_speed_m_s:.3f} m/s")
    typer.echo(f"results in {run_dir}/calibration.toml, fields.nc, calibration/*.png")


# ----------------------------------------------------------------------------------------------
# continuum

@app.command("continuum")
@input_errors
def continuum(
    scenario: ScenarioArg,
    out: Annotated[Path, typer.Option("--out", "-o", help="Output folder.")],
    method: Annotated[str, typer.Option(
        "--method", help="Formulation: lagrangian (material point method) or eulerian (fixed "
                         "mesh of the tub); continuum/formulation.py.")] = "lagrangian",
    calibration: Annotated[Optional[Path], typer.Option(
        "--calibration", help="calibration.toml, or a run folder holding one; default: "
                              "tub47's parameters.")] = None,
    rheology: Annotated[str, typer.Option(
        "--rheology", help="mu_i (Dunatunga & Kamrin) or drucker_prager.")] = "mu_i",
    dilatancy: Annotated[bool, typer.Option(
        "--dilatancy", help="mu_i with peak friction and dilation (Pailha & Pouliquen 2009), "
                            "K_dil from the calibration's \\[dilatancy] (vibroflow calibrate "
                            "--dilatancy).")] = False,
    compaction: Annotated[bool, typer.Option(
        "--compaction", help="Cyclic compaction of the connected bed towards the cyclic shear "
                             "cell's packing (Sawicki & Swidzinski 1989), from the calibration's "
                             "\\[compaction] (vibroflow calibrate --dilatancy).")] = False,
    dx: Annotated[Optional[float], typer.Option(
        "--dx", help="Grid spacing (m); default 3 ball diameters (why: continuum/options.py, "
                    "DEFAULT_DX_DIAMETERS).")] = None,
    cfl: Annotated[Optional[float], typer.Option(
        "--cfl", help="Courant number of the time step in (0, 1]; default 0.3 "
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
    set_: SetOption = None,
    vtk: Annotated[bool, typer.Option("--vtk", help="Also write ParaView files of the material "
                                                    "points and the grid fields over the last "
                                                    "cycle.")] = False,
    resume: Annotated[bool, typer.Option("--resume", help="Go on from the last checkpoint "
                                                          "in --out.")] = False,
    stop_after_steps: Annotated[Optional[int], typer.Option(
        "--stop-after-steps", help="Write a checkpoint and stop after this many vibration "
                                   "steps (to split a run; go on with --resume).")] = None,
) -> None:
    """Run a continuum model of a tub scenario: --out/summary.json, bulk_velocity.csv."""
    if method not in FORMULATIONS:
        *rest, last = FORMULATIONS
        raise InputError(f"--method = {method!r}: must be {', '.join(rest)} or {last}")
    if stop_after_steps is not None and stop_after_steps < 0:
        raise InputError(f"--stop-after-steps = {stop_after_steps}: must be >= 0")
    s = _load(scenario, set_)  # before anything is written: bad input leaves --out untouched
    from vibroflow.continuum.formulation import formulation
    from vibroflow.continuum.material import material_for
    from vibroflow.continuum.mpm.solver import ContinuumBlowUp
    from vibroflow.continuum.tub_run import run_continuum

    form = formulation(method)
    cal = None
    if calibration is not None:
        from vibroflow.io.calibration_file import read_calibration

        cal = read_calibration(calibration)
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
                           bed_viscosity=bed_viscosity, damping_length=damping_length, **step)
    material_for(s, cal, options)  # validates the parameters before --out is made
    try:
        summary = run_continuum(s, out, method, calibration=cal, options=options,
                                progress=True, vtk=vtk, resume=resume,
                                stop_after_steps=stop_after_steps)
    except ContinuumBlowUp as exc:
        # a numerical blow-up is not bad input: its own exit code, the points and the cause
        sys.stderr.write("error: " + str(exc) + "\n")
        raise typer.Exit(EXIT_BLOWUP)
    if summary is None:
        typer.echo(f"stopped after {stop_after_steps} steps; checkpoint in {out}, go on with "
                   "--resume")
        return
    c = summary["circulation"]
    typer.echo(f"circulation {c['sense']}, strength {c['strength']:.4g} m^2/s; "
               f"{summary['n_particles']} points, {summary['wall_time_s']:.1f} s")
    typer.echo(f"results in {out}")


# ----------------------------------------------------------------------------------------------
# run: the whole study

@app.command("run")
@input_errors
def run(
    scenario: Annotated[str, typer.Argument(
        metavar="[SCENARIO]",
        help="A preset (tub47, tub47-quick) or a TOML file.")] = "tub47-quick",
    out: Annotated[Path, typer.Option("--out", "-o", help="Study folder.")] = ...,
    set_: Annotated[Optional[list[str]], typer.Option(
        "--set", "-s", metavar="KEY=VALUE",
        help="Override a scenario field (run.duration=0.2) or set a continuum method's option "
             "(lagrangian.dx=0.004, lagrangian.model=\"drucker_prager\"); repeatable, the "
             "value is read as TOML.")] = None,
    shear_cell: Annotated[bool, typer.Option(
        "--shear-cell", help="Calibrate mu(I) and the moduli in DEM shear-cell tests "
                             "(minutes) instead of the tub's own cells.")] = False,
) -> None:
    """DEM, calibration, every continuum formulation and their comparison into --out; a rerun
    redoes only the stages whose inputs changed (DIR/summary.json, vibroflow.load(DIR))."""
    from vibroflow.study.folder import check_study_dir
    from vibroflow.study.pipeline import split_settings

    scenario_sets, method_sets = split_settings(set_)
    s = _load(scenario, scenario_sets)  # before anything is written
    check_study_dir(out)
    from vibroflow.continuum.mpm.solver import ContinuumBlowUp
    from vibroflow.dem.simulate import BlowUp
    from vibroflow.report.stage import report_stage
    from vibroflow.study.pipeline import run_study

    try:
        summary = run_study(s, out, method_sets, shear_cell=shear_cell, progress=True,
                            echo=typer.echo, extra_stages=[report_stage()])
    except (BlowUp, ContinuumBlowUp) as exc:
        sys.stderr.write("error: " + str(exc) + "\n")
        raise typer.Exit(EXIT_BLOWUP)
    for name, m in summary["methods"].items():
        c = m["circulation"]
        line = (f"{name}: circulation {c['sense']} {c['strength']:.4g} m^2/s, wall time "
                f"{m['wall_time_s']:.1f} s")
        a = m.get("against_dem")
        if a:
            E = a["field_difference_E"]
            line += (f", E vs DEM = {E:.3f}" if E is not None else ", E vs DEM: n/a")
            line += (", circulation " + ("agrees" if a["circulation_agrees"] else "differs")
                     + f", cost x{a['cost_ratio']:.3g}")
        typer.echo(line)
    typer.echo(f"results in {out}/summary.json")


# ----------------------------------------------------------------------------------------------
# sweep: the study at every amplitude factor (and other values), on Dask distributed

@app.command("sweep")
@input_errors
def sweep(
    scenario: Annotated[str, typer.Argument(
        metavar="[SCENARIO]",
        help="A preset (tub47, tub47-quick) or a TOML file.")] = "tub47-quick",
    out: Annotated[Path, typer.Option("--out", "-o", help="Sweep folder.")] = ...,
    factors: Annotated[str, typer.Option(
        "--factors", metavar="F1,F2,...",
        help="Amplitude factors (motion.amplitude_factor), comma-separated.")
    ] = "0.5,0.75,1,1.25,1.5",
    vary: Annotated[Optional[list[str]], typer.Option(
        "--vary", metavar="KEY=V1,V2,...",
        help="Also vary a scenario field (fill.count=300,400) or a continuum option "
             "(lagrangian.dx=0.004,0.002); the points are every combination; repeatable.")
    ] = None,
    set_: Annotated[Optional[list[str]], typer.Option(
        "--set", "-s", metavar="KEY=VALUE",
        help="Fix a scenario field or a continuum method's option for every point, as "
             "`vibroflow run --set`; repeatable.")] = None,
    scheduler: Annotated[Optional[str], typer.Option(
        "--scheduler", metavar="ADDRESS",
        help="Run the points on the Dask cluster at ADDRESS (tcp://host:8786, started with "
             "`dask scheduler` and `dask worker`); default: a local cluster.")] = None,
    workers: Annotated[Optional[int], typer.Option(
        "--workers", help="Local cluster: worker processes (one thread each); default: one "
                          "per core.")] = None,
    shear_cell: Annotated[bool, typer.Option(
        "--shear-cell", help="Calibrate mu(I) and the moduli in DEM shear-cell tests at every "
                             "point (minutes each).")] = False,
) -> None:
    """The whole study (DEM, calibration, continuum, comparison) at every point of the sweep,
    as Dask tasks: DIR/points/<point>, DIR/sweep.csv, DIR/sweep.json, DIR/plots/sweep_*.png.
    A rerun computes only the missing points; a failed point does not stop the others."""
    import os

    from vibroflow.study.sweep_points import parse_factors, parse_vary, plan_sweep

    if workers is not None and workers < 1:
        raise InputError(f"--workers = {workers}: must be at least 1")
    if workers is not None and scheduler:
        raise InputError("--workers: only for the local cluster, not with --scheduler")
    plan = plan_sweep(scenario, parse_factors(factors), parse_vary(vary), set_, shear_cell)
    from vibroflow.study.sweep import (check_sweep_dir, failed_points, print_table, run_sweep,
                                       summary_of)

    check_sweep_dir(out, plan)  # before anything is written or started
    if scheduler:
        from vibroflow.study.sweep import check_scheduler

        check_scheduler(scheduler)  # before the first line: a wrong address is one line
    where = scheduler or f"a local cluster of {workers or os.cpu_count()} worker(s)"
    typer.echo(f"{len(plan.points)} point(s) of {', '.join(plan.varied)} on {where}")
    try:
        from vibroflow.report.stage import report_stage

        record = run_sweep(plan, out, scheduler=scheduler, workers=workers, echo=typer.echo,
                           finishing=[report_stage])
    except KeyboardInterrupt:
        raise Interrupted(f"interrupted; the finished points are kept and a point cut short "
                          f"resumes: run the same command again to go on (out: {out})") from None
    print_table(record)
    counts = summary_of(record)
    typer.echo(", ".join(f"{v} {k}" for k, v in sorted(counts.items()))
               + f"; results in {out}/sweep.csv, {out}/plots")
    failed = failed_points(record)
    if failed:
        sys.stderr.write(f"{len(failed)} of {len(record['results'])} point(s) failed: "
                         f"{', '.join(failed)} (see {out}/points/<point>/failed.json)\n")
        raise typer.Exit(1)


@app.command("report")
@input_errors
def report(
    directory: Annotated[Path, typer.Argument(metavar="DIR", help="A finished study folder "
                                                                  "(vibroflow run --out DIR).")],
) -> None:
    """Write DIR/report.html: the study side by side for the DEM and each continuum method
    (one self-contained page) and the DEM animation DIR/report/dem_slice.gif."""
    from vibroflow.report import write_report

    typer.echo(f"report in {write_report(directory)}")


@app.command("compare")
@input_errors
def compare(
    results: Annotated[Optional[list[Path]], typer.Argument(
        metavar="RESULT...", help="Run folders to judge (vibroflow dem, vibroflow continuum, "
                                  "a study's DIR/<method>), or folders of them.")] = None,
    reference: Annotated[Optional[list[Path]], typer.Option(
        "--reference", "-r", help="A run of the reference method (repeatable: runs that "
                                  "differ only in their fill seed), or a folder of such runs "
                                  "(each of its run folders); required.")] = None,
    e_seed: Annotated[Optional[float], typer.Option(
        "--e-seed", help="The reference's seed-to-seed E, when only one reference is "
                         "given.")] = None,
    json_out: Annotated[Optional[Path], typer.Option(
        "--json", help="Also write the judgement as JSON to this file.")] = None,
) -> None:
    """Judge runs against a reference method's runs as tub47.md does (circulation strengths,
    the field difference E against the seed-to-seed floor): with several references, the floor
    is measured on them and every run is compared with each (vibroflow.analysis.judge)."""
    from vibroflow.analysis.judge import (format_judgement, judge, read_result, run_folders,
                                          write_judgement)

    refs = [read_result(f) for f in run_folders(reference or [])]
    runs = [read_result(f) for f in run_folders(results or [])]
    j = judge(runs, refs, e_seed)
    typer.echo(format_judgement(j))
    if json_out is not None:
        write_judgement(j, json_out)
        typer.echo(f"judgement in {json_out}")


# ----------------------------------------------------------------------------------------------
# LIGGGHTS round trip

@export_app.command("liggghts")
@input_errors
def export_liggghts(
    scenario: ScenarioArg,
    directory: Annotated[Path, typer.Argument(metavar="DIR", help="Folder for the deck.")],
    set_: SetOption = None,
) -> None:
    """Write a LIGGGHTS input deck (with STL walls) for a scenario into DIR."""
    s = _load(scenario, set_)
    from vibroflow.liggghts import export_deck

    export_deck(s, Path(directory))


def _import_scenario_source(dumpdir: Path, scenario: str | None) -> str | Path:
    """The scenario of an import: the one given, else the deck's scenario.toml (written by the
    export next to the deck, the dumps in the deck or a folder of it), else tub47."""
    if scenario is not None:
        return scenario
    for folder in (dumpdir, dumpdir.parent):
        if (folder / "scenario.toml").is_file():
            return folder / "scenario.toml"
    return "tub47"


@import_app.command("liggghts")
@input_errors
def import_liggghts(
    dumpdir: Annotated[Path, typer.Argument(metavar="DUMPDIR", help="LIGGGHTS dump folder.")],
    out: Annotated[Path, typer.Option("--out", "-o", help="Output folder.")],
    scenario: Annotated[Optional[str], typer.Option(
        "--scenario", help="The scenario run (preset or TOML file); default: the deck's "
                           "scenario.toml, else tub47.")] = None,
    set_: SetOption = None,
) -> None:
    """Convert a LIGGGHTS run's dumps into vibroflow results in --out."""
    if not dumpdir.is_dir():
        raise InputError(f"{dumpdir}: no such dump folder")
    s = _load(_import_scenario_source(dumpdir, scenario), set_)
    from vibroflow.liggghts import import_run

    import_run(Path(dumpdir), s, Path(out))


def main() -> None:
    """Entry point of the `vibroflow` script."""
    app()


if __name__ == "__main__":
    main()
