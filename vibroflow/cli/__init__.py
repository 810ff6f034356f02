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


def main() -> None:
    """Entry point of the `vibroflow` script."""
    app()
