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
before anything is written (failures.py).  Heavy modules (the DEM, numba) are imported inside
the commands so that `--help` and the scenario commands stay quick.

The app and its groups are in apps.py, the shared options in options.py, and each command group
in its own module, which registers its commands when imported; the order of the imports below is
the order of `vibroflow --help`.
"""
from __future__ import annotations

from . import dem, calibrate, continuum, study, sweep, compare  # noqa: F401  (registration)
from . import liggghts, scenario  # noqa: F401  (registration)
from .apps import app


def _usage_error():
    """The parser's UsageError class: typer's own copy of click where it has one, else click's."""
    try:
        from typer._click.exceptions import UsageError  # noqa: PLC0415
    except ImportError:
        from click.exceptions import UsageError  # noqa: PLC0415
    return UsageError


def _usage_line(e) -> str:
    """One line for a parser error: what click says, the value it refused (click's message
    leaves it out when pydantic converted it), and where the allowed ones are listed."""
    message = e.format_message()
    cause = getattr(e, "__cause__", None)
    try:
        value = cause.errors()[0]["input"] if cause is not None else None
    except (AttributeError, IndexError, KeyError, TypeError):
        value = None
    if value is not None and repr(value) not in message:
        message = f"{message.rstrip('.')} (got {value!r})"
    where = e.ctx.command_path if getattr(e, "ctx", None) is not None else "vibroflow"
    return f"{message} (`{where} --help` lists what is allowed)"


def main() -> None:
    """Entry point of the `vibroflow` script.  The parser's own errors (an unknown option, a
    missing one, a value of the wrong type) are bad input as well: one line naming the option
    and the value, exit code 2, as failures.fail says every other."""
    import sys  # noqa: PLC0415

    import typer  # noqa: PLC0415

    from vibroflow.errors import InputError  # noqa: PLC0415
    from vibroflow.threads import check_threads_env  # noqa: PLC0415

    from .failures import EXIT_INPUT, EXIT_INTERRUPTED  # noqa: PLC0415

    try:
        check_threads_env()
        code = app(standalone_mode=False)
    except InputError as e:
        sys.stderr.write("error: " + " ".join(e.message.split()) + "\n")
        code = EXIT_INPUT
    except _usage_error() as e:
        if type(e).__name__ == "NoArgsIsHelpError":  # a group without its command: its help
            sys.stderr.write(e.format_message() + "\n")
        else:
            sys.stderr.write("error: " + " ".join(_usage_line(e).split()) + "\n")
        code = EXIT_INPUT
    except typer.Abort:
        sys.stderr.write("interrupted\n")
        code = EXIT_INTERRUPTED
    except typer.Exit as e:  # a command's own exit code (failures.fail)
        code = e.exit_code
    raise SystemExit(code if isinstance(code, int) else 0)
