"""Fixtures for the detector node's tests: real processes, each graph on a ROS domain of its own.

Every process runs with ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST (set here,
before anything imports rclpy). ``ros_domain`` holds a domain id for the test
(the same lock files as ``phfdi launch`` and tests/ros, so no two graphs share
one); ``phfdi launch`` and ``phfdi replay --live`` reserve their own.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from phfdi.ros.env import ensure_localhost, graph_env, reserve_domain_id

ensure_localhost()  # this test process too (its own rclpy nodes)

ROOT = Path(__file__).resolve().parents[2]

#: the paper loop shortened: pH 8 from 200 s, backlash at 1000 s (warm-up 600 s, isolation 300 s later)
SHORT_FAULTY = ["--fault", "backlash", "--onset", "1000", "--set", "duration_s=1600",
                "--set", "setpoints.ph.changes=[{at_s: 200, value: 8.0}]"]


@pytest.fixture
def ros_domain():
    lease = reserve_domain_id()
    yield lease.domain_id
    lease.release()


@pytest.fixture
def ros_env(ros_domain) -> dict[str, str]:
    return graph_env(ros_domain)


def phfdi_cmd(*args: str) -> list[str]:
    return [sys.executable, "-m", "phfdi.cli", *args]


def node_cmd(module: str, **params) -> list[str]:
    cmd = [sys.executable, "-m", module, "--ros-args"]
    for k, v in params.items():
        cmd += ["-p", f"{k}:={v}"]
    return cmd


def processes_with(text: str) -> list[int]:
    """PIDs of live processes whose command line contains ``text``."""
    out = []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit() or int(d.name) == os.getpid():
            continue
        try:
            cmd = (d / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
            state = (d / "stat").read_text().split()[2]
        except OSError:
            continue
        if text in cmd and state != "Z":
            out.append(int(d.name))
    return out


def stop(proc: subprocess.Popen, timeout_s: float = 30.0) -> None:
    """SIGTERM, then SIGKILL if it does not end (only this test's own process)."""
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
