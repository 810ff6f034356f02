"""The analytic properties of the contact laws a scenario names (models.md, "DEM contact
laws"): the damping that gives a pair its restitution, the effective moduli of two materials and
the duration of a head-on collision.  The scenario checks its time step against these; the DEM
packs them into its kernels' table (vibroflow.dem.laws) and the continuum's wall law takes the
same damping (vibroflow.continuum.boundary).

* linear spring-dashpot (Cundall & Strack 1979): F_n = k_n delta - gamma_n v_n,
  gamma_n = 2 zeta sqrt(m_eff k_n), zeta = -ln e / sqrt(pi^2 + ln^2 e).
* Hertz-Mindlin: F_n = k_h sqrt(R_eff) delta^(3/2) - c delta^(1/4) v_n with k_h = 4/3 E*; the
  delta^(1/4) form (Tsuji et al. 1992) makes the restitution independent of the impact speed,
  and eta(e) is found by integrating the dimensionless collision once (so e is met to the
  solver's tolerance rather than through an approximate closed form).
"""
from __future__ import annotations

import math
from functools import lru_cache

from scipy.integrate import solve_ivp
from scipy.optimize import brentq


def damping_ratio(restitution: float) -> float:
    """zeta of the linear law giving restitution e for a head-on collision (models.md)."""
    if restitution >= 1.0:
        return 0.0
    ln_e = math.log(restitution)
    return -ln_e / math.sqrt(math.pi**2 + ln_e**2)


def _hertz_collision(eta: float) -> tuple[float, float]:
    """Dimensionless Hertz collision x'' = -x^(3/2) - eta x^(1/4) x', x(0) = 0, x'(0) = 1.

    Returns (restitution, contact time): time in units of (m_eff / (k sqrt(v)))^(2/5) with
    k = k_h sqrt(R_eff) and v the impact speed (derivation in the module docstring of
    tests/test_dem_collisions.py).
    """
    def rhs(_t, y):
        x = max(y[0], 0.0)
        return [y[1], -x**1.5 - eta * x**0.25 * y[1]]

    def leave(_t, y):
        return y[0]
    leave.terminal = True
    leave.direction = -1
    # start a hair inside so the event is not triggered at t = 0
    t0 = 1e-9
    sol = solve_ivp(rhs, (t0, 50.0), [t0, 1.0], events=leave, rtol=1e-11, atol=1e-13,
                    method="DOP853")
    if not sol.t_events[0].size:
        return 0.0, math.inf
    v_out = sol.y_events[0][0][1]
    return -v_out, float(sol.t_events[0][0])


@lru_cache(maxsize=64)
def hertz_eta(restitution: float) -> float:
    """Damping constant eta of the Hertz law for restitution e (velocity independent)."""
    if restitution >= 1.0:
        return 0.0
    return brentq(lambda eta: _hertz_collision(eta)[0] - restitution, 0.0, 20.0, xtol=1e-12)


@lru_cache(maxsize=64)
def _hertz_tau(restitution: float) -> float:
    """Dimensionless duration of the Hertz collision of restitution e (_hertz_collision): one
    integration per restitution, as every scenario's validation asks for it."""
    return _hertz_collision(hertz_eta(restitution))[1]


def effective_moduli(mat_a, mat_b) -> tuple[float, float]:
    """E* and G* of two materials (Johnson, Contact Mechanics; Mindlin)."""
    e_star = 1.0 / ((1 - mat_a.poisson_ratio**2) / mat_a.youngs_modulus
                    + (1 - mat_b.poisson_ratio**2) / mat_b.youngs_modulus)
    g_a = mat_a.youngs_modulus / (2 * (1 + mat_a.poisson_ratio))
    g_b = mat_b.youngs_modulus / (2 * (1 + mat_b.poisson_ratio))
    g_star = 1.0 / ((2 - mat_a.poisson_ratio) / g_a + (2 - mat_b.poisson_ratio) / g_b)
    return e_star, g_star


def contact_time(pair, materials: dict, m_eff: float, r_eff: float,
                 impact_speed: float = 1.0) -> float:
    """Duration (s) of a head-on collision of the pair.

    Linear: t_c = pi / sqrt(k_n/m_eff - (gamma_n / (2 m_eff))^2).  Hertz: from the dimensionless
    collision, at `impact_speed` (m/s; Hertz contacts are shorter at higher speed).
    """
    if pair.model == "linear":
        zeta = damping_ratio(pair.restitution)
        w0 = math.sqrt(pair.k_n / m_eff)
        return math.pi / (w0 * math.sqrt(1.0 - zeta**2))
    e_star, _ = effective_moduli(materials[pair.pair[0]], materials[pair.pair[1]])
    k = 4.0 / 3.0 * e_star * math.sqrt(r_eff)
    return _hertz_tau(pair.restitution) * (m_eff / (k * math.sqrt(impact_speed))) ** 0.4
