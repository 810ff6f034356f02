"""What counts as a number where values arrive from files, summaries and tables: a real number
(int, float or numpy scalar), not a bool (JSON's true is not 1) and, where asked, finite.  A
missing value (None, text, NaN) becomes NaN or False here, once, for every layer."""
from __future__ import annotations

import math

import numpy as np


def is_finite_number(v) -> bool:
    """True for a finite real number; False for NaN, inf, None, a bool or anything else."""
    return (isinstance(v, (int, float, np.floating, np.integer)) and not isinstance(v, bool)
            and bool(np.isfinite(v)))


def number_or_nan(v) -> float:
    """v as a float where it is a real number (NaN and inf kept), NaN otherwise (None, a bool,
    text)."""
    if isinstance(v, (int, float, np.floating, np.integer)) and not isinstance(v, bool):
        return float(v)
    return math.nan
