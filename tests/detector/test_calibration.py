"""Thresholds for a false-alarm target: the tail-fit method, and the shipped calibration file."""

from __future__ import annotations

import math

import numpy as np
import pytest

from phfdi.study.evaluation import EvalConfig
from phfdi_base.errors import UserError
from wavelet_fdi.calibration import (
    DEFAULT_CALIBRATION_SEEDS,
    alarm_positions,
    calibrate_from_traces,
    tail_threshold,
    window_maxima,
)
from wavelet_fdi.config import Calibration, DetectorSettings, load_default_calibration
from wavelet_fdi.filterbank import CausalSwt
from wavelet_fdi.statistics import increments, parse_statistic


def test_tail_fit_recovers_an_exponential_quantile():
    rng = np.random.default_rng(0)
    maxima = 3.0 + rng.exponential(2.0, 400)  # P(M > h) = exp(-(h - 3) / 2)
    fit = tail_threshold(maxima, 1e-3)
    assert fit.threshold == pytest.approx(3.0 + 2.0 * math.log(1e3), rel=0.08)
    with pytest.raises(UserError, match="at least 8 windows"):
        tail_threshold(maxima[:5], 1e-3)


def test_window_maxima_restart_the_cusum_in_each_window():
    z = np.random.default_rng(1).standard_normal(3000) - 0.5
    got = window_maxima(z, 1000)
    for w in range(3):
        s, m = 0.0, 0.0
        for v in z[w * 1000:(w + 1) * 1000]:
            s = max(0.0, s + v)
            m = max(m, s)
        assert got[w] == pytest.approx(m)


def synthetic_trace(rng, n: int, settings: DetectorSettings, sigma: float = 0.01) -> dict:
    r = rng.standard_normal(n) * sigma
    out = CausalSwt(settings.wavelet, settings.level).process(r)
    coef = np.vstack((out.details, out.approx[None, :], r[None, :])).T
    mask = np.arange(n) >= 200
    return {"ph_residual": r, "ph_monitored": mask, "ph_coefficients": coef,
            "level_residual_cm": r * 2, "level_monitored": mask, "level_coefficients": coef * 2}


def test_calibrated_union_detector_meets_its_false_alarm_target_on_fresh_noise():
    """Calibrate on white noise, then count false alarms of the union on 12x more fresh noise."""
    settings = DetectorSettings(arl0_samples=2e4)
    rng = np.random.default_rng(7)
    cal = calibrate_from_traces([synthetic_trace(rng, 20_200, settings) for _ in range(4)], settings, "synthetic",
                                1.0, [1, 2, 3, 4])
    fresh = synthetic_trace(rng, 1_000_200, settings)
    names = settings.statistic_names()
    rows = settings.rows()
    u = fresh["ph_coefficients"][200:]
    parsed = [parse_statistic(n) for n in names]
    z = np.vstack([increments(kind, u[:, rows.index(band)] / cal.sigma["ph"]["raw" if band == "R" else band],
                              settings.reference_value(n)) for n, (_, band, kind) in zip(names, parsed)])
    alarms = alarm_positions(z, np.array([cal.thresholds[n] for n in names]), 0)
    arl = len(u) / max(len(alarms), 1)
    # 50 alarms expected at the target; the tail extrapolation is good to about a factor 2
    assert 2e4 / 2.5 < arl < 2e4 * 2.5, (len(alarms), arl)


def test_shipped_calibration_matches_the_default_detector_and_keeps_its_seeds_apart():
    settings = DetectorSettings()
    cal = load_default_calibration("paper", settings)
    cal.check(settings, 1.0)
    assert set(cal.thresholds) >= set(settings.statistic_names())
    assert tuple(cal.seeds) == DEFAULT_CALIBRATION_SEEDS
    assert not set(cal.seeds) & (set(EvalConfig().eval_seeds) | set(EvalConfig().healthy_seeds))
    assert cal.sigma["ph"]["raw"] == pytest.approx(0.01, rel=0.05)  # the paper scenario's probe noise


def test_mismatched_calibration_is_refused_with_a_reason(tmp_path):
    cal = load_default_calibration("paper", DetectorSettings())
    with pytest.raises(UserError, match="db8"):
        cal.check(DetectorSettings(wavelet="db8"), 1.0)
    with pytest.raises(UserError, match="sample time"):
        cal.check(DetectorSettings(), 0.5)
    path = cal.save(tmp_path / "c.json")
    assert Calibration.load(path).thresholds == cal.thresholds
    (tmp_path / "bad.yaml").write_text("just text")
    with pytest.raises(UserError, match="not a calibration file"):
        Calibration.load(tmp_path / "bad.yaml")


def test_a_damaged_calibration_is_refused_on_load(tmp_path):
    """Keys the detector reads, with the wrong types (found by the fuzz test): one line naming the key."""
    import re

    import yaml

    from wavelet_fdi.config import CALIBRATION_DIR

    good = yaml.safe_load((CALIBRATION_DIR / "paper_sym4_L3.yaml").read_text())
    for key, value, where in (("design", {"channels": [None]}, "design.channels"), ("level", "3", "level"),
                              ("thresholds", {"ph.R.mean_up": "x"}, "thresholds.ph.R.mean_up")):
        path = tmp_path / f"{key}.yaml"
        path.write_text(yaml.safe_dump({**good, key: value}))
        with pytest.raises(UserError, match=re.escape(f"not a calibration file ({where}: expected")):
            Calibration.load(path)
