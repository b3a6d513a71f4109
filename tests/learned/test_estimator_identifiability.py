"""`phfdi calibrate --estimator` refuses runs it cannot identify the reference from, naming what is missing, and a
hand-edited reference with a wrong-signed strength is refused on load (issue 36, item 2)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from .test_estimator import flask, simulate

COLUMNS = ["--column", "acid_flow_ml_s=acid", "--column", "base_flow_ml_s=base", "--column", "ph_measured=ph",
           "--column", "time=t"]


def _write(path, t, rows) -> str:
    lines = ["t,acid,base,ph"] + [f"{a:.3f},{r[0]:g},{r[1]:g},{r[2]:.2f}" for a, r in zip(t, rows)]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return str(path)


def _healthy(tmp_path, name: str, seed: int, base=lambda k: 2.0 if (k // 300) % 2 == 0 else 0.5, ph0=11.0) -> str:
    t, rows = simulate(flask(), 1200, base, seed=seed, ph0=ph0)
    return _write(tmp_path / name, t, rows)


def _calibrate(run_cli, tmp_path, *runs):
    return run_cli("calibrate", "--estimator", *runs, *COLUMNS, "--out", tmp_path / "ref.json")


def test_a_feed_that_never_runs_is_named_and_nothing_written(run_cli, tmp_path):
    runs = [_healthy(tmp_path, f"r{i}.csv", 60 + i, base=lambda k: 0.0) for i in range(2)]
    status, _, err = _calibrate(run_cli, tmp_path, *runs)
    assert status == 2 and "base_flow_ml_s" in err and "never runs" in err and "Traceback" not in err
    assert not (tmp_path / "ref.json").exists()


def test_a_reading_outside_0_to_14_is_refused(run_cli, tmp_path):
    t, rows = simulate(flask(), 1200, lambda k: 1.0, seed=3)
    rows[500:520, 2] = 15.0
    status, _, err = _calibrate(run_cli, tmp_path, _write(tmp_path / "bad.csv", t, rows), _healthy(tmp_path, "ok.csv", 4))
    assert status == 2 and "outside 0-14" in err and "line" in err


def test_a_ph_that_never_moves_is_refused(run_cli, tmp_path):
    t, rows = simulate(flask(), 1200, lambda k: 1.0, seed=5)
    rows[:, 2] = 7.0
    status, _, err = _calibrate(run_cli, tmp_path, _write(tmp_path / "flat.csv", t, rows))
    assert status == 2 and "pH moves by less than" in err


def test_a_wrong_signed_strength_in_a_hand_edited_reference_is_refused(run_cli, tmp_path):
    # the base switched on and off against a steady acid feed from neutral: the pH swings both ways, each feed's
    # strength is identified (a base dominating at pH 11-12 leaves the acid's at the fit's bound: refused)
    runs = [_healthy(tmp_path, f"r{i}.csv", 70 + i, base=lambda k: 0.4 if (k // 300) % 2 == 0 else 0.0, ph0=7.0)
            for i in range(2)]
    status, _, err = _calibrate(run_cli, tmp_path, *runs)
    assert status == 0, err
    d = json.loads((tmp_path / "ref.json").read_text(encoding="utf-8"))
    d["reference"]["feeds"][0]["strength_mM"] = abs(d["reference"]["feeds"][0]["strength_mM"])  # the acid made a base
    (tmp_path / "edited.json").write_text(json.dumps(d), encoding="utf-8")
    status, _, err = run_cli("replay", runs[0], *COLUMNS, "--reference", tmp_path / "edited.json")
    assert status == 2 and "acid_flow_ml_s" in err and "wrong sign" in err and "Traceback" not in err


@pytest.mark.parametrize("field", ["volume"])
def test_identifiability_notes_name_a_value_at_a_bound(field):
    from dataclasses import replace

    from phfdi.estimator import identifiability_notes

    notes = identifiability_notes(replace(flask(), volume_ml=50000.0))
    assert any(n.startswith("volume 50000 mL is at the fit's upper bound") for n in notes)
    assert not identifiability_notes(replace(flask(), volume_ml=4000.0, noise=replace(flask().noise, timing_s=1.0)))
    assert np.isfinite(flask().volume_ml)


def test_a_strength_the_runs_do_not_identify_is_refused_before_the_folds(run_cli, tmp_path):
    """A base dominating at pH 11-12 with the acid feed steady: the acid's strength ends at the fit's bound; the
    command says so, names the feed, and does not first spend the leave-one-run-out fits."""
    runs = [_healthy(tmp_path, f"r{i}.csv", 70 + i) for i in range(2)]
    status, _, err = _calibrate(run_cli, tmp_path, *runs)
    assert status == 2 and "acid_flow_ml_s strength" in err and "bound" in err and "Traceback" not in err
    assert "fitting without run" not in err
    assert not (tmp_path / "ref.json").exists()
