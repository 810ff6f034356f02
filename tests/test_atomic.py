"""vibroflow.io.atomic: a reader sees the old file or the whole new one; a failed write leaves
the old file and no temporary file; the new file has the umask's mode."""
from __future__ import annotations

import json
import math
import os
import stat
import threading
from pathlib import Path

import pytest

from vibroflow.io import atomic
from vibroflow.io.atomic import (atomic_path, replace_atomic, write_bytes_atomic,
                                 write_json_atomic, write_text_atomic)

PACKAGE = Path(atomic.__file__).resolve().parents[1]


def _leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.startswith(".tmp-"))


@pytest.fixture
def umask():
    """Set the process's umask for one test (restored after)."""
    old = os.umask(0o022)
    os.umask(old)
    yield lambda m: os.umask(m)
    os.umask(old)


def _mode(path: Path) -> int:
    return stat.S_IMODE(path.stat().st_mode)


# ---- content ---------------------------------------------------------------------------------

def test_bytes_round_trip_and_parent_made(tmp_path):
    data = bytes(range(256)) * 1000
    path = tmp_path / "a" / "b" / "blob.bin"
    assert write_bytes_atomic(path, data) == path
    assert path.read_bytes() == data
    assert _leftovers(path.parent) == []


def test_text_is_utf8_and_line_ends_are_kept(tmp_path):
    text = "x,z\r\n1 ± 2 m²\nend\n"
    path = write_text_atomic(str(tmp_path / "t.csv"), text)  # a str path is fine too
    assert isinstance(path, Path)
    assert path.read_bytes() == text.encode("utf-8")  # no newline translation


@pytest.mark.parametrize("kw", [{}, {"indent": None}, {"indent": 4, "sort_keys": True}])
def test_json_is_json_dumps_plus_newline(tmp_path, kw):
    data = {"b": [1, 2.5, None], "a": {"nested": "é"}, "nan": math.nan}
    path = write_json_atomic(tmp_path / "s.json", data, **kw)
    expected = json.dumps(data, indent=kw.get("indent", 2), sort_keys=kw.get("sort_keys", False))
    assert path.read_text(encoding="utf-8") == expected + "\n"
    back = json.loads(path.read_text(encoding="utf-8"))
    assert back["b"] == [1, 2.5, None] and back["a"] == {"nested": "é"}
    assert math.isnan(back["nan"])


def test_call_sites_share_the_helper():
    """The study's and the continuum's write_json_atomic (imported by other modules) are the
    shared one, so their bytes are json.dumps(indent=2) + newline like every other summary."""
    from vibroflow.study import stages
    assert stages.write_json_atomic is write_json_atomic


def test_no_hand_rolled_atomic_writes():
    """The package writes through vibroflow.io.atomic; os.replace stands only where the rename is part of a
    bigger protocol (the DEM's partial -> final dem.h5, the LIGGGHTS import's dem.h5, the
    continuum checkpoint's own fsync'ed write)."""
    allowed = {"io/atomic.py", "dem/output.py", "liggghts/importer.py", "continuum/checkpoint.py"}
    users = {p.relative_to(PACKAGE).as_posix() for p in PACKAGE.rglob("*.py")
             if "os.replace(" in p.read_text(encoding="utf-8")}
    assert users <= allowed, sorted(users - allowed)


# ---- failures leave the old file and nothing else ---------------------------------------------

def test_unserialisable_json_leaves_old_file(tmp_path):
    path = tmp_path / "summary.json"
    write_json_atomic(path, {"ok": 1})
    before = path.read_bytes()
    with pytest.raises(TypeError):
        write_json_atomic(path, {"ok": 2, "bad": object()})
    with pytest.raises(ValueError):
        write_json_atomic(path, {"x": math.inf}, allow_nan=False)
    assert path.read_bytes() == before
    assert _leftovers(tmp_path) == []


def test_failure_after_the_temp_file_exists_removes_it(tmp_path, monkeypatch):
    """An error between writing the temporary file and the rename (here: fsync fails, as on a
    full disk) leaves the old file and no temporary one."""
    path = tmp_path / "data.bin"
    write_bytes_atomic(path, b"old")
    created = []
    real_mkstemp = atomic.tempfile.mkstemp

    def mkstemp(*a, **k):
        fd, name = real_mkstemp(*a, **k)
        created.append(name)
        return fd, name

    def fsync(fd):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(atomic.tempfile, "mkstemp", mkstemp)
    monkeypatch.setattr(atomic.os, "fsync", fsync)
    with pytest.raises(OSError, match="No space"):
        write_bytes_atomic(path, b"new" * 1000)
    assert created and not os.path.exists(created[0])  # it was made, then removed
    assert path.read_bytes() == b"old"
    assert _leftovers(tmp_path) == []


@pytest.mark.parametrize("exc", [RuntimeError("writer failed"), KeyboardInterrupt()])
def test_writer_that_raises_leaves_old_file(tmp_path, exc):
    path = tmp_path / "fields.nc"
    path.write_bytes(b"previous")
    seen = []

    def writer(tmp: Path):
        seen.append(tmp)
        tmp.write_bytes(b"half of the new fi")
        raise exc

    with pytest.raises(type(exc)):
        replace_atomic(path, writer)
    with pytest.raises(type(exc)):
        with atomic_path(path) as tmp:
            seen.append(tmp)
            tmp.write_bytes(b"half")
            raise exc
    assert path.read_bytes() == b"previous"
    assert seen and not any(p.exists() for p in seen)
    assert _leftovers(tmp_path) == []


def test_failed_first_write_leaves_no_file(tmp_path):
    with pytest.raises(RuntimeError):
        with atomic_path(tmp_path / "new.png"):
            raise RuntimeError("no picture")
    assert list(tmp_path.iterdir()) == []


# ---- the temporary path ---------------------------------------------------------------------

def test_atomic_path_is_unique_in_the_target_folder(tmp_path):
    path = tmp_path / "sub" / "plot.png"
    with atomic_path(path) as a, atomic_path(path) as b:
        assert a != b
        assert a.parent == b.parent == path.parent  # same file system: the rename is atomic
        assert a.name.startswith(".tmp-") and a.name.endswith("-plot.png")
        assert a.exists()  # mkstemp made it: no other process can take the name
        a.write_bytes(b"first")
        b.write_bytes(b"second")
    # b (the inner block) was moved into place first, then a: the last to finish wins, whole
    assert path.read_bytes() == b"first"
    with atomic_path(tmp_path / "grid.vtr", suffix=".vtr") as c:
        assert c.name.endswith(".vtr") and not c.name.endswith("-grid.vtr")
        c.write_text("x")
    assert (tmp_path / "grid.vtr").read_text() == "x"
    assert _leftovers(tmp_path) == [] and _leftovers(path.parent) == []


def test_savefig_picks_the_format_from_the_temp_name(tmp_path):
    import matplotlib
    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1])
    with atomic_path(tmp_path / "p.png") as tmp:
        fig.savefig(tmp)
    with atomic_path(tmp_path / "p.pdf") as tmp:
        fig.savefig(tmp)
    plt.close(fig)
    assert (tmp_path / "p.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert (tmp_path / "p.pdf").read_bytes()[:5] == b"%PDF-"


# ---- mode ------------------------------------------------------------------------------------

@pytest.mark.parametrize("mask", [0o022, 0o077, 0o002])
def test_mode_follows_the_umask(tmp_path, umask, mask):
    umask(mask)
    want = 0o666 & ~mask
    assert atomic.file_mode() == want
    p1 = write_text_atomic(tmp_path / "a.txt", "a")
    p2 = write_json_atomic(tmp_path / "b.json", [1])
    with atomic_path(tmp_path / "c.h5") as tmp:  # mkstemp's own mode is 0o600
        tmp.write_bytes(b"c")
    p3 = tmp_path / "c.h5"
    plain = tmp_path / "plain.txt"
    plain.write_text("p")  # what open() gives, for comparison
    for p in (p1, p2, p3):
        assert _mode(p) == want == _mode(plain), (p.name, oct(_mode(p)))


def test_replacing_a_file_gives_the_umask_mode(tmp_path, umask):
    umask(0o022)
    path = tmp_path / "x.txt"
    path.write_text("old")
    path.chmod(0o600)
    write_text_atomic(path, "new")
    assert _mode(path) == 0o644


# ---- several writers ---------------------------------------------------------------------------

def test_two_writes_leave_the_last(tmp_path):
    path = tmp_path / "s.json"
    write_json_atomic(path, {"run": 1})
    write_json_atomic(path, {"run": 2, "longer": "x" * 100})
    write_json_atomic(path, {"run": 3})
    assert json.loads(path.read_text()) == {"run": 3}
    assert _leftovers(tmp_path) == []


def test_concurrent_writers_and_a_reader_see_only_whole_files(tmp_path):
    """Threads writing the same file (distinct sizes) while another reads it: every read is one
    writer's whole content (never empty, never a mix), and no temporary file is left."""
    path = tmp_path / "shared.bin"
    payloads = [bytes([65 + k]) * (50_000 + 7919 * k) for k in range(4)]
    write_bytes_atomic(path, payloads[0])
    stop = threading.Event()
    bad: list[int] = []

    def reader():
        while not stop.is_set():
            data = path.read_bytes()
            if data not in payloads:
                bad.append(len(data))

    def writer(k):
        for _ in range(25):
            write_bytes_atomic(path, payloads[k])

    r = threading.Thread(target=reader)
    r.start()
    ws = [threading.Thread(target=writer, args=(k,)) for k in range(4)]
    for w in ws:
        w.start()
    for w in ws:
        w.join()
    stop.set()
    r.join()
    assert bad == []
    assert path.read_bytes() in payloads
    assert _leftovers(tmp_path) == []
