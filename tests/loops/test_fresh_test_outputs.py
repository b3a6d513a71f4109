"""benchmarks/stiction_fresh_test.py: an output it cannot write is one message (exit 2) before any simulation,
and its outputs are written whole."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
ROW = {"name": "T0", "loop_class": "stiction", "stiction": True, "conditions": [], "valve": ["stiction", {"s_pct": 1.0}],
       "slips": 5, "valve_effect_noise_levels": 3.0, "verdict": "stiction", "probability": 0.9, "contradiction": None,
       "screen_call": "stiction", "error": None, "fit_decides": False, "fit_takes_back": False}


def _fresh_test():
    spec = importlib.util.spec_from_file_location("stiction_fresh_test", ROOT / "benchmarks" / "stiction_fresh_test.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_an_output_under_a_file_is_refused_in_one_line(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    assert _fresh_test().main(["--per-class", "1", "--out", str(blocker / "rows.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(blocker) in err[0] and "Traceback" not in err[0]


def test_the_metrics_replace_an_earlier_file_whole(tmp_path):
    rows = tmp_path / "rows.json"
    rows.write_text(json.dumps({"rows": [ROW, dict(ROW, name="T1", loop_class="healthy_other", stiction=False,
                                                   verdict="no_stiction", valve=None, valve_effect_noise_levels=None)]}))
    out = tmp_path / "m.json"
    out.write_text("earlier")
    assert _fresh_test().main(["--from-rows", str(rows), "--json", str(out)]) == 0
    m = json.loads(out.read_text())
    assert (m["tp"], m["fp"], m["loops"]) == (1, 0, 2)
    assert not [p for p in tmp_path.iterdir() if ".partial" in p.name]  # no staging file left behind
