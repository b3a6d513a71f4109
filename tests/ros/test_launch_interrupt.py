"""Ctrl-C at any moment of ``phfdi launch`` (issue 36 item 8): no traceback, exit status 130, no node left.

SIGINT 0.15 s after the start used to land while the command line was still importing its subcommands (building
the parser takes about 0.3 s) and printed a KeyboardInterrupt traceback; on a loaded machine it could also land in
the console script's import of the command line (the entry point is now :mod:`phfdi.console`, which imports
nothing before it can answer a Ctrl-C). The test sends SIGINT at several moments,
from the imports to the running graph (paced, so that it is still running), to a real ``phfdi`` process.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from .conftest import SHORT_RUN, processes_with

pytestmark = [pytest.mark.ros, pytest.mark.timeout(300)]

PHFDI = Path(sys.executable).parent / "phfdi"  # the console script a user runs
#: seconds after the start: the imports, the parser, the scenario, the nodes starting, the graph running
DELAYS_S = (0.15, 0.3, 0.6, 1.2, 2.5, 5.0)


@pytest.mark.parametrize("delay_s", DELAYS_S)
def test_sigint_at_any_moment_of_a_launch_ends_it_cleanly(delay_s, tmp_path):
    if not PHFDI.exists():
        pytest.skip(f"{PHFDI} not installed (bash scripts/setup.sh)")
    logs = tmp_path / "logs"  # every node's command line names its parameter file in here
    # as from a user's terminal: SIGINT at its default even where the test run itself ignores it (a shell starts a
    # background job, `pytest ... &`, with SIGINT ignored, and an ignored SIGINT is inherited: Python then never
    # installs its handler and the early signals are lost)
    proc = subprocess.Popen([str(PHFDI), "launch", *SHORT_RUN, "--pace", "50", "--log-dir", str(logs)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    time.sleep(delay_s)
    assert proc.poll() is None, "the launch ended before the signal"
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=120)
    if proc.returncode == -signal.SIGINT and not err:
        pass  # ended by the signal before the interpreter had set up its handler: no output at all, as wanted
    elif "init_import_site" in err:
        # on a loaded machine the interpreter itself may still be starting (its site module, where the ROS wheels'
        # bootstrapper re-executes it): Python's own fatal error, before any code of phfdi runs
        assert "/phfdi/" not in err and proc.returncode != 0, err
    else:
        assert proc.returncode == 130, (out, err)
        assert "Traceback" not in err and "KeyboardInterrupt" not in err, err
        if "started" in err:  # the nodes had started: the summary says they were stopped
            assert "stopped by SIGINT: all nodes stopped" in out, out
        else:  # still starting: one line
            assert err.strip().splitlines() in (["phfdi launch: interrupted"], ["phfdi: interrupted"]) \
                or "stopped by SIGINT" in out, (out, err)
    deadline = time.monotonic() + 10
    while processes_with(str(logs)) and time.monotonic() < deadline:  # a node ends within moments of the launcher
        time.sleep(0.1)
    assert processes_with(str(logs)) == [], "a node of the launch is still running"
