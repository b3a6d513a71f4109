"""A simulated run in the rig's CSV format: the recorded files' layout, read back unchanged through the ``ph_rig``
map, written atomically with its sidecars."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from phfdi.commands.common import shipped_map
from phfdi.learned import read_measured
from phfdi.rigsim import FLOW_PER_PCT, HEADER, ProbeFault, csv_text, simulate_run, write_run
from phfdi.rigsim.record import sidecars
from phfdi_base.errors import UserError

CHANNELS = ["acid_flow_ml_s", "base_flow_ml_s", "ph_measured"]
#: a data row of the recorded files: wall clock with a trailing space, ElapsedTime padded with spaces, 2 decimals
ROW = re.compile(r"^\d{1,2}/\d{1,2}/\d{4} \d{1,2}:\d\d:\d\d [AP]M , \d+\.?\d* ,(\d+\.\d\d,){4}\d+\.\d\d,\d+\.\d\d,,,,$")


@pytest.fixture(scope="module")
def run():
    return simulate_run("on_off_base", seed=4, duration_s=300.0)


def test_rows_have_the_recorded_files_layout(run):
    lines = csv_text(run).split("\n")
    assert lines[0] == HEADER and lines[-1] == ""
    assert all(ROW.match(line) for line in lines[1:-1]), next(line for line in lines[1:-1] if not ROW.match(line))
    assert len(lines) - 2 == len(run)


def test_flows_are_the_rigs_table_of_the_commands(run):
    for pump, pct, flow in (("acid", run.acid_pct, run.acid_flow_ml_s), ("base", run.base_pct, run.base_flow_ml_s)):
        assert np.allclose(flow, pct * FLOW_PER_PCT[pump])
    # the table reproduces every recorded (command, flow) pair at 2 decimals
    recorded = {("base", 20.0): "1.29", ("base", 33.6): "2.17", ("base", 49.9): "3.22", ("base", 50.0): "3.22",
                ("base", 60.0): "3.87", ("base", 100.0): "6.45", ("acid", 50.0): "3.59", ("acid", 60.0): "4.31"}
    assert all(f"{pct * FLOW_PER_PCT[pump]:.2f}" == text for (pump, pct), text in recorded.items())


def test_reads_back_through_the_ph_rig_map(run, tmp_path):
    path = tmp_path / "run.csv"
    write_run(run, path)
    rec = read_measured(path, shipped_map("ph_rig"), channels=CHANNELS)
    assert rec.notes == []
    assert np.allclose(rec.time_s, run.time_s, atol=1e-9)
    assert np.array_equal(rec.x, run.measured(CHANNELS).x)
    assert np.allclose(rec.x[:, 2], run.ph, atol=1e-9)
    assert np.allclose(rec.x[:, :2], np.column_stack([run.acid_flow_ml_s, run.base_flow_ml_s]), atol=0.005 + 1e-9)


def test_sampling_carries_the_recorded_jitter(run):
    dt = np.diff(run.time_s)
    assert np.all(dt >= 0.32) and np.all(dt <= 0.44)
    assert 0.343 < dt.mean() < 0.351 and 0.005 < dt.std() < 0.012  # recorded: mean 0.346-0.348 s, std 0.008 s
    assert np.allclose(dt * 1000.0, np.round(dt * 1000.0), atol=1e-6)  # the logger's millisecond clock


def test_write_refuses_to_overwrite_and_places_the_truth(tmp_path):
    faulty = simulate_run("pi_base", seed=2, duration_s=200.0, probe_fault=ProbeFault("probe_drift", 100.0, 0.3))
    path = tmp_path / "sub" / "run.csv"
    written = write_run(faulty, path)
    meta, fault = sidecars(path)
    assert written == [path, meta, fault]
    truth = json.loads(fault.read_text())
    assert truth["kind"] == "probe_drift" and truth["unit"] == "pH/min" and truth["closed_loop"] is True
    assert faulty.time_s[truth["onset_index"]] >= 100.0 > faulty.time_s[truth["onset_index"] - 1]
    assert json.loads(meta.read_text())["probe_fault"] == truth
    before = path.read_bytes()
    with pytest.raises(UserError, match="exists; give --overwrite"):
        write_run(simulate_run("pi_base", seed=3, duration_s=200.0), path)
    assert path.read_bytes() == before and fault.exists()
    # a healthy run written over a faulty one takes its stale truth away
    write_run(simulate_run("pi_base", seed=3, duration_s=200.0), path, overwrite=True)
    assert not fault.exists() and path.read_bytes() != before
    assert sorted(p.name for p in path.parent.iterdir()) == ["run.csv", "run.csv.rigsim.json"]
