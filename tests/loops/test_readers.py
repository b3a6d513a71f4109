"""Readers: the plant_loops export, CSV with a column mapping, and one clear message per bad file."""

from __future__ import annotations

import numpy as np
import pytest

from phfdi.loopdiag.readers import (
    LoopDataError,
    guess_columns,
    parse_loop_columns,
    process_type_for,
    read_loop,
    read_loop_segments,
)


def simple_export(path, n=150, pv=None, dt=10):
    """A file in the plant_loops layout (CRLF, 5 header lines, then rows) with a sine PV."""
    t = np.arange(n)
    pv = 100 + np.sin(2 * np.pi * t / 30) if pv is None else pv
    op = 40 + 0.5 * np.cos(2 * np.pi * t / 30)
    lines = ["PROCESSDATA\tX1LIC7 Data\tyyyy-MM-dd HH:mm:ss", f"8\t{dt}\t2024-01-01 00:00:00\t{n}",
             "tagname\tX1LIC7.MV\tX1LIC7.PV\tX1LIC7.SV\tX1LIC7.MODE\tbOpOFL\tbPvOFL\tbSpOFL\tbAutOFL",
             "desc\ta\tb\tc\tAut\tf1\tf2\tf3\tf4", "settings"]
    for k in range(n):
        secs = k * dt
        lines.append(f"2024-01-01 {secs // 3600:02d}:{secs // 60 % 60:02d}:{secs % 60:02d}\t{float(op[k])!r}\t"
                     f"{float(pv[k])!r}\t100\t1\t0\t0\t0\t0")
    path.write_bytes(("\r\n".join(lines) + "\r\n").encode("utf-8"))
    return path


def test_plant_export_becomes_a_run(tmp_path):
    run = read_loop(simple_export(tmp_path / "a.txt"))
    assert run.names == ["op_pct", "pv", "sp"] and "time_s" in run  # MODE keeps automatic stretches, no signal
    assert run.metadata["loop_tag"] == "X1LIC7"
    assert run.metadata["process_type"] == "integrating"  # a level loop
    assert run.dt_s == 10.0 and len(run) == 150
    assert run["pv"][0] == pytest.approx(100.0) and run["op_pct"][0] == pytest.approx(40.5)
    assert run.metadata["descriptions"]["pv"] == "b"


def test_csv_with_mapping_string_and_yaml(tmp_path):
    t = np.arange(200) * 5.0
    rows = ["Timestamp;FIC1.OUT;FIC1.MEAS;FIC1.SET"] + [f"{ti};{50 + np.sin(ti / 40)};{3 + np.cos(ti / 40)};3"
                                                         for ti in t]
    path = tmp_path / "x.csv"
    path.write_text("\n".join(rows))
    cmap = parse_loop_columns("op=FIC1.OUT,pv=FIC1.MEAS,sp=FIC1.SET,time=Timestamp")
    run = read_loop(path, cmap)
    assert run.dt_s == 5.0 and run["sp"][3] == 3.0 and run["pv"][0] == pytest.approx(4.0)
    yml = tmp_path / "map.yaml"
    yml.write_text("columns: {op: FIC1.OUT, pv: FIC1.MEAS}\nloop_tag: FIC1\nsample_time_s: 5\n")
    run2 = read_loop(path, parse_loop_columns(str(yml)))
    assert run2.metadata["loop_tag"] == "FIC1" and "sp" not in run2
    assert np.allclose(run2["op_pct"], run["op_pct"])


def test_csv_columns_guessed_from_tags_and_iso_time(tmp_path):
    rows = ["time,TIC5.OP,TIC5.PV,TIC5.SP"] + [f"2024-01-01T00:{k // 60:02d}:{k % 60:02d},{50 + k % 7},{(k // 5) % 5},2"
                                             for k in range(0, 600, 5)]
    path = tmp_path / "t.csv"
    path.write_text("\n".join(rows))
    run = read_loop(path)
    assert run.metadata["loop_tag"] == "TIC5" and run.dt_s == 5.0
    assert guess_columns(["a", "b"]) is None


def test_constant_pv_is_read_and_left_to_the_diagnosis(tmp_path):
    run = read_loop(simple_export(tmp_path / "constant.txt", pv=np.full(150, 5.0)))
    assert np.all(run["pv"] == 5.0)  # loopcheck calls it frozen (tests/loops/test_verdicts.py)


@pytest.mark.parametrize("problem, expected", [
    ("short", "too short"),
    ("nan", "missing for 20 samples"),
])
def test_bad_files_get_one_clear_message(tmp_path, problem, expected):
    n = 40 if problem == "short" else 150
    pv = np.full(n, 5.0) if problem == "constant" else 100 + np.sin(np.arange(n) / 3)
    if problem == "nan":
        pv[50:70] = np.nan
    path = simple_export(tmp_path / f"{problem}.txt", n=n, pv=pv)
    with pytest.raises(LoopDataError, match=expected) as err:
        read_loop(path)
    assert str(path) in str(err.value) and "\n" not in str(err.value)


def test_short_gaps_are_filled_and_noted(tmp_path):
    pv = 100 + np.sin(np.arange(150) / 3)
    pv[10:12] = np.nan
    run = read_loop(simple_export(tmp_path / "gap.txt", pv=pv))
    assert np.all(np.isfinite(run["pv"]))
    assert any("filled 2 missing pv" in note for note in run.metadata["notes"])


def test_wrong_columns_and_uneven_time(tmp_path):
    path = tmp_path / "w.csv"
    path.write_text("a,b,c\n" + "\n".join(f"{k},{k},{k}" for k in range(200)))
    with pytest.raises(LoopDataError, match="cannot tell the OP and PV"):
        read_loop(path)
    with pytest.raises(LoopDataError, match="column 'zz': no such column"):
        read_loop(path, parse_loop_columns("op=zz,pv=b,time=a"))
    uneven = tmp_path / "u.csv"
    uneven.write_text("time_s,op_pct,pv\n" + "\n".join(f"{k + (5 if k > 100 else 0)},{k % 9},{k % 4}"
                                                       for k in range(200)))
    run = read_loop(uneven)  # a 5-sample gap ends a stretch: the longer one (101 samples) is diagnosed
    assert len(run) == 101 and run.time_s[-1] == 100.0
    assert any("gap in time" in n for n in run.metadata["notes"])
    assert any("the longest, lines 2-102 (101 samples)" in n for n in run.metadata["notes"])


def test_mapping_errors_name_the_key():
    with pytest.raises(Exception, match="unknown key 'opp'"):
        parse_loop_columns("opp=a,pv=b")
    with pytest.raises(Exception, match="needs op"):
        parse_loop_columns("pv=b")


def test_process_type_from_tag():
    assert process_type_for("2111LIC31102B") == "integrating"
    assert process_type_for("2#CDU.7040-312_LIC63001") == "integrating"
    assert process_type_for("2111FIC46005") == "self_regulating"
    assert process_type_for("2111PIC10201") == "self_regulating"


def export_rows(path, stamps, pv, modes=None):
    """A plant_loops export with the given stamps (seconds from midnight), PV and MODE per row."""
    lines = ["PROCESSDATA\tX1FIC7 Data\tyyyy-MM-dd HH:mm:ss", f"8\t10\t2024-01-01 00:00:00\t{len(stamps)}",
             "tagname\tX1FIC7.MV\tX1FIC7.PV\tX1FIC7.SV\tX1FIC7.MODE\tbOpOFL\tbPvOFL\tbSpOFL\tbAutOFL",
             "desc\ta\tb\tc\tAut\tf1\tf2\tf3\tf4", "settings"]
    for k, secs in enumerate(stamps):
        mode = 1 if modes is None else modes[k]
        lines.append(f"2024-01-01 {secs // 3600:02d}:{secs // 60 % 60:02d}:{secs % 60:02d}\t{40 + k % 7}\t"
                     f"{float(pv[k])!r}\t100\t{mode}\t0\t0\t0\t0")
    path.write_bytes(("\r\n".join(lines) + "\r\n").encode("utf-8"))
    return path


def test_historian_repeated_stamp_and_skip_is_respaced(tmp_path):
    stamps = [10 * k for k in range(200)]
    stamps[50] = stamps[49]  # 490, 490, 510: the export repeated a stamp and skipped the next one
    pv = 100 + np.sin(np.arange(200) / 3)
    run = read_loop(export_rows(tmp_path / "r.txt", stamps, pv))
    assert len(run) == 200 and np.allclose(run["pv"], pv)
    assert any("lines 55-56: repeated stamp 2024-01-01 00:08:10 next to a skipped one" in n
               for n in run.metadata["notes"])


def test_historian_manual_mode_and_clock_reset_make_stretches(tmp_path):
    stamps = [10 * k for k in range(150)] + [10 * k for k in range(260)]  # the clock starts again at row 151
    modes = [1] * 150 + [0] * 30 + [1] * 230  # manual for 30 rows after the reset
    pv = 100 + np.sin(np.arange(410) / 3)
    path = export_rows(tmp_path / "r.txt", stamps, pv, modes)
    run = read_loop(path)
    assert len(run) == 230 and np.allclose(run["pv"], pv[180:])
    notes = "\n".join(run.metadata["notes"])
    assert "line 156: time goes back" in notes and "30 samples not in automatic" in notes
    runs = read_loop_segments(path)
    assert [len(r) for r in runs] == [150, 230]
    modes = [1] * 60 + [0] * 300 + [1] * 50
    with pytest.raises(LoopDataError, match="no usable stretch of 100 samples"):
        read_loop(export_rows(tmp_path / "m.txt", stamps, pv, modes))


def test_a_records_column_map_without_op_is_refused_in_one_line(tmp_path):
    """read_loop takes the one phfdi.records.ColumnMap; a map that names no OP column cannot make a loop."""
    from phfdi.records import ColumnMap

    path = tmp_path / "w.csv"
    path.write_text("a,b,c\n" + "\n".join(f"{k},{k},{k}" for k in range(200)))
    with pytest.raises(LoopDataError, match="maps no op_pct"):
        read_loop(path, ColumnMap.from_mapping({"time_s": "a", "pv": "b"}))
    run = read_loop(path, parse_loop_columns("op=c,pv=b,time=a"))
    assert run.names == ["op_pct", "pv"] and "time_s" in run
