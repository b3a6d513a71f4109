"""``phfdi loop-diagnose --scheduler`` with an address that is no scheduler (issue 36 item 4).

A malformed address (``notaurl``), a web address (``http://...``), a port with nothing behind it and a listener that
accepts the connection and never answers: each ends in one line and exit status 2, within the connection timeout
that ``--help`` states (the listener used to hold the command for more than 100 s; the others gave a traceback).
A running scheduler is still used.
"""

from __future__ import annotations

import socket
import subprocess
import sys
import threading

import numpy as np
import pytest

from phfdi.loopdiag.dask_run import CONNECT_TIMEOUT_S, dask_client

#: the bound the subprocess gets: the command's start (about 3 s on a loaded machine) plus the connection timeout
#: plus room; the former hang lasted more than 100 s
BOUND_S = 60.0


@pytest.fixture
def loop_csv(tmp_path):
    t = np.arange(400.0)
    op = 50 + 5 * np.sin(t / 20)
    path = tmp_path / "loop.csv"
    path.write_text("time_s,op_pct,pv,sp\n" + "".join(f"{a},{b},{b + 1},{b}\n" for a, b in zip(t, op)))
    return path


def _diagnose(path, scheduler: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "phfdi.cli", "loop-diagnose", str(path), "--scheduler", scheduler],
                          capture_output=True, text=True, timeout=BOUND_S)


def _one_error_line(proc: subprocess.CompletedProcess) -> str:
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    (line,) = proc.stderr.strip().splitlines()
    assert line.startswith("phfdi loop-diagnose: error: ")
    return line


@pytest.mark.parametrize("address, says", [
    ("notaurl", "missing port number"),
    ("http://127.0.0.1:8787", "unknown scheme 'http'"),
    ("tcp://127.0.0.1", "missing port number"),
    ("tcp://127.0.0.1:0", "a port 1 .. 65535"),
])
def test_an_address_that_is_not_a_scheduler_address_is_one_line(loop_csv, address, says):
    line = _one_error_line(_diagnose(loop_csv, address))
    assert repr(address) in line and says in line and "tcp://" in line


def test_a_port_with_nothing_behind_it_is_one_line(loop_csv):
    with socket.socket() as s:  # a free port, closed again: nothing listens there
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    line = _one_error_line(_diagnose(loop_csv, f"tcp://127.0.0.1:{port}"))
    # distributed's refusal (its retries end at 4 s) or, on a machine too loaded for those, our 5 s limit
    assert (f"cannot reach the Dask scheduler at tcp://127.0.0.1:{port}" in line
            or f"the Dask scheduler at tcp://127.0.0.1:{port} did not answer within" in line), line


def test_a_listener_that_never_answers_is_one_line_within_the_timeout(loop_csv):
    server = socket.create_server(("127.0.0.1", 0))
    port = server.getsockname()[1]
    accepted: list[socket.socket] = []
    stop = threading.Event()

    def accept_and_stay_silent() -> None:
        server.settimeout(0.2)
        while not stop.is_set():
            try:
                accepted.append(server.accept()[0])
            except TimeoutError:
                pass

    thread = threading.Thread(target=accept_and_stay_silent, daemon=True)
    thread.start()
    try:
        line = _one_error_line(_diagnose(loop_csv, f"tcp://127.0.0.1:{port}"))
    finally:
        stop.set()
        thread.join()
        for c in accepted:
            c.close()
        server.close()
    assert accepted, "the command never connected to the listener"
    assert f"the Dask scheduler at tcp://127.0.0.1:{port} did not answer within {CONNECT_TIMEOUT_S:g} s" in line


def test_the_help_states_the_timeout():
    out = subprocess.run([sys.executable, "-m", "phfdi.cli", "loop-diagnose", "--help"], capture_output=True,
                         text=True, timeout=BOUND_S).stdout
    assert f"does not answer within {CONNECT_TIMEOUT_S:g} s" in " ".join(out.split())


def test_a_running_scheduler_is_used():
    from distributed import LocalCluster

    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, protocol="tcp://", host="127.0.0.1",
                      dashboard_address=None, silence_logs=40) as cluster:
        with dask_client(cluster.scheduler_address) as client:
            assert client.submit(sum, [1, 2, 3]).result() == 6
