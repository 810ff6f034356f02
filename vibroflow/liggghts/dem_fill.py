"""A LIGGGHTS deck's start from vibroflow's DEM's own settled bed (`export_deck(fill_from=...)`,
`vibroflow export liggghts --fill-from DEM_RUN_DIR`).

Both codes then vibrate the very same bed, which isolates their contact dynamics from their
fills (LIGGGHTS' random insertion up to the rim leaves a bed that still flows when the vibration
starts: docs/validation.md section 27).  The bed is the one the DEM run started its vibration
from: vibroflow.dem.fill.settled_bed of the run's scenario (the fill cache, else settled again,
which is deterministic), accepted only when the run's fill is the exported scenario's (the same
vibroflow.dem.fill.fill_cache_key: fill, tub, materials, contacts, gravity, dt, seed, skin,
pivot, parts) and the run is finished (summary.json) by vibroflow's DEM (dem.h5's source).

It goes to LIGGGHTS as a data file (`read_data`, atom_style granular: per ball "id type
diameter density x y z", 17 significant digits, so the positions are the DEM's to the last bit),
ball i of the DEM being atom id i + 1, at rest (velocities zero: LIGGGHTS' default) and without
its contact histories, which LIGGGHTS builds anew during a short settle with the tub at rest
(FROM_FILL_SETTLE_TIME, then on until the kinetic energy per ball is below
fill.settle_kinetic_energy, at most FROM_FILL_MAX_SETTLE_TIME).
"""
from __future__ import annotations

import json
import tomllib
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from vibroflow.dem.fill import fill_cache_key, settled_bed
from vibroflow.dem.simulate import make_system, store_by_id
from vibroflow.errors import InputError
from vibroflow.progress import RunProgress
from vibroflow.scenario.io import parse_scenario
from vibroflow.scenario.part_shapes import signed_distance
from vibroflow.tub.geometry import distance_to_wall_np
from vibroflow.tub.parts import parts_of

#: the data file of a deck made from a DEM's fill
DATA_NAME = "fill.data"
#: settling of the DEM's bed in LIGGGHTS (s): at least this, then until the kinetic energy per
#: ball is below fill.settle_kinetic_energy, at most FROM_FILL_MAX_SETTLE_TIME
FROM_FILL_SETTLE_TIME = 0.02
FROM_FILL_MAX_SETTLE_TIME = 0.1
#: the facets' largest deviation from the U's and the parts' circles (m) for a deck from a DEM
#: bed: the bed rests on the analytic circles with overlaps of about 1 um (k_n = 1e5 N/m against
#: the weight of a few balls), and the default 0.05 mm chords press the balls at the wall with
#: up to 2.5 N at step 0 (measured; some 240 ball weights), the fine ones at most the DEM's own
#: 0.3 N (docs/validation.md section 27)
FROM_FILL_MAX_SAGITTA = 1.0e-6
#: the fields that shape the settled bed (vibroflow.dem.fill.fill_cache_key), named in the
#: refusal of a foreign run's fill
_FILL_FIELDS = ("fill", "tub", "materials", "contacts", "gravity", "parts")
_RUN_FIELDS = ("dt", "seed", "skin")


@dataclass(frozen=True)
class DemFill:
    """The settled bed of a DEM run, by ball id (ball i is LIGGGHTS atom i + 1): centres (N, 3)
    m in the tub frame (the lab frame, the tub at rest), radii (N,) m, densities (N,) kg/m^3."""

    position: np.ndarray
    radius: np.ndarray
    density: np.ndarray
    source: Path

    @property
    def n(self) -> int:
        return int(self.position.shape[0])


def _field(run_dir: Path, what: str) -> InputError:
    return InputError(f"--fill-from = {str(run_dir)!r}: {what}")


def _run_scenario(run_dir: Path):
    """The scenario of a finished vibroflow DEM run folder and its dem.h5 attributes."""
    if not run_dir.is_dir():
        what = "a file, not a folder" if run_dir.exists() else "no such folder"
        raise _field(run_dir, f"{what}; give the folder of a finished `vibroflow dem` run")
    h5 = run_dir / "dem.h5"
    if not h5.is_file() or not (run_dir / "summary.json").is_file():
        raise _field(run_dir, "not a finished vibroflow DEM run (no dem.h5 and summary.json)")
    try:
        with h5py.File(h5, "r") as f:
            attrs = {k: f.attrs.get(k) for k in ("source", "scenario_toml", "n_particles")}
            radius = np.asarray(f["particles/radius"][()], dtype=float)
        text = attrs["scenario_toml"]
        text = text.decode() if isinstance(text, bytes) else str(text)
        try:
            raw = tomllib.loads(text)
        except tomllib.TOMLDecodeError:  # dem.h5 keeps JSON where TOML cannot hold the scenario
            raw = json.loads(text)
        scenario = parse_scenario(raw)
        summary = json.loads((run_dir / "summary.json").read_text())
    except (OSError, KeyError, ValueError, TypeError, InputError,
            tomllib.TOMLDecodeError) as exc:
        raise _field(run_dir, f"its dem.h5 or summary.json is unreadable "
                              f"({str(exc).splitlines()[0][:120]})") from None
    source = attrs["source"].decode() if isinstance(attrs["source"], bytes) else attrs["source"]
    if source != "vibroflow":
        raise _field(run_dir, f"a run of {source!r}, not of vibroflow's DEM; give a "
                              "`vibroflow dem` run folder")
    if scenario.explicit:
        raise _field(run_dir, "a run of explicit balls, not of a tub fill")
    return scenario, radius, summary


def _differences(a, b) -> list[str]:
    """The fill-shaping fields (fill_cache_key's) in which scenarios a and b differ."""
    da, db = a.model_dump(mode="json"), b.model_dump(mode="json")
    out = [name for name in _FILL_FIELDS if json.dumps(da.get(name), sort_keys=True)
           != json.dumps(db.get(name), sort_keys=True)]
    out += [f"run.{k}" for k in _RUN_FIELDS if getattr(a.run, k) != getattr(b.run, k)]
    if list(a.motion.pivot) != list(b.motion.pivot):
        out.append("motion.pivot")
    return out


def dem_fill(run_dir, scenario) -> DemFill:
    """The settled bed of the finished DEM run in `run_dir`, for a deck of `scenario`.

    One-line InputError (naming --fill-from) when the folder is missing, is not a finished run
    of vibroflow's DEM (a LIGGGHTS import's folder included), its fill is not the scenario's
    (the differing fields named), its balls are not the run's (count and radii by id), or a ball
    overlaps the U, a partition or a part by more than the run's own largest overlap."""
    run_dir = Path(run_dir)
    theirs, radius, summary = _run_scenario(run_dir)
    if fill_cache_key(theirs) != fill_cache_key(scenario):
        diff = _differences(theirs, scenario) or ["the vibroflow version"]
        raise _field(run_dir, f"its fill is another scenario's (differs in {', '.join(diff)}); "
                              "give a DEM run of this scenario, fill and seed")
    system = make_system(theirs)
    with RunProgress(False) as prog:
        state, _ = settled_bed(system, theirs, prog)
    store_by_id(system, state)
    n = state.n
    if n != radius.size or n != scenario.fill.count:
        raise _field(run_dir, f"its bed has {n} balls, its dem.h5 {radius.size}, the scenario's "
                              f"fill.count {scenario.fill.count}; they must be equal")
    if not np.array_equal(state.radius, radius):
        raise _field(run_dir, "its bed's radii by ball id are not its dem.h5's")
    pos = np.array(state.pos, dtype=float)
    density = np.array([theirs.materials[system.material_names[m]].density
                        for m in state.mat], dtype=float)
    fill = DemFill(pos, np.array(state.radius, dtype=float), density, run_dir)
    check_clear(fill, scenario, _largest_overlap(summary, scenario.fill.diameter), run_dir)
    return fill


def _largest_overlap(summary: dict, d: float) -> float:
    """The run's largest overlap (m) of a ball with a ball, a wall or a part."""
    keys = ("max_overlap_over_d", "max_wall_overlap_over_d")
    return d * max(float(summary.get(k) or 0.0) for k in keys)


def check_clear(fill: DemFill, scenario, allowed: float, run_dir: Path) -> None:
    """Every ball at least its radius minus `allowed` (m) from the U, the partitions (a closed
    tub) and every part; InputError naming the worst ball otherwise."""
    tub = scenario.tub
    p, r = fill.position, fill.radius
    gaps = {"the U wall": distance_to_wall_np(p[:, 0], p[:, 2], tub.radius)}
    if not tub.periodic:
        gaps["a partition"] = np.minimum(p[:, 1], tub.length - p[:, 1])
    shifts = (-tub.length, 0.0, tub.length) if tub.periodic else (0.0,)
    for spec, part in zip(scenario.parts or [], parts_of(scenario)):
        gaps[f"part {spec.name}"] = np.min(
            [signed_distance(spec, p + np.array([0.0, dy, 0.0]), part.triangles)
             for dy in shifts], axis=0)
    for what, gap in gaps.items():
        overlap = r - gap
        worst = int(np.argmax(overlap))
        if overlap[worst] > allowed * (1.0 + 1e-9) + 1e-15:
            raise _field(run_dir, f"ball {worst} overlaps {what} by {overlap[worst]:.3g} m, more "
                                  f"than the run's largest overlap {allowed:.3g} m")


def data_file_text(fill: DemFill, box: tuple[float, ...], n_types: int,
                   periodic_length: float | None = None) -> str:
    """A LIGGGHTS data file (atom_style granular) of the bed: the box (x_lo, x_hi, y_lo, y_hi,
    z_lo, z_hi, m), `n_types` atom types, and per ball "id 1 diameter density x y z" (SI, 17
    significant digits); in a periodic tub (periodic_length, m) y is taken into [0, L)."""
    pos = fill.position.copy()
    if periodic_length is not None:
        pos[:, 1] = np.mod(pos[:, 1], periodic_length)
        pos[pos[:, 1] >= periodic_length, 1] = 0.0
    x_lo, x_hi, y_lo, y_hi, z_lo, z_hi = (float(v) for v in box)
    lines = ["LIGGGHTS data file: the settled bed of a vibroflow DEM run", "",
             f"{fill.n} atoms", f"{int(n_types)} atom types", "",
             f"{x_lo!r} {x_hi!r} xlo xhi", f"{y_lo!r} {y_hi!r} ylo yhi",
             f"{z_lo!r} {z_hi!r} zlo zhi", "", "Atoms", ""]
    for i in range(fill.n):
        x, y, z = (float(v) for v in pos[i])
        lines.append(f"{i + 1} 1 {2.0 * float(fill.radius[i])!r} {float(fill.density[i])!r} "
                     f"{x!r} {y!r} {z!r}")
    return "\n".join(lines) + "\n"
