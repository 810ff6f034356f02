"""What every formulation's column collapse shares in its set-up (continuum.column): gravity,
the checks of the column's size and the grid's default reach."""
from __future__ import annotations

import math

from vibroflow.errors import InputError

G_ACC = 9.81  # m/s^2


def check_lengths(L0: float, H0: float, dx: float) -> None:
    """InputError (one line) unless the half-width L0, height H0 and grid spacing dx are finite
    lengths > 0 m."""
    for name, v in (("L0", L0), ("H0", H0), ("dx", dx)):
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise InputError(f"column {name} = {v!r}: must be a finite length > 0 m")


def default_reach(L0: float, H0: float) -> float:
    """How far (m) the grid reaches from x = 0 by default: L0 (2 + 3 a), a = H0 / L0, beyond
    the run-outs the experiments and the mu(I) continuum reach (about 2 a L0 at a = 3)."""
    a = H0 / L0
    return L0 * (2.0 + 3.0 * a)
