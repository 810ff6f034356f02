"""A sample's wall contacts and floor force from the wall layer's cells, in one compiled pass.

A sample (formulation.CellSampler.record) counts as a wall contact, as the material point
method counts them, a cell of the U's wall layer that holds at least half a cell of material
(a material point's size) and whose wall law presses on the U (wall.py: state 1 stick, 2
slide): its normal and tangential force over the slice (N, the DEM's unit), its arc-length
coordinate and its tub-frame position.  The floor force is the z component (tub axes) of the
wall law's force on the material in the floor's cells (measure.floor_force.on_floor), summed
over them in numpy's order (numpy_sum.py) and taken over the slice.  Picked with numpy's masks
this was some twenty calls a sample; here it is one, with numpy's numbers bit for bit.
"""
from __future__ import annotations

from collections import namedtuple

import numba as nb
import numpy as np

from ..numpy_sum import pairwise_sum

#: a sample's wall contacts (`wall_sample`), packed first in the wall cells' order: particle
#: (n,) int32 the contact's pseudo-ball (its place among the sampled cells), fn, ft (n,) N the
#: normal force and the tangential one's magnitude over the slice, sliding (n,) whether it
#: slides, arc (n,) m its arc-length coordinate, position (n, 3) m its tub-frame position;
#: fz (F,) N/m the z components of the wall law's force on the F floor cells (a work array)
WallContacts = namedtuple("WallContacts", ["particle", "fn", "ft", "sliding", "arc",
                                           "position", "fz"])


def wall_contacts_work(n_wall: int, n_floor: int) -> WallContacts:
    """`wall_sample`'s arrays for n_wall wall cells and n_floor floor cells."""
    return WallContacts(np.zeros(n_wall, np.int32), np.zeros(n_wall), np.zeros(n_wall),
                        np.zeros(n_wall, np.bool_), np.zeros(n_wall), np.zeros((n_wall, 3)),
                        np.zeros(n_floor))


@nb.njit(cache=True)
def wall_sample(state, fn, ft, mass, half, wall_cells, wall_point, wall_arc, wall_position,
                floor_cells, floor_normal, length, out):
    """The wall contacts and the floor force of a sample (module docstring): state (N,) int8,
    fn, ft (N,) N/m the cells' wall law (wall.empty_history's), mass (N,) kg/m, half the mass
    of half a cell (kg/m); wall_cells (W,) the wall layer's cells, wall_point, wall_arc,
    wall_position their pseudo-balls, arc coordinates (m) and tub-frame positions (W, 3) (m);
    floor_cells (F,) the floor's cells and floor_normal (F, 2) their inward normals; length
    the slice's (m).  Fills out (WallContacts); returns (contacts, floor force N)."""
    count = 0
    for j in range(wall_cells.shape[0]):
        p = wall_cells[j]
        if state[p] > 0 and mass[p] >= half:
            out.particle[count] = wall_point[j]
            out.fn[count] = fn[p] * length
            out.ft[count] = abs(ft[p]) * length
            out.sliding[count] = state[p] == 2
            out.arc[count] = wall_arc[j]
            for c in range(3):
                out.position[count, c] = wall_position[j, c]
            count += 1
    nf = floor_cells.shape[0]
    for j in range(nf):
        p = floor_cells[j]
        out.fz[j] = fn[p] * floor_normal[j, 1] - ft[p] * floor_normal[j, 0]
    return count, pairwise_sum(out.fz, 0, nf) * length
