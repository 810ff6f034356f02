"""Does the continuum's cylinder collapse converge as the grid is refined, and to what?

    python benchmarks/column_convergence.py [--method lagrangian eulerian] [--aspect 3]
        [--grids 10,20,40,80] [--friction-deg 29.5] [--transfers 1 [--hold-damping]]
        [--jobs 2] [--out DIR]

The grid convergence of the checks of tests/test_axisymmetric.py: a cylinder of radius R0 = 1 m and
height a R0 of the experiments' sand (vibroflow.continuum.column.sand_material) collapses on the
rough (no-slip grid) floor, and its deposit is compared with Lube et al. 2004's run-out
(r_inf - R0)/R0 = 1.6 a^(1/2) and Lajeunesse et al. 2004's height H_inf/R0 = 0.74 (a > 1.7;
vibroflow.measure.column).  The suite runs it on one grid; this script runs it on a sequence
of grids R0/n (n from --grids), in each formulation of --method, and prints for each its
run-out and height (the mean thickness within 0.1 R0 of the axis, the tests' measure) beside
the laws, then the convergence of each sequence: the successive changes, their ratio q (a
first-order method halving dx gives q ~ 0.5, a second-order one q ~ 0.25) and, where
0 < q < 1 on the last three grids, the Richardson limit x_n + d_n q / (1 - q) (d_n the last
change).  A sequence whose changes do not shrink has no limit here, which is said.

--transfers k makes k APIC transfers a step (default 1, the checks' setting) on every grid, or,
with --hold-damping, on the first grid only, the count scaled as the tub runs scale it
(vibroflow.continuum.options.damping_transfer_cfl: k (n / n_0)^3 on R0/n, n_0 the first grid),
which holds the transfers' hyperviscosity alpha c dx^3 / transfer_cfl fixed
(docs/decisions/grid-spacing.md; the cost grows as the transfers do: R0/80 at 8 a step is
about 20 minutes; the Eulerian's R0/40 at 8, about an hour).

Runs go --jobs at a time, one numba thread each (a 2-core machine: --jobs 2).  Costs, on this
machine with one thread: Lagrangian R0/10 to R0/80 about 2, 10, 40 and 200 s at a = 3;
Eulerian R0/10, /20, /40 about 7, 70 and 1000 s.  Figures, once printed, go to
benchmarks/README.md with the date; --out DIR also writes DIR/column_convergence.json.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path

import bench

#: the height is the deposit's mean thickness within this fraction of R0 of the axis (the
#: tests' measure, tests/test_axisymmetric.py CENTRE)
CENTRE = 0.1


def _one(job: tuple) -> dict:
    """Run one (method, a, n, friction_deg, transfers) cylinder; its deposit and wall time."""
    method, a, n, friction_deg, transfers = job
    os.environ["NUMBA_NUM_THREADS"] = "1"   # before numba is imported: a spawned process
    from vibroflow.continuum.column import run_column, sand_material

    mat = sand_material(friction_deg)
    t0 = time.perf_counter()
    run = run_column(1.0, a, 1.0 / n, material=mat, rough_floor=True, axisymmetric=True,
                     transfers=transfers, method=method)
    dep = run.deposit(wall_window=CENTRE)
    mass_error = float(run.mass_error)
    runout, height = dep.normalised(1.0)
    return {"method": method, "a": a, "n": n, "transfers": transfers,
            "runout": float(runout), "height": float(height), "settled": bool(run.settled),
            "t_end_s": float(run.t_end), "mass_error": mass_error,
            "wall_s": time.perf_counter() - t0}


def convergence(values: list[float]) -> tuple[list[float], float | None, float | None]:
    """(successive changes, ratio q of the last two, Richardson limit) of a sequence on grids
    halved each time: q = d_n / d_(n-1); the limit x_n + d_n q / (1 - q) where 0 < q < 1."""
    d = [b - a for a, b in zip(values, values[1:])]
    if len(d) < 2 or d[-2] == 0:
        return d, None, None
    q = d[-1] / d[-2]
    limit = values[-1] + d[-1] * q / (1.0 - q) if 0 < q < 1 else None
    return d, q, limit


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--method", nargs="+", default=["lagrangian"],
                    choices=["lagrangian", "eulerian"])
    ap.add_argument("--aspect", type=float, nargs="+", default=[3.0])
    ap.add_argument("--grids", default="10,20,40,80",
                    help="comma-separated n of the grids R0/n, each twice the last")
    ap.add_argument("--friction-deg", type=float, default=None,
                    help="the sand's friction angle (default SAND_FRICTION_DEG, 29.5)")
    ap.add_argument("--transfers", type=int, default=1,
                    help="APIC transfers a step (on the first grid with --hold-damping)")
    ap.add_argument("--hold-damping", action="store_true",
                    help="scale the transfers as (n/n_0)^3: the hyperviscosity held fixed")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args(argv)
    from vibroflow.measure.column import LAJEUNESSE_2004, LUBE_2004
    from vibroflow.continuum.column import SAND_FRICTION_DEG, sand_material
    from vibroflow.errors import InputError

    try:
        grids = [int(g) for g in args.grids.split(",")]
    except ValueError:
        print(f"--grids {args.grids!r}: must be comma-separated whole numbers (R0/n)",
              file=sys.stderr)
        return 2
    if not grids or any(g < 2 for g in grids) or \
            any(b != 2 * a for a, b in zip(grids, grids[1:])):
        print(f"--grids {args.grids!r}: every n must be >= 2 and twice the one before (the "
              "convergence ratios assume halved grids)", file=sys.stderr)
        return 2
    if args.transfers < 1 or args.jobs < 1:
        print(f"--transfers {args.transfers}, --jobs {args.jobs}: must be >= 1",
              file=sys.stderr)
        return 2
    if any(a <= 1.7 for a in args.aspect):
        print(f"--aspect {args.aspect}: the laws compared here are the tall branch, a > 1.7",
              file=sys.stderr)
        return 2
    friction = SAND_FRICTION_DEG if args.friction_deg is None else args.friction_deg
    try:
        sand_material(friction)
    except InputError as exc:
        print(f"--friction-deg: {exc}", file=sys.stderr)
        return 2
    jobs = []
    for method in args.method:
        for a in args.aspect:
            for n in grids:
                k = args.transfers * (round((n / grids[0]) ** 3) if args.hold_damping else 1)
                jobs.append((method, a, n, friction, max(1, k)))
    print(f"sand cylinder (friction {friction} deg), R0 = 1 m, rough floor, APIC; "
          f"height within {CENTRE} R0 of the axis", flush=True)
    with ProcessPoolExecutor(max_workers=args.jobs, mp_context=get_context("spawn")) as pool:
        results = list(pool.map(_one, jobs))
    print(f"{'method':<11}{'a':>4}{'grid':>8}{'transfers':>10}{'run-out':>9}{'Lube 04':>9}"
          f"{'height':>8}{'Lajeun. 04':>11}{'wall s':>8}")
    for r in results:
        lr, lh = LUBE_2004.runout(r["a"]), LAJEUNESSE_2004.height(r["a"])
        flag = "" if r["settled"] else "  (not at rest)"
        print(f"{r['method']:<11}{r['a']:>4g}{'R0/' + str(r['n']):>8}{r['transfers']:>10}"
              f"{r['runout']:>9.3f}{r['runout'] / lr - 1:>+9.1%}{r['height']:>8.3f}"
              f"{r['height'] / lh - 1:>+11.1%}{r['wall_s']:>8.0f}{flag}")
    print("\nconvergence (changes from grid to grid; q the ratio of the last two; limit: "
          "Richardson's where 0 < q < 1)")
    summary = []
    for method in args.method:
        for a in args.aspect:
            rows = [r for r in results if r["method"] == method and r["a"] == a]
            for key, law in (("runout", LUBE_2004.runout(a)),
                             ("height", LAJEUNESSE_2004.height(a))):
                d, q, limit = convergence([r[key] for r in rows])
                text = " ".join(f"{x:+.3f}" for x in d)
                qs = "n/a" if q is None else f"{q:.2f}"
                if q is None:
                    lim = "needs three grids"
                elif limit is None:
                    lim = "none (the changes do not shrink)"
                else:
                    lim = f"{limit:.3f} ({limit / law - 1:+.1%} of the law)"
                print(f"  {method} a = {a:g} {key}: changes {text}; q {qs}; limit {lim}")
                summary.append({"method": method, "a": a, "measure": key, "changes": d,
                                "q": q, "limit": limit, "law": law})
    if args.out is not None:
        bench.write_json(args.out / "column_convergence.json",
                         {"runs": results, "convergence": summary, "machine": bench.machine()})
    return 0


if __name__ == "__main__":
    sys.exit(main())
