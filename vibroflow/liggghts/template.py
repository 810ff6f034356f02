"""What user input may put into a deck.

A LIGGGHTS deck is a program: a newline in a value starts a new command (and `shell` runs
anything), `&` at a line's end joins the next line, `#` starts a comment, `$` substitutes a
variable, quotes group words.  So the deck is built from lines whose text is a literal of
this package (a template) with slots ("{}") for values, and every value is rendered as one
token of a small safe set: a number (_fmt), a whole number, or a name of SAFE_NAME's
characters.  A scenario can then fill a slot but never add a word, a line, a comment, a
variable or a quoted string the template did not have; the written text is checked line by
line against the templates (`_Deck.render`) before anything goes to disk.
"""
from __future__ import annotations

import math
import re

import numpy as np

from vibroflow.errors import InputError

#: the names a deck or its README may carry (case, materials, file names): the scenario's own
#: rule for names
SAFE_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.+-]{0,63}")
SAFE_NAME_RULE = ("1 to 64 characters of A-Z a-z 0-9 _ . + -, the first a letter or a digit "
                  "(it is written into the LIGGGHTS deck)")
#: one value of a deck line: a number, a whole number, a safe name, or a lone * (LIGGGHTS'
#: "any", in `processors`)
_TOKEN = r"(?:[A-Za-z0-9_.+-]+|\*)"
_TOKEN_RE = re.compile(_TOKEN)
#: a slot of a template
_SLOT = "{}"
#: the `processors` grid: three counts, each a whole number or *
_PROCESSORS = re.compile(r"(?:\*|[1-9][0-9]{0,5})(?: (?:\*|[1-9][0-9]{0,5})){2}")


def _short(value, limit: int = 80) -> str:
    """repr(value), cut to `limit` characters (one line: repr escapes newlines)."""
    text = repr(value)
    return text if len(text) <= limit else text[:limit - 3] + "..."


def safe_name(field: str, value) -> str:
    """`value` if it is a name a deck may carry (SAFE_NAME), else a one-line InputError naming
    `field`.  The guard of every user-derived string of the deck and its README."""
    if not isinstance(value, str) or SAFE_NAME.fullmatch(value) is None:
        raise InputError(f"{field} = {_short(value)}: must be {SAFE_NAME_RULE}")
    return value


def _whole(field: str, value, minimum: int = 0) -> int:
    """A user-derived whole number for the deck, at least `minimum`; InputError otherwise."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) \
            or value < minimum:
        raise InputError(f"{field} = {_short(value)}: must be a whole number >= {minimum}")
    return int(value)


def _fmt(x) -> str:
    """A real number as a deck token (10 significant digits); InputError unless finite."""
    try:
        v = float(x)
    except (TypeError, ValueError):
        raise InputError(f"LIGGGHTS deck number = {_short(x)}: must be a real number") from None
    if not math.isfinite(v):
        raise InputError(f"LIGGGHTS deck number = {v!r}: must be finite (a scenario value is "
                         "nan or inf, or a quantity made from them overflows)")
    return f"{v:.10g}"


def _token(value, template: str) -> str:
    """One slot's value as deck text: int -> decimal, float -> _fmt, str -> as is; each must
    be a single _TOKEN."""
    if isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_)):
        text = str(int(value))
    elif isinstance(value, (float, np.floating)):
        text = _fmt(value)
    elif isinstance(value, str):
        text = value
    else:
        text = None
    if text is None or _TOKEN_RE.fullmatch(text) is None:
        raise InputError(f"LIGGGHTS deck value = {_short(value)} (in {template!r}): must be a "
                         "number or a name of A-Z a-z 0-9 _ . + -, nothing LIGGGHTS or a shell "
                         "reads specially")
    return text


class _Deck:
    """Lines of a deck (or of its README), each a template and the values of its slots.

    A template is text of vibroflow.liggghts: a literal, or literals joined by code; it holds no
    newline and no user input, which goes into the slots only (rendered by `_token`)."""

    def __init__(self) -> None:
        self._lines: list[tuple[str, tuple]] = []

    def add(self, template: str = "", *values) -> None:
        if "\n" in template or "\r" in template or template.count(_SLOT) != len(values):
            raise ValueError(f"deck template {template!r}: one line with {len(values)} slots "
                             "expected (a bug in vibroflow.liggghts)")
        self._lines.append((template, values))

    def add_block(self, template: str, *values) -> None:
        """The lines of a multi-line template, the values shared out to their slots in order."""
        values = list(values)
        for line in template.split("\n"):
            k = line.count(_SLOT)
            self.add(line, *values[:k])
            values = values[k:]
        if values:
            raise ValueError(f"deck template: {len(values)} values left over")

    def extend(self, other: _Deck) -> None:
        self._lines.extend(other._lines)

    def lines(self) -> list[str]:
        return [_fill(template, values) for template, values in self._lines]

    def render(self, name: str) -> str:
        """The text, "\\n" after every line, checked: it has exactly one line per template,
        each line printable ASCII and matched by its template with one _TOKEN per slot."""
        text = "".join(line + "\n" for line in self.lines())
        written = text.split("\n")[:-1]
        if len(written) != len(self._lines):
            raise InputError(f"{name}: {len(written)} lines written for {len(self._lines)} "
                             "template lines (a value held a newline)")
        for k, ((template, _), line) in enumerate(zip(self._lines, written), 1):
            pattern = _TOKEN.join(re.escape(part) for part in template.split(_SLOT))
            if not line.isascii() or not line.isprintable() or \
                    re.fullmatch(pattern, line) is None:
                raise InputError(f"{name} line {k} = {_short(line)}: not the line its template "
                                 f"{template!r} allows")
        return text


def _fill(template: str, values) -> str:
    parts = template.split(_SLOT)
    out = [parts[0]]
    for value, part in zip(values, parts[1:]):
        out += [_token(value, template), part]
    return "".join(out)


def _table(deck: _Deck, name: str, arr: np.ndarray) -> None:
    """A per-type-pair `fix property/global` line of the n x n table `arr`."""
    arr = np.asarray(arr)
    n = arr.shape[0]
    deck.add(f"fix {name} all property/global {name} peratomtypepair {n} "
             + " ".join([_SLOT] * (n * n)), *(_fmt(v) for v in arr.ravel()))

