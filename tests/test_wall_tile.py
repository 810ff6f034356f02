"""The tub step's wall pass in tiles (vibroflow.dem.wall_pass: the wall contacts' law over a
tile, contact.contact_law in a loop LLVM vectorises across contacts) against the same pass
contact by contact (contact.contact_force, as with parts).

The known answer is IEEE arithmetic, as in tests/test_contact_tile.py: the same operations in
the same order for each contact, and each ball's force the same sum in the same order, so
every force, torque, history, flag, stored contact, impact row and diagnostic comes out equal
bit for bit.  On a bed of tub47-quick's balls thrown into the U wall, both partitions and two
plane walls through the bed, for every kind of law (linear and Hertz, each rolling model),
one kind a tile or several (the glass partitions' law of another rolling model), on contacts
old and new, sticking and sliding.  The assembly of the law's loop holds packed square roots
and divisions and no FMA.
"""
from __future__ import annotations

import re

import numba as nb
import numpy as np
import pytest

from vibroflow.dem import laws as L
from vibroflow.dem import simulate as S
from vibroflow.dem import step as K
from vibroflow.dem import wall_pass as W
from vibroflow.dem.fill import fill_state
from vibroflow.dem.records import Walls, pairs_of
from vibroflow.scenario.io import load_scenario

PLANES = 2


def _bed():
    """tub47-quick's bed, its balls shaken (pressed into the U wall and the partitions, random
    velocities and spins), with two plane walls through it: a slanted one moving harmonically
    and a level one."""
    sc = load_scenario("tub47-quick", ["fill.count=600"])
    system = S.make_system(sc)
    state = fill_state(system, sc)
    state.vibrating = True
    rng = np.random.default_rng(5)
    axis = np.array([0.0, 0.0, sc.tub.radius])  # the U's axis (tub frame at rest)
    state.pos[:] = axis + (state.pos - axis) * np.array([1.003, 1.0, 1.003])
    state.pos[:, 1] += rng.uniform(-3e-3, 3e-3, state.n)
    state.vel[:] = rng.uniform(-1.0, 1.0, state.vel.shape)
    state.omg[:] = rng.normal(0.0, 100.0, state.omg.shape)
    state.force[:] = rng.normal(0.0, 1.0, state.force.shape)
    state.torque[:] = rng.normal(0.0, 1e-3, state.torque.shape)
    lo, hi = state.pos[:, 2].min(), state.pos[:, 2].max()
    planes = np.zeros((PLANES, 14))
    tilt = np.array([0.3, 0.1, 1.0]) / np.linalg.norm([0.3, 0.1, 1.0])
    planes[0, :3] = (0.0, 0.0, lo + 0.3 * (hi - lo))
    planes[0, 3:6] = tilt
    planes[0, 9:14] = (1e-3, 0.0, 2e-3, 300.0, 0.4)
    planes[1, :3] = (0.0, 0.0, lo + 0.6 * (hi - lo))
    planes[1, 3:6] = (0.0, 0.0, -1.0)
    planes[1, 6:9] = (0.01, 0.0, 0.0)
    return system, state, planes


def _pass(system, state, planes, table, tiled, seed):
    """The wall pass of every block on copies of the state's arrays; returns them."""
    n = state.n
    nw = W.WALL_PLANE0 + PLANES
    rng = np.random.default_rng(seed)
    arrays = {
        "hist": np.zeros((n, nw, 6)), "flag": np.zeros((n, nw), np.uint8),
        "fn": np.zeros((n, nw)), "ft": np.zeros((n, nw)), "slide": np.zeros((n, nw), np.uint8),
        "point": np.zeros((n, nw, 3)), "force": np.zeros((n, nw, 3)), "arc": state.wall_arc.copy()}
    # old contacts: a history on a third of the slots, some of them apart now
    old = rng.random((n, nw)) < 1 / 3
    arrays["flag"][:] = old
    # of lengths over decades: contacts that stick and contacts that slide
    scale = 10.0 ** rng.uniform(-9.0, -3.0, (n, nw, 1))
    arrays["hist"][:] = rng.normal(0.0, 1.0, (n, nw, 6)) * scale * old[:, :, None]
    wrec = Walls(**arrays)
    b = S._buf(system, state)
    balls = b.balls._replace(force=state.force.copy(), torque=state.torque.copy())
    work = b.work._replace(imp_buf=np.zeros((K.NBLOCK, 4 * n, K.N_IMP_BUF)),
                           imp_count=np.zeros(K.NBLOCK, np.int64),
                           diag=np.zeros((K.NBLOCK, K.N_DIAG)) - 1.0,
                           tile=np.zeros_like(b.work.tile), tile_idx=np.zeros_like(b.work.tile_idx))
    work.diag[:, K.D_WALL_OVERLAP] = 0.0
    work.pose[:] = S._tub_pose(system, state)
    params = system.params._replace(table=table, planes=planes,
                                    wall_mat=np.array([1, 2, 2, 1, 2], np.int64))
    pairs = pairs_of(state.nl, K.NBLOCK)
    t = state.time(system.dt)
    for c in range(K.NBLOCK):
        W._ball_walls(c, t, system.dt, True, balls, pairs, wrec, params, work, b.parts, tiled)
    return (balls.force, balls.torque, *arrays.values(), work.imp_buf, work.imp_count,
            work.diag)


def _table(table, model, roll, glass_roll):
    t = table.copy()
    t[:, :, L.P_MODEL] = model
    t[:, :, L.P_ROLL] = roll
    t[:, 2, L.P_ROLL] = t[2, :, L.P_ROLL] = glass_roll
    if model == L.MODEL_HERTZ:  # steel-like, as tests/test_contact_tile.py's
        t[:, :, L.P_KN], t[:, :, L.P_KT], t[:, :, L.P_DAMP] = 1.5e11, 6.4e10, 0.3
    return t


@pytest.fixture(scope="module")
def bed():
    return _bed()


@pytest.mark.parametrize("model", [L.MODEL_LINEAR, L.MODEL_HERTZ])
def test_the_tiled_wall_pass_gives_the_scalar_passes_bits(bed, model):
    system, state, planes = bed
    rolls = (L.ROLL_NONE, L.ROLL_CDT, L.ROLL_EPSD, L.ROLL_CDT_LIGGGHTS)
    for roll in rolls:
        for glass_roll in (roll, rolls[(roll + 1) % 4]):  # one kind of law, or two
            table = _table(system.params.table, model, roll, glass_roll)
            ref = _pass(system, state, planes, table, False, roll)
            out = _pass(system, state, planes, table, True, roll)
            # every kind of wall touches, new and old contacts, sticking and sliding
            touching, slide = ref[4] != 0.0, ref[6]
            assert np.all(touching.sum(axis=0) > 3), touching.sum(axis=0)
            assert 0 < slide.sum() < touching.sum()
            assert ref[-2].sum() > 10
            for k, (a, b) in enumerate(zip(ref, out)):
                assert np.array_equal(a, b), (roll, glass_roll, k)


def test_the_wall_laws_loop_is_packed_and_has_no_fma():
    fn = nb.njit(error_model="numpy")(W._wall_law_tile.py_func)  # uncached: its assembly
    b = np.zeros(W.N_WALL_TILE * W.W_TILE)
    b[W.W_DELTA * W.W_TILE:(W.W_DELTA + 1) * W.W_TILE] = 1e-5
    fn(W.W_TILE, b, 1.0, 1.0, False, 1e-6)
    asm = fn.inspect_asm(fn.signatures[0])
    if "ymm" not in asm and "zmm" not in asm:
        pytest.skip("no AVX on this machine")
    assert re.search(r"vsqrtpd\s+%[yz]mm", asm) and re.search(r"vdivpd\s+%[yz]mm", asm)
    assert "vfmadd" not in asm and "vfmsub" not in asm and "vfnmadd" not in asm
