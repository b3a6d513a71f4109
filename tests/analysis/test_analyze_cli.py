"""End-to-end `phfdi analyze` on a small simulated set, re-analysis from the saved runs, bad input,
and the units on every figure axis."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from phfdi.cli import main

SMALL = ["--variants", "1", "--samples", "256", "--level", "5", "--set", "duration_s=2400",
         "--set", "setpoints.ph.changes.0.at_s=1200", "--section7-onset", "1800"]


@pytest.fixture(scope="module")
def small_analysis(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("analyze")
    assert main(["analyze", "--out", str(out), *SMALL, "--save-runs", "--no-figures"]) == 0
    return out


def test_analyze_writes_the_claim_table(small_analysis, capsys):
    report = (small_analysis / "REPORT.md").read_text()
    assert "| Paper (section, figure) | Paper's claim | Ours (measured) | Verdict |" in report
    for where in ("6, Fig. 29", "6, Fig. 33, 34", "6, Fig. 35, 36", "7, Fig. 49, 56", "7, Fig. 52-55, 58-61",
                  "7, introduction (wvarchg)"):
        assert f"| {where}" in report
    results = json.loads((small_analysis / "results.json").read_text())
    assert results["section6"]["decomposition"]["ca_shape"] == [5, 14]
    assert results["section6"]["decomposition"]["reconstruction_error"] < 1e-9
    assert {p["fault"] for p in results["section7"]} == {"backlash", "friction"}
    for p in results["section7"]:
        for band, d in p["twin_detection"]["sym4"].items():
            assert d["false_alarms"] == 0 and d["first_alarm_s"] >= 1800, band
    assert len(list((small_analysis / "runs" / "section6").glob("*.parquet"))) == 5
    assert len(list((small_analysis / "runs" / "section7").glob("*.parquet"))) == 5


def test_reanalysis_from_saved_runs_gives_the_same_numbers(small_analysis, tmp_path, capsys):
    runs = small_analysis / "runs"
    out = tmp_path / "again"
    code = main(["analyze", "--out", str(out), "--samples", "256", "--level", "5", "--no-figures", "--json",
                 "--bags", *map(str, sorted((runs / "section6").glob("*.parquet"))),
                 "--section7-bags", *map(str, sorted((runs / "section7").glob("*.parquet")))])
    assert code == 0
    claims = json.loads(capsys.readouterr().out)
    assert any(c["where"].startswith("6, Fig. 35") for c in claims)
    first = json.loads((small_analysis / "results.json").read_text())
    again = json.loads((out / "results.json").read_text())
    # the saved files were given sorted by name: compare row by row in that order
    names = first["section6"]["names"]
    order = sorted(range(len(names)), key=lambda i: names[i])
    assert again["section6"]["names"] == [names[i] for i in order]
    for key in ("raw_nonzero_pct", "centred_nonzero_pct", "raw_energy_pct"):
        np.testing.assert_allclose(again["section6"]["compression"][key],
                                   [first["section6"]["compression"][key][i] for i in order])
    assert again["section7"] == first["section7"]


@pytest.mark.parametrize("args,message", [
    (["--bags", "no/such/run.csv"], "no such file"),
    (["--level", "9", "--samples", "256"], "--level 9"),
    (["--clusters", "many"], "--clusters"),
    (["--bags", "a.csv", "b.csv", "--labels", "healthy"], None),
])
def test_bad_input_is_one_line_and_exit_2(args, message, tmp_path, capsys):
    if message is None:  # label count mismatch: needs two readable files
        for name in ("a.csv", "b.csv"):
            (tmp_path / name).write_text("time_s,ph_measured\n0,7\n1,7.1\n2,7.2\n")
        args = ["--bags", str(tmp_path / "a.csv"), str(tmp_path / "b.csv"), "--labels", "healthy"]
        message = "labels"
    assert main(["analyze", "--out", str(tmp_path / "out"), *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0] and "Traceback" not in err[0]


def test_an_unreadable_bag_is_a_one_line_user_error(tmp_path, capsys):
    bag = tmp_path / "run.mcap"
    bag.write_bytes(b"")
    assert main(["analyze", "--out", str(tmp_path / "o"), "--bags", str(bag)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "cannot read the bag" in err[0] and "phfdi bag recover" in err[0]


def test_help_has_examples(capsys):
    with pytest.raises(SystemExit):
        main(["analyze", "--help"])
    assert "phfdi analyze --out" in capsys.readouterr().out


def test_every_figure_axis_has_a_label_with_units(small_analysis, tmp_path, monkeypatch):
    """Draw every figure of the small set; check labels on the figure objects instead of rendering PNGs."""
    from phfdi.commands.analyze import load_runs, section7_pairs
    from phfdi.study import figures, report
    from phfdi.study.analysis import Options
    from phfdi.study.multisignal import from_runs
    from phfdi.study.paperset import PAPER_GROUPING

    checked = []

    def has_unit(text: str) -> bool:
        return "(" in text and text.endswith(")")

    def check(fig, path):
        for ax in fig.axes:
            # a shared x axis is labelled once, under the bottom panel
            xs = [a.get_xlabel() for a in ax.get_shared_x_axes().get_siblings(ax)]
            assert any(has_unit(x) for x in xs), f"{Path(path).name}: x axis without a label with units"
            labels = [ax.get_ylabel()] + ([ax.get_zlabel()] if hasattr(ax, "get_zlabel") else [])
            for text in labels:
                assert has_unit(text), f"{Path(path).name}: axis label {text!r} has no unit"
        import matplotlib.pyplot as plt

        plt.close(fig)
        checked.append(Path(path).name)
        return Path(path)

    monkeypatch.setattr(figures, "_save", check)
    runs = small_analysis / "runs"
    paths6 = sorted(map(str, (runs / "section6").glob("*.parquet")))
    paths7 = sorted(map(str, (runs / "section7").glob("*.parquet")))
    r6, r7 = load_runs(paths6), load_runs(paths7)
    opts = Options(level=5, denoise_levels=(3, 5))
    ms = from_runs(r6, [r.metadata["label"] for r in r6], n_samples=256)
    pairs = section7_pairs(r7, [r.metadata["label"] for r in r7], "ph_measured", opts)
    result = report.write_all(ms, pairs, tmp_path, opts, {}, PAPER_GROUPING)
    assert len(checked) >= 20 and len(result["files"]) == len(checked)
    assert "fig52_55_residuals_backlash.png" in checked and "fig35_clusters_energy.png" in checked


def test_run_files_without_metadata_or_truth(tmp_path, capsys):
    """CSV runs (no metadata, no ph_true): labels from file names, Section 7 said to be skipped."""
    t = np.arange(0.0, 2000.0)
    rng = np.random.default_rng(0)
    paths = []
    for i, label in enumerate(["healthy", "healthy", "cycling", "cycling"]):
        ph = 8 + 0.01 * rng.normal(size=t.size) + (0.3 * np.sin(t / 20.0) if label == "cycling" else 0.0)
        path = tmp_path / f"{label}_{i}.csv"
        np.savetxt(path, np.column_stack([t, ph]), delimiter=",", header="time_s,ph_measured", comments="")
        paths.append(str(path))
    out = tmp_path / "out"
    assert main(["analyze", "--out", str(out), "--bags", *paths, "--samples", "512", "--level", "6", "--clusters", "2",
                 "--no-figures", "--json"]) == 0
    claims = json.loads(capsys.readouterr().out)
    assert any(c["verdict"] == "not checked" for c in claims)
    report = (out / "REPORT.md").read_text()
    assert "Not run: it needs a faulty run" in report
    assert "healthy (2), cycling (2)" in report
    results = json.loads((out / "results.json").read_text())
    runs = results["section6"]["clustering"]["runs"]
    energy = [r for r in runs if r["features"].startswith("detail energies") and r["k_source"] == "given"]
    assert all(r["ari_classes"] == pytest.approx(1.0) for r in energy)
