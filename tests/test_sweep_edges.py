"""`vibroflow sweep --scheduler` at an address where no Dask scheduler answers: a
malformed address, a port where nothing listens, a service that speaks HTTP or garbage, a
silent one, a worker: one line naming the address and what is there, exit code 2, no
traceback, nothing written to --out."""
from __future__ import annotations

import contextlib
import socket
import threading

import pytest

from vibroflow.errors import InputError
from vibroflow.study.sweep import check_scheduler

REPLIES = {
    "http": b"HTTP/1.1 400 Bad Request\r\nContent-Length: 0\r\nConnection: close\r\n\r\n",
    "garbage": b"\xff" * 64 + b"hello, garbage" * 8,
}


@contextlib.contextmanager
def server(kind: str):
    """A TCP server on localhost that answers every connection with REPLIES[kind] after
    reading the client's first bytes ("silent": reads and never answers); yields its
    address."""
    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    sock.listen(8)
    stop = threading.Event()
    held = []

    def serve():
        sock.settimeout(0.2)
        while not stop.is_set():
            try:
                conn, _ = sock.accept()
            except OSError:
                continue
            held.append(conn)
            conn.settimeout(5)
            with contextlib.suppress(OSError):
                if kind == "garbage":
                    conn.sendall(REPLIES[kind])
                conn.recv(4096)
                if kind == "http":
                    conn.sendall(REPLIES[kind])
            if kind != "silent":
                conn.close()

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    try:
        yield f"tcp://127.0.0.1:{sock.getsockname()[1]}"
    finally:
        stop.set()
        thread.join()
        for c in held:
            c.close()
        sock.close()


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _sweep(run_cli, out, address):
    r = run_cli("sweep", "tub47-quick", "--out", out, "--factors", "1", "--scheduler",
                address, timeout=120)
    assert r.returncode == 2, (r.stdout, r.stderr)
    assert "Traceback" not in r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    assert not out.exists()  # checked before anything is written
    return lines[0]


NOT_DASK = "; start one with `dask scheduler` or leave --scheduler out"


@pytest.mark.parametrize("address, why", [
    ("foo", "missing port number in address 'foo'"),
    ("http://x", "scheme http://; Dask's are tcp, tls, ws, wss, ucx"),
])
def test_malformed_scheduler_address_is_one_line(run_cli, tmp_path, address, why):
    line = _sweep(run_cli, tmp_path / "sweep", address)
    assert line == (f"error: --scheduler = '{address}': not a Dask scheduler address ({why}); "
                    "give tcp://HOST:PORT as `dask scheduler` prints it, or leave --scheduler "
                    "out")


def test_port_where_nothing_listens_is_one_line(run_cli, tmp_path):
    address = f"tcp://127.0.0.1:{_free_port()}"
    line = _sweep(run_cli, tmp_path / "sweep", address)
    assert line == (f"error: --scheduler = '{address}': no Dask scheduler answers there "
                    f"(nothing listens on that port: connection refused){NOT_DASK}")


@pytest.mark.parametrize("kind", ["http", "garbage"])
def test_a_service_that_is_not_dask_is_one_line(run_cli, tmp_path, kind):
    """An HTTP reply made distributed's Client try to allocate 3.07 EiB; garbage, a
    ValueError."""
    with server(kind) as address:
        line = _sweep(run_cli, tmp_path / "sweep", address)
    assert line == (f"error: --scheduler = '{address}': no Dask scheduler answers there (a "
                    f"service that answers in another protocol than Dask's){NOT_DASK}")


def test_a_silent_service_times_out_in_one_line():
    with server("silent") as address:
        with pytest.raises(InputError) as e:
            check_scheduler(address, timeout=1.0)
    assert e.value.message == (f"--scheduler = '{address}': no Dask scheduler answers there (a "
                               "service that accepts connections but gives no Dask handshake "
                               f"in 1 s){NOT_DASK}")
