"""phfdi diagnose on the malformed files of issue 15: one line and exit 2, or a repaired record whose repairs are
named on stderr and in the report; an all-NaN pH is an error, never a verdict from the level alone."""

from __future__ import annotations

import json

import numpy as np
import pytest

from phfdi.diagnosis.data import load_record

from .test_replay_cli import csv_lines, one_error_line, set_cell


def diagnose(run_cli, path, tmp_path, *extra):
    return run_cli("diagnose", "--data", path, "--model", "paper", "--out", tmp_path / "o", "--quiet", *extra)


def test_all_nan_ph_is_an_error_not_a_verdict(short_run, tmp_path, run_cli):
    def edit(lines):
        for row in range(1, len(lines)):
            set_cell(lines, row, "ph_measured", "nan")

    path = csv_lines(short_run, tmp_path / "r.csv", edit)
    status, out, err = diagnose(run_cli, path, tmp_path)
    assert "line 2, column 'ph_measured': no usable value" in one_error_line(status, err) and out == ""


@pytest.mark.parametrize("to, why", [("150", "out of order"), ("0", "clock reset")])
def test_time_going_back_is_refused(short_run, tmp_path, run_cli, to, why):
    def edit(lines):
        for k, row in enumerate(range(500, len(lines))):
            set_cell(lines, row, "time_s", str(float(to) + k))

    line = one_error_line(*diagnose(run_cli, csv_lines(short_run, tmp_path / "r.csv", edit), tmp_path)[::2])
    assert f"line 501: time goes back from 498 s to {float(to):g} s ({why}); split the file" in line


def test_damaged_files_are_one_line(short_run, tmp_path, run_cli):
    pq = short_run.to_parquet(tmp_path / "r.parquet")
    pq.write_bytes(pq.read_bytes()[:200])
    assert "not a readable Parquet file" in one_error_line(*diagnose(run_cli, pq, tmp_path)[::2])
    bag = tmp_path / "m.mcap"
    bag.write_bytes(b"\x89MCAP0\r\n")
    assert "cannot read the bag" in one_error_line(*diagnose(run_cli, bag, tmp_path)[::2])
    csv = tmp_path / "b.csv"
    csv.write_bytes(b"time_s,ph_measured,valve_command_pct\n0,7,\x81\x9d\n")
    line = one_error_line(*diagnose(run_cli, csv, tmp_path)[::2])
    assert "b.csv: line 2: byte 0x81 is not UTF-8" in line and "--encoding" in line


def test_repairs_become_notes_of_the_record(short_run, tmp_path):
    def edit(lines):
        lines[101] = lines[100]  # exact duplicate
        set_cell(lines, 201, "time_s", lines[200].split(",")[0])  # repeated stamp before a skipped one
        set_cell(lines, 301, "ph_measured", "inf")
        set_cell(lines, 302, "ph_measured", "n/a?")

    rec = load_record(csv_lines(short_run, tmp_path / "r.csv", edit))
    # the duplicate took the place of t = 100 s: one gap, resampled onto the 1 s grid (and said)
    assert len(rec) == len(short_run) and np.all(np.isfinite(rec.outputs["ph_measured"]))
    text = "\n".join(rec.notes)
    assert "line 102: 1 exact duplicate row" in text
    assert "lines 201-202: repeated stamp 199 s next to a skipped one" in text
    assert "column 'ph_measured': 2 cells not a number (inf 1, text 1)" in text and "first at line 302" in text
    assert "ph_measured: 2 missing samples in 1 gap(s) filled by linear interpolation" in text
    assert "resampled from non-uniform sampling" in text


def test_notes_reach_stderr_and_the_json_report(short_run, tmp_path, run_cli):
    def edit(lines):
        set_cell(lines, 301, "ph_measured", "nan")

    status, out, err = diagnose(run_cli, csv_lines(short_run, tmp_path / "r.csv", edit), tmp_path, "--json",
                                "--candidates", "sensor_bias", "--no-pairs", "--workers", "1")
    assert status in (0, 2) and "Traceback" not in err
    note = "column 'ph_measured': 1 cell not a number (NaN 1), first at line 302: marked missing"
    assert f"phfdi diagnose: note: r.csv: {note}" in err
    assert any(note in n for n in json.loads(out)["notes"])


def test_a_jump_in_time_is_refused_not_resampled(tmp_path, run_cli):
    """A stamp far ahead (a clock jump, a typo) would make a grid of 10^12 samples: one line instead."""
    rows = ["time_s,valve_command_pct,ph_measured"] + [f"{i},{40 + i % 5},{7 + 0.01 * i}" for i in range(100)]
    path = tmp_path / "jump.csv"
    path.write_text("\n".join(rows + ["1e12,40,7"]) + "\n")
    line = one_error_line(*diagnose(run_cli, path, tmp_path)[::2])
    assert "jump.csv: time jumps from t = 99 s to 1e+12 s" in line and "must be cut out" in line
    path.write_text("\n".join(rows) + "\n")
    line = one_error_line(*diagnose(run_cli, path, tmp_path, "--dt", "1e-9")[::2])
    assert "--dt 1e-09 s would make" in line


def test_an_absurd_flow_is_one_line_not_a_hang(short_run, tmp_path, run_cli):
    """A flow of 1e20 mL/s (a damaged cell) made the plant's integrator loop for ever (found by the fuzz test)."""
    def edit(lines):
        set_cell(lines, 40, "buffer_flow_ml_s", "1e20")

    path = csv_lines(short_run, tmp_path / "r.csv", edit)
    status, out, err = diagnose(run_cli, path, tmp_path, "--candidates", "sensor_bias", "--no-pairs", "--workers", "1")
    assert "the plant model cannot run on this record's inputs" in one_error_line(status, err)
    status, _, err = run_cli("simulate", "--inputs", path)
    assert status == 2 and "beyond 100000 integration sub-steps" in err


def test_ljung_box_of_a_flat_error_has_every_key():
    from phfdi.diagnosis.residual import ljung_box

    assert ljung_box(np.zeros(50)) == {"q": 0.0, "p_value": 1.0, "lags": 12, "white": True, "structure": 0.0}
