"""Reading measured data: column maps, units, resampling, and one clear message for bad input."""

from __future__ import annotations

import numpy as np
import pytest

from phfdi.diagnosis.data import diagnosis_map, load_record
from phfdi.records import ColumnMap
from phfdi_base.errors import UserError

HEADER = "Time, t (s),OP %,PV,level mm,,"


def _write(path, t, op, ph, level_mm, header=HEADER):
    rows = [header] + [f"x,{a},{b},{c},{d},," for a, b, c, d in zip(t, op, ph, level_mm)]
    path.write_text("\n".join(rows) + "\n")
    return path


def _map(tmp_path, extra: str = ""):
    p = tmp_path / "map.yaml"
    p.write_text('time_s: "t (s)"\nvalve_command_pct: {column: "OP %", unit: "%"}\nph_measured: PV\n'
                 'level_measured_cm: {column: "level mm", unit: mm}\n' + extra)
    return p


@pytest.fixture
def good(tmp_path):
    n = 400
    t = np.arange(n) * 1.0
    op = 40 + 10 * (np.arange(n) // 50 % 2)
    ph = 9 + 0.3 * np.sin(t / 30)
    return tmp_path, t, op, ph, np.full(n, 140.0)


def test_mapped_csv_units_and_uniform_time(good):
    tmp, t, op, ph, lev = good
    rec = load_record(_write(tmp / "a.csv", t, op, ph, lev), diagnosis_map(ColumnMap.load(_map(tmp))))
    assert rec.dt_s == pytest.approx(1.0)
    assert np.allclose(rec.outputs["level_measured_cm"], 14.0)  # mm -> cm
    assert set(rec.inputs) == {"valve_command_pct"} and not rec.notes


def test_nonuniform_sampling_is_resampled_and_said(good):
    tmp, t, op, ph, lev = good
    jitter = t * 0.35 + np.random.default_rng(0).uniform(-0.04, 0.04, len(t))
    rec = load_record(_write(tmp / "a.csv", jitter, op, ph, lev), diagnosis_map(ColumnMap.load(_map(tmp))))
    assert any("resampled" in n for n in rec.notes)
    assert np.allclose(np.diff(rec.time_s), rec.dt_s)
    # inputs held (zero-order hold): only values that were in the data
    assert set(np.unique(rec.inputs["valve_command_pct"])) <= set(np.unique(op))


def test_short_nan_gap_filled_and_said(good):
    tmp, t, op, ph, lev = good
    ph = ph.copy()
    ph[100:103] = np.nan
    rec = load_record(_write(tmp / "a.csv", t, op, ph, lev), diagnosis_map(ColumnMap.load(_map(tmp))))
    assert np.all(np.isfinite(rec.outputs["ph_measured"]))
    assert any("filled" in n for n in rec.notes)


@pytest.mark.parametrize("case, message", [
    ("missing_column", "column 'PV': no such column"),
    ("misnamed_column", "did you mean 'op%'"),
    ("time_backwards", "time goes back from 199 s to 150 s (out of order); split the file"),
    ("nan_stretch", "missing (NaN)"),
    ("ph_range", "pH must lie in 0..14"),
    ("bad_unit", "unit 'furlong'"),
    ("all_nan_ph", "line 2, column 'PV': no usable value"),
])
def test_bad_input_one_clear_message_exit_2(good, run_cli, case, message):
    tmp, t, op, ph, lev = good
    ph, t = ph.copy(), t.copy()
    header = HEADER
    if case == "missing_column":
        header = "Time, t (s),OP %,pH value,level mm,,"
    elif case == "misnamed_column":
        header = "Time, t (s),op%,PV,level mm,,"
    elif case == "time_backwards":
        t[200] = t[150]
    elif case == "nan_stretch":
        ph[100:160] = np.nan
    elif case == "ph_range":
        ph[50] = 15.2
    path = _write(tmp / "data.csv", t, op, ph, lev, header)
    mp = _map(tmp)
    if case == "bad_unit":
        mp.write_text(mp.read_text().replace("unit: mm", "unit: furlong"))
    if case == "all_nan_ph":
        path = _write(tmp / "data.csv", t, op, np.full(len(t), np.nan), lev, header)
    status, out, err = run_cli("diagnose", "--data", path, "--map", mp, "--model", "paper", "--out", tmp / "o",
                               "--quiet")
    assert status == 2
    assert message in err, err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_constant_inputs_nothing_identifiable(good, run_cli):
    tmp, t, op, ph, lev = good
    path = _write(tmp / "flat.csv", t, np.full(len(t), 45.0), ph, lev)
    status, out, err = run_cli("diagnose", "--data", path, "--map", _map(tmp), "--model", "paper", "--out",
                               tmp / "o", "--quiet", "--json")
    assert status == 2
    assert "nothing identifiable" in err and "constant" in err
    import json

    rep = json.loads(out)
    assert rep["verdict"] == "not_identifiable" and rep["cause"] == "none"


def test_arguments_checked(run_cli, tmp_path):
    status, _, err = run_cli("diagnose", "--model", "paper")
    assert status == 2 and "no data" in err
    status, _, err = run_cli("diagnose", "--data", tmp_path / "nope.csv")
    assert status == 2 and "no such file" in err
    status, _, err = run_cli("diagnose", "--data", tmp_path / "x.csv", "--column", "ph_measured")
    assert status == 2 and "SIGNAL=COLUMN" in err


def test_map_needs_time_output_input(tmp_path):
    with pytest.raises(UserError, match="needs time_s"):
        diagnosis_map(ColumnMap.from_mapping({"ph_measured": "pH", "valve_command_pct": "OP"}, "column map"))
    with pytest.raises(UserError, match="needs an input"):
        diagnosis_map(ColumnMap.from_mapping({"time_s": "t", "ph_measured": "pH"}, "column map"))
    with pytest.raises(UserError, match="cannot map onto 'temperature'"):
        diagnosis_map(ColumnMap.from_mapping({"time_s": "t", "temperature": "T"}, "column map"))


def test_the_diagnosis_reads_the_one_record_type_on_its_grid(good):
    """The diagnosis's record is phfdi.records.Record (issue 37: one in-memory record): its inputs and outputs are
    views of the same signals, its step is the grid's exactly, and a slice is a record of its own."""
    from phfdi.records import Record

    tmp, t, op, ph, lev = good
    jitter = t + np.where(np.arange(len(t)) % 3 == 1, 0.02, 0.0)  # non-uniform: put on a grid
    rec = load_record(_write(tmp / "a.csv", jitter, op, ph, lev), diagnosis_map(ColumnMap.load(_map(tmp))))
    assert isinstance(rec, Record)
    assert list(rec.inputs) == ["valve_command_pct"] and list(rec.outputs) == ["ph_measured", "level_measured_cm"]
    assert rec.inputs["valve_command_pct"] is rec.signals["valve_command_pct"]
    assert rec.grid_s is not None and rec.dt_s == rec.grid_s  # the grid's step, not a median of rounded steps
    assert rec.units["level_measured_cm"] == "cm" and rec.name == "a.csv"
    part = rec.slice(100, 200, name="middle")
    assert (len(part), part.name, part.dt_s) == (100, "middle", rec.dt_s)
    part.signals["ph_measured"][:] = 0.0  # a copy: the record it came from keeps its samples
    assert np.all(rec.outputs["ph_measured"][100:200] > 8.0)
    assert not rec.constant_inputs()
