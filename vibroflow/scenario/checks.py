"""The scenario's cross-field checks, run by `Scenario`'s validator: every material named
exists, every pair that can touch has one contact law, the averaging window and the time step
fit, the run has a size that can be allocated and finished, the fill fits the tub and an
explicit start has no overlaps.  Each failure is one line "FIELD = VALUE: what is allowed",
raised as a pydantic error (so `Scenario(...)` built in code is checked too).

The scenario record itself is vibroflow.scenario.model, which imports this module; here it is
only read (its type is not imported, which would close an import circle).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from pydantic_core import PydanticCustomError

from vibroflow.errors import InputError
from vibroflow.scenario.part_checks import check_parts, parts_volume_m3

#: a vibroflow.scenario.model.Scenario (and its Tub, ContactPair): read here, not imported
Scenario = Any
Tub = Any
ContactPair = Any


def check_consistent(s: Scenario) -> None:
    """Every cross-field check of a scenario, in the order its errors are reported."""
    _check_mode(s)
    _check_materials(s)
    _check_ball_masses(s)
    _check_contacts(s)
    if s.run.average_last > s.run.duration:
        fail(f"run.average_last = {s.run.average_last!r}: must be at most run.duration "
             f"= {s.run.duration!r} s")
    if not s.explicit and s.run.average_last > 0:
        # batch means need at least `batches` whole cycles in the window (tub47.md)
        cycles = math.floor(s.run.average_last * s.motion.frequency + 1e-9)
        if cycles < s.run.batches:
            fail(f"run.average_last = {s.run.average_last!r}: holds {cycles} whole "
                 f"cycles at {s.motion.frequency!r} Hz; must hold at least run.batches "
                 f"= {s.run.batches} (i.e. >= "
                 f"{s.run.batches / s.motion.frequency:.4g} s)")
    _check_time_step(s)
    _check_vibration_step(s)
    _check_size(s)
    check_parts(s, fail)
    if s.explicit:
        _check_particles(s)
    else:
        _check_tub_fill(s)
        _check_tub_motion(s)


def require_tub_mode(s: Scenario, who: str, where: str = "scenario") -> None:
    """InputError (one line) when `who` (a command or a method, "the continuum") needs a
    tub-mode scenario and `s` (read from `where`) is in explicit mode."""
    if s.tub is None or s.fill is None:
        raise InputError(f"{where}: {who} needs a tub-mode scenario (with [tub] and [fill]), "
                         "not explicit particles")


def fail(message: str):
    # the message goes through a context variable so that braces in it are not a template
    raise PydanticCustomError("scenario", "{message}", {"message": message})


def _q(name: str) -> str:
    return '"' + name + '"'


@dataclass(frozen=True)
class TouchingPair:
    """A pair of materials that can touch in a scenario, with the smallest bodies involved.

    `kind` is "ball-ball", "ball-tub wall", "ball-partition", "ball-plane wall" or "ball-part"; m_eff (kg)
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
    for i, p in enumerate(s.parts or []):
        out.append((p.material, "ball-part", f"parts.{i}.material"))
    return out


def _ball_mass(s: Scenario, material: str, diameter: float) -> float:
    return s.materials[material].density * math.pi * diameter**3 / 6.0


#: the lightest and the heaviest ball a run takes (kg): far beyond any medium (a 10 um steel
#: ball is 4e-12 kg, a 0.5 m one 500 kg), far inside the doubles, where a contact's time and
#: damping divide by the mass and multiply by it
MIN_BALL_MASS, MAX_BALL_MASS = 1.0e-20, 1.0e6


def _check_ball_masses(s: Scenario) -> None:
    for name, (d, _d2, _n, field) in ball_materials(s).items():
        mass = _ball_mass(s, name, d)
        if not MIN_BALL_MASS <= mass <= MAX_BALL_MASS:
            where = "fill.diameter" if field == "fill.material" else field.replace(
                ".material", ".diameter")
            fail(f"{where} = {d!r} m with materials.{name}.density = "
                 f"{s.materials[name].density!r} kg/m^3: a ball weighs {mass:.3g} kg; must "
                 f"weigh {MIN_BALL_MASS:g} - {MAX_BALL_MASS:g} kg")


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
                fail(f"{key}: required unless particles are given (explicit mode)")
    elif len(s.particles) == 0:
        fail("particles = []: must hold at least one particle")


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
    used += [(f"parts.{i}.material", p.material) for i, p in enumerate(s.parts or [])]
    for field, name in used:
        if name not in s.materials:
            fail(f"{field} = {_q(name)}: no such material (materials: {known})")


def _check_contacts(s: Scenario) -> None:
    known = ", ".join(sorted(s.materials)) or "none"
    seen: dict[tuple[str, str], int] = {}
    for i, c in enumerate(s.contacts):
        shown = "[" + ", ".join(_q(m) for m in c.pair) + "]"
        for m in c.pair:
            if m not in s.materials:
                fail(f"contacts.{i}.pair = {shown}: no such material {_q(m)} (materials: "
                      f"{known})")
        key = tuple(sorted(c.pair))
        if key in seen:
            fail(f"contacts.{i}.pair = {shown}: duplicate of contacts.{seen[key]} (the order "
                  f"of a pair does not matter)")
        seen[key] = i
    for tp in touching_pairs(s):
        if find_contact(s, tp.a, tp.b) is None:
            fail(f"{tp.field} = {_q(tp.value)}: no contact law for the pair {tp.label} "
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
        fail(f"run.dt = {s.run.dt!r}: must be at most {t_c / STEPS_PER_CONTACT:.2e} s "
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
#: cubes of a ball's diameter in the tub's box (the long tub of 140 000 balls: 3e5)
MAX_TUB_BALL_BOXES = 1e8
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
        fail(f"motion.frequency = {f!r}: its period {1 / f:.3g} s holds "
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
        fail(f"{what} = {value:g}: {steps + settle:.3g} steps of run.dt = {run.dt!r} s; a run "
              f"may have at most {MAX_STEPS:.0e} steps ({MAX_STEPS * run.dt:.3g} s at this dt)")
    rows = steps / run.series_every
    if rows > MAX_SERIES_ROWS:
        fail(f"run.series_every = {run.series_every}: the series would have {rows:.3g} rows "
              f"over run.duration = {run.duration!r} s; must give at most "
              f"{MAX_SERIES_ROWS:.0e} (raise run.series_every to at least "
              f"{math.ceil(steps / MAX_SERIES_ROWS)})")
    if not s.explicit:
        cycles = math.floor(run.average_last * s.motion.frequency + 1e-9)
        snapshots = cycles * run.phases_per_cycle
        size = 36.0 * snapshots * s.fill.count
        if size > MAX_SNAPSHOT_BYTES:
            fail(f"run.average_last = {run.average_last:g}: {snapshots} snapshots of "
                  f"{s.fill.count} balls would take {size / 2**30:.3g} GiB; must take at most "
                  f"{MAX_SNAPSHOT_BYTES / 2**30:.0f} GiB (shorten run.average_last or lower "
                  "run.phases_per_cycle)")
        tub = s.tub
        d = s.fill.diameter
        boxes = (2.0 * tub.radius / d) * (tub.rim_height / d) * (tub.length / d)
        if boxes > MAX_TUB_BALL_BOXES:
            fail(f"tub.radius = {tub.radius!r}, tub.rim_height = {tub.rim_height!r}, tub.length "
                 f"= {tub.length!r}: the tub spans {boxes:.3g} cubes of fill.diameter = {d!r} m "
                 f"(the neighbour search's cells); must span at most {MAX_TUB_BALL_BOXES:.0e}")
        area = 2.0 * tub.radius * tub.rim_height
        cells = area / s.analysis.cell_size**2
        if cells > MAX_ANALYSIS_CELLS:
            fail(f"analysis.cell_size = {s.analysis.cell_size!r} with tub.radius = "
                 f"{tub.radius!r}, tub.rim_height = {tub.rim_height!r}: {cells:.3g} cells over "
                 f"the tub's cross-section; must give at most {MAX_ANALYSIS_CELLS:.0e} (cells of "
                 f"at least {math.sqrt(area / MAX_ANALYSIS_CELLS):.2g} m, or a smaller tub)")


def tub_volume(tub: Tub) -> float:
    """Volume (m^3) of the tub below its rim: a half disc of the radius and the straight walls
    above it, times the length."""
    area = 0.5 * math.pi * tub.radius**2 + 2.0 * tub.radius * (tub.rim_height - tub.radius)
    return area * tub.length


#: the farthest the tub's wall may move in one step, in ball diameters: a wall that moves half
#: a diameter in a step drives a ball past any overlap a contact resolves (tub47 at amplitude
#: factor 1.5 moves 0.0025 of a diameter a step)
MAX_WALL_STEP_D = 0.5
#: the strongest gravity a tub run takes (m/s^2): a thousand times the Earth's
MAX_GRAVITY = 1.0e4


def _check_tub_motion(s: Scenario) -> None:
    """The tub's wall moves less than MAX_WALL_STEP_D ball diameters a step at its fastest (its
    translations' and its rotation's peak speeds, the rotation at the tub's point farthest from
    the pivot), and gravity pulls the fill down into the tub."""
    m, tub, d = s.motion, s.tub, s.fill.diameter
    w = 2.0 * math.pi * m.frequency
    f = m.amplitude_factor
    px, pz = m.pivot
    reach = max(math.hypot(x - px, z - pz) for x in (-tub.radius, tub.radius)
                for z in (0.0, tub.rim_height))
    speed = f * w * (math.hypot(m.amplitude_x, m.amplitude_z) + m.amplitude_theta * reach)
    if speed * s.run.dt > MAX_WALL_STEP_D * d:
        fail(f"motion.amplitude_x, amplitude_z, amplitude_theta = {m.amplitude_x!r}, "
             f"{m.amplitude_z!r}, {m.amplitude_theta!r} (x amplitude_factor {f!r}, pivot "
             f"{tuple(m.pivot)!r} m, {m.frequency!r} Hz): the wall moves at up to "
             f"{speed:.3g} m/s, {speed * s.run.dt / d:.3g} ball diameters a step of run.dt = "
             f"{s.run.dt!r} s; must be at most {MAX_WALL_STEP_D} (smaller amplitudes or "
             "run.dt)")
    g, gz = math.hypot(*s.gravity), s.gravity[2]
    if g > MAX_GRAVITY:
        fail(f"gravity = {_fmt_vec(s.gravity)}: {g:.3g} m/s^2; must be at most "
             f"{MAX_GRAVITY:g} m/s^2")
    if not gz < 0:
        fail(f"gravity = {_fmt_vec(s.gravity)}: in a tub run it must pull down (its z "
             "component < 0), so that the fill settles into the tub")


def _check_tub_fill(s: Scenario) -> None:
    fill, tub = s.fill, s.tub
    d = fill.diameter
    if 2.0 * tub.radius < 2.0 * d:
        fail(f"tub.radius = {tub.radius!r}: the tub is narrower than two balls of "
              f"fill.diameter = {d!r} m; must be at least {d:g} m")
    # the insertion lattice (dem/fill.py) keeps a ball and its jitter off the partitions
    s_lat = fill.lattice_spacing * d
    need = s_lat if tub.periodic else d + 0.9 * (s_lat - d)
    if tub.length < need:
        fail(f"tub.length = {tub.length!r}: shorter than one insertion lattice layer of "
              f"balls (fill.diameter x fill.lattice_spacing); must be at least {need:.4g} m")
    if fill.insert_above >= tub.rim_height:
        fail(f"fill.insert_above = {fill.insert_above!r}: the balls are inserted inside the "
             f"tub; must be below tub.rim_height = {tub.rim_height!r} m")
    bed = fill.count * math.pi * d**3 / 6.0 / LOOSE_PACKING
    room = tub_volume(tub) - (parts_volume_m3(s) if s.parts else 0.0)
    if bed > room:
        fits = int(room * LOOSE_PACKING / (math.pi * d**3 / 6.0))
        fail(f"fill.count = {fill.count}: {fill.count} balls of d = {d:g} m take "
              f"{bed:.3g} m^3 at a loose packing ({LOOSE_PACKING}), more than the tub holds "
              f"below its rim{' less its parts' if s.parts else ''} ({room:.3g} m^3); must be at most {fits}, or make the tub larger")


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
            fail(f"particles.{i}.position = {_fmt_vec(ps[i].position)}: the ball's centre is "
                  f"{-dist[i]:.3g} m behind walls.{k} (the side its normal points away from); "
                  "every ball must start on the walls' side")
        over = (r - dist) / (2.0 * r)
        bad = np.flatnonzero(over >= bound)
        if bad.size:
            i = int(bad[0])
            fail(f"particles.{i}.position = {_fmt_vec(ps[i].position)}: the ball overlaps "
                  f"walls.{k} by {over[i]:.3g} of its diameter; must be below run.max_overlap "
                  f"= {bound:g}")
    if len(ps) < 2:
        return
    reach = 2.0 * float(r.max())
    if len(ps) <= 256:
        i_idx, j_idx = np.triu_indices(len(ps), 1)
    else:
        from scipy.spatial import cKDTree  # lazy: scipy stays out of `import vibroflow`

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
            fail(f"particles.{j}.position = {_fmt_vec(ps[j].position)}: the same position as "
                  f"particles.{i}; balls must not overlap")
        fail(f"particles.{j}.position = {_fmt_vec(ps[j].position)}: overlaps particles.{i} "
              f"by {over[k]:.3g} of the smaller diameter; must be below run.max_overlap = "
              f"{bound:g}")


def _fmt_vec(v) -> str:
    return "[" + ", ".join(f"{c:g}" for c in v) + "]"
