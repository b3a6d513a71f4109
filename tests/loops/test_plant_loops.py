"""The real refinery loops (../shared/data/plant_loops): reading all 59, and the evaluation table.

The full evaluation (benchmarks/plant_loops_eval.py) diagnoses 59 files and takes minutes; its
per-file records are kept in benchmarks/results/plant_loops_records.json. Here, cheaply:
every file is read and its loop tag matches labels.csv; two files are diagnosed again and must
give their records back (the cache is current); and the leave-one-loop-out table computed from
the records must be the one docs/loop_diagnosis.md shows.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from phfdi.loopdiag.batch import diagnose_file
from phfdi.loopdiag.diagnose import Settings
from phfdi.loopdiag.evaluate import evaluate, format_table, read_labels, record
from phfdi.loopdiag.readers import read_loop

ROOT = Path(__file__).resolve().parents[2]
RECORDS = ROOT / "benchmarks" / "results" / "plant_loops_records.json"
DOC = ROOT / "docs" / "loop_diagnosis.md"
#: one stiction file with a limit cycle and the shortest record (126 samples at 60 s)
RECHECK = ("stiction/stic_2111FIC46005_0902_0003.txt", "no_stiction/stic_2_CDU.7040-312_LIC63001_0628_1642.txt")


@pytest.fixture
def plant_loops(shared_data) -> Path:
    folder = shared_data / "plant_loops"
    if not (folder / "labels.csv").is_file():
        pytest.skip(f"no labels.csv in {folder}")
    return folder


def cached_records() -> list[dict]:
    return json.loads(RECORDS.read_text())


def test_all_files_read_with_their_labelled_loop_tag(plant_loops):
    labels = read_labels(plant_loops / "labels.csv")
    assert len(labels) == 59 and len({x.loop_tag for x in labels}) == 17
    for item in labels:
        run = read_loop(item.file)
        assert run.metadata["loop_tag"] == item.loop_tag
        assert {"op_pct", "pv", "sp"} <= set(run.names) and "time_s" in run


@pytest.mark.parametrize("rel", RECHECK)
def test_cached_records_are_current(plant_loops, rel):
    item = next(x for x in read_labels(plant_loops / "labels.csv") if x.file.endswith(rel))
    fresh = record(diagnose_file(item.file, settings=Settings(fits="all")), item)
    cached = next(r for r in cached_records() if r["file"] == rel)
    assert fresh["extended_cause"] == cached["extended_cause"]
    assert fresh["gain_percent"] == pytest.approx(cached["gain_percent"], abs=0.5)
    assert fresh["cause"] == cached["cause"] and fresh["oscillating"] == cached["oscillating"]
    for key in ("horch_index", "he_index"):
        if cached[key] is None:
            assert fresh[key] is None
        else:
            assert fresh[key] == pytest.approx(cached[key], abs=1e-3)


def test_documented_table_is_the_leave_one_loop_out_result(plant_loops):
    records = cached_records()
    assert {r["loop_tag"] for r in records} == {x.loop_tag for x in read_labels(plant_loops / "labels.csv")}
    table = format_table(evaluate(records))
    doc = DOC.read_text(encoding="utf-8")
    for row in table.splitlines():
        assert row in doc, f"docs/loop_diagnosis.md lacks the row: {row}"
