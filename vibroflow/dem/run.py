"""Orchestration of a DEM run: fill and settle (or the cached bed), vibrate, sample, checkpoint,
write results, summarise.  The numerics live in step.py / simulate.py; this file only decides
when things happen and where they are written.

Timeline of a tub run (tub47.md, "Procedure"), t counted from the start of the vibration:
    [0, duration - average_last)      vibrate
    [duration - average_last, end]    vibrate and sample: `phases_per_cycle` snapshots a cycle
                                      over the whole cycles of the window (with the wall
                                      contacts at those instants), and every new contact's
                                      impact.

The folder (DIR) as a run leaves it at any instant, and what `--resume` does with it:
    checkpoint.h5 + dem.parts/            go on from the checkpoint (whether or not dem.h5 is
                                          there yet: it is assembled again)
    summary.json + dem.h5                 finished (a leftover checkpoint and dem.parts are
                                          removed); nothing to run
    neither                               start afresh
A run's end keeps this true at every instant: a checkpoint of the final state, dem.h5
assembled from the parts (kept), summary.json, the checkpoint removed, the parts removed last.
A fresh run removes the previous results first, so a summary.json is always its own run's.
The checkpoint records a fingerprint of the scenario (scenario_fingerprint), the sha256 of its
own contents and of every result part it counts on: a resume of another scenario or from a
damaged file is refused in one line (InputError).  Ctrl-C (SIGINT) during the vibration writes a
checkpoint of the current state and raises errors.Interrupted; during the fill it raises
Interrupted with nothing written.
"""
from __future__ import annotations

import contextlib
import hashlib
import json
import math
import os
import shutil
import signal
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numba
import numpy as np

from ..errors import InputError, Interrupted
from ..io.atomic import write_json_atomic
from ..io.folder_lock import folder_lock
from ..progress import RunProgress
from ..run_clock import RunClock
from ..tub.motion import pose_np
from . import fill as F
from .output import (DamagedFile, ResultWriter, fault_kill_at, load_state_file,
                     save_state_file)
from .query import ball_contacts_now
from .simulate import (BlowUp, DEMState, DEMSystem, init_state, make_system, run_steps,
                       take_max_overlaps, wall_contacts_now)

SMALL_RUN = 1500  # below this many balls one thread is faster than two (thread wake-ups)

CHECKPOINT_NAME = "checkpoint.h5"
SUMMARY_NAME = "summary.json"
# what a fresh run removes before it writes: the previous run's results and checkpoint
_PREVIOUS = (CHECKPOINT_NAME, SUMMARY_NAME, "bulk_velocity.csv", "dem.h5", "dem.h5.partial")


def _scenario_toml(scenario) -> str:
    try:
        from ..scenario.io import dump_scenario
        return dump_scenario(scenario)
    except Exception:  # pragma: no cover - io module absent
        return json.dumps(scenario.model_dump(mode="json"))


def scenario_record(scenario) -> dict:
    """The scenario as plain data, less what may change on resume (run.checkpoint_every, a
    wall-clock interval that shapes no number)."""
    record = scenario.model_dump(mode="json")
    record.get("run", {}).pop("checkpoint_every", None)
    return record


def scenario_fingerprint(scenario) -> str:
    """sha256 of scenario_record: a checkpoint resumes only the scenario that wrote it."""
    text = json.dumps(scenario_record(scenario), sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def _flatten(value, prefix: str = "") -> Iterator[tuple[str, object]]:
    if isinstance(value, dict):
        for k in value:
            yield from _flatten(value[k], f"{prefix}.{k}" if prefix else str(k))
    elif isinstance(value, list) and any(isinstance(v, (dict, list)) for v in value):
        for k, v in enumerate(value):
            yield from _flatten(v, f"{prefix}.{k}")
        yield f"{prefix}.__len__", len(value)
    else:
        yield prefix, value


def first_difference(there: dict | None, now: dict) -> str:
    """"KEY = A there, B now" for the first field that differs between two scenario records
    (in the scenario's own order), or a plain remark when the record there is unknown."""
    if there is None:
        return "it records no scenario"
    a, b = dict(_flatten(there)), dict(_flatten(now))
    for key in [*b, *(k for k in a if k not in b)]:
        if a.get(key, "(none)") != b.get(key, "(none)"):
            name = key.replace(".__len__", " (count)")
            return f"{name} = {a.get(key, '(none)')} there, {b.get(key, '(none)')} now"
    return "another vibroflow's fingerprint"


def _refuse(path, what: str) -> InputError:
    return InputError(f"--resume: {path} {what}; run without --resume to start afresh")


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
    """The settled bed, from the cache or made now (and cached).  A cache entry that is
    unreadable or fails its checksum (output.load_state_file) is made again; a cache that
    cannot be written costs only the time of the next run's settling (a warning)."""
    key = F.fill_cache_key(scenario, system.nchunk)
    path = F.cache_dir() / "fills" / f"{key}.h5"
    if path.exists():
        try:
            state, attrs = load_state_file(path)
            info = json.loads(attrs.get("settle_info", "{}"))
            if state.n != scenario.fill.count:
                raise DamagedFile(path, f"{state.n} balls, not {scenario.fill.count}")
            info["cached"] = True
            prog.log(f"settled bed from cache {path}")
            return state, info
        except (DamagedFile, ValueError, TypeError, KeyError) as exc:
            prog.log(f"settled-bed cache entry {path} is damaged ({exc}): settling again")
    state = F.fill_state(system, scenario)
    n = state.n

    def progress(t, ke):
        prog.update(t, int(round(t / system.dt)) * n)
        _fault_sigint_settling()

    prog.stage("fill + settle", max(scenario.fill.settle_time, 1e-9))
    info = F.settle(system, state, scenario, progress=progress)
    info["cached"] = False
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        save_state_file(path, state, {"settle_info": json.dumps(info)})
    except OSError as exc:
        prog.log(f"warning: the settled bed cannot be cached in {path.parent} "
                 f"({(exc.strerror or str(exc)).lower()}); the next run settles it again")
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
    tub mode).  Returns the summary.

    DIR is locked (io.folder_lock) while the run writes it: a second run on it is an
    InputError naming the holder.  resume=True goes on from DIR/checkpoint.h5 bit for bit, or
    returns the summary of a finished run (see the module's docstring); InputError when the
    checkpoint is another scenario's or a file it needs is damaged.  Ctrl-C raises
    errors.Interrupted (one line: where it stopped, how to go on); BlowUp names the cause.

    Fault injection for tests (environment): VIBROFLOW_FAULT_KILL_AFTER_CHECKPOINT=1
    (_fault_after_checkpoint), VIBROFLOW_FAULT_KILL_AT=<phase of the end> (output.fault_kill_at),
    VIBROFLOW_FAULT_SIGINT_AFTER_STEPS=N (a SIGINT to itself once N vibration steps are done),
    VIBROFLOW_FAULT_SIGINT_SETTLING=1 (a SIGINT after the first settling chunk)."""
    out_dir = Path(out_dir)
    with folder_lock(out_dir, "vibroflow dem"):
        system = make_system(scenario, nchunk)
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


def _finished(out_dir: Path, fingerprint: str, record: dict) -> dict | None:
    """The summary of a finished run in out_dir (summary.json and dem.h5 there), or None;
    InputError when it is another scenario's run."""
    import h5py
    summary_path, h5 = out_dir / SUMMARY_NAME, out_dir / "dem.h5"
    if not (summary_path.is_file() and h5.is_file()):
        return None
    try:
        summary = json.loads(summary_path.read_text())
        with h5py.File(h5, "r") as f:
            there_fp = f.attrs.get("fingerprint")
            there = f.attrs.get("scenario_json")
    except (OSError, ValueError):
        return None  # not a whole result: the checkpoint, if any, decides
    if there_fp != fingerprint:
        diff = first_difference(json.loads(there) if there else None, record)
        raise _refuse(out_dir, f"holds the finished run of another scenario ({diff})")
    return summary


def _run(scenario, out_dir: Path, system: DEMSystem, vtk: bool, resume: bool,
         prog: RunProgress, clock: RunClock) -> dict:
    dt = system.dt
    ckpt = out_dir / CHECKPOINT_NAME
    explicit = scenario.explicit
    record = scenario_record(scenario)
    fingerprint = scenario_fingerprint(scenario)
    if resume:
        summary = _finished(out_dir, fingerprint, record)
        if summary is not None:
            # a run killed after its summary: only the clean-up was left
            ckpt.unlink(missing_ok=True)
            shutil.rmtree(out_dir / "dem.parts", ignore_errors=True)
            prog.log(f"{out_dir}: the run is finished already; nothing to resume")
            return summary
    if resume and ckpt.exists():
        try:
            system, state, settle_info, writer = _resumed(scenario, out_dir, system, clock,
                                                          fingerprint, record)
        except KeyboardInterrupt:
            # reading and checking only: the checkpoint and the parts it counts on are intact
            raise Interrupted(f"interrupted while reading {ckpt}; nothing changed, resume "
                              "again") from None
        prog.log(f"resuming from {ckpt} at t = {state.time(dt):.4f} s")
    else:
        if resume:
            prog.log(f"no checkpoint in {out_dir}: starting afresh")
        try:
            state, settle_info = _start(scenario, system, prog)
        except KeyboardInterrupt:
            what = "setting up the run" if explicit else "settling the fill"
            raise Interrupted(f"interrupted while {what}; nothing to resume, run again") \
                from None
        # the previous run's results go before anything of this one is written, the
        # checkpoint first (with its parts it would be resumed), so no summary.json outlives
        # the run it belongs to
        for name in _PREVIOUS:
            (out_dir / name).unlink(missing_ok=True)
        attrs = {"case": scenario.case, "n_particles": state.n, "dt": dt,
                 "frequency": scenario.motion.frequency,
                 "scenario_toml": _scenario_toml(scenario), "source": "vibroflow",
                 "fingerprint": fingerprint,
                 "scenario_json": json.dumps(record, sort_keys=True, default=str)}
        writer = ResultWriter(out_dir, state.n, attrs, state.radius)
    try:
        summary = _vibrate(scenario, out_dir, system, state, writer, prog, settle_info,
                           clock, explicit, vtk, fingerprint, record)
    except BlowUp:
        # nothing half-written stays behind: a blown-up run has no result to resume
        writer.discard()
        ckpt.unlink(missing_ok=True)
        raise
    except Interrupted:
        writer.close()
        raise
    except KeyboardInterrupt:
        # a second Ctrl-C, or one outside the main thread's deferral: the state in memory may
        # be between two updates, so the last checkpoint on disk is where to go on from
        writer.close()
        if (out_dir / SUMMARY_NAME).exists():
            raise Interrupted(f"interrupted while tidying up after the run; its results are "
                              f"complete in {out_dir} (--resume removes what is left over)") \
                from None
        if ckpt.exists():
            raise Interrupted(f"interrupted at t = {state.time(dt):.4f} s; resume from the last "
                              f"checkpoint with: vibroflow dem <the same scenario and --set> "
                              f"--resume --out {out_dir}") from None
        writer.discard()
        raise Interrupted(f"interrupted at t = {state.time(dt):.4f} s before the first "
                          "checkpoint; nothing to resume, run again") from None
    except BaseException:
        writer.close()
        raise
    return summary


def _resumed(scenario, out_dir: Path, system: DEMSystem, clock: RunClock, fingerprint: str,
             record: dict):
    """(system, state, settle_info, writer) of the run in out_dir/checkpoint.h5, its
    fingerprint, checksum and parts checked (InputError when it cannot be resumed)."""
    ckpt = out_dir / CHECKPOINT_NAME
    try:
        state, attrs = load_state_file(ckpt)
    except DamagedFile as exc:
        raise _refuse(ckpt, f"is damaged ({exc.reason})") from None
    if attrs.get("fingerprint") != fingerprint:
        there = attrs.get("scenario_json")
        diff = first_difference(json.loads(there) if there else None, record)
        raise _refuse(ckpt, f"is the checkpoint of another scenario ({diff})")
    if int(attrs["nchunk"]) != system.nchunk:
        system = make_system(scenario, int(attrs["nchunk"]))
    settle_info = json.loads(attrs["settle_info"])
    try:
        writer = ResultWriter(out_dir, state.n, {}, state.radius,
                              parts_done=int(attrs["parts_done"]),
                              part_hashes=json.loads(attrs["parts_sha256"]),
                              meta_hash=str(attrs["meta_sha256"]))
    except DamagedFile as exc:
        # "checkpoint" named: a study rewrites such a line into its own remedy
        raise _refuse(exc.path, f"is damaged ({exc.reason}), a part {ckpt.name} counts on") \
            from None
    clock.resume_from(float(attrs["wall_time_s"]))
    if attrs.get("diag") and json.loads(attrs["diag"]) is not None:
        from .simulate import _buf
        _buf(system, state).diag[:] = np.array(json.loads(attrs["diag"]))
    return system, state, settle_info, writer


def _start(scenario, system: DEMSystem, prog: RunProgress) -> tuple[DEMState, dict]:
    """The state at the start of the vibration (explicit: the given balls; tub: the settled
    bed) and the settling's record."""
    if scenario.explicit:
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
    return state, settle_info


@contextlib.contextmanager
def _deferred_sigint() -> Iterator[dict]:
    """While the block runs, a first SIGINT only sets flag["raised"]; the caller stops at its
    next safe point (state and result rows consistent) with a checkpoint.  A KeyboardInterrupt
    raised anywhere else could land between the compiled step's return and the step count's
    update, and a checkpoint of that state would resume with other numbers.  A second SIGINT
    raises KeyboardInterrupt at once.  Only in the main thread with Python's own handler in
    place (a SIGINT ignored or handled by the caller is left so)."""
    flag = {"raised": False}
    install = (threading.current_thread() is threading.main_thread()
               and signal.getsignal(signal.SIGINT) is signal.default_int_handler)

    def handler(signum, frame):
        if flag["raised"]:
            raise KeyboardInterrupt
        flag["raised"] = True

    if install:
        signal.signal(signal.SIGINT, handler)
    try:
        yield flag
    finally:
        if install:
            signal.signal(signal.SIGINT, signal.default_int_handler)


def _vibrate(scenario, out_dir, system, state, writer, prog, settle_info, clock: RunClock,
             explicit, vtk, fingerprint: str, record: dict):
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
    ckpt = out_dir / CHECKPOINT_NAME
    done_snapshots = writer.rows("snapshots/time")
    vstep = state.step - state.time_origin_step
    last_ckpt = time.perf_counter()
    stage_steps0 = vstep
    prog.stage("vibrate" if not explicit else "run", run.duration)

    def on_impacts(imp):
        writer.append("impacts", **_impact_rows(system, imp))

    def checkpoint():
        _checkpoint(ckpt, state, writer, system, settle_info, clock.solver_s(), fingerprint,
                    record)

    sigint_after = _fault_sigint_after_steps()
    with _deferred_sigint() as sigint:
        _vibration_loop(state, system, writer, prog, run, samples, done_snapshots, total,
                        window_start, explicit, f, stage_steps0, n, last_ckpt, on_impacts,
                        checkpoint, sigint, sigint_after, out_dir)
    if sigint["raised"] and ckpt.exists():
        # a SIGINT while the last rows were written: the final state's checkpoint is on disk
        raise Interrupted(f"interrupted at t = {state.time(dt):.4f} s; checkpoint written; "
                          f"resume with: vibroflow dem <the same scenario and --set> --resume "
                          f"--out {out_dir}")

    # the end, in an order that a kill at any instant leaves a folder --resume completes
    # (module docstring): dem.h5 from the parts (kept), summary.json, checkpoint, parts
    wall = clock.solver_s()
    path = writer.finish(keep_parts=True)
    fault_kill_at("assembled")
    summary = _summary(scenario, system, state, path, out_dir, wall, settle_info, explicit)
    summary["compile_time_s"] = clock.compile_s()
    if vtk:
        _write_vtk(path, out_dir, scenario)
    write_json_atomic(out_dir / SUMMARY_NAME, summary)
    fault_kill_at("summary")
    ckpt.unlink(missing_ok=True)
    fault_kill_at("checkpoint-removed")
    writer.remove_parts()
    return summary


def _vibration_loop(state, system, writer, prog, run, samples, done_snapshots, total,
                    window_start, explicit, f, stage_steps0, n, last_ckpt, on_impacts,
                    checkpoint, sigint, sigint_after, out_dir) -> None:
    """Step to the end, writing the rows of each sample and series step before stepping on;
    a checkpoint every run.checkpoint_every wall seconds and one of the final state (before
    its rows, as every checkpoint), and one at a SIGINT, which then raises Interrupted."""
    dt = system.dt
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
        now = state.step - state.time_origin_step
        prog.update(state.time(dt), (now - stage_steps0) * n)
        if sigint_after is not None and now >= sigint_after:
            sigint_after = None
            os.kill(os.getpid(), signal.SIGINT)
        written = False
        if now >= total or time.perf_counter() - last_ckpt > run.checkpoint_every:
            checkpoint()
            written = True
            last_ckpt = time.perf_counter()
            if now >= total:
                fault_kill_at("final-checkpoint")
        if sigint["raised"]:
            if not written:
                checkpoint()
            raise Interrupted(f"interrupted at t = {state.time(dt):.4f} s; checkpoint written; "
                              f"resume with: vibroflow dem <the same scenario and --set> "
                              f"--resume --out {out_dir}")


def _checkpoint(path, state, writer, system, settle_info, wall, fingerprint: str,
                record: dict):
    """The state, the count of complete result parts with their checksums, and the scenario's
    fingerprint, to DIR/checkpoint.h5 (atomically, with a checksum of its own)."""
    parts_done = writer.rotate()
    # the overlap maxima since the last series row travel too, so the series is exact
    diag = state.scratch.diag if state.scratch is not None else None
    save_state_file(path, state, {"parts_done": parts_done,
                                  "nchunk": system.nchunk, "wall_time_s": wall,
                                  "settle_info": json.dumps(settle_info),
                                  "diag": json.dumps(diag.tolist() if diag is not None
                                                     else None),
                                  "fingerprint": fingerprint,
                                  "scenario_json": json.dumps(record, sort_keys=True,
                                                              default=str),
                                  "parts_sha256": json.dumps(writer.part_hashes),
                                  "meta_sha256": writer.meta_hash})
    _fault_after_checkpoint()


def _fault_after_checkpoint() -> None:
    """Fault injection for the resume tests: with VIBROFLOW_FAULT_KILL_AFTER_CHECKPOINT=1 in
    the environment the process SIGKILLs itself as soon as its first checkpoint is on disk,
    the deterministic version of a power cut (a test that kills from outside races a fast
    machine, which may finish the run between the checkpoint and the signal)."""
    if os.environ.get("VIBROFLOW_FAULT_KILL_AFTER_CHECKPOINT") == "1":
        os.kill(os.getpid(), signal.SIGKILL)


def _fault_sigint_after_steps() -> int | None:
    """Fault injection for the Ctrl-C tests: VIBROFLOW_FAULT_SIGINT_AFTER_STEPS=N makes the
    run send itself a SIGINT as soon as N vibration steps are done (at the return of the
    compiled call that passes N), deterministic where a signal from outside races the run."""
    value = os.environ.get("VIBROFLOW_FAULT_SIGINT_AFTER_STEPS")
    return int(value) if value else None


def _fault_sigint_settling() -> None:
    """Fault injection: VIBROFLOW_FAULT_SIGINT_SETTLING=1 sends a SIGINT after each settling
    chunk (a Ctrl-C while the fill settles)."""
    if os.environ.get("VIBROFLOW_FAULT_SIGINT_SETTLING") == "1":
        os.kill(os.getpid(), signal.SIGINT)


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
    from ..measure.summary import tub_summary
    summary.update(tub_summary(h5path, scenario, bulk_csv=out_dir / "bulk_velocity.csv"))
    return summary


def _write_vtk(h5path: Path, out_dir: Path, scenario) -> None:
    import h5py

    from ..io import vtk as V
    from ..tub.geometry import geometry_of
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
