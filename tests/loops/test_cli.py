"""phfdi loop-diagnose from the command line: batches, bad files, JSON, exit status."""

from __future__ import annotations

import json

import numpy as np
import pytest

from phfdi.cli import main
from phfdi.loopdiag.synthetic import SyntheticLoop, simulate_loop, steps_every

FAST = ["--causes", "backlash", "--no-baselines", "--workers", "2"]


@pytest.fixture
def backlash_csv(tmp_path):
    run = simulate_loop(SyntheticLoop(valve=("backlash", {"width_pct": 2.0}), duration_s=2400,
                                      setpoint_steps=steps_every(400, 2400, 50, 3), loop_tag="FIC7"))
    return run.to_csv(tmp_path / "FIC7.csv")


def bad_files(tmp_path):
    constant = tmp_path / "constant.csv"
    constant.write_text("time_s,op_pct,pv,sp\n" + "\n".join(f"{k},{50 + k % 3},7,7" for k in range(300)))
    short = tmp_path / "short.csv"
    short.write_text("time_s,op_pct,pv,sp\n" + "\n".join(f"{k},{k % 3},{k % 5},1" for k in range(20)))
    columns = tmp_path / "columns.csv"
    columns.write_text("a,b\n" + "\n".join(f"{k},{k}" for k in range(300)))
    gap = tmp_path / "gap.csv"
    gap.write_text("time_s,op_pct,pv,sp\n" + "\n".join(
        f"{k},{k % 3},{'nan' if 100 <= k < 130 else k % 5},1" for k in range(300)))
    return {"constant": constant, "short": short, "columns": columns, "gap": gap}


def test_batch_with_bad_files_reports_each_once_and_goes_on(tmp_path, backlash_csv, capsys):
    bad = bad_files(tmp_path)
    status = main(["loop-diagnose", str(backlash_csv), *map(str, bad.values()), "--json", *FAST])
    out, err = capsys.readouterr()
    assert status == 1  # some failed (exit 2: none could be diagnosed)
    doc = json.loads(out)
    assert [f["loop_tag"] for f in doc["files"]] == ["FIC7", "constant", "gap"]
    assert doc["files"][0]["cause"] == "backlash"
    # a constant PV under a moving OP is a verdict, not a reading error
    assert doc["files"][1]["loop_verdict"]["verdict"] == "pv_frozen"
    # historian policy: the 30-sample PV gap ends a stretch; the longer one (170 samples) is diagnosed, said
    assert doc["files"][2]["samples"] == 170
    assert any("2 stretches" in n and "cut where OP or PV is missing for 30 samples in a row (from t = 100 s)" in n
               for n in doc["files"][2]["reading_notes"])
    assert len(doc["failed"]) == 2
    lines = [ln for ln in err.splitlines() if ln.startswith("phfdi loop-diagnose:") and ": note: " not in ln]
    assert len(lines) == 2
    for name, needle in (("short", "too short"), ("columns", "cannot tell the OP and PV")):
        assert sum(str(bad[name]) in ln and needle in ln for ln in lines) == 1, (name, lines)
    assert f"phfdi loop-diagnose: note: {bad['gap']}: column 'pv': 30 cells not a number (NaN 30), first at line 102" \
        in err
    assert "Traceback" not in err


def test_every_file_bad_exits_2(tmp_path, capsys):
    bad = bad_files(tmp_path)
    assert main(["loop-diagnose", str(bad["columns"]), str(bad["short"]), *FAST]) == 2
    assert "Traceback" not in capsys.readouterr().err


def test_text_report_shows_linear_model_ranking_and_verdict(backlash_csv, capsys):
    assert main(["loop-diagnose", str(backlash_csv), "--causes", "backlash,stiction", "--workers", "1"]) == 0
    out = capsys.readouterr().out
    for needle in ("oscillation:", "linear model:", "the linear model misses:", "valve models, held-out NRMSE",
                   "valve-model fit: explained, cause backlash", "verdict: ", "baselines: horch_ccf"):
        assert needle in out


def test_column_mapping_and_figure(tmp_path, capsys):
    t = np.arange(400) * 5.0
    pv = 3 + np.sin(t / 60) + 0.01 * np.cos(t / 7)
    op = 50 + 2 * np.cos(t / 60)
    path = tmp_path / "hist.csv"
    path.write_text("Stamp;OUT;MEAS\n" + "\n".join(f"{a};{b};{c}" for a, b, c in zip(t, op, pv)))
    figs = tmp_path / "figs"
    status = main(["loop-diagnose", str(path), "--columns", "op=OUT,pv=MEAS,time=Stamp", "--figure", str(figs),
                   "--json", *FAST])
    assert status == 0
    rep = json.loads(capsys.readouterr().out)["files"][0]
    assert (figs / "hist.png").stat().st_size > 10_000 and rep["figure"].endswith("hist.png")


def test_bad_arguments_are_one_line(capsys, backlash_csv):
    assert main(["loop-diagnose", str(backlash_csv), "--causes", "friction"]) == 2
    assert "unknown cause 'friction'" in capsys.readouterr().err


def test_help_has_examples(capsys):
    with pytest.raises(SystemExit):
        main(["loop-diagnose", "--help"])
    out = capsys.readouterr().out
    assert "examples:" in out and "--columns op=" in out and "exit status" in out
