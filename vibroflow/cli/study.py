"""`vibroflow run`: the whole study of a scenario.  The study's modules are imported inside the
command, so that `--help` stays quick."""
from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from ..rounding import plus_minus
from ..threads import use_threads
from .after_run import warn_empty_probes
from .apps import app
from .failures import EXIT_FAILED, blown_up, fail, input_errors
from .options import (StudyScenarioArg, ThreadsOption, VtkEveryOption, VtkFrameOption,
                      VtkFromOption, load, out_option, set_option, shear_cell_option)


@app.command("run")
@input_errors
def run(
    scenario: StudyScenarioArg = "tub47-quick",
    out: Annotated[Path, out_option("Study folder.")] = ...,
    set_: Annotated[Optional[list[str]], set_option(
        "Override a scenario field (run.duration=0.2) or set a continuum method's option "
        "(lagrangian.dx=0.004, lagrangian.model=\"drucker_prager\"); repeatable, the value is "
        "read as TOML.")] = None,
    shear_cell: Annotated[bool, shear_cell_option(
        "Calibrate mu(I) and the moduli in DEM shear-cell tests (minutes) instead of the "
        "tub's own cells.")] = False,
    vtk: Annotated[bool, typer.Option("--vtk", help="Also write ParaView files: the DEM's balls "
                                                    "and each continuum's fields, in DIR/dem/vtk "
                                                    "and DIR/<method>/vtk.")] = False,
    vtk_frame: VtkFrameOption = None,
    vtk_every: VtkEveryOption = None,
    vtk_from: VtkFromOption = None,
    threads: ThreadsOption = None,
) -> None:
    """DEM, calibration, every continuum formulation and their comparison into --out; a rerun
    redoes only the stages whose inputs changed (DIR/summary.json, vibroflow.load(DIR))."""
    from vibroflow.study.folder import check_study_dir
    from vibroflow.study.pipeline import split_settings

    scenario_sets, method_sets = split_settings(set_)
    s = load(scenario, scenario_sets)  # before anything is written
    use_threads(threads)
    from vibroflow.io.vtk_frame import check_vtk_window, cli_vtk_options

    paraview = cli_vtk_options(vtk, vtk_frame, vtk_every, vtk_from)
    check_vtk_window(paraview, s)
    check_study_dir(out)
    from vibroflow.continuum.mpm.solver import ContinuumBlowUp
    from vibroflow.dem.impact_order import ImpactsLost
    from vibroflow.dem.simulate import BlowUp
    from vibroflow.report.stage import report_stage
    from vibroflow.study.pipeline import run_study

    try:
        summary = run_study(s, out, method_sets, shear_cell=shear_cell, progress=True,
                            echo=typer.echo, extra_stages=[report_stage()], vtk=paraview)
    except (BlowUp, ContinuumBlowUp) as exc:
        blown_up(exc)
    except ImpactsLost as exc:
        fail(str(exc), EXIT_FAILED)
    for name, m in summary["methods"].items():
        warn_empty_probes(f"{name}:", m)
        c = m["circulation"]
        strength = plus_minus(c["strength"], c.get("strength_stderr"))
        line = (f"{name}: circulation {c['sense']} {strength} m^2/s, wall time "
                f"{m['wall_time_s']:.1f} s")
        a = m.get("against_dem")
        if a:
            E = a["field_difference_E"]
            line += (f", E vs DEM = {plus_minus(E, a.get('field_difference_E_stderr'), '.3f')}"
                     if E is not None else ", E vs DEM: n/a")
            verdict = {True: "agrees", False: "differs"}.get(a["circulation_agrees"],
                                                              "not judged")
            line += f", circulation {verdict}, cost x{a['cost_ratio']:.3g}"
        typer.echo(line)
    typer.echo(f"results in {out}/summary.json")
