"""benchmarks/soak.py writes a new measurement to out/soak/ unless told: a run with its defaults replaced the
committed results in benchmarks/results/soak/ (issue 36, item 9)."""

from __future__ import annotations

import importlib.util
import json

from tests.conftest import ROOT


def _soak():
    spec = importlib.util.spec_from_file_location("soak_benchmark", ROOT / "benchmarks" / "soak.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_a_soak_run_writes_outside_the_committed_results_by_default():
    soak = _soak()
    assert soak.parse_args([]).out == "out/soak"
    assert soak.parse_args(["--results"]).out == "benchmarks/results/soak"
    assert soak.parse_args(["--out", "/tmp/x"]).out == "/tmp/x"


def test_an_earlier_runs_results_are_kept_without_overwrite(tmp_path, capsys):
    soak = _soak()
    earlier = tmp_path / "soak_lockstep_100000s.json"
    earlier.write_text(json.dumps({"an": "earlier run"}))
    assert soak.main(["--sim-s", "100000", "--out", str(tmp_path)]) == 2  # before any graph starts
    assert "exists (an earlier run's results): give --overwrite" in capsys.readouterr().err
    assert json.loads(earlier.read_text()) == {"an": "earlier run"}
