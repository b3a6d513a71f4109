"""Fixtures for the detector node's tests: real processes, each graph on a ROS domain of its own.

The ROS fixtures and helpers are tests/ros's (imported, not copied): every
process runs with ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST (set there, before
anything imports rclpy); ``ros_domain`` holds a domain id for the test (the same
lock files as ``phfdi launch``, so no two graphs share one); ``phfdi launch``
and ``phfdi replay --live`` reserve their own.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

from ..ros.conftest import node_cmd, phfdi_cmd, processes_with, ros_domain, ros_env  # noqa: F401

ROOT = Path(__file__).resolve().parents[2]

#: the paper loop shortened: pH 8 from 200 s, backlash at 1000 s (warm-up 600 s, isolation 300 s later)
SHORT_FAULTY = ["--fault", "backlash", "--onset", "1000", "--set", "duration_s=1600",
                "--set", "setpoints.ph.changes=[{at_s: 200, value: 8.0}]"]


def stop(proc: subprocess.Popen, timeout_s: float = 30.0) -> None:
    """SIGTERM, then SIGKILL if it does not end (only this test's own process)."""
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
