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
from dataclasses import dataclass
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator
from pydantic_core import PydanticCustomError

Vector3 = tuple[float, float, float]


class _Strict(BaseModel):
    # forbid: an unknown key is an error naming the key, not silently ignored; inf and nan (TOML
    # literals) are not a size, a speed or a duration: every number must be finite
    model_config = ConfigDict(extra="forbid", frozen=True, validate_default=True,
                              allow_inf_nan=False)


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
    seed: int = Field(1, ge=0, description="random seed of the fill")
    phases_per_cycle: int = Field(8, ge=1, description="snapshots per vibration cycle in the "
                                  "averaging window")
    batches: int = Field(4, ge=2, description="batch-means batches for standard errors")
    skin: float = Field(0.3, gt=0, description="Verlet skin as a fraction of the ball diameter")
    checkpoint_every: float = Field(120.0, gt=0, description="wall seconds between checkpoints")
    series_every: int = Field(100, ge=1, description="steps between time-series samples")
    max_overlap: float = Field(0.25, gt=0, description="blow-up bound on overlap / diameter")
    record_impacts: bool = True
    force_chunks: int = Field(2, ge=1, le=1024, description="chunks of the DEM's parallel force "
                              "assembly and of the continuum's parallel particle-to-grid "
                              "scatter: they fix the summation order, so the numbers depend on "
                              "them and not on the thread count; threads beyond them idle")


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
        for name in v:
            check_name("analysis.probes", name, key=True)
        return v


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

    @field_validator("case")
    @classmethod
    def _case_is_a_name(cls, v: str) -> str:
        return check_name("case", v)

    @field_validator("materials")
    @classmethod
    def _material_names(cls, v: dict) -> dict:
        for name in v:
            check_name("materials", name, key=True)
        return v

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
        """Cross-field checks: modes, materials, contact laws, averaging window, time step."""
        _check_mode(self)
        _check_materials(self)
        _check_contacts(self)
        if self.run.average_last > self.run.duration:
            _fail(f"run.average_last = {self.run.average_last!r}: must be at most run.duration "
                  f"= {self.run.duration!r} s")
        if not self.explicit and self.run.average_last > 0:
            # batch means need at least `batches` whole cycles in the window (tub47.md)
            cycles = math.floor(self.run.average_last * self.motion.frequency + 1e-9)
            if cycles < self.run.batches:
                _fail(f"run.average_last = {self.run.average_last!r}: holds {cycles} whole "
                      f"cycles at {self.motion.frequency!r} Hz; must hold at least run.batches "
                      f"= {self.run.batches} (i.e. >= "
                      f"{self.run.batches / self.motion.frequency:.4g} s)")
        _check_time_step(self)
        _check_vibration_step(self)
        _check_size(self)
        if self.explicit:
            _check_particles(self)
        else:
            _check_tub_fill(self)
        return self


# ----------------------------------------------------------------------------------------------
# Cross-field validation.  Each failure is one line "FIELD = VALUE: what is allowed"; it is raised
# as a pydantic error (so `Scenario(...)` built in code is checked too) whose message is the line.

def _fail(message: str):
    # the message goes through a context variable so that braces in it are not a template
    raise PydanticCustomError("scenario", "{message}", {"message": message})


def _q(name: str) -> str:
    return '"' + name + '"'


@dataclass(frozen=True)
class TouchingPair:
    """A pair of materials that can touch in a scenario, with the smallest bodies involved.

    `kind` is "ball-ball", "ball-tub wall", "ball-partition" or "ball-plane wall"; m_eff (kg)
    and r_eff (m) are those of the smallest balls of the pair (a wall: the ball's own mass and
    radius), which give the shortest contact time; `field`/`value` name the scenario field that
    brought the pair in (for error messages).
    """

    a: str
    b: str
    kind: str
    m_eff: float
    r_eff: float
    field: str
    value: str

    @property
    def label(self) -> str:
        return f"{self.a}-{self.b}"


def ball_materials(s: Scenario) -> dict[str, tuple[float, float, int, str]]:
    """Ball materials in use: name -> (smallest diameter, second smallest diameter (m; inf if
    the material has one ball), number of balls, the first field naming it)."""
    out: dict[str, tuple[float, float, int, str]] = {}
    if s.particles is not None:
        for i, p in enumerate(s.particles):
            d1, d2, n, f = out.get(p.material, (math.inf, math.inf, 0, f"particles.{i}.material"))
            d1, d2 = sorted((d1, d2, p.diameter))[:2]
            out[p.material] = (d1, d2, n + 1, f)
    elif s.fill is not None:
        d2 = s.fill.diameter if s.fill.count > 1 else math.inf
        out[s.fill.material] = (s.fill.diameter, d2, s.fill.count, "fill.material")
    return out


def wall_materials(s: Scenario) -> list[tuple[str, str, str]]:
    """Wall materials in use: (material, kind, field) for the tub wall, the partitions (none
    when the tub is periodic) and each plane wall."""
    out: list[tuple[str, str, str]] = []
    if s.tub is not None:
        out.append((s.tub.wall_material, "ball-tub wall", "tub.wall_material"))
        if not s.tub.periodic:
            out.append((s.tub.partition_material, "ball-partition", "tub.partition_material"))
    for i, w in enumerate(s.walls or []):
        out.append((w.material, "ball-plane wall", f"walls.{i}.material"))
    return out


def _ball_mass(s: Scenario, material: str, diameter: float) -> float:
    return s.materials[material].density * math.pi * diameter**3 / 6.0


def touching_pairs(s: Scenario) -> list[TouchingPair]:
    """Every pair of materials that can touch: ball-ball (a material with itself only when it
    has two balls or more) and ball-wall, each with the smallest two balls that can make it
    (their contact is the shortest: t_c grows with m_eff and r_eff, linear and Hertz alike).
    Materials must exist (see `_check_materials`)."""
    balls = ball_materials(s)
    out: list[TouchingPair] = []
    names = list(balls)
    for i, a in enumerate(names):
        da, da2, na, fa = balls[a]
        for b in names[i:]:
            if a == b and na < 2:
                continue
            db, _, _, fb = balls[b]
            if a == b:
                db = da2  # the smallest ball meets the next smallest of its own material
            ma, mb = _ball_mass(s, a, da), _ball_mass(s, b, db)
            ra, rb = 0.5 * da, 0.5 * db
            field, value = (fb, b) if a != b else (fa, a)
            out.append(TouchingPair(a, b, "ball-ball", ma * mb / (ma + mb), ra * rb / (ra + rb),
                                    field, value))
        for w, kind, field in wall_materials(s):
            out.append(TouchingPair(a, w, kind, _ball_mass(s, a, da), 0.5 * da, field, w))
    return out


def find_contact(s: Scenario, a: str, b: str) -> ContactPair | None:
    """The contact law of materials a and b (in either order), or None."""
    for c in s.contacts:
        if tuple(sorted(c.pair)) == tuple(sorted((a, b))):
            return c
    return None


def _check_mode(s: Scenario) -> None:
    if s.particles is None:
        for key in ("tub", "fill"):
            if getattr(s, key) is None:
                _fail(f"{key}: required unless particles are given (explicit mode)")
    elif len(s.particles) == 0:
        _fail("particles = []: must hold at least one particle")


def _check_materials(s: Scenario) -> None:
    known = ", ".join(sorted(s.materials)) or "none"
    used: list[tuple[str, str]] = []
    if s.fill is not None:
        used.append(("fill.material", s.fill.material))
    if s.tub is not None:
        used += [("tub.wall_material", s.tub.wall_material),
                 ("tub.partition_material", s.tub.partition_material)]
    used += [(f"particles.{i}.material", p.material) for i, p in enumerate(s.particles or [])]
    used += [(f"walls.{i}.material", w.material) for i, w in enumerate(s.walls or [])]
    for field, name in used:
        if name not in s.materials:
            _fail(f"{field} = {_q(name)}: no such material (materials: {known})")


def _check_contacts(s: Scenario) -> None:
    known = ", ".join(sorted(s.materials)) or "none"
    seen: dict[tuple[str, str], int] = {}
    for i, c in enumerate(s.contacts):
        shown = "[" + ", ".join(_q(m) for m in c.pair) + "]"
        for m in c.pair:
            if m not in s.materials:
                _fail(f"contacts.{i}.pair = {shown}: no such material {_q(m)} (materials: "
                      f"{known})")
        key = tuple(sorted(c.pair))
        if key in seen:
            _fail(f"contacts.{i}.pair = {shown}: duplicate of contacts.{seen[key]} (the order "
                  f"of a pair does not matter)")
        seen[key] = i
    for tp in touching_pairs(s):
        if find_contact(s, tp.a, tp.b) is None:
            _fail(f"{tp.field} = {_q(tp.value)}: no contact law for the pair {tp.label} "
                  f"({tp.kind}); add a [[contacts]] entry with pair = [{_q(tp.a)}, {_q(tp.b)}]")


def contact_times(s: Scenario) -> list[tuple[TouchingPair, float]]:
    """Contact time (s) of every pair in use, shortest first, from
    `vibroflow.scenario.laws.contact_time` (linear: the damped half period; Hertz: at 1 m/s)."""
    from vibroflow.scenario.laws import contact_time  # lazy: scipy stays out of `import vibroflow`

    out = [(tp, float(contact_time(find_contact(s, tp.a, tp.b), s.materials, tp.m_eff, tp.r_eff)))
           for tp in touching_pairs(s)]
    return sorted(out, key=lambda item: item[1])


# the time step must resolve each contact with at least this many steps
STEPS_PER_CONTACT = 10


def _check_time_step(s: Scenario) -> None:
    times = contact_times(s)
    if not times:
        return
    tp, t_c = times[0]
    if s.run.dt > t_c / STEPS_PER_CONTACT:
        _fail(f"run.dt = {s.run.dt!r}: must be at most {t_c / STEPS_PER_CONTACT:.2e} s "
              f"(1/{STEPS_PER_CONTACT} of the {tp.label} contact time {t_c:.2e} s)")


# ----------------------------------------------------------------------------------------------
# What a run will need, known before it starts: steps, rows, bytes, room in the tub, a start
# without overlaps.  Each bound is far beyond any run that finishes (tub47: 3.5e5 steps, 0.4 GB
# of snapshots), so it only stops a typo before it allocates exabytes or runs for years.

#: time steps of one run (vibration plus settling); at 1e7 ball-steps/s a one-ball run of 1e11
#: steps takes three hours
MAX_STEPS = 1e11
#: rows of the time series (run.duration / (run.dt * run.series_every))
MAX_SERIES_ROWS = 1e8
#: bytes of the snapshots (position, velocity, angular velocity: 36 bytes a ball a snapshot)
MAX_SNAPSHOT_BYTES = 256 * 2**30
#: cells of the analysis grid over the tub's cross-section
MAX_ANALYSIS_CELLS = 1e7
#: the vibration period must hold this many steps at least
STEPS_PER_CYCLE = 20
#: solid fraction of a loose random packing of spheres (Onoda & Liniger 1990: 0.555): the
#: least dense bed a fill settles to, so the largest volume it can take
LOOSE_PACKING = 0.555


def _check_vibration_step(s: Scenario) -> None:
    if s.explicit:
        return
    f = s.motion.frequency
    need = max(STEPS_PER_CYCLE, s.run.phases_per_cycle)
    if s.run.dt * f * need > 1.0:
        _fail(f"motion.frequency = {f!r}: its period {1 / f:.3g} s holds "
              f"{1 / (f * s.run.dt):.3g} steps of run.dt = {s.run.dt!r} s; must hold at least "
              f"{need} (at least {STEPS_PER_CYCLE} and run.phases_per_cycle = "
              f"{s.run.phases_per_cycle}): lower motion.frequency or run.dt")


def _check_size(s: Scenario) -> None:
    run = s.run
    steps = run.duration / run.dt
    settle = 0.0 if s.fill is None else max(s.fill.settle_time, s.fill.max_settle_time) / run.dt
    if steps + settle > MAX_STEPS:
        what = "run.duration" if steps >= settle else "fill.max_settle_time"
        value = run.duration if steps >= settle else s.fill.max_settle_time
        _fail(f"{what} = {value:g}: {steps + settle:.3g} steps of run.dt = {run.dt!r} s; a run "
              f"may have at most {MAX_STEPS:.0e} steps ({MAX_STEPS * run.dt:.3g} s at this dt)")
    rows = steps / run.series_every
    if rows > MAX_SERIES_ROWS:
        _fail(f"run.series_every = {run.series_every}: the series would have {rows:.3g} rows "
              f"over run.duration = {run.duration!r} s; must give at most "
              f"{MAX_SERIES_ROWS:.0e} (raise run.series_every to at least "
              f"{math.ceil(steps / MAX_SERIES_ROWS)})")
    if not s.explicit:
        cycles = math.floor(run.average_last * s.motion.frequency + 1e-9)
        snapshots = cycles * run.phases_per_cycle
        size = 36.0 * snapshots * s.fill.count
        if size > MAX_SNAPSHOT_BYTES:
            _fail(f"run.average_last = {run.average_last:g}: {snapshots} snapshots of "
                  f"{s.fill.count} balls would take {size / 2**30:.3g} GiB; must take at most "
                  f"{MAX_SNAPSHOT_BYTES / 2**30:.0f} GiB (shorten run.average_last or lower "
                  "run.phases_per_cycle)")
        tub = s.tub
        area = 2.0 * tub.radius * tub.rim_height
        cells = area / s.analysis.cell_size**2
        if cells > MAX_ANALYSIS_CELLS:
            _fail(f"analysis.cell_size = {s.analysis.cell_size!r}: {cells:.3g} cells over the "
                  f"tub's cross-section; must give at most {MAX_ANALYSIS_CELLS:.0e} (at least "
                  f"{math.sqrt(area / MAX_ANALYSIS_CELLS):.2g} m)")


def tub_volume(tub: Tub) -> float:
    """Volume (m^3) of the tub below its rim: a half disc of the radius and the straight walls
    above it, times the length."""
    area = 0.5 * math.pi * tub.radius**2 + 2.0 * tub.radius * (tub.rim_height - tub.radius)
    return area * tub.length


def _check_tub_fill(s: Scenario) -> None:
    fill, tub = s.fill, s.tub
    d = fill.diameter
    if 2.0 * tub.radius < 2.0 * d:
        _fail(f"tub.radius = {tub.radius!r}: the tub is narrower than two balls of "
              f"fill.diameter = {d!r} m; must be at least {d:g} m")
    # the insertion lattice (dem/fill.py) keeps a ball and its jitter off the partitions
    s_lat = fill.lattice_spacing * d
    need = s_lat if tub.periodic else d + 0.9 * (s_lat - d)
    if tub.length < need:
        _fail(f"tub.length = {tub.length!r}: shorter than one insertion lattice layer of "
              f"balls (fill.diameter x fill.lattice_spacing); must be at least {need:.4g} m")
    bed = fill.count * math.pi * d**3 / 6.0 / LOOSE_PACKING
    room = tub_volume(tub)
    if bed > room:
        fits = int(room * LOOSE_PACKING / (math.pi * d**3 / 6.0))
        _fail(f"fill.count = {fill.count}: {fill.count} balls of d = {d:g} m take "
              f"{bed:.3g} m^3 at a loose packing ({LOOSE_PACKING}), more than the tub holds "
              f"below its rim ({room:.3g} m^3); must be at most {fits}, or make the tub larger")


def _check_particles(s: Scenario) -> None:
    """Explicit mode: no ball starts inside another or behind a plane wall (the contact law
    would throw them apart at the first step, a blow-up whose cause is the input)."""
    import numpy as np  # lazy: keeps `import vibroflow` light

    ps = s.particles
    x = np.array([p.position for p in ps], dtype=float)
    r = 0.5 * np.array([p.diameter for p in ps], dtype=float)
    bound = s.run.max_overlap
    for k, w in enumerate(s.walls or []):
        dist = (x - np.array(w.point)) @ np.array(w.normal)
        behind = np.flatnonzero(dist < 0.0)
        if behind.size:
            i = int(behind[0])
            _fail(f"particles.{i}.position = {_fmt_vec(ps[i].position)}: the ball's centre is "
                  f"{-dist[i]:.3g} m behind walls.{k} (the side its normal points away from); "
                  "every ball must start on the walls' side")
        over = (r - dist) / (2.0 * r)
        bad = np.flatnonzero(over >= bound)
        if bad.size:
            i = int(bad[0])
            _fail(f"particles.{i}.position = {_fmt_vec(ps[i].position)}: the ball overlaps "
                  f"walls.{k} by {over[i]:.3g} of its diameter; must be below run.max_overlap "
                  f"= {bound:g}")
    if len(ps) < 2:
        return
    reach = 2.0 * float(r.max())
    if len(ps) <= 256:
        i_idx, j_idx = np.triu_indices(len(ps), 1)
    else:
        from scipy.spatial import cKDTree

        pairs = cKDTree(x).query_pairs(reach, output_type="ndarray")
        i_idx, j_idx = pairs[:, 0], pairs[:, 1]
    gap = np.linalg.norm(x[i_idx] - x[j_idx], axis=1)
    d_min = 2.0 * np.minimum(r[i_idx], r[j_idx])
    over = (r[i_idx] + r[j_idx] - gap) / d_min
    bad = np.flatnonzero(over >= bound)
    if bad.size:
        k = bad[np.lexsort((j_idx[bad], i_idx[bad]))[0]]
        i, j = sorted((int(i_idx[k]), int(j_idx[k])))
        if gap[k] == 0.0:
            _fail(f"particles.{j}.position = {_fmt_vec(ps[j].position)}: the same position as "
                  f"particles.{i}; balls must not overlap")
        _fail(f"particles.{j}.position = {_fmt_vec(ps[j].position)}: overlaps particles.{i} "
              f"by {over[k]:.3g} of the smaller diameter; must be below run.max_overlap = "
              f"{bound:g}")


def _fmt_vec(v) -> str:
    return "[" + ", ".join(f"{c:g}" for c in v) + "]"
