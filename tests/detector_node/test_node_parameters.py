"""The detector node's parameters: listed with ranges, bad ones refused with one line (exit status 2)."""

from __future__ import annotations

import subprocess

import pytest

from phfdi.cli import main

from .conftest import node_cmd

pytestmark = [pytest.mark.ros, pytest.mark.timeout(300)]


def test_help_lists_the_parameters_with_ranges():
    out = subprocess.run(node_cmd("wavelet_fdi.node")[:3] + ["--help"], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0
    for text in ("calibration", "wavelet", "level", "[1, 10]", "heartbeat_period_s", "changeable at runtime",
                 "pairing_timeout_s"):
        assert text in out.stdout


def test_bad_parameters_are_refused_with_one_line(ros_env):
    cases = {
        "range": (node_cmd("wavelet_fdi.node", level="12"), ["level", "[1, 10]"]),
        "type": (node_cmd("wavelet_fdi.node", heartbeat_period_s="60"), ["heartbeat_period_s", "double"]),
        "no calibration": (node_cmd("wavelet_fdi.node", wavelet="db4"), ["no shipped calibration", "db4"]),
        "missing file": (node_cmd("wavelet_fdi.node", calibration="/nonexistent/cal.yaml"),
                         ["no such calibration file"]),
        "channel": (node_cmd("wavelet_fdi.node", channels="[ph, flow]"), ["channel 'flow'"]),
    }
    procs = {k: subprocess.Popen(cmd, env=ros_env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for k, (cmd, _) in cases.items()}
    for key, proc in procs.items():
        _out, err = proc.communicate(timeout=120)
        lines = [ln for ln in err.splitlines() if ln.strip()]
        assert proc.returncode == 2, (key, err)
        assert len(lines) == 1 and "Traceback" not in err, (key, err)
        for word in cases[key][1]:
            assert word in lines[0], (key, lines[0])


@pytest.mark.parametrize("args, words", [
    (["launch", "--detector-param", "level"], ["--detector-param", "NAME=VALUE"]),
    (["replay", "--live", "run.csv"], ["--live", ".mcap"]),
    (["replay", "--live", "missing.mcap"], ["no such file"]),
])
def test_bad_command_lines_are_refused_before_any_node_starts(args, words, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(args) == 2
    lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert len(lines) == 1 and all(w in lines[0] for w in words), lines
