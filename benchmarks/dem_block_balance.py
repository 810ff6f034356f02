"""How evenly the DEM step's blocks of balls share its work: the load balance of its two
parallel loops on T threads, measured on one.

    python benchmarks/dem_block_balance.py [--size tub47|quick|long] [--phases 8] [--reps 40]
        [--warmup 2128] [--json runs/dem_block_balance.json]

The step (vibroflow.dem.step) is two parallel loops over step.NBLOCK blocks of balls: the
pairs (_pair_block), then the ball pass (_gather_block, wall_pass.ball_walls, _kick_block).
numba's OpenMP layer gives thread t of T the blocks t NBLOCK/T to (t + 1) NBLOCK/T - 1 (its
scheduler cuts the loop into T equal ranges, `omp for` hands them out statically), so a loop
takes as long as its slowest thread's blocks.  This script times every block of both loops
alone, on one thread (`--reps` calls each, from the same state), at `--phases` phases of one
cycle of tub47's vibration after `--warmup` steps, and prints for T = 2, 4, 8, 16, 32 and 64:

- the static bound: sum of the blocks' times / (T x the slowest thread's sum), the parallel
  efficiency that the cut alone allows (memory bandwidth and the loops' wake-up come on top);
- the lanes' bound: the same for the step's schedule (vibroflow.dem.block_queue): each thread
  its own static share first, in order, then the blocks left in the next threads' shares,
  whenever it comes free.

and, per loop, a least-squares fit of a block's time on its balls, list entries, touching
entries (the law's work) and balls not clear of the tub's walls (the wall pass's work), across
every block and phase: the cost model of a cut by work.  No timing here depends on another
process's load as much as a whole step's does (each block's time is the minimum of its calls'
means over the phases' repeats), but on a shared machine repeat it.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(Path(__file__).resolve().parent))

THREADS = (2, 4, 8, 16, 32, 64)


def static_bound(times: np.ndarray, threads: int) -> float:
    """Efficiency sum(times) / (T max thread sum) of contiguous equal-count block ranges."""
    n = times.shape[0]
    edges = [(t * n) // threads for t in range(threads + 1)]
    sums = [times[edges[t]:edges[t + 1]].sum() for t in range(threads)]
    return float(times.sum() / (threads * max(sums)))


def lanes_bound(times: np.ndarray, threads: int) -> float:
    """Efficiency of the step's schedule (vibroflow.dem.block_queue): each thread takes the
    blocks of its own static share in order, then those left in the next lanes in turn (each
    from its lane's front), whenever it comes free."""
    n = times.shape[0]
    lanes = min(threads, n)
    head = [(t * n) // lanes for t in range(lanes)]
    end = [((t + 1) * n) // lanes for t in range(lanes)]
    free = np.zeros(lanes)
    done = np.zeros(lanes, bool)
    offset = [0] * lanes
    while not done.all():
        t = int(np.argmin(np.where(done, np.inf, free)))  # the thread that comes free first
        while offset[t] < lanes and head[(t + offset[t]) % lanes] >= end[(t + offset[t]) % lanes]:
            offset[t] += 1
        if offset[t] == lanes:
            done[t] = True
            continue
        r = (t + offset[t]) % lanes
        free[t] += times[head[r]]
        head[r] += 1
    return float(times.sum() / (threads * free.max()))


def _best_time(kernel, c: int, reps: int, t: float, *records) -> float:
    """Seconds a call of block c's pass: one call untimed, then the best of three means of
    `reps` calls."""
    kernel(c, 1, t, *records)
    best = np.inf
    for _ in range(3):
        t0 = time.perf_counter()
        kernel(c, reps, t, *records)
        best = min(best, (time.perf_counter() - t0) / reps)
    return best


def measure(size: str, phases: int, reps: int, warmup: int) -> dict:
    import numba

    from dem_scaling import CYCLE, SIZES, _bed
    from vibroflow.dem import simulate as S
    from vibroflow.dem import step as K
    from vibroflow.dem.contact_rows import pack, unpack
    from vibroflow.dem.records import pairs_of, slots_of
    from vibroflow.dem.wall_pass import clear_of_walls
    from vibroflow.scenario.io import load_scenario

    numba.set_num_threads(1)
    case, sets = SIZES[size]
    scenario = load_scenario(case, sets)
    system = S.make_system(scenario)
    state = _bed(size, scenario, system)
    state.time_origin_step = state.step
    state.vibrating = True
    S.run_steps(system, state, warmup)

    @numba.njit
    def pair_reps(c, reps, t, balls, pairs, slots, params, work):
        for _ in range(reps):
            K._pair_block(c, t, 0.0, 0.0, False, balls, pairs, slots, params, work)

    @numba.njit
    def ball_reps(c, reps, t, balls, pairs, slots, walls, params, work, prt):
        for _ in range(reps):
            K._gather_block(c, balls, pairs, slots)
            K.ball_walls(c, t, 0.0, False, balls, pairs, walls, params, work, prt)
            K._kick_block(c, balls, pairs, params, work, False)

    @numba.njit
    def near_walls(pos, radius, bounds, tub, pose, out):
        cth, sth = np.cos(pose[2]), np.sin(pose[2])
        for c in range(bounds.shape[0] - 1):
            for i in range(bounds[c], bounds[c + 1]):
                if not clear_of_walls(pos[i, 0], pos[i, 1], pos[i, 2], radius[i], tub, pose,
                                      cth, sth, True):
                    out[c] += 1

    nblock = K.NBLOCK
    rows = []
    per_phase = max(CYCLE // phases, 1)
    for ph in range(phases):
        S.run_steps(system, state, per_phase)
        buf = S._buf(system, state)
        pairs, slots = pairs_of(state.nl, nblock), slots_of(state.nl)
        S._forces_now(system, state)
        t = state.time(system.dt)
        buf.work.pose[:] = S._tub_pose(system, state)
        saved = {k: getattr(state, k).copy() for k in ("pos", "vel", "omg", "force", "torque")}
        hist, flag = state.nl.hist.copy(), state.nl.flag.copy()
        b = pairs.bounds
        balls_n = np.diff(b)
        entries = np.diff(pairs.start[b])
        touching = np.add.reduceat(flag.astype(np.int64), pairs.start[b[:-1]]) \
            if flag.shape[0] else np.zeros(nblock, np.int64)
        touching = np.where(entries > 0, touching, 0)
        near = np.zeros(nblock, np.int64)
        near_walls(state.pos, state.radius, b, system.params.tub, buf.work.pose, near)
        pair_t = np.empty(nblock)
        ball_t = np.empty(nblock)
        pack(pairs, slots, buf.work)  # the contact rows, as step.advance makes them
        for c in range(nblock):
            pair_t[c] = _best_time(pair_reps, c, reps, t, buf.balls, pairs, slots,
                                   system.params, buf.work)
            ball_t[c] = _best_time(ball_reps, c, reps, t, buf.balls, pairs, slots, buf.walls,
                                   system.params, buf.work, buf.parts)
        unpack(pairs, slots)
        for k, v in saved.items():
            getattr(state, k)[:] = v
        state.nl.hist[:], state.nl.flag[:] = hist, flag
        rows.append({"phase": ph, "step": int(state.step), "pair_us": (1e6 * pair_t).tolist(),
                     "ball_us": (1e6 * ball_t).tolist(), "balls": balls_n.tolist(),
                     "entries": entries.tolist(), "touching": touching.tolist(),
                     "near_walls": near.tolist()})
    return {"size": size, "balls": state.n, "nblock": nblock, "reps": reps, "phases": rows}


def report(r: dict) -> None:
    rows = r["phases"]
    print(f"{r['size']}: {r['balls']} balls, {r['nblock']} blocks, {len(rows)} phases of a cycle")
    header = "".join(f"{t:>9d}" for t in THREADS)
    for loop in ("pair", "ball"):
        print(f"  {loop} loop: efficiency bound on T threads (static share | lanes), "
              f"cycle mean\n      T:  {header}")
        st = np.array([[static_bound(np.array(ph[f'{loop}_us']), t) for t in THREADS]
                       for ph in rows])
        dy = np.array([[lanes_bound(np.array(ph[f'{loop}_us']), t) for t in THREADS]
                       for ph in rows])
        # the cycle's loop time: each phase's slowest thread, summed over the phases
        tot = np.array([sum(ph[f"{loop}_us"]) for ph in rows])
        cyc_st = np.array([tot.sum() / (tot / st[:, k]).sum() for k in range(len(THREADS))])
        cyc_dy = np.array([tot.sum() / (tot / dy[:, k]).sum() for k in range(len(THREADS))])
        print("  static:  " + "".join(f"{x:9.2f}" for x in cyc_st))
        print("  lanes:   " + "".join(f"{x:9.2f}" for x in cyc_dy))
        print(f"      one-thread loop time: {tot.mean():.0f} us (phases "
              f"{tot.min():.0f} - {tot.max():.0f})")
        X = np.concatenate([np.column_stack([ph["balls"], ph["entries"], ph["touching"],
                                             ph["near_walls"]]) for ph in rows]).astype(float)
        y = np.concatenate([ph[f"{loop}_us"] for ph in rows])
        coef, *_ = np.linalg.lstsq(X, y, rcond=None)
        resid = y - X @ coef
        print(f"      fit, ns each: ball {1e3 * coef[0]:.1f}, entry {1e3 * coef[1]:.1f}, "
              f"touching entry {1e3 * coef[2]:.1f}, ball near a wall {1e3 * coef[3]:.1f} "
              f"(rms residual {np.sqrt(np.mean(resid ** 2)):.2f} us of a mean "
              f"{y.mean():.2f} us a block)")


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--size", default="tub47", choices=("quick", "tub47", "long"))
    p.add_argument("--phases", type=int, default=8)
    p.add_argument("--reps", type=int, default=40)
    p.add_argument("--warmup", type=int, default=2128)
    p.add_argument("--json", type=Path, default=ROOT / "runs" / "dem_block_balance.json")
    a = p.parse_args(argv)
    r = measure(a.size, a.phases, a.reps, a.warmup)
    a.json.parent.mkdir(parents=True, exist_ok=True)
    a.json.write_text(json.dumps(r))
    report(r)


if __name__ == "__main__":
    main()
