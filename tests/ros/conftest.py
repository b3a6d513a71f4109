"""Fixtures for tests that start real ROS 2 processes.

Every process of these tests runs with ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
(set here, before anything imports rclpy) and on a ROS domain of its own:
``ros_domain`` holds a domain id for the test (a lock no other phfdi graph or
test worker can take); ``phfdi launch`` reserves its own the same way.
"""

from __future__ import annotations

import fcntl
import os
import select
import subprocess
import sys
import time
from pathlib import Path

import pytest

from phfdi_base.ros.env import ensure_localhost, graph_env, reserve_domain_id, use_discovery_profile

ensure_localhost()  # this test process too (its own rclpy nodes)
use_discovery_profile()  # and it discovers the graph's nodes as they discover each other

pytestmark = pytest.mark.ros


@pytest.fixture
def ros_domain():
    lease = reserve_domain_id()
    yield lease.domain_id
    lease.release()


@pytest.fixture
def ros_env(ros_domain) -> dict[str, str]:
    env = graph_env(ros_domain)
    return env


@pytest.fixture
def rclpy_context(ros_domain):
    """An rclpy context of this test process on the test's domain."""
    import rclpy

    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=ros_domain)
    yield ctx
    close_context(ctx)


def close_context(context, node=None, executor=None) -> None:
    """End a test's rclpy context with its DDS participant. ``shutdown`` alone leaves the participant alive
    until garbage collection; it keeps writing to the ports of nodes that have stopped and re-creates their
    shared-memory files, ownerless, during later tests of this process (seen as port7000/7001 left behind)."""
    import rclpy

    if node is not None:
        node.destroy_node()
    if executor is not None:
        executor.shutdown()
    rclpy.try_shutdown(context=context)
    context.destroy()


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


def shm_files_used(pids: list[int]) -> set[str]:
    """Fast DDS shared-memory files mapped by these processes (what a graph uses)."""
    names = set()
    for pid in pids:
        try:
            maps = Path(f"/proc/{pid}/maps").read_text()
        except OSError:
            continue
        names.update(line.rsplit("/", 1)[-1] for line in maps.splitlines() if "/dev/shm/fastrtps_" in line)
    return names


def _owned(name: str) -> bool:
    """A live process holds the lock file of this segment."""
    lock = Path("/dev/shm") / f"{name}_el"
    try:
        with open(lock, "rb") as fd:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            fcntl.flock(fd, fcntl.LOCK_UN)
        return False
    except FileNotFoundError:
        return False
    except OSError:
        return True


def ownerless_shm_files() -> set[str]:
    """Fast DDS shared-memory files on disk that no live process owns (e.g. left by an earlier run)."""
    return {f.name for f in Path("/dev/shm").glob("fastrtps_*")
            if not f.name.endswith(("_el", "_sl")) and not _owned(f.name)}


def stale_shm_files(domain_id: int, used: set[str] = frozenset(), before: set[str] = frozenset()) -> list[str]:
    """Shared-memory files of a finished graph still on disk: the domain's port segments
    nobody owns, and any file the graph used (``shm_files_used``) whose owner is gone; files that
    were already ownerless before the graph started (``before``) are not the graph's."""
    from phfdi.ros.launcher import ownerless_port_segments

    stale = {f.name for f in ownerless_port_segments(domain_id, since=float("inf"))}
    stale |= {n for n in used if (Path("/dev/shm") / n).exists() and not _owned(n)}
    return sorted(stale - set(before))


def domain_of(launch_stderr: str) -> int:
    """The ROS domain a launch reported ("... on ROS domain N: ...")."""
    import re

    return int(re.search(r"on ROS domain (\d+)", launch_stderr).group(1))


def phfdi_cmd(*args: str) -> list[str]:
    return [sys.executable, "-m", "phfdi.cli", *args]


def node_cmd(module: str, **params) -> list[str]:
    cmd = [sys.executable, "-m", module, "--ros-args"]
    for k, v in params.items():
        cmd += ["-p", f"{k}:={v}"]
    return cmd


def read_until(proc: subprocess.Popen, pattern: str, timeout_s: float) -> str:
    """Read the process's stderr until a line contains ``pattern``; returns what was read."""
    seen = getattr(proc, "stderr_seen", "")
    deadline = time.monotonic() + timeout_s
    fd = proc.stderr.fileno()
    while time.monotonic() < deadline:
        ready, _, _ = select.select([fd], [], [], 0.2)
        if ready:
            chunk = os.read(fd, 65536).decode(errors="replace")
            if not chunk:
                break
            seen += chunk
            proc.stderr_seen = seen
            if pattern in seen:
                return seen
        elif proc.poll() is not None:
            break
    raise AssertionError(f"{pattern!r} not seen within {timeout_s} s; stderr so far:\n{seen}")


#: a short paper scenario: setpoint step at 200 s, a valve and a sensor fault inside the run
SHORT_RUN = ["--set", "duration_s=600", "--set", "setpoints.ph.changes.0.at_s=200",
             "--set", "faults=[{type: backlash, params: {width_pct: 0.7}, onset_s: 300.0},"
                      " {type: sensor_delay, where: ph_sensor, params: {delay_s: 10.0}, onset_s: 400.0}]"]
SHORT_OVERRIDES = [SHORT_RUN[i + 1] for i in range(0, len(SHORT_RUN), 2)]
