"""How a command fails: bad input, a Ctrl-C, an operating-system error or a numerical blow-up,
each said in one line on stderr with its own exit code, without a traceback."""
from __future__ import annotations

import errno
import sys
import tomllib
from collections.abc import Callable
from functools import wraps
from typing import Any, NoReturn

import typer
from pydantic import ValidationError

from vibroflow.errors import InputError, Interrupted

EXIT_INPUT = 2
EXIT_BLOWUP = 3
EXIT_FAILED = 1
EXIT_INTERRUPTED = 130  # 128 + SIGINT, as a shell reports a command stopped by Ctrl-C

# operating-system errors that a user's path or machine causes, said in one line: the path, the
# reason; a full disk is not bad input (exit 1), a path that cannot be written is (exit 2)
_PATH_ERRNOS = (errno.EACCES, errno.EPERM, errno.EROFS, errno.ENOTDIR, errno.EISDIR,
                errno.EEXIST, errno.ENAMETOOLONG, errno.ELOOP)
_MACHINE_ERRNOS = (errno.ENOSPC, errno.EDQUOT, errno.EMFILE, errno.ENFILE, errno.EIO)


def input_error_message(exc: BaseException) -> str | None:
    """The one-line message of an input error, or None if `exc` is not one (a bug)."""
    if isinstance(exc, InputError):
        return exc.message
    if isinstance(exc, ValidationError):
        # imported here: the scenario's model is heavy, and --help stays quick without it
        from vibroflow.scenario.io import format_validation_error

        return format_validation_error(exc)
    if isinstance(exc, tomllib.TOMLDecodeError):
        return f"malformed TOML: {exc}"
    if isinstance(exc, FileNotFoundError):
        what = (exc.strerror or "no such file or directory").lower()
        return f"{exc.filename}: {what}" if exc.filename else str(exc)
    return None


def fail(message: str, code: int = EXIT_INPUT, prefix: str = "error: ") -> NoReturn:
    """Print `message` as one line on stderr and exit with `code`."""
    # plain write, not rich: rich would wrap a long line and eat [brackets] as markup
    sys.stderr.write(prefix + " ".join(message.split()) + "\n")
    sys.stderr.flush()
    raise typer.Exit(code)


def blown_up(exc: Exception) -> NoReturn:
    """A numerical blow-up is not bad input: its own exit code, and its message (the balls or
    points and the cause) in one line."""
    sys.stderr.write("error: " + str(exc) + "\n")
    raise typer.Exit(EXIT_BLOWUP)


def _os_error_line(exc: OSError) -> str:
    what = (exc.strerror or type(exc).__name__).lower()
    where = exc.filename if exc.filename is not None else ""
    return f"{where}: {what}" if where else what


def input_errors(fn: Callable[..., Any]) -> Callable[..., Any]:
    """Run a command, turning input errors into one line on stderr and exit code 2, a Ctrl-C
    into one line saying where the run stopped and exit code 130, and an operating-system error
    (a path that cannot be written, a full disk) into one line naming the path."""

    @wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except (InputError, ValidationError, tomllib.TOMLDecodeError, FileNotFoundError) as e:
            message = input_error_message(e)
            assert message is not None
            fail(message)
        except Interrupted as e:
            fail(e.message, EXIT_INTERRUPTED, prefix="")
        except KeyboardInterrupt:
            fail("interrupted", EXIT_INTERRUPTED, prefix="")
        except OSError as e:
            if e.errno in _PATH_ERRNOS:
                fail(_os_error_line(e))
            if e.errno in _MACHINE_ERRNOS:
                fail(_os_error_line(e), EXIT_FAILED)
            raise

    return wrapper
