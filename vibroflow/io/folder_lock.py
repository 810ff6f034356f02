"""An exclusive lock on an output folder, held while a command writes it.

Two commands writing one folder (two `vibroflow dem --out X`, a `vibroflow run` and a
`vibroflow report` of the same study) would delete or overwrite each other's files and could
both report success.  Every command that writes a folder therefore holds DIR/.vibroflow.lock:
an flock (the same kind the sweep's points use, vibroflow.study.sweep_folder) that belongs to
the open file, so the kernel releases it when the process ends, killed or not, and no stale
lock outlives its holder.  The file records who holds it (pid, command, start time) so that the
second command can say so in its one-line error.

A process may take the lock of a folder it already holds (a study writes DIR and its stage
folders; a stage called from it takes DIR/dem again): nested takes of one folder are counted
and the flock is released by the outermost.  On a file system without working flock (an NFS v3
mount without lockd) the folder is used unlocked, with a warning on stderr.

    with folder_lock(out, "vibroflow dem"):
        ...                                       # write into out
"""
from __future__ import annotations

import contextlib
import errno
import fcntl
import json
import os
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

from vibroflow.errors import InputError

LOCK_NAME = ".vibroflow.lock"

_held: dict[str, list[int]] = {}  # realpath -> [fd, depth] held by this process
_guard = threading.Lock()


def check_not_under_a_file(path: Path, field: str) -> None:
    """One-line InputError when the nearest existing folder above `path` is a file."""
    for parent in Path(path).parents:
        if parent.exists():
            if not parent.is_dir():
                raise InputError(f"{field} = {str(path)!r}: {str(parent)!r} is a file, not a "
                                 "folder")
            return


def check_writable_dir(path: Path, field: str = "--out") -> Path:
    """`path` as an output folder, made if missing: one-line InputError when it is a file, sits
    under a file, or cannot be made or written (read-only, permissions)."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise InputError(f"{field} = {str(path)!r}: is a file, not a folder; give a folder")
    check_not_under_a_file(path, field)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"{field} = {str(path)!r}: cannot be made "
                         f"({(exc.strerror or str(exc)).lower()})") from None
    if not os.access(path, os.W_OK | os.X_OK):
        raise InputError(f"{field} = {str(path)!r}: not writable (permission denied); give a "
                         "folder you may write")
    return path


def check_writable_file(path: Path, field: str) -> Path:
    """`path` as an output file: one-line InputError when it is a folder, or its folder is
    missing, a file, or cannot be written."""
    path = Path(path)
    if path.is_dir():
        raise InputError(f"{field} = {str(path)!r}: is a folder, not a file; give a file")
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.exists():
        raise InputError(f"{field} = {str(path)!r}: no folder {str(folder)!r}; give a file in "
                         "an existing folder")
    check_writable_dir(folder, field=f"{field}'s folder")
    return path


def _holder(fd: int) -> str:
    try:
        os.lseek(fd, 0, os.SEEK_SET)
        record = json.loads(os.read(fd, 4096).decode("utf-8") or "{}")
        since = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(float(record["since"])))
        return f"process {int(record['pid'])} ({record['command']}, since {since})"
    except (OSError, ValueError, KeyError, TypeError):
        return "another process"


@contextlib.contextmanager
def folder_lock(path: Path, command: str, field: str = "--out") -> Iterator[Path]:
    """Hold the exclusive lock of output folder `path` (made if missing) while the block runs.

    Raises InputError (one line: the folder, the holder's pid and command) when another process
    holds it; the caller has then written nothing."""
    path = check_writable_dir(path, field)
    key = os.path.realpath(path)
    with _guard:
        if key in _held:
            _held[key][1] += 1
            nested = True
        else:
            nested = False
    if nested:
        try:
            yield path
        finally:
            with _guard:
                _held[key][1] -= 1
        return
    fd = _take(path / LOCK_NAME, path, field)
    record = json.dumps({"pid": os.getpid(), "command": command, "since": time.time()})
    os.ftruncate(fd, 0)
    os.pwrite(fd, record.encode("utf-8"), 0)
    with _guard:
        _held[key] = [fd, 1]
    try:
        yield path
    finally:
        with _guard:
            del _held[key]
        # unlinked while still locked, so that a command that ends leaves no file behind; a
        # waiting process that opened the old file notices it was unlinked and opens anew
        with contextlib.suppress(OSError):
            os.unlink(path / LOCK_NAME)
        os.close(fd)


def _take(lock_file: Path, path: Path, field: str) -> int:
    """The open, flocked descriptor of `lock_file` (the file now at that name)."""
    while True:
        try:
            fd = os.open(lock_file, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise InputError(f"{field} = {str(path)!r}: cannot write its lock file "
                             f"({(exc.strerror or str(exc)).lower()})") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            who = _holder(fd)
            os.close(fd)
            raise InputError(f"{field} = {str(path)!r}: in use by {who}; wait for it to end or "
                             "give another folder") from None
        except OSError as exc:
            if exc.errno not in (errno.ENOLCK, errno.EOPNOTSUPP, errno.ENOSYS):
                os.close(fd)
                raise
            sys.stderr.write(f"warning: {path}: this file system has no working locks; nothing "
                             "stops another command from writing this folder at the same "
                             "time\n")
            return fd
        try:
            same = os.path.samestat(os.fstat(fd), os.stat(lock_file))
        except FileNotFoundError:
            same = False
        if same:
            return fd
        os.close(fd)  # its holder unlinked it as we opened it: take the new one
