"""The check every bad-input probe of the command line makes: the promised one line."""
from __future__ import annotations

import subprocess


def one_line_error(r: subprocess.CompletedProcess, code: int = 2) -> str:
    """The only line on stderr of a command that ended with `code`, no traceback anywhere; for
    bad input (code 2) the line is the "error: ..." one."""
    assert r.returncode == code, (r.returncode, r.stderr)
    assert "Traceback" not in r.stderr and "Traceback" not in (r.stdout or "")
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    if code == 2:
        assert lines[0].startswith("error: "), lines[0]
    return lines[0]
