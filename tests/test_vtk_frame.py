"""ParaView output in one frame (vibroflow.io.vtk_frame, dem.paraview): balls fixed in the tub
have zero relative velocity and a constant tub-frame position, while in the lab frame they and
the tub's surface follow the motion's translation and rotation, written out by hand here from
tub47.md "Tub motion"; the files are read back with an independent reader (tests/vtk_reader)."""
from __future__ import annotations

import math

import h5py
import numpy as np
import pytest

from tests.cli_helpers import one_line_error
from tests.vtk_reader import read_pvd, read_vtk
from vibroflow.errors import InputError
from vibroflow.io.vtk_frame import (FIELD_UNITS, VtkOptions, cli_vtk_options,
                                    extra_frame_steps, relative_to_frame)

#: tub-frame centres (x, y, z) m of three balls held by the tub
HELD = np.array([[0.0, 0.005, 0.01], [-0.1, 0.01, 0.12], [0.12, 0.015, 0.2]])


def hand_motion(m, t):
    """X, Z, theta and their rates at t: s = a [sin(w t + phi) - sin(phi)] (tub47.md)."""
    w = 2 * math.pi * m.frequency

    def s(a, ph):
        return a * (math.sin(w * t + ph) - math.sin(ph)), a * w * math.cos(w * t + ph)

    (X, Xd), (Z, Zd), (th, thd) = (s(m.amplitude_x, m.phase_x), s(m.amplitude_z, m.phase_z),
                                   s(m.amplitude_theta, m.phase_theta))
    return X, Z, th, Xd, Zd, thd


def hand_lab(m, t, p):
    """Lab position and velocity of tub-frame points p (N, 3): P + R(theta)(p - P) + (X, Z) and
    its time derivative (X', Z') + theta' R'(theta)(p - P)."""
    X, Z, th, Xd, Zd, thd = hand_motion(m, t)
    c, s = math.cos(th), math.sin(th)
    rx, rz = p[:, 0] - m.pivot[0], p[:, 2] - m.pivot[1]
    pos = np.stack([m.pivot[0] + c * rx - s * rz + X, p[:, 1], m.pivot[1] + s * rx + c * rz + Z],
                   axis=1)
    vel = np.stack([Xd + thd * (-s * rx - c * rz), np.zeros(len(p)),
                    Zd + thd * (c * rx - s * rz)], axis=1)
    return pos, vel


def _scenario():
    from vibroflow.scenario.io import load_scenario

    return load_scenario("tub47-quick", [])


def _held_h5(path, scenario, times):
    """A dem.h5 with the snapshots of the HELD balls at `times` (lab frame, float32 as a run
    stores them)."""
    m = scenario.motion
    n = len(HELD)
    with h5py.File(path, "w") as f:
        f["particles/radius"] = np.full(n, 0.003175)
        f["snapshots/time"] = np.asarray(times)
        f["snapshots/tub_pose"] = np.array([hand_motion(m, t) for t in times])
        pos, vel = zip(*(hand_lab(m, t, HELD) for t in times))
        f["snapshots/position"] = np.array(pos, np.float32)
        f["snapshots/velocity"] = np.array(vel, np.float32)
        omg = np.zeros((len(times), n, 3), np.float32)
        omg[:, :, 1] = [[-hand_motion(m, t)[5]] * n for t in times]
        f["snapshots/angular_velocity"] = omg


TIMES = [0.0, 0.0031, 0.0077, 0.0122, 0.0168, 0.0205]


@pytest.mark.parametrize("frame", ["tub", "lab"])
def test_balls_held_by_the_tub(tmp_path, frame):
    """Balls fixed in the tub frame: in the tub frame they stand still with zero velocity
    relative to the tub at every snapshot; in the lab frame they sit where the motion carries
    them, and the tub's surface is moved by the same motion.  float32 storage: 1e-7 m, 1e-6
    m/s (the tub moves 0.44 m/s)."""
    from vibroflow.dem.paraview import write_vtk

    s = _scenario()
    m = s.motion
    h5 = tmp_path / "dem.h5"
    _held_h5(h5, s, TIMES)
    out = tmp_path / frame
    out.mkdir()
    write_vtk(h5, out, s, VtkOptions(frame=frame))
    vdir = out / "vtk"
    entries = read_pvd(vdir / "snapshots.pvd")
    assert [t for t, _ in entries] == pytest.approx(TIMES, abs=1e-15)
    ref = tmp_path / "ref"  # the tub's surface in its own frame
    ref.mkdir()
    write_vtk(h5, ref, s, VtkOptions(frame="tub"))
    surface_tub = read_vtk(ref / "vtk" / "tub.vtu")["Points"]["points"]
    for (t, name), tt in zip(entries, TIMES):
        d = read_vtk(vdir / name)
        pd, pts = d["PointData"], d["Points"]["points"]
        assert d["FieldData"]["time_s"][0] == tt
        assert set(pd) == set(FIELD_UNITS)
        assert np.abs(pd["velocity_relative_m_per_s"]).max() < 1e-6
        assert np.abs(pd["angular_velocity_relative_rad_per_s"]).max() < 1e-6
        assert np.allclose(pd["radius_m"], 0.003175)
        lab_pos, lab_vel = hand_lab(m, tt, HELD)
        # the lab speed is the same in either frame's axes
        assert np.allclose(np.linalg.norm(pd["velocity_lab_m_per_s"], axis=1),
                           np.linalg.norm(lab_vel, axis=1), atol=1e-6)
        if frame == "tub":
            assert np.abs(pts - HELD).max() < 1e-7
        else:
            assert np.abs(pts - lab_pos).max() < 1e-7
            assert np.abs(pd["velocity_lab_m_per_s"] - lab_vel).max() < 1e-6
            surf = read_vtk(vdir / f"tub_{name}")
            assert surf["FieldData"]["time_s"][0] == tt
            assert np.abs(surf["Points"]["points"] - hand_lab(m, tt, surface_tub)[0]).max() \
                < 1e-12
    if frame == "tub":
        assert (vdir / "tub.vtu").is_file() and not (vdir / "tub.pvd").exists()
    else:
        assert [f for _, f in read_pvd(vdir / "tub.pvd")] == [f"tub_{n}" for _, n in entries]
        # the motion does move them: 0.03 rad over 0.25 m is millimetres
        first = read_vtk(vdir / entries[1][1])["Points"]["points"]
        assert np.abs(first - HELD).max() > 5e-4


def test_material_at_rest_in_the_tub_moves_with_it_in_the_lab():
    """The continuum's points (tub frame, velocity relative to the tub): at rest relative to the
    tub their lab velocity is the tub's rigid velocity there; a relative velocity u in tub axes
    is R(theta) u in lab axes."""
    s = _scenario()
    m = s.motion
    t = 0.0093
    pose = np.array(hand_motion(m, t))
    pos, f = relative_to_frame("lab", HELD, np.zeros_like(HELD), pose, m.pivot)
    lab_pos, lab_vel = hand_lab(m, t, HELD)
    assert np.abs(pos - lab_pos).max() < 1e-15
    assert np.abs(f["velocity_lab_m_per_s"] - lab_vel).max() < 1e-14
    u = np.array([[0.05, 0.0, 0.0]] * 3)
    _, f = relative_to_frame("lab", HELD, u, pose, m.pivot)
    th = pose[2]
    assert np.allclose(f["velocity_relative_m_per_s"],
                       [[0.05 * math.cos(th), 0.0, 0.05 * math.sin(th)]] * 3, atol=1e-16)
    pos, f = relative_to_frame("tub", HELD, u, pose, m.pivot)
    assert np.array_equal(pos, HELD) and np.array_equal(f["velocity_relative_m_per_s"], u)


def test_early_frames_and_options():
    """Frames every 0.01 s from 0.005 s up to a window starting at 0.03 s: at 0.005, 0.015,
    0.025 s; the options' bad values are one-line input errors naming the flag."""
    opts = VtkOptions(every=0.01, start=0.005)
    assert extra_frame_steps(opts, 1.0e-5, 0.03).tolist() == [500, 1500, 2500]
    assert extra_frame_steps(VtkOptions(), 1.0e-5, 0.03).size == 0
    assert extra_frame_steps(VtkOptions(every=0.01, start=0.04), 1.0e-5, 0.03).size == 0
    assert cli_vtk_options(False, None, None, None) is None
    assert cli_vtk_options(True, None, None, None) == VtkOptions()
    for args, flag in [((False, "lab", None, None), "--vtk-frame"),
                       ((True, "side", None, None), "--vtk-frame"),
                       ((True, None, 0.0, None), "--vtk-every"),
                       ((True, None, None, 0.1), "--vtk-from"),
                       ((True, None, 0.01, -1.0), "--vtk-from")]:
        with pytest.raises(InputError, match=flag):
            cli_vtk_options(*args)


def test_vtk_flags_without_vtk_are_one_line_errors(run_cli, tmp_path):
    """`--vtk-frame` without `--vtk`: exit 2, one line naming the flag, nothing written."""
    out = tmp_path / "dem"
    line = one_line_error(run_cli("dem", "tub47-quick", "--out", out, "--vtk-frame", "lab"))
    assert "--vtk-frame = 'lab': needs --vtk" in line
    assert not out.exists()
    line = one_line_error(run_cli("run", "tub47-quick", "--out", tmp_path / "study", "--vtk",
                                  "--vtk-frame", "sideways"))
    assert "--vtk-frame = 'sideways': must be tub or lab" in line


@pytest.mark.parametrize("part_frame, frame", [("tub", "tub"), ("tub", "lab"), ("lab", "tub")])
def test_a_part_moves_in_the_frame_it_is_not_fixed_in(tmp_path, part_frame, frame):
    """tub47-bar's bar over the HELD snapshots: in its own frame one surface at rest; in the
    other frame one surface per snapshot, collected in part_bar.pvd in the snapshots' order,
    with parts.nc's map patch by patch: a tub-fixed bar in the lab frame is its surface at rest
    carried by the hand-written motion (hand_lab) at the snapshot's time, and a lab-fixed bar
    in the tub frame is the surface that motion carries back onto the one at rest."""
    from vibroflow.dem.paraview import write_vtk
    from vibroflow.io.parts_file import empty_parts_dataset, write_parts
    from vibroflow.scenario.io import load_scenario
    from vibroflow.tub.parts import parts_of, patch_layout

    s = load_scenario("tub47-bar", [f"parts.0.frame={part_frame}"])
    m = s.motion
    bar = parts_of(s)[0]
    assert bar.frame == part_frame
    names, areas = patch_layout(bar, s.tub.length)
    for out in (tmp_path / "out", tmp_path / "ref"):
        out.mkdir()
        _held_h5(out / "dem.h5", s, TIMES)
        ds = empty_parts_dataset([bar.name], [names], [areas], 8, "dem", 1.0, 4, "hand")
        ds["impact_rate_per_area"].values[0, :len(names)] = np.arange(len(names), dtype=float)
        write_parts(out / "parts.nc", ds)
    write_vtk(tmp_path / "out" / "dem.h5", tmp_path / "out", s, VtkOptions(frame=frame))
    write_vtk(tmp_path / "ref" / "dem.h5", tmp_path / "ref", s, VtkOptions(frame=part_frame))
    rest = read_vtk(tmp_path / "ref" / "vtk" / "part_bar.vtu")
    at_rest = rest["Points"]["points"]
    assert np.array_equal(rest["CellData"]["impact_rate_per_area_1_per_m2_s"],
                          rest["CellData"]["patch"].astype(float))
    vdir = tmp_path / "out" / "vtk"
    if frame == part_frame:
        assert (vdir / "part_bar.vtu").is_file() and not (vdir / "part_bar.pvd").exists()
        return
    assert not (vdir / "part_bar.vtu").exists()
    entries = read_pvd(vdir / "part_bar.pvd")
    balls = read_pvd(vdir / "snapshots.pvd")
    assert [f for _, f in entries] == [f"part_bar_{n}" for _, n in balls]
    for (t, name), tt in zip(entries, TIMES):
        d = read_vtk(vdir / name)
        pts = d["Points"]["points"]
        assert d["FieldData"]["time_s"][0] == tt
        if part_frame == "tub":
            assert np.abs(pts - hand_lab(m, tt, at_rest)[0]).max() < 1e-12
        else:
            assert np.abs(hand_lab(m, tt, pts)[0] - at_rest).max() < 1e-12
        assert np.array_equal(d["CellData"]["impact_rate_per_area_1_per_m2_s"],
                              rest["CellData"]["impact_rate_per_area_1_per_m2_s"])
    # the motion does move it: about half a millimetre at the second snapshot
    moved = read_vtk(vdir / entries[1][1])["Points"]["points"]
    assert np.abs(moved - at_rest).max() > 1e-4
