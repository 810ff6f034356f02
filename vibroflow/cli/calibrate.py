"""`vibroflow calibrate`: the continuum's parameters from a DEM run.  The calibration is imported
inside the command, so that `--help` stays quick."""
from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import Annotated, Optional

import typer

from vibroflow.errors import InputError

from .apps import app
from .failures import input_errors
from .options import shear_cell_option


@app.command("calibrate")
@input_errors
def calibrate(
    run_dir: Annotated[Path, typer.Argument(metavar="RUN_DIR",
                                            help="A DEM run folder (with dem.h5).")],
    shear_cell: Annotated[bool, shear_cell_option(
        "Measure mu(I), phi(I) in Lees-Edwards simple-shear cells and the elastic moduli in "
        "DEM compression/shear tests at the bed's pressure (minutes); without it they come "
        "from the tub's own cells and the affine estimate.")] = False,
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
                            "minute) -> [dilatancy].")] = False,
) -> None:
    """Calibrate the continuum on a DEM run: RUN_DIR/calibration.toml, fields.nc, pictures."""
    if not run_dir.is_dir():
        what = "a file, not a folder" if run_dir.exists() else "no such folder"
        raise InputError(f"RUN_DIR = {str(run_dir)!r}: {what}; give the folder of a DEM run")
    if kernel not in ("gaussian", "lucy"):
        raise InputError(f"--kernel = {kernel!r}: must be gaussian or lucy")
    if width is not None and not (math.isfinite(width) and width > 0):
        raise InputError(f"--width = {width!r}: must be a finite length > 0 m")
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
