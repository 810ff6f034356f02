"""The summary of a DEM run (DIR/summary.json): the run's figures, its overlaps and, in tub mode,
the measures of vibroflow.measure.summary (with bulk_velocity.csv) and the floor's force over
the cycle with the bed's take-off (vibroflow.measure.floor_force: floor.csv, "floor").
"""
from __future__ import annotations

from pathlib import Path

import h5py
import numba

from ..io.atomic import json_safe
from ..measure.floor_force import FLOOR_CSV_NAME, dem_floor_cycle, weight_of, write_floor_csv
from ..measure.summary import tub_summary
from .simulate import DEMState, DEMSystem
from .step import ASSEMBLY


def run_summary(scenario, system: DEMSystem, state: DEMState, h5path: Path, out_dir: Path,
                wall: float, settle_info: dict, explicit: bool) -> dict:
    """The summary of the finished run whose results are h5path (wall: the solver's seconds,
    settling included; particle_steps_per_s: the vibration's throughput, the settling's in
    "settle")."""
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
    # wall (s) holds the settling, when this run settled or loaded the fill, and the vibration:
    # the throughput is the vibration's alone, the settling's is in "settle"
    settle_wall = float((settle_info or {}).get("wall_time_s", 0.0))
    vib_wall = max(wall - settle_wall, 0.0)
    summary = {
        "case": scenario.case, "source": "vibroflow", "n_particles": state.n, "steps": steps,
        "dt": dt, "simulated_time_s": steps * dt, "wall_time_s": wall,
        "vibration_wall_time_s": vib_wall,
        "particle_steps_per_s": state.n * steps / vib_wall if vib_wall > 0 else None,
        "max_overlap_over_d": float(ob.max() / d) if ob.size else 0.0,
        "max_wall_overlap_over_d": float(ow.max() / d) if ow.size else 0.0,
        "max_overlap_over_d_window": float(ob[in_window].max() / d) if in_window.any()
        else 0.0,
        "max_wall_overlap_over_d_window": float(ow[in_window].max() / d) if in_window.any()
        else 0.0,
        "balls_lost": 0, "threads": numba.get_num_threads(), "assembly": ASSEMBLY,
        "neighbour_builds": state.nl.builds,
    }
    if settle_info:
        summary["settle"] = dict(settle_info)
        if settle_wall > 0 and not settle_info.get("cached", False):
            summary["settle"]["particle_steps_per_s"] = (
                state.n * settle_info["settle_time_s"] / dt / settle_wall)
    if explicit:
        summary["final_state"] = [
            {"id": i, "position": state.pos[i].tolist(), "velocity": state.vel[i].tolist(),
             "angular_velocity": state.omg[i].tolist()} for i in range(state.n)]
        return summary
    # the cell table's batches beside it (measure.bulk_batches), as a continuum run writes
    # them: a run folder alone gives each cell's error and E's (analysis.judge)
    summary.update(tub_summary(h5path, scenario, bulk_csv=out_dir / "bulk_velocity.csv",
                               batch_csvs=True))
    # the floor over the cycle (measure/floor_force.py): floor.csv and the take-off
    with h5py.File(h5path, "r") as f:
        floor = dem_floor_cycle(f, scenario, weight_of(scenario.gravity, state.mass.sum()))
    if floor is not None:
        write_floor_csv(out_dir / FLOOR_CSV_NAME, floor)
        summary["floor"] = json_safe(floor.as_dict())
    return summary

