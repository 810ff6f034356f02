"""`vibroflow sweep`: the study at every amplitude factor (and other values), on Dask
distributed.  The sweep's modules are imported inside the command, so that `--help` stays
quick."""
from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Annotated, Optional

import typer

from vibroflow.errors import InputError, Interrupted

from .apps import app
from .failures import input_errors
from .options import StudyScenarioArg, out_option, set_option, shear_cell_option


@app.command("sweep")
@input_errors
def sweep(
    scenario: StudyScenarioArg = "tub47-quick",
    out: Annotated[Path, out_option("Sweep folder.")] = ...,
    factors: Annotated[str, typer.Option(
        "--factors", metavar="F1,F2,...",
        help="Amplitude factors (motion.amplitude_factor), comma-separated.")
    ] = "0.5,0.75,1,1.25,1.5",
    vary: Annotated[Optional[list[str]], typer.Option(
        "--vary", metavar="KEY=V1,V2,...",
        help="Also vary a scenario field (fill.count=300,400) or a continuum option "
             "(lagrangian.dx=0.004,0.002); the points are every combination; repeatable.")
    ] = None,
    set_: Annotated[Optional[list[str]], set_option(
        "Fix a scenario field or a continuum method's option for every point, as "
        "`vibroflow run --set`; repeatable.")] = None,
    scheduler: Annotated[Optional[str], typer.Option(
        "--scheduler", metavar="ADDRESS",
        help="Run the points on the Dask cluster at ADDRESS (tcp://host:8786, started with "
             "`dask scheduler` and `dask worker`); default: a local cluster.")] = None,
    workers: Annotated[Optional[int], typer.Option(
        "--workers", help="Local cluster: worker processes (one thread each); default: one "
                          "per core.")] = None,
    shear_cell: Annotated[bool, shear_cell_option(
        "Calibrate mu(I) and the moduli in DEM shear-cell tests at every point (minutes "
        "each).")] = False,
) -> None:
    """The whole study (DEM, calibration, continuum, comparison) at every point of the sweep,
    as Dask tasks: DIR/points/<point>, DIR/sweep.csv, DIR/sweep.json, DIR/plots/sweep_*.png and
    the sweep report DIR/report.html.
    A rerun computes only the missing points; a failed point does not stop the others."""
    from vibroflow.study.sweep_points import parse_factors, parse_vary, plan_sweep

    if workers is not None and workers < 1:
        raise InputError(f"--workers = {workers}: must be at least 1")
    from vibroflow.threads import THREADS_PER_CORE_MAX, allowed_cores

    if workers is not None and workers > THREADS_PER_CORE_MAX * allowed_cores():
        raise InputError(f"--workers = {workers}: at most {THREADS_PER_CORE_MAX * allowed_cores()} "
                         f"here ({THREADS_PER_CORE_MAX} a core of the {allowed_cores()} this "
                         "process may use; a cluster of more machines: --scheduler)")
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
    from vibroflow.report.sweep_report import write_sweep_report

    page = write_sweep_report(out)
    counts = summary_of(record)
    typer.echo(", ".join(f"{v} {k}" for k, v in sorted(counts.items()))
               + f"; results in {out}/sweep.csv, {out}/plots, {page}")
    failed = failed_points(record)
    if failed:
        sys.stderr.write(f"{len(failed)} of {len(record['results'])} point(s) failed: "
                         f"{', '.join(failed)} (see {out}/points/<point>/failed.json)\n")
        raise typer.Exit(1)
