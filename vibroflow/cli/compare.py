"""`vibroflow report` and `vibroflow compare`: a study's page, and runs judged against a
reference method's runs.  Their modules are imported inside the commands, so that `--help`
stays quick."""
from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from vibroflow.errors import InputError

from .apps import app
from .failures import input_errors


@app.command("report")
@input_errors
def report(
    directory: Annotated[Path, typer.Argument(
        metavar="DIR", help="A finished study folder (vibroflow run --out DIR) or a sweep "
                            "folder (vibroflow sweep --out DIR).")],
) -> None:
    """Write DIR/report.html: for a study, the DEM and each continuum method side by side (one
    self-contained page) and the DEM animation DIR/report/dem_slice.gif; for a sweep, the
    circulation strength, sense and E against the amplitude factor for every method, with
    every point in a table."""
    if (directory / "sweep.json").is_file():
        from vibroflow.report.sweep_report import write_sweep_report

        typer.echo(f"sweep report in {write_sweep_report(directory)}")
        return
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
    from vibroflow.analysis.judge import (format_judgement, is_judgement, judge, read_result,
                                          run_folders, write_judgement)
    from vibroflow.io.folder_lock import check_writable_file

    if json_out is not None:
        check_writable_file(json_out, "--json")
        if json_out.exists() and not is_judgement(json_out):
            raise InputError(f"--json = {str(json_out)!r}: exists and is not a judgement of "
                             "`vibroflow compare` (a run's own file?); give a new file")
    refs = [read_result(f) for f in run_folders(reference or [])]
    runs = [read_result(f) for f in run_folders(results or [])]
    j = judge(runs, refs, e_seed)
    typer.echo(format_judgement(j))
    if json_out is not None:
        write_judgement(j, json_out)
        typer.echo(f"judgement in {json_out}")
