"""vibroflow's DEM against LIGGGHTS 3.8 on the same tub scenario (first version).

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

Results go to --out (default runs/dem_vs_liggghts/, git-ignored) as speed.json or
physics.json, with the runs' folders beside them.  Use a quiet machine: other processes on the
cores distort both timings.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import time
from pathlib import Path

from vibroflow.io import liggghts as LG


def load(case: str, overrides: list[str]):
    from vibroflow.scenario.io import load_scenario
    return load_scenario(case, overrides)


def _copy(s, **sections):
    """Scenario with fields of its sections replaced: _copy(s, run={"seed": 2})."""
    update = {name: getattr(s, name).model_copy(update=vals) for name, vals in sections.items()}
    return s.model_copy(update=update)


def _write_json(path: Path, data: dict) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(LG._json_safe(data), indent=2) + "\n")
    os.replace(tmp, path)


# ----------------------------------------------------------------------------------------------
# Speed

def speed_scenario(s, steps: int, settle: float):
    """The case with a short settle and `steps` vibration steps, no snapshots."""
    dt = s.run.dt
    return _copy(s, run={"duration": steps * dt, "average_last": 0.0},
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
            "threads": numba.get_num_threads(), "chunks": system.nchunk,
            "particle_steps_per_s": state.n * steps / wall if wall > 0 else math.nan}


def run_speed(args) -> dict:
    s = speed_scenario(load(args.case, args.set), args.steps, args.settle)
    out = Path(args.out)
    res = {"mode": "speed", "case": s.case, "steps": args.steps, "settle_s": args.settle,
           "machine": {"cpus": os.cpu_count(), "platform": platform.platform(),
                       "processor": platform.processor()}}
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
            print(f"  {code:9s} {r['particle_steps_per_s']:12.4g} particle-steps/s "
                  f"({r['n_particles']} x {r['steps']} steps in {r['wall_time_s']:.2f} s)")
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
    from vibroflow.analysis.bulk import read_csv
    return read_csv(folder / "bulk_velocity.csv", cell_size=s.analysis.cell_size)


def run_physics(args) -> dict:
    from vibroflow.analysis.compare import field_difference, fields_agree, strengths_agree

    base = load(args.case, args.set)
    out = Path(args.out) / f"physics-{base.case}"
    runs = {}
    for seed in args.seeds:
        s = _copy(base, run={"seed": seed})
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


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--case", default="tub47-quick", help="preset or scenario TOML")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="scenario override (repeatable)")
    ap.add_argument("--physics", action="store_true", help="full runs and field comparison")
    ap.add_argument("--steps", type=int, default=2000, help="vibration steps timed (speed)")
    ap.add_argument("--settle", type=float, default=0.1, help="settling time before the timed "
                    "vibration (s, speed mode)")
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2], help="fill seeds (physics)")
    ap.add_argument("--nprocs", type=int, default=2, help="LIGGGHTS MPI ranks")
    ap.add_argument("--timeout", type=float, default=None, help="per LIGGGHTS run (s)")
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent.parent / "runs"
                                         / "dem_vs_liggghts"))
    ap.add_argument("--reuse", action="store_true", help="physics: reuse finished runs in --out")
    ap.add_argument("--skip-liggghts", action="store_true")
    ap.add_argument("--skip-vibroflow", action="store_true")
    args = ap.parse_args(argv)
    if not args.skip_liggghts and LG.find_liggghts() is None:
        print("LIGGGHTS not found: apt-get install -y liggghts (or --skip-liggghts)",
              file=sys.stderr)
        return 2
    res = run_physics(args) if args.physics else run_speed(args)
    res["argv"] = sys.argv[1:] if argv is None else list(argv)
    path = Path(args.out) / ("physics.json" if args.physics else "speed.json")
    _write_json(path, res)
    print(f"results: {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
