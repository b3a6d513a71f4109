"""Stopping the graph at any moment: SIGTERM to the launcher, a node killed with SIGKILL.

Either way every process of the graph is gone afterwards, no Fast DDS
shared-memory file of a dead process is left, and the bag is readable.
"""

from __future__ import annotations

import os
import signal
import subprocess
import time

import pytest

from phfdi import bagio
from phfdi_base import topics as T

from .conftest import (
    SHORT_RUN,
    domain_of,
    ownerless_shm_files,
    phfdi_cmd,
    processes_with,
    read_until,
    shm_files_used,
    stale_shm_files,
)
from .rosbag2_check import rosbag2_record

pytestmark = [pytest.mark.ros, pytest.mark.timeout(300)]


def _start_paced(tmp_path, *extra):
    """A launch slow enough (20 x real time: 30 s for 600 s) to be stopped in the middle."""
    logs = tmp_path / "logs"
    bag = tmp_path / "run.mcap"
    before = ownerless_shm_files()
    proc = subprocess.Popen(phfdi_cmd("launch", *SHORT_RUN, "--pace", "20", "--record", str(bag),
                                      "--log-dir", str(logs), *extra),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    seen = read_until(proc, "graph connected", timeout_s=120)
    time.sleep(2.0)  # let some samples through
    used = shm_files_used(processes_with(str(logs)))
    assert used, "the graph's processes map no Fast DDS shared memory: the check below would be empty"
    return proc, bag, logs, (domain_of(seen), used, before)


def _pid_of(logs, module: str) -> int:
    (pid,) = [pid for pid in processes_with(str(logs))
              if module in open(f"/proc/{pid}/cmdline", "rb").read().decode(errors="replace")]
    return pid


def _wait_gone(logs, timeout_s: float = 30.0) -> list[int]:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and processes_with(str(logs)):
        time.sleep(0.2)
    return processes_with(str(logs))


def _assert_counts_consistent(bag):
    info = bagio.bag_info(bag)
    assert info["finished"], info
    counts = {t["topic"]: t["count"] for t in info["topics"]}
    n = counts[T.MEASUREMENT.name]
    assert n > 0
    # stopped in the middle of a sample: each later stage of it may be missing, nothing else
    assert n - 1 <= counts[T.CONTROLLER.name] <= n
    assert counts[T.CONTROLLER.name] - 1 <= counts[T.VALVE_STATE.name] <= counts[T.CONTROLLER.name]
    assert counts[T.VALVE_STATE.name] - 1 <= counts[T.PLANT_STATE.name] <= counts[T.VALVE_STATE.name]
    run = bagio.load_run(bag)
    assert len(run) == n
    return n


def test_sigterm_to_the_launcher_stops_every_node_and_closes_the_bag(tmp_path):
    proc, bag, logs, domain = _start_paced(tmp_path)
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 128 + signal.SIGTERM, err.decode()
    assert "stopped by SIGTERM" in out.decode()
    assert _wait_gone(logs) == []
    n = _assert_counts_consistent(bag)
    assert n < 601  # it really was stopped in the middle
    assert stale_shm_files(*domain) == []


def test_a_killed_node_is_named_and_the_rest_stops_cleanly(tmp_path):
    proc, bag, logs, domain = _start_paced(tmp_path)
    os.kill(_pid_of(logs, "valve_actuator.node"), signal.SIGKILL)
    out, err = proc.communicate(timeout=120)
    err = err.decode()
    assert proc.returncode == 1, err
    assert "node valve" in err and "SIGKILL" in err
    assert _wait_gone(logs) == []
    _assert_counts_consistent(bag)
    assert stale_shm_files(*domain) == []  # the launcher cleaned the killed node's shared memory


def test_a_killed_recorder_leaves_a_bag_the_launcher_recovers(tmp_path):
    proc, bag, logs, domain = _start_paced(tmp_path)
    os.kill(_pid_of(logs, "phfdi.ros.recorder"), signal.SIGKILL)
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 1
    assert "node recorder" in err.decode() and "recovered" in out.decode()
    assert _wait_gone(logs) == []
    info = bagio.bag_info(bag)
    assert info["finished"] and info["messages"] > 0
    # the killed recorder never wrote rosbag2's metadata record (it is written at close): the recovery did
    meta = rosbag2_record(bag)
    assert meta["message_count"] == info["messages"]
    assert {t["topic_metadata"]["name"]: t["message_count"] for t in meta["topics_with_message_count"]} == \
        {t["topic"]: t["count"] for t in info["topics"]}
    assert stale_shm_files(*domain) == []


def test_every_node_ends_when_the_launcher_is_killed(tmp_path):
    """SIGKILL gives the launcher no chance to stop anything: each node asked the kernel for SIGTERM when it
    dies (PR_SET_PDEATHSIG, set by the node itself since the launcher starts it without a pre-exec hook)."""
    from phfdi.ros.launcher import remove_ownerless_ports

    t0 = time.time()
    proc, bag, logs, domain = _start_paced(tmp_path)
    nodes = [pid for pid in processes_with(str(logs)) if pid != proc.pid]
    assert len(nodes) == 4, nodes  # plant, valve, controllers, recorder
    proc.kill()
    proc.communicate(timeout=60)
    try:
        assert _wait_gone(logs) == []
    finally:
        for pid in processes_with(str(logs)):  # only this test's nodes (their command lines name its folder)
            os.kill(pid, signal.SIGKILL)
        time.sleep(1.0)
        remove_ownerless_ports(domain[0], t0)
