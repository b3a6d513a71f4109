"""The historian workflow (issue 24 item 2): a reference keeps its column map, training windows by time,
alarms with the record's time stamps, one row numbering."""

from __future__ import annotations

import json

import numpy as np
import pytest

from phfdi.cli import main

from .test_learned_detector import CHANNELS, plant

#: the historian's own column names for the project's channels
TAGS = {c: f"FIC101.{c.upper()}" for c in CHANNELS}


def write_export(path, x, start="2021-05-01 00:00:00", step_s=1):
    """A historian-style export: its own tag names, a wall-clock stamp column called 'Stamp'."""
    t0 = np.datetime64(start)
    lines = [";".join(["Stamp", *TAGS.values()])]
    for i, row in enumerate(x):
        stamp = str(t0 + np.timedelta64(i * step_s, "s")).replace("T", " ")
        lines.append(";".join([stamp, *(f"{v:.6g}" for v in row)]))
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture(scope="module")
def export(tmp_path_factory):
    d = tmp_path_factory.mktemp("historian")
    x = plant(2600, 21)
    onset = 1700
    x[onset:, 1] += 10 * np.std(x[:400, 1])  # a step in "pressure"
    faulty = write_export(d / "faulty.csv", x)
    cmap = d / "tags.yaml"
    cmap.write_text("time_s: Stamp\n" + "".join(f"{c}: {t}\n" for c, t in TAGS.items()))
    return {"dir": d, "faulty": faulty, "map": cmap, "onset": onset}


def _json(capsys, argv):
    assert main(argv) == 0
    out = capsys.readouterr()
    return json.loads(out.out), out.err


def test_reference_keeps_its_column_map(export, capsys):
    ref = export["dir"] / "ref_map.json"
    assert main(["calibrate", "--learn", str(export["faulty"]), "--rows", "800", "--map", str(export["map"]),
                 "--out", str(ref)]) == 0
    capsys.readouterr()
    stored = json.loads(ref.read_text())["source"]
    assert stored["column_map"]["pressure"] == {"column": "FIC101.PRESSURE"}
    assert stored["column_map_given_as"] == f"--map {export['map']}"
    # no --map at replay: the stored one reads the export, and the replay says so
    report, err = _json(capsys, ["replay", str(export["faulty"]), "--reference", str(ref), "--json"])
    assert f"columns: the map stored in {ref}" in err
    assert report["alarms"] and report["alarms"][0]["channels"][0] == "pressure"
    assert report["columns"].startswith("columns: the map stored")


def test_an_explicit_map_wins_over_the_stored_one(export, tmp_path, capsys):
    ref = export["dir"] / "ref_map2.json"
    assert main(["calibrate", "--learn", str(export["faulty"]), "--rows", "800", "--map", str(export["map"]),
                 "--out", str(ref)]) == 0
    # the same data under other tag names: only an explicit map can read it
    renamed = tmp_path / "renamed.csv"
    renamed.write_text(export["faulty"].read_text().replace("FIC101.", "FIC202."))
    other = tmp_path / "other.yaml"
    other.write_text(export["map"].read_text().replace("FIC101.", "FIC202."))
    capsys.readouterr()
    assert main(["replay", str(renamed), "--reference", str(ref)]) == 2  # the stored map names FIC101 columns
    assert "FIC101" in capsys.readouterr().err
    report, err = _json(capsys, ["replay", str(renamed), "--reference", str(ref), "--map", str(other), "--json"])
    assert f"columns: --map {other} as given (not the map stored in {ref})" in err
    assert report["alarms"][0]["channels"][0] == "pressure"


def test_column_units_are_stored(export, tmp_path, capsys):
    ref = tmp_path / "ref_cols.json"
    args = ["--column", "time_s=Stamp", *(f"--column {c}={t}".split() for c, t in TAGS.items())]
    flat = [a for item in args for a in (item if isinstance(item, list) else [item])]
    assert main(["calibrate", "--learn", str(export["faulty"]), "--rows", "800", *flat, "--out", str(ref)]) == 0
    source = json.loads(ref.read_text())["source"]
    assert source["column_map"]["time_s"] == {"column": "Stamp", "unit": "s"}
    assert set(source["units"]) == set(CHANNELS)
    capsys.readouterr()
    _, err = _json(capsys, ["replay", str(export["faulty"]), "--reference", str(ref), "--json"])
    assert "calibrated with --column time_s=Stamp" in err


def _reference(capsys, export, out, *window):
    assert main(["calibrate", "--learn", str(export["faulty"]), *window, "--map", str(export["map"]),
                 "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    return json.loads(out.read_text()), printed


def test_training_window_by_seconds_or_stamps(export, tmp_path, capsys):
    by_rows, _ = _reference(capsys, export, tmp_path / "rows.json", "--rows", "701")
    by_s, _ = _reference(capsys, export, tmp_path / "s.json", "--from", "100", "--to", "800")
    by_iso, printed = _reference(capsys, export, tmp_path / "iso.json",
                                 "--from", "2021-05-01T00:01:40", "--to", "2021-05-01 00:13:20")
    assert by_s["reference"] == by_iso["reference"]  # seconds 100-800 are those stamps (1 s rows from 00:00:00)
    assert by_s["reference"] != by_rows["reference"]  # a later window than the first 701 rows: another fit
    src = by_iso["source"]
    assert (src["rows"], src["from_s"], src["to_s"]) == (701, 100.0, 800.0)
    assert (src["first_row"], src["from_stamp"], src["to_stamp"]) == (102, "2021-05-01T00:01:40", "2021-05-01T00:13:20")
    assert "100 s (2021-05-01T00:01:40) to 800 s (2021-05-01T00:13:20)" in printed
    # a UTC offset is converted as the reader converts stamps with one (these are naive: read as UTC)
    with_tz, _ = _reference(capsys, export, tmp_path / "tz.json",
                            "--from", "2021-05-01T02:01:40+02:00", "--to", "800")
    assert with_tz["reference"] == by_s["reference"]


def _one_line(capsys, argv) -> str:
    assert main(argv) == 2
    err = capsys.readouterr().err
    errors = [ln for ln in err.splitlines() if ": error: " in ln]
    assert len(errors) == 1 and "Traceback" not in err
    return errors[0]


def test_training_window_refusals(export, tmp_path, capsys):
    learn = ["calibrate", "--learn", str(export["faulty"]), "--map", str(export["map"]), "--out", str(tmp_path / "r.json")]
    line = _one_line(capsys, [*learn, "--from", "2022-01-01T00:00:00"])
    assert "no row in that window; the record runs from 0 s (2021-05-01T00:00:00) to 2599 s" in line
    assert "only one row" in _one_line(capsys, [*learn, "--from", "5", "--to", "5.5"])
    assert "not both" in _one_line(capsys, [*learn, "--rows", "100", "--from", "5"])
    assert "ISO 8601" in _one_line(capsys, [*learn, "--from", "yesterday"])
    # a record whose time is plain seconds has no wall clock: stamps are refused, seconds work
    plain = tmp_path / "plain.csv"
    lines = export["faulty"].read_text().splitlines()
    plain.write_text("\n".join([lines[0]] + [f"{i};{ln.split(';', 1)[1]}" for i, ln in enumerate(lines[1:])]) + "\n")
    argv = ["calibrate", "--learn", str(plain), "--map", str(export["map"]), "--out", str(tmp_path / "p.json")]
    assert "has no wall-clock time column; give seconds" in _one_line(capsys, [*argv, "--from", "2021-05-01T00:01:40"])
    assert main([*argv, "--from", "100", "--to", "800"]) == 0


def test_alarms_carry_the_records_stamps(export, tmp_path, capsys):
    ref = tmp_path / "ref.json"
    assert main(["calibrate", "--learn", str(export["faulty"]), "--rows", "800", "--map", str(export["map"]),
                 "--out", str(ref)]) == 0
    capsys.readouterr()
    report, _ = _json(capsys, ["replay", str(export["faulty"]), "--reference", str(ref), "--json"])
    (alarm,) = report["alarms"]
    # rows are 1 s apart from 2021-05-01 00:00:00: the stamp is the seconds on that clock
    detected = np.datetime64("2021-05-01T00:00:00") + np.timedelta64(int(alarm["detection_time"]), "s")
    assert alarm["detection_stamp"] == str(detected)
    assert export["onset"] <= alarm["detection_time"] <= export["onset"] + 120
    assert alarm["onset_stamp"] is not None and alarm["onset_stamp"] <= alarm["detection_stamp"]
    assert main(["replay", str(export["faulty"]), "--reference", str(ref)]) == 0
    assert f"({alarm['detection_stamp']}, line {alarm['detection_line']})" in capsys.readouterr().out
    # plain seconds: no wall clock, the stamps are null and the text is as before
    plain = tmp_path / "plain.csv"
    lines = export["faulty"].read_text().splitlines()
    plain.write_text("\n".join([lines[0]] + [f"{i};{ln.split(';', 1)[1]}" for i, ln in enumerate(lines[1:])]) + "\n")
    report, _ = _json(capsys, ["replay", str(plain), "--reference", str(ref), "--json"])
    assert report["alarms"][0]["detection_stamp"] is None
    assert report["alarms"][0]["detection_time"] == alarm["detection_time"]


def test_offline_and_live_name_the_same_line(export, tmp_path, capsys):
    """One numbering: the node counts samples from 0; what it reports is mapped to the source file's line (the
    number an editor and a spreadsheet show, header = line 1) and stamp, as the offline replay gives them."""
    from phfdi.alarm_text import format_alarms
    from phfdi.commands.replay import _located_live

    ref = tmp_path / "ref.json"
    assert main(["calibrate", "--learn", str(export["faulty"]), "--rows", "800", "--map", str(export["map"]),
                 "--out", str(ref)]) == 0
    bag = tmp_path / "export.mcap"
    assert main(["bag", "from-csv", str(export["faulty"]), str(bag), "--map", str(export["map"])]) == 0
    capsys.readouterr()
    offline, _ = _json(capsys, ["replay", str(export["faulty"]), "--reference", str(ref), "--json"])
    (alarm,) = offline["alarms"]
    # the node's report carries only its own fields (0-based indices, seconds)
    node = {k: v for k, v in alarm.items() if not k.endswith(("_line", "_stamp")) and k != "where"}
    (live,) = _located_live(str(bag), [node], offline["samples"])
    assert alarm["detection_line"] == alarm["detection_index"] + 2  # header on line 1, data from line 2
    for key in ("where", "detection_line", "cleared_line", "detection_stamp", "onset_stamp", "cleared_stamp"):
        assert live.get(key) == alarm.get(key), key
    assert f"line {alarm['detection_line']}" in format_alarms([live])
    # a bag without the source's positions (an older one): its own sample numbers, 1 = the first
    assert f"(sample {node['detection_index'] + 1})" in format_alarms([node])


def test_column_without_time_keeps_the_files_time_column(tmp_path, capsys):
    """--column naming only the channels: the time still comes from the file's 'datetime' column (it used to be
    refused as 'no time column'), with a note, so alarms keep their seconds and stamps."""
    from phfdi.records import read_record

    path = tmp_path / "export.csv"
    path.write_text("datetime;pH;OP\n" + "".join(f"2021-05-01 00:00:{2 * i:02d};7.{i};5{i}\n" for i in range(10)))
    rec = read_record(path, {"ph_measured": "pH"})
    assert list(rec.time_s[:3]) == [0.0, 2.0, 4.0] and rec.names == ["ph_measured"]
    assert rec.wall_clock is not None and rec.wall_clock.isoformat() == "2021-05-01T00:00:00"
    assert any("time from column 'datetime'" in n for n in rec.notes)
    # a column map that gives a sample time still means "no time column"
    assert list(read_record(path, {"ph_measured": "pH", "sample_time_s": 5}).time_s[:2]) == [0.0, 5.0]


def test_a_record_in_the_references_own_channel_names_needs_no_stored_map(export, tmp_path, capsys):
    """A reference with a stored map replays a record whose columns already are its channels (a gridded or
    converted export) under those names, and says why; the same alarms as the export read through the map."""
    ref = export["dir"] / "ref_map3.json"
    assert main(["calibrate", "--learn", str(export["faulty"]), "--rows", "800", "--map", str(export["map"]),
                 "--out", str(ref)]) == 0
    own = tmp_path / "own_names.csv"
    text = export["faulty"].read_text().replace("Stamp", "Timestamp")
    for channel, tag in TAGS.items():
        text = text.replace(tag, channel)
    own.write_text(text)
    capsys.readouterr()
    via_map, _ = _json(capsys, ["replay", str(export["faulty"]), "--reference", str(ref), "--json"])
    report, err = _json(capsys, ["replay", str(own), "--reference", str(ref), "--json"])
    assert "columns: the file's own column names (they are the reference's channels" in err
    assert [a["detection_index"] for a in report["alarms"]] == [a["detection_index"] for a in via_map["alarms"]]
    assert report["alarms"]
