"""The scenario a calibration was measured on (calibration.toml's [scenario]) and its check
against the scenario a solver runs: a calibration measured on other media or another tub is an
error unless it is asked for (`--allow-other-calibration`).

The media are the balls (diameter m, density kg/m^3) and the contact laws that shape the bed's
rheology (normal restitution and Coulomb friction of ball-ball, ball-wall and ball-partition
contacts); the tub is its radius, rim height and length (m) and whether the length is periodic.
The case's name is recorded but not compared: two cases with the same media and tub share a
calibration.
"""
from __future__ import annotations

import math

from vibroflow.errors import InputError
from vibroflow.scenario.checks import find_contact

from .calibration_file import Calibration

ALLOW_FLAG = "--allow-other-calibration"


def _contact(sc, a: str, b: str, name: str) -> dict:
    c = find_contact(sc, a, b)
    if c is None:
        return {}
    return {f"{name}_restitution": float(c.restitution), f"{name}_friction": float(c.friction)}


def scenario_source(sc) -> dict:
    """The [scenario] table of calibration.toml for the tub scenario `sc`: its case, media and
    tub (SI units)."""
    out: dict = {"case": str(sc.case)}
    if sc.fill is not None:
        ball = sc.fill.material
        media = {"diameter_m": float(sc.fill.diameter),
                 "density_kg_m3": float(sc.materials[ball].density)}
        if sc.tub is not None:
            media.update(_contact(sc, ball, ball, "ball_ball"))
            media.update(_contact(sc, ball, sc.tub.wall_material, "ball_wall"))
            media.update(_contact(sc, ball, sc.tub.partition_material, "ball_partition"))
        out["media"] = media
    if sc.tub is not None:
        out["tub"] = {"radius_m": float(sc.tub.radius), "rim_height_m": float(sc.tub.rim_height),
                      "length_m": float(sc.tub.length), "periodic": bool(sc.tub.periodic)}
    return out


def _same(a, b) -> bool:
    if isinstance(a, bool) or isinstance(b, bool):
        return a == b
    return math.isclose(float(a), float(b), rel_tol=1e-9, abs_tol=0.0)


def check_calibration_source(cal: Calibration, sc, where: str = "calibration",
                             allow: bool = False) -> str | None:
    """Check that the calibration `cal` was measured on the media and tub of scenario `sc`.

    A field that differs is an InputError naming `where`, the field, both values and the way
    out (ALLOW_FLAG), unless `allow`; returns a one-line warning when `cal` has no [scenario]
    (it cannot be checked) or when `allow` lets a difference through, else None.
    """
    if cal.scenario is None:
        return (f"warning: {where} has no [scenario] table: cannot check that it was measured on "
                f"this scenario's media and tub")
    own = scenario_source(sc)
    recorded = cal.scenario.to_toml_dict()
    for table in ("media", "tub"):
        mine, theirs = own.get(table, {}), recorded.get(table, {})
        for key, value in theirs.items():
            if key in mine and not _same(value, mine[key]):
                field = f"scenario.{table}.{key}"
                what = (f"{where}: {field} = {value!r} (case {recorded.get('case', '?')}) but "
                        f"the scenario ({own['case']}) has {mine[key]!r}")
                if allow:
                    return f"warning: {what}; used anyway ({ALLOW_FLAG})"
                raise InputError(f"{what}: the calibration is from other {table}; "
                                 f"{ALLOW_FLAG} uses it anyway")
    return None
