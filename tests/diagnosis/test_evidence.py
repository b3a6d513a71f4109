"""phfdi.diagnosis.evidence: the features it reports are the ones put into synthetic records."""

from __future__ import annotations

import numpy as np

from phfdi.diagnosis.evidence import best_shift, crossings, evidence, passages, table


def _titration(t: np.ndarray, t_eq: float, width_s: float) -> np.ndarray:
    """pH 3 -> 11 through an equivalence point at t_eq, passing pH 5..9 in about ``width_s``."""
    return 7.0 + 4.0 * np.tanh((t - t_eq) / (width_s / 1.1))


def _fold(y: np.ndarray, preds: dict, t: np.ndarray) -> dict:
    scored = np.ones(len(t), bool)
    scored[:20] = False
    return {"run": "synthetic", "time_s": t.tolist(), "measured": y.tolist(), "scored": scored.tolist(),
            "dt_s": float(t[1] - t[0]), "predictions": {k: v.tolist() for k, v in preds.items()}}


def test_crossings_and_passages_of_a_known_signal():
    t = np.arange(0.0, 600.0, 1.0)
    y = _titration(t, 200.0, 30.0) - 4.0 * (1 + np.tanh((t - 450.0) / 10.0))  # up at 200 s, down at 450 s
    rng = np.random.default_rng(1)
    noisy = y + rng.normal(0, 0.05, len(t))  # ripple near pH 7 must not add crossings
    cr = crossings(t, noisy)
    assert [d for _, d in cr] == [1, -1]
    assert abs(cr[0][0] - 200.0) < 2.0 and abs(cr[1][0] - 450.0) < 2.0
    pas = passages(t, y)
    assert [d for _, d in pas] == [1, -1]
    assert 25.0 < pas[0][0] < 35.0 and pas[1][0] < pas[0][0]


def test_a_late_prediction_is_found_by_its_shift_and_crossing():
    t = np.arange(0.0, 500.0, 1.0)
    y = _titration(t, 200.0, 20.0)
    late = _titration(t, 212.0, 20.0)
    mask = np.ones(len(t), bool)
    shift, after = best_shift(t, y, late, mask, 1.0)
    assert shift == 12.0 and after < 1e-9
    ev = evidence(_fold(y, {"nominal": late}, t))
    assert ev.crossing_error_s["nominal"] == [12.0]
    assert ev.band_share["transition pH 5-9"] > 0.5  # a timing error shows where the pH moves fast


def test_a_flatter_measured_curve_shows_as_a_longer_passage_and_a_transition_band_error():
    t = np.arange(0.0, 500.0, 1.0)
    y = _titration(t, 250.0, 80.0)  # buffered: 80 s through pH 5..9
    steep = _titration(t, 250.0, 8.0)  # strong acid - strong base: 8 s
    ev = evidence(_fold(y, {"nominal": steep, "structure": steep}, t))
    assert ev.passages_measured[0] > 5 * ev.passages_model["nominal"][0]
    assert ev.crossing_error_s["nominal"] == [0.0] or abs(ev.crossing_error_s["nominal"][0]) < 1.0
    assert max(ev.band_share, key=ev.band_share.get) == "transition pH 5-9"
    assert "synthetic" in table([ev])


def test_the_best_model_and_the_best_per_band_are_the_closest_ones():
    t = np.arange(0.0, 400.0, 1.0)
    y = _titration(t, 200.0, 20.0)
    offset = y + 0.3  # an offset everywhere
    wrong_base = np.where(y > 9, y - 1.0, y)  # right except in the basic band
    ev = evidence(_fold(y, {"nominal": offset, "structure": wrong_base}, t))
    assert ev.band_rmse_best_any["acidic pH < 5"][0] == "structure"
    assert ev.band_rmse_best_any["basic pH > 9"][0] == "nominal"
    assert abs(ev.end_offset["nominal"] - 0.3) < 1e-9
