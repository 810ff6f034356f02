"""Hostile and clumsy input, caught before a run: each case is a probe of `vibroflow scenario
check` (and of the command that would run it) that must end in one line naming the field, the
value and what is allowed, exit code 2, no traceback and nothing written.

Also the command line's own edges: an output folder held by another command, an output path
that is a file, a Ctrl-C and an operating-system error, each one line with its exit code."""
from __future__ import annotations

import errno
import os
import subprocess
import sys
from pathlib import Path

import pytest
import typer

from tests.cli_helpers import one_line_error as _one_line_error

from vibroflow.cli.failures import EXIT_INTERRUPTED, input_errors
from vibroflow.errors import InputError, Interrupted
from vibroflow.io.folder_lock import LOCK_NAME, folder_lock
from vibroflow.scenario.io import load_scenario

DROP = """case = "drop"
[run]
dt = 1.0e-6
duration = 0.01
average_last = 0.0
[[particles]]
position = [0.0, 0.0, 0.01]
velocity = [0.0, 0.0, -1.0]
[[particles]]
position = [0.02, 0.0, 0.01]
[[walls]]
point = [0.0, 0.0, 0.0]
normal = [0.0, 0.0, 1.0]
"""


def _cli(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "vibroflow.cli", *args], capture_output=True,
                          text=True, cwd=cwd, timeout=120)




@pytest.fixture
def drop(tmp_path) -> Path:
    path = tmp_path / "drop.toml"
    path.write_text(DROP)
    return path


# ---------------------------------------------------------------------------------------------
# Names that reach a deck, a file name, HTML or a shell: a safe character set, at load

@pytest.mark.parametrize("key, value", [
    ("case", '"run\\nshell rm -rf /"'),       # a newline would start a new LIGGGHTS line
    ("case", '"a;b"'),
    ("case", '"../../etc"'),
    ("case", '"<script>"'),
    ("case", '"with space"'),
    ("case", '""'),
    ("case", '"' + "x" * 65 + '"'),
])
def test_unsafe_case_names_are_refused(key, value):
    with pytest.raises(InputError, match=r"^case = .*: must be a name: a letter or digit"):
        load_scenario("tub47-quick", [f"{key}={value}"])


def test_unsafe_material_and_probe_names_are_refused(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text('[materials."steel\\nshell id"]\ndensity = 7800.0\n')
    with pytest.raises(InputError, match=r"^materials key 'steel\\nshell id': must be a name"):
        load_scenario(path)
    with pytest.raises(InputError, match=r"^analysis\.probes key 'P 1': must be a name"):
        load_scenario("tub47-quick", ['analysis.probes={"P 1"={x=0.0,z=0.1}}'])


def test_a_file_name_that_is_not_a_safe_name_gives_a_safe_case(tmp_path):
    path = tmp_path / "my run; rm.toml"
    path.write_text("[run]\nduration = 0.4\naverage_last = 0.2\n")
    assert load_scenario(path).case == "my-run-rm"


# ---------------------------------------------------------------------------------------------
# Numbers: finite, and runs of a size that can be allocated and finished

@pytest.mark.parametrize("setting, field", [
    ("fill.diameter=inf", "fill.diameter = inf: must be a finite number"),
    ("materials.steel.density=inf", "materials.steel.density = inf: must be a finite number"),
    ("contacts.0.k_n=inf", "contacts.0.k_n = inf: must be a finite number"),
    ("run.duration=inf", "run.duration = inf: must be a finite number"),
    ("run.dt=nan", "run.dt = nan: must be a finite number"),
    ("gravity=[0, nan, -9.81]", "gravity.1 = nan: must be a finite number"),
    ("motion.pivot=[0.0, -inf]", "motion.pivot.1 = -inf: must be a finite number"),
    ("analysis.probes.P1.x=nan", "analysis.probes.P1.x = nan: must be a finite number"),
])
def test_non_finite_numbers_are_refused(setting, field):
    with pytest.raises(InputError) as e:
        load_scenario("tub47-quick", [setting])
    assert e.value.message == field


@pytest.mark.parametrize("setting, field", [
    ("particles.0.position=[0.0, nan, 0.01]", "particles.0.position.1 = nan"),
    ("particles.0.velocity=[inf, 0.0, 0.0]", "particles.0.velocity.0 = inf"),
    ("particles.1.angular_velocity=[0.0, 0.0, -inf]", "particles.1.angular_velocity.2 = -inf"),
    ("walls.0.point=[0.0, 0.0, nan]", "walls.0.point.2 = nan"),
])
def test_non_finite_vectors_are_refused(drop, setting, field):
    with pytest.raises(InputError, match=f"^{field.replace('.', '[.]')}: must be a finite"):
        load_scenario(drop, [setting])


def test_a_duration_that_no_machine_could_run_is_refused_before_it_allocates(drop):
    # 1e14 s at dt = 1e-6 s: 1e20 steps, whose series alone would ask numpy for 6.94 EiB
    with pytest.raises(InputError, match=r"^run\.duration = 1e\+14: 1e\+20 steps of run\.dt = "
                                         r"1e-06 s; a run may have at most 1e\+11 steps"):
        load_scenario(drop, ["run.duration=1e14"])
    with pytest.raises(InputError, match=r"^run\.series_every = 1: the series would have"):
        load_scenario(drop, ["run.duration=1000", "run.series_every=1"])
    with pytest.raises(InputError, match=r"^run\.average_last = 90000: .* snapshots of 14000 "
                                         r"balls would take .* GiB"):
        load_scenario("tub47", ["run.duration=1e5", "run.average_last=9e4"])


def test_the_vibration_period_must_hold_enough_steps():
    with pytest.raises(InputError, match=r"^motion\.frequency = 20000\.0: its period .* holds "
                                         r"5 steps of run\.dt = 1e-05 s; must hold at least 20"):
        load_scenario("tub47-quick", ["motion.frequency=2e4"])


def test_an_overfilled_tub_is_refused_with_the_room_it_has():
    # tub47's tub below its rim: (pi R^2 / 2 + 2 R (H - R)) L = 7.01e-3 m^3; 100 000 balls of
    # 6.35 mm at the loose random packing 0.555 need 2.42e-2 m^3
    with pytest.raises(InputError) as e:
        load_scenario("tub47", ["fill.count=100000"])
    assert e.value.message.startswith("fill.count = 100000: 100000 balls of d = 0.00635 m take "
                                      "0.0242 m^3 at a loose packing (0.555), more than the tub "
                                      "holds below its rim (0.00701 m^3); must be at most 29006")
    load_scenario("tub47", ["fill.count=29006"])  # the most that fits passes


def test_a_tub_too_small_for_one_ball_is_refused():
    with pytest.raises(InputError, match=r"^tub\.length = 0\.001: shorter than one insertion"):
        load_scenario("tub47-quick", ["tub.length=0.001"])
    with pytest.raises(InputError, match=r"^tub\.radius = 0\.005: the tub is narrower than two"):
        load_scenario("tub47-quick", ["tub.radius=0.005", "tub.rim_height=0.4"])


def test_the_analysis_grid_must_be_of_a_size_that_fits():
    with pytest.raises(InputError,
                       match=r"^analysis\.cell_size = 1e-05 with tub\.radius .* cells"):
        load_scenario("tub47-quick", ["analysis.cell_size=1e-5"])


# ---------------------------------------------------------------------------------------------
# Explicit mode: a start that would blow up at the first step is bad input, said as such

def test_coincident_balls_are_refused(drop):
    with pytest.raises(InputError) as e:
        load_scenario(drop, ["particles.1.position=[0.0, 0.0, 0.01]"])
    assert e.value.message == ("particles.1.position = [0, 0, 0.01]: the same position as "
                               "particles.0; balls must not overlap")


def test_overlapping_balls_are_refused_beyond_the_blow_up_bound(drop):
    # centres 4 mm apart, d = 6.35 mm: an overlap of 2.35 mm = 0.370 d > run.max_overlap 0.25
    with pytest.raises(InputError) as e:
        load_scenario(drop, ["particles.1.position=[0.004, 0.0, 0.01]"])
    assert e.value.message == ("particles.1.position = [0.004, 0, 0.01]: overlaps particles.0 "
                               "by 0.37 of the smaller diameter; must be below run.max_overlap "
                               "= 0.25")
    load_scenario(drop, ["particles.1.position=[0.0055, 0.0, 0.01]"])  # 0.134 d: allowed


def test_overlaps_are_found_among_many_balls(tmp_path):
    # 300 balls (the k-d tree's branch): one pair overlapping, found and named by its indices
    lines = ['case = "many"', "[run]", "dt = 1.0e-6", "duration = 0.01", "average_last = 0.0"]
    for i in range(300):
        x = 0.01 * (i % 20)
        z = 0.01 + 0.01 * (i // 20)
        if i == 217:
            x += 0.001 - 0.01  # 1 mm from ball 216
        lines += ["[[particles]]", f"position = [{x!r}, 0.0, {z!r}]"]
    path = tmp_path / "many.toml"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match=r"^particles\.217\.position = .*: overlaps "
                                         r"particles\.216 by 0\.843 of the smaller diameter"):
        load_scenario(path)


def test_balls_behind_a_wall_or_deep_in_it_are_refused(drop):
    with pytest.raises(InputError, match=r"^particles\.0\.position = \[0, 0, -0\.001\]: the "
                                         r"ball's centre is 0\.001 m behind walls\.0"):
        load_scenario(drop, ["particles.0.position=[0.0, 0.0, -0.001]"])
    with pytest.raises(InputError, match=r"^particles\.0\.position = \[0, 0, 0\.0005\]: the "
                                         r"ball overlaps walls\.0 by 0\.421 of its diameter"):
        load_scenario(drop, ["particles.0.position=[0.0, 0.0, 0.0005]"])


def test_scenario_check_says_it_in_one_line_and_dem_writes_nothing(drop, tmp_path):
    r = _cli("scenario", "check", str(drop), "--set", "particles.1.position=[0.0, 0.0, 0.01]")
    assert _one_line_error(r).startswith("error: particles.1.position = [0, 0, 0.01]: the same")
    out = tmp_path / "out"
    r = _cli("dem", str(drop), "--out", str(out), "--set", "run.duration=inf")
    assert _one_line_error(r) == "error: run.duration = inf: must be a finite number"
    assert not out.exists()


@pytest.mark.parametrize("command", ["continuum", "run", "sweep"])
def test_an_explicit_scenario_is_refused_by_the_tub_commands_in_one_line(drop, tmp_path,
                                                                        command):
    out = tmp_path / "out"
    line = _one_line_error(_cli(command, str(drop), "--out", str(out)))
    assert line.endswith("needs a tub-mode scenario (with [tub] and [fill]), not explicit "
                         "particles"), line
    assert not out.exists()


# ---------------------------------------------------------------------------------------------
# Output folders: one writer at a time; a file or a read-only folder is bad input

@pytest.mark.slow  # 5 - 8 s of DEM or CLI subprocesses
def test_a_folder_in_use_is_refused_naming_its_holder(drop, tmp_path):
    out = tmp_path / "out"
    with folder_lock(out, "vibroflow dem"):
        for args in (["dem", str(drop), "--out", str(out)],
                     ["run", "tub47-quick", "--out", str(out)],
                     ["report", str(out)]):
            line = _one_line_error(_cli(*args))
            assert line.startswith(f"error: {'DIR' if args[0] != 'dem' else '--out'} = "
                                   f"'{out}': in use by process {os.getpid()} (vibroflow dem, "
                                   "since "), line
        assert sorted(p.name for p in out.iterdir()) == [LOCK_NAME]
    assert not (out / LOCK_NAME).exists()  # released: the folder is as it was


def test_a_process_may_nest_the_lock_of_its_own_folder(tmp_path):
    with folder_lock(tmp_path / "a", "outer"):
        with folder_lock(tmp_path / "a", "inner"):
            pass
        assert (tmp_path / "a" / LOCK_NAME).exists()  # still held by the outer one
    assert not (tmp_path / "a" / LOCK_NAME).exists()


def test_a_killed_holder_leaves_no_lock(tmp_path):
    # flock belongs to the open file: the kernel releases it when its process dies, SIGKILL too
    out = tmp_path / "out"
    code = ("import os, signal\nfrom vibroflow.io.folder_lock import folder_lock\n"
            f"with folder_lock({str(out)!r}, 'x'):\n    os.kill(os.getpid(), signal.SIGKILL)\n")
    assert subprocess.run([sys.executable, "-c", code]).returncode == -9
    assert (out / LOCK_NAME).exists()  # the file stays, the lock does not
    with folder_lock(out, "next"):
        pass


@pytest.mark.parametrize("command", ["dem", "run", "sweep"])
def test_an_output_path_that_is_a_file_is_refused(drop, tmp_path, command):
    a_file = tmp_path / "a_file"
    a_file.write_text("precious\n")
    args = [str(drop)] if command == "dem" else ["tub47-quick"]
    for target in (a_file, a_file / "sub"):
        line = _one_line_error(_cli(command, *args, "--out", str(target)))
        assert "is a file" in line or "not a folder" in line, line
    assert a_file.read_text() == "precious\n"


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_a_read_only_output_folder_is_refused(drop, tmp_path):
    out = tmp_path / "ro"
    out.mkdir()
    out.chmod(0o500)
    try:
        line = _one_line_error(_cli("dem", str(drop), "--out", str(out)))
        assert line == f"error: --out = '{out}': not writable (permission denied); give a " \
                       "folder you may write"
    finally:
        out.chmod(0o700)


# ---------------------------------------------------------------------------------------------
# The command line's wrapper: Ctrl-C and operating-system errors in one line

def _wrapped(exc: BaseException):
    @input_errors
    def command():
        raise exc
    return command


@pytest.mark.parametrize("exc, line", [
    (Interrupted("interrupted at t = 0.1234 s; resume with --resume"),
     "interrupted at t = 0.1234 s; resume with --resume"),
    (KeyboardInterrupt(), "interrupted"),
])
def test_ctrl_c_is_one_line_and_exit_130(capsys, exc, line):
    with pytest.raises(typer.Exit) as e:
        _wrapped(exc)()
    assert e.value.exit_code == EXIT_INTERRUPTED == 130
    assert capsys.readouterr().err == line + "\n"


@pytest.mark.parametrize("exc, code, line", [
    (PermissionError(errno.EACCES, "Permission denied", "/x/summary.json"), 2,
     "error: /x/summary.json: permission denied"),
    (OSError(errno.ENOSPC, "No space left on device", "/x/dem.h5"), 1,
     "error: /x/dem.h5: no space left on device"),
])
def test_operating_system_errors_are_one_line(capsys, exc, code, line):
    with pytest.raises(typer.Exit) as e:
        _wrapped(exc)()
    assert e.value.exit_code == code
    assert capsys.readouterr().err == line + "\n"


def test_a_bug_is_not_disguised_as_input(capsys):
    with pytest.raises(ZeroDivisionError):
        _wrapped(ZeroDivisionError("a bug"))()


# ---------------------------------------------------------------------------------------------
# Results read back (`vibroflow compare`): a table that is not one is one line

SEEDS = Path(__file__).resolve().parent / "data" / "tub47-dem-seeds"


@pytest.mark.parametrize("cell, words", [
    ("nan", "row 2, column samples = nan: must be a finite number"),
    ("inf", "row 2, column samples = inf: must be a finite number"),
    ("abc", "could not convert string 'abc'"),
    ("-5", "row 2: solid_fraction = 0.1912256727, samples = -5.0: must be >= 0"),
])
def test_compare_refuses_a_bulk_table_with_no_measurement_in_it(tmp_path, cell, words):
    import shutil

    run = tmp_path / "run"
    shutil.copytree(SEEDS / "seed1", run)
    lines = (run / "bulk_velocity.csv").read_text().splitlines()
    lines[2] = lines[2].rsplit(",", 1)[0] + "," + cell
    (run / "bulk_velocity.csv").write_text("\n".join(lines) + "\n")
    r = _cli("compare", str(run), "-r", str(SEEDS / "seed2"), "--e-seed", "0.2")
    line = _one_line_error(r)
    assert line.startswith(f"error: {run / 'bulk_velocity.csv'}: ") and words in line, line


# ---------------------------------------------------------------------------------------------
# A fresh run replaces only its own command's files (vibroflow/io/run_folder.py)

def _files(folder: Path) -> dict[str, str]:
    return {p.name: p.read_text() for p in folder.iterdir() if p.is_file()}


@pytest.mark.parametrize("command, holds, named", [
    ("dem", {"summary.json": '{"source": "vibroflow continuum"}', "stress.csv": "x\n"},
     "a `vibroflow continuum` run"),
    ("dem", {"checkpoint.npz": "x"}, "a `vibroflow continuum` run"),
    ("dem", {"study.json": '{"kind": "vibroflow study"}'}, "a study"),
    ("dem", {"sweep.json": '{"kind": "vibroflow sweep"}'}, "a sweep"),
    ("continuum", {"summary.json": '{"source": "vibroflow"}', "floor.csv": "x\n"},
     "a `vibroflow dem` run"),
    ("continuum", {"summary.json": '{"source": "liggghts"}'}, "a LIGGGHTS import"),
    ("continuum", {"summary.json": "my notes\n", "notes.txt": "keep\n"},
     "a summary.json that no vibroflow run wrote"),
    ("continuum", {"floor.csv": "mine\n"}, "files that no vibroflow continuum run wrote"),
])
def test_a_folder_of_another_commands_results_is_refused_and_kept(drop, tmp_path, command,
                                                                   holds, named):
    out = tmp_path / "out"
    out.mkdir()
    for name, text in holds.items():
        (out / name).write_text(text)
    before = _files(out)
    args = [str(drop)] if command == "dem" else ["tub47-quick", "--stop-after-steps", "1"]
    line = _one_line_error(_cli(command, *args, "--out", str(out)))
    assert named in line and "replaces only its own runs' files" in line, line
    assert _files(out) == before


def test_a_folder_of_the_same_command_or_of_other_files_is_the_runs_to_write(tmp_path):
    from vibroflow.io.run_folder import claim_for_fresh_run

    replaces = ("summary.json", "floor.csv", "vtk")
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("keep\n")
    claim_for_fresh_run(out, "continuum", replaces)          # other files only
    (out / "vtk").mkdir()
    (out / "vtk" / "points_0001.vtu").write_text("x")
    claim_for_fresh_run(out, "continuum", replaces)          # a stopped run's frames
    (out / "vtk" / "mine.png").write_text("x")
    with pytest.raises(InputError, match=r"files that no vibroflow continuum run wrote there "
                                         r"\(vtk\)"):
        claim_for_fresh_run(out, "continuum", replaces)
    (out / "summary.json").write_text('{"source": "vibroflow continuum"}')
    claim_for_fresh_run(out, "continuum", replaces)          # an earlier continuum run's
    with pytest.raises(InputError, match="a `vibroflow continuum` run"):
        claim_for_fresh_run(out, "dem", replaces)


# ---------------------------------------------------------------------------------------------
# The parser's own errors, the thread counts and an empty folder name: one line, exit 2

@pytest.mark.parametrize("args, words", [
    (["dem", "DROP", "--threads", "abc", "--out", "OUT"], ["'--threads'", "'abc'"]),
    (["dem", "DROP"], ["Missing option '--out'"]),
    (["dem", "DROP", "--out", "OUT", "--bogus"], ["No such option: --bogus"]),
    (["continuum", "tub47-quick", "--dx", "abc", "--out", "OUT"], ["'--dx'", "'abc'"]),
    (["bogus"], ["No such command 'bogus'"]),
    (["scenario", "check", "tub47-quick", "extra"], ["unexpected extra argument"]),
    (["dem", "DROP", "--threads", "100000", "--out", "OUT"], ["--threads = 100000: at most"]),
    (["dem", "DROP", "--out", ""], ["'--out'", "an empty path"]),
    (["export", "liggghts", "tub47-quick", ""], ["'DIR'", "an empty path"]),
])
def test_the_parsers_errors_are_one_line_and_write_nothing(drop, tmp_path, args, words):
    out = tmp_path / "out"
    args = [str(drop) if a == "DROP" else str(out) if a == "OUT" else a for a in args]
    work = tmp_path / "cwd"
    work.mkdir()
    line = _one_line_error(_cli(*args, cwd=work))
    for w in words:
        assert w in line, line
    assert not out.exists() and not any(work.iterdir())


@pytest.mark.parametrize("value", ["abc", "0", "-3"])
def test_a_bad_numba_num_threads_is_one_line(drop, tmp_path, value):
    r = subprocess.run([sys.executable, "-m", "vibroflow.cli", "dem", str(drop), "--out",
                        str(tmp_path / "out")], capture_output=True, text=True, timeout=120,
                       env={**os.environ, "NUMBA_NUM_THREADS": value})
    line = _one_line_error(r)
    assert line.startswith(f"error: NUMBA_NUM_THREADS = '{value}': a whole number of threads")
    assert not (tmp_path / "out").exists()


# ---------------------------------------------------------------------------------------------
# What a run cannot take, known before it starts (vibroflow/scenario/checks.py)

@pytest.mark.parametrize("setting, words", [
    ("materials.steel.density=1e-300", r"^fill\.diameter = 0\.00635 m with materials\.steel\."
                                       r"density = 1e-300 kg/m\^3: a ball weighs"),
    ("fill.diameter=1e-300", r"^fill\.diameter = 1e-300 m with .* must weigh 1e-20 - 1e\+06 kg"),
    ("fill.insert_above=1e6", r"^fill\.insert_above = 1000000\.0: .* below tub\.rim_height"),
    ("tub.length=1e6", r"^tub\.radius = .*tub\.length = 1000000\.0: the tub spans .* cubes"),
    ("motion.amplitude_x=1e3", r"^motion\.amplitude_x, amplitude_z, amplitude_theta = 1000\.0, "
                               r".* ball diameters a step"),
    ("motion.pivot=[1e9, 0.0]", r"pivot \(1000000000\.0, 0\.0\) m.* ball diameters a step"),
    ("motion.amplitude_factor=1e9", r"amplitude_factor 1000000000\.0.* ball diameters a step"),
    ("gravity=[0.0, 0.0, 9.81]", r"^gravity = \[0, 0, 9\.81\]: in a tub run it must pull down"),
    ("gravity=[0.0, 0.0, -1e300]", r"^gravity = .*: 1e\+300 m/s\^2; must be at most 10000"),
    ("fill.count=true", r"^fill\.count = true: must be a number, not true or false"),
    ("run.duration=false", r"^run\.duration = false: must be a number"),
])
def test_what_a_run_cannot_take_is_refused_before_it(setting, words):
    with pytest.raises(InputError, match=words):
        load_scenario("tub47-quick", [setting])


def test_the_reference_case_and_its_amplitude_sweep_pass_the_checks():
    for factor in ("0.5", "1.0", "1.5", "3.0"):
        load_scenario("tub47", [f"motion.amplitude_factor={factor}"])
    load_scenario("tub47-quick", [])


def test_an_export_replaces_only_an_earlier_exports_deck(tmp_path):
    from vibroflow.liggghts import export_deck

    s = load_scenario("tub47-quick", [])
    deck = tmp_path / "deck"
    export_deck(s, deck)
    export_deck(s, deck)                                     # an earlier export's: replaced
    # an earlier deck's inputs that this one does not write go: no stale part beside it
    export_deck(load_scenario("tub47-bar", []), deck)
    assert (deck / "part_bar.stl").is_file()
    export_deck(s, deck)
    assert not (deck / "part_bar.stl").exists()
    assert "part_bar" not in (deck / "in.tub").read_text()
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "scenario.toml").write_text("# my notes\n")
    with pytest.raises(InputError, match=r"holds scenario\.toml, which no `vibroflow export "
                                         r"liggghts` wrote there"):
        export_deck(s, mine)
    assert (mine / "scenario.toml").read_text() == "# my notes\n"
    run = tmp_path / "run"
    run.mkdir()
    (run / "summary.json").write_text('{"source": "vibroflow"}')
    with pytest.raises(InputError, match=r"holds the results of a `vibroflow dem` run"):
        export_deck(s, run)
    assert sorted(p.name for p in run.iterdir()) == ["summary.json"]
