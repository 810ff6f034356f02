"""Bad input at the LIGGGHTS round trip (vibroflow.liggghts): what the deck writer refuses to
write and what the importer refuses to read.

The deck is a program (LIGGGHTS' `shell` runs anything), so no user-derived string may add a
line or a word to it: names outside the safe set are refused even when the scenario's own
validation is bypassed (model_copy does not validate), and nothing is written then.  Dumps that
are not whole (truncated, cut, binary, text in a number, nan, a count of 1e11 atoms, balls that
come and go) give one line naming the file and the line, exit code 2 from the CLI, no
traceback, and leave --out as it was.
"""
from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from tests.cli_helpers import one_line_error

from vibroflow import liggghts as LG
from vibroflow.errors import InputError
from vibroflow.io.folder_lock import LOCK_NAME
from vibroflow.liggghts import deck as LG_deck
from vibroflow.liggghts import template as LG_template
from vibroflow.scenario.model import Scenario

COLS = "id type x y z vx vy vz omegax omegay omegaz radius"
IDS = (17, 3, 9)  # LIGGGHTS ids, written out of order
N0 = 5000         # the step at which the vibration starts


def small() -> Scenario:
    """tub47's tub 19 mm long with 3 balls, 0.1 s of vibration (32 snapshots)."""
    s = Scenario()
    return s.model_copy(update={
        "case": "edges",
        "tub": s.tub.model_copy(update={"length": 0.01905}),
        "fill": s.fill.model_copy(update={"count": 3}),
        "run": s.run.model_copy(update={"duration": 0.1, "average_last": 0.09, "batches": 2,
                                        "seed": 3}),
    })


def ball_rows(k: int) -> list[str]:
    """The rows of snapshot k: three balls at rest near the bottom of the tub, 10 digits."""
    pos = {3: (0.0, 0.002, 0.02), 9: (0.0063, 0.002, 0.02), 17: (-0.0063, 0.002, 0.02 + k * 1e-6)}
    return [f"{i} 1 " + " ".join(f"{v:.10g}" for v in (*pos[i], 0.01, 0.0, -0.02, 1.0, 2.0, 3.0,
                                                     0.003175)) for i in IDS]


def dump_text(steps, rows_of=ball_rows, cols=COLS) -> str:
    """A ball dump as the deck's `dump custom` writes it."""
    out = []
    for k, step in enumerate(steps):
        rows = rows_of(k)
        out += ["ITEM: TIMESTEP", str(step), "ITEM: NUMBER OF ATOMS",
                str(len(rows)),
                "ITEM: BOX BOUNDS ff ff ff", "-0.3 0.3", "-0.03 0.05", "-0.1 0.6",
                f"ITEM: ATOMS {cols}", *rows]
    return "\n".join(out) + "\n"


@pytest.fixture(scope="module")
def template_run(tmp_path_factory):
    """An exported deck with a whole run in post/: the start step, the ball dump, series.txt."""
    root = tmp_path_factory.mktemp("run")
    info = LG.export_deck(small(), root / "deck")
    post = root / "deck" / "post"
    (post / LG.START_FILE).write_text(f"{N0}\n")
    steps = [N0 + int(r) for r in info.dump_steps]
    (post / LG.BALL_DUMP).write_text(dump_text(steps))
    (post / LG.SERIES_FILE).write_text("# t_vibration_s kinetic_energy_J\n0.0 1.5\n0.001 2.5\n")
    return root / "deck", steps


@pytest.fixture
def run(template_run, tmp_path):
    """A private copy of the run: (post folder, snapshot steps, out folder)."""
    deck, steps = template_run
    shutil.copytree(deck, tmp_path / "deck")
    return tmp_path / "deck" / "post", steps, tmp_path / "out"


def untouched(out: Path) -> bool:
    """--out, made for an import that failed, is gone again: no results, no temporaries."""
    return not out.exists()


def cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "vibroflow.cli", *map(str, args)],
                          capture_output=True, text=True, timeout=120)




# ----------------------------------------------------------------------------------------------
# The deck: nothing but what its template means

INJECTIONS = ["x\nshell rm -rf /", "x\rshell ls", "x & ", "x # c", "x$y", "x;shell ls", "x'y",
              'x"y', "x y", "", "-x", "x" * 65, "x\u2028shell ls", "x{}"]


@pytest.mark.parametrize("value", INJECTIONS)
@pytest.mark.parametrize("field", ["case", "fill.material", "tub.wall_material",
                                   "tub.partition_material"])
def test_export_refuses_a_name_that_could_change_the_deck(tmp_path, field, value):
    s = small()
    if field == "case":
        bad = s.model_copy(update={"case": value})  # model_copy does not validate
    else:
        part, name = field.split(".")
        bad = s.model_copy(update={part: getattr(s, part).model_copy(update={name: value})})
    deck = tmp_path / "deck"
    with pytest.raises(InputError) as err:
        LG.export_deck(bad, deck)
    message = err.value.message
    assert "\n" not in message and message.startswith(f"{field} = {repr(value)[:60]}")
    assert message.endswith(": must be 1 to 64 characters of A-Z a-z 0-9 _ . + -, the first a "
                            "letter or a digit (it is written into the LIGGGHTS deck)")
    assert not deck.exists()  # nothing written, not even the folder


def test_export_refuses_a_bad_count_or_processor_grid_and_writes_nothing(tmp_path):
    s = small()
    deck = tmp_path / "deck"
    for bad, match in [
        (s.model_copy(update={"fill": s.fill.model_copy(update={"count": "3\nshell ls"})}),
         r"^fill\.count = '3\\nshell ls': must be a whole number >= 1$"),
        (s.model_copy(update={"run": s.run.model_copy(update={"series_every": 2.5})}),
         r"^run\.series_every = 2\.5: must be a whole number >= 1$"),
        (s.model_copy(update={"tub": s.tub.model_copy(update={"wall_material": "unobtanium"})}),
         r"^tub\.wall_material = 'unobtanium': not one of the scenario's materials"),
        (s.model_copy(update={"materials": {**s.materials, "steel": s.materials["steel"]
                                            .model_copy(update={"density": float("nan")})}}),
         r"must be finite"),
    ]:
        with pytest.raises(InputError, match=match):
            LG.export_deck(bad, deck)
    for grid in ["* 1 1\nshell ls", "2 2", "a b c", "* 1 1 # x"]:
        with pytest.raises(InputError, match=r"^processors = .*: must be three counts"):
            LG.export_deck(s, deck, processors=grid)
    assert not deck.exists()


def test_a_name_past_a_missing_guard_is_still_refused(tmp_path, monkeypatch):
    """Defence in depth: with the name guard switched off, the deck's own line check (every
    slot one token of the safe set, every line its template's) still refuses the deck."""
    monkeypatch.setattr(LG_deck, "safe_name", lambda field, value: value)
    s = small()
    for value in ["x\nshell rm -rf /", "x'\nshell ls #", "a b"]:
        with pytest.raises(InputError, match=r"^LIGGGHTS deck value = .*nothing LIGGGHTS or a "
                                             r"shell reads specially$"):
            LG.export_deck(s.model_copy(update={"case": value}), tmp_path / "deck")
    assert not (tmp_path / "deck").exists()
    deck = LG_template._Deck()
    deck.add("label {}", "fill_loop")
    deck._lines.append(("label {}", ("x\nshell ls",)))  # a value no slot accepts
    with pytest.raises(InputError):
        deck.render("in.tub")


def test_every_line_of_a_written_deck_is_a_template_line(tmp_path):
    """A valid deck: each line is a known LIGGGHTS command or a comment, every user-derived
    token (numbers, the case, the materials) of the safe set; no line ends with '&' (which
    would join it to the next)."""
    s = small()
    LG.export_deck(s, tmp_path / "deck")
    text = (tmp_path / "deck" / "in.tub").read_text()
    assert text.isascii() and "\r" not in text
    commands = {"atom_style", "atom_modify", "boundary", "newton", "communicate", "units",
                "hard_particles", "processors", "region", "create_box", "neighbor",
                "neigh_modify", "fix", "pair_style", "pair_coeff", "timestep", "compute",
                "variable", "thermo_style", "thermo", "thermo_modify", "label", "run", "if",
                "next", "jump", "unfix", "print", "dump", "dump_modify"}
    for line in text.splitlines():
        assert not line.rstrip().endswith("&")
        if line and not line.startswith("#"):
            assert line.split()[0] in commands, line
    assert text.count("edges") == 1  # the case, in the first comment only
    readme = (tmp_path / "deck" / "README.txt").read_text()
    assert "'edges'" in readme and readme.isascii()


def test_export_holds_the_folder_lock(tmp_path):
    s = small()
    plain = tmp_path / "plain"
    plain.write_text("a file")
    with pytest.raises(InputError, match=r"^DIR = '.*plain': is a file, not a folder"):
        LG.export_deck(s, plain)
    (tmp_path / "deck").mkdir()
    (tmp_path / "deck" / "post").write_text("a file")
    with pytest.raises(InputError, match=r"^DIR = '.*post': is a file"):
        LG.export_deck(s, tmp_path / "deck")
    assert sorted(p.name for p in (tmp_path / "deck").iterdir()) == ["post"]
    # held by another process: refused, naming it
    deck = tmp_path / "held"
    with _held(deck, "vibroflow test") as pid:
        with pytest.raises(InputError, match=rf"^DIR = '.*held': in use by process {pid} "
                                             r"\(vibroflow test, since "):
            LG.export_deck(s, deck)
        assert sorted(p.name for p in deck.iterdir()) == [LOCK_NAME]
    LG.export_deck(s, deck)
    assert {p.name for p in deck.iterdir()} == {"in.tub", "README.txt", "scenario.toml",
                                                "tub_u.stl", "partitions.stl", "post"}


class _held:
    """Another process holding folder_lock(path) while the block runs; yields its pid."""

    def __init__(self, path: Path, command: str):
        code = ("import sys\nfrom vibroflow.io.folder_lock import folder_lock\n"
                f"with folder_lock({str(path)!r}, {command!r}):\n"
                "    print('held', flush=True)\n    sys.stdin.read()\n")
        self.proc = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, text=True)

    def __enter__(self) -> int:
        assert self.proc.stdout.readline().strip() == "held"
        return self.proc.pid

    def __exit__(self, *exc) -> None:
        self.proc.stdin.close()
        self.proc.wait(timeout=60)


# ----------------------------------------------------------------------------------------------
# The import: whole dumps or a one-line error

def test_the_template_run_imports(run):
    post, steps, out = run
    summary = LG.import_run(post, None, out)
    assert summary["n_particles"] == 3 and summary["snapshots"] == len(steps)
    assert summary["bulk_velocity_csv"] == os.fspath(out / "bulk_velocity.csv")
    assert sorted(p.name for p in out.iterdir()) == [
        "bulk_velocity.csv", "bulk_velocity_batches.csv", "bulk_velocity_stderr.csv", "dem.h5",
        "floor.csv", "summary.json"]


def _lines_of(post: Path) -> list[str]:
    return (post / LG.BALL_DUMP).read_text().split("\n")


def _set_lines(post: Path, lines: list[str]) -> None:
    (post / LG.BALL_DUMP).write_text("\n".join(lines))


def _row_line(k: int, row: int) -> int:
    """0-based index in the dump's lines of row `row` of snapshot k (9 header lines + 3 rows)."""
    return 12 * k + 9 + row


def _replace_in_row(post, k, row, column, value):
    lines = _lines_of(post)
    i = _row_line(k, row)
    words = lines[i].split()
    words[COLS.split().index(column)] = value
    lines[i] = " ".join(words)
    _set_lines(post, lines)
    return i + 1  # the line number in messages


def _probe(post, out, match):
    with pytest.raises(InputError) as err:
        LG.import_run(post, None, out)
    message = err.value.message
    assert "\n" not in message
    assert re.search(match, message), message
    assert untouched(out), sorted(p.name for p in out.iterdir())
    return message


def test_a_truncated_dump(run):
    post, steps, out = run
    lines = _lines_of(post)
    _set_lines(post, lines[:_row_line(len(steps) - 1, 2)])  # the last snapshot: 2 rows of 3
    _probe(post, out, rf"balls\.dump: the file ends after 2 of the 3 rows of step {steps[-1]} "
                      rf"\(NUMBER OF ATOMS at line {12 * (len(steps) - 1) + 4}; a truncated "
                      r"dump\)$")


def test_a_cut_off_line(run):
    post, steps, out = run
    text = (post / LG.BALL_DUMP).read_text()
    (post / LG.BALL_DUMP).write_text(text[:-40])  # within the last row
    n = len(text[:-40].split("\n"))
    _probe(post, out, rf"balls\.dump: line {n}: \d+ values, expected 12 \({COLS}\) \(a cut-off "
                      r"line\?\)$")


def test_a_snapshot_with_fewer_rows_than_it_claims(run):
    post, steps, out = run
    lines = _lines_of(post)
    del lines[_row_line(3, 2)]  # snapshot 3 loses a row; the next ITEM line comes early
    _set_lines(post, lines)
    _probe(post, out, rf"line {_row_line(3, 2) + 1}: 'ITEM: TIMESTEP' after 2 of the 3 rows that "
                      r"NUMBER OF ATOMS promises \(a truncated snapshot\)$")


def test_a_snapshot_with_more_rows_than_it_claims(run):
    post, steps, out = run
    lines = _lines_of(post)
    lines.insert(_row_line(2, 3), lines[_row_line(2, 0)])
    _set_lines(post, lines)
    _probe(post, out, rf"line {_row_line(2, 3) + 1}: '17 1 .*' where 'ITEM: TIMESTEP' of the "
                      r"next snapshot belongs \(more rows than the last ITEM: NUMBER OF says, or "
                      r"not a LIGGGHTS dump\)$")


@pytest.mark.parametrize("value, match", [
    ("abc", "vx = 'abc': not a number$"),
    ("0x1p3", "vx = '0x1p3': not a number$"),
    ("nan", "vx = nan: must be a finite number"),
    ("-inf", "vx = -inf: must be a finite number"),
    ("1e999", "vx = 1e999: must be a finite number"),
    ("-1e300", "vx = -1e\\+300: must be at most 3.40282e\\+38 in magnitude \\(dem.h5 stores "
               "float32; did the run blow up\\?\\)$"),
])
def test_text_nan_or_inf_in_a_number(run, value, match):
    post, steps, out = run
    line = _replace_in_row(post, 5, 1, "vx", value)
    _probe(post, out, rf"balls\.dump: line {line}: {match}")


def test_a_binary_file(run):
    post, steps, out = run
    rng = np.random.default_rng(1)
    (post / LG.BALL_DUMP).write_bytes(b"ITEM: TIMESTEP\n5000\n" + rng.bytes(4096))
    _probe(post, out, r"balls\.dump: line \d+: byte 0x[0-9a-f]{2} at column \d+ is not text; a "
                      r"LIGGGHTS text dump is ASCII")
    (post / LG.BALL_DUMP).write_bytes(bytes(b for b in range(256) if b != 10) * 2000)
    _probe(post, out, r"balls\.dump: line 1: longer than 65536 bytes; not a LIGGGHTS text dump")
    (post / LG.BALL_DUMP).write_bytes(b"\x1f\x8b\x08\x00" + rng.bytes(1000))  # gzip
    _probe(post, out, r"balls\.dump: line 1: ")


@pytest.mark.parametrize("column", ["omegax", "radius", "id"])
def test_a_missing_column(run, column):
    post, steps, out = run
    names = COLS.split()
    j = names.index(column)
    cols = " ".join(n for n in names if n != column)

    def rows(k):
        return [" ".join(w for i, w in enumerate(r.split()) if i != j) for r in ball_rows(k)]

    (post / LG.BALL_DUMP).write_text(dump_text(steps, rows, cols))
    _probe(post, out, rf"balls\.dump: line 9 \(step {steps[0]}\): no column {column} \(found: "
                      rf"{cols}\); the import needs id x y z vx vy vz omegax omegay omegaz "
                      r"radius$")


def test_a_dump_that_claims_1e11_atoms_fails_at_once(run):
    post, steps, out = run
    lines = _lines_of(post)
    lines[12 * 4 + 3] = "100000000000"
    _set_lines(post, lines)
    left = len("\n".join(lines[12 * 4 + 9:]))
    tracemalloc.start()
    _probe(post, out, rf"balls\.dump: line {12 * 4 + 4}: NUMBER OF ATOMS = 100000000000 \(step "
                      rf"{steps[4]}\), but the {left} bytes left in the file hold at most "
                      rf"{(left + 1) // 24} rows of 12 values \(a truncated or corrupt dump\)$")
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 64 * 2**20, peak  # the count is checked before anything is allocated
    lines[12 * 4 + 3] = "1e11"
    _set_lines(post, lines)
    _probe(post, out, rf"line {12 * 4 + 4}: NUMBER OF ATOMS = '1e11': must be a whole number "
                      r">= 0$")


def test_balls_that_come_and_go(run):
    post, steps, out = run
    lines = _lines_of(post)
    del lines[_row_line(6, 2)]
    lines[12 * 6 + 3] = "2"
    _set_lines(post, lines)
    _probe(post, out, rf"step {steps[6]} \(line {12 * 6 + 1}\) holds 2 balls, not the 3 of the "
                      r"first snapshot \(id 9 missing; balls lost\?\); every snapshot must hold "
                      r"the same balls$")


def test_missing_repeated_or_broken_ids(run):
    post, steps, out = run
    _replace_in_row(post, 7, 2, "id", "10")  # id 9 gone, 10 in its place
    _probe(post, out, rf"step {steps[7]} \(line {12 * 7 + 1}\) holds other ids than the first "
                      r"snapshot \(id 9 missing, id 10 new; balls lost\?\)")
    _replace_in_row(post, 7, 2, "id", "3")  # id 3 twice
    _probe(post, out, rf"step {steps[7]} \(line {12 * 7 + 1}\): id 3 appears twice; the ids "
                      r"must be whole numbers >= 1, each once$")
    _replace_in_row(post, 7, 2, "id", "9.5")
    _probe(post, out, rf"line {_row_line(7, 2) + 1}: id = 9\.5: must be a whole number$")


def test_steps_out_of_order_or_before_the_start(run):
    post, steps, out = run
    lines = _lines_of(post)
    lines[12 * 3 + 1] = str(steps[1])
    _set_lines(post, lines)
    _probe(post, out, rf"line {12 * 3 + 2}: step {steps[1]} after step {steps[2]}: the steps of "
                      r"the snapshots must increase$")
    (post / LG.START_FILE).write_text(f"{steps[-1] + 1}\n")
    _probe(post, out, rf"line 2: step {steps[0]} is before the vibration's start, step "
                      rf"{steps[-1] + 1} \(vibration_start_step\.txt\)")
    for text in ["", "abc\n", "nan\n", "-5\n", b"\xff\xfe"]:
        if isinstance(text, bytes):
            (post / LG.START_FILE).write_bytes(text)
        else:
            (post / LG.START_FILE).write_text(text)
        _probe(post, out, r"vibration_start_step\.txt: line 1")


def test_an_empty_or_headless_dump(run):
    post, steps, out = run
    (post / LG.BALL_DUMP).write_text("")
    _probe(post, out, r"balls\.dump: no snapshot \(no 'ITEM: TIMESTEP'\)")
    (post / LG.BALL_DUMP).write_text("ITEM: TIMESTEP\n")
    _probe(post, out, r"balls\.dump: the file ends after line 1, where the timestep belongs "
                      r"\(a truncated dump\)$")
    (post / LG.BALL_DUMP).write_text("some text\n")
    _probe(post, out, r"line 1: 'some text' where 'ITEM: TIMESTEP' of the next snapshot "
                      r"belongs")
    text = dump_text(steps[:2])
    (post / LG.BALL_DUMP).write_text(text[:text.rindex("ITEM: NUMBER") + 10])  # a cut header
    _probe(post, out, r"line 15: 'ITEM: NUMB' where 'ITEM: NUMBER OF ATOMS' \(or ENTRIES\) "
                      r"belongs \(the file ends within this line: a truncated dump\)$")
    (post / LG.BALL_DUMP).write_text(dump_text([steps[0]], lambda k: []))
    _probe(post, out, r"step \d+ holds no balls")


def test_a_bad_series_file(run):
    post, steps, out = run
    for text, match in [("# t e\n0.0 1.5\n0.001 abc\n", r"line 3: '0.001 abc': must be two "
                                                        r"numbers"),
                        ("# t e\n0.0 nan\n", r"line 2: '0.0 nan': must be finite numbers"),
                        ("# t e\n0.0\n", r"line 2: '0.0': must be two numbers"),
                        ("# t e\n", r"series\.txt: no rows")]:
        (post / LG.SERIES_FILE).write_text(text)
        _probe(post, out, match)


def _contact_dump(steps, rows, cols) -> str:
    out = []
    for step in steps:
        out += ["ITEM: TIMESTEP", str(step), "ITEM: NUMBER OF ENTRIES", str(len(rows)),
                "ITEM: BOX BOUNDS ff ff ff", "-1 1", "-1 1", "-1 1", f"ITEM: ENTRIES {cols}",
                *rows]
    return "\n".join(out) + "\n"


def test_bad_contact_dumps(run):
    post, steps, out = run
    pair_cols = " ".join(f"c_pairc[{k}]" for k in range(1, 7))
    wall_cols = " ".join(f"c_wallc[{k}]" for k in range(1, 10))
    cases = [
        (LG.PAIR_DUMP, _contact_dump(steps, ["9 3 0 0.5 0"], pair_cols.rsplit(" ", 1)[0]),
         r"pairs\.dump: line 9 \(step \d+\): 5 columns, expected 6"),
        (LG.PAIR_DUMP, _contact_dump(steps, ["9.5 3 0 0.5 0 0"], pair_cols),
         r"pairs\.dump: line 10: c_pairc\[1\] = 9\.5: must be a whole number$"),
        (LG.PAIR_DUMP, _contact_dump(steps, ["9 3 0 inf 0 0"], pair_cols),
         r"pairs\.dump: line 10: c_pairc\[4\] = inf: must be a finite number"),
        (LG.PAIR_DUMP, _contact_dump(steps[:3], ["9 3 0 0.5 0 0"], pair_cols),
         rf"pairs\.dump: no entry for step {steps[3]}"),
        (LG.WALL_DUMP, _contact_dump(steps, ["0 5 9 0 0 1 0 0"], wall_cols.rsplit(" ", 1)[0]),
         r"wall\.dump: line 9 \(step \d+\): 8 columns, expected 9"),
        (LG.WALL_DUMP, _contact_dump(steps, ["0 5.5 9 0 0 1 0 0 0"], wall_cols),
         r"wall\.dump: line 10: c_wallc\[2\] = 5\.5: must be a whole number$"),
    ]
    for name, text, match in cases:
        (post / name).write_text(text)
        _probe(post, out, match)
        (post / name).unlink()


def test_a_failed_import_leaves_the_earlier_results_as_they_were(run):
    post, steps, out = run
    LG.import_run(post, None, out)
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    _replace_in_row(post, 9, 0, "z", "nan")
    with pytest.raises(InputError, match="z = nan"):
        LG.import_run(post, None, out)
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


def test_import_holds_the_folder_lock(run, tmp_path):
    post, steps, out = run
    with _held(out, "vibroflow test") as pid:
        with pytest.raises(InputError, match=rf"^--out = '.*out': in use by process {pid} "):
            LG.import_run(post, None, out)
    (tmp_path / "file").write_text("x")
    with pytest.raises(InputError, match=r"^--out = '.*file': is a file, not a folder"):
        LG.import_run(post, None, tmp_path / "file")


def test_import_refuses_an_out_folder_whose_result_names_are_folders(run):
    post, steps, out = run
    (out / "dem.h5").mkdir(parents=True)
    with pytest.raises(InputError, match=r"^--out = '.*out': dem\.h5 there is a folder; the "
                                         r"import writes a file of that name$"):
        LG.import_run(post, None, out)
    assert sorted(p.name for p in out.iterdir()) == ["dem.h5"]


# ----------------------------------------------------------------------------------------------
# Through the CLI: exit code 2, one line, no traceback, --out as it was

@pytest.mark.slow  # 5 - 8 s of DEM or CLI subprocesses
def test_cli_import_of_bad_dumps(run, tmp_path):
    post, steps, out = run
    empty = tmp_path / "empty"
    empty.mkdir()
    line = one_line_error(cli("import", "liggghts", empty, "--out", out))
    assert line == (f"error: {empty}: no LIGGGHTS dump balls.dump here or in {empty}/post; give "
                    "the post/ folder (or the deck folder) of a LIGGGHTS run of an exported deck")
    assert not out.exists()
    good = (post / LG.BALL_DUMP).read_bytes()
    lines = good.decode().split("\n")
    lines[12 * 2 + 3] = "100000000000"
    probes = {
        "1e11": ("\n".join(lines).encode(), r"NUMBER OF ATOMS = 100000000000 \(step \d+\), but "),
        "binary": (b"ITEM: TIMESTEP\n\x00\xff\xfe\n", r"line 2: byte 0xff at column 2 is not "
                                                      "text"),
        "truncated": (good[:len(good) // 2], r"(the file ends|values, expected 12)"),
        "nan": (good.replace(b" 0.003175\n", b" nan\n", 1), r"line 10: radius = nan: must be "
                                                            r"a finite number"),
    }
    for name, (data, match) in probes.items():
        (post / LG.BALL_DUMP).write_bytes(data)
        line = one_line_error(cli("import", "liggghts", post, "--out", out))
        assert line.startswith(f"error: {post / LG.BALL_DUMP}: "), (name, line)
        assert re.search(match, line), (name, line)
        assert untouched(out), (name, sorted(p.name for p in out.iterdir()))


def test_cli_export_of_a_case_with_a_newline(tmp_path):
    """The scenario's validation refuses the name first; the command still ends in one line,
    exit 2, and writes nothing."""
    toml = tmp_path / "bad.toml"
    toml.write_text('case = "x\\nshell touch pwned"\n')
    line = one_line_error(cli("export", "liggghts", toml, tmp_path / "deck"))
    assert "case" in line
    assert not (tmp_path / "deck").exists()

