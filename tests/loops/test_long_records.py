"""Long records: screened in windows, read as windows when the file is too long to read whole, bounded either way.

The time and memory figures are benchmarks/plant_wide.py's (a 1 M and a 10 M-sample record); here the rules, on
records made small by shrinking the bounds.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.stats import binom

from phfdi.loopdiag import readers, windows
from phfdi.loopdiag.classifier import NO_STICTION, STICTION, UNDETERMINED
from phfdi.loopdiag.diagnose import Settings
from phfdi.loopdiag.single import diagnose_run
from phfdi.loopdiag.synthetic import SyntheticLoop, simulate_loop
from phfdi.records.record import Record


def test_window_bounds_cover_a_record_evenly_and_are_bounded():
    run = Record.of({"time_s": np.arange(10 * 751.0)})
    b = windows.window_bounds(run)
    assert len(b) == 10 and b[0] == (0, 751) and b[-1] == (10 * 751 - 751, 10 * 751)
    long = Record.of({"time_s": np.arange(1000 * 751.0)})
    b = windows.window_bounds(long)
    assert len(b) == windows.MAX_WINDOWS and b[0][0] == 0 and b[-1][1] == 1000 * 751
    assert all(stop - start == windows.WINDOW for start, stop in b)


@pytest.mark.parametrize("m", [2, 3, 10, 64])
def test_critical_count_is_the_least_count_healthy_windows_reach_at_the_level(m):
    k = windows.critical_count(m, 0.02, 0.01)
    assert binom.sf(k - 1, m, 0.02) <= 0.01 < binom.sf(k - 2, m, 0.02)


def _windows(st: int, und: int, no: int, unscored: int = 0) -> list[dict]:
    calls = [STICTION] * st + [UNDETERMINED] * und + [NO_STICTION] * no
    out = [{"start": 0, "stop": 1, "structure": None, "call": c, "probability": 0.5} for c in calls]
    return out + [{"start": 0, "stop": 1, "structure": "pv_frozen", "call": None, "probability": None}] * unscored


def test_record_call_from_the_windows():
    k = windows.critical_count(20)
    assert windows.record_call(_windows(k, 0, 20 - k))["call"] == STICTION
    assert windows.record_call(_windows(k - 1, 12 - k, 9))["call"] == UNDETERMINED
    assert windows.record_call(_windows(k - 1, 0, 21 - k))["call"] == NO_STICTION
    assert windows.record_call(_windows(0, 0, 0, unscored=3))["call"] == "pv_frozen"


def _sticky(n: int, seed: int = 1) -> Record:
    return simulate_loop(SyntheticLoop(valve=("stiction", {"s_pct": 3.0, "j_pct": 1.0}), ti_s=30, dt_s=4.0,
                                       duration_s=4.0 * n, setpoint_steps=[(100, 52), (1500, 49)], seed=seed,
                                       loop_tag="FIC7"))


def test_a_long_record_is_screened_in_windows_and_says_so(tmp_path):
    run = _sticky(4 * 751)
    rep = diagnose_run(run, Settings(baselines=False), figure_dir=str(tmp_path))
    w = rep["windows"]
    assert rep["samples"] == len(run) and w["windows"] == 4 and w["scored"] == 4
    assert w[STICTION] + w[UNDETERMINED] + w[NO_STICTION] == 4
    lv = rep["loop_verdict"]  # the windows' call, unless the valve-model fit took it back or decided it
    assert lv["verdict"] == w["call"] or lv["contradiction"] or lv["decided_by_valve_model"]
    assert any("4 windows of up to 751 samples screened" in n for n in rep["notes"])
    assert (tmp_path / Path(rep["figure"]).name).is_file()


def test_a_file_too_long_to_read_whole_is_read_as_windows_with_its_line_numbers(tmp_path, monkeypatch):
    monkeypatch.setattr(readers, "MAX_READ_ROWS", 2000)
    monkeypatch.setattr(readers, "WINDOW_ROWS", 300)
    monkeypatch.setattr(readers, "SAMPLED_WINDOWS", 4)
    run = _sticky(3000)
    path = run.to_csv(tmp_path / "FIC7.csv")
    lines = path.read_text().splitlines()
    got = readers.read_loop(path)
    assert got.metadata["windows"][0][:2] == (0, 300) and len(got.metadata["windows"]) == 4
    assert "the file holds 3000 rows, more than 2000" in got.metadata["notes"][0]
    for start, stop, line_a, line_b in got.metadata["windows"]:
        # each window's samples are the file's lines it names
        assert float(lines[line_a - 1].split(",")[1]) == pytest.approx(got["op_pct"][start])
        assert float(lines[line_b - 1].split(",")[1]) == pytest.approx(got["op_pct"][stop - 1])
    # a file under the bound is read whole, as before
    monkeypatch.setattr(readers, "MAX_READ_ROWS", 5000)
    assert len(readers.read_loop(path)) == 3000 and "windows" not in readers.read_loop(path).metadata
