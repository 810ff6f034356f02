"""The edges of a DEM run: the output folder's lock, resume of another scenario, a
kill at every phase of a run's end, damaged checkpoints, parts and fill-cache entries, Ctrl-C,
and the blow-up's cause read from the state.

Runs are small explicit scenarios (a few steel balls bouncing on a plate, milliseconds of
simulated time) and, where the fill matters, a 200-ball tub47-quick; kills are deterministic
(the fault-injection hooks of vibroflow.dem.interrupts and vibroflow.dem.output, DEVELOPERS.md
"Tests that kill a run"), never a race against the run.
"""
from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from vibroflow.dem.run import run_dem
from vibroflow.dem.simulate import BlowUp
from vibroflow.errors import InputError, Interrupted
from vibroflow.io.folder_lock import folder_lock
from vibroflow.scenario.io import load_scenario

sys.path.insert(0, str(Path(__file__).parent))
import dem_helpers as H  # noqa: E402

# four balls falling onto a steel plate and bouncing on it: contacts with the plate and each
# other, 3000 steps of 10 us (0.03 s), a series row every 100 steps
BOUNCE = """
case = "bounce"
gravity = [0.0, 0.0, -9.81]
[run]
dt = 1.0e-5
duration = 0.03
average_last = 0.0
checkpoint_every = 1000.0
[[particles]]
position = [0.0, 0.0, 0.0035]
velocity = [0.0, 0.0, -0.5]
[[particles]]
position = [0.0066, 0.0, 0.0040]
velocity = [-0.3, 0.0, -0.2]
[[particles]]
position = [0.0030, 0.0040, 0.0100]
velocity = [0.0, -0.1, -0.8]
[[particles]]
position = [-0.0070, 0.0010, 0.0050]
velocity = [0.2, 0.0, 0.0]
[[walls]]
point = [0.0, 0.0, 0.0]
normal = [0.0, 0.0, 1.0]
material = "steel"
"""

# summary entries that are clocks or machine facts, not results
TIMES = {"wall_time_s", "vibration_wall_time_s", "compile_time_s", "particle_steps_per_s",
         "threads"}


def _cli(*args, env=None, **kw):
    return subprocess.run([sys.executable, "-m", "vibroflow.cli", *args], capture_output=True,
                          text=True, env=env, **kw)


def _env(tmp_path, **extra):
    env = dict(os.environ)
    env["VIBROFLOW_CACHE"] = str(tmp_path / "cache")
    env.update(extra)
    return env


def _names(folder: Path) -> list[str]:
    """The folder's entries but its lock file (io.folder_lock)."""
    return sorted(p.name for p in folder.iterdir() if p.name != ".vibroflow.lock")


def _last_line(r) -> str:
    lines = r.stderr.strip().splitlines()
    return lines[-1] if lines else ""


def _one_line_error(r, code=2) -> str:
    assert r.returncode == code, (r.returncode, r.stderr)
    assert "Traceback" not in r.stderr, r.stderr
    return _last_line(r)


@pytest.fixture(scope="module")
def bounce_toml(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("scenario") / "bounce.toml"
    path.write_text(BOUNCE)
    return path


@pytest.fixture(scope="module")
def bounce_ref(tmp_path_factory, bounce_toml) -> Path:
    """An uninterrupted run of BOUNCE: the numbers every interrupted one must reproduce."""
    out = tmp_path_factory.mktemp("ref") / "ref"
    run_dem(load_scenario(bounce_toml), out, progress=False)
    return out


def _results(summary: dict) -> dict:
    """The summary less its timings (the settling's too): what a resumed run must repeat."""
    out = {k: v for k, v in summary.items() if k not in TIMES}
    if "settle" in out:
        out["settle"] = {k: v for k, v in out["settle"].items() if k not in TIMES}
    return out


def _same_h5(a: Path, b: Path) -> None:
    with h5py.File(a) as fa, h5py.File(b) as fb:
        for group in ("snapshots", "wall_contacts", "ball_contacts", "impacts", "series"):
            for name in fa[group]:
                x, y = fa[group][name][()], fb[group][name][()]
                assert x.shape == y.shape, f"{group}/{name}: {x.shape} != {y.shape}"
                assert np.array_equal(x, y, equal_nan=True), f"{group}/{name} differs"
        assert np.array_equal(fa["particles/radius"][()], fb["particles/radius"][()])


def _same_as_ref(out: Path, ref: Path) -> None:
    a = json.loads((ref / "summary.json").read_text())
    b = json.loads((out / "summary.json").read_text())
    assert _results(a) == _results(b)
    _same_h5(ref / "dem.h5", out / "dem.h5")
    assert not (out / "checkpoint.h5").exists() and not (out / "dem.parts").exists()


# ---------------------------------------------------------------------------------------------
# A. the folder lock


def test_second_run_on_a_locked_folder_is_refused_and_leaves_it_alone(tmp_path, bounce_toml):
    """While one process holds --out, `vibroflow dem` there exits 2 with one line naming the
    holder, and run_dem raises InputError, both without touching the folder."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "summary.json").write_text('{"mine": 1}\n')
    with folder_lock(out, "vibroflow dem"):
        r = _cli("dem", str(bounce_toml), "--out", str(out), env=_env(tmp_path))
        line = _one_line_error(r)
        assert f"process {os.getpid()} (vibroflow dem" in line and "in use" in line, line
    # the lock held by another process, the run in this one (a library call)
    holder = subprocess.Popen(
        [sys.executable, "-c", "import sys, time\n"
         "from vibroflow.io.folder_lock import folder_lock\n"
         "with folder_lock(sys.argv[1], 'vibroflow dem'):\n"
         "    print('held', flush=True)\n"
         "    time.sleep(60)\n", str(out)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        with pytest.raises(InputError, match=f"process {holder.pid} "):
            run_dem(load_scenario(bounce_toml), out, progress=False)
    finally:
        holder.kill()
        holder.wait()
    assert (out / "summary.json").read_text() == '{"mine": 1}\n'
    assert _names(out) == ["summary.json"]


# ---------------------------------------------------------------------------------------------
# B. resume checks the scenario


@pytest.mark.slow  # 5 - 8 s of DEM or CLI subprocesses
def test_resume_with_another_scenario_is_refused(tmp_path, bounce_toml):
    """A checkpoint resumes only its own scenario: another --set is refused in one line that
    names the first field that differs; run.checkpoint_every may change."""
    out = tmp_path / "out"
    env = _env(tmp_path, VIBROFLOW_FAULT_KILL_AT="final-checkpoint")
    r = _cli("dem", str(bounce_toml), "--out", str(out), env=env)
    assert r.returncode == -signal.SIGKILL, (r.returncode, r.stderr)
    ckpt = out / "checkpoint.h5"
    r = _cli("dem", str(bounce_toml), "--out", str(out), "--resume", "--set",
             "run.duration=0.04", env=_env(tmp_path))
    line = _one_line_error(r)
    assert line.endswith(f"--resume: {ckpt} is the checkpoint of another scenario "
                         "(run.duration = 0.03 there, 0.04 now); run without --resume to "
                         "start afresh"), line
    with pytest.raises(InputError, match=r"particles\.2\.velocity = \[0\.0, -0\.1, -0\.8\] "
                                         r"there, \[0\.0, -0\.1, -0\.9\] now"):
        run_dem(load_scenario(bounce_toml, ["particles.2.velocity=[0.0, -0.1, -0.9]"]), out,
                resume=True, progress=False)
    assert ckpt.exists() and not (out / "summary.json").exists()
    # the interval between checkpoints is no part of the physics
    summary = run_dem(load_scenario(bounce_toml, ["run.checkpoint_every=500.0"]), out,
                      resume=True, progress=False)
    assert summary["steps"] == 3000
    with h5py.File(out / "dem.h5") as f:
        assert "duration = 0.03" in f.attrs["scenario_toml"]


# ---------------------------------------------------------------------------------------------
# C. a kill at any instant of the end


@pytest.mark.parametrize("phase", ["final-checkpoint", "assembling", "assembled", "summary",
                                   "checkpoint-removed"])
def test_kill_at_each_phase_of_the_end_then_resume(tmp_path, bounce_toml, bounce_ref, phase):
    """SIGKILL at each phase of a run's end (output.fault_kill_at); --resume completes the
    folder to the uninterrupted run's summary (clocks aside) and dem.h5, bit for bit, and a
    plain rerun of the killed folder does too."""
    out = tmp_path / "out"
    r = _cli("dem", str(bounce_toml), "--out", str(out),
             env=_env(tmp_path, VIBROFLOW_FAULT_KILL_AT=phase))
    assert r.returncode == -signal.SIGKILL, (r.returncode, r.stderr)
    assert (out / "dem.parts").is_dir()
    again = tmp_path / "again"
    __import__("shutil").copytree(out, again)
    summary = run_dem(load_scenario(bounce_toml), out, resume=True, progress=False)
    _same_as_ref(out, bounce_ref)
    assert _results(summary) == _results(json.loads((out / "summary.json").read_text()))
    # resuming a finished folder says so and changes nothing
    before = (out / "summary.json").read_bytes()
    assert _results(run_dem(load_scenario(bounce_toml), out, resume=True,
                            progress=False)) == _results(summary)
    assert (out / "summary.json").read_bytes() == before
    # a plain rerun of the killed folder starts afresh and gets the same
    run_dem(load_scenario(bounce_toml), again, progress=False)
    _same_as_ref(again, bounce_ref)


def test_killed_mid_run_resumes_from_its_checkpoint(tmp_path, bounce_toml, bounce_ref):
    """The existing kill after the first checkpoint, with a checkpoint every step chunk: the
    parts it counts on are verified and the run completes bit for bit."""
    out = tmp_path / "out"
    r = _cli("dem", str(bounce_toml), "--out", str(out), "--set", "run.checkpoint_every=1e-9",
             env=_env(tmp_path, VIBROFLOW_FAULT_KILL_AFTER_CHECKPOINT="1"))
    assert r.returncode == -signal.SIGKILL, (r.returncode, r.stderr)
    r = _cli("dem", str(bounce_toml), "--out", str(out), "--resume", env=_env(tmp_path))
    assert r.returncode == 0, r.stderr
    _same_as_ref(out, bounce_ref)


# ---------------------------------------------------------------------------------------------
# D. damaged checkpoints, parts and fill-cache entries


def _killed_with_checkpoint(tmp_path, bounce_toml) -> Path:
    out = tmp_path / "out"
    r = _cli("dem", str(bounce_toml), "--out", str(out), "--set", "run.checkpoint_every=1e-9",
             env=_env(tmp_path, VIBROFLOW_FAULT_KILL_AT="final-checkpoint"))
    assert r.returncode == -signal.SIGKILL, (r.returncode, r.stderr)
    return out


def _flip_byte_in(path: Path, dataset: str) -> None:
    with h5py.File(path, "r") as f:
        ds = f[dataset]
        offset = ds.id.get_offset()
        assert offset is not None, "a contiguous dataset"
        offset += ds.id.get_storage_size() // 2
    with open(path, "r+b") as f:
        f.seek(offset)
        b = f.read(1)
        f.seek(offset)
        f.write(bytes([b[0] ^ 0x01]))


def test_damaged_checkpoint_is_refused_in_one_line(tmp_path, bounce_toml, bounce_ref):
    """A flipped byte in a state array, a truncated and an empty checkpoint: each resume is
    refused in one line (exit 2) naming the file and the damage, and a plain rerun still
    completes the folder."""
    out = _killed_with_checkpoint(tmp_path, bounce_toml)
    ckpt = out / "checkpoint.h5"
    good = ckpt.read_bytes()
    env = _env(tmp_path)
    tail = "; run without --resume to start afresh"
    _flip_byte_in(ckpt, "state/vel")
    r = _cli("dem", str(bounce_toml), "--out", str(out), "--resume", env=env)
    assert _one_line_error(r).endswith(f"--resume: {ckpt} is damaged (checksum mismatch){tail}")
    ckpt.write_bytes(good[: len(good) // 2])
    r = _cli("dem", str(bounce_toml), "--out", str(out), "--resume", env=env)
    assert _one_line_error(r).endswith(f"--resume: {ckpt} is damaged (truncated){tail}")
    ckpt.write_bytes(b"")
    with pytest.raises(InputError, match=r"is damaged \(empty\); run without --resume"):
        run_dem(load_scenario(bounce_toml), out, resume=True, progress=False)
    ckpt.write_bytes(b"not an HDF5 file at all\n" * 100)
    with pytest.raises(InputError, match=r"is damaged \(not an HDF5 file\)"):
        run_dem(load_scenario(bounce_toml), out, resume=True, progress=False)
    # the attributes that matter are in the checksum too
    ckpt.write_bytes(good)
    with h5py.File(ckpt, "r+") as f:
        f.attrs["parts_done"] = int(f.attrs["parts_done"]) - 1
    with pytest.raises(InputError, match=r"is damaged \(checksum mismatch\)"):
        run_dem(load_scenario(bounce_toml), out, resume=True, progress=False)
    run_dem(load_scenario(bounce_toml), out, progress=False)
    _same_as_ref(out, bounce_ref)


def test_damaged_part_is_refused_in_one_line(tmp_path, bounce_toml, bounce_ref):
    out = _killed_with_checkpoint(tmp_path, bounce_toml)
    part = out / "dem.parts" / "part_00000.h5"
    data = bytearray(part.read_bytes())
    data[len(data) // 2] ^= 0x01
    part.write_bytes(bytes(data))
    with pytest.raises(InputError) as err:
        run_dem(load_scenario(bounce_toml), out, resume=True, progress=False)
    assert str(err.value) == (f"--resume: {part} is damaged (checksum mismatch), a part "
                              "checkpoint.h5 counts on; run without --resume to start afresh")
    part.unlink()
    with pytest.raises(InputError, match=r"part_00000\.h5 is damaged \(missing\)"):
        run_dem(load_scenario(bounce_toml), out, resume=True, progress=False)
    assert (out / "checkpoint.h5").exists()  # refused, not consumed


# 200 balls settled for 20 ms, vibrated for 4 cycles (85 ms, the fewest a summary takes)
SMALL_FILL = ["fill.count=200", "fill.settle_time=0.02", "fill.max_settle_time=0.02",
              "run.duration=0.086", "run.average_last=0.086"]


@pytest.mark.slow  # 5 - 8 s of DEM or CLI subprocesses
def test_damaged_fill_cache_entry_is_made_again(tmp_path, monkeypatch):
    """A cached settled bed with a flipped byte is settled again (the same bed: the settling
    is deterministic), never used."""
    monkeypatch.setenv("VIBROFLOW_CACHE", str(tmp_path / "cache"))
    scenario = load_scenario("tub47-quick", SMALL_FILL)
    first = run_dem(scenario, tmp_path / "a", progress=False)
    assert first["settle"]["cached"] is False
    (entry,) = (tmp_path / "cache" / "fills").glob("*.h5")
    _flip_byte_in(entry, "state/pos")
    second = run_dem(scenario, tmp_path / "b", progress=False)
    assert second["settle"]["cached"] is False
    third = run_dem(scenario, tmp_path / "c", progress=False)
    assert third["settle"]["cached"] is True
    _same_h5(tmp_path / "a" / "dem.h5", tmp_path / "c" / "dem.h5")
    entry.write_bytes(entry.read_bytes()[:1000])
    assert run_dem(scenario, tmp_path / "d", progress=False)["settle"]["cached"] is False


# ---------------------------------------------------------------------------------------------
# E. Ctrl-C


def test_ctrl_c_writes_a_checkpoint_and_resume_is_bit_for_bit(tmp_path, monkeypatch,
                                                            bounce_toml, bounce_ref):
    """A SIGINT during the vibration (sent by the run itself after 1000 steps: deterministic)
    stops the run at its next safe point with a checkpoint and Interrupted; --resume ends with
    the uninterrupted run's final state, bit for bit."""
    out = tmp_path / "out"
    monkeypatch.setenv("VIBROFLOW_FAULT_SIGINT_AFTER_STEPS", "1000")
    with pytest.raises(Interrupted) as err:
        run_dem(load_scenario(bounce_toml), out, progress=False)
    assert str(err.value) == ("interrupted at t = 0.0100 s; checkpoint written; resume with: "
                              "vibroflow dem <the same scenario and --set> --resume --out "
                              f"{out}")
    assert (out / "checkpoint.h5").exists() and not (out / "summary.json").exists()
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    monkeypatch.delenv("VIBROFLOW_FAULT_SIGINT_AFTER_STEPS")
    summary = run_dem(load_scenario(bounce_toml), out, resume=True, progress=False)
    ref = json.loads((bounce_ref / "summary.json").read_text())
    assert summary["final_state"] == ref["final_state"]
    _same_as_ref(out, bounce_ref)


def test_ctrl_c_at_the_last_step_is_resumable(tmp_path, monkeypatch, bounce_toml, bounce_ref):
    """A SIGINT with the last step done: the final state's checkpoint is there to go on from."""
    out = tmp_path / "out"
    monkeypatch.setenv("VIBROFLOW_FAULT_SIGINT_AFTER_STEPS", "3000")
    with pytest.raises(Interrupted, match=r"^interrupted at t = 0\.0300 s; checkpoint written"):
        run_dem(load_scenario(bounce_toml), out, progress=False)
    monkeypatch.delenv("VIBROFLOW_FAULT_SIGINT_AFTER_STEPS")
    run_dem(load_scenario(bounce_toml), out, resume=True, progress=False)
    _same_as_ref(out, bounce_ref)


def test_ctrl_c_in_the_cli_exits_130_in_one_line(tmp_path, bounce_toml):
    out = tmp_path / "out"
    r = _cli("dem", str(bounce_toml), "--out", str(out),
             env=_env(tmp_path, VIBROFLOW_FAULT_SIGINT_AFTER_STEPS="500"))
    assert r.returncode == 130, r.stderr
    assert "Traceback" not in r.stderr
    assert _last_line(r).endswith(f"interrupted at t = 0.0050 s; checkpoint written; resume "
                                  f"with: vibroflow dem <the same scenario and --set> --resume "
                                  f"--out {out}")
    assert (out / "checkpoint.h5").exists()


def test_ctrl_c_while_settling_leaves_nothing(tmp_path, monkeypatch):
    monkeypatch.setenv("VIBROFLOW_CACHE", str(tmp_path / "cache"))
    monkeypatch.setenv("VIBROFLOW_FAULT_SIGINT_SETTLING", "1")
    out = tmp_path / "out"
    with pytest.raises(Interrupted) as err:
        run_dem(load_scenario("tub47-quick", SMALL_FILL), out, progress=False)
    assert str(err.value) == "interrupted while settling the fill; nothing to resume, run again"
    assert _names(out) == []
    assert not list((tmp_path / "cache").rglob("*.h5"))


# ---------------------------------------------------------------------------------------------
# F. the blow-up's cause


def _two_balls(**update):
    sc = H.scenario([H.ball((0.0, 0.0, 0.01)), H.ball((0.02, 0.0, 0.01))], [H.contact()],
                    walls=[H.plane()], dt=1e-5, duration=0.01)
    return sc


def _with(sc, particles=None, dt=None):
    update = {}
    if particles is not None:
        update["particles"] = particles
    if dt is not None:
        update["run"] = sc.run.model_copy(update={"dt": dt})
    return sc.model_copy(update=update)


def _blowup(sc, tmp_path) -> str:
    out = tmp_path / "out"
    with pytest.raises(BlowUp) as err:
        run_dem(sc, out, progress=False)
    assert "\n" not in str(err.value)
    assert not (out / "summary.json").exists() and not (out / "dem.parts").exists()
    return str(err.value)


def test_blow_up_of_non_finite_input_names_balls_and_fields(tmp_path):
    sc = _two_balls()
    p0, p1 = sc.particles
    msg = _blowup(_with(sc, [p0.model_copy(update={"velocity": (0.0, math.inf, 0.0)}),
                             p1.model_copy(update={"position": (math.nan, 0.0, 0.01)})]),
                  tmp_path)
    assert msg == ("blow-up at t = 0 s: non-finite input: ball 1 position = (nan, 0, 0.01), "
                   "ball 0 velocity = (0, inf, 0); the starting state must be finite (radius "
                   "and mass > 0); not a time-step problem")


def test_blow_up_of_coincident_balls_names_both(tmp_path):
    sc = _two_balls()
    p0, _ = sc.particles
    msg = _blowup(_with(sc, [p0, p0.model_copy()]), tmp_path)
    assert msg.startswith("blow-up at t = 0 s: balls 0 and 1 are coincident (both centres at "
                          "(0, 0, 0.01) m)"), msg
    assert "time step" not in msg.replace("not a time-step problem", "")


def test_blow_up_of_overlap_at_start_and_ball_behind_wall(tmp_path):
    sc = _two_balls()
    p0, p1 = sc.particles
    msg = _blowup(_with(sc, [p0, p1.model_copy(update={"position": (0.7 * H.D_STEEL, 0.0,
                                                                   0.01)})]), tmp_path)
    assert msg == ("blow-up at t = 0 s: balls 0 and 1 overlap by 30.0% of d at the start "
                   "(bound 25%): the starting positions overlap; not a time-step problem")
    msg = _blowup(_with(sc, [p0, p1.model_copy(update={"position": (0.02, 0.0, -0.01)})]),
                  tmp_path)
    assert msg == ("blow-up at t = 0 s: ball 1 is behind wall 3 (plane walls[0]) at the start: "
                   "its centre (0.02, 0, -0.01) m lies 10 mm beyond the wall; the starting "
                   "positions put it there; not a time-step problem")


def test_blow_up_names_the_time_step_only_when_it_is_the_cause(tmp_path):
    """A ball squeezed between two plates: with dt = 0.62 t_c the integration is unstable and
    the time step is named, against the one contact there is, ball on plate (m_eff = m:
    t_c = pi / (sqrt(k_n / m) sqrt(1 - zeta^2)) = 0.322 ms; a lone ball has no ball-ball pair); the soft-contact blow-up of test_dem_run names the stiffness and
    calls the step enough."""
    g = 0.05 * H.D_STEEL
    sc = H.scenario([H.ball((0.0, 0.0, H.R_STEEL - g - 0.02 * H.D_STEEL))], [H.contact()],
                    walls=[H.plane(), H.plane(point=(0.0, 0.0, H.D_STEEL - 2 * g),
                                              normal=(0.0, 0.0, -1.0))],
                    dt=1e-5, duration=0.01)
    msg = _blowup(_with(sc, dt=2e-4), tmp_path)
    assert msg.startswith("blow-up at t = 0.0004 s: ball 0 overlaps wall 3 (plane walls[0]) by"
                          ), msg
    m = H.sphere_mass(H.R_STEEL, H.RHO_STEEL)
    t_c = math.pi / (math.sqrt(1.0e5 / m) * math.sqrt(1.0 - H.zeta_of(0.85) ** 2))
    assert f"{t_c:.3g}" == "0.000322"
    assert msg.endswith("likely cause: time step dt = 0.0002 s, 1.6 steps per shortest contact "
                        "time 0.000322 s, too large (at least 10 needed)"), msg
    soft = H.scenario([H.ball((0.0, 0.0, 0.0), vel=(2.0, 0.0, 0.0)),
                       H.ball((0.0064, 0.0, 0.0), vel=(-2.0, 0.0, 0.0))],
                      [H.contact(k_n=20.0, e=0.9)], dt=1e-5, duration=0.01)
    msg = _blowup(soft, tmp_path)
    assert "balls 0 and 1 overlap by" in msg and "contact stiffness k_n too low" in msg
    assert msg.endswith("s: enough)") and "relative speed" in msg, msg


def test_blow_up_of_a_ball_outside_the_tub(tmp_path):
    """A library call that starts a tub run with a ball below the tub's floor."""
    from vibroflow.dem import simulate as S
    sc = load_scenario("tub47-quick", SMALL_FILL)
    system = S.make_system(sc)
    # beside the tub, above its rim: touching no wall, outside all the same
    y = 0.5 * sc.tub.length
    pos = [(0.0, y, 0.01), (sc.tub.radius + 0.05, y, sc.tub.rim_height + 0.01)]
    with pytest.raises(S.BlowUp) as err:
        S.init_state(system, pos, np.zeros((2, 3)), np.zeros((2, 3)),
                     [0.5 * sc.fill.diameter] * 2, [7800.0] * 2, [0, 0])
    assert "ball(s) [1] start outside the tub" in str(err.value), str(err.value)
