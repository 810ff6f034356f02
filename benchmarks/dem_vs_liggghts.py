"""vibroflow's DEM against LIGGGHTS 3.8 on the same tub scenario.

Speed (default):
    python benchmarks/dem_vs_liggghts.py [--case tub47-quick] [--steps 2000] [--nprocs 2]
Both codes fill and briefly settle the case (--settle seconds, default 0.1 s, tub at rest), then
vibrate it for --steps steps; only the vibration is timed: LIGGGHTS' own "Loop time" of its
vibration run (MPI, --nprocs ranks), vibroflow's wall time of `run_steps` (numba threads, after
JIT compilation).  Prints particle-steps per second (N x steps / wall s) of both and their ratio.
The beds are not identical (different fills, see docs/liggghts.md), nor fully settled; for a
speed comparison only the number of contacts matters, which is close.

Physics (--physics):
    python benchmarks/dem_vs_liggghts.py --physics [--case tub47-quick|tub47] [--seeds 1 2]
Full runs of the case in both codes with two fill seeds each (tub47-quick: about 15 min per
LIGGGHTS run on 2 ranks, tub47 about ten times more).  Prints the probe velocities and the
circulation strengths (+- batch-means standard errors) of every run, the field difference E
between the codes (LIGGGHTS against vibroflow, seed by seed) beside each code's seed-to-seed E,
and the tub47.md verdicts (strengths agree within max(10 %, 2 sigma); fields agree when
E(codes) <= 1.5 E_seed(vibroflow)).

Overlap (--overlap):
    python benchmarks/dem_vs_liggghts.py --overlap [--case tub47-quick] [--seeds 1]
tub47.md asks for the largest ball-ball overlap below 2 % of d; with the reference case's
k_n = 1e5 N/m, does another code get below it?  A full run of the case in both codes with the
first fill seed; prints each code's largest ball-ball and ball-wall overlap / d over every step
of the vibration and over the averaging window (vibroflow: its force kernel's running maximum,
summary.json's max_overlap_over_d; LIGGGHTS: `compute reduce max` over the contact computes'
`delta`, printed every step, see overlap_deck), the maxima over blocks of run.series_every
steps (their median and 99th percentile: the run's largest overlap is one extreme of a chaotic
trajectory), and, as a like-with-like check, the largest overlap at the snapshots computed the
same way from both codes' ball centres.

Results go to --out (default runs/dem_vs_liggghts/, git-ignored) as speed.json, physics.json
or overlap_seed<N>.json, with the runs' folders beside them.  Use a quiet machine: other
processes on the cores distort both timings.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

import bench
from vibroflow import liggghts as LG


# ----------------------------------------------------------------------------------------------
# Speed

def speed_scenario(s, steps: int, settle: float):
    """The case with a short settle and `steps` vibration steps, no snapshots."""
    dt = s.run.dt
    return bench.with_sections(s, run={"duration": steps * dt, "average_last": 0.0},
                 fill={"settle_time": settle, "max_settle_time": max(settle, dt)})


def liggghts_speed(s, work: Path, nprocs: int, timeout: float | None = None) -> dict:
    """Run the speed scenario in LIGGGHTS; the vibration's particle-steps/s from its log."""
    work.mkdir(parents=True, exist_ok=True)
    info = LG.export_deck(s, work, wall_contacts=False)
    t0 = time.perf_counter()
    LG.run_deck(work, nprocs=nprocs, timeout=timeout)
    total = time.perf_counter() - t0
    vib = LG.loop_times(work / "log.liggghts")[-1]
    if vib.steps != info.vibration_steps:
        raise RuntimeError(f"last LIGGGHTS run has {vib.steps} steps, expected "
                           f"{info.vibration_steps}")
    return {"code": "liggghts", "n_particles": vib.atoms, "steps": vib.steps,
            "wall_time_s": vib.seconds, "mpi_ranks": vib.procs,
            "particle_steps_per_s": vib.particle_steps_per_s, "total_wall_time_s": total,
            "binary": LG.find_liggghts()}


def vibroflow_speed(s, steps: int) -> dict:
    """Fill, settle (tub at rest) and time `steps` vibration steps of vibroflow's DEM.

    Uses the DEM's state API directly so that only the vibration is timed (run_dem's
    particle_steps_per_s counts the fill and settling too when the bed is not cached).
    """
    import numba

    from vibroflow.dem import fill as F
    from vibroflow.dem.simulate import make_system, run_steps
    from vibroflow.dem.step import ASSEMBLY

    system = make_system(s)
    state = F.fill_state(system, s)
    F.settle(system, state, s)           # compiles the kernels too
    state.time_origin_step = state.step
    state.vibrating = True
    run_steps(system, state, 1)          # the vibrating pose path, once
    t0 = time.perf_counter()
    run_steps(system, state, steps)
    wall = time.perf_counter() - t0
    return {"code": "vibroflow", "n_particles": state.n, "steps": steps, "wall_time_s": wall,
            "threads": numba.get_num_threads(), "assembly": ASSEMBLY,
            "gomp_spincount": os.environ.get("GOMP_SPINCOUNT"),
            "particle_steps_per_s": state.n * steps / wall if wall > 0 else math.nan}


def run_speed(args) -> dict:
    s = speed_scenario(bench.scenario(args.case, args.set), args.steps, args.settle)
    out = Path(args.out)
    res = {"mode": "speed", "case": s.case, "steps": args.steps, "settle_s": args.settle,
           "machine": bench.machine()}
    if not args.skip_liggghts:
        print(f"LIGGGHTS: {s.fill.count} balls, {args.steps} vibration steps on {args.nprocs} "
              "MPI ranks ...", flush=True)
        res["liggghts"] = liggghts_speed(s, out / "liggghts_speed", args.nprocs, args.timeout)
    if not args.skip_vibroflow:
        print(f"vibroflow: {s.fill.count} balls, {args.steps} vibration steps ...", flush=True)
        res["vibroflow"] = vibroflow_speed(s, args.steps)
    for code in ("liggghts", "vibroflow"):
        if code in res:
            r = res[code]
            spin = f", GOMP_SPINCOUNT {r['gomp_spincount']}" if code == "vibroflow" else ""
            print(f"  {code:9s} {r['particle_steps_per_s']:12.4g} particle-steps/s "
                  f"({r['n_particles']} x {r['steps']} steps in {r['wall_time_s']:.2f} s{spin})")
    if "liggghts" in res and "vibroflow" in res:
        res["ratio_vibroflow_over_liggghts"] = (res["vibroflow"]["particle_steps_per_s"]
                                                / res["liggghts"]["particle_steps_per_s"])
        print(f"  vibroflow / LIGGGHTS = {res['ratio_vibroflow_over_liggghts']:.3g}")
    return res


# ----------------------------------------------------------------------------------------------
# Physics

def liggghts_physics(s, work: Path, nprocs: int, timeout: float | None) -> Path:
    """Full LIGGGHTS run of a scenario; returns the folder with dem.h5 / summary.json."""
    deck = work / "deck"
    LG.export_deck(s, deck)
    LG.run_deck(deck, nprocs=nprocs, timeout=timeout)
    out = work / "result"
    LG.import_run(deck / "post", s, out)
    return out


def vibroflow_physics(s, work: Path) -> Path:
    from vibroflow.dem.run import run_dem
    run_dem(s, work, progress=False)
    return work


def _summary(folder: Path) -> dict:
    return json.loads((folder / "summary.json").read_text())


def _table(folder: Path, s):
    from vibroflow.measure.bulk import read_csv
    return read_csv(folder / "bulk_velocity.csv", cell_size=s.analysis.cell_size)


def run_physics(args) -> dict:
    from vibroflow.analysis.compare import field_difference, fields_agree, strengths_agree

    base = bench.scenario(args.case, args.set)
    out = Path(args.out) / f"physics-{base.case}"
    runs = {}
    for seed in args.seeds:
        s = bench.with_sections(base, run={"seed": seed})
        for code in ("vibroflow", "liggghts"):
            key = f"{code}-seed{seed}"
            folder = out / key
            done = folder / "result" if code == "liggghts" else folder
            if args.reuse and (done / "summary.json").is_file():
                runs[key] = done
                print(f"{key}: reusing {done}", flush=True)
                continue
            print(f"{key}: running ...", flush=True)
            t0 = time.perf_counter()
            runs[key] = (liggghts_physics(s, folder, args.nprocs, args.timeout)
                         if code == "liggghts" else vibroflow_physics(s, folder))
            print(f"{key}: done in {time.perf_counter() - t0:.0f} s", flush=True)
    res = {"mode": "physics", "case": base.case, "seeds": list(args.seeds), "runs": {}}
    min_phi = base.analysis.min_solid_fraction
    for key, folder in runs.items():
        sm = _summary(folder)
        res["runs"][key] = {"folder": str(folder), "probes": sm.get("probes"),
                            "circulation": sm.get("circulation"),
                            "wall_contacts": sm.get("wall_contacts"),
                            "particle_steps_per_s": sm.get("particle_steps_per_s")}
    print(f"\n{base.case}: probes (bulk velocity in the tub frame, m/s, +- stderr)")
    for key, r in res["runs"].items():
        parts = []
        for name, p in (r["probes"] or {}).items():
            if p.get("vx") is None:
                parts.append(f"{name} --")
            else:
                parts.append(f"{name} ({p['vx']:+.4f}+-{p['vx_stderr'] or 0:.4f}, "
                             f"{p['vz']:+.4f}+-{p['vz_stderr'] or 0:.4f})")
        print(f"  {key:20s} " + "  ".join(parts))
    print("circulation strength (m^2/s)")
    for key, r in res["runs"].items():
        c = r["circulation"] or {}
        print(f"  {key:20s} {c.get('strength') or math.nan:.4e} +- "
              f"{c.get('strength_stderr') or math.nan:.1e}  {c.get('sense')}")
    tables = {key: _table(Path(r["folder"]), base) for key, r in res["runs"].items()}
    E = {}
    seeds = list(args.seeds)
    if len(seeds) >= 2:
        a, b = seeds[0], seeds[1]
        for code in ("vibroflow", "liggghts"):
            E[f"seed_{code}"] = field_difference(tables[f"{code}-seed{b}"],
                                                 tables[f"{code}-seed{a}"], min_phi)
    for seed in seeds:
        E[f"codes_seed{seed}"] = field_difference(tables[f"liggghts-seed{seed}"],
                                                  tables[f"vibroflow-seed{seed}"], min_phi)
    res["E"] = E
    print("field difference E (reference: vibroflow; seed-to-seed: second seed vs first)")
    for k, v in E.items():
        print(f"  {k:20s} {v:.3f}")
    verdict = {}
    if "seed_vibroflow" in E:
        verdict["fields_agree"] = {f"seed{sd}": fields_agree(E[f"codes_seed{sd}"],
                                                             E["seed_vibroflow"])
                                   for sd in seeds}
    verdict["strengths_agree"] = {}
    for sd in seeds:
        cl = res["runs"][f"liggghts-seed{sd}"]["circulation"] or {}
        cv = res["runs"][f"vibroflow-seed{sd}"]["circulation"] or {}
        if cl.get("strength") is not None and cv.get("strength") is not None:
            verdict["strengths_agree"][f"seed{sd}"] = strengths_agree(
                cl["strength"], cl.get("strength_stderr") or math.nan, cv["strength"],
                cv.get("strength_stderr") or math.nan, cl.get("sense"), cv.get("sense"))
    res["verdict"] = verdict
    print(f"verdict: {verdict}")
    return res


# ----------------------------------------------------------------------------------------------
# Overlap (tub47.md: is "the largest ball-ball overlap below 2 % of d" reachable at k_n = 1e5?)

#: per-step record of the largest overlaps that the --overlap deck adds (in post/)
OVERLAP_FILE = "overlap.txt"
# the exported deck's contact computes, and what --overlap makes of them: `delta` (the overlap,
# r_i + r_j - |x_i - x_j| for a pair, r - |x - contact point| at a wall, m) appended as the last
# column, so the snapshot dumps (columns 1-6 and 1-9) are unchanged
_PAIR_COMPUTE = "compute pairc all pair/gran/local id force"
_WALL_COMPUTE = "compute wallc all wall/gran/local id force_normal force_tangential"
_PAIR_DELTA_COLUMN = 7      # id (3) + force (3) + delta
_WALL_DELTA_COLUMN = 10     # id (3) + force_normal (3) + force_tangential (3) + delta


def overlap_deck(s, deck: Path) -> "LG.DeckInfo":
    """The exported deck, plus the largest ball-ball and ball-wall overlap of every vibration
    step written to post/overlap.txt.

    vibroflow's `max_overlap_over_d` is the maximum over every step of the vibration (its force
    kernel keeps a running maximum between the series rows), so LIGGGHTS must be asked at every
    step too, not at the snapshots: the largest overlap lasts a few steps of a 0.2 ms contact
    and falls between snapshots 2.7 ms apart.  LIGGGHTS allows one pair/gran/local compute per
    pair style, so the deck's own computes get the `delta` column, and a `compute reduce max`
    over it (local data, combined over the MPI ranks by MPI_MAX) is printed every step by
    `fix print`.  The reduce invokes the local computes once a step, which re-evaluates the
    contacts without updating their histories, so the trajectory is the plain deck's (checked:
    tub47-quick's balls agree bit for bit after 10 000 vibration steps), and the step's
    record equals the overlap computed from the dumped centres at the snapshot steps.
    """
    info = LG.export_deck(s, deck)
    text = info.deck.read_text()
    for old in (_PAIR_COMPUTE, _WALL_COMPUTE):
        if text.count(old + "\n") != 1:
            raise RuntimeError(f"{info.deck}: expected the line {old!r} once (has "
                               "vibroflow.liggghts.export_deck changed?)")
    text = text.replace(_PAIR_COMPUTE + "\n", _PAIR_COMPUTE + " delta\n")
    text = text.replace(_WALL_COMPUTE + "\n", _WALL_COMPUTE + " delta\n")
    run_line = f"\nrun {info.vibration_steps}\n"
    at = text.rfind(run_line)
    if at < 0:
        raise RuntimeError(f"{info.deck}: no 'run {info.vibration_steps}' (the vibration)")
    lines = [
        "",
        "# ---- largest overlaps (m) every vibration step (benchmarks/dem_vs_liggghts.py "
        "--overlap)",
        f"compute ovball all reduce max c_pairc[{_PAIR_DELTA_COLUMN}]",
        f"compute ovwall all reduce max c_wallc[{_WALL_DELTA_COLUMN}]",
        "variable ovb equal c_ovball",
        "variable ovw equal c_ovwall",
        f'fix ovprint all print 1 "${{tvib}} ${{ovb}} ${{ovw}}" file {LG.POST_DIR}/'
        f'{OVERLAP_FILE} screen no title "# t_vibration_s max_ball_ball_overlap_m '
        'max_ball_wall_overlap_m"',
    ]
    text = text[:at] + "\n".join(lines) + text[at:]
    info.deck.write_text(text)
    return info


def _block_max(values: np.ndarray, block: int) -> np.ndarray:
    """Maxima over consecutive blocks of `block` entries (the last block may be short)."""
    nb = -(-values.size // block)
    pad = np.full(nb * block, -np.inf)
    pad[:values.size] = values
    return pad.reshape(nb, block).max(axis=1)


def _overlap_figures(t: np.ndarray, ob: np.ndarray, ow: np.ndarray, s, d: float,
                     block: int) -> dict:
    """Largest overlaps / d of a record: over the whole vibration, over the averaging window,
    when the largest happened, and the median and 99th percentile of the maxima over blocks of
    `block` steps (run.series_every): the largest overlap is one extreme of a chaotic run, the
    block maxima say whether two runs differ by more than their scatter."""
    in_window = t >= s.run.duration - s.run.average_last - 1e-12
    k = int(np.argmax(ob))
    blocks = _block_max(ob, block) / d
    return {"records": int(t.size), "first_time_s": float(t[0]), "last_time_s": float(t[-1]),
            "max_ball_over_d": float(ob.max() / d), "time_of_max_ball_s": float(t[k]),
            "max_wall_over_d": float(ow.max() / d),
            "max_ball_over_d_window": float(ob[in_window].max() / d),
            "max_wall_over_d_window": float(ow[in_window].max() / d),
            "block_steps": block, "block_max_ball_over_d_median": float(np.median(blocks)),
            "block_max_ball_over_d_p99": float(np.percentile(blocks, 99.0))}


def _snapshot_max_overlap(positions, radius: np.ndarray) -> np.ndarray:
    """Largest ball-ball overlap (m) at each snapshot from the ball centres alone (KD-tree over
    pairs closer than 2 r_max): the measure both codes' snapshots allow, for a like-with-like
    check of the per-step figures at the same instants (positions: iterable of (N, 3))."""
    from scipy.spatial import cKDTree
    out = []
    rmax = float(radius.max())
    for x in positions:
        x = np.asarray(x, dtype=float)
        pairs = cKDTree(x).query_pairs(2.0 * rmax, output_type="ndarray")
        if pairs.size == 0:
            out.append(0.0)
            continue
        gap = np.linalg.norm(x[pairs[:, 0]] - x[pairs[:, 1]], axis=1)
        out.append(float(np.max(radius[pairs[:, 0]] + radius[pairs[:, 1]] - gap)))
    return np.asarray(out)


def vibroflow_overlap(s, work: Path, reuse: bool) -> dict:
    """vibroflow's run of the scenario: its per-step maxima (dem.h5 /series, each row the
    maximum since the previous row, run.series_every steps) and the snapshots' maxima."""
    import h5py
    if not (reuse and (work / "summary.json").is_file()):
        t0 = time.perf_counter()
        vibroflow_physics(s, work)
        wall = time.perf_counter() - t0
    else:
        wall = None
    sm = _summary(work)
    with h5py.File(work / "dem.h5", "r") as f:
        t = f["series/time"][()]
        ob = f["series/max_overlap_ball"][()]
        ow = f["series/max_overlap_wall"][()]
        radius = f["particles/radius"][()]
        snap_t = f["snapshots/time"][()]
        snap = _snapshot_max_overlap((f["snapshots/position"][k]
                                      for k in range(snap_t.size)), radius)
    # the first row (t = 0) is the empty maximum of the settled bed's reset
    t, ob, ow = t[1:], ob[1:], ow[1:]
    d = 2.0 * float(radius.max())
    res = _overlap_figures(t, ob, ow, s, d, 1)
    res["block_steps"] = s.run.series_every
    res.update(how="every step: the force kernel's running maximum, one row per "
               f"{s.run.series_every} steps (dem.h5 /series)",
               summary_max_overlap_over_d=sm.get("max_overlap_over_d"),
               summary_max_wall_overlap_over_d=sm.get("max_wall_overlap_over_d"),
               snapshots=int(snap_t.size), snapshot_max_ball_over_d=float(snap.max() / d)
               if snap.size else None,
               wall_time_s=wall, code_wall_time_s=sm.get("wall_time_s"), folder=str(work))
    return res


def liggghts_overlap(s, work: Path, nprocs: int, timeout: float | None, reuse: bool) -> dict:
    """LIGGGHTS' run of the scenario with the per-step overlap record (overlap_deck), and the
    maxima at the snapshots (post/balls.dump, the same vibration steps as vibroflow's)."""
    deck = work / "deck"
    post = deck / LG.POST_DIR
    record = post / OVERLAP_FILE
    wall = None
    if not (reuse and record.is_file() and (post / LG.BALL_DUMP).is_file()
            and "vibration of" in (deck / "screen.txt").read_text(errors="replace")):
        overlap_deck(s, deck)
        t0 = time.perf_counter()
        LG.run_deck(deck, nprocs=nprocs, timeout=timeout)
        wall = time.perf_counter() - t0
    data = np.loadtxt(record, comments="#", ndmin=2)
    t, ob, ow = data[:, 0], data[:, 1], data[:, 2]
    # a step without any contact of a kind reduces to -1e20 (LIGGGHTS' empty maximum)
    ob, ow = np.maximum(ob, 0.0), np.maximum(ow, 0.0)
    d = s.fill.diameter
    res = _overlap_figures(t, ob, ow, s, d, s.run.series_every)
    snaps, radius = [], None
    for _, cols, arr in LG.iter_dump(post / LG.BALL_DUMP):
        ix = [cols.index(c) for c in ("x", "y", "z")]
        radius = arr[:, cols.index("radius")]
        snaps.append(arr[:, ix])
    snap = _snapshot_max_overlap(snaps, radius) if snaps else np.zeros(0)
    vib = LG.loop_times(deck / "log.liggghts")
    res.update(how="every step: compute reduce max over pair/gran/local (wall/gran/local) "
               f"delta, printed each step (post/{OVERLAP_FILE})",
               snapshots=len(snaps),
               snapshot_max_ball_over_d=float(snap.max() / d) if snap.size else None,
               wall_time_s=wall, vibration_loop_time_s=vib[-1].seconds if vib else None,
               mpi_ranks=nprocs, folder=str(deck))
    return res


def run_overlap(args) -> dict:
    base = bench.scenario(args.case, args.set)
    seed = args.seeds[0]
    s = bench.with_sections(base, run={"seed": seed})
    out = Path(args.out) / f"overlap-{s.case}-seed{seed}"
    res = {"mode": "overlap", "case": s.case, "seed": seed, "duration_s": s.run.duration,
           "window_s": s.run.average_last, "dt_s": s.run.dt, "d_m": s.fill.diameter,
           "runs": {}}
    for code in ("vibroflow", "liggghts"):
        if getattr(args, f"skip_{code}"):
            continue
        print(f"{code}: {s.fill.count} balls, {s.run.duration} s of vibration, seed {seed} ...",
              flush=True)
        res["runs"][code] = (vibroflow_overlap(s, out / code, args.reuse) if code == "vibroflow"
                             else liggghts_overlap(s, out / code, args.nprocs, args.timeout,
                                                   args.reuse))
        w = res["runs"][code]["wall_time_s"]
        print(f"{code}: done" + (f" in {w:.0f} s" if w is not None else " (reused)"),
              flush=True)
    print(f"\n{s.case}, seed {seed}: largest overlap / d over {s.run.duration} s of vibration "
          f"(window: the last {s.run.average_last} s)")
    for code, r in res["runs"].items():
        print(f"  {code:9s} ball-ball {r['max_ball_over_d']:.4%} (t = "
              f"{r['time_of_max_ball_s']:.4f} s; window {r['max_ball_over_d_window']:.4%})   "
              f"ball-wall {r['max_wall_over_d']:.4%} (window {r['max_wall_over_d_window']:.4%})")
        print(f"  {'':9s} maxima over {r['block_steps']}-step blocks: median "
              f"{r['block_max_ball_over_d_median']:.4%}, 99th percentile "
              f"{r['block_max_ball_over_d_p99']:.4%}; at the {r['snapshots']} snapshots "
              f"{(r['snapshot_max_ball_over_d'] or math.nan):.4%}")
        print(f"  {'':9s} ({r['how']})")
    return res


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--case", default="tub47-quick", help="preset or scenario TOML")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="scenario override (repeatable)")
    ap.add_argument("--physics", action="store_true", help="full runs and field comparison")
    ap.add_argument("--overlap", action="store_true", help="full runs; the largest ball-ball "
                    "and ball-wall overlap / d of each code (tub47.md)")
    ap.add_argument("--steps", type=int, default=2000, help="vibration steps timed (speed)")
    ap.add_argument("--settle", type=float, default=0.1, help="settling time before the timed "
                    "vibration (s, speed mode)")
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2], help="fill seeds (physics; "
                    "overlap: the first)")
    ap.add_argument("--nprocs", type=int, default=2, help="LIGGGHTS MPI ranks")
    ap.add_argument("--timeout", type=float, default=None, help="per LIGGGHTS run (s)")
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent.parent / "runs"
                                         / "dem_vs_liggghts"))
    ap.add_argument("--reuse", action="store_true", help="physics, overlap: reuse finished runs "
                    "in --out")
    ap.add_argument("--skip-liggghts", action="store_true")
    ap.add_argument("--skip-vibroflow", action="store_true")
    args = ap.parse_args(argv)
    if not args.skip_liggghts and LG.find_liggghts() is None:
        print("LIGGGHTS not found: apt-get install -y liggghts (or --skip-liggghts)",
              file=sys.stderr)
        return 2
    if args.physics and args.overlap:
        print("--physics and --overlap: choose one", file=sys.stderr)
        return 2
    mode = "overlap" if args.overlap else "physics" if args.physics else "speed"
    res = {"overlap": run_overlap, "physics": run_physics, "speed": run_speed}[mode](args)
    res["argv"] = sys.argv[1:] if argv is None else list(argv)
    # an overlap run is one fill seed's: its file says which, so seeds do not overwrite
    name = f"overlap_seed{args.seeds[0]}" if mode == "overlap" else mode
    path = Path(args.out) / f"{name}.json"
    bench.write_json(path, res)
    print(f"results: {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
