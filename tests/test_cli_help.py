"""`vibroflow ... --help`: every command's help shows its flags as plain flags and every help
text as written (bracketed words such as `[dilatancy]` are words, not markup)."""
from __future__ import annotations

import re

import click
import pytest
from typer.main import get_command
from typer.testing import CliRunner

from vibroflow.cli import app

ROOT = get_command(app)


def _commands(group: click.Group, path: tuple[str, ...] = ()):
    for name, cmd in group.commands.items():
        yield (*path, name), cmd
        if isinstance(cmd, click.Group):
            yield from _commands(cmd, (*path, name))


COMMANDS = list(_commands(ROOT))


def _help(path) -> str:
    r = CliRunner().invoke(app, [*path, "--help"], env={"COLUMNS": "200", "NO_COLOR": "1"})
    assert r.exit_code == 0, r.output
    return r.output


def _flat(text: str) -> str:
    return " ".join(text.split())


@pytest.mark.parametrize("path", [p for p, _ in COMMANDS], ids=" ".join)
def test_flags_are_plain_and_bracketed_words_stay(path):
    cmd = dict(COMMANDS)[path]
    out = _help(path)
    assert "<bool>" not in out
    usage = out.splitlines()[0]
    assert usage.startswith("Usage: vibroflow ") and "[[" not in usage, usage
    for p in cmd.params:
        if isinstance(p, click.Option) and p.is_flag:
            # the flag's own line: its names (--x / --no-x), no value placeholder after them
            line = next(ln for ln in out.splitlines() if p.opts[-1] in ln)
            names = " / ".join([p.opts[-1], *p.secondary_opts])
            assert re.search(re.escape(names) + r"(\s\s|$)", line), line
        for word in re.findall(r"\[[A-Za-z_]+\]", p.help or ""):
            assert word in out, (word, out)
    assert _flat(cmd.help or "").split(". ")[0] in _flat(out)


def test_dilatancy_and_compaction_tables_are_named_in_the_help():
    """Bracketed words print as written, not read as rich's style tags."""
    out = _flat(_help(("continuum",)))
    assert "from the calibration's [dilatancy] (vibroflow calibrate --dilatancy)" in out
    assert "from the calibration's [compaction] (vibroflow calibrate --dilatancy)" in out
    assert "(its [scenario] differs)" in out
    assert re.search(r"--vtk\s+Also write ParaView", _help(("continuum",)))
    assert "-> [dilatancy]." in _flat(_help(("calibrate",)))
