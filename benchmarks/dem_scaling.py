"""The DEM step's cost against the ball count and the thread count, its memory, and where a
step's time goes.

    python benchmarks/dem_scaling.py [--sizes quick,tub47,long] [--threads 1,2] [--steps 2128]
        [--repeats 2] [--warmup 2128] [--pass-steps 200] [--impacts]
        [--json runs/dem_scaling.json]

Sizes (and `tub47-periodic`, `long-periodic`, below): `quick` is tub47-quick (4 200 balls in a
19.05 mm slice), `tub47` the reference case (14 000 balls, 63.5 mm), `long` tub47 ten times
longer (`--set tub.length=0.635 --set fill.count=140000`).  Each (size, threads) runs in its own
process with NUMBA_NUM_THREADS set, from the case's settled bed, the bed a run vibrates: `quick`
and `tub47` from the fill cache (vibroflow.dem.fill.cache_dir; settled and cached there when
absent, as `vibroflow dem CASE` does), `long` from tub47's settled bed laid ten times end to end
along the tub (its contact histories zeroed: the copies touch at the nine seams where tub47's
end walls stood, so the bed there settles a little in the first steps; settling 140 000 balls
would take an hour here). `tub47-periodic` and `long-periodic` are the same two tubs with
periodic ends instead of end walls (`--set tub.periodic=true`), the long one tub47-periodic's
settled bed laid ten times along it: a periodic bed laid end to end has no seams, and without
end walls the two beds have the same physics a unit of length (the same contacts a ball over a
cycle), so their step times compare the code's cost alone; the long tubs' growth is read from
their own tub47. The tub vibrates for `--warmup` untimed steps (numba's cache load or
compilation, the first neighbour lists), then `--repeats` times `--steps` steps are timed (wall
and CPU), neighbour rebuilds included, in calls that leave the balls stored as the steps left
them (in space order from MEMORY_ORDER_FROM balls on), as `vibroflow dem` does between its rows;
with `--impacts`, recording and flushing every impact as `vibroflow dem` does (the rows dropped).
Then the passes of one step are timed apart, each `--pass-steps` times from the same saved
state, each its own parallel loop over the blocks: the pairs (step._pair_block, a step's first
loop), the gather (_gather_block), the walls (wall_pass.ball_walls), the second half kick with
the next step's first half kick and drift (step._kick_block, as the ball pass makes them), and
the step's second loop whole less that drift (step._ball_pass: gather, walls, second half kick;
a pass that drifted the balls 2 000 times under frozen forces would fling them against the
walls); and one neighbour-list rebuild (simulate.rebuild: cell binning, list, history transfer,
reverse order).

Printed per process: balls, median wall and CPU microseconds a step, nanoseconds per ball-step,
the megabytes the step's arrays hold (the balls', the neighbour list's, the contact rows', the
walls', the work arrays') beside the machine's last-level cache,
the mean ball-ball contact count over the timed steps (counted CONTACT_SAMPLES times a repeat)
with the nanoseconds per contact-step, the passes' shares, the process's peak resident memory
(ru_maxrss), numba's threading layer and GOMP_SPINCOUNT, and the sha256 of the balls'
positions, velocities and spins (by id) after the warm-up and the repeats; at the end, per
size, whether that state is the same bits on every thread count run (the DEM's promise: it
must be) and each thread count's throughput over one thread's, and the time per step against
the ball count and against the mean contact count relative to the run's first size, or for a
long tub to its own tub47 (1.0: the cost grows as the count).  On a shared machine compare the
rows of one run, and repeat under load.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SIZES = {"quick": ("tub47-quick", []), "tub47": ("tub47", []),
         "long": ("tub47", ["tub.length=0.635", "fill.count=140000"]),
         "tub47-periodic": ("tub47", ["tub.periodic=true"]),
         "long-periodic": ("tub47", ["tub.periodic=true", "tub.length=0.635",
                                     "fill.count=140000"])}
#: the long tubs, each laid from the settled bed of the size named here
LAID_FROM = {"long": "tub47", "long-periodic": "tub47-periodic"}
#: copies of that settled bed along the long tub
COPIES = 10
#: a whole cycle of tub47's vibration (47 Hz, dt 1e-5 s): the bed leaves the floor and lands
#: within a cycle, and its contact count changes tenfold, so a step's cost is a cycle's mean
CYCLE = 2128
WARMUP = CYCLE
#: the timed steps of a repeat go in this many calls, the ball-ball contacts counted after each:
#: their mean is the work a step does, which an instant's count misreads (it changes tenfold
#: within a cycle, and its phase differs between beds of different sizes)
CONTACT_SAMPLES = 16


def _settled(case: str, sets: list[str]):
    """The case's settled bed (dem_step_cost.settled_state: the fill cache, settled and cached
    when absent)."""
    from dem_step_cost import settled_state

    from vibroflow.dem import simulate as S
    from vibroflow.scenario.io import load_scenario

    scenario = load_scenario(case, sets)
    return settled_state(scenario, S.make_system(scenario))


def _bed(size: str, scenario, system):
    """The settled bed of a size (module docstring)."""
    import numpy as np

    from vibroflow.dem import simulate as S

    if size not in LAID_FROM:
        return _settled(*SIZES[size])
    base = _settled(*SIZES[LAID_FROM[size]])
    if base.nl.ids is not None:  # tub47's 14 000 balls are stored by id (memory_order)
        raise SystemExit(f"{LAID_FROM[size]}'s settled bed is not stored by id")
    length = scenario.tub.length / COPIES
    shift = np.zeros((COPIES, 1, 3))
    shift[:, 0, 1] = np.arange(COPIES) * length
    pos = (base.pos[None, :, :] + shift).reshape(-1, 3)
    tile = lambda a: np.tile(a, (COPIES, 1) if a.ndim == 2 else COPIES)  # noqa: E731
    rho = base.mass / (4.0 / 3.0 * np.pi * base.radius ** 3)
    return S.init_state(system, pos, tile(base.vel), tile(base.omg), tile(base.radius), tile(rho),
                        tile(base.mat))


def _drop(rows) -> None:
    """An impact sink that keeps nothing."""


def _megabytes(rec) -> float:
    """The MB (1e6 bytes) of the distinct arrays in a record (a NamedTuple of arrays and
    tuples of them)."""
    import numpy as np

    seen: dict = {}

    def walk(x):
        if isinstance(x, np.ndarray):
            seen[(x.__array_interface__["data"][0], x.nbytes)] = x.nbytes
        elif isinstance(x, tuple):
            for y in x:
                walk(y)

    walk(rec)
    return sum(seen.values()) / 1e6


def _l3_megabytes() -> float | None:
    """This machine's level-3 cache (MB; Linux's sysfs), or None where the system does not
    say."""
    for index in sorted(Path("/sys/devices/system/cpu/cpu0/cache").glob("index*")):
        try:
            if (index / "level").read_text().strip() != "3":
                continue
            size = (index / "size").read_text().strip()
        except OSError:
            continue
        unit = {"K": 1024, "M": 1024 ** 2}.get(size[-1:], 1)
        return int(size.rstrip("KM")) * unit / 1e6
    return None


def _base_size(size: str, sizes: list[str]) -> str:
    """The size a size's growth is read from: the size a long tub is laid from when the run
    has it, else the run's first size."""
    own = LAID_FROM.get(size)
    return own if own in sizes else sizes[0]


def worker(size: str, steps: int, repeats: int, warmup: int = WARMUP,
           pass_steps: int = 200, memory_order: bool | None = None,
           impacts: bool = False) -> dict:
    """Time the steps in this process (NUMBA_NUM_THREADS set by the caller)."""
    import numba
    import numpy as np

    from vibroflow.dem import simulate as S
    from vibroflow.dem import memory_order as M
    from vibroflow.dem import step as K
    from vibroflow.dem.contact_rows import pack, unpack
    from vibroflow.dem.records import pairs_of, slots_of
    from vibroflow.scenario.io import load_scenario

    case, sets = SIZES[size]
    scenario = load_scenario(case, sets)
    system = S.make_system(scenario)
    state = _bed(size, scenario, system)
    if state.n != scenario.fill.count:
        raise SystemExit(f"{size}: {state.n} balls, the scenario has {scenario.fill.count}")
    state.time_origin_step = state.step
    state.vibrating = True
    # the balls stay in the storage the steps leave, as `vibroflow dem` keeps them between its
    # calls (vibroflow.dem.run: keep_order), so that a call is not timed storing them by id
    # with `impacts`, every impact recorded and flushed as `vibroflow dem` records them, the
    # rows dropped (their writing is the output's, not the step's)
    record = dict(record_impacts=True, on_impacts=_drop, on_part_impacts=_drop) if impacts \
        else {}
    S.run_steps(system, state, warmup, memory_order=memory_order, keep_order=True, **record)
    wall, cpu, counted = [], [], []
    b0 = state.nl.builds
    cuts = np.linspace(0, steps, CONTACT_SAMPLES + 1).astype(np.int64)
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        for n in np.diff(cuts):
            S.run_steps(system, state, int(n), memory_order=memory_order, keep_order=True,
                        **record)
            counted.append(np.count_nonzero(state.nl.flag))
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    builds = state.nl.builds - b0
    # the state after the same steps at every thread count: bit for bit the same (by id)
    by_id = M.by_id(state)
    digest = hashlib.sha256(b"".join(
        np.ascontiguousarray(getattr(state, k) if by_id is None else getattr(state, k)[by_id])
        .tobytes() for k in ("pos", "vel", "omg"))).hexdigest()[:16]

    @numba.njit(parallel=True)
    def gather(balls, pairs, slots, nblock):
        for c in numba.prange(nblock):
            K._gather_block(c, balls, pairs, slots)

    @numba.njit(parallel=True)
    def walls(t, balls, pairs, w, params, work, prt, nblock):
        for c in numba.prange(nblock):
            K.ball_walls(c, t, 0.0, False, balls, pairs, w, params, work, prt)

    @numba.njit(parallel=True)
    def kick(balls, pairs, params, work, nblock):
        for c in numba.prange(nblock):
            K._kick_block(c, balls, pairs, params, work, True)

    buf = S._buf(system, state)
    pairs, slots = pairs_of(state.nl, K.NBLOCK), slots_of(state.nl)
    # what the step's passes hold, beside the last-level cache: the balls' arrays are swept by
    # every pass, the list by the pairs, the contact rows where there are contacts, the walls'
    # arrays where a ball is near a wall; the work's impact buffer only when impacts are made
    footprint = {"balls": _megabytes(buf.balls), "list": _megabytes(pairs),
                 "contact_rows": _megabytes(slots), "walls": _megabytes(buf.walls),
                 "work": _megabytes(buf.work)}
    t = state.time(system.dt)
    saved = {name: getattr(state, name).copy() for name in ("pos", "vel", "omg")}
    hist, flag, rflag = state.nl.hist.copy(), state.nl.flag.copy(), state.nl.rflag.copy()
    passes = {
        "pairs": lambda: K._pair_pass(t, 0.0, 0.0, False, buf.balls, pairs, slots,
                                      system.params, buf.work),
        "gather": lambda: gather(buf.balls, pairs, slots, K.NBLOCK),
        "walls": lambda: walls(t, buf.balls, pairs, buf.walls, system.params, buf.work,
                               buf.parts, K.NBLOCK),
        "kick_drift": lambda: kick(buf.balls, pairs, system.params, buf.work, K.NBLOCK),
        "ball_pass": lambda: K._ball_pass(t, 0.0, True, False, False, buf.balls, pairs, slots,
                                          buf.walls, system.params, buf.work, buf.parts),
    }
    profile = {}
    for name, fn in passes.items():
        # each pass from the same state (the kick and drift move the balls)
        state.pos[:], state.vel[:], state.omg[:] = saved["pos"], saved["vel"], saved["omg"]
        state.nl.hist[:], state.nl.flag[:], state.nl.rflag[:] = hist, flag, rflag
        pack(pairs, slots, buf.work)  # the contact rows, as step.advance makes them
        fn()
        t0 = time.perf_counter()
        for _ in range(pass_steps):
            fn()
        profile[name] = 1e6 * (time.perf_counter() - t0) / pass_steps
        unpack(pairs, slots)
    state.pos[:], state.vel[:], state.omg[:] = saved["pos"], saved["vel"], saved["omg"]
    state.nl.hist[:], state.nl.flag[:], state.nl.rflag[:] = hist, flag, rflag
    S.rebuild(system, state)
    t0 = time.perf_counter()
    S.rebuild(system, state)
    profile["rebuild_once"] = 1e6 * (time.perf_counter() - t0)
    profile["rebuild_per_step"] = profile["rebuild_once"] * builds / (repeats * steps)
    return {"size": size, "balls": state.n, "threads": numba.get_num_threads(),
            "threading_layer": numba.threading_layer(),
            "memory_order": bool(state.n >= M.MEMORY_ORDER_FROM if memory_order is None
                                 else memory_order),
            "gomp_spincount": os.environ.get("GOMP_SPINCOUNT"), "impacts": impacts,
            "steps": steps, "warmup": warmup, "state_sha256": digest, "wall_s": wall,
            "cpu_s": cpu, "builds": builds,
            "list_entries": int(state.nl.nbr.shape[0]),
            "contacts_at_end": int(np.count_nonzero(state.nl.flag)),
            "mean_contacts": float(np.mean(counted)),
            "profile_us": profile, "footprint_MB": footprint, "l3_MB": _l3_megabytes(),
            "max_rss_MB": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0}


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--sizes", default="quick,tub47,long")
    p.add_argument("--threads", default="1,2")
    p.add_argument("--steps", type=int, default=CYCLE, help="timed steps a repeat")
    p.add_argument("--repeats", type=int, default=2)
    p.add_argument("--pass-steps", type=int, default=200,
                   help="calls of each pass in the profile, from the state after the repeats")
    p.add_argument("--json", type=Path, default=ROOT / "runs" / "dem_scaling.json")
    p.add_argument("--warmup", type=int, default=WARMUP,
                   help="untimed steps before the timing (the same at every thread count)")
    p.add_argument("--memory-order", choices=("auto", "on", "off"), default="auto",
                   help="the balls sorted in space at rebuilds (vibroflow.dem.memory_order): "
                        "auto from MEMORY_ORDER_FROM balls on, as a run does")
    p.add_argument("--impacts", action="store_true",
                   help="record the impacts during the steps, as `vibroflow dem` does")
    p.add_argument("--worker", help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.worker:
        order = {"auto": None, "on": True, "off": False}[a.memory_order]
        print(json.dumps(worker(a.worker, a.steps, a.repeats, a.warmup, a.pass_steps, order,
                                a.impacts)))
        return
    sizes = a.sizes.split(",")
    unknown = [s for s in sizes if s not in SIZES]
    if unknown:
        p.exit(2, f"--sizes {unknown[0]!r}: not one of {', '.join(SIZES)}\n")
    rows = []
    for size in sizes:
        for threads in (int(x) for x in a.threads.split(",")):
            env = dict(os.environ, NUMBA_NUM_THREADS=str(threads))
            load0 = os.getloadavg()[0]
            out = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--worker",
                                  size, "--steps", str(a.steps), "--repeats", str(a.repeats),
                                  "--warmup", str(a.warmup), "--pass-steps", str(a.pass_steps),
                                  "--memory-order", a.memory_order]
                                 + (["--impacts"] if a.impacts else []),
                                 env=env, capture_output=True, text=True)
            if out.returncode != 0:
                raise SystemExit(f"{size} on {threads} threads failed:\n{out.stderr[-3000:]}")
            r = json.loads(out.stdout.strip().splitlines()[-1])
            r["load"] = (load0, os.getloadavg()[0])
            us = 1e6 * statistics.median(r["wall_s"]) / a.steps
            cpu = 1e6 * statistics.median(r["cpu_s"]) / a.steps
            r.update(median_us_per_step=us, median_cpu_us_per_step=cpu,
                     ns_per_ball_step=1e3 * us / r["balls"],
                     ns_per_contact_step=1e3 * us / r["mean_contacts"])
            prof = r["profile_us"]
            print(f"{size:6s} {r['balls']:7d} balls, {threads} thread(s): {us:9.1f} us/step wall "
                  f"({cpu:9.1f} CPU), {r['ns_per_ball_step']:6.1f} ns/ball-step, "
                  f"{r['builds']} builds, {r['mean_contacts']:.0f} contacts (mean; "
                  f"{r['mean_contacts'] / r['balls']:.2f} a ball, "
                  f"{r['ns_per_contact_step']:.1f} ns/contact-step), max RSS "
                  f"{r['max_rss_MB']:.0f} MB, {'sorted' if r['memory_order'] else 'by id'}, "
                  f"{r['threading_layer']} layer, GOMP_SPINCOUNT "
                  f"{r['gomp_spincount']} (load {r['load'][0]:.1f} -> {r['load'][1]:.1f})",
                  flush=True)
            print("        passes (us): " + ", ".join(f"{k} {v:.1f}" for k, v in prof.items()),
                  flush=True)
            l3 = f", L3 {r['l3_MB']:.0f}" if r["l3_MB"] else ""
            print("        arrays held (MB): " + ", ".join(
                f"{k} {v:.1f}" for k, v in r["footprint_MB"].items()) + l3, flush=True)
            print(f"        state after {r['warmup'] + a.repeats * a.steps} steps: sha256 "
                  f"{r['state_sha256']}", flush=True)
            rows.append(r)
            a.json.parent.mkdir(parents=True, exist_ok=True)
            a.json.write_text(json.dumps(rows, indent=1))
    for size in sizes:
        mine = [r for r in rows if r["size"] == size]
        same = len({r["state_sha256"] for r in mine}) == 1
        print(f"{size:6s} state on {', '.join(str(r['threads']) for r in mine)} thread(s): "
              + ("bit for bit the same" if same else "DIFFERS: " + ", ".join(
                  f"{r['threads']}: {r['state_sha256']}" for r in mine)))
        one = [r for r in mine if r["threads"] == 1]
        for r in mine:
            if one and r["threads"] > 1:
                r["speedup_over_one_thread"] = (one[0]["median_us_per_step"]
                                                / r["median_us_per_step"])
                print(f"{size:6s} {r['threads']:2d} threads: {r['speedup_over_one_thread']:.2f} x "
                      f"the one-thread throughput (efficiency "
                      f"{r['speedup_over_one_thread'] / r['threads']:.2f})")
    for r in rows:
        base = next(b for b in rows if b["threads"] == r["threads"]
                    and b["size"] == _base_size(r["size"], sizes))
        growth = r["median_us_per_step"] / base["median_us_per_step"]
        r["cost_growth_over_ball_growth"] = growth / (r["balls"] / base["balls"])
        r["cost_growth_over_contact_growth"] = growth / (r["mean_contacts"]
                                                         / base["mean_contacts"])
        print(f"{r['size']:6s} {r['threads']} thread(s): time per step grows "
              f"{r['cost_growth_over_ball_growth']:.2f} x the ball count's growth and "
              f"{r['cost_growth_over_contact_growth']:.2f} x the mean contact count's from "
              f"{base['size']}")
    a.json.parent.mkdir(parents=True, exist_ok=True)
    a.json.write_text(json.dumps(rows, indent=1))
    print(f"written {a.json}")


if __name__ == "__main__":
    main()
