"""`vibroflow export liggghts` and `vibroflow import liggghts`: the LIGGGHTS round trip.  Its
modules are imported inside the commands, so that `--help` stays quick."""
from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from vibroflow.errors import InputError

from .apps import export_app, import_app
from .failures import input_errors
from .options import OutOption, ScenarioArg, SetOption, folder_path, load


@export_app.command("liggghts")
@input_errors
def export_liggghts(
    scenario: ScenarioArg,
    directory: Annotated[Path, typer.Argument(metavar="DIR", help="Folder for the deck.",
                                              parser=folder_path)],
    set_: SetOption = None,
    fill_from: Annotated[Optional[Path], typer.Option(
        "--fill-from", metavar="DEM_RUN_DIR",
        help="Start from this finished `vibroflow dem` run's settled bed (same scenario, fill "
             "and seed) instead of inserting balls.")] = None,
) -> None:
    """Write a LIGGGHTS input deck (with STL walls) for a scenario into DIR."""
    s = load(scenario, set_)
    from vibroflow.liggghts import dem_fill, export_deck

    bed = None if fill_from is None else dem_fill(fill_from, s)
    export_deck(s, Path(directory), fill_from=bed)


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
    out: OutOption,
    scenario: Annotated[Optional[str], typer.Option(
        "--scenario", help="The scenario run (preset or TOML file); default: the deck's "
                           "scenario.toml, else tub47.")] = None,
    set_: SetOption = None,
) -> None:
    """Convert a LIGGGHTS run's dumps into vibroflow results in --out."""
    if not dumpdir.is_dir():
        raise InputError(f"{dumpdir}: no such dump folder")
    s = load(_import_scenario_source(dumpdir, scenario), set_)
    from vibroflow.liggghts import import_run

    import_run(Path(dumpdir), s, Path(out))
