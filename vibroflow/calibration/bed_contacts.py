"""The packed bed's contacts, as the calibration measures them on a DEM run: the ball-ball
coordination number, the contact stiffness at the bed's pressure, and the Young's modulus and
Poisson ratio of given bulk and shear moduli."""
from __future__ import annotations

import math

import numpy as np

from vibroflow.errors import InputError
from vibroflow.scenario.checks import find_contact

from .dem_result import DEMResult


def contact_pair(scenario, a: str, b: str):
    """The contact law of materials a and b; an InputError when the scenario lacks it."""
    c = find_contact(scenario, a, b)
    if c is not None:
        return c
    raise InputError(f"contacts: no pair for materials {a!r} and {b!r}")


def coordination(res: DEMResult) -> dict:
    """Mean ball-ball coordination number of the sampled snapshots: Z = 2 C / N over all balls,
    and Z_nr = 2 C / N' over the balls with at least two ball contacts (rattlers out)."""
    if not res.has_ball_contacts or not res.has("ball_contacts/i"):
        return {"z_all": float("nan"), "z_non_rattler": float("nan")}
    f = res.file
    batch = res.batches()
    snap = f["ball_contacts/snapshot"][()]
    i = f["ball_contacts/i"][()]
    j = f["ball_contacts/j"][()]
    n = res.n_particles
    used = np.nonzero(batch >= 0)[0]
    rows = np.searchsorted(snap, np.arange(snap.max(initial=0) + 2))
    za, zn = [], []
    for s in used[:: max(1, used.size // 64)]:  # 64 snapshots are plenty for a mean
        a, b = rows[s], rows[s + 1]
        if b <= a:
            continue
        deg = np.bincount(i[a:b], minlength=n) + np.bincount(j[a:b], minlength=n)
        za.append(2.0 * (b - a) / n)
        keep = deg >= 2
        zn.append(deg[keep].sum() / max(keep.sum(), 1))
    return {"z_all": float(np.mean(za)) if za else float("nan"),
            "z_non_rattler": float(np.mean(zn)) if zn else float("nan")}


def contact_stiffness_at(scenario, pressure: float, phi: float, z: float, d: float):
    """Normal and tangential stiffness (N/m) of a ball-ball contact of the bed at `pressure`.

    Linear law: k_n and k_t as given.  Hertz-Mindlin: the tangent stiffnesses at the mean
    contact force f = pi d^2 p / (phi Z) (Rothenburg & Bathurst: p = phi Z <f> / (pi d^2)):
    delta = (3 f / (4 E* sqrt(R)))^(2/3), k_n = 2 E* sqrt(R delta), k_t = 8 G* sqrt(R delta)
    (Johnson, Contact Mechanics; Mindlin), R = d/4 for two equal balls.
    """
    pair = contact_pair(scenario, scenario.fill.material, scenario.fill.material)
    if pair.model == "linear":
        k_n = float(pair.k_n)
        return k_n, k_n * float(pair.k_t_over_k_n)
    mat = scenario.materials[scenario.fill.material]
    E, nu = float(mat.youngs_modulus), float(mat.poisson_ratio)
    e_star = E / (2.0 * (1.0 - nu**2))
    g_star = (E / (2.0 * (1.0 + nu))) / (2.0 * (2.0 - nu))
    R = 0.25 * d
    f = math.pi * d**2 * pressure / (phi * z)
    delta = (3.0 * f / (4.0 * e_star * math.sqrt(R))) ** (2.0 / 3.0)
    return 2.0 * e_star * math.sqrt(R * delta), 8.0 * g_star * math.sqrt(R * delta)


def young_poisson(K: float, G: float) -> tuple[float, float]:
    """Young's modulus (Pa) and Poisson ratio of an isotropic solid with moduli K, G (3D)."""
    E = 9.0 * K * G / (3.0 * K + G)
    nu = (3.0 * K - 2.0 * G) / (2.0 * (3.0 * K + G))
    return E, nu
