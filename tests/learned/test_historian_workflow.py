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
