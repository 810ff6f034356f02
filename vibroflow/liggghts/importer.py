"""A LIGGGHTS run of an exported deck as vibroflow results: dem.h5 (vibroflow's DEM layout,
source "liggghts"), summary.json and bulk_velocity.csv.

The importer refuses any dump that is not whole, in one line naming the file and the line
(vibroflow.liggghts.dumps).  It recomputes the tub pose of every snapshot from the scenario (the
pose is a known function of time), so no pose file is needed.  It writes under the out folder's
lock (vibroflow.io.folder_lock) and puts its files in place only once all of them are whole.
"""
from __future__ import annotations

import contextlib
import math
import os
import shutil
import tempfile
from pathlib import Path

import h5py
import numpy as np

from vibroflow.dem.output import ResultWriter
from vibroflow.dem.part_output import PARTS_NC, part_dataset, summary_lines
from vibroflow.errors import InputError
from vibroflow.io.atomic import TMP_PREFIX, json_safe, write_json_atomic
from vibroflow.io.folder_lock import folder_lock
from vibroflow.io.run_folder import claim_for_fresh_run
from vibroflow.io.parts_file import write_parts
from vibroflow.liggghts.contacts import PairCheck, _pair_rows, _wall_rows
from vibroflow.liggghts.deck import _scenario_toml
from vibroflow.liggghts.deck_files import (BALL_DUMP, PAIR_DUMP, POST_DIR, SERIES_FILE,
                                           START_FILE, WALL_DUMP)
from vibroflow.liggghts.dumps import DumpSnapshot, _StepReader, _whole_column, read_dump
from vibroflow.liggghts.launch import loop_times
from vibroflow.liggghts.parameters import _check_exportable
from vibroflow.liggghts.part_contacts import (PartGeometry, check_outside, deck_meshes,
                                              part_impacts, part_load_rows, part_rolling)
from vibroflow.liggghts.part_deck import PART_DUMP
from vibroflow.liggghts.template import _short
from vibroflow.measure.bulk_batches import BATCHES_CSV_NAME, STDERR_CSV_NAME
from vibroflow.measure.floor_force import (FLOOR_CSV_NAME, dem_floor_cycle, weight_of,
                                           write_floor_csv)
from vibroflow.measure.summary import tub_summary
from vibroflow.scenario.io import load_scenario
from vibroflow.tub.geometry import geometry_of
from vibroflow.tub.motion import TubMotion, pose_np
from vibroflow.tub.parts import parts_of

#: the ball dump's columns the import reads (the deck's `dump custom`)
BALL_COLUMNS = ("id", "x", "y", "z", "vx", "vy", "vz", "omegax", "omegay", "omegaz", "radius")
BULK_CSV = "bulk_velocity.csv"
#: what an import writes into its out folder, in the order they are moved into place (and
#: PARTS_NC before summary.json for a scenario with parts)
IMPORT_FILES = ("dem.h5", BULK_CSV, STDERR_CSV_NAME, BATCHES_CSV_NAME, "summary.json")
#: dem.h5 stores positions and velocities as float32: larger magnitudes would be inf there
FLOAT32_MAX = float(np.finfo(np.float32).max)
#: a wall dump's snapshot without contacts (a step the dump has no entry for)
_NO_ROWS = DumpSnapshot(0, [], np.zeros((0, 9)), 0, 0)


def import_run(dump_dir, scenario=None, out_dir=None) -> dict:
    """Convert a LIGGGHTS run of an exported deck into vibroflow results.

    dump_dir: the deck's post/ folder (or the deck folder).  scenario: the Scenario run (default:
    scenario.toml next to the dumps).  out_dir: where dem.h5, summary.json and bulk_velocity.csv
    go (default: dump_dir).  Returns the summary dict.

    Bad dumps (see read_dump; also missing columns, ids that are not whole, unique and the same
    in every snapshot, steps that do not increase) raise a one-line InputError.  out_dir is
    written under its folder lock, and only at the end: the three files are made in a temporary
    folder inside it and moved into place once all of them are whole, so a failed import leaves
    out_dir as it was.
    """
    post = _resolve_dump_dir(Path(dump_dir))
    scenario = _scenario_for(post, scenario)
    _check_exportable(scenario)
    out_dir = Path(out_dir) if out_dir is not None else post
    n0 = _read_start_step(post)
    for name in IMPORT_FILES:
        if (out_dir / name).is_dir():
            raise InputError(f"--out = {str(out_dir)!r}: {name} there is a folder; the import "
                             "writes a file of that name")
    made = not out_dir.exists()
    try:
        with folder_lock(out_dir, "vibroflow import liggghts"):
            # a DEM run's or a study's folder is not the import's to replace
            claim_for_fresh_run(out_dir, "import liggghts",
                                (*IMPORT_FILES, PARTS_NC, FLOOR_CSV_NAME))
            tmp_dir = Path(tempfile.mkdtemp(prefix=f"{TMP_PREFIX}liggghts-import-",
                                            dir=out_dir))
            try:
                summary = _import(post, scenario, n0, tmp_dir)
                summary["bulk_velocity_csv"] = os.fspath(out_dir / BULK_CSV)
                write_json_atomic(tmp_dir / "summary.json", json_safe(summary))
                names = IMPORT_FILES if not scenario.parts else (*IMPORT_FILES[:-1], PARTS_NC,
                                                                 IMPORT_FILES[-1])
                (out_dir / FLOOR_CSV_NAME).unlink(missing_ok=True)  # another import's
                if (tmp_dir / FLOOR_CSV_NAME).is_file():
                    names = (FLOOR_CSV_NAME, *names)
                for name in names:  # summary.json last: it says the import is done
                    os.replace(tmp_dir / name, out_dir / name)
            finally:
                shutil.rmtree(tmp_dir, ignore_errors=True)
    except BaseException:
        if made:  # a folder made for a failed import goes again (if still empty)
            with contextlib.suppress(OSError):
                out_dir.rmdir()
        raise
    return summary


def _import(post: Path, scenario, n0: int, tmp_dir: Path) -> dict:
    """The import proper: dem.h5 and bulk_velocity.csv into tmp_dir; returns the summary."""
    run = scenario.run
    dt = run.dt
    f = scenario.motion.frequency
    motion = TubMotion.of_scenario(scenario)
    geom = geometry_of(scenario)
    rho = scenario.materials[scenario.fill.material].density

    ball_path = post / BALL_DUMP
    wall_path = post / WALL_DUMP
    walls = _StepReader(wall_path) if wall_path.is_file() else None
    # ball-ball contacts: absent from decks written before they were dumped; then dem.h5 has
    # an empty ball_contacts group, which the calibration reads as "no ball contacts"
    pair_path = post / PAIR_DUMP
    pairs = _StepReader(pair_path) if pair_path.is_file() else None
    pair_check = PairCheck()
    period = float(scenario.tub.length) if scenario.tub.periodic else 0.0
    parts = parts_of(scenario)
    part_path = post / PART_DUMP
    if parts and not part_path.is_file():
        raise InputError(f"{post}: no {PART_DUMP}; the scenario has parts, and a deck exported "
                         "with them dumps the balls near them there")
    part_geom = (PartGeometry(parts, scenario.tub.length, scenario.tub.periodic,
                              deck_meshes(post.parent, parts)) if parts else None)
    rolling = part_rolling(scenario) if parts else None

    writer = None
    ids = radius = None
    ke_t, ke_v = [], []
    n_snap = 0
    last = None
    try:
        for snap in read_dump(ball_path):
            step, cols, data = snap.step, snap.columns, snap.data
            c = {name: i for i, name in enumerate(cols)}
            missing = [name for name in BALL_COLUMNS if name not in c]
            if missing:
                raise InputError(f"{ball_path}: line {snap.first_row - 1} (step {step}): no "
                                 f"column {' '.join(missing)} (found: {' '.join(cols)}); the "
                                 f"import needs {' '.join(BALL_COLUMNS)}")
            if last is not None and step <= last:
                raise InputError(f"{ball_path}: line {snap.line + 1}: step {step} after step "
                                 f"{last}: the steps of the snapshots must increase")
            if step < n0:
                raise InputError(f"{ball_path}: line {snap.line + 1}: step {step} is before the "
                                 f"vibration's start, step {n0} ({START_FILE}): the dump and "
                                 "that file are not of one run")
            last = step
            if data.shape[0] == 0:
                raise InputError(f"{ball_path}: line {snap.line + 3}: step {step} holds no "
                                 "balls; every snapshot must hold the bed")
            stored = [c[name] for name in BALL_COLUMNS[1:10]]
            big = np.abs(data[:, stored]) > FLOAT32_MAX
            if np.any(big):
                i, j = np.unravel_index(int(np.argmax(big)), big.shape)
                raise InputError(f"{ball_path}: line {snap.first_row + i}: "
                                 f"{cols[stored[j]]} = {data[i, stored[j]]:.6g}: must be at most "
                                 f"{FLOAT32_MAX:.6g} in magnitude (dem.h5 stores float32; did "
                                 "the run blow up?)")
            these_raw = _whole_column(ball_path, snap, c["id"])
            order = np.argsort(these_raw, kind="stable")
            data = data[order]
            these = these_raw[order]
            dup = these[1:] == these[:-1]
            if np.any(dup) or these[0] < 1:
                what = (f"id {these[int(np.argmax(dup))]} appears twice" if np.any(dup)
                        else f"id {these[0]}")
                raise InputError(f"{ball_path}: step {step} (line {snap.line}): {what}; the ids "
                                 "must be whole numbers >= 1, each once")
            if ids is None:
                ids = these
                radius = data[:, c["radius"]].astype(np.float64)
                if np.any(radius <= 0):
                    k = int(np.argmax(radius <= 0))
                    raise InputError(f"{ball_path}: step {step}: radius of id {ids[k]} = "
                                     f"{radius[k]!r} m: must be > 0")
                n = ids.size
                attrs = {"case": scenario.case, "n_particles": int(n), "dt": float(dt),
                         "frequency": float(f), "scenario_toml": _scenario_toml(scenario),
                         "source": "liggghts"}
                writer = ResultWriter(tmp_dir, n, attrs, radius, parts=bool(parts))
            elif these.size != ids.size or np.any(these != ids):
                gone = np.setdiff1d(ids, these)
                new = np.setdiff1d(these, ids)
                which = ", ".join(([f"id {gone[0]} missing"] if gone.size else [])
                                  + ([f"id {new[0]} new"] if new.size else []))
                what = (f"holds {these.size} balls, not the {ids.size} of the first snapshot"
                        if these.size != ids.size else "holds other ids than the first snapshot")
                raise InputError(f"{ball_path}: step {step} (line {snap.line}) {what} ({which}; "
                                 "balls lost?); every snapshot must hold the same balls")
            t = (step - n0) * dt
            p = pose_np(motion, t)
            pose = np.array([p["X"], p["Z"], p["theta"], p["Xdot"], p["Zdot"], p["thetadot"]],
                            dtype=float)
            pos = data[:, [c["x"], c["y"], c["z"]]]
            if scenario.tub.periodic:  # LIGGGHTS wraps only when it re-neighbours
                pos[:, 1] = np.mod(pos[:, 1], scenario.tub.length)
            vel = data[:, [c["vx"], c["vy"], c["vz"]]]
            omg = data[:, [c["omegax"], c["omegay"], c["omegaz"]]]
            if parts and n_snap == 0:
                check_outside(part_geom, pos, (pose[0], pose[1], pose[2], motion.pivot_x,
                                               motion.pivot_z), ids, ball_path)
            writer.append("snapshots", time=[t], step=[step - n0], phase=[(t * f) % 1.0],
                          tub_pose=pose[None], position=pos[None].astype(np.float32),
                          velocity=vel[None].astype(np.float32),
                          angular_velocity=omg[None].astype(np.float32))
            mass = 4.0 / 3.0 * math.pi * radius**3 * rho
            ke = 0.5 * np.sum(mass * np.sum(vel**2, axis=1)) + 0.5 * np.sum(
                0.4 * mass * radius**2 * np.sum(omg**2, axis=1))
            ke_t.append(t)
            ke_v.append(ke)
            # wall contacts of this step
            wsnap = walls.at(step) if walls is not None else None
            if wsnap is not None:
                rows = _wall_rows(wsnap, n_snap, ids, pos, pose, motion, scenario, geom,
                                  wall_path)
                if rows is not None:
                    writer.append("wall_contacts", **rows)
            if parts and walls is not None:
                writer.append("part_loads", **part_load_rows(
                    wsnap if wsnap is not None else _NO_ROWS, n_snap, ids, pos,
                    (pose[0], pose[1], pose[2], motion.pivot_x, motion.pivot_z), part_geom,
                    1 if scenario.tub.periodic else 2, wall_path, omg, radius, rolling))
            # ball-ball contacts of this step: every snapshot must have its entry (a missing
            # one would read as a snapshot without contacts and bias the contact stress)
            if pairs is not None:
                psnap = pairs.at(step)
                if psnap is None:
                    raise InputError(f"{pair_path}: no entry for step {step} of {BALL_DUMP} "
                                     "(truncated dump?)")
                writer.append("ball_contacts", **_pair_rows(psnap, n_snap, ids, pos, radius,
                                                            period, pair_path, pair_check))
            n_snap += 1
        if writer is None:
            raise InputError(f"{ball_path}: no snapshot (no 'ITEM: TIMESTEP'); a LIGGGHTS run "
                             "writes one at every dump step")
        pair_check.verdict(pair_path)
        # time series: LIGGGHTS' own every series_every steps, else from the snapshots
        series = post / SERIES_FILE
        if series.is_file():
            st, sv = _read_series(series)
        else:
            st, sv = np.asarray(ke_t), np.asarray(ke_v)
        nan = np.full(st.shape, np.nan)
        writer.append("series", time=st, kinetic_energy=sv, max_overlap_ball=nan,
                      max_overlap_wall=nan)
        if parts:
            writer.append("part_impacts", **part_impacts(
                part_path, part_geom, motion, n0, dt,
                int(round((run.duration - run.average_last) / dt)), ids, rho))
        h5 = writer.finish()
        writer = None
    finally:
        if writer is not None:
            writer.close()

    summary = {"case": scenario.case, "source": "liggghts", "n_particles": int(ids.size),
               "dt": float(dt), "snapshots": n_snap}
    steps = int(round(run.duration / dt))
    summary["steps"] = steps
    summary["simulated_time_s"] = steps * dt
    log = _find_log(post)
    if log is not None:
        lt = loop_times(log)
        if lt:
            vib = lt[-1]
            summary["wall_time_s"] = sum(x.seconds for x in lt)
            summary["vibration_wall_time_s"] = vib.seconds
            summary["mpi_ranks"] = vib.procs
            summary["particle_steps_per_s"] = vib.particle_steps_per_s
    summary["balls_lost"] = int(scenario.fill.count - ids.size)
    summary["wall_contacts_available"] = wall_path.is_file()
    summary["ball_contacts_available"] = pairs is not None
    if pairs is not None:
        summary["ball_contacts"] = pair_check.contacts
        summary["ball_contacts_repulsive_fraction"] = (
            pair_check.repulsive / pair_check.contacts if pair_check.contacts else float("nan"))
    summary["impacts_available"] = False
    if parts:
        ds = part_dataset(h5, scenario, parts)
        write_parts(tmp_dir / PARTS_NC, ds)
        summary["parts"] = json_safe(summary_lines(ds, parts))
    summary.update(tub_summary(h5, scenario, bulk_csv=tmp_dir / BULK_CSV, batch_csvs=True))
    # the floor over the cycle (measure.floor_force), from the wall contacts' forces
    mass = float(np.sum(4.0 / 3.0 * np.pi * np.asarray(radius, float) ** 3 * rho))
    with h5py.File(h5, "r") as hf:
        floor = dem_floor_cycle(hf, scenario, weight_of(scenario.gravity, mass))
    if floor is not None:
        write_floor_csv(tmp_dir / FLOOR_CSV_NAME, floor)
        summary["floor"] = floor.as_dict()
    return summary


def _resolve_dump_dir(dump_dir: Path) -> Path:
    dump_dir = Path(dump_dir)
    if dump_dir.exists() and not dump_dir.is_dir():
        raise InputError(f"DUMPDIR = {str(dump_dir)!r}: a file, not a folder; give the post/ "
                         "folder (or the deck folder) of a LIGGGHTS run of an exported deck")
    for cand in (dump_dir, dump_dir / POST_DIR):
        if (cand / BALL_DUMP).is_file():
            return cand
    raise InputError(f"{dump_dir}: no LIGGGHTS dump {BALL_DUMP} here or in {dump_dir / POST_DIR}; "
                     "give the post/ folder (or the deck folder) of a LIGGGHTS run of an "
                     "exported deck")


def _scenario_for(dump_dir: Path, scenario):
    if scenario is not None:
        return scenario
    for folder in (dump_dir, dump_dir.parent):
        if (folder / "scenario.toml").is_file():
            return load_scenario(folder / "scenario.toml")
    raise InputError(f"{dump_dir}: no scenario given and no scenario.toml next to the dumps")


def _read_text(path: Path) -> str:
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise InputError(f"{path}: cannot be read ({(exc.strerror or str(exc)).lower()})") \
            from None
    text = raw.decode("ascii", errors="replace")
    if "\ufffd" in text:
        line = text[:text.index("\ufffd")].count("\n") + 1
        raise InputError(f"{path}: line {line}: not text; LIGGGHTS writes this file as ASCII "
                         "(a binary file?)")
    return text


def _read_start_step(post: Path) -> int:
    p = post / START_FILE
    if not p.is_file():
        raise InputError(f"{post}: no {START_FILE} (did the LIGGGHTS run reach the vibration?)")
    words = _read_text(p).split()
    try:
        n0 = float(words[0]) if words else math.nan
    except ValueError:
        n0 = math.nan
    if not (math.isfinite(n0) and n0 >= 0 and n0 == round(n0) and n0 < 2.0**53):
        raise InputError(f"{p}: line 1 = {_short(words[0] if words else '')}: must be the step "
                         "at which the vibration starts, a whole number >= 0")
    return int(n0)


def _read_series(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Time (s) and kinetic energy (J) of LIGGGHTS' series file: '#' comment lines, then rows
    of at least two finite numbers."""
    t, e = [], []
    for k, line in enumerate(_read_text(path).split("\n"), 1):
        words = line.split()
        if not words or words[0].startswith("#"):
            continue
        try:
            a, b = float(words[0]), float(words[1])
        except (ValueError, IndexError):
            raise InputError(f"{path}: line {k}: {_short(line.strip())}: must be two numbers, "
                             "t_vibration_s kinetic_energy_J") from None
        if not (math.isfinite(a) and math.isfinite(b)):
            raise InputError(f"{path}: line {k}: {_short(line.strip())}: must be finite numbers "
                             "(nan or inf is no data: did the run blow up?)")
        t.append(a)
        e.append(b)
    if not t:
        raise InputError(f"{path}: no rows of t_vibration_s kinetic_energy_J (did the LIGGGHTS "
                         "run reach the vibration?)")
    return np.asarray(t), np.asarray(e)


def _find_log(post: Path) -> Path | None:
    for folder in (post, post.parent):
        for name in ("log.liggghts", "log.lammps", "screen.txt"):
            if (folder / name).is_file():
                return folder / name
    return None
