"""`vibroflow dem`: the DEM of a scenario.  The solver is imported inside the command, so that
`--help` stays quick."""
from __future__ import annotations

from typing import Annotated

import typer

from ..threads import use_threads
from .after_run import warn_empty_probes
from .apps import app
from .failures import EXIT_FAILED, blown_up, fail, input_errors
from .options import (OutOption, ResumeOption, ScenarioArg, SetOption, ThreadsOption,
                      VtkEveryOption, VtkFrameOption, VtkFromOption, load)


@app.command("dem")
@input_errors
def dem(
    scenario: ScenarioArg,
    out: OutOption,
    set_: SetOption = None,
    vtk: Annotated[bool, typer.Option("--vtk", help="Also write ParaView files of the balls "
                                                    "and the tub in DIR/vtk/.")] = False,
    vtk_frame: VtkFrameOption = None,
    vtk_every: VtkEveryOption = None,
    vtk_from: VtkFromOption = None,
    resume: ResumeOption = False,
    threads: ThreadsOption = None,
) -> None:
    """Run the DEM of a scenario (fill, settle, vibrate, average) into --out."""
    s = load(scenario, set_)  # before anything is written: bad input leaves --out untouched
    use_threads(threads)
    from vibroflow.io.vtk_frame import check_vtk_window, cli_vtk_options

    paraview = cli_vtk_options(vtk, vtk_frame, vtk_every, vtk_from)
    check_vtk_window(paraview, s)
    from vibroflow.dem.impact_order import ImpactsLost
    from vibroflow.dem.run import run_dem
    from vibroflow.dem.simulate import BlowUp

    try:
        summary = run_dem(s, out_dir=out, vtk=paraview, resume=resume, progress=True)
    except BlowUp as exc:
        blown_up(exc)
    except ImpactsLost as exc:
        fail(str(exc), EXIT_FAILED)
    warn_empty_probes("the DEM's", summary)
    from vibroflow.dem.part_output import part_line

    for entry in summary.get("parts", []):
        typer.echo(part_line(entry))
    typer.echo(f"results in {out}")
