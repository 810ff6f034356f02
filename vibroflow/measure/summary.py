"""The summary of a tub run: what tub47.md "What is measured" asks for, from a dem.h5 file.

Every method writes (or imports into) the same dem.h5 layout, so this one function serves our
DEM, LIGGGHTS imports and anything else that produces ball snapshots:

    /  attrs: case, n_particles, dt, frequency (Hz), scenario_toml
    /particles/radius (N,)
    /snapshots/time (S,), step (S,), phase (S,), tub_pose (S, 6) [X, Z, theta, Xdot, Zdot,
        thetadot], position (S, N, 3) lab, velocity (S, N, 3) lab, angular_velocity (S, N, 3)
    /wall_contacts/snapshot, particle, wall (0 = tub U), position_tub, arc, fn, ft, sliding
    /impacts/time, kind, position_tub, normal_speed
    /series/...

The averaging window is [t_end - run.average_last, t_end) with t_end = run.duration (the clock of
the tub motion: t = 0 when vibration starts), split into run.batches batches of whole cycles of
motion.frequency (stats.py).  Snapshots, wall contacts (by their snapshot) and impacts (by their
time) outside the window are not used.  Wall-contact statistics use only wall == 0 (the tub's U
surface).  Missing optional groups (/wall_contacts, /impacts) give zero counts and None means.

Values that cannot be estimated (NaN: an empty probe cell, a standard error with fewer than two
batches, a kind with no impact) are reported as None so the dict is valid JSON.
"""
from __future__ import annotations

import os
from collections.abc import Mapping

import h5py
import numpy as np

from vibroflow.io.atomic import json_safe
from vibroflow.measure.bulk import cell_table, probe_values, write_csv
from vibroflow.measure.bulk_batches import write_batch_csvs
from vibroflow.measure.circulation import circulation
from vibroflow.measure.contacts import impact_stats, impact_stats_chunked, wall_contact_stats
from vibroflow.measure.stats import batches_of_whole_cycles, cycles_in_window
from vibroflow.tub.geometry import geometry_of

BULK_CSV_NAME = "bulk_velocity.csv"


def _get(src, key, required: bool = True):
    """Dataset `key` ("group/name") from an h5py File/Group, a flat dict keyed by paths, or a
    nested dict; None when absent and not required."""
    try:
        if isinstance(src, Mapping) and key in src:
            return src[key]
        cur = src
        for part in key.split("/"):
            cur = cur[part]
        return cur
    except (KeyError, TypeError):
        if required:
            raise ValueError(f"dem.h5 input: missing dataset /{key}") from None
        return None


def _attrs(src) -> Mapping:
    a = getattr(src, "attrs", None)
    if a is None and isinstance(src, Mapping):
        a = src.get("attrs", {})
    return a if a is not None else {}


def tub_summary(source, scenario, bulk_csv=None, t_end: float | None = None,
                batch_csvs: bool = False) -> dict:
    """Summary of a tub run and its bulk_velocity.csv.

    Parameters
    ----------
    source : path of a dem.h5 file, an open h5py File/Group, or a dict of arrays keyed like the
        file ("snapshots/time", ... or nested {"snapshots": {"time": ...}}).
    scenario : the run's Scenario (tub mode): tub, motion (frequency, pivot), run (duration,
        average_last, batches), analysis (cell_size, probes).
    bulk_csv : where to write the cell table; default bulk_velocity.csv next to the dem.h5 file
        (not written when source is not a path and bulk_csv is None).
    t_end : end of the averaging window (s); default scenario.run.duration.
    batch_csvs : also write the table's batches beside bulk_csv (bulk_velocity_stderr.csv and
        bulk_velocity_batches.csv, bulk_batches.py), for a method whose snapshots are not kept.

    Returns a JSON-ready dict: probes {name: {x, z, cell_x, cell_z, vx, vz, vx_stderr,
    vz_stderr, solid_fraction, samples}}, circulation {sense, strength, strength_stderr,
    psi_extreme, x, z}, wall_contacts {mean_ft_over_fn, ratio_of_sums, sliding_fraction, count,
    and stderrs}, impacts {ball_ball_mean_normal_speed, ball_wall_mean_normal_speed, count, ...},
    window {t_start, t_end, cycles, batches, snapshots}, cells, bulk_velocity_csv.
    Units: m, m/s, m^2/s, s.
    """
    if isinstance(source, (str, os.PathLike)):
        path = os.fspath(source)
        if bulk_csv is None:
            bulk_csv = os.path.join(os.path.dirname(os.path.abspath(path)), BULK_CSV_NAME)
        with h5py.File(path, "r") as f:
            return _summary(f, scenario, bulk_csv, t_end, batch_csvs)
    return _summary(source, scenario, bulk_csv, t_end, batch_csvs)


def _summary(src, scenario, bulk_csv, t_end, batch_csvs: bool = False) -> dict:
    geometry = geometry_of(scenario)
    run, motion, analysis = scenario.run, scenario.motion, scenario.analysis
    freq = float(motion.frequency)
    attrs = _attrs(src)
    if "frequency" in attrs and not np.isclose(float(attrs["frequency"]), freq, rtol=1e-9):
        raise ValueError(f"dem.h5 frequency = {float(attrs['frequency'])} Hz: must equal the "
                         f"scenario's motion.frequency = {freq} Hz")
    t_end = float(run.duration if t_end is None else t_end)
    t_start = t_end - float(run.average_last)
    nb = int(run.batches)

    times = np.asarray(_get(src, "snapshots/time"), dtype=float)
    batch = batches_of_whole_cycles(times, t_start, t_end, freq, nb)
    n_used = int((batch >= 0).sum())
    if n_used == 0:
        raise ValueError(f"snapshots/time: no snapshot in the averaging window [{t_start}, "
                         f"{t_end}) s (snapshots span {times.min(initial=np.nan)} .. "
                         f"{times.max(initial=np.nan)} s)")
    table = cell_table(_get(src, "snapshots/position"), _get(src, "snapshots/velocity"),
                       np.asarray(_get(src, "snapshots/tub_pose"), dtype=float),
                       np.asarray(_get(src, "particles/radius"), dtype=float), geometry,
                       cell_size=analysis.cell_size, pivot=tuple(motion.pivot),
                       batch_of_sample=batch, n_batches=nb)
    if bulk_csv is not None:
        write_csv(table, bulk_csv)
        if batch_csvs:
            write_batch_csvs(table, os.path.dirname(os.path.abspath(bulk_csv)))

    probes = probe_values(table, analysis.probes)
    circ = circulation(table)

    # wall contacts: the tub's U only (wall == 0), batched by their snapshot's batch
    wall = _get(src, "wall_contacts/wall", required=False)
    if wall is not None and len(wall):
        wall = np.asarray(wall)
        snap = np.asarray(_get(src, "wall_contacts/snapshot"), dtype=np.int64)
        on_u = wall == 0
        cb = np.where((snap >= 0) & (snap < batch.size), batch[np.clip(snap, 0, batch.size - 1)],
                      -1)
        arc = _get(src, "wall_contacts/arc", required=False)
        L = geometry.wall_arc_length()
        n_arc = max(1, int(np.ceil(L / analysis.cell_size)))
        wc = wall_contact_stats(np.asarray(_get(src, "wall_contacts/fn"))[on_u],
                                np.asarray(_get(src, "wall_contacts/ft"))[on_u],
                                np.asarray(_get(src, "wall_contacts/sliding"))[on_u],
                                arc=None if arc is None else np.asarray(arc)[on_u],
                                batch=cb[on_u], n_batches=nb,
                                arc_edges=np.linspace(-0.5 * L, 0.5 * L, n_arc + 1))
    else:
        wc = wall_contact_stats(np.zeros(0), np.zeros(0), np.zeros(0, bool),
                                batch=np.zeros(0, np.int64), n_batches=nb)

    kind = _get(src, "impacts/kind", required=False)
    if kind is not None and len(kind):
        # streamed: a tub47 run holds ~25 million impacts
        im = impact_stats_chunked(kind, _get(src, "impacts/normal_speed"),
                                  _get(src, "impacts/time"), t_start, t_end, freq, nb)
    else:
        im = impact_stats(np.zeros(0, np.int64), np.zeros(0), batch=np.zeros(0, np.int64),
                          n_batches=nb)

    keep = ("x", "z", "cell_x", "cell_z", "vx", "vz", "vx_stderr", "vz_stderr",
            "solid_fraction", "samples")
    out = {
        "probes": {name: {k: rec[k] for k in (*keep, "note") if k in rec}
                   for name, rec in probes.items()},
        "circulation": circ.as_dict(),
        "wall_contacts": wc.as_dict(),
        "impacts": im.as_dict(),
        "window": {"t_start": t_start, "t_end": t_end,
                   "cycles": cycles_in_window(t_start, t_end, freq), "batches": nb,
                   "snapshots": n_used},
        "cells": len(table),
        "bulk_velocity_csv": None if bulk_csv is None else os.fspath(bulk_csv),
    }
    return json_safe(out)
