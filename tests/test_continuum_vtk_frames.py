"""The continuum's ParaView frames before the averaging window (`--vtk-every`, `--vtk-from`),
read back from the files (tests/vtk_reader.py): at the asked times, in time order in the
collections, in the asked frame, with the settled bed at rest in the tub (zero velocity
relative to the tub, the tub's own velocity in the lab, by the hand-written motion of
tests/test_vtk_frame.py); they change no number of the run, and a run stopped among them and
resumed writes each once, the same bytes."""
from __future__ import annotations

import copy
import json
import math

import numpy as np
import pytest

from continuum_helpers import METHODS, THREE_CYCLES
from tests.test_vtk_frame import hand_lab, hand_motion
from tests.vtk_reader import read_pvd, read_vtk

#: per formulation: the frame of the files, the collections written, the options
CASES = {"lagrangian": ("tub", ("points", "grid"), {}),
         "eulerian": ("lab", ("grid", "tub"), {"dx": 0.015})}
#: every 5 ms from the vibration's start: 0, 5, 10, 15, 20 ms before the window's start (one
#: 21.3 ms cycle; `--vtk-from` is the command's test)
EVERY, START = 0.005, 0.0
N_EARLY = 5


def _rigid_minus(frame: str, m, t: float, d: dict) -> np.ndarray:
    """velocity_lab - velocity_relative - the tub's rigid velocity at each point of file d
    (in the file's axes): zero when the lab velocity is the relative one plus the tub's."""
    pd, p = d["PointData"], d["Points"]["points"]
    X, Z, th, Xd, Zd, thd = hand_motion(m, t)
    c, s = math.cos(th), math.sin(th)
    if frame == "lab":
        rx, rz = p[:, 0] - X - m.pivot[0], p[:, 2] - Z - m.pivot[1]
        rigid = np.stack([Xd - thd * rz, 0.0 * rx, Zd + thd * rx], axis=1)
    else:
        w = hand_lab(m, t, p)[1]
        rigid = np.stack([c * w[:, 0] + s * w[:, 2], w[:, 1], -s * w[:, 0] + c * w[:, 2]],
                         axis=1)
    return pd["velocity_lab_m_per_s"] - pd["velocity_relative_m_per_s"] - rigid


def _strip(summary: dict) -> str:
    """The summary's text without its wall times (which differ run to run)."""
    summary = copy.deepcopy(summary)
    for key in ("wall_time_s", "compile_time_s", "particle_steps_per_s", "bulk_velocity_csv"):
        summary.pop(key)
    summary["continuum"].pop("wall_time_s")
    return json.dumps(summary, sort_keys=True)


@pytest.mark.parametrize("method", METHODS)
def test_early_frames_at_their_times_at_rest_in_the_tub_and_resumable(method, tmp_path):
    from vibroflow.continuum.files import CHECKPOINT_NAME
    from vibroflow.continuum.formulation import formulation
    from vibroflow.continuum.sampling import sample_times
    from vibroflow.continuum.tub_run import run_continuum
    from vibroflow.io.vtk_frame import VtkOptions
    from vibroflow.scenario.io import load_scenario

    frame, kinds, kw = CASES[method]
    opt = formulation(method).options(**kw) if kw else None
    s = load_scenario("tub47-quick", THREE_CYCLES)
    m = s.motion
    vtk = VtkOptions(frame=frame, every=EVERY, start=START)
    full = run_continuum(s, tmp_path / "full", method, options=opt, vtk=vtk)
    plain = run_continuum(s, tmp_path / "plain", method, options=opt,
                          vtk=VtkOptions(frame=frame))
    dt = full["dt"]
    window = sample_times(s)[1]
    vdir = tmp_path / "full" / "vtk"
    for kind in kinds:
        entries = read_pvd(vdir / f"{kind}.pvd")
        times = [t for t, _ in entries]
        assert times == sorted(times)
        early = [(t, f) for t, f in entries if "early_" in f]
        # t_k = START + k EVERY up to the window's start, each at the nearest step
        want = START + EVERY * np.arange(N_EARLY)
        assert want[-1] < window < want[-1] + EVERY
        assert len(early) == N_EARLY and entries[:N_EARLY] == early
        assert np.abs(np.array([t for t, _ in early]) - want).max() <= 0.5 * dt + 1e-12
        assert len(entries) == N_EARLY + 8  # the early frames, then the last cycle's samples
        for t, name in early:
            assert read_vtk(vdir / name)["FieldData"]["time_s"][0] == t
    # the frames' velocities: the lab one is the relative one plus the tub's rigid velocity
    # (exactly), and the bed settled before the vibration is at rest in the tub at the first
    # frame (t = 0): its relative speed within the settling's residual (a few mm/s), against
    # the tub's 0.1 m/s in the lab
    first = read_pvd(vdir / f"{kinds[0]}.pvd")[0]
    d = read_vtk(vdir / first[1])
    assert np.abs(_rigid_minus(frame, m, first[0], d)).max() < 1e-12
    pd = d["PointData"]
    phi = pd["solid_fraction"].ravel()
    u = np.linalg.norm(pd["velocity_relative_m_per_s"], axis=1)
    v = np.linalg.norm(pd["velocity_lab_m_per_s"], axis=1)
    rms = (lambda a: float(np.sqrt(np.sum(phi * a * a) / np.sum(phi))))
    assert rms(u) < 0.01 < 0.1 < rms(v)
    # no number changes: the results and the window's files are those of a run without them
    assert _strip(full) == _strip(plain)
    for name in ["bulk_velocity.csv"] + [f"vtk/{f}" for kind in kinds
                                         for _, f in read_pvd(vdir / f"{kind}.pvd")
                                         if "early_" not in f]:
        assert ((tmp_path / "full" / name).read_bytes()
                == (tmp_path / "plain" / name).read_bytes()), name
    # stopped between the second and third frame, checkpointed at every event, resumed
    split = tmp_path / "split"
    busy = load_scenario("tub47-quick", THREE_CYCLES + ["run.checkpoint_every=1e-9"])
    stop = int(round((START + 1.5 * EVERY) / dt))
    assert run_continuum(busy, split, method, options=opt, vtk=vtk,
                         stop_after_steps=stop) is None
    assert (split / CHECKPOINT_NAME).is_file()
    assert len(list((split / "vtk").glob(f"{kinds[0]}_early_*"))) == 2
    resumed = run_continuum(s, split, method, options=opt, vtk=vtk, resume=True)
    assert _strip(resumed) == _strip(full)
    for kind in kinds:
        assert (split / "vtk" / f"{kind}.pvd").read_bytes() == (vdir / f"{kind}.pvd").read_bytes()
        for _, f in read_pvd(vdir / f"{kind}.pvd"):
            assert (split / "vtk" / f).read_bytes() == (vdir / f).read_bytes(), f


def test_continuum_command_takes_vtk_every(run_cli, tmp_path):
    """`vibroflow continuum --vtk --vtk-every` writes the early frames; without --vtk it is a
    one-line error naming the flag."""
    from cli_helpers import one_line_error

    r = run_cli("continuum", "tub47-quick", "--method", "eulerian", "--dx", "0.015",
                "--out", tmp_path / "bad", "--vtk-every", "0.005")
    assert one_line_error(r) == "error: --vtk-every = 0.005: needs --vtk"
    out = tmp_path / "cont"
    r = run_cli("continuum", "tub47-quick", "--method", "eulerian", "--dx", "0.015",
                "--out", out, "--vtk", "--vtk-every", "0.01", "--vtk-from", "0.001",
                *(a for s in THREE_CYCLES for a in ("--set", s)))
    assert r.returncode == 0, r.stderr
    early = [(t, f) for t, f in read_pvd(out / "vtk" / "grid.pvd") if "early_" in f]
    assert [f for _, f in early] == ["grid_early_00000.vtr", "grid_early_00001.vtr",
                                     "grid_early_00002.vtr"]
    assert np.allclose([t for t, _ in early], [0.001, 0.011, 0.021], atol=1e-4)
    assert json.loads((out / "vtk" / "vtk.json").read_text()) == {
        "frame": "tub", "every": 0.01, "start": 0.001}
