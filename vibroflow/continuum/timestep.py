"""The stable time step of the explicit MPM.

* Elastic waves (Courant-Friedrichs-Lewy): dt <= cfl dx / (c + v_max) with the P-wave speed
  c = sqrt((K + 4 G / 3) / rho_c) at the critical density (the lowest density that carries
  stress, so the fastest wave), dx the grid spacing (m) and v_max a bound on the material speed.
* Penalty walls: a point of side l on a wall of stiffness k_n (Pa/m) is an oscillator of
  frequency omega = sqrt(k_n l / m) = sqrt(k_n / (rho l)); the explicit update of a damped
  oscillator is stable for omega dt < 2 (sqrt(1 + zeta^2) - zeta); the step keeps the fraction
  cfl of that.
"""
from __future__ import annotations

import math

from vibroflow.errors import InputError


def stable_dt(material, dx: float, point_size: float, boundaries=(), v_max: float = 0.0,
              cfl: float = 0.3) -> float:
    """Largest stable time step (s) for grid spacing dx (m), smallest point side point_size (m),
    the walls in `boundaries` (those with a `stiffness`) and material speeds up to v_max (m/s)."""
    if not 0 < cfl <= 1:
        raise InputError(f"cfl = {cfl!r}: must be in (0, 1]")
    c = material.p_wave_speed()
    dt = cfl * dx / (c + max(v_max, 0.0))
    rho = material.critical_density
    for b in boundaries:
        k = getattr(b, "stiffness", None)
        if k is None:
            continue
        for kk in (k, k * getattr(b, "tangential_ratio", 1.0)):
            if kk <= 0:
                continue
            omega = math.sqrt(kk / (rho * point_size))
            z = b.damping_ratio
            dt = min(dt, cfl * 2.0 * (math.sqrt(1.0 + z * z) - z) / omega)
    return dt
