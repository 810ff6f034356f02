"""The force assembly over a full neighbour list against the step's own, on the same beds.

    python benchmarks/dem_full_list.py [--sizes tub47-periodic,long-periodic] [--threads 1,2]
        [--phases 4] [--reps 20] [--warmup 2128] [--json runs/dem_full_list.json]

Issue 31 names two force assemblies whose numbers do not depend on the thread count: each
ball's force summed by the thread that owns the ball over a full neighbour list (each pair
evaluated from both sides), and the step's (vibroflow.dem.step: each pair of the half list
evaluated once, the force on the second ball written to the contact's row and gathered by its
owner).  This benchmark builds the first beside the second and measures both.

**The full list gives the same bits.**  Ball i's full entries are its half-list entries in their
order, then the entries where it is the second ball in the gather's order (the list's reverse
order), each with a history of its own: the half list's for the first, its negative for the
second.  The contact law is exactly antisymmetric in IEEE arithmetic when i and j trade places:
the branch vector, the relative velocity and the normal change sign exactly (a - b = -(b - a),
(-a)(-b) = ab, r_i w_i + r_j w_j = r_j w_j + r_i w_i), so the force from j's side is the exact
negative of the force from i's, the torque on i from j's side is the torque on j from i's, and
each side's history is the exact negative of the other's after every step.  Each ball sums its
weight, then its entries' forces in the order above: the terms and the order of the step's
pairs and gather, so the same bits.  The benchmark checks it at every state it times: forces
and torques against the step's bit for bit, histories as numbers (a zero history may be +0 on
one side and -0 on the other; tests/test_contact_antisymmetry.py).

**Measured**: the step's two loops over the blocks as a run makes them, against the full
list's: (A) the pair pass, then the ball pass (gather, walls, second half kick); (B) the full
list's pass (each ball's entries), then the ball pass without the gather.  Both from the same
state, alternated, `--reps` times each at each of `--phases` states one `CYCLE / phases` steps
apart over a cycle of vibration after `--warmup` untimed steps (the bed's contacts change tenfold
within a cycle); each loop's median, in microseconds.  The full list's build from the half list
(at each neighbour rebuild) is timed once.  Sizes as in benchmarks/dem_scaling.py; each
(size, threads) in its own process with NUMBA_NUM_THREADS set.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numba as nb
import numpy as np

from vibroflow.dem import step as K
from vibroflow.dem.block_queue import open_lanes, take
from vibroflow.dem.block_record import D_BALL_OVERLAP, keep_largest
from vibroflow.dem.contact import add_force_torque, normal_constants, put3
from vibroflow.dem.laws import P_ROLL, ROLL_EPSD
from vibroflow.dem.wall_pass import ball_walls

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(Path(__file__).resolve().parent))

T = K.TILE


@nb.njit(cache=True, parallel=True)
def full_list(start, nbr, hist, flag, rstart, rpos):
    """(fstart (N + 1,), fnbr (2M,) int32, fhist (2M, w), fflag (2M,) uint8): each ball's
    half-list entries, then the entries where it is the second ball in reverse order, with
    their histories (negated on the second side) and contact flags."""
    n = start.shape[0] - 1
    m = nbr.shape[0]
    rslot = np.empty(m, np.int64)
    for k in range(m):
        rslot[rpos[k]] = k
    first = np.empty(m, np.int32)
    for i in range(n):
        for k in range(start[i], start[i + 1]):
            first[rpos[k]] = i
    fstart = np.empty(n + 1, np.int64)
    fstart[0] = 0
    for i in range(n):
        fstart[i + 1] = fstart[i] + (start[i + 1] - start[i]) + (rstart[i + 1] - rstart[i])
    w = hist.shape[1]
    fnbr = np.empty(2 * m, np.int32)
    fhist = np.empty((2 * m, w))
    fflag = np.empty(2 * m, np.uint8)
    for i in nb.prange(n):
        f = fstart[i]
        for k in range(start[i], start[i + 1]):
            fnbr[f] = nbr[k]
            fflag[f] = flag[k]
            for a in range(w):
                fhist[f, a] = hist[k, a]
            f += 1
        for r in range(rstart[i], rstart[i + 1]):
            k = rslot[r]
            fnbr[f] = first[r]
            fflag[f] = flag[k]
            for a in range(w):
                fhist[f, a] = -hist[k, a]
            f += 1
    return fstart, fnbr, fhist, fflag


@nb.njit(cache=True)
def _full_block(c, dt_hist, periodic_length, balls, bounds, fstart, fnbr, fhist, fflag,
                params, work):
    """The full-list entries of the balls of block c: each ball's force its weight plus its
    entries' forces in entry order, its torque their torques on it; each entry's own history
    advanced.  The tiles, the law and the sums of step._pair_block, less its contact rows."""
    pos, vel, omg = balls.pos, balls.vel, balls.omg
    radius, mass, mat = balls.radius, balls.mass, balls.mat
    force, torque, gravity = balls.force, balls.torque, params.gravity
    table = params.table
    diag = work.diag
    b = work.tile[c]
    bi = work.tile_idx[c]
    lo, hi = bounds[c], bounds[c + 1]
    if lo >= hi:
        return
    nh = 3
    for a in range(table.shape[0]):
        for bb in range(table.shape[1]):
            if table[a, bb, P_ROLL] == ROLL_EPSD:
                nh = 6
    wrap = 0.25 * periodic_length if periodic_length > 0.0 else np.inf
    key_ri = key_mi = key_rj = key_mj = np.nan
    key_mat_i = key_mat_j = -1
    m_eff = r_eff = kn = damp = 0.0
    cur = lo
    sfx = mass[lo] * gravity[0]
    sfy = mass[lo] * gravity[1]
    sfz = mass[lo] * gravity[2]
    stx = 0.0
    sty = 0.0
    stz = 0.0
    i = lo
    k = fstart[lo]
    while i < hi:
        n = 0
        while i < hi and n < T:
            xi = pos[i, 0]
            yi = pos[i, 1]
            zi = pos[i, 2]
            ri = radius[i]
            kend = fstart[i + 1]
            while k < kend and n < T:
                ku = np.uint64(k)
                j = np.uint64(fnbr[ku])
                dx = xi - pos[j, 0]
                dy = yi - pos[j, 1]
                dz = zi - pos[j, 2]
                if abs(dy) > wrap:
                    dy -= periodic_length * np.rint(dy / periodic_length)
                rsum = ri + radius[j]
                d2 = dx * dx + dy * dy + dz * dz
                touch = np.int64(d2 < rsum * rsum)
                if fflag[ku] > touch:  # parted: the entry's history forgotten
                    fflag[ku] = 0
                    for a in range(nh):
                        fhist[ku, a] = 0.0
                nu = np.uint64(n)
                bi[np.uint64(K.I_K * T) + nu] = k
                bi[np.uint64(K.I_I * T) + nu] = i
                n += touch
                k += 1
            if k == kend:
                i += 1
        mat0_i = mat0_j = -1
        mixed = False
        for m in range(n):
            ku = np.uint64(bi[K.I_K * T + m])
            iu = np.uint64(bi[K.I_I * T + m])
            ju = np.uint64(fnbr[ku])
            bi[K.I_J * T + m] = np.int64(ju)
            dx = pos[iu, 0] - pos[ju, 0]
            dy = pos[iu, 1] - pos[ju, 1]
            dz = pos[iu, 2] - pos[ju, 2]
            if abs(dy) > wrap:
                dy -= periodic_length * np.rint(dy / periodic_length)
            rsum = radius[iu] + radius[ju]
            b[K.T_DX * T + m] = dx
            b[K.T_DY * T + m] = dy
            b[K.T_DZ * T + m] = dz
            b[K.T_D2 * T + m] = dx * dx + dy * dy + dz * dz
            b[K.T_RSUM * T + m] = rsum
            ri = radius[iu]
            mi = mass[iu]
            mat_i = mat[iu]
            rj = radius[ju]
            mj = mass[ju]
            mat_j = mat[ju]
            if not (ri == key_ri and mi == key_mi and mat_i == key_mat_i and rj == key_rj
                    and mj == key_mj and mat_j == key_mat_j):
                m_eff = mi * mj / (mi + mj)
                r_eff = ri * rj / (ri + rj)
                kn, damp = normal_constants(table[mat_i, mat_j], r_eff, m_eff)
                key_ri, key_mi, key_mat_i = ri, mi, mat_i
                key_rj, key_mj, key_mat_j = rj, mj, mat_j
            if m == 0:
                mat0_i, mat0_j = mat_i, mat_j
            elif mat_i != mat0_i or mat_j != mat0_j:
                mixed = True
            b[K.T_RI * T + m] = ri
            b[K.T_RJ * T + m] = rj
            b[K.T_DVX * T + m] = vel[iu, 0] - vel[ju, 0]
            b[K.T_DVY * T + m] = vel[iu, 1] - vel[ju, 1]
            b[K.T_DVZ * T + m] = vel[iu, 2] - vel[ju, 2]
            b[K.T_WIX * T + m] = omg[iu, 0]
            b[K.T_WIY * T + m] = omg[iu, 1]
            b[K.T_WIZ * T + m] = omg[iu, 2]
            b[K.T_WJX * T + m] = omg[ju, 0]
            b[K.T_WJY * T + m] = omg[ju, 1]
            b[K.T_WJZ * T + m] = omg[ju, 2]
            b[K.T_REFF * T + m] = r_eff
            b[K.T_KN * T + m] = kn
            b[K.T_DAMP * T + m] = damp
            for a in range(nh):
                b[(K.T_H0 + a) * T + m] = fhist[ku, a]
        if n == 0:
            continue
        if mixed:
            K._law_tile_mixed(n, b, bi, mat, table, dt_hist)
        else:
            K._law_tile(n, b, table[mat0_i, mat0_j], dt_hist)
        for m in range(n):
            ku = np.uint64(bi[K.I_K * T + m])
            ii = bi[K.I_I * T + m]
            jj = bi[K.I_J * T + m]
            while cur < ii:
                put3(force, cur, sfx, sfy, sfz)
                put3(torque, cur, stx, sty, stz)
                cur += 1
                sfx = mass[cur] * gravity[0]
                sfy = mass[cur] * gravity[1]
                sfz = mass[cur] * gravity[2]
                stx = 0.0
                sty = 0.0
                stz = 0.0
            fflag[ku] = 1
            for a in range(nh):
                fhist[ku, a] = b[(K.T_H0 + a) * T + m]
            sfx, sfy, sfz, stx, sty, stz = add_force_torque(
                sfx, sfy, sfz, stx, sty, stz, b[K.T_FX * T + m], b[K.T_FY * T + m],
                b[K.T_FZ * T + m], b[K.T_TIX * T + m], b[K.T_TIY * T + m], b[K.T_TIZ * T + m])
            keep_largest(diag, c, D_BALL_OVERLAP, b[K.T_DELTA * T + m], ii, jj)
    while True:
        put3(force, cur, sfx, sfy, sfz)
        put3(torque, cur, stx, sty, stz)
        cur += 1
        if cur >= hi:
            break
        sfx = mass[cur] * gravity[0]
        sfy = mass[cur] * gravity[1]
        sfz = mass[cur] * gravity[2]
        stx = 0.0
        sty = 0.0
        stz = 0.0


@nb.njit(cache=True, parallel=True)
def full_pass(dt_hist, periodic_length, balls, bounds, fstart, fnbr, fhist, fflag, params,
              work):
    """The full list's forces of every block, in the step's lanes."""
    queue = work.queue
    lanes = open_lanes(queue, work.diag.shape[0])
    for lane in nb.prange(lanes):
        c, s = take(queue, lane, lanes, 0)
        while c >= 0:
            _full_block(c, dt_hist, periodic_length, balls, bounds, fstart, fnbr, fhist, fflag,
                        params, work)
            c, s = take(queue, lane, lanes, s)


@nb.njit(cache=True, parallel=True)
def walls_kick_pass(t, dt_hist, balls, pairs, walls, params, work, prt):
    """The step's ball pass without the gather: walls, second half kick."""
    queue = work.queue
    lanes = open_lanes(queue, work.diag.shape[0])
    for lane in nb.prange(lanes):
        c, s = take(queue, lane, lanes, 0)
        while c >= 0:
            ball_walls(c, t, dt_hist, False, balls, pairs, walls, params, work, prt)
            K._kick_block(c, balls, pairs, params, work, False)
            c, s = take(queue, lane, lanes, s)


@nb.njit(cache=True, parallel=True)
def gather_only(balls, pairs, slots, nblock):
    """The step's gather of every block (the pairs' forces on their second balls)."""
    for c in nb.prange(nblock):
        K._gather_block(c, balls, pairs, slots)


def worker(size: str, phases: int, reps: int, warmup: int) -> dict:
    """Both assemblies at `phases` states of a cycle, in this process."""
    import numba
    from dem_scaling import CYCLE, SIZES, _bed

    from vibroflow.dem import simulate as S
    from vibroflow.dem.contact_rows import pack, unpack
    from vibroflow.dem.records import pairs_of, slots_of
    from vibroflow.dem.walls import TUB_LENGTH, TUB_PERIODIC, TUB_PRESENT
    from vibroflow.scenario.io import load_scenario

    case, sets = SIZES[size]
    scenario = load_scenario(case, sets)
    system = S.make_system(scenario)
    state = _bed(size, scenario, system)
    state.time_origin_step = state.step
    state.vibrating = True
    S.run_steps(system, state, warmup, keep_order=True)
    tub = system.params.tub
    plen = tub[TUB_LENGTH] if tub[TUB_PRESENT] > 0.0 and tub[TUB_PERIODIC] > 0.0 else 0.0
    dt = system.dt
    rows = []
    for ph in range(phases):
        if ph:
            S.run_steps(system, state, CYCLE // phases, keep_order=True)
        buf = S._buf(system, state)
        buf.work.pose[:] = S._tub_pose(system, state)
        pairs, slots = pairs_of(state.nl, K.NBLOCK), slots_of(state.nl)
        t = state.time(dt)
        saved = {k: getattr(state, k).copy() for k in ("vel", "omg")}
        hist0, flag0, rflag0 = state.nl.hist.copy(), state.nl.flag.copy(), state.nl.rflag.copy()
        wall_saved = {k: getattr(buf.walls, k).copy() for k in buf.walls._fields}
        lists = (state.nl.start, state.nl.nbr, hist0, flag0, state.nl.rstart, state.nl.rpos)
        full_list(*lists)  # compiled, or loaded from numba's cache, untimed
        t0 = time.perf_counter()
        fstart, fnbr, fhist0, fflag0 = full_list(*lists)
        build_us = 1e6 * (time.perf_counter() - t0)

        def restore():
            state.vel[:], state.omg[:] = saved["vel"], saved["omg"]
            state.nl.hist[:], state.nl.flag[:], state.nl.rflag[:] = hist0, flag0, rflag0
            for k, v in wall_saved.items():
                getattr(buf.walls, k)[:] = v

        # the same bits: one evaluation each from the same state, the histories advanced by dt
        restore()
        pack(pairs, slots, buf.work)
        K._pair_pass(t, dt, plen, False, buf.balls, pairs, slots, system.params, buf.work)
        gather_only(buf.balls, pairs, slots, K.NBLOCK)
        unpack(pairs, slots)
        f_a, t_a = state.force.copy(), state.torque.copy()
        h_a, g_a = state.nl.hist.copy(), state.nl.flag.copy()
        restore()
        fhist, fflag = fhist0.copy(), fflag0.copy()
        state.force[:] = np.nan
        full_pass(dt, plen, buf.balls, pairs.bounds, fstart, fnbr, fhist, fflag,
                  system.params, buf.work)
        _, _, h_b, g_b = full_list(state.nl.start, state.nl.nbr, h_a, g_a, state.nl.rstart,
                                   state.nl.rpos)
        same = (np.array_equal(f_a.view(np.uint64), state.force.view(np.uint64))
                and np.array_equal(t_a.view(np.uint64), state.torque.view(np.uint64))
                and np.array_equal(fflag, g_b)
                and np.array_equal(fhist, h_b))  # a zero history may be -0 on one side

        # the timing: each assembly's two loops, alternated, from the same state, after one
        # untimed round (each loop compiled or loaded from numba's cache)
        times = {"pairs": [], "ball_pass": [], "full": [], "walls_kick": []}
        for _ in range(reps + 1):
            restore()
            pack(pairs, slots, buf.work)
            t0 = time.perf_counter()
            K._pair_pass(t, dt, plen, False, buf.balls, pairs, slots, system.params, buf.work)
            t1 = time.perf_counter()
            K._ball_pass(t, dt, True, False, False, buf.balls, pairs, slots, buf.walls,
                         system.params, buf.work, buf.parts)
            t2 = time.perf_counter()
            unpack(pairs, slots)
            times["pairs"].append(t1 - t0)
            times["ball_pass"].append(t2 - t1)
            restore()
            fhist[:], fflag[:] = fhist0, fflag0
            t0 = time.perf_counter()
            full_pass(dt, plen, buf.balls, pairs.bounds, fstart, fnbr, fhist, fflag,
                      system.params, buf.work)
            t1 = time.perf_counter()
            walls_kick_pass(t, dt, buf.balls, pairs, buf.walls, system.params, buf.work,
                            buf.parts)
            t2 = time.perf_counter()
            times["full"].append(t1 - t0)
            times["walls_kick"].append(t2 - t1)
        restore()
        med = {k: 1e6 * statistics.median(v[1:]) for k, v in times.items()}
        rows.append({"phase": ph, "step": int(state.step), "same_bits": bool(same),
                     "contacts": int(np.count_nonzero(flag0)),
                     "entries": int(state.nl.nbr.shape[0]), "build_us": build_us,
                     **{k + "_us": v for k, v in med.items()},
                     "step_us": med["pairs"] + med["ball_pass"],
                     "full_step_us": med["full"] + med["walls_kick"]})
    return {"size": size, "balls": state.n, "threads": numba.get_num_threads(), "rows": rows}


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--sizes", default="tub47-periodic,long-periodic")
    p.add_argument("--threads", default="1,2")
    p.add_argument("--phases", type=int, default=4)
    p.add_argument("--reps", type=int, default=20)
    p.add_argument("--warmup", type=int, default=2128)
    p.add_argument("--json", type=Path, default=ROOT / "runs" / "dem_full_list.json")
    p.add_argument("--worker", help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.worker:
        print(json.dumps(worker(a.worker, a.phases, a.reps, a.warmup)))
        return
    from dem_scaling import SIZES

    sizes = a.sizes.split(",")
    unknown = [s for s in sizes if s not in SIZES]
    if unknown:
        p.exit(2, f"--sizes {unknown[0]!r}: not one of {', '.join(SIZES)}\n")
    if a.phases < 1 or a.reps < 1 or a.warmup < 0:
        p.exit(2, "--phases and --reps: at least 1; --warmup: at least 0\n")
    out = []
    for size in sizes:
        for threads in (int(x) for x in a.threads.split(",")):
            env = dict(os.environ, NUMBA_NUM_THREADS=str(threads))
            res = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--worker",
                                  size, "--phases", str(a.phases), "--reps", str(a.reps),
                                  "--warmup", str(a.warmup)],
                                 env=env, capture_output=True, text=True)
            if res.returncode != 0:
                raise SystemExit(f"{size} on {threads} threads failed:\n{res.stderr[-3000:]}")
            r = json.loads(res.stdout.strip().splitlines()[-1])
            out.append(r)
            for row in r["rows"]:
                print(f"{size} {r['balls']} balls, {threads} thread(s), step {row['step']}: "
                      f"{row['contacts']} contacts / {row['entries']} entries; step's "
                      f"pairs {row['pairs_us']:.0f} + ball pass {row['ball_pass_us']:.0f} = "
                      f"{row['step_us']:.0f} us; full list {row['full_us']:.0f} + walls and "
                      f"kick {row['walls_kick_us']:.0f} = {row['full_step_us']:.0f} us "
                      f"({row['full_step_us'] / row['step_us']:.2f} x); its build "
                      f"{row['build_us']:.0f} us; same bits: {row['same_bits']}", flush=True)
            mean = lambda k: statistics.mean(row[k] for row in r["rows"])  # noqa: E731
            print(f"{size} {threads} thread(s), mean over the phases: step "
                  f"{mean('step_us'):.0f} us, full list {mean('full_step_us'):.0f} us "
                  f"({mean('full_step_us') / mean('step_us'):.2f} x)", flush=True)
            a.json.parent.mkdir(parents=True, exist_ok=True)
            a.json.write_text(json.dumps(out, indent=1))
    print(f"written {a.json}")


if __name__ == "__main__":
    main()
