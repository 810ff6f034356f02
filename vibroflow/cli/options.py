"""The options and arguments several commands share, and the scenario they name."""
from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any, Optional

import typer

SCENARIO_HELP = "A preset (tub47, tub47-quick) or a TOML file."


def folder_path(raw: str) -> Path:
    """A folder a command writes, as typed: an empty one (an unset shell variable) is refused,
    where Path('') would be the current folder."""
    if not raw.strip():
        raise typer.BadParameter("an empty path; give a folder (`.` for the current one)")
    return Path(raw)


def out_option(help: str) -> Any:
    """--out/-o, the folder a command writes."""
    return typer.Option("--out", "-o", metavar="DIR", help=help, parser=folder_path)


def set_option(help: str) -> Any:
    """The repeatable --set/-s KEY=VALUE (typer wants a list default of None)."""
    return typer.Option("--set", "-s", metavar="KEY=VALUE", help=help)


def shear_cell_option(help: str) -> Any:
    """--shear-cell: mu(I) and the moduli from DEM shear cells."""
    return typer.Option("--shear-cell", help=help)


ScenarioArg = Annotated[str, typer.Argument(metavar="SCENARIO", help=SCENARIO_HELP)]
# a scenario that another option (--like RUN_DIR) may give instead
OptionalScenarioArg = Annotated[Optional[str], typer.Argument(
    metavar="SCENARIO", help=SCENARIO_HELP + " Or --like RUN_DIR.", show_default=False)]
# a study's scenario, optional (default tub47-quick)
StudyScenarioArg = Annotated[str, typer.Argument(metavar="SCENARIO", help=SCENARIO_HELP)]
SetOption = Annotated[Optional[list[str]], set_option(
    "Override a scenario field, e.g. --set run.duration=0.2 --set contacts.0.friction=0.3 "
    "(repeatable; the value is read as TOML).")]
OutOption = Annotated[Path, out_option("Output folder.")]
ThreadsOption = Annotated[Optional[int], typer.Option(
    "--threads", metavar="N",
    help="Threads of the solvers' parallel loops (default: every core the process may use, or "
         "NUMBA_NUM_THREADS); the numbers are the same on any count.", show_default=False)]
ResumeOption = Annotated[bool, typer.Option("--resume", help="Go on from the last checkpoint "
                                                             "in --out.")]


def load(source: str | Path, overrides: list[str] | None):
    """The scenario `source` (a preset or a TOML file) with its --set overrides."""
    # imported here: the scenario's model is heavy, and --help stays quick without it
    from vibroflow.scenario.io import load_scenario

    return load_scenario(source, overrides or [])


VtkFrameOption = Annotated[Optional[str], typer.Option(
    "--vtk-frame", metavar="tub|lab",
    help="With --vtk: the frame of the ParaView files, tub (default: the tub stands still, the "
         "roll shows) or lab (the tub moves by its vibration).")]
VtkEveryOption = Annotated[Optional[float], typer.Option(
    "--vtk-every", metavar="SECONDS",
    help="With --vtk: also a frame of the balls (the continuum's points and grid fields) "
         "every SECONDS of the vibration before the averaging window (whose snapshots are "
         "always written).")]
VtkFromOption = Annotated[Optional[float], typer.Option(
    "--vtk-from", metavar="SECONDS",
    help="With --vtk-every: the time of the first of those frames (s since the vibration "
         "started; default 0).")]
