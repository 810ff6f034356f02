"""Reading LIGGGHTS/LAMMPS text dumps (custom and local): whole snapshots, or a one-line
InputError naming the file, the line, what is there and what belongs there (`read_dump`)."""
from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vibroflow.errors import InputError
from vibroflow.liggghts.template import _short

#: the longest line a dump may have (bytes): a ball row is about 150, a header a few hundred;
#: a longer "line" is no dump's (a binary file without newlines)
MAX_DUMP_LINE = 1 << 16


@dataclass(frozen=True)
class DumpSnapshot:
    """One snapshot of a dump: its step, column names, data (rows, columns) and where it is
    in the file (line numbers from 1: its ITEM: TIMESTEP and its first row)."""

    step: int
    columns: list[str]
    data: np.ndarray
    line: int
    first_row: int


def _decode(raw: bytes, path, line: int) -> str:
    try:
        return raw.decode("ascii")
    except UnicodeDecodeError as exc:
        raise InputError(f"{path}: line {line}: byte {raw[exc.start]:#04x} at column "
                         f"{exc.start + 1} is not text; a LIGGGHTS text dump is ASCII (a binary "
                         "or compressed file?)") from None


class _Lines:
    """The lines of an open binary dump, counted, each at most MAX_DUMP_LINE bytes."""

    def __init__(self, f, path):
        self.f, self.path, self.n = f, path, 0
        self.cut = False  # the last line read ends the file without a newline

    def raw(self) -> bytes:
        """The next line as bytes (with its newline), b"" at the end of the file."""
        raw = self.f.readline(MAX_DUMP_LINE + 1)
        if raw:
            self.n += 1
        self.cut = bool(raw) and not raw.endswith(b"\n")
        if len(raw) > MAX_DUMP_LINE:
            raise InputError(f"{self.path}: line {self.n}: longer than {MAX_DUMP_LINE} bytes; "
                             "not a LIGGGHTS text dump (a binary file?)")
        return raw

    def text(self) -> str | None:
        raw = self.raw()
        return _decode(raw, self.path, self.n).rstrip("\r\n") if raw else None

    def required(self, what: str) -> str:
        text = self.text()
        if text is None:
            raise InputError(f"{self.path}: the file ends after line {self.n}, where {what} "
                             "belongs (a truncated dump)")
        return text

    def misplaced(self, text: str, expected: str, why: str) -> InputError:
        """The error of the line just read, `text`, where `expected` belongs."""
        if self.cut:
            why = "the file ends within this line: a truncated dump"
        return InputError(f"{self.path}: line {self.n}: {_short(text)} where {expected} belongs "
                          f"({why})")

    def whole(self, what: str) -> int:
        text = self.required(what)
        words = text.split()
        if len(words) != 1 or not words[0].isdigit():
            raise InputError(f"{self.path}: line {self.n}: {what} = {_short(text.strip())}: "
                             "must be a whole number >= 0")
        return int(words[0])


def read_dump(path):
    """Snapshots of a LIGGGHTS/LAMMPS text dump (custom or local), as DumpSnapshot.

    Anything but whole snapshots is refused with a one-line InputError naming the file, the
    line, what is there and what belongs there: text that is not ASCII, a header out of place,
    a count that is not a whole number, more rows claimed than the rest of the file can hold
    (checked before anything is read or allocated), a snapshot cut short, a row with too few
    or too many values, a value that is not a number, and nan or inf (not data: a run that
    blew up).  Blank lines between snapshots are allowed."""
    path = Path(path)
    try:
        f = open(path, "rb")
    except OSError as exc:
        raise InputError(f"{path}: cannot be read ({(exc.strerror or str(exc)).lower()})") \
            from None
    with f:
        size = os.fstat(f.fileno()).st_size
        src = _Lines(f, path)
        while True:
            text = src.text()
            if text is None:
                return
            if not text.strip():
                continue
            if text.strip() != "ITEM: TIMESTEP":
                raise src.misplaced(text, "'ITEM: TIMESTEP' of the next snapshot",
                                    "more rows than the last ITEM: NUMBER OF says, or not a "
                                    "LIGGGHTS dump")
            at = src.n
            step = src.whole("the timestep")
            text = src.required("'ITEM: NUMBER OF ATOMS' (or ENTRIES)")
            if not text.startswith("ITEM: NUMBER OF "):
                raise src.misplaced(text, "'ITEM: NUMBER OF ATOMS' (or ENTRIES)", f"step {step}")
            what = text[len("ITEM: "):].strip()
            n = src.whole(what)
            count_line = src.n
            text = src.required("'ITEM: ATOMS' (or ENTRIES) and the column names")
            if text.startswith("ITEM: BOX BOUNDS"):
                for _ in range(3):
                    src.required("a line of the box bounds")
                text = src.required("'ITEM: ATOMS' (or ENTRIES) and the column names")
            cols = text.split()[2:]
            if not (text.startswith("ITEM: ATOMS ") or text.startswith("ITEM: ENTRIES ")) \
                    or not cols:
                raise src.misplaced(text, "'ITEM: ATOMS' (or ENTRIES) and the column names",
                                    f"step {step}")
            if len(set(cols)) != len(cols):
                raise InputError(f"{path}: line {src.n}: column names {cols}: each must appear "
                                 "once")
            k = len(cols)
            # every row is at least k one-character values and k - 1 blanks and a newline
            left = size - f.tell()
            if n and n * 2 * k - 1 > left:
                raise InputError(f"{path}: line {count_line}: {what} = {n} (step {step}), but the "
                                 f"{left} bytes left in the file hold at most "
                                 f"{(left + 1) // (2 * k)} rows of {k} values (a truncated or "
                                 "corrupt dump)")
            first = src.n + 1
            rows = []
            for i in range(n):
                raw = src.raw()
                if not raw:
                    raise InputError(f"{path}: the file ends after {i} of the {n} rows of step "
                                     f"{step} ({what} at line {count_line}; a truncated "
                                     "dump)")
                rows.append(raw)
            data = _parse_rows(path, rows, first, cols, what)
            yield DumpSnapshot(step, cols, data, at, first)


def _parse_rows(path, rows: list[bytes], first: int, cols: list[str], what: str) -> np.ndarray:
    """The rows of a snapshot as a float64 array (rows, columns); a one-line InputError at the
    first bad row (`first`: the line number of rows[0])."""
    n, k = len(rows), len(cols)
    if n == 0:
        return np.zeros((0, k))
    try:  # fast: all at once
        words = [row.split() for row in rows]
        if all(len(w) == k for w in words):
            data = np.array([x for w in words for x in w], dtype=float).reshape(n, k)
            if np.isfinite(data).all():
                return data
    except (UnicodeDecodeError, ValueError):
        pass
    # slow: row by row, to say where and what
    data = np.empty((n, k))
    for i, raw in enumerate(rows):
        line = first + i
        text = _decode(raw, path, line).strip()
        if text.startswith("ITEM:"):
            raise InputError(f"{path}: line {line}: {_short(text)} after {i} of the {n} rows "
                             f"that {what} promises (a truncated snapshot)")
        values = text.split()
        if len(values) != k:
            raise InputError(f"{path}: line {line}: {len(values)} values, expected {k} "
                             f"({' '.join(cols)}) (a cut-off line?)")
        for j, (word, col) in enumerate(zip(values, cols)):
            try:
                v = float(word)
            except ValueError:
                raise InputError(f"{path}: line {line}: {col} = {_short(word)}: not a "
                                 "number") from None
            if not math.isfinite(v):
                raise InputError(f"{path}: line {line}: {col} = {word}: must be a finite "
                                 "number (nan or inf is no data: did the run blow up?)")
            data[i, j] = v
    return data


def iter_dump(path):
    """Snapshots of a LIGGGHTS/LAMMPS text dump (custom or local): yields (step, columns, data)
    with data a float64 array (rows, columns).  Bad files: see read_dump."""
    for snap in read_dump(path):
        yield snap.step, snap.columns, snap.data


class _StepReader:
    """A local dump read in step with the ball dump: `at(step)` returns the entries of that
    step, or None when the dump has none (skipping the dump's earlier steps)."""

    def __init__(self, path: Path):
        self.path = path
        self._it = read_dump(path)
        self._pending = None

    def at(self, step: int):
        while True:
            if self._pending is None:
                self._pending = next(self._it, None)
            if self._pending is None or self._pending.step > step:
                return None
            found = self._pending
            self._pending = None
            if found.step == step:
                return found


def _whole_column(path, snap: DumpSnapshot, j: int) -> np.ndarray:
    """Column j of a snapshot as int64; InputError unless every value is a whole number
    (an atom id, a mesh or triangle index)."""
    col = snap.data[:, j]
    bad = (col != np.round(col)) | (np.abs(col) >= 2.0**53)
    if np.any(bad):
        k = int(np.argmax(bad))
        raise InputError(f"{path}: line {snap.first_row + k}: {snap.columns[j]} = "
                         f"{float(col[k])!r}: must be a whole number")
    return col.astype(np.int64)
