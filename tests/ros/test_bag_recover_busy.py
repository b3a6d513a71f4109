"""``phfdi bag recover`` and a bag that is being recorded (issue 36 item 8).

A recording process holds its bag's writer lock (``phfdi.bagio.BagWriter``, what the recorder node writes with)
until it closes the file. Recovering that bag used to copy what was on disk so far into a finished-looking partial
bag, exit 0; recovering onto it (``--overwrite``) would replace the file under its recorder. Both are refused in
one line (exit 2) and nothing is written. The recording is a real process.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from phfdi import bagio
from phfdi_base import topics as T

RECORDING = textwrap.dedent("""
    import sys, time
    from phfdi import bagio
    from phfdi_base import topics as T
    writer = bagio.BagWriter(sys.argv[1])
    cid = writer.add_topic(T.FAULT_ALARM.name, T.FAULT_ALARM.type)
    for k in range(50):
        writer.write(cid, k * 10**9, bytes(200))  # payloads are not decoded here
    writer.flush()  # complete chunks on disk: what a recover would copy
    print("recording", flush=True)
    sys.stdin.read()  # records until told to stop
    writer.close()
    """)


@pytest.fixture
def recording(tmp_path):
    """A process recording tmp_path/live.mcap (its writer holds the lock until stdin closes)."""
    path = tmp_path / "live.mcap"
    proc = subprocess.Popen([sys.executable, "-c", RECORDING, str(path)], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "recording"
        yield path, proc.pid
    finally:
        proc.stdin.close()
        proc.wait(timeout=60)


def _recover(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "phfdi.cli", "bag", "recover", *args], capture_output=True,
                          text=True, timeout=120)


def _finished_bag(path: Path) -> Path:
    writer = bagio.BagWriter(path)
    writer.write(writer.add_topic(T.FAULT_ALARM.name, T.FAULT_ALARM.type), 0, bytes(200))
    writer.close()
    return path


def test_recover_refuses_a_bag_that_is_being_recorded(recording, tmp_path):
    live, pid = recording
    out = tmp_path / "copy.mcap"
    proc = _recover(str(live), str(out))
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert proc.stderr.strip().splitlines() == [
        f"phfdi bag: error: {live}: another process (pid {pid}) is recording this bag now; recover it after that "
        "recording has ended"]
    assert not out.exists() and list(tmp_path.glob("*copy*")) == []


def test_recover_does_not_replace_a_bag_that_is_being_recorded(recording, tmp_path):
    live, pid = recording
    before = live.read_bytes()
    proc = _recover(str(_finished_bag(tmp_path / "done.mcap")), str(live), "--overwrite")
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    (line,) = proc.stderr.strip().splitlines()
    assert f"{live}: another process (pid {pid}) is recording this bag now" in line
    assert live.read_bytes() == before


def test_recover_of_another_bag_works_while_one_is_recorded(recording, tmp_path):
    live, _ = recording
    done = _finished_bag(tmp_path / "done.mcap")
    proc = _recover(str(done), str(tmp_path / "copy.mcap"))
    assert proc.returncode == 0, proc.stderr
    assert "recovered 1 messages" in proc.stdout
