"""When the DEM cannot go on: `BlowUp`, and the diagnosis its one-line message gives from the
state (vibroflow.dem.simulate raises it): non-finite input, balls coincident or overlapping at
the start, a ball behind a wall or outside the tub, an overlap beyond the bound during the run,
and the time step only when it resolves the contact time too coarsely (STEPS_PER_CONTACT).
`system` and `state` are vibroflow.dem.simulate's DEMSystem and DEMState (which imports this
module, so they are not imported here).
"""
from __future__ import annotations

import math
import numpy as np

from ..scenario.checks import STEPS_PER_CONTACT
from . import step as K
from .walls import WALL_PARTITION_HI, WALL_PARTITION_LO, WALL_PLANE0, WALL_U


class BlowUp(RuntimeError):
    """The run became unphysical, or its starting state cannot be run; the message (one line)
    names the balls and the cause the state shows: non-finite input, balls coincident or
    overlapping at the start, a ball behind a wall or outside the tub, and the time step only
    when it resolves the contact time too coarsely."""


def _vec(v) -> str:
    return "(" + ", ".join(f"{float(x):.6g}" for x in np.ravel(v)) + ")"


def _ids(ids, at_most: int = 10) -> str:
    ids = [int(i) for i in ids]
    more = f" and {len(ids) - at_most} more" if len(ids) > at_most else ""
    return str(ids[:at_most]) + more


def _wall_name(w: int, system=None) -> str:
    """The wall slot w, or the part whose index follows the slots (vibroflow.dem.step)."""
    if system is not None and w >= system.n_walls:
        part = system.parts[w - system.n_walls]
        return f"part {part.name!r} ({part.shape}, parts[{w - system.n_walls}])"
    if w == WALL_U:
        return "wall 0 (the tub's U wall)"
    if w == WALL_PARTITION_LO:
        return "wall 1 (the partition at y = 0)"
    if w == WALL_PARTITION_HI:
        return "wall 2 (the partition at y = length)"
    return f"wall {w} (plane walls[{w - WALL_PLANE0}])"


def check_finite_start(state) -> None:
    """BlowUp naming the balls and fields of a starting state that holds NaN or infinity, or a
    radius or mass not > 0: the kernels would turn it into NaN everywhere (and the neighbour
    grid into nonsense) and the blow-up would be blamed on the time step."""
    bad = []
    for name, a in (("position", state.pos), ("velocity", state.vel),
                    ("angular_velocity", state.omg), ("radius", state.radius),
                    ("mass", state.mass)):
        rows = a.reshape(state.n, -1)
        wrong = ~np.isfinite(rows).all(axis=1)
        if name in ("radius", "mass"):
            wrong |= ~(rows[:, 0] > 0.0)
        bad += [(int(i), name, rows[i]) for i in np.nonzero(wrong)[0]]
    if bad:
        shown = ", ".join(f"ball {i} {name} = {_vec(v)}" for i, name, v in bad[:5])
        more = f" and {len(bad) - 5} more" if len(bad) > 5 else ""
        raise BlowUp(f"blow-up at t = 0 s: non-finite input: {shown}{more}; the starting state "
                     "must be finite (radius and mass > 0); not a time-step problem")


def list_pairs(system, state) -> tuple[np.ndarray, np.ndarray,
                                                            np.ndarray]:
    """(i, j, squared centre distance) of the neighbour list's pairs, minimum image in y when
    periodic, summed in the kernel's order (dx^2 + dy^2 + dz^2)."""
    nl = state.nl
    i = np.repeat(np.arange(state.n), np.diff(nl.start))
    j = nl.nbr
    d = state.pos[i] - state.pos[j]
    L = system.periodic_length
    if L > 0.0:
        d[:, 1] -= L * np.rint(d[:, 1] / L)
    return i, j, d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2]


def coincident_pair(system, state) -> tuple[int, int] | None:
    """The first pair of balls at one spot (zero centre distance: no contact normal, and the
    kernel's 1/d divides by zero), or None."""
    if not np.all(np.isfinite(state.pos)):
        return None
    i, j, d2 = list_pairs(system, state)
    hit = np.nonzero(d2 == 0.0)[0]
    if hit.size == 0:
        return None
    return int(i[hit[0]]), int(j[hit[0]])


def coincident_message(system, state, pair: tuple[int, int]) -> str:
    i, j = pair
    where = (f"blow-up at t = {state.time(system.dt):.6g} s: balls {i} and {j} are coincident "
             f"(both centres at {_vec(state.pos[i])} m): two balls on one spot have no contact "
             "normal")
    if state.step == 0:
        return f"{where}; the starting positions put them there; not a time-step problem"
    return f"{where}; they met head-on with no repulsion between them"


def check_overlaps_at_start(system, state, diag: np.ndarray) -> None:
    """BlowUp when the starting positions already break the overlap bound (two balls deep in
    each other, a ball behind a wall) or put a ball outside the tub: the first step would blow
    up, and not because of the time step.  The set-up force evaluation has measured them."""
    d = 2.0 * float(state.radius.max())
    bound = system.max_overlap
    c = int(np.argmax(diag[:, K.D_BALL_OVERLAP]))
    if diag[c, K.D_BALL_OVERLAP] > bound:
        i, j = int(diag[c, K.D_BALL_I]), int(diag[c, K.D_BALL_J])
        raise BlowUp(f"blow-up at t = 0 s: balls {i} and {j} overlap by "
                     f"{diag[c, K.D_BALL_OVERLAP] / d:.1%} of d at the start (bound "
                     f"{bound / d:.0%}): the starting positions overlap; not a time-step "
                     "problem")
    cw = int(np.argmax(diag[:, K.D_WALL_OVERLAP]))
    if diag[cw, K.D_WALL_OVERLAP] > bound:
        i, w = int(diag[cw, K.D_WALL_I]), int(diag[cw, K.D_WALL_W])
        delta = float(diag[cw, K.D_WALL_OVERLAP])
        r = float(state.radius[i])
        if delta >= r:
            raise BlowUp(f"blow-up at t = 0 s: ball {i} is behind {_wall_name(w, system)} at "
                         f"the start: its centre {_vec(state.pos[i])} m lies {(delta - r) * 1e3:.3g} mm "
                         "beyond the wall; the starting positions put it there; not a "
                         "time-step problem")
        raise BlowUp(f"blow-up at t = 0 s: ball {i} overlaps {_wall_name(w, system)} by "
                     f"{delta / d:.1%} of d at the start (bound {bound / d:.0%}): the starting "
                     "positions put it into the wall; not a time-step problem")
    lost = [int(x) for x in diag[:, K.D_LOST] if x >= 0]
    if lost:
        raise BlowUp(f"blow-up at t = 0 s: ball(s) {_ids(lost)} start outside the tub (ball "
                     f"{lost[0]} at {_vec(state.pos[lost[0]])} m); the starting positions put "
                     "them there; not a time-step problem")


def time_step_cause(system) -> tuple[bool, str]:
    """(is the time step a likely cause, words on it): only when it resolves the shortest
    contact time with fewer than STEPS_PER_CONTACT steps."""
    tc = system.notes.get("shortest_contact_time")
    if not tc or not math.isfinite(tc):
        return False, f"time step dt = {system.dt:.3g} s (contact time not known)"
    per = tc / system.dt
    words = (f"time step dt = {system.dt:.3g} s, {per:.1f} steps per shortest contact time "
             f"{tc:.3g} s")
    return per < STEPS_PER_CONTACT * (1.0 - 1e-9), words


def blowup_message(system, state, diag: np.ndarray) -> str:
    """One line: when, which balls, and the cause the state shows."""
    t = state.time(system.dt)
    d = 2.0 * float(state.radius.max())
    nan = [int(x) for x in diag[:, K.D_NAN] if x >= 0]
    lost = [int(x) for x in diag[:, K.D_LOST] if x >= 0]
    c = int(np.argmax(diag[:, K.D_BALL_OVERLAP]))
    cw = int(np.argmax(diag[:, K.D_WALL_OVERLAP]))
    dt_is_cause, dt_words = time_step_cause(system)
    too_coarse = (f"likely cause: {dt_words}, too large (at least {STEPS_PER_CONTACT:.0f} "
                  "needed)")
    finite = np.isfinite(state.vel).all(axis=1)
    vmax = float(np.sqrt((state.vel[finite] ** 2).sum(axis=1)).max()) if finite.any() else 0.0
    if nan:
        where = f"blow-up at t = {t:.6g} s: ball(s) {_ids(nan)} have non-finite position"
        if dt_is_cause:
            return f"{where}; {too_coarse}"
        return (f"{where}; not the time step ({dt_words}); the largest finite speed is "
                f"{vmax:.3g} m/s: look at the starting velocities and the materials' density "
                "and contact stiffness")
    if diag[c, K.D_BALL_OVERLAP] > system.max_overlap:
        i, j = int(diag[c, K.D_BALL_I]), int(diag[c, K.D_BALL_J])
        where = (f"blow-up at t = {t:.6g} s: balls {i} and {j} overlap by "
                 f"{diag[c, K.D_BALL_OVERLAP] / d:.1%} of d (bound {system.max_overlap / d:.0%})")
        if dt_is_cause:
            return f"{where}; {too_coarse}"
        v = float(np.linalg.norm(state.vel[i] - state.vel[j]))
        return (f"{where}; likely cause: contact stiffness k_n too low for the load or for "
                f"their relative speed {v:.3g} m/s ({dt_words}: enough)")
    if diag[cw, K.D_WALL_OVERLAP] > system.max_overlap:
        i, w = int(diag[cw, K.D_WALL_I]), int(diag[cw, K.D_WALL_W])
        where = (f"blow-up at t = {t:.6g} s: ball {i} overlaps {_wall_name(w, system)} by "
                 f"{diag[cw, K.D_WALL_OVERLAP] / d:.1%} of d (bound "
                 f"{system.max_overlap / d:.0%})")
        if dt_is_cause:
            return f"{where}; {too_coarse}"
        v = float(np.linalg.norm(state.vel[i]))
        return (f"{where}; likely cause: wall contact stiffness k_n too low for the load or "
                f"for the ball's speed {v:.3g} m/s ({dt_words}: enough)")
    where = (f"blow-up at t = {t:.6g} s: ball(s) {_ids(lost)} outside the tub (ball {lost[0]} "
             f"at {_vec(state.pos[lost[0]])} m)" if lost else
             f"blow-up at t = {t:.6g} s: no ball named by the kernel")
    if dt_is_cause:
        return f"{where}; {too_coarse}, so a fast ball passed through the wall"
    v = float(np.linalg.norm(state.vel[lost[0]])) if lost else vmax
    return (f"{where}; likely cause: wall contact stiffness too low for the ball's speed "
            f"{v:.3g} m/s, so it passed through the wall ({dt_words}: enough)")
