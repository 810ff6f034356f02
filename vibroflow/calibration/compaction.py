"""Cyclic compaction of the packed media from DEM: the parameters of the continuum's compaction
option (constitutive.py, "Option: compaction"),

    d phi / d gamma = (phi_cyc - phi) / gamma_c,   phi_cyc = phi_c + dphi_cyc,

measured in the cyclic shear cell (cyclic_shear.py) that the calibration already runs at the
tub's frequency, pressure and strain amplitude gamma_0.

Why.  Under cycles of shear a granular packing shakes down towards a packing denser than its
steady-shear one (cyclic densification: Youd 1972; Sawicki & Swidzinski 1989, Int. J. Numer.
Anal. Meth. Geomech. 13, 273-285, whose compaction per cycle is proportional to the distance from
the limit packing; Knight et al. 1995 for tapping).  The tub's bed is such a packing: the cyclic
cell holds phi 0.610 at the tub's amplitude where steady shear of the same balls gives 0.600.

The fit.  At the tub's amplitude the cell records the packing at the end of each cycle, N = 1 ..
n, starting from phi_start (the packing the previous, smaller amplitude left).  Sawicki &
Swidzinski's law integrates to

    phi_N = phi_inf - (phi_inf - phi_start) exp(-N / N_c),

fitted by least squares (phi_inf linear, N_c by a log-spaced scan refined by golden section);
a cycle of amplitude gamma_0 accumulates 4 gamma_0 of shear strain, so gamma_c = 4 gamma_0 N_c.
The excess dphi_cyc carries the cell's cyclic packing over to the continuum's phi_c (the tub
cells' phi(I -> 0), a different, lower number: coarse-graining near walls, a 3-ball slice): it is
phi_inf over the same balls' steady-shear packing phi_ss in the dilatancy cell (at the tub's
inertial number I_ss), both referred to I = 0 with the calibrated phi(I) slope a:
dphi_cyc = phi_inf - (phi_ss + a I_ss).
"""
from __future__ import annotations

import math

import numpy as np

from vibroflow.errors import InputError


def fit_compaction(phi_start: float, phi_cycle_end, strain_amplitude: float) -> dict:
    """Fit phi_N = phi_inf - (phi_inf - phi_start) exp(-N / N_c) to the packing at the end of
    cycles N = 1 .. n (module notes).  Returns phi_inf (-), cycles N_c (-), gamma_c = 4 gamma_0
    N_c (-) and the fit's rms residual (-).  Needs at least 3 cycles that compact the packing."""
    y = np.asarray(phi_cycle_end, float)
    if y.size < 3 or not np.all(np.isfinite(y)) or not math.isfinite(phi_start):
        raise InputError(f"phi_cycle_end = {list(y)!r}: needs at least 3 finite packings")
    if not strain_amplitude > 0:
        raise InputError(f"strain_amplitude = {strain_amplitude!r}: must be > 0")
    if not y[-1] > phi_start:
        raise InputError(f"phi_cycle_end = {list(y)!r}: the packing did not compact from "
                         f"phi_start = {phi_start!r}; no compaction to fit")
    n = np.arange(1, y.size + 1, dtype=float)
    dy = y - phi_start

    def solve(nc):
        g = 1.0 - np.exp(-n / nc)
        A = float(g @ dy / (g @ g))
        r = dy - A * g
        return float(r @ r), A

    grid = np.exp(np.linspace(math.log(0.05), math.log(1.0e3), 400))
    k = int(np.argmin([solve(c)[0] for c in grid]))
    lo, hi = math.log(grid[max(k - 1, 0)]), math.log(grid[min(k + 1, grid.size - 1)])
    gr = (math.sqrt(5.0) - 1.0) / 2.0
    for _ in range(60):  # golden section in log N_c
        a, b = hi - gr * (hi - lo), lo + gr * (hi - lo)
        if solve(math.exp(a))[0] < solve(math.exp(b))[0]:
            hi = b
        else:
            lo = a
    nc = math.exp(0.5 * (lo + hi))
    res, A = solve(nc)
    return {"phi_inf": float(phi_start + A), "cycles": nc,
            "gamma_c": 4.0 * float(strain_amplitude) * nc,
            "rms_residual": math.sqrt(res / y.size)}


def compaction_table(cyclic: dict, dilatancy: dict, rheology: dict) -> dict:
    """The [compaction] table of calibration.toml from its [cyclic_shear] (with the per-cycle
    packings at the tub's amplitude), [dilatancy] (phi_ss per seed, inertial_number) and
    [rheology] (phi_max, phi_min) tables (module notes)."""
    ends = cyclic.get("solid_fraction_cycle_end_at_tub_amplitude")
    start = cyclic.get("solid_fraction_start_at_tub_amplitude")
    g0 = cyclic.get("tub_strain_amplitude")
    if ends is None or start is None or g0 is None:
        raise InputError("calibration [cyclic_shear]: no per-cycle packing at the tub's "
                         "amplitude (solid_fraction_cycle_end_at_tub_amplitude); calibrate again")
    phi_ss = [float(v) for v in dilatancy.get("phi_ss", [])]
    I_ss = dilatancy.get("inertial_number")
    if not phi_ss or not isinstance(I_ss, (int, float)):
        raise InputError("calibration [dilatancy]: no steady packing phi_ss; calibrate with "
                         "--dilatancy")
    fit = fit_compaction(float(start), ends, float(g0))
    slope = float(rheology["phi_max"]) - float(rheology["phi_min"])
    phi_ss_mean = float(np.mean(phi_ss))
    phi_ss_se = float(np.std(phi_ss, ddof=1) / math.sqrt(len(phi_ss))) if len(phi_ss) > 1 \
        else float("nan")
    excess = fit["phi_inf"] - (phi_ss_mean + slope * float(I_ss))
    return {"model": "d phi / d gamma = (phi_c + dphi_cyc - phi) / gamma_c on connected points, "
                     "gamma the total equivalent shear strain (Sawicki & Swidzinski 1989, rate "
                     "form)",
            "source": "cyclic shear cell at the tub's strain amplitude: packing at the end of each "
                      "cycle fitted by phi_inf - (phi_inf - phi_start) exp(-N / N_c); excess over "
                      "the dilatancy cell's steady packing, both at I = 0 "
                      "(vibroflow.calibration.compaction)",
            "compaction_strain": float(fit["gamma_c"]), "cycles": float(fit["cycles"]),
            "strain_amplitude": float(g0), "phi_cyclic": float(fit["phi_inf"]),
            "fit_rms_residual": float(fit["rms_residual"]),
            "phi_steady_shear": phi_ss_mean, "phi_steady_shear_stderr": phi_ss_se,
            "inertial_number_steady_shear": float(I_ss),
            "excess_solid_fraction": float(max(excess, 0.0))}
