"""Contact-law parameters: from a scenario's materials and contact pairs to the flat table the
numba kernels read (models.md, "DEM contact laws").

Table row of a material pair (a, b), see the `P_*` indices:

* linear spring-dashpot (Cundall & Strack 1979): F_n = k_n delta - gamma_n v_n,
  gamma_n = 2 zeta sqrt(m_eff k_n), zeta = -ln e / sqrt(pi^2 + ln^2 e);  k_t = ratio * k_n.
* Hertz-Mindlin: F_n = k_h sqrt(R_eff) delta^(3/2) - c delta^(1/4) v_n with k_h = 4/3 E*,
  c = eta sqrt(m_eff k_h sqrt(R_eff)); the delta^(1/4) form (Tsuji et al. 1992) makes the
  restitution independent of the impact speed, and eta(e) is found here by integrating the
  dimensionless collision once (so e is met to the solver's tolerance rather than through an
  approximate closed form).  k_t = 8 G* sqrt(R_eff delta) (Mindlin).
  The formulas of damping, moduli and contact time are vibroflow.scenario.laws.

In both laws the damping force may pull during the rebound (no clipping of F_n at zero), as in
LIGGGHTS' and LAMMPS' defaults; that is what makes the textbook e and t_c formulas exact.
"""
from __future__ import annotations

import numpy as np

from ..scenario.laws import damping_ratio, effective_moduli, hertz_eta

# indices into a pair's parameter row
P_MODEL, P_KN, P_KT, P_DAMP, P_MU, P_MUR, P_ROLL = range(7)
N_PARAMS = 8
MODEL_LINEAR, MODEL_HERTZ = 0, 1
ROLL_NONE, ROLL_CDT, ROLL_EPSD, ROLL_CDT_LIGGGHTS = 0, 1, 2, 3
_ROLL = {"none": ROLL_NONE, "cdt": ROLL_CDT, "epsd": ROLL_EPSD,
         "cdt_liggghts": ROLL_CDT_LIGGGHTS}


def material_index(scenario) -> dict[str, int]:
    """Index of every material of the scenario, in the order of `scenario.materials`."""
    return {name: k for k, name in enumerate(scenario.materials)}


def pair_table(scenario) -> np.ndarray:
    """Parameter table (n_materials, n_materials, N_PARAMS), symmetric; rows of pairs without a
    contact entry are NaN (the scenario validation guarantees they never touch)."""
    index = material_index(scenario)
    n = len(index)
    table = np.full((n, n, N_PARAMS), np.nan)
    for pair in scenario.contacts:
        a, b = index[pair.pair[0]], index[pair.pair[1]]
        row = np.zeros(N_PARAMS)
        if pair.model == "linear":
            row[P_MODEL] = MODEL_LINEAR
            row[P_KN] = pair.k_n
            row[P_KT] = pair.k_t_over_k_n
            row[P_DAMP] = damping_ratio(pair.restitution)
        else:
            e_star, g_star = effective_moduli(scenario.materials[pair.pair[0]],
                                              scenario.materials[pair.pair[1]])
            row[P_MODEL] = MODEL_HERTZ
            row[P_KN] = 4.0 / 3.0 * e_star
            row[P_KT] = 8.0 * g_star
            row[P_DAMP] = hertz_eta(pair.restitution)
        row[P_MU] = pair.friction
        row[P_MUR] = pair.rolling_friction
        row[P_ROLL] = _ROLL[pair.rolling_model]
        table[a, b] = row
        table[b, a] = row
    return table


def history_width(table: np.ndarray) -> int:
    """The columns of a ball pair's contact history that the table's laws keep: the tangential
    spring xi_t (3), and the EPSD rolling torque (3 more) only where some pair's law has one.
    A list of the narrow rows is half the bytes that the pair pass streams a step on a bed
    larger than the caches (docs/decisions/threads.md)."""
    return 6 if bool(np.any(table[:, :, P_ROLL] == ROLL_EPSD)) else 3
