"""Wall time of the continuum formulations on a tub case, against the DEM's.

    python benchmarks/continuum_speed.py [--case tub47-quick] [--calibration FILE]
        [--dem-dir DIR] [--methods lagrangian,eulerian] [--threads 1,2] [--cfl C]
        [--dx M] [--stiffness-factor 1.0] [--set KEY=VALUE ...] [--kernels]
        [--temperature] [--initial-temperature T] [--json PATH]

Every (method, thread count) case runs in its own process (NUMBA_NUM_THREADS set before numba
is imported): it first times the compiled kernels' first call (numba's cache load, or the
compilation when the cache is cold) on a few steps of the settled bed, then the whole run
(vibroflow.continuum.tub_run.run_continuum: settling, vibration, sampling, the analysis) into a
temporary folder.  Printed per case: points (material points, or the Eulerian mesh's cells),
steps (settling + vibration), the run's wall time (its summary's wall_time_s, as the DEM's),
steps/s and point-steps/s, the DEM's wall time and the ratio (the mission's target: >= 100 at
equal accuracy), and, with a DEM folder, the field difference E of tub47.md against the DEM and
the circulation (equal accuracy is judged on these).  The 1-minute load average before and after
each case is printed: on a shared machine the ratio is only indicative.

--kernels: one thread, in this process, on the settled bed: microseconds per call of each kernel
of a step (the Lagrangian's boundaries, p2g, grid update, g2p, volume and stress; the Eulerian's
material fraction, wall, partitions, p2g over the cells holding material, the chunk sums and
grid update, g2p, face velocities, stress update, remap) and of a whole step made by the
compiled loop (mpm.advance / eulerian.solver.advance), so the step's overhead beyond its
kernels shows.  A kernel timed from Python pays its call (~1 us with these many arguments).

--temperature: every case is run twice, without and with the granular temperature (its
balance made inside the compiled loops: mpm/temperature_loop.py, eulerian/temperature_loop.py;
initial T --initial-temperature, default 0.01 m^2/s^2), the column T saying which, and the
ratio of their wall times printed; with --kernels, the step is also timed on one bed 3000 steps
into a run with T: the mechanical step alone, with T in the compiled loop, and with T step by
step (`temperature_steps`).

--dem-dir: a `vibroflow dem` folder (or a study's dem/) of the same case: its summary.json's
wall_time_s and bulk_velocity.csv.  --calibration: a calibration.toml (default: the DEM
folder's calibration.toml when there is one, else tub47's defaults).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import bench

ROOT = Path(__file__).resolve().parent.parent


def _options(method: str, a):
    from vibroflow.continuum.formulation import formulation

    extra = {} if a.cfl is None else {"cfl": a.cfl}  # None: the options' default
    if a.transfer_cfl is not None:  # 0: one transfer a step
        extra["transfer_cfl"] = a.transfer_cfl
    if getattr(a, "temperature_on", False):
        extra.update(temperature=True, initial_temperature=a.initial_temperature)
    return formulation(method).options(dx=a.dx, stiffness_factor=a.stiffness_factor, **extra)


def _inputs(a):
    from vibroflow.io.calibration_file import read_calibration
    from vibroflow.scenario.io import load_scenario

    scenario = load_scenario(a.case, a.set)
    cal = None
    if a.calibration:
        cal = read_calibration(a.calibration)
    elif a.dem_dir and (Path(a.dem_dir) / "calibration.toml").exists():
        cal = read_calibration(Path(a.dem_dir) / "calibration.toml")
    return scenario, cal


def _settled(method: str, scenario, cal, opts):
    """(system, state, advance) of the settled bed in the vibrating tub's frame: the bed the
    run starts vibrating (tub_run.vibration_start)."""
    from vibroflow.continuum.formulation import formulation
    from vibroflow.continuum.tub_run import vibration_start

    system, state = vibration_start(scenario, cal, opts, method)
    return system, state, formulation(method).advance


def worker(a) -> dict:
    """One case in this process (NUMBA_NUM_THREADS set by the parent)."""
    import numba

    from vibroflow.measure.bulk import read_csv
    from vibroflow.analysis.compare import field_difference

    scenario, cal = _inputs(a)
    opts = _options(a.method, a)
    system, state, advance = _settled(a.method, scenario, cal, opts)
    t1 = time.perf_counter()
    advance(system, state, 2)
    first = time.perf_counter() - t1
    from vibroflow.continuum.tub_run import run_continuum

    load0 = bench.load_1min()
    res = {}
    with tempfile.TemporaryDirectory() as out:
        summary = run_continuum(scenario, out, a.method, calibration=cal, options=opts)
        dem_csv = Path(a.dem_dir) / "bulk_velocity.csv" if a.dem_dir else None
        if dem_csv is not None and dem_csv.exists():
            h = scenario.analysis.cell_size
            res["E"] = field_difference(read_csv(Path(out) / "bulk_velocity.csv", cell_size=h),
                                        read_csv(dem_csv, cell_size=h),
                                        scenario.analysis.min_solid_fraction)
    load1 = bench.load_1min()
    c = summary["continuum"]
    steps = summary["steps"] + int(math.ceil(opts.settle_time / c["dt_s"]))
    wall = summary["wall_time_s"]
    res.update({"method": a.method, "temperature": bool(a.temperature_on),
                "threads": numba.get_num_threads(), "points": c["points"],
                "steps": steps, "dt_s": c["dt_s"], "wall_time_s": wall,
                "steps_per_s": steps / wall, "point_steps_per_s": c["points"] * steps / wall,
                "first_call_s": first, "load_before": load0, "load_after": load1,
                "circulation": summary["circulation"]["strength"],
                "circulation_stderr": summary["circulation"]["strength_stderr"]})
    return res


def _per_call(f, n: int) -> float:
    """Microseconds per call of f (best of 3 batches of n)."""
    f()
    best = math.inf
    for _ in range(3):
        t = time.perf_counter()
        for _ in range(n):
            f()
        best = min(best, (time.perf_counter() - t) / n)
    return 1e6 * best


def kernels(a) -> dict:
    """Microseconds per call of each kernel of a step and of a whole step (module docstring),
    one thread, on the settled bed."""
    import numba
    import numpy as np

    from vibroflow.continuum.eulerian.operator_build import operator_columns, operator_rows
    from vibroflow.continuum.transfer_operator import (HALF, expand, operator_of_points,
                                                       transfer_rows)

    numba.set_num_threads(1)
    scenario, cal = _inputs(a)
    out = {}
    for method in a.methods:
        opts = _options(method, a)
        system, state, advance = _settled(method, scenario, cal, opts)
        t = {}
        if method == "lagrangian":
            from vibroflow.continuum.boundary import partition_forces, u_wall_forces
            from vibroflow.continuum.stress_update import update_stress_points
            from vibroflow.continuum.g2p import g2p
            from vibroflow.continuum.grid_update import grid_update
            from vibroflow.continuum.p2g import p2g
            from vibroflow.continuum.plasticity import update_volume

            g = system.grid
            gw = system.work
            gm, gmv, gf, gv = gw.gm, gw.gmv, gw.gf, gw.gv
            wall, part = system.boundaries[0], system.boundaries[-1]
            h = state.history[0]
            x, v, C, L = state.x.copy(), state.v.copy(), state.C.copy(), state.L.copy()
            stress, vol, rho = state.stress.copy(), state.volume.copy(), state.density.copy()
            t["boundaries"] = _per_call(lambda: (
                u_wall_forces(x, v, state.mass, vol, h["xi"].copy(), state.fext, h["f"],
                              h["fn"], h["ft"], h["state"], wall.radius, wall.stiffness,
                              wall.tangential_stiffness, wall.damping_ratio, wall.friction,
                              system.dt),
                partition_forces(v, state.mass, vol, stress, state.fext, part.friction,
                                 part.length, system.dt)), 200)
            t["p2g"] = _per_call(lambda: p2g(x, v, C, state.mass, vol, stress, state.fext,
                                             g.x0, g.z0, g.dx, g.periodic, gm, gmv, gf), 200)
            t["grid_update"] = _per_call(lambda: grid_update(
                gm, gmv, gf, gv, g.x0, g.z0, g.dx, system.dt, 0.0, -9.81, 0.0, 0.0, 0.0, 0.0,
                g.periodic), 200)
            t["g2p"] = _per_call(lambda: g2p(x.copy(), v.copy(), C.copy(), L, gv, g.x0, g.z0,
                                             g.dx, 0.0, g.periodic, gm, gmv, 0.0), 200)
            t["volume_and_stress"] = _per_call(lambda: (
                update_volume(L, state.mass, vol.copy(), rho, 0.0, 0.0),
                update_stress_points(stress.copy(), L, rho, system.dt, system.params,
                                     state.gamma_dot.copy(), state.phase.copy())), 200)
            B = np.zeros((g.nx, g.nz, HALF))
            gtmp = np.zeros_like(gv)

            def build():
                B[:] = 0.0
                operator_of_points(x, state.mass, g.x0, g.z0, g.dx, g.periodic, B)

            t["transfer operator (build)"] = _per_call(build, 200)
            mass = expand(B).sum(axis=(2, 3))  # the nodes' masses: the operator's row sums
            t[f"one transfer (x {system.transfers - 1} a step)"] = _per_call(
                lambda: transfer_rows(0, g.nx, B, mass, gv, gtmp, g.periodic, 0, 0), 200)
        else:
            from vibroflow.continuum.boundary import partition_forces
            from vibroflow.continuum.stress_update import update_stress_points
            from vibroflow.continuum.eulerian.advection import remap, remap_fluxes_serial
            from vibroflow.continuum.eulerian.remap_rows import (bed_top, fit_rows, pack_cells,
                                                                 pack_faces, renew_columns)
            from vibroflow.continuum.eulerian.face_velocity import face_velocities
            from vibroflow.continuum.eulerian.lagrangian_step import (end_density,
                                                                      material_fraction)
            from vibroflow.continuum.eulerian.solver import NQ
            from vibroflow.continuum.eulerian.column_gather import gather
            from vibroflow.continuum.eulerian.column_scatter import scatter
            from vibroflow.continuum.eulerian.wall import wall_forces
            from vibroflow.continuum.grid_update import grid_update

            mesh = system.mesh
            g = mesh.grid
            n = mesh.n
            gw = system.work
            gm, gmv, gf, gv = gw.gm, gw.gmv, gw.gf, gw.gv
            rows = np.flatnonzero((state.mass.reshape(mesh.ncx, mesh.ncz) > 0).any(axis=0))
            ktop = int(rows[-1]) + 1
            cw = system.cell_work
            tcx, tcz = system.tables[0], system.tables[1]
            w, pf, hist = system.wall, system.partitions, state.wall
            frac, vol, fext = state.frac.copy(), state.volume.copy(), state.fext.copy()
            t["material fraction"] = _per_call(lambda: material_fraction(
                state.mass, state.density, mesh.h, system.cell_weight, frac, vol), 200)
            t["wall"] = _per_call(lambda: wall_forces(
                system.wall_cells, mesh.normal, state.v, state.mass,
                system.material.critical_density, mesh.h, system.cell_weight,
                hist["delta"].copy(),
                hist["xi"].copy(), fext, hist["fn"].copy(), hist["ft"].copy(),
                hist["state"].copy(), w.stiffness, w.tangential_stiffness, w.damping_ratio,
                w.friction, system.dt), 200)
            t["partitions"] = _per_call(lambda: partition_forces(
                state.v, state.mass, state.volume, state.stress, fext, pf.friction, pf.length,
                system.dt), 200)
            t["p2g (cells holding material, both passes)"] = _per_call(lambda: scatter(
                ktop, tcx, tcz, g.dx, system.mesh_record.columns, state.mass, state.volume,
                state.v, state.C, state.stress, state.fext, system.inv_r, cw.zscat, gm, gmv,
                gf), 200)
            t["grid update"] = _per_call(lambda: grid_update(
                gm, gmv, gf, gv, g.x0, g.z0, g.dx, system.dt, 0.0, -9.81, 0.0, 0.0, 0.0, 0.0,
                g.periodic), 200)
            v, C, L = state.v.copy(), state.C.copy(), state.L.copy()
            t["g2p (cells holding material, both passes)"] = _per_call(lambda: gather(
                ktop, tcx, tcz, system.tables[3], g.dx, g.periodic, gv, cw.zgath, state.mass, v,
                C, L), 200)
            m2 = state.mass.reshape(mesh.ncx, mesh.ncz)
            t["face_velocities (both passes)"] = _per_call(lambda: face_velocities(
                gv, system.tables, g.dx, g.periodic, mesh.open_x, mesh.open_z, m2, system.ux,
                system.uz), 200)
            rho = np.zeros(n)
            end_density(state.density, state.L, system.dt, rho)
            t["stress update (every cell)"] = _per_call(lambda: update_stress_points(
                state.stress.copy(), state.L, rho, system.dt, system.params,
                state.gamma_dot.copy(), state.phase.copy()), 200)
            q = np.zeros((NQ, n))
            q[0:2] = state.v.T
            q[6:10] = state.stress.T
            q[10] = state.density
            s2 = (mesh.ncx, mesh.ncz)
            t["remap (every cell)"] = _per_call(lambda: remap(
                m2.copy(), q.copy().reshape((NQ,) + s2), system.ux, system.uz, mesh.h,
                system.dt, mesh.periodic, system.remap_work), 200)
            # the compiled loop's: on the rows up to one above the bed's top (remap_rows.py)
            rw = cw.remap
            kr = min(bed_top(state.mass, mesh.ncx, mesh.ncz, mesh.h, rw.weights[0]) + 1,
                     mesh.ncz)
            nr = mesh.ncx * kr
            fit_rows(rw, kr, mesh.ncx, mesh.ncz)
            qr, mr = rw.q[:NQ * nr].reshape(NQ, nr), rw.mass[:nr]
            rv, rC, rs, rrho, rm = (a.copy() for a in (state.v, state.C, state.stress,
                                                        state.density, state.mass))
            work = rw.work

            def remap_rows():
                pack_faces(0, mesh.ncx + 1, system.ux, kr, rw.ux)
                pack_cells(0, n, kr, mesh.ncz, state.v, state.C, state.stress,
                           state.density, state.mass, qr, mr)
                remap_fluxes_serial(mr.reshape(mesh.ncx, kr), qr.reshape(NQ, mesh.ncx, kr),
                                    rw.ux[:(mesh.ncx + 1) * kr].reshape(mesh.ncx + 1, kr),
                                    system.uz, mesh.h, system.dt, mesh.periodic, work)
                renew_columns(0, mesh.ncx, kr, mesh.ncz, qr, mr, work[9], work[6],
                              work[0][4], work[0][3], rv, rC, rs, rrho, rm)

            t["remap (the rows that can hold material, packed)"] = _per_call(remap_rows, 200)
            B = np.zeros((g.nx, g.nz, HALF))
            gtmp = np.zeros_like(gv)

            op, rc = system.mesh_record.operator, system.mesh_record.columns
            m2 = state.mass.reshape(mesh.ncx, mesh.ncz)

            def build():
                operator_columns(0, mesh.ncx, ktop, m2, tcz, op.zf, cw.S)
                operator_rows(0, g.nx, ktop, tcz, cw.S, op.xf, *rc, cw.rows, B)

            t["transfer operator (build)"] = _per_call(build, 200)
            mass = expand(B).sum(axis=(2, 3))  # the nodes' masses: the operator's row sums
            t[f"one transfer (x {system.transfers - 1} a step)"] = _per_call(
                lambda: transfer_rows(0, g.nx, B, mass, gv, gtmp, g.periodic, 0, 0), 200)
        t["whole step (compiled loop, 20 steps a call)"] = _per_call(
            lambda: advance(system, state, 20), 10) / 20
        t["whole step (one step a call)"] = _per_call(lambda: advance(system, state, 1), 100)
        if a.temperature:
            t.update(temperature_steps(method, scenario, cal, a))
        out[method] = {"points": int(state.n if method == "lagrangian"
                                     else (state.mass > 0).sum()), "us_per_call": t}
    return out


def temperature_steps(method, scenario, cal, a, warm: int = 3000, n: int = 200) -> dict:
    """Microseconds a step on one bed, the settled bed `warm` steps into a run with the
    granular temperature (hotter and looser than without it): the mechanical step alone (the
    fused loop without T), the compiled loop with T, and the step-by-step path
    (solver.advance_stepwise), each best of 3 runs of n steps from a copy of the same state."""
    import copy

    import numpy as np

    from vibroflow.continuum.eulerian import solver as eulerian
    from vibroflow.continuum.mpm import solver as mpm

    solver = mpm if method == "lagrangian" else eulerian
    a.temperature_on = True
    system, state, advance = _settled(method, scenario, cal, _options(method, a))
    a.temperature_on = False
    advance(system, state, warm)
    out = {}
    for name, run in ((f"mechanical step alone ({warm} steps into T)",
                       lambda s: solver._advance(system, s, n, np.empty((0, 5)))),
                      ("step with T (compiled loop)", lambda s: advance(system, s, n)),
                      ("step with T (step by step)",
                       lambda s: solver.advance_stepwise(system, s, n))):
        best = math.inf
        for _ in range(3):
            s = copy.deepcopy(state)
            t0 = time.perf_counter()
            run(s)
            best = min(best, time.perf_counter() - t0)
        out[name] = 1e6 * best / n
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--case", default="tub47-quick")
    p.add_argument("--calibration")
    p.add_argument("--dem-dir")
    p.add_argument("--methods", default="lagrangian,eulerian")
    p.add_argument("--threads", default="1,2")
    p.add_argument("--cfl", type=float, default=None)
    p.add_argument("--transfer-cfl", type=float, default=None)
    p.add_argument("--dx", type=float)
    p.add_argument("--stiffness-factor", type=float, default=1.0)
    p.add_argument("--set", action="append", default=[])
    p.add_argument("--kernels", action="store_true")
    p.add_argument("--temperature", action="store_true")
    p.add_argument("--initial-temperature", type=float, default=0.01)
    p.add_argument("--temperature-on", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--json", default=str(ROOT / "runs" / "continuum_speed.json"))
    p.add_argument("--method", help=argparse.SUPPRESS)  # a worker's case
    a = p.parse_args(argv)
    a.methods = [m for m in a.methods.split(",") if m]
    if a.method:
        print("RESULT " + json.dumps(worker(a)))
        return 0
    # vibroflow (and with it numba) is imported in functions, after a worker's
    # NUMBA_NUM_THREADS is set (module docstring)
    from vibroflow.continuum.formulation import formulation

    dem_wall = None
    if a.dem_dir:
        dem_wall = json.loads((Path(a.dem_dir) / "summary.json").read_text())["wall_time_s"]
    report = {"case": a.case, "options": {"cfl": _options("lagrangian", a).cfl, "dx": a.dx,
                                          "stiffness_factor": a.stiffness_factor,
                                          "transfers_per_step": {
                                              m: formulation(m).transfers_on(
                                                  _options(m, a), _inputs(a)[0])
                                              for m in ("lagrangian", "eulerian")}},
              "dem_wall_time_s": dem_wall, "cases": []}
    if a.kernels:
        report["kernels"] = kernels(a)
        for method, k in report["kernels"].items():
            print(f"{method}: {k['points']} points, one thread, us per call")
            for name, us in k["us_per_call"].items():
                print(f"  {name:45s} {us:9.1f}")
    head = (f"{'method':11s} {'T':>3s} {'thr':>3s} {'points':>6s} {'steps':>6s} {'wall s':>7s} "
            f"{'steps/s':>8s} {'Mpt-st/s':>8s} {'1st call':>8s} {'DEM/cont':>8s} {'E':>6s} "
            f"{'circ':>8s} {'load':>9s}")
    print(head)
    for method in a.methods:
        for th, t_on in [(int(t), on) for t in a.threads.split(",") if t
                         for on in ((False, True) if a.temperature else (False,))]:
            cmd = [sys.executable, __file__, "--method", method, "--case", a.case,
                   "--stiffness-factor", str(a.stiffness_factor),
                   "--initial-temperature", str(a.initial_temperature)]
            if t_on:
                cmd.append("--temperature-on")
            for flag, val in (("--calibration", a.calibration), ("--dem-dir", a.dem_dir),
                              ("--dx", a.dx), ("--cfl", a.cfl),
                              ("--transfer-cfl", a.transfer_cfl)):
                if val is not None:
                    cmd += [flag, str(val)]
            for kv in a.set:
                cmd += ["--set", kv]
            env = dict(os.environ, NUMBA_NUM_THREADS=str(th))
            r = subprocess.run(cmd, env=env, capture_output=True, text=True, cwd=ROOT)
            line = [ln for ln in r.stdout.splitlines() if ln.startswith("RESULT ")]
            if r.returncode != 0 or not line:
                print(f"{method} threads {th}: failed\n{r.stderr[-2000:]}")
                continue
            res = json.loads(line[-1][7:])
            res["dem_over_continuum"] = dem_wall / res["wall_time_s"] if dem_wall else None
            report["cases"].append(res)
            ratio = f"{res['dem_over_continuum']:8.1f}" if dem_wall else f"{'-':>8s}"
            E = f"{res['E']:6.3f}" if "E" in res else f"{'-':>6s}"
            print(f"{method:11s} {'on' if t_on else 'off':>3s} {th:3d} {res['points']:6d} {res['steps']:6d} "
                  f"{res['wall_time_s']:7.2f} {res['steps_per_s']:8.0f} "
                  f"{res['point_steps_per_s'] / 1e6:8.2f} {res['first_call_s']:8.2f} {ratio} "
                  f"{E} {res['circulation']:8.5f} "
                  f"{res['load_before']:4.1f}/{res['load_after']:4.1f}")
            off = report["cases"][-2] if len(report["cases"]) > 1 else None
            if t_on and off and not off["temperature"] and off["method"] == method \
                    and off["threads"] == res["threads"]:
                print(f"{'':11s} T on / off wall time "
                      f"{res['wall_time_s'] / off['wall_time_s']:.2f}")
    if dem_wall:
        print(f"DEM wall time {dem_wall:.1f} s ({a.dem_dir})")
    path = bench.write_json(a.json, report)
    print(f"written {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
