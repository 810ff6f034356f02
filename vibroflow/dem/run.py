"""Orchestration of a DEM run: fill and settle (or the cached bed), vibrate, sample, checkpoint,
write results, summarise.  The numerics live in step.py / simulate.py; this file only decides
when things happen and where they are written.

Timeline of a tub run (tub47.md, "Procedure"), t counted from the start of the vibration:
    [0, duration - average_last)      vibrate
    [duration - average_last, end]    vibrate and sample: `phases_per_cycle` snapshots a cycle
                                      over the whole cycles of the window (with the wall
                                      contacts at those instants), and every new contact's
                                      impact.
"""
from __future__ import annotations

import json
import math
import os
import signal
import time
from pathlib import Path

import numba
import numpy as np

from ..io.atomic import write_json_atomic
from ..progress import RunProgress
from ..run_clock import RunClock
from ..tub.motion import pose_np
from . import fill as F
from .output import ResultWriter, load_state_file, save_state_file
from .query import ball_contacts_now
from .simulate import (BlowUp, DEMState, DEMSystem, init_state, make_system, run_steps,
                       shortest_contact_time, take_max_overlaps, wall_contacts_now)

SMALL_RUN = 1500  # below this many balls one thread is faster than two (thread wake-ups)


def _scenario_toml(scenario) -> str:
    try:
        from ..scenario.io import dump_scenario
        return dump_scenario(scenario)
    except Exception:  # pragma: no cover - io module absent
        return json.dumps(scenario.model_dump(mode="json"))


def sample_steps(scenario, dt: float) -> tuple[np.ndarray, float, float]:
    """Vibration steps of the snapshots, and the averaging window [t0, t1) (s).

    The window starts `average_last` seconds before the end and holds its whole cycles; samples
    sit at the phases k / phases_per_cycle of the vibration, rounded to the nearest step (a phase
    error below dt/2, 0.02% of a cycle at tub47's settings)."""
    run, f = scenario.run, scenario.motion.frequency
    t0 = run.duration - run.average_last
    n_cycles = int(math.floor(run.average_last * f + 1e-9))
    if n_cycles < 1:
        return np.zeros(0, np.int64), t0, run.duration
    # at the phases m / P of the vibration (phase 0 = t multiple of 1/f), P per cycle
    per = run.phases_per_cycle
    m0 = math.ceil(t0 * f * per - 1e-9)
    times = (m0 + np.arange(n_cycles * per)) / (f * per)
    return np.round(times / dt).astype(np.int64), t0, t0 + n_cycles / f


def settled_bed(system: DEMSystem, scenario, prog: RunProgress) -> tuple[DEMState, dict]:
    """The settled bed, from the cache or made now (and cached)."""
    key = F.fill_cache_key(scenario, system.nchunk)
    path = F.cache_dir() / "fills" / f"{key}.h5"
    if path.exists():
        try:
            state, attrs = load_state_file(path)
            info = json.loads(attrs.get("settle_info", "{}"))
            info["cached"] = True
            prog.log(f"settled bed from cache {path}")
            return state, info
        except Exception:
            pass  # unreadable cache entry: make it again
    state = F.fill_state(system, scenario)
    n = state.n
    prog.stage("fill + settle", max(scenario.fill.settle_time, 1e-9))
    info = F.settle(system, state, scenario,
                    progress=lambda t, ke: prog.update(t, int(round(t / system.dt)) * n))
    info["cached"] = False
    path.parent.mkdir(parents=True, exist_ok=True)
    save_state_file(path, state, {"settle_info": json.dumps(info)})
    return state, info


def _impact_rows(system: DEMSystem, imp: np.ndarray) -> dict:
    """Impacts (lab) -> /impacts columns (contact point in the tub frame)."""
    p = pose_np(system.motion, imp[:, 0])
    pv = (system.motion.pivot_x, system.motion.pivot_z)
    c, s = np.cos(p["theta"]), np.sin(p["theta"])
    rx = imp[:, 2] - p["X"] - pv[0]
    rz = imp[:, 4] - p["Z"] - pv[1]
    pos = np.stack([pv[0] + c * rx + s * rz, imp[:, 3], pv[1] - s * rx + c * rz], axis=1)
    return {"time": imp[:, 0], "kind": imp[:, 1].astype(np.int8),
            "position_tub": pos.astype(np.float32),
            "normal_speed": imp[:, 5].astype(np.float32)}


def _snapshot(writer: ResultWriter, system: DEMSystem, state: DEMState, index: int,
              frequency: float) -> None:
    t = state.time(system.dt)
    p = pose_np(system.motion, t)
    pose = np.array([[p["X"], p["Z"], p["theta"], p["Xdot"], p["Zdot"], p["thetadot"]]])
    writer.append("snapshots", time=[t], step=[state.step - state.time_origin_step],
                  phase=[(t * frequency) % 1.0], tub_pose=pose,
                  position=state.pos[None].astype(np.float32),
                  velocity=state.vel[None].astype(np.float32),
                  angular_velocity=state.omg[None].astype(np.float32))
    wc = wall_contacts_now(system, state)
    m = wc["particle"].shape[0]
    if m:
        writer.append("wall_contacts", snapshot=np.full(m, index, np.int32),
                      particle=wc["particle"], wall=wc["wall"],
                      position_tub=wc["position_tub"], arc=wc["arc"], fn=wc["fn"],
                      ft=wc["ft"], sliding=wc["sliding"],
                      force_lab=wc["force"].astype(np.float32))
    bc = ball_contacts_now(system, state)
    b = bc["i"].shape[0]
    if b:
        writer.append("ball_contacts", snapshot=np.full(b, index, np.int32),
                      i=bc["i"].astype(np.int32), j=bc["j"].astype(np.int32),
                      force_lab=bc["force"].astype(np.float32))


def run_dem(scenario, out_dir: Path, vtk: bool = False, resume: bool = False,
            progress: bool = True, nchunk: int | None = None) -> dict:
    """Run the scenario's DEM and write DIR/dem.h5, DIR/summary.json (and bulk_velocity.csv in
    tub mode).  Returns the summary."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    system = make_system(scenario, nchunk)
    system.notes["shortest_contact_time"] = shortest_contact_time(scenario)
    n_balls = len(scenario.particles) if scenario.explicit else scenario.fill.count
    threads_before = numba.get_num_threads()
    if n_balls < SMALL_RUN:
        numba.set_num_threads(1)  # same results: the chunking, not the threads, fixes order
    try:
        # the solver's time, numba's compilation apart (vibroflow.run_clock)
        with RunProgress(progress) as prog, RunClock() as clock:
            return _run(scenario, out_dir, system, vtk, resume, prog, clock)
    finally:
        numba.set_num_threads(threads_before)


def _run(scenario, out_dir: Path, system: DEMSystem, vtk: bool, resume: bool,
         prog: RunProgress, clock: RunClock) -> dict:
    dt = system.dt
    ckpt = out_dir / "checkpoint.h5"
    explicit = scenario.explicit
    if resume and ckpt.exists():
        state, attrs = load_state_file(ckpt)
        if int(attrs["nchunk"]) != system.nchunk:
            system = make_system(scenario, int(attrs["nchunk"]))
            system.notes["shortest_contact_time"] = shortest_contact_time(scenario)
        clock.resume_from(float(attrs["wall_time_s"]))
        settle_info = json.loads(attrs["settle_info"])
        writer = ResultWriter(out_dir, state.n, {}, state.radius,
                              parts_done=int(attrs["parts_done"]))
        if attrs.get("diag") and json.loads(attrs["diag"]) is not None:
            from .simulate import _buf
            _buf(system, state).diag[:] = np.array(json.loads(attrs["diag"]))
        prog.log(f"resuming from {ckpt} at t = {state.time(dt):.4f} s")
    else:
        if resume:
            prog.log(f"no checkpoint in {out_dir}: starting afresh")
        if explicit:
            index = system.material_names
            ps = scenario.particles
            state = init_state(system, [p.position for p in ps], [p.velocity for p in ps],
                               [p.angular_velocity for p in ps], [0.5 * p.diameter for p in ps],
                               [scenario.materials[p.material].density for p in ps],
                               [index.index(p.material) for p in ps])
            settle_info = {}
        else:
            state, settle_info = settled_bed(system, scenario, prog)
            state.time_origin_step = state.step
            take_max_overlaps(system, state)  # the series starts with the vibration
        state.vibrating = True
        attrs = {"case": scenario.case, "n_particles": state.n, "dt": dt,
                 "frequency": scenario.motion.frequency,
                 "scenario_toml": _scenario_toml(scenario), "source": "vibroflow"}
        writer = ResultWriter(out_dir, state.n, attrs, state.radius)
    try:
        summary = _vibrate(scenario, out_dir, system, state, writer, prog, settle_info,
                           clock, explicit, vtk)
    except BlowUp:
        # nothing half-written stays behind: a blown-up run has no result to resume
        writer.discard()
        ckpt.unlink(missing_ok=True)
        raise
    except BaseException:
        writer.close()
        raise
    return summary


def _vibrate(scenario, out_dir, system, state, writer, prog, settle_info, clock: RunClock,
             explicit, vtk):
    dt = system.dt
    run = scenario.run
    f = scenario.motion.frequency
    n = state.n
    total = int(round(run.duration / dt))
    if explicit:
        samples = np.arange(0, total + 1, run.series_every, dtype=np.int64)
        window = (0.0, run.duration)
    else:
        samples, t0, t1 = sample_steps(scenario, dt)
        window = (t0, t1)
    window_start = int(round(window[0] / dt))
    ckpt = out_dir / "checkpoint.h5"
    done_snapshots = writer.rows("snapshots/time")
    vstep = state.step - state.time_origin_step
    last_ckpt = time.perf_counter()
    stage_steps0 = vstep
    prog.stage("vibrate" if not explicit else "run", run.duration)

    def on_impacts(imp):
        writer.append("impacts", **_impact_rows(system, imp))

    while True:
        vstep = state.step - state.time_origin_step
        if done_snapshots < len(samples) and samples[done_snapshots] == vstep:
            _snapshot(writer, system, state, done_snapshots, f)
            done_snapshots += 1
        if vstep % run.series_every == 0:
            ob, ow = take_max_overlaps(system, state)
            writer.append("series", time=[state.time(dt)],
                          kinetic_energy=[state.kinetic_energy()], max_overlap_ball=[ob],
                          max_overlap_wall=[ow])
        if vstep >= total:
            break
        nxt = min(total, (vstep // run.series_every + 1) * run.series_every)
        if done_snapshots < len(samples):
            nxt = min(nxt, int(samples[done_snapshots]))
        record = run.record_impacts and not explicit and vstep >= window_start
        if not explicit and vstep < window_start:
            nxt = min(nxt, window_start)
        run_steps(system, state, nxt - vstep, record_impacts=record,
                  on_impacts=on_impacts if record else None)
        prog.update(state.time(dt), (state.step - state.time_origin_step - stage_steps0) * n)
        if time.perf_counter() - last_ckpt > run.checkpoint_every:
            _checkpoint(ckpt, state, writer, system, settle_info,
                        clock.solver_s())
            last_ckpt = time.perf_counter()

    wall = clock.solver_s()
    path = writer.finish()
    summary = _summary(scenario, system, state, path, out_dir, wall, settle_info, explicit)
    summary["compile_time_s"] = clock.compile_s()
    if vtk:
        _write_vtk(path, out_dir, scenario)
    write_json_atomic(out_dir / "summary.json", summary)
    if ckpt.exists():
        ckpt.unlink()
    return summary


def _checkpoint(path, state, writer, system, settle_info, wall):
    parts_done = writer.rotate()
    # the overlap maxima since the last series row travel too, so the series is exact
    diag = state.scratch.diag if state.scratch is not None else None
    save_state_file(path, state, {"parts_done": parts_done,
                                  "nchunk": system.nchunk, "wall_time_s": wall,
                                  "settle_info": json.dumps(settle_info),
                                  "diag": json.dumps(diag.tolist() if diag is not None
                                                     else None)})
    _fault_after_checkpoint()


def _fault_after_checkpoint() -> None:
    """Fault injection for the resume tests: with VIBROFLOW_FAULT_KILL_AFTER_CHECKPOINT=1 in
    the environment the process SIGKILLs itself as soon as its first checkpoint is on disk,
    the deterministic version of a power cut (a test that kills from outside races a fast
    machine, which may finish the run between the checkpoint and the signal)."""
    if os.environ.get("VIBROFLOW_FAULT_KILL_AFTER_CHECKPOINT") == "1":
        os.kill(os.getpid(), signal.SIGKILL)


def _summary(scenario, system, state, h5path, out_dir, wall, settle_info, explicit) -> dict:
    import h5py
    dt = system.dt
    steps = state.step - state.time_origin_step
    with h5py.File(h5path, "r") as f:
        ob = f["series/max_overlap_ball"][()]
        ow = f["series/max_overlap_wall"][()]
        ts = f["series/time"][()]
    d = 2.0 * float(state.radius.max())
    # the same maxima over the averaging window only: the start of the vibration (the tub
    # starting at full speed against a bed at rest) gives the run's hardest impacts
    in_window = ts >= scenario.run.duration - scenario.run.average_last - 1e-12
    summary = {
        "case": scenario.case, "source": "vibroflow", "n_particles": state.n, "steps": steps,
        "dt": dt, "simulated_time_s": steps * dt, "wall_time_s": wall,
        "particle_steps_per_s": state.n * steps / wall if wall > 0 else None,
        "max_overlap_over_d": float(ob.max() / d) if ob.size else 0.0,
        "max_wall_overlap_over_d": float(ow.max() / d) if ow.size else 0.0,
        "max_overlap_over_d_window": float(ob[in_window].max() / d) if in_window.any()
        else 0.0,
        "max_wall_overlap_over_d_window": float(ow[in_window].max() / d) if in_window.any()
        else 0.0,
        "balls_lost": 0, "threads": numba.get_num_threads(), "chunks": system.nchunk,
        "neighbour_builds": state.nl.builds,
    }
    if settle_info:
        summary["settle"] = settle_info
    if explicit:
        summary["final_state"] = [
            {"id": i, "position": state.pos[i].tolist(), "velocity": state.vel[i].tolist(),
             "angular_velocity": state.omg[i].tolist()} for i in range(state.n)]
        return summary
    from ..analysis.summary import tub_summary
    summary.update(tub_summary(h5path, scenario, bulk_csv=out_dir / "bulk_velocity.csv"))
    return summary


def _write_vtk(h5path: Path, out_dir: Path, scenario) -> None:
    import h5py

    from ..analysis import vtk as V
    from ..analysis.summary import geometry_of
    vdir = out_dir / "vtk"
    vdir.mkdir(exist_ok=True)
    entries = []
    with h5py.File(h5path, "r") as f:
        radius = f["particles/radius"][()]
        times = f["snapshots/time"][()]
        for s in range(times.shape[0]):
            name = f"snapshot_{s:05d}.vtu"
            V.write_snapshot_vtu(vdir / name, f["snapshots/position"][s],
                                 f["snapshots/velocity"][s],
                                 f["snapshots/angular_velocity"][s], radius)
            entries.append((float(times[s]), name))
    V.write_pvd(vdir / "snapshots.pvd", entries)
    if scenario.tub is not None:
        V.write_tub_surface(vdir / "tub.vtu", geometry_of(scenario))
