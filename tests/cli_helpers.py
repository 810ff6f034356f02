"""The check every bad-input probe of the command line makes: the promised one line."""
from __future__ import annotations

import re
import subprocess

from vibroflow.progress import COMPILED, COMPILING

# The compile display's and the stages' plain lines (vibroflow/progress.py): a command that
# finds its input bad only after some kernels ran (a bed too small to calibrate on, a blow-up)
# may have compiled them and started a stage first, and said so; that is progress, not a
# second error line.
_COMPILE_LINE = re.compile(
    rf"^({re.escape(COMPILING)} \d+ s|{re.escape(COMPILED)} \(\d+ s\))$")
# A stage's plain progress line (RunProgress._plain_line), said at its start and every 10 s
_STAGE_LINE = re.compile(r"^.+: (t = \S+ / \S+ s|\S+ / \S+ \S+), "
                         r"(\S+ M particle-steps/s, )?(estimating \.\.\.|\S+ (s|min|h) left)$")


def one_line_error(r: subprocess.CompletedProcess, code: int = 2) -> str:
    """The only line on stderr, compile progress aside, of a command that ended with `code`, no
    traceback anywhere; for bad input (code 2) the line is the "error: ..." one."""
    assert r.returncode == code, (r.returncode, r.stderr)
    assert "Traceback" not in r.stderr and "Traceback" not in (r.stdout or "")
    lines = [ln for ln in r.stderr.strip().splitlines()
             if not (_COMPILE_LINE.match(ln) or _STAGE_LINE.match(ln))]
    assert len(lines) == 1, r.stderr
    if code == 2:
        assert lines[0].startswith("error: "), lines[0]
    return lines[0]
