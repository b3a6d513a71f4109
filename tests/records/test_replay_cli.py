"""phfdi replay and phfdi bag to-run on the malformed files of issue 15: one line and exit 2, or a repaired run
whose every repair is named on stderr and in --json."""

from __future__ import annotations

import json

import numpy as np
import pytest

from phfdi.records import read_run
from phfdi.records.record import Record


def csv_lines(run: Record, path, edit=None) -> str:
    """The run as CSV text; ``edit(lines)`` changes the data lines (lines[0] is the header) before writing."""
    run.to_csv(path)
    lines = path.read_text().splitlines()
    if edit:
        edit(lines)
    path.write_text("\n".join(lines) + "\n")
    return str(path)


def set_cell(lines: list[str], row: int, column: str, value: str) -> None:
    col = lines[0].split(",").index(column)
    cells = lines[row].split(",")
    cells[col] = value
    lines[row] = ",".join(cells)


def one_error_line(status: int, err: str) -> str:
    lines = err.strip().splitlines()
    assert status == 2 and len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def test_clean_run_replays_without_notes(short_run, tmp_path, run_cli):
    status, out, err = run_cli("replay", csv_lines(short_run, tmp_path / "r.csv"), "--json", "--no-isolation")
    rep = json.loads(out)
    assert status == 0 and rep["notes"] == [] and rep["samples"] == len(short_run) and "note:" not in err


@pytest.mark.parametrize("value", ["nan", "inf", "-inf", "n/a"])
def test_nonfinite_ph_is_missing_held_and_said(short_run, tmp_path, run_cli, value):
    def edit(lines):
        for row in (300, 301, 302):
            set_cell(lines, row, "ph_measured", value)

    status, out, err = run_cli("replay", csv_lines(short_run, tmp_path / "r.csv", edit), "--json",
                               "--no-isolation")
    rep = json.loads(out)
    assert status == 0
    (note,) = [n for n in rep["notes"] if "'ph_measured'" in n]
    assert "3 cells not a number" in note and "line 301" in note
    assert f"note: {note}" in err
    # the detector took them as missing and said where they began and ended (a run's positions are its samples,
    # 1-based: file line 301 is sample 300)
    start, end = rep["input_problems"]
    assert "ph_measured: missing from 299 s" in start["message"] and start["line"] == 300
    assert "ph_measured: back at 302 s after 3 samples missing" in end["message"] and end["line"] == 303


def test_all_nan_ph_is_an_error(short_run, tmp_path, run_cli):
    def edit(lines):
        for row in range(1, len(lines)):
            set_cell(lines, row, "ph_measured", "nan")

    line = one_error_line(*run_cli("replay", csv_lines(short_run, tmp_path / "r.csv", edit))[::2])
    assert "r.csv: line 2, column 'ph_measured': no usable value" in line


def test_repeated_stamps_are_repaired_and_named(short_run, tmp_path, run_cli):
    def edit(lines):
        lines[101] = lines[100]  # exact duplicate of the row before (t = 99 s)
        set_cell(lines, 201, "time_s", lines[200].split(",")[0])  # 199, 199, 201: re-spaced

    status, out, err = run_cli("replay", csv_lines(short_run, tmp_path / "r.csv", edit), "--json",
                               "--no-isolation")
    rep = json.loads(out)
    assert status == 0
    assert any("line 102: 1 exact duplicate row" in n for n in rep["notes"])
    assert any("lines 201-202: repeated stamp 199 s next to a skipped one" in n for n in rep["notes"])
    assert rep["samples"] == len(short_run) - 1


@pytest.mark.parametrize("to, why", [("150", "out of order"), ("0", "clock reset")])
def test_time_going_back_is_refused(short_run, tmp_path, run_cli, to, why):
    def edit(lines):
        for k, row in enumerate(range(500, len(lines))):
            set_cell(lines, row, "time_s", str(float(to) + k))

    path = csv_lines(short_run, tmp_path / "r.csv", edit)
    line = one_error_line(*run_cli("replay", path)[::2])
    assert line == f"phfdi replay: error: {path}: line 501: time goes back from 498 s to {float(to):g} s ({why}); " \
                   f"split the file"


def test_non_utf8_csv(short_run, tmp_path, run_cli):
    path = tmp_path / "r.csv"
    csv_lines(short_run, path)
    data = path.read_bytes().replace(b"level_setpoint_cm", b"level_setpoint_\xb5m_cm")  # latin-1 micro sign
    path.write_bytes(data)
    status, out, err = run_cli("replay", path, "--no-isolation")
    assert status == 0 and "not UTF-8" in err and "read as latin-1" in err
    path.write_bytes(data.replace(b"\xb5", b"\x81\x8d"))  # neither UTF-8 nor latin-1/cp1252 text
    line = one_error_line(*run_cli("replay", path)[::2])
    assert "line 1: byte 0x81 is not UTF-8" in line and "--encoding" in line
    assert run_cli("replay", path, "--encoding", "cp437", "--no-isolation")[0] == 0


def test_corrupt_parquet_and_magic_only_mcap(short_run, tmp_path, run_cli):
    pq = short_run.to_parquet(tmp_path / "r.parquet")
    pq.write_bytes(pq.read_bytes()[:300] + b"\0" * 50 + pq.read_bytes()[350:])
    assert "not a readable Parquet file" in one_error_line(*run_cli("replay", pq)[::2])
    bag = tmp_path / "m.mcap"
    bag.write_bytes(b"\x89MCAP0\r\n")
    assert "m.mcap: cannot read the bag" in one_error_line(*run_cli("replay", bag)[::2])


def test_column_map_options(short_run, tmp_path, run_cli):
    path = tmp_path / "plant.csv"
    table = np.column_stack([short_run.time_s, short_run["ph_measured"], short_run["valve_command_pct"] / 100])
    np.savetxt(path, table, delimiter=";", header="t;pH;OP", comments="", fmt="%.12g")
    args = ["--column", "time_s=t", "--column", "ph_measured=pH", "--column", "valve_command_pct=OP",
            "--unit", "valve_command_pct=fraction", "--json", "--no-isolation"]
    status, out, err = run_cli("replay", path, *args)
    assert status == 0 and json.loads(out)["samples"] == len(short_run)
    assert "no such column" in one_error_line(*run_cli("replay", path, "--column", "ph_measured=PH")[::2])
    line = one_error_line(*run_cli("replay", path)[::2])
    assert "column 'ph_measured': no such column" in line


def test_bag_to_run_names_its_repairs(short_run, tmp_path, run_cli):
    from phfdi.bagio import write_run

    run = Record.of({"time_s": short_run.time_s.copy(), **{k: v.copy() for k, v in short_run.signals.items()}},
                   dict(short_run.metadata))
    run.signals["ph_measured"][10] = np.nan
    bag = write_run(run, tmp_path / "r.mcap")
    status, out, err = run_cli("bag", "to-run", bag, tmp_path / "out.csv")
    assert status == 0 and "sample 11" in err and "'ph_measured'" in err
    assert read_run(tmp_path / "out.csv")["ph_measured"][10] != read_run(tmp_path / "out.csv")["ph_measured"][10]
    bad = tmp_path / "m.mcap"
    bad.write_bytes(b"\x89MCAP0\r\n")
    assert "cannot read the bag" in one_error_line(*run_cli("bag", "to-run", bad, tmp_path / "o.csv")[::2])


def test_simulate_inputs_with_bad_samples_is_one_line(short_run, tmp_path, run_cli):
    """Open-loop inputs: a missing or negative flow is named by line and column (not a ValueError of the plant)."""
    def edit_nan(lines):
        set_cell(lines, 40, "acid_flow_ml_s", "nan")

    def edit_negative(lines):
        set_cell(lines, 40, "buffer_flow_ml_s", "-3")

    status, _, err = run_cli("simulate", "--inputs", csv_lines(short_run, tmp_path / "a.csv", edit_nan))
    *notes, line = err.strip().splitlines()  # the reader's note on the NaN cell, then the one error line
    assert status == 2 and all(": note: " in n for n in notes) and "Traceback" not in err
    assert "a.csv: line 41, column 'acid_flow_ml_s': 1 missing value" in line
    line = one_error_line(*run_cli("simulate", "--inputs",
                                   csv_lines(short_run, tmp_path / "b.csv", edit_negative))[::2])
    assert "b.csv: line 41, column 'buffer_flow_ml_s': a flow cannot be negative (-3)" in line
