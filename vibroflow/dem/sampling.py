"""What a DEM run samples while it vibrates: the instants of the snapshots, and the rows of a
snapshot (balls, wall contacts, ball contacts) and of the impacts in dem.h5 (vibroflow.dem.output
has the layout).
"""
from __future__ import annotations

import math

import numpy as np

from ..tub.motion import pose_np
from . import parts as P
from .output import ResultWriter
from .query import ball_contacts_now
from .simulate import DEMState, DEMSystem, part_loads_now, wall_contacts_now


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


def impact_rows(system: DEMSystem, imp: np.ndarray) -> dict:
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


def part_impact_rows(imp: np.ndarray) -> dict:
    """Ball-part impacts (vibroflow.dem.parts' IMP_* columns) -> /part_impacts columns."""
    return {"time": imp[:, P.IMP_TIME], "part": imp[:, P.IMP_PART].astype(np.int16),
            "patch": imp[:, P.IMP_PATCH].astype(np.int16),
            "position_part": imp[:, P.IMP_X:P.IMP_Z + 1].astype(np.float32),
            "normal_speed": imp[:, P.IMP_VN].astype(np.float32),
            "tangential_speed": imp[:, P.IMP_VT].astype(np.float32),
            "energy": imp[:, P.IMP_ENERGY], "ball": imp[:, P.IMP_BALL].astype(np.int32)}


def write_snapshot(writer: ResultWriter, system: DEMSystem, state: DEMState, index: int,
                   frequency: float) -> None:
    """The rows of snapshot `index` of the state now: balls, wall contacts, ball contacts."""
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
    if system.n_parts:
        load = part_loads_now(system, state)
        writer.append("part_loads", snapshot=np.full(system.n_parts, index, np.int32),
                      part=np.arange(system.n_parts, dtype=np.int16), force=load[:, :3],
                      torque=load[:, 3:])
    bc = ball_contacts_now(system, state)
    b = bc["i"].shape[0]
    if b:
        writer.append("ball_contacts", snapshot=np.full(b, index, np.int32),
                      i=bc["i"].astype(np.int32), j=bc["j"].astype(np.int32),
                      force_lab=bc["force"].astype(np.float32))
