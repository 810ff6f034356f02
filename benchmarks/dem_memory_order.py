"""Time per ball-step of the DEM with and without the space sort (vibroflow.dem.memory_order).

    python benchmarks/dem_memory_order.py [--sizes quick,tub47,long] [--threads 2] [--steps 400]
        [--repeats 3] [--every 1,8] [--no-impacts] [--json runs/dem_memory_order.json]

Sizes as benchmarks/dem_scaling.py: `quick` is tub47-quick (4 200 balls), `tub47` tub47
(14 000), `long` tub47 ten times longer (`--set tub.length=0.635 --set fill.count=140000`).
Each size runs in its own process with NUMBA_NUM_THREADS set: the balls are placed on the
closed-up fill lattice and fall into the vibrating tub for the warm-up steps; then, in the same
process on the same bed, calls of 100 steps (as `vibroflow dem` makes them, one a time-series
row; the balls stored back by id every third call, as for a snapshot every 266 steps in tub47's
window) are timed, alternating between the balls stored by id (`off`) and stored in space
order at every `every`-th rebuild (`sort/every`), `--repeats` rounds of `--steps` steps each,
impacts recorded as in `vibroflow dem`'s window unless `--no-impacts` (the rows in the order
of the balls by id, vibroflow.dem.impact_order).  Two beds: `as filled` (ids in the fill
lattice's order, already near space order) and `mixed` (the ids shuffled, as after a long run
has mixed the bed).  The numbers and the impact rows of the runs are the same with and without
the sort (tests/test_dem_memory_order.py); only the time differs.  Printed: wall and CPU
nanoseconds per ball-step (medians), and their ratio to `off`.
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

ROOT = Path(__file__).resolve().parent.parent
DENSE = ["fill.lattice_spacing=1.01", "fill.insert_above=0.0"]
SIZES = {"quick": ("tub47-quick", DENSE, 2500),
         "tub47": ("tub47", DENSE, 2000),
         "long": ("tub47", DENSE + ["tub.length=0.635", "fill.count=140000"], 1500)}
CALL = 100  # steps a run_steps call (run.series_every's default)
SNAPSHOT = 3  # calls between two reads of the state by id (tub47's 266 steps between snapshots)


def worker(size: str, steps: int, repeats: int, everies: list[int], impacts: bool) -> dict:
    import numpy as np

    from vibroflow.dem import fill as F
    from vibroflow.dem import memory_order as M
    from vibroflow.dem import simulate as S
    from vibroflow.scenario.io import load_scenario

    case, sets, warmup = SIZES[size]
    scenario = load_scenario(case, sets)
    system = S.make_system(scenario)
    state = F.fill_state(system, scenario)
    state.vibrating = True
    S.run_steps(system, state, warmup, memory_order=False)
    seen = [0]

    def rows_seen(imp) -> None:
        seen[0] += imp.shape[0]

    rows = []
    for bed in ("as filled", "mixed"):
        if bed == "mixed":
            # new ids at random: the storage by id is then scattered in space
            b = S._buf(system, state)
            S.store_by_id(system, state)
            M.store(state, b.work.diag,
                    np.random.default_rng(1).permutation(state.n).astype(np.int64))
            state.nl.ids = None
            b.order = None
        modes = [("off", None)] + [(f"sort/{e}", e) for e in everies]
        times = {m: ([], []) for m, _ in modes}
        for mode, every in modes:  # compile each path once, untimed
            if every is not None:
                M.SORT_EVERY = every
            S.run_steps(system, state, CALL, memory_order=every is not None,
                        record_impacts=True, on_impacts=rows_seen)
        S.store_by_id(system, state)
        for _ in range(repeats):
            for mode, every in modes:
                if every is not None:
                    M.SORT_EVERY = every
                t0, c0 = time.perf_counter(), time.process_time()
                for call in range(steps // CALL):
                    S.run_steps(system, state, CALL, memory_order=every is not None,
                                keep_order=True, record_impacts=impacts,
                                on_impacts=rows_seen, on_part_impacts=rows_seen)
                    if call % SNAPSHOT == SNAPSHOT - 1:
                        S.store_by_id(system, state)
                S.store_by_id(system, state)
                times[mode][0].append(time.perf_counter() - t0)
                times[mode][1].append(time.process_time() - c0)
        for mode, (wall, cpu) in times.items():
            rows.append({"size": size, "bed": bed, "mode": mode, "balls": state.n,
                         "ns_wall": 1e9 * statistics.median(wall) / (steps // CALL * CALL)
                         / state.n,
                         "ns_cpu": 1e9 * statistics.median(cpu) / (steps // CALL * CALL)
                         / state.n,
                         "contacts": int(np.count_nonzero(state.nl.flag))})
    return {"rows": rows}


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--sizes", default="quick,long")
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--steps", type=int, default=400)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--every", default="1,8")
    p.add_argument("--no-impacts", action="store_true", help="time the steps without impacts")
    p.add_argument("--json", type=Path, default=ROOT / "runs" / "dem_memory_order.json")
    p.add_argument("--worker", help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    everies = [int(x) for x in a.every.split(",")]
    if a.worker:
        print(json.dumps(worker(a.worker, a.steps, a.repeats, everies, not a.no_impacts)))
        return
    rows = []
    for size in a.sizes.split(","):
        env = dict(os.environ, NUMBA_NUM_THREADS=str(a.threads))
        load0 = os.getloadavg()[0]
        out = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--worker", size,
                              "--steps", str(a.steps), "--repeats", str(a.repeats),
                              "--every", a.every] + ["--no-impacts"] * a.no_impacts,
                             env=env, capture_output=True, text=True)
        if out.returncode != 0:
            raise SystemExit(f"{size} failed:\n{out.stderr[-3000:]}")
        got = json.loads(out.stdout.strip().splitlines()[-1])["rows"]
        base = {}
        for r in got:
            r["load"] = (load0, os.getloadavg()[0])
            b = base.setdefault((r["bed"]), r)
            print(f"{size:6s} {r['balls']:7d} balls, {a.threads} thread(s), {r['bed']:9s} "
                  f"{r['mode']:7s}: {r['ns_wall']:6.1f} ns/ball-step wall "
                  f"({r['ns_wall'] / b['ns_wall']:.2f} x off), {r['ns_cpu']:6.1f} CPU "
                  f"({r['ns_cpu'] / b['ns_cpu']:.2f} x off), {r['contacts']} contacts, "
                  f"load {r['load'][0]:.1f} -> {r['load'][1]:.1f}", flush=True)
        rows += got
    a.json.parent.mkdir(parents=True, exist_ok=True)
    a.json.write_text(json.dumps(rows, indent=1))
    print(f"written {a.json}")


if __name__ == "__main__":
    main()
