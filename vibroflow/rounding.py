"""A measured value and its standard error as text: the error to two significant figures, the
value to the same decimal place (the convention of the GUM, JCGM 100:2008 section 7.2.6), so
that a value never shows more digits than its error allows nor fewer than it supports.

    plus_minus(0.0023012, 0.0053) -> "0.0023 ± 0.0053"
    plus_minus(1.046, 0.2036)     -> "1.05 ± 0.20"
    plus_minus(0.001675, 8.3e-5)  -> "0.001675 ± 0.000083"
    plus_minus(31.94, 2.04)       -> "31.9 ± 2.0"
    plus_minus(123456.0, 2100.0)  -> "123500 ± 2100"
    plus_minus(5e-9, 1e-9)        -> "5.0e-09 ± 1.0e-09"

Where the error is zero or missing the value keeps `fmt` (four significant figures by
default); very small or very large numbers switch to a shared exponent form.
"""
from __future__ import annotations

import math

from vibroflow.numbers import is_finite_number

#: the error's significant figures
ERROR_FIGURES = 2
#: beyond these decimal exponents of the error, the text takes the exponent form
SMALLEST_FIXED, LARGEST_FIXED = -6, 4


def plus_minus(x: float, se: float | None, fmt: str = ".4g") -> str:
    """'x ± se' rounded as the module says; 'x' in `fmt` where se is missing, zero or not
    finite; 'n/a' where x is not a finite number."""
    if not is_finite_number(x):
        return "n/a"
    if not is_finite_number(se) or se <= 0.0:
        return format(x, fmt)
    exponent = math.floor(math.log10(se))
    if round(se / 10.0 ** (exponent - ERROR_FIGURES + 1)) >= 10 ** ERROR_FIGURES:
        exponent += 1  # 0.996 rounds to 1.0, not 1.00
    place = exponent - (ERROR_FIGURES - 1)  # the decimal place of the error's last figure
    if SMALLEST_FIXED <= exponent <= LARGEST_FIXED:
        decimals = max(-place, 0)
        step = 10.0 ** place
        xr, sr = round(x / step) * step, round(se / step) * step
        return f"{xr:.{decimals}f} ± {sr:.{decimals}f}"
    # exponent form: the value's figures down to the error's place
    xe = math.floor(math.log10(abs(x))) if x != 0 else exponent
    figures = max(xe - place + 1, 1)
    return f"{x:.{figures - 1}e} ± {se:.{ERROR_FIGURES - 1}e}"
