"""The scenario: a validated, typed record of everything a run needs (SI units throughout).

Every number of tub47.md is a field and tub47's values are the defaults, so `Scenario()` *is*
the reference case.  A scenario has one of two modes:

* tub mode (the default): balls are filled into the U tub, settled, then vibrated;
* explicit mode: `particles` (and optionally `walls`) are given, no tub and no fill; there
  `run.duration` is the whole simulated time.

The record is frozen after validation; use `scenario.model_copy(update=...)` or
`vibroflow.scenario.io.apply_overrides` to derive variants.
"""
from __future__ import annotations

import math
import re
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from vibroflow.scenario.checks import check_consistent, fail as _fail

Vector3 = tuple[float, float, float]


class _Strict(BaseModel):
    # forbid: an unknown key is an error naming the key, not silently ignored; inf and nan (TOML
    # literals) are not a size, a speed or a duration: every number must be finite
    model_config = ConfigDict(extra="forbid", frozen=True, validate_default=True,
                              allow_inf_nan=False)

    @field_validator("*", mode="before")
    @classmethod
    def _no_bool_for_a_number(cls, value: Any, info) -> Any:
        # pydantic's lax mode reads true as 1 and false as 0: a count or a size typed as a
        # boolean is a slip, not a number
        if isinstance(value, bool):
            annotation = cls.model_fields[info.field_name].annotation
            if annotation in (int, float, "int", "float"):
                raise ValueError("must be a number, not true or false")
        return value


#: names that reach file names, a LIGGGHTS deck, HTML and shells: a letter or digit, then
#: letters, digits and _ . + -, at most 64 characters (no space, quote, newline or separator)
NAME_PATTERN = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.+-]{0,63}")
NAME_RULE = ("a letter or digit, then letters, digits and _ . + - (at most 64 characters, no "
             "spaces)")


def check_name(field: str, name: str, key: bool = False) -> str:
    """`name` if it is a safe name (NAME_PATTERN), else the one-line scenario error; `key`: the
    name is a table's key (a material's, a probe's), shown after the table's field."""
    if not isinstance(name, str) or NAME_PATTERN.fullmatch(name) is None:
        where = f"{field} key {_show(name)}" if key else f"{field} = {_show(name)}"
        _fail(f"{where}: must be a name: {NAME_RULE}")
    return name


def check_keys(field: str, table: dict) -> dict:
    """`table` if each of its keys is a safe name (check_name), else the one-line scenario
    error naming the first that is not."""
    for name in table:
        check_name(field, name, key=True)
    return table


def _show(value: Any) -> str:
    # a hostile name shown safely: escapes for newlines and control characters, cut short
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


class Material(_Strict):
    """Bulk properties of a solid (the Hertz law uses E and nu)."""

    density: float = Field(7800.0, gt=0, description="kg/m^3")
    youngs_modulus: float = Field(2.0e11, gt=0, description="Pa")
    poisson_ratio: float = Field(0.3, gt=-1.0, lt=0.5, description="-")


class ContactPair(_Strict):
    """Contact law of one pair of materials (models.md).  The same law serves ball-ball and
    ball-wall contacts."""

    pair: tuple[str, str]
    model: Literal["linear", "hertz"] = "linear"
    k_n: float | None = Field(1.0e5, gt=0, description="N/m, linear law only")
    k_t_over_k_n: float = Field(2.0 / 7.0, gt=0, description="linear law; Hertz uses Mindlin")
    restitution: float = Field(0.85, gt=0, le=1.0, description="normal restitution, (0, 1]")
    friction: float = Field(0.20, ge=0, description="Coulomb sliding friction coefficient")
    rolling_friction: float = Field(0.002, ge=0, description="rolling resistance mu_r (-)")
    rolling_model: Literal["cdt", "epsd", "none", "cdt_liggghts"] = Field(
        "cdt", description="constant directional torque (tub47.md: mu_r R_eff |F_n| against "
        "the relative rolling velocity), or elastic-plastic spring-dashpot (Ai et al. 2011), "
        "or LIGGGHTS 3.8's CDT for comparisons with it (mu_r R_eff k_n delta along the "
        "relative spin, its twisting part removed)")

    @model_validator(mode="before")
    @classmethod
    def _hertz_has_no_kn(cls, data: Any) -> Any:
        # k_n belongs to the linear law: a Hertz pair given no k_n has none (rather than the
        # linear default), so that a dumped Hertz pair (None is not written) loads back equal
        if isinstance(data, dict) and data.get("model") == "hertz" and "k_n" not in data:
            data = {**data, "k_n": None}
        return data

    @model_validator(mode="after")
    def _linear_needs_kn(self):
        if self.model == "linear" and self.k_n is None:
            raise ValueError("k_n is required by the linear law")
        return self


class Run(_Strict):
    dt: float = Field(1.0e-5, gt=0, description="time step (s)")
    duration: float = Field(3.0, gt=0, description="vibration time after settling (s); in "
                            "explicit mode the whole simulated time")
    average_last: float = Field(2.0, ge=0, description="averaging window at the end (s)")
    seed: int = Field(1, ge=0, lt=2**63, description="random seed of the fill")
    phases_per_cycle: int = Field(8, ge=1, description="snapshots per vibration cycle in the "
                                  "averaging window")
    batches: int = Field(4, ge=2, description="batch-means batches for standard errors")
    skin: float = Field(0.3, gt=0, description="Verlet skin as a fraction of the ball diameter")
    checkpoint_every: float = Field(120.0, gt=0, description="wall seconds between checkpoints")
    series_every: int = Field(100, ge=1, description="steps between time-series samples")
    max_overlap: float = Field(0.25, gt=0, description="blow-up bound on overlap / diameter")
    record_impacts: bool = True
    force_chunks: int = Field(2, ge=1, le=1024, description="chunks of the continuum's "
                              "parallel particle-to-grid scatter: they fix its summation order, "
                              "so the continuum's numbers depend on them and not on the thread "
                              "count; threads beyond them idle there (the DEM's numbers depend "
                              "on neither)")


class Fill(_Strict):
    count: int = Field(14000, ge=1, description="number of balls")
    diameter: float = Field(0.00635, gt=0, description="ball diameter (m)")
    material: str = "steel"
    settle_time: float = Field(0.5, ge=0, description="settling time with the tub at rest (s)")
    insert_above: float = Field(0.01, ge=0, description="lowest insertion height (m)")
    lattice_spacing: float = Field(1.1, gt=1.0, description="insertion lattice spacing / d")
    settle_kinetic_energy: float = Field(1.0e-7, gt=0, description="settled when the kinetic "
                                         "energy per ball is below this (J)")
    max_settle_time: float = Field(2.0, gt=0, description="give up settling after (s)")


class Tub(_Strict):
    radius: float = Field(0.15, gt=0, description="bottom half-circle radius = half width (m)")
    rim_height: float = Field(0.40, gt=0, description="rim height above the lowest point (m)")
    length: float = Field(0.0635, gt=0, description="partition spacing L_y (m)")
    periodic: bool = Field(False, description="periodic length instead of partitions")
    wall_material: str = "polyurethane"
    partition_material: str = "glass"

    @model_validator(mode="after")
    def _rim_above_bottom(self):
        if self.rim_height < self.radius:
            raise ValueError(f"rim_height = {self.rim_height}: must be at least radius = "
                             f"{self.radius}")
        return self


class Motion(_Strict):
    """Harmonic rigid motion s(a, phi, t) = a [sin(omega t + phi) - sin(phi)] (tub47.md)."""

    frequency: float = Field(47.0, gt=0, description="Hz")
    amplitude_x: float = Field(1.0e-3, ge=0, description="m")
    phase_x: float = 0.0
    amplitude_z: float = Field(1.5e-3, ge=0, description="m")
    phase_z: float = 0.5 * math.pi
    amplitude_theta: float = Field(4.0e-3, ge=0, description="rad")
    phase_theta: float = 0.0
    pivot: tuple[float, float] = Field((0.0, -0.10), description="(x, z) in the tub frame (m)")
    amplitude_factor: float = Field(1.0, ge=0, description="multiplies every amplitude")


class Probe(_Strict):
    x: float
    z: float


def _default_probes() -> dict[str, Probe]:
    return {
        "P1": Probe(x=-0.10, z=0.15), "P2": Probe(x=0.00, z=0.15),
        "P3": Probe(x=0.10, z=0.15), "P4": Probe(x=0.00, z=0.05),
        "P5": Probe(x=0.00, z=0.18),
    }


class Analysis(_Strict):
    cell_size: float = Field(0.015, gt=0, description="square cells (m), centred on multiples")
    min_solid_fraction: float = Field(0.3, ge=0, le=1, description="cells counted in E")
    probes: dict[str, Probe] = Field(default_factory=_default_probes)

    @field_validator("probes")
    @classmethod
    def _probe_names(cls, v: dict) -> dict:
        return check_keys("analysis.probes", v)


class ParticleSpec(_Strict):
    position: Vector3
    velocity: Vector3 = (0.0, 0.0, 0.0)
    angular_velocity: Vector3 = (0.0, 0.0, 0.0)
    diameter: float = Field(0.00635, gt=0, description="m")
    material: str = "steel"


class WallSpec(_Strict):
    """An infinite plane through `point` with unit `normal` pointing to the balls' side,
    moving with constant `velocity` plus an optional harmonic displacement per axis,
    amplitude [sin(2 pi frequency t + phase) - sin(phase)]."""

    point: Vector3 = (0.0, 0.0, 0.0)
    normal: Vector3 = (0.0, 0.0, 1.0)
    material: str = "steel"
    velocity: Vector3 = (0.0, 0.0, 0.0)
    amplitude: Vector3 = (0.0, 0.0, 0.0)
    frequency: float = Field(0.0, ge=0, description="Hz")
    phase: float = 0.0

    @field_validator("normal")
    @classmethod
    def _unit(cls, v):
        n = math.sqrt(sum(c * c for c in v))
        if n == 0:
            raise ValueError("normal must not be the zero vector")
        return tuple(c / n for c in v)


class PartSpec(_Strict):
    """A rigid part in the bed (vibroflow/tub/parts.py), fixed in the tub frame (it moves with
    the tub) or in the lab.  Shapes: a cylinder across the slice (axis along y through
    `center`'s x and z, spanning partition to partition), a box (edge lengths `size` along x, y,
    z, turned by `angle_y` about y), a sphere, or a triangulated STL surface (`file`, its
    coordinates times `scale` placed at `center`).  Which fields a shape takes is checked in
    vibroflow/scenario/part_checks.py."""

    name: str
    shape: Literal["cylinder", "box", "sphere", "stl"]
    center: Vector3 = Field(description="m, tub frame (the lab's at t = 0)")
    radius: float | None = Field(None, gt=0, description="m; cylinder and sphere")
    size: Vector3 | None = Field(None, description="m, edge lengths along x, y, z; box")
    angle_y: float = Field(0.0, description="rad, the box turned about y (x towards z); box")
    file: str | None = Field(None, description="a binary or ASCII STL file, its path relative to the scenario file; stl")
    scale: float = Field(1.0, gt=0, description="m per STL file unit (0.001 for mm); stl")
    material: str = "steel"
    frame: Literal["tub", "lab"] = Field("tub", description="tub: moves with the tub; lab: "
                                         "held still")

    @field_validator("name")
    @classmethod
    def _name(cls, v: str) -> str:
        return check_name("parts.name", v)


def _default_materials() -> dict[str, Material]:
    return {
        "steel": Material(density=7800.0, youngs_modulus=2.0e11, poisson_ratio=0.3),
        # polyurethane lining and glass partitions: density and moduli only matter for Hertz
        "polyurethane": Material(density=1200.0, youngs_modulus=2.5e7, poisson_ratio=0.45),
        "glass": Material(density=2500.0, youngs_modulus=6.3e10, poisson_ratio=0.23),
    }


def _default_contacts() -> list[ContactPair]:
    r = 2.0 / 7.0
    return [
        ContactPair(pair=("steel", "steel"), k_n=1.0e5, k_t_over_k_n=r, restitution=0.85,
                    friction=0.20, rolling_friction=0.002),
        ContactPair(pair=("steel", "polyurethane"), k_n=5.0e4, k_t_over_k_n=r,
                    restitution=0.60, friction=0.40, rolling_friction=0.002),
        ContactPair(pair=("steel", "glass"), k_n=1.0e5, k_t_over_k_n=r, restitution=0.85,
                    friction=0.15, rolling_friction=0.002),
    ]


class Scenario(_Strict):
    case: str = "tub47"
    gravity: Vector3 = (0.0, 0.0, -9.81)
    materials: dict[str, Material] = Field(default_factory=_default_materials)
    contacts: list[ContactPair] = Field(default_factory=_default_contacts)
    run: Run = Field(default_factory=Run)
    fill: Fill | None = Field(default_factory=Fill)
    tub: Tub | None = Field(default_factory=Tub)
    motion: Motion = Field(default_factory=Motion)
    analysis: Analysis = Field(default_factory=Analysis)
    particles: list[ParticleSpec] | None = None
    walls: list[WallSpec] | None = None
    parts: list[PartSpec] | None = None

    @field_validator("case")
    @classmethod
    def _case_is_a_name(cls, v: str) -> str:
        return check_name("case", v)

    @field_validator("materials")
    @classmethod
    def _material_names(cls, v: dict) -> dict:
        return check_keys("materials", v)

    @property
    def explicit(self) -> bool:
        """True in explicit mode (given particles, no tub, no fill)."""
        return self.particles is not None

    @model_validator(mode="before")
    @classmethod
    def _explicit_mode(cls, data: Any) -> Any:
        # Given particles, the scenario has no tub and no fill.  A TOML file cannot say None, so
        # they are switched off here; saying both is a contradiction, not something to guess at.
        if isinstance(data, dict) and data.get("particles") is not None:
            data = dict(data)
            for key in ("tub", "fill"):
                if data.get(key) is not None:
                    _fail(f"{key}: not allowed with particles (explicit mode has no tub and no "
                          f"fill); remove [{key}] or the [[particles]]")
                data[key] = None
        return data

    @model_validator(mode="after")
    def _consistent(self):
        """Cross-field checks (vibroflow.scenario.checks): modes, materials, contact laws, the
        averaging window, the time step, the run's size, the fill's room, the start."""
        check_consistent(self)
        return self
