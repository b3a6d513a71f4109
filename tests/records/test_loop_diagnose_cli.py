"""phfdi loop-diagnose under the historian policy: repairs named on stderr and in --json, each stretch on request,
one line for a file with nothing usable."""

from __future__ import annotations

import json

import numpy as np

from tests.loops.test_readers import export_rows


def test_repairs_on_stderr_and_in_json(tmp_path, run_cli):
    stamps = [10 * k for k in range(300)]
    stamps[120] = stamps[119]
    pv = 100 + np.sin(np.arange(300) / 4)
    path = export_rows(tmp_path / "r.txt", stamps, pv)
    status, out, err = run_cli("loop-diagnose", path, "--json", "--no-baselines", "--causes", "stiction",
                               "--workers", "1")
    assert status == 0 and "Traceback" not in err
    (rep,) = json.loads(out)["files"]
    (note,) = [n for n in rep["reading_notes"] if "re-spaced" in n]
    assert "lines 125-126" in note and f"phfdi loop-diagnose: note: {path}: {note}" in err
    assert note in rep["notes"]


def test_each_stretch_is_diagnosed_on_request(tmp_path, run_cli):
    stamps = [10 * k for k in range(150)] + [10 * k for k in range(200)]
    pv = 100 + np.sin(np.arange(350) / 4)
    path = export_rows(tmp_path / "r.txt", stamps, pv)
    status, out, err = run_cli("loop-diagnose", path, "--json", "--no-baselines", "--causes", "stiction",
                               "--workers", "1", "--segments", "each")
    reps = json.loads(out)["files"]
    assert status == 0 and [r["lines"] for r in reps] == [[6, 155], [156, 355]]
    assert [r["samples"] for r in reps] == [150, 200]


def test_nothing_usable_is_one_line_exit_2(tmp_path, run_cli):
    modes = [0] * 200
    path = export_rows(tmp_path / "r.txt", [10 * k for k in range(200)], np.sin(np.arange(200.0)), modes)
    status, out, err = run_cli("loop-diagnose", path)
    lines = err.strip().splitlines()
    assert status == 2 and len(lines) == 1 and "no usable stretch" in lines[0] and "Traceback" not in err
