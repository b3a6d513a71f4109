"""The launcher's watchdog (issue 22 item 3): a stalled graph is named and stopped cleanly, a slow paced one is not.

The stall is real: the valve node's process is stopped with SIGSTOP while the graph runs.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time

import pytest

from phfdi.ros.launcher import WATCHDOG_S, WATCHDOG_SAMPLE_PERIODS, Launcher, NodeSpec

from .conftest import phfdi_cmd, processes_with, stale_shm_files
from .test_lifecycle import _assert_counts_consistent, _pid_of, _start_paced, _wait_gone

pytestmark = [pytest.mark.ros, pytest.mark.timeout(300)]


def test_the_watchdog_limit_is_never_shorter_than_a_few_sample_periods():
    from phfdi.commands import launch

    assert (launch.WATCHDOG_S, launch.WATCHDOG_SAMPLE_PERIODS) == (WATCHDOG_S, WATCHDOG_SAMPLE_PERIODS)
    launcher = Launcher([NodeSpec("plant", "ph_plant_sim.node")], watchdog_s=3.0)
    assert launcher.watchdog_limit_s(1.0) == 3.0  # lock-step
    launcher._pace = 20.0  # as the plant reports it: 0.05 s of wall time per sample
    assert launcher.watchdog_limit_s(1.0) == 3.0
    launcher._pace = 0.1  # 10 s per sample
    assert launcher.watchdog_limit_s(1.0) == pytest.approx(WATCHDOG_SAMPLE_PERIODS * 10.0)


def test_a_stalled_graph_is_named_and_stopped_by_the_watchdog(tmp_path):
    watchdog_s = 3.0
    proc, bag, logs, domain = _start_paced(tmp_path, "--watchdog-s", str(watchdog_s))
    valve = _pid_of(logs, "valve_actuator.node")
    try:
        os.kill(valve, signal.SIGSTOP)
        t_stall = time.monotonic()
        out, err = proc.communicate(timeout=120)
        stopped_after_s = time.monotonic() - t_stall
        out, err = out.decode(), err.decode()
        assert proc.returncode == 1, err
        (line,) = [ln for ln in err.splitlines() if "error:" in ln]
        assert line.startswith("phfdi launch: error: graph stalled: no progress from the plant for ")
        assert f"(watchdog {watchdog_s:g} s) at sample " in line
        assert f"stopped processes (SIGSTOP or a debugger): valve (pid {valve})" in line
        assert "Traceback" not in err
        # the watchdog counts from the last progress report (at most PROGRESS_PERIOD_S = 1 s before the stall);
        # the stop then takes a few seconds
        assert watchdog_s - 1.1 < stopped_after_s < watchdog_s + 10.0, stopped_after_s
        assert _wait_gone(logs) == []  # the stopped valve too: it got SIGCONT after SIGTERM
        n = _assert_counts_consistent(bag)  # the bag was closed the SIGTERM way: finished, readable
        assert 0 < n < 601
        assert f"at sample {n - 1} of 601" in line  # the sample the plant waits at, exact from the nodes' counts
        assert "messages published per topic when the stalled graph was stopped" in out
        assert stale_shm_files(*domain) == []
    finally:
        for pid in processes_with(str(logs)):  # only this test's nodes (their command lines name its folder)
            os.kill(pid, signal.SIGCONT)
            os.kill(pid, signal.SIGKILL)
    # the plant reported progress at least every second of wall time (1 s = 20 samples at pace 20), more often
    # than every twentieth of the run (30 samples), which is what a paced run's watchdog needs
    samples = [e["sample"] for e in map(json.loads, (logs / "plant.stdout").read_text().splitlines())
               if e.get("event") == "progress"]
    gaps = [b - a for a, b in zip(samples, samples[1:])]
    assert gaps and max(gaps) <= 25, samples


def test_a_slow_paced_run_is_not_taken_for_a_stall(tmp_path):
    """2 s of wall time per sample against a 1 s watchdog: the limit grows to several sample periods."""
    proc = subprocess.run(phfdi_cmd("launch", "--set", "duration_s=4", "--set", "setpoints.ph.changes.0.at_s=2",
                                    "--pace", "0.5", "--watchdog-s", "1", "--json"),
                          capture_output=True, text=True, timeout=180)
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    assert summary["samples"] == summary["of"] == 5 and summary["wall_s"] > 6.0  # 4 sample periods of 2 s
