"""Cost of the DEM's compiled step on a case's settled bed, in this checkout and in a peer
checkout of vibroflow, on a given number of threads, the same machine, the same hour.

    python benchmarks/dem_step_cost.py [--peer DIR] [--case tub47-quick] [--steps 300]
        [--repeats 7] [--rounds 2] [--threads 1] [--set KEY=VALUE] [--peer-set KEY=VALUE]
        [--json PATH]

Each (checkout, round) runs in its own process, with NUMBA_NUM_THREADS=--threads (1 by
default), the case's scenario with the --set overrides (and, for the peer, --peer-set too: e.g.
run.force_chunks=64 for a vibroflow whose DEM sums per-chunk buffers), the checkout first on
the path (PYTHONPATH) and its own interpreter (DIR/.venv/bin/python when there is one, else
this one).  The process loads the case's settled bed from the fill cache
(vibroflow.dem.fill.cache_dir; settled and cached there when absent, as `vibroflow dem CASE`
does), starts the vibration as a run does, makes one untimed call (numba's cache load or
compilation), then times `--repeats` calls of vibroflow.dem.simulate.run_steps of `--steps`
vibration steps, each from the same settled bed: the compiled step with its neighbour-list
rebuilds, as a run pays it.  The rounds alternate the checkouts and their order (A B, B A,
A B ...), so a change of the machine's load, and the cost of going first, fall on both.

Printed per checkout: balls, the median wall time and CPU time of a step (microseconds) over
every repeat of every round with the fastest and slowest, nanoseconds per ball-step, the
neighbour builds of a repeat, and the ratios of the medians (this / peer: <= 1 means the step
costs no more here); the 1-minute load average before and after each process.  On a shared
machine the CPU time (the process's own; on one thread) is the figure to compare: the wall time
also counts the time the process waited for a core.  Both checkouts must give the same kinetic
energy after the steps (printed): the step is the same computation.
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


def settled_state(scenario, system):
    """The case's settled bed at the start of its vibration, as vibroflow.dem.run starts it (the
    fill cache; settled and cached there when absent).  benchmarks/dem_scaling.py uses it too."""
    # vibroflow is imported in the worker only: each checkout's own package (PYTHONPATH)
    from vibroflow.dem import fill as F
    from vibroflow.dem.output import load_state_file, save_state_file

    try:  # the key of this checkout, or of a peer whose DEM had force chunks
        key = F.fill_cache_key(scenario)
    except TypeError:
        key = F.fill_cache_key(scenario, system.nchunk)
    path = F.cache_dir() / "fills" / f"{key}.h5"
    if not path.exists():
        state = F.fill_state(system, scenario)
        info = F.settle(system, state, scenario)
        path.parent.mkdir(parents=True, exist_ok=True)
        save_state_file(path, state, {"settle_info": json.dumps(info)})
    state, _attrs = load_state_file(path)
    state.time_origin_step = state.step
    state.vibrating = True
    return state


def worker(case: str, steps: int, repeats: int, sets: list[str]) -> dict:
    """Time run_steps in this process (NUMBA_NUM_THREADS set by the caller)."""
    # imported here, in the worker: each checkout's own package (PYTHONPATH), numba after
    # NUMBA_NUM_THREADS is set
    import numba

    import vibroflow
    from vibroflow.dem.simulate import make_system, run_steps
    from vibroflow.scenario.io import load_scenario

    scenario = load_scenario(case, sets)
    system = make_system(scenario)
    state = settled_state(scenario, system)
    t0 = time.perf_counter()
    run_steps(system, state, 2)
    first_call = time.perf_counter() - t0
    times, cpu, builds = [], [], []
    for _ in range(repeats):
        state = settled_state(scenario, system)
        b0 = state.nl.builds
        t0, c0 = time.perf_counter(), time.process_time()
        run_steps(system, state, steps)
        cpu.append(time.process_time() - c0)
        times.append(time.perf_counter() - t0)
        builds.append(state.nl.builds - b0)
    return {"package": str(Path(vibroflow.__file__).parent), "threads": numba.get_num_threads(),
            "balls": state.n, "steps": steps, "first_call_s": first_call, "times_s": times,
            "cpu_s": cpu, "builds": builds, "kinetic_energy_J": state.kinetic_energy()}


def _interpreter(checkout: Path) -> str:
    own = checkout / ".venv" / "bin" / "python"
    return str(own) if own.exists() else sys.executable


def _run(checkout: Path, a, sets: list[str]) -> dict:
    env = dict(os.environ, NUMBA_NUM_THREADS=str(a.threads), PYTHONPATH=str(checkout))
    cmd = [_interpreter(checkout), str(Path(__file__).resolve()), "--worker", "--case", a.case,
           "--steps", str(a.steps), "--repeats", str(a.repeats)]
    for kv in sets:
        cmd += ["--set", kv]
    load0 = os.getloadavg()[0]
    out = subprocess.run(cmd, env=env, cwd=checkout, capture_output=True, text=True)
    if out.returncode != 0:
        raise SystemExit(f"{checkout}: the worker failed:\n{out.stderr[-3000:]}")
    result = json.loads(out.stdout.strip().splitlines()[-1])
    result["load"] = (load0, os.getloadavg()[0])
    return result


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--peer", type=Path, help="another vibroflow checkout to compare with")
    p.add_argument("--case", default="tub47-quick")
    p.add_argument("--steps", type=int, default=300, help="vibration steps a repeat")
    p.add_argument("--repeats", type=int, default=7, help="timed repeats a process")
    p.add_argument("--rounds", type=int, default=2, help="processes a checkout, alternated")
    p.add_argument("--threads", type=int, default=1, help="NUMBA_NUM_THREADS of each process")
    p.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE",
                   help="scenario override for both checkouts (repeatable)")
    p.add_argument("--peer-set", dest="peer_sets", action="append", default=[],
                   metavar="KEY=VALUE", help="scenario override for the peer only (repeatable)")
    p.add_argument("--json", type=Path, default=ROOT / "runs" / "dem_step_cost.json")
    p.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.worker:
        print(json.dumps(worker(a.case, a.steps, a.repeats, a.sets)))
        return
    checkouts = {"this": ROOT}
    if a.peer is not None:
        checkouts["peer"] = a.peer.resolve()
    runs: dict[str, list[dict]] = {k: [] for k in checkouts}
    for r in range(a.rounds):
        order = list(checkouts.items())
        for name, path in (order if r % 2 == 0 else order[::-1]):
            res = _run(path, a, a.sets + (a.peer_sets if name == "peer" else []))
            runs[name].append(res)
            us = [1e6 * t / a.steps for t in res["times_s"]]
            cpu = [1e6 * t / a.steps for t in res["cpu_s"]]
            print(f"round {r + 1} {name:4s} {path}: median {statistics.median(us):8.1f} us/step "
                  f"wall, {statistics.median(cpu):8.1f} CPU (load {res['load'][0]:.2f} -> "
                  f"{res['load'][1]:.2f})", flush=True)
    summary = {}
    for name, rs in runs.items():
        us = [1e6 * t / a.steps for res in rs for t in res["times_s"]]
        cpu = [1e6 * t / a.steps for res in rs for t in res["cpu_s"]]
        balls = rs[0]["balls"]
        med = statistics.median(us)
        summary[name] = {"checkout": str(checkouts[name]), "balls": balls, "steps": a.steps,
                         "repeats": len(us), "median_us_per_step": med, "min_us": min(us),
                         "max_us": max(us), "median_cpu_us_per_step": statistics.median(cpu),
                         "min_cpu_us": min(cpu), "max_cpu_us": max(cpu),
                         "ns_per_ball_step": 1e3 * med / balls,
                         "builds_per_repeat": rs[0]["builds"][0],
                         "kinetic_energy_J": rs[0]["kinetic_energy_J"],
                         "first_call_s": [res["first_call_s"] for res in rs]}
    print(f"\n{a.case}, {a.threads} thread(s), {a.steps} vibration steps from the settled bed, "
          f"{a.rounds} x {a.repeats} repeats a checkout")
    print(f"{'':6s}{'balls':>7s}{'wall us/step: median':>22s}{'min':>9s}{'max':>9s}"
          f"{'CPU us/step: median':>21s}{'min':>9s}{'max':>9s}{'ns/ball-step':>14s}"
          f"{'builds':>8s}  kinetic energy (J)")
    for name, s in summary.items():
        print(f"{name:6s}{s['balls']:7d}{s['median_us_per_step']:22.1f}{s['min_us']:9.1f}"
              f"{s['max_us']:9.1f}{s['median_cpu_us_per_step']:21.1f}{s['min_cpu_us']:9.1f}"
              f"{s['max_cpu_us']:9.1f}{s['ns_per_ball_step']:14.1f}"
              f"{s['builds_per_repeat']:8d}  {s['kinetic_energy_J']!r}")
    if "peer" in summary:
        this, peer = summary["this"], summary["peer"]
        ratio = this["median_us_per_step"] / peer["median_us_per_step"]
        ratio_cpu = this["median_cpu_us_per_step"] / peer["median_cpu_us_per_step"]
        same = this["kinetic_energy_J"] == peer["kinetic_energy_J"]
        summary.update(ratio_this_over_peer=ratio, cpu_ratio_this_over_peer=ratio_cpu,
                       same_kinetic_energy=same)
        print(f"ratio this / peer: wall {ratio:.3f}, CPU {ratio_cpu:.3f}; same kinetic energy: "
              f"{same}")
    a.json.parent.mkdir(parents=True, exist_ok=True)
    a.json.write_text(json.dumps(summary, indent=1))
    print(f"written {a.json}")


if __name__ == "__main__":
    main()
