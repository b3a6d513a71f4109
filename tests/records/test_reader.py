"""read_record: each case of the reading policy, on small files made here."""

from __future__ import annotations

import math

import numpy as np
import pytest

from phfdi.records import ColumnMap, ReadError, read_record
from phfdi.records.record import Record
from phfdi_base.errors import UserError


def write(tmp_path, text: str, name: str = "r.csv", encoding: str = "utf-8") -> str:
    path = tmp_path / name
    path.write_bytes(text.encode(encoding))
    return str(path)


def table(n: int = 10, dt: float = 1.0, fmt=lambda i: f"{i * 0.1:.3f}") -> str:
    return "time_s,ph_measured,valve_command_pct\n" + "".join(f"{i * dt:g},{7 + i * 0.01:.2f},{fmt(i)}\n"
                                                              for i in range(n))


def test_clean_csv_reads_without_notes(tmp_path):
    r = read_record(write(tmp_path, table()))
    assert len(r) == 10 and r.names == ["ph_measured", "valve_command_pct"]
    assert r.note_lines() == []
    assert r.units["ph_measured"] == "pH" and r.units["valve_command_pct"] == "%"
    run = r.to_run()
    assert isinstance(run, Record) and np.allclose(run["time_s"], np.arange(10.0))


@pytest.mark.parametrize("delimiter", [",", ";", "\t"])
def test_any_delimiter(tmp_path, delimiter):
    r = read_record(write(tmp_path, table().replace(",", delimiter)))
    assert np.allclose(r.signals["ph_measured"][:2], [7.0, 7.01])


def test_semicolon_file_with_decimal_commas(tmp_path):
    text = "time_s;ph_measured\n" + "".join(f"{i};7,{i}\n" for i in range(5))
    r = read_record(write(tmp_path, text))
    assert np.allclose(r.signals["ph_measured"], [7.0, 7.1, 7.2, 7.3, 7.4])
    assert any("decimal commas" in n for n in r.notes)


@pytest.mark.parametrize("encoding", ["utf-8-sig", "utf-16", "utf-16-le", "latin-1"])
def test_encodings_detected(tmp_path, encoding):
    text = "time_s,temperature_°C,ph_measured\n0,20,7\n1,21,7.1\n2,22,7.2\n"
    r = read_record(write(tmp_path, text, encoding=encoding))
    assert "temperature_°C" in r.signals
    if encoding == "latin-1":
        assert any("not UTF-8" in n and "latin-1" in n for n in r.notes)


def test_undecodable_bytes_ask_for_encoding(tmp_path):
    path = tmp_path / "r.csv"
    path.write_bytes(b"time_s,ph\n0,7\n1,\x81\x8d\n")
    with pytest.raises(ReadError, match=r"r.csv: line 3: byte 0x81 is not UTF-8.*--encoding"):
        read_record(path)
    r = read_record(path, encoding="cp437")
    assert r.notes  # the text cell is missing and noted


def test_duplicate_rows_dropped_and_noted(tmp_path):
    lines = table(6).splitlines()
    text = "\n".join(lines[:4] + [lines[3]] + lines[4:]) + "\n"  # row at t=2 twice (file lines 4 and 5)
    r = read_record(write(tmp_path, text))
    assert len(r) == 6
    assert any("line 5: 1 exact duplicate row" in n for n in r.notes)


def test_repeated_stamp_before_a_skipped_one_is_respaced(tmp_path):
    stamps = ["12:00:30", "12:00:31", "12:00:31", "12:00:33", "12:00:34"]
    text = "timestamp,pv\n" + "".join(f"2026-01-01 {s},{i}\n" for i, s in enumerate(stamps))
    r = read_record(write(tmp_path, text))
    assert np.allclose(r.time_s, [0, 1, 2, 3, 4])
    assert np.allclose(r.signals["pv"], [0, 1, 2, 3, 4])
    note = [n for n in r.notes if "re-spaced" in n]
    assert note and "lines 3-4" in note[0] and "12:00:31" in note[0]


def test_other_repeated_stamps_are_averaged(tmp_path):
    text = "time_s,pv\n0,1\n1,2\n1,4\n2,5\n3,6\n"
    r = read_record(write(tmp_path, text))
    assert np.allclose(r.time_s, [0, 1, 2, 3]) and np.allclose(r.signals["pv"], [1, 3, 5, 6])
    assert any("averaged" in n and "lines 3-4" in n for n in r.notes)


@pytest.mark.parametrize("cell,kind", [("nan", "NaN 1"), ("inf", "inf 1"), ("-inf", "inf 1"), ("bad", "text 1"),
                                       ("", "empty 1")])
def test_nonnumeric_cells_are_missing_and_noted(tmp_path, cell, kind):
    text = "time_s,ph_measured\n0,7\n1,7.1\n2," + cell + "\n3,7.3\n"
    r = read_record(write(tmp_path, text))
    assert math.isnan(r.signals["ph_measured"][2])
    assert r.missing["ph_measured"].tolist() == [False, False, True, False]
    note = [n for n in r.notes if "column 'ph_measured'" in n]
    assert note and kind in note[0] and "line 4" in note[0]


def test_all_missing_channel_is_refused(tmp_path):
    text = "time_s,ph_measured,valve_command_pct\n" + "".join(f"{i},nan,{i}\n" for i in range(5))
    with pytest.raises(ReadError, match=r"r.csv: line 2, column 'ph_measured': no usable value"):
        read_record(write(tmp_path, text), channels=["ph_measured", "valve_command_pct"])


def test_all_missing_column_nobody_asked_for_is_kept_and_noted(tmp_path):
    text = "time_s,ph_measured,spare\n" + "".join(f"{i},7,\n" for i in range(5))
    r = read_record(write(tmp_path, text))
    assert r.names == ["ph_measured", "spare"] and np.isnan(r.signals["spare"]).all()
    assert any("'spare': all 5 cells not a number (empty 5)" in n for n in r.notes)
    with pytest.raises(ReadError, match="column 'spare': no usable value"):
        read_record(write(tmp_path, text), required=("spare",))


def test_short_gaps_filled_only_when_asked(tmp_path):
    text = "time_s,pv\n" + "".join(f"{i},{'' if i in (3, 4) else i}\n" for i in range(8))
    r = read_record(write(tmp_path, text))
    assert np.isnan(r.signals["pv"][3:5]).all()
    with pytest.raises(ReadError, match=r"line 5, column 'pv': 2 missing values"):
        r.refuse_missing("pv")
    f = r.filled(max_gap_s=2.0)
    assert np.allclose(f.signals["pv"], np.arange(8.0))
    assert any("filled by linear interpolation" in n and "lines 5-6" in n for n in f.notes)
    assert np.isnan(r.filled(max_gap_s=1.0).signals["pv"][3])  # a 2 s gap is longer than 1 s


def test_time_going_back_is_refused_under_run_policy(tmp_path):
    text = "time_s,pv\n0,1\n1,2\n2,3\n0,4\n1,5\n"
    with pytest.raises(ReadError) as err:
        read_record(write(tmp_path, text))
    path = tmp_path / "r.csv"
    assert str(err.value) == f"{path}: line 5: time goes back from 2 s to 0 s (clock reset); split the file"


def test_clock_reset_starts_a_segment_under_historian_policy(tmp_path):
    text = "time_s,pv\n" + "".join(f"{i},{i}\n" for i in range(6)) + "".join(f"{i},{10 + i}\n" for i in range(4))
    r = read_record(write(tmp_path, text), policy="historian")
    segs = r.segments()
    assert [len(s) for s in segs] == [6, 4]
    assert np.allclose(segs[1].signals["pv"], [10, 11, 12, 13])
    assert any("line 8: time goes back" in n and "new segment" in n for n in r.notes)
    with pytest.raises(ReadError, match="segments"):
        r.to_run()


def test_forward_jump_is_a_gap_under_run_and_a_segment_under_historian(tmp_path):
    text = "time_s,pv\n" + "".join(f"{t},{t}\n" for t in [*range(5), *range(100, 105)])
    run = read_record(write(tmp_path, text))
    assert not run.boundaries and any("gap in time" in n for n in run.notes)
    grid = run.on_grid(1.0)
    assert len(grid) == 105 and np.isnan(grid.signals["pv"][5:100]).all()
    hist = read_record(write(tmp_path, text), policy="historian")
    assert [len(s) for s in hist.segments()] == [5, 5]


def test_mode_column_segments_only_automatic(tmp_path):
    modes = ["AUTO"] * 4 + ["MAN"] * 3 + ["CAS"] * 5
    text = "time,op,pv,mode\n" + "".join(f"{i},{i},{i * 2},{m}\n" for i, m in enumerate(modes))
    cmap = ColumnMap.from_mapping({"columns": {"time": "time", "op": "op", "pv": "pv"}, "mode": "mode"})
    r = read_record(write(tmp_path, text), cmap, policy="historian")
    assert [len(s) for s in r.segments()] == [4, 5]
    assert len(r.longest_segment()) == 5
    assert any("lines 6-8, column 'mode': 3 samples not in automatic" in n for n in r.notes)


def test_quality_flag_marks_values_missing(tmp_path):
    text = "t,pv,q\n" + "".join(f"{i},{i},{'BAD' if i == 2 else 'GOOD'}\n" for i in range(5))
    r = read_record(write(tmp_path, text), {"time_s": "t", "pv": "pv", "quality": "q"})
    assert np.isnan(r.signals["pv"][2]) and not np.isnan(r.signals["pv"][3])
    assert any("line 4, column 'q': 1 samples flagged bad" in n for n in r.notes)


def test_step_hold_and_quantisation_are_noted(tmp_path):
    rng = np.random.default_rng(1)
    pv = np.round(np.repeat(rng.normal(50, 5, 40), 3) * 2) / 2  # held 3 samples, steps of 0.5
    text = "time_s,pv\n" + "".join(f"{i},{v}\n" for i, v in enumerate(pv))
    r = read_record(write(tmp_path, text))
    assert any("repeat the one before" in n for n in r.notes)
    assert any("quantised in steps of 0.5" in n for n in r.notes)


def test_column_map_units_and_both_forms(tmp_path):
    text = "Zeit (min),pH,OP\n0,7,0.5\n1,7.1,0.6\n2,7.2,0.7\n"
    path = write(tmp_path, text)
    cmap = ColumnMap.from_args(["time_s=Zeit (min)", "ph_measured=pH", "valve_command_pct=OP"],
                               ["time_s=min", "valve_command_pct=fraction"])
    r = read_record(path, cmap)
    assert np.allclose(r.time_s, [0, 60, 120]) and np.allclose(r.signals["valve_command_pct"], [50, 60, 70])
    assert r.columns["valve_command_pct"] == "OP"
    (tmp_path / "m.yaml").write_text("columns: {time: 'Zeit (min)', op: OP, pv: pH}\nloop_tag: X1\n")
    r2 = read_record(path, str(tmp_path / "m.yaml"))
    assert r2.names == ["op_pct", "pv"] and r2.metadata["loop_tag"] == "X1"


def test_missing_column_named(tmp_path):
    with pytest.raises(ReadError, match=r"r.csv: line 1, column 'ph': no such column.*did you mean 'pH'"):
        read_record(write(tmp_path, "time_s,pH\n0,7\n1,7\n"), {"time_s": "time_s", "ph_measured": "ph"})


@pytest.mark.parametrize("text,match", [("", "line 1: empty file"), ("time_s,ph\n", "line 2: no data rows"),
                                        ("time_s,ph\n0,7\n", "only 1 usable sample"),
                                        ("a,b\nx,1\ny,2\n", "line 1: no time column")])
def test_unusable_text_files(tmp_path, text, match):
    with pytest.raises(ReadError, match=match):
        read_record(write(tmp_path, text))


def test_not_a_time(tmp_path):
    with pytest.raises(ReadError, match=r"line 2, column 'time_s': 'abc' is not a time"):
        read_record(write(tmp_path, "time_s,ph\nabc,7\ndef,7\n"))


def test_parquet_round_trip_and_damage(tmp_path):
    run = Record.of({"time_s": np.arange(5.0), "ph_measured": np.array([7, np.nan, 7, np.inf, 7.0])}, {"seed": 3})
    path = run.to_parquet(tmp_path / "r.parquet")
    r = read_record(path)
    assert r.metadata["seed"] == 3 and r.where == "row"
    assert any("NaN 1, inf 1" in n and "row 2" in n for n in r.notes)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(ReadError, match=r"r.parquet: not a readable Parquet file"):
        read_record(path)


def test_magic_only_mcap(tmp_path):
    path = tmp_path / "m.mcap"
    path.write_bytes(b"\x89MCAP0\r\n")
    with pytest.raises(ReadError, match=r"m.mcap: cannot read the bag"):
        read_record(path)


def test_read_error_is_a_user_error():
    assert issubclass(ReadError, UserError)


def test_summary_is_json_ready(tmp_path):
    import json

    r = read_record(write(tmp_path, "time_s,pv\n0,1\n1,\n2,3\n"))
    s = json.loads(json.dumps(r.summary()))
    assert s["channels"]["pv"]["missing"] == 1 and s["notes"] == r.note_lines()


def test_on_grid_refuses_a_grid_blown_up_by_a_jump(tmp_path):
    text = "time_s,pv\n" + "".join(f"{i},{i}\n" for i in range(20)) + "1e9,1\n"
    rec = read_record(write(tmp_path, text))
    with pytest.raises(ReadError, match="would hold 1e\\+09 slots for 21 samples"):
        rec.on_grid(1.0)
