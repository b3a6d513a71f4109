"""The detector node's parameters: listed with ranges, bad ones refused with one line (exit status 2); the retired
physics detector node's parameters refused by phfdi launch in one line that says what does their work now."""

from __future__ import annotations

import subprocess

import pytest

from phfdi.cli import main

from .conftest import node_cmd

pytestmark = [pytest.mark.ros, pytest.mark.timeout(300)]


def test_help_lists_the_parameters_with_ranges():
    out = subprocess.run(node_cmd("wavelet_fdi.learned_node")[:3] + ["--help"], capture_output=True, text=True,
                         timeout=60)
    assert out.returncode == 0
    for text in ("reference", "paper_physics", "loop_graph_topics", "channel_map_file", "heartbeat_period_s",
                 "changeable at runtime", "input_problem_period_s", "[0.05, 3600]"):
        assert text in out.stdout, text


def test_bad_parameters_are_refused_with_one_line(ros_env):
    cases = {
        "range": (node_cmd("wavelet_fdi.learned_node", reference="paper_physics", input_problem_period_s="0.01"),
                  ["input_problem_period_s", "[0.05, 3600]"]),
        "type": (node_cmd("wavelet_fdi.learned_node", reference="paper_physics", heartbeat_period_s="60"),
                 ["heartbeat_period_s", "double"]),
        "no reference": (node_cmd("wavelet_fdi.learned_node"), ["parameter reference", "paper_physics"]),
        "missing file": (node_cmd("wavelet_fdi.learned_node", reference="/nonexistent/ref.json"),
                         ["no such reference file"]),
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
    (["launch", "--detector-param", "calibration=my.yaml"],
     ["'calibration'", "retired", "phfdi calibrate --out REF.json", "reference="]),
    (["launch", "--detector-param", "foxglove_port=8765"], ["'foxglove_port'", "phfdi launch --foxglove"]),
    (["replay", "--live", "run.csv"], ["--live", ".mcap"]),
    (["replay", "--live", "missing.mcap"], ["no such file"]),
])
def test_bad_command_lines_are_refused_before_any_node_starts(args, words, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(args) == 2
    lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert len(lines) == 1 and all(w in lines[0] for w in words), lines
