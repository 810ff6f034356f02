"""Errors that mean "the input is wrong", as opposed to a bug.

The CLI turns every `InputError` (and pydantic's `ValidationError`, a malformed TOML file or a
missing file) into exactly one line on stderr and exit code 2, without a traceback.  So the
message of an `InputError` must be one line that names the field, shows the value and says what
is allowed:

    run.dt = 0.0001: must be at most 2.27e-05 s (1/10 of the steel-steel contact time 2.27e-04 s)
"""
from __future__ import annotations


class InputError(Exception):
    """Bad input from the user: a one-line "FIELD = VALUE: what is allowed" message."""

    def __init__(self, message: str):
        # one line, always: the CLI prints the message as is and a newline would split it
        super().__init__(" ".join(str(message).split()))

    @property
    def message(self) -> str:
        return str(self.args[0])


#: how to go on from a refused --resume, unless the caller knows better (CheckpointRefused)
START_AFRESH = "run without --resume to start afresh"


class CheckpointRefused(InputError):
    """A --resume refused: the checkpoint, or a file it counts on, is damaged or another run's.
    `reason` says which ("--resume: DIR/checkpoint.h5 is damaged (truncated)"), `remedy` how to
    go on; the message is "REASON; REMEDY"."""

    def __init__(self, reason: str, remedy: str = START_AFRESH):
        self.reason = " ".join(str(reason).split())
        self.remedy = remedy
        super().__init__(f"{self.reason}; {remedy}")

    def __reduce__(self):
        # rebuilt from its reason and remedy: a sweep point's exception crosses processes
        return CheckpointRefused, (self.reason, self.remedy)


class Interrupted(Exception):
    """A run stopped by the user (Ctrl-C, SIGINT): `message` is the one line the CLI prints,
    saying where the run stopped and how to go on ("interrupted at t = 0.1234 s; resume with
    --resume"); the CLI exits with code 130 (128 + SIGINT), as a shell does.  `where` is where
    it stopped ("at t = 0.1234 s", "while settling"): given, or the line's first clause less
    its "interrupted"."""

    def __init__(self, message: str, where: str | None = None):
        super().__init__(" ".join(str(message).split()))
        self._where = where

    @property
    def message(self) -> str:
        return str(self.args[0])

    @property
    def where(self) -> str:
        if self._where is not None:
            return self._where
        return self.message.split(";")[0].removeprefix("interrupted").strip()

    def __reduce__(self):
        # rebuilt with its where: a sweep point's exception crosses processes
        return type(self), (self.message, self._where)
