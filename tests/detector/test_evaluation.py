"""phfdi evaluate on a small matrix: every detector on the same residual, the bound, tables and figures."""

from __future__ import annotations

import json

from phfdi.study.evaluation import DETECTORS, EvalConfig, run_evaluation
from wavelet_fdi.learned_detector import LearnedModel


def test_small_evaluation_writes_tables_figures_and_results(tmp_path):
    # the paper loop shortened (pH 8 from 200 s, faults at 1500 s) to keep the test short; five 3000-s
    # calibration runs give the 10 windows of 1000 samples our thresholds are measured on (8 at least)
    short = ("duration_s=3000", "setpoints.ph.changes=[{at_s: 200, value: 8.0}]")
    cfg = EvalConfig.quick(faults=("backlash", "probe_noise"), calibration_seeds=tuple(range(1001, 1006)),
                           overrides=short, onset_s=1500.0, window_samples=250, jobs=1)
    messages = []
    summary = run_evaluation(cfg, tmp_path, progress=messages.append)
    assert any("calibration" in m for m in messages)  # long work says what it is doing
    for name in ("evaluation.md", "results.json", "reference.json", "peers.json", "delays.png", "false_alarms.png",
                 "isolation.png", "parameters.png", "coefficient_residuals_backlash.png"):
        assert (tmp_path / name).stat().st_size > 0, name
    table = (tmp_path / "evaluation.md").read_text()
    for label in ("wavelet (ours)", "bands only", "CUSUM", "FOCuS", "Page-Hinkley", "ADWIN", "bound"):
        assert label in table
    results = json.loads((tmp_path / "results.json").read_text())
    assert {r["seed"] for r in results["runs"]}.isdisjoint(results["config"]["calibration_seeds"])
    # ours is the multichannel detector with the physics kind, saved as replay --reference reads it
    model = LearnedModel.load(tmp_path / "reference.json")
    assert model.reference.kind == "physics" and model.thresholds == summary["thresholds"]["wavelet"]
    assert "ph_measured.R.mean_up" not in summary["thresholds"]["wavelet_bands"]  # bands only: no R
    rows = {r["fault"]: r for r in summary["rows"]}
    backlash, noise = rows["backlash"], rows["probe_noise"]
    # a mean shift: everyone detects it; ours no slower than plain CUSUM beyond what its R threshold costs (its
    # false-alarm budget is spread over all its statistics, so R's threshold is above the CUSUM's: a CUSUM's
    # delay grows about in proportion to its threshold), plus a block's worth of slack
    assert all(backlash["delay"][d] is not None for d in DETECTORS)
    th = summary["thresholds"]
    ratio = max(th["wavelet"]["ph_measured.R.mean_up"], th["wavelet"]["ph_measured.R.mean_down"]) / th["cusum"]
    assert backlash["delay"]["wavelet"] <= ratio * backlash["delay"]["cusum"] + 10.0, (backlash["delay"], ratio)
    assert backlash["bound_s"] is not None and backlash["correct"] == 1
    # extra probe noise has no mean: the band energies see it, and isolation calls it unknown
    assert noise["delay"]["wavelet"] is not None and noise["classes"] == ["unknown"]
    assert noise["delay"]["cusum"] is None or noise["delay"]["cusum"] > 3 * noise["delay"]["wavelet"]
    assert set(summary["false_alarms"]) == set(DETECTORS)
