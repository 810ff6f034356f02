"""The parts of [[parts]] in a LIGGGHTS deck: each part's mesh, its place in the wall fix, its
motion and the per-step dump of the balls near it (docs/liggghts.md, "Parts in the export").

* Mesh: one STL file per part, part_<name>.stl (vibroflow.liggghts.part_meshes), read by its
  own `fix mesh/surface` (id pmesh<k>, k = 1, 2, ...) with the part's own atom type (4, 5, ...:
  its material and its contact law with the balls in the per-type-pair tables,
  vibroflow.liggghts.parameters), with LIGGGHTS' default `curvature`: every part is convex
  seen from the balls, and LIGGGHTS computes no contact at an edge it treats as smooth
  (TriMesh's inactive edges), so a `curvature` above the crease angle (the U's, which is
  concave) would leave the ball whose nearest point is a crease without a contact: around a
  faceted cylinder of radius R the fraction r / (R + r) of the angles, 20 % for the bar of
  tub47-bar, whatever the facet count (docs/validation.md section 27).
* Wall fix: the part meshes follow the U and the partitions in the one `fix wall/gran` (LIGGGHTS
  3.8 allows one mesh wall fix), so `compute wall/gran/local` dumps their contacts with the
  others at the snapshots, the mesh index telling them apart (0 the U, 1 the partitions, then
  the parts; the parts from 1 in a periodic tub).
* Motion: a part with frame = "tub" gets the same two `fix move/mesh` (translation, then the
  rotation about the pivot) as the U; a part with frame = "lab" does not move.
* Dump: from one step before the averaging window to the end of the run, every step, the balls
  inside a box around the parts (their meshes' bounds, widened by a ball diameter, the skin and
  the tub's largest displacement there; `dump_modify region`): id, position, velocity, angular
  velocity, radius (post/part_contacts.dump).  The importer finds there each ball's first step
  in contact with a part's mesh (vibroflow.liggghts.part_contacts); LIGGGHTS-PUBLIC 3.8 has no
  per-contact event output, and dumping every wall contact every step would be a thousand
  times larger (the partitions' contacts).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from vibroflow.errors import InputError
from vibroflow.liggghts.part_meshes import part_triangles
from vibroflow.liggghts.stl import write_stl
from vibroflow.liggghts.template import _SLOT, _Deck, _fmt, safe_name

#: post/ file of the balls near the parts, every step of the window
PART_DUMP = "part_contacts.dump"
#: the part dump's columns
PART_DUMP_COLUMNS = ("id", "x", "y", "z", "vx", "vy", "vz", "omegax", "omegay", "omegaz",
                     "radius")


def part_file(name: str) -> str:
    """The STL file name of the part `name` (a safe name: vibroflow.liggghts.template)."""
    return f"part_{name}.stl"


def check_part_names(scenario) -> None:
    """Every part's name is a safe deck name, and its material one of the scenario's."""
    materials = scenario.materials if isinstance(scenario.materials, dict) else {}
    for k, p in enumerate(scenario.parts or []):
        safe_name(f"parts.{k}.name", p.name)
        safe_name(f"parts.{k}.material", p.material)
        if p.material not in materials:
            raise InputError(f"parts.{k}.material = {p.material!r}: not one of the scenario's "
                             f"materials {sorted(map(str, materials))}")


def part_mesh_ids(parts) -> list[str]:
    """The parts' mesh fix ids, in the scenario's order."""
    return [f"pmesh{k}" for k in range(1, len(parts) + 1)]


def add_part_meshes(deck: _Deck, parts) -> None:
    """Each part's `fix mesh/surface` with its own type (4 and up), module docstring."""
    for k, part in enumerate(parts, 1):
        mesh = part_file(safe_name(f"parts.{k - 1}.name", part.name))
        deck.add(f"fix pmesh{k} all mesh/surface file {_SLOT} type {k + 3}", mesh)


def moving_meshes(parts) -> list[str]:
    """The mesh fix ids of the parts that move with the tub (frame = "tub")."""
    return [f"pmesh{k}" for k, part in enumerate(parts, 1) if part.frame == "tub"]


def near_box(meshes, pad: float) -> np.ndarray:
    """(x_lo, x_hi, y_lo, y_hi, z_lo, z_hi) (m) of the box around the parts' meshes (list of
    (T, 3, 3) arrays) widened by `pad` (m) on every side."""
    pts = np.concatenate([np.asarray(m, dtype=float).reshape(-1, 3) for m in meshes])
    lo, hi = pts.min(axis=0) - pad, pts.max(axis=0) + pad
    return np.array([lo[0], hi[0], lo[1], hi[1], lo[2], hi[2]])


def add_part_exclusions(deck: _Deck, parts, length: float, max_sagitta: float,
                        margin: float) -> list[str]:
    """The regions outside each part (`side out`) for the fill's insertion region, so that no
    ball is inserted in or on a part (LIGGGHTS' insertion checks overlaps with balls, not with
    meshes): a cylinder's circle widened by `margin` (m, the ball radius and half the skin),
    another part's mesh bounds widened by it.  Returns the regions' ids."""
    ids = []
    for k, p in enumerate(parts, 1):
        if p.shape == "cylinder":
            deck.add(f"region pout{k} cylinder y {_SLOT} {_SLOT} {_SLOT} INF INF side out "
                     "units box", _fmt(p.center[0]), _fmt(p.center[2]), _fmt(p.radius + margin))
        else:
            box = near_box([part_triangles(p, length, max_sagitta)], margin)
            deck.add(f"region pout{k} block {_SLOT} {_SLOT} {_SLOT} {_SLOT} {_SLOT} {_SLOT} "
                     "side out units box", *(_fmt(v) for v in box))
        ids.append(f"pout{k}")
    return ids


def add_part_dump(deck: _Deck, parts, length: float, max_sagitta: float, pad: float,
                  window_start: int) -> None:
    """The per-step dump of the balls in the box around the parts' meshes widened by `pad` (m),
    from one step before the window's first vibration step `window_start` (relative to n0; at
    least step 1), into post/PART_DUMP."""
    box = near_box([part_triangles(p, length, max_sagitta) for p in parts], pad)
    deck.add("# the balls near the parts, every step from one step before the window")
    deck.add("region pnear block {} {} {} {} {} {} units box", *(_fmt(v) for v in box))
    deck.add("variable pfirst equal ${n0}+" + _SLOT, max(1, window_start - 1))
    deck.add("variable pstep equal (step>=v_pfirst)*(step+1)+(step<v_pfirst)*v_pfirst")
    deck.add("dump dpart all custom 1 post/" + PART_DUMP + " " + " ".join(PART_DUMP_COLUMNS))
    deck.add('dump_modify dpart every v_pstep region pnear sort id format "%d '
             + " ".join(["%.10g"] * 3 + ["%.7g"] * (len(PART_DUMP_COLUMNS) - 4)) + '"')


def write_part_meshes(out_dir, parts, length: float, max_sagitta: float) -> None:
    """Each part's mesh as out_dir/part_<name>.stl (ASCII, written atomically)."""
    for p in parts:
        write_stl(Path(out_dir) / part_file(p.name), part_triangles(p, length, max_sagitta),
                  p.name)
