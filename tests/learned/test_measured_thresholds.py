"""Thresholds measured for a stated false-alarm rate (LearnedSettings.arl0_samples), as the physics detector's are.

The declared energy threshold (energy_h 20) is no false-alarm design: the detail bands of an undecimated wavelet
transform are autocorrelated, so a CUSUM of d^2 - k on them crosses 20 far more often than an i.i.d. design says.
With arl0_samples the calibration measures each statistic's threshold on the healthy rows for the whole
detector's average run length to a false alarm; held-out healthy rows of the same process then alarm at about
that rate. Fixed seeds: each assertion is deterministic.
"""

from __future__ import annotations

import numpy as np
import pytest

from phfdi_base.errors import UserError
from wavelet_fdi.learned_detector import LearnedDetector, LearnedModel, LearnedSettings, learn, run_record

CHANNELS = ("flow", "pressure")
HELD_OUT_RECORDS, HELD_OUT_ROWS = 20, 10_000


def healthy(n: int, seed: int) -> np.ndarray:
    """Two correlated AR(1) channels: a healthy plant's readings."""
    rng = np.random.default_rng(seed)
    e = rng.normal(size=(n, 2))
    x = np.empty((n, 2))
    x[0] = e[0]
    for t in range(1, n):
        x[t] = 0.6 * x[t - 1] + e[t]
    x[:, 1] += 0.5 * x[:, 0]
    return x


def settings(arl0: float) -> LearnedSettings:
    return LearnedSettings(level=3, energy_variance_ratio=4.0, arl0_samples=arl0)


def held_out_alarms(model: LearnedModel) -> int:
    n = 0
    for k in range(HELD_OUT_RECORDS):
        events, _, _ = run_record(model, np.arange(float(HELD_OUT_ROWS)), healthy(HELD_OUT_ROWS, 500 + k))
        n += sum(e.kind == "alarm" for e in events)
    return n


def test_measured_thresholds_hold_the_stated_rate_where_the_declared_ones_do_not():
    rows = healthy(30_000, 1)
    declared = learn(rows, CHANNELS, settings(0.0))
    measured = learn(rows, CHANNELS, settings(1e5))
    # the energy statistics get thresholds of their own, above the declared 20 (their bands are autocorrelated)
    energy = {k: v for k, v in measured.thresholds.items() if k.endswith(".energy")}
    assert len(energy) == 2 * 3 and min(energy.values()) > 20.0, measured.thresholds
    # the mean statistics' k (5 healthy sigmas of AJ) keeps their CUSUMs at zero: no tail, declared thresholds kept
    assert not any(k.endswith(("mean_up", "mean_down")) for k in measured.thresholds)
    det = LearnedDetector(measured)
    assert [det.h[det.stat_names.index(k)] for k in energy] == list(energy.values())
    # 2e5 held-out samples at ARL0 1e5: about 2 false alarms by design (Bonferroni makes it fewer); the declared
    # thresholds give tens
    few, many = held_out_alarms(measured), held_out_alarms(declared)
    assert few <= 9 < 20 <= many, (few, many)


def test_the_thresholds_travel_with_the_model_file_and_a_bad_one_is_refused(tmp_path):
    model = learn(healthy(12_000, 2), CHANNELS, settings(1e5))
    path = tmp_path / "model.json"
    model.save(path)
    again = LearnedModel.load(path)
    assert again.thresholds == model.thresholds and again.thresholds
    d = model.to_dict()
    name = next(iter(d["thresholds"]))
    with pytest.raises(UserError, match=f"threshold of {name} must be a positive number"):
        LearnedModel.from_dict({**d, "thresholds": {**d["thresholds"], name: -1.0}})
    odd = LearnedModel.from_dict({**d, "thresholds": {"flow.D9.energy": 30.0}})
    with pytest.raises(UserError, match="flow.D9.energy, a statistic these settings do not run"):
        LearnedDetector(odd)


def test_too_few_healthy_rows_for_the_thresholds_is_one_clear_refusal():
    with pytest.raises(UserError, match="needs at least 8 windows of 1000 healthy rows"):
        learn(healthy(5_000, 3), CHANNELS, settings(1e5))
    with pytest.raises(UserError, match="arl0_samples must be 0"):
        settings(10.0)
