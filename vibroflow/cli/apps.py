"""The `vibroflow` Typer app and its command groups; the commands register themselves on them
(vibroflow.cli's modules).

The help is click's plain text (rich_markup_mode=None): a help text is shown as written, so
bracketed words (`[dilatancy]`) stay (rich markup would take them for style tags), flags show
as flags (`--vtk`, not `--vtk <bool>`), and a log file gets whole lines, not boxes cut to a
terminal's width."""
from __future__ import annotations

from typing import Annotated

import typer

from vibroflow import __version__

app = typer.Typer(
    name="vibroflow",
    help="Media flow in vibratory tub finishers: DEM, continuum models, comparisons.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
)
scenario_app = typer.Typer(help="Show and check scenarios.", no_args_is_help=True,
                           rich_markup_mode=None)
export_app = typer.Typer(help="Write input decks for other codes.", no_args_is_help=True,
                         rich_markup_mode=None)
import_app = typer.Typer(help="Read other codes' results.", no_args_is_help=True,
                         rich_markup_mode=None)
app.add_typer(scenario_app, name="scenario")
app.add_typer(export_app, name="export")
app.add_typer(import_app, name="import")


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
