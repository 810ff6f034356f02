"""Fill and settle: random non-overlapping insertion of the balls in the tub, then settling under
gravity with the tub at rest until the kinetic energy has died out (tub47.md, "Procedure").

Insertion: the sites of a cubic lattice of spacing s = lattice_spacing * d covering the tub
(above `insert_above`, at least s/2 from every wall, continued above the rim between the two
side walls if the tub is too small) are ranked by height and the lowest N taken, each moved by a
random jitter of up to 0.45 (s - d) per axis.  Any two balls are then at least d apart, so the
fill is non-overlapping by construction and needs no rejection loop, and it starts dense, so the
bed settles quickly.  The jitter, the lattice's random offset and the order of balls come from the
scenario's seed.

The settled state (positions, velocities, forces, neighbour list and every contact history) is
cached on disk (`settled_bed`), keyed by the hash of the scenario fields that shape it, so later
runs, e.g. an amplitude sweep, start from the very same bed.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
from pathlib import Path
from typing import Callable

import numpy as np

from .. import __version__
from ..errors import InputError
from ..progress import RunProgress
from ..scenario.part_shapes import signed_distance
from ..tub.geometry import distance_to_wall_np
from ..tub.parts import parts_of
from .interrupts import fault_sigint_settling
from .output import DamagedFile, load_state_file, save_state_file
from .simulate import DEMState, DEMSystem, init_state, run_steps
from .step import ASSEMBLY


def lattice_fill(scenario, rng: np.random.Generator) -> np.ndarray:
    """Initial ball centres (N, 3) in the tub frame (= lab frame at rest)."""
    fill, tub = scenario.fill, scenario.tub
    d = fill.diameter
    r = 0.5 * d
    s = fill.lattice_spacing * d
    jitter = 0.45 * (s - d)
    margin = r + jitter + 1e-9
    if tub.periodic:
        ny = max(int(tub.length // s), 1)
        ys = (np.arange(ny) + 0.5) * tub.length / ny
        if ny > 1 and tub.length / ny < s:
            raise InputError(f"tub.length = {tub.length!r}: too short for the insertion lattice "
                             f"(spacing {s:.4g} m); give a length of at least {s:.4g} m")
    else:
        ny = int((tub.length - 2 * margin) // s) + 1
        if tub.length - 2 * margin < 0:
            raise InputError(f"tub.length = {tub.length!r}: shorter than one ball diameter with "
                             f"its insertion jitter ({2 * margin:.4g} m); give a longer tub")
        span = (ny - 1) * s
        ys = tub.length / 2 - span / 2 + np.arange(ny) * s
    width = 2.0 * (tub.radius - margin)
    nx = int(width // s) + 1
    # random offset of the lattice across the tub, within the room the last column leaves
    xs = -tub.radius + margin + rng.uniform(0.0, width - (nx - 1) * s) + np.arange(nx) * s
    need = math.ceil(fill.count / ny)
    z = fill.insert_above + margin
    rows = []
    sites = np.zeros((0, 3))
    while sites.shape[0] < fill.count:
        if not scenario.parts:
            while sum(len(rw) for rw in rows) < need:
                z = _add_row(rows, xs, z, s, margin, tub)
        else:
            z = _add_row(rows, xs, z, s, margin, tub)
        sites_xz = np.array([p for rw in rows for p in rw]).reshape(-1, 2)
        sites = np.array([(x, y, z) for (x, z) in sites_xz for y in ys]).reshape(-1, 3)
        # sites within reach of a part (with the jitter) are not used: the bed settles around it
        # (the jitter moves a ball up to sqrt(3) jitter)
        sites = sites[clear_of_parts(scenario, sites, r + math.sqrt(3.0) * jitter + 1e-9)]
    order = np.lexsort((sites[:, 1], sites[:, 0], sites[:, 2]))
    sites = sites[order][: fill.count]
    sites += rng.uniform(-jitter, jitter, size=sites.shape)
    # kept in lattice order (by height, then x, then y): neighbours in space are neighbours in
    # memory, which keeps the force loops cache-friendly
    return sites


#: how far above the rim (m) the insertion lattice may reach (its balls fall in while settling)
INSERT_ABOVE_RIM_MAX = 10.0


def _add_row(rows: list, xs: np.ndarray, z: float, s: float, margin: float, tub) -> float:
    """Append the lattice row at height z (the sites at least `margin` from the U wall);
    returns the next row's height."""
    dist = distance_to_wall_np(xs, np.full_like(xs, z), tub.radius)
    ok = xs[(dist >= margin) & (np.abs(xs) <= tub.radius - margin)]
    rows.append([(x, z) for x in ok])
    if z + s > tub.rim_height + INSERT_ABOVE_RIM_MAX:
        raise InputError(f"fill.count: the insertion lattice reaches {INSERT_ABOVE_RIM_MAX:g} m "
                         f"above tub.rim_height = {tub.rim_height!r} m before it holds the "
                         "balls; give fewer balls, a lower fill.insert_above or a larger tub")
    return z + s


def clear_of_parts(scenario, sites: np.ndarray, margin: float) -> np.ndarray:
    """Whether each site (m, tub frame) lies at least `margin` (m) outside every part (the
    minimum image along y in a periodic tub)."""
    ok = np.ones(sites.shape[0], bool)
    length = scenario.tub.length
    shifts = (-length, 0.0, length) if scenario.tub.periodic else (0.0,)
    for spec, part in zip(scenario.parts or [], parts_of(scenario)):
        for dy in shifts:
            q = sites + np.array([0.0, dy, 0.0])
            ok &= signed_distance(spec, q, part.triangles) >= margin
    return ok


def fill_cache_key(scenario) -> str:
    """Hash of everything that shapes the settled bed (the force assembly, step.ASSEMBLY,
    included: it fixes the summation order)."""
    payload = {
        "fill": scenario.fill.model_dump(mode="json"),
        "tub": scenario.tub.model_dump(mode="json"),
        "materials": {k: v.model_dump(mode="json") for k, v in scenario.materials.items()},
        "contacts": [c.model_dump(mode="json") for c in scenario.contacts],
        "gravity": list(scenario.gravity), "dt": scenario.run.dt, "seed": scenario.run.seed,
        "skin": scenario.run.skin, "pivot": list(scenario.motion.pivot),
        "assembly": ASSEMBLY,
        # format 2: entries carry a checksum (output.save_state_file)
        "version": __version__, "format": 2,
    }
    if scenario.parts:  # the bed settles around them (a scenario without parts keeps its key)
        payload["parts"] = [p.model_dump(mode="json") for p in scenario.parts]
    text = json.dumps(payload, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:24]


def cache_dir() -> Path:
    root = os.environ.get("VIBROFLOW_CACHE")
    if root:
        return Path(root)
    return Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "vibroflow"


def fill_state(system: DEMSystem, scenario) -> DEMState:
    """The freshly inserted (unsettled) bed."""
    rng = np.random.default_rng(scenario.run.seed)
    pos = lattice_fill(scenario, rng)
    n = pos.shape[0]
    mat = system.material_names.index(scenario.fill.material)
    rho = scenario.materials[scenario.fill.material].density
    return init_state(system, pos, np.zeros((n, 3)), np.zeros((n, 3)),
                      np.full(n, 0.5 * scenario.fill.diameter), np.full(n, rho),
                      np.full(n, mat))


def settle(system: DEMSystem, state: DEMState, scenario,
           progress: Callable[[float, float], None] | None = None) -> dict:
    """Let the bed settle with the tub at rest: at least fill.settle_time, then until the kinetic
    energy per ball is below fill.settle_kinetic_energy (at most fill.max_settle_time)."""
    fill = scenario.fill
    dt = system.dt
    chunk = max(int(round(0.01 / dt)), 1)  # check every 10 ms of simulated time
    state.vibrating = False
    t_min, t_max = fill.settle_time, max(fill.max_settle_time, fill.settle_time)
    ke = state.kinetic_energy() / state.n
    while True:
        t = state.step * dt
        if t >= t_min - 0.5 * dt and ke < fill.settle_kinetic_energy:
            break
        if t >= t_max - 0.5 * dt:
            break
        run_steps(system, state, chunk)
        ke = state.kinetic_energy() / state.n
        if progress is not None:
            progress(state.step * dt, ke)
    return {"settle_time_s": state.step * dt, "kinetic_energy_per_ball_J": ke,
            "settled": bool(ke < fill.settle_kinetic_energy)}


def settled_bed(system: DEMSystem, scenario, prog: RunProgress) -> tuple[DEMState, dict]:
    """The settled bed, from the cache or made now (and cached).  A cache entry that is
    unreadable or fails its checksum (output.load_state_file) is made again; a cache that
    cannot be written costs only the time of the next run's settling (a warning)."""
    key = fill_cache_key(scenario)
    path = cache_dir() / "fills" / f"{key}.h5"
    if path.exists():
        try:
            state, attrs = load_state_file(path)
            info = json.loads(attrs.get("settle_info", "{}"))
            if state.n != scenario.fill.count:
                raise DamagedFile(path, f"{state.n} balls, not {scenario.fill.count}")
            info["cached"] = True
            prog.log(f"settled bed from cache {path}")
            return state, info
        except (DamagedFile, ValueError, TypeError, KeyError) as exc:
            prog.log(f"settled-bed cache entry {path} is damaged ({exc}): settling again")
    state = fill_state(system, scenario)
    n = state.n

    def progress(t, ke):
        prog.update(t, int(round(t / system.dt)) * n)
        fault_sigint_settling()

    prog.stage("fill + settle", max(scenario.fill.settle_time, 1e-9))
    info = settle(system, state, scenario, progress=progress)
    info["cached"] = False
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        save_state_file(path, state, {"settle_info": json.dumps(info)})
    except OSError as exc:
        prog.log(f"warning: the settled bed cannot be cached in {path.parent} "
                 f"({(exc.strerror or str(exc)).lower()}); the next run settles it again")
    return state, info
