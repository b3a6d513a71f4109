"""The README's speed table is written by benchmarks/speed_table.py from the committed results, never by hand: its
figures (detector 44 800/s "not met", plant-wide 27.8 loops/min, the whole plant in 70 s) had gone stale while the
code got faster (issue 36, item 9). The benchmarks are not run here; their results file is read."""

from __future__ import annotations

import importlib.util
import json
import sys

from tests.conftest import ROOT


def _speed_table():
    spec = importlib.util.spec_from_file_location("speed_table", ROOT / "benchmarks" / "speed_table.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


def test_the_readmes_speed_table_is_the_one_written_from_the_committed_results():
    st = _speed_table()
    results = json.loads(st.RESULTS.read_text())
    written = st.table(results)
    assert st.readme_table(st.README.read_text(encoding="utf-8")) == written, \
        "README.md's speed table differs from benchmarks/results/speed_table.json: run " \
        ".venv/bin/python benchmarks/speed_table.py --update (never edit the table by hand)"
    assert st.DETAILS.read_text(encoding="utf-8") == st.details(results)


def test_every_row_is_measured_and_dated():
    st = _speed_table()
    results = json.loads(st.RESULTS.read_text())
    assert set(results) == set(st.KEYS), "rows never measured: " + ", ".join(set(st.KEYS) - set(results))
    for key, entry in results.items():
        assert entry["measured"] and entry["date"] and entry["commit"], key
        assert entry["load1_before"] >= 0 and entry["wall_s"] > 0, key


def test_a_rows_figure_is_read_off_its_benchmarks_output():
    """The patterns read what the scripts print (a changed print would otherwise leave the table unmeasurable)."""
    st = _speed_table()
    out = "  real-time factor best 41,000 x, median 37,000 x (target >= 20,000 x)\n"
    assert st.KEYS["simulate"].read(out) == ("41 000 x real time (median of 5 runs 37 000 x)", 37000.0, True)
    out = "replay, 4096 samples per call:   122000 samples/s (    8.2 us/sample)\n"
    assert st.KEYS["detector"].read(out) == ("122 000 samples/s", 122000.0, True)
    out = "1000 loops (0 failed) in 243.0 s on Dask (LocalCluster, 2 worker processes): 246.9 loops/minute\n"
    assert st.KEYS["plant_wide"].read(out) == ("247 loops/min on 2 workers", 246.9, False)  # target >= 1000
    out = "3000 loops (0 failed) in 132.4 s on Dask (LocalCluster, 2 worker processes): 1359.5 loops/minute\n"
    assert st.KEYS["plant_wide"].read(out) == ("1360 loops/min on 2 workers", 1359.5, True)
