"""Section 7 residuals: coefficient timing, exact twin residuals, calibrated detection."""

from __future__ import annotations

import numpy as np
import pytest

from phfdi.study import residuals


@pytest.mark.parametrize("wavelet", ["sym4", "db8"])
def test_coefficient_times_point_at_an_impulse(wavelet):
    n, p = 2000, 1234
    x = np.zeros(n)
    x[p] = 1.0
    bands = residuals.band_coefficients(x, wavelet, 3)
    centre = residuals.coefficient_times(n, wavelet, 3, dt_s=1.0)
    end = residuals.coefficient_times(n, wavelet, 3, anchor="end")
    for b, c in bands.items():
        k = int(np.argmax(np.abs(c)))
        step = 2 ** int(b[1:])
        assert abs(centre[b][k] - p) <= 2 * step  # within two coefficient spacings
        assert end[b][k] >= p  # a coefficient that sees the impulse is not computable before it


def test_twin_residuals_are_zero_before_the_change_and_alarm_after_it():
    rng = np.random.default_rng(20)
    healthy = 8 + 0.01 * rng.normal(size=3000)
    faulty = healthy.copy()
    faulty[2000:] += 0.05 * np.sin(np.arange(1000) / 15.0)
    rs = residuals.residuals(healthy, faulty, "sym4", 3)
    assert rs.lengths[-1] == 3000 and rs.reconstruction_error < 1e-12
    det = residuals.detect(rs, {b: 1e-9 for b in rs.residual}, onset_s=2000)
    for b, d in det.items():
        assert d.false_alarms == 0
        assert 2000 <= d.first_alarm_s <= 2000 + 60, b


def test_calibrated_detector_finds_a_slow_oscillation_without_false_alarms():
    rng = np.random.default_rng(21)
    n = 6000
    reference, calibration, faulty = (8 + 0.01 * rng.normal(size=n) for _ in range(3))
    faulty[4000:] += 0.1 * np.sin(2 * np.pi * np.arange(n - 4000) / 120.0)
    cal = residuals.residuals(reference, calibration, "sym4", 3)
    thr = residuals.calibrate(cal, window=8)
    real = residuals.residuals(reference, faulty, "sym4", 3)
    det = residuals.detect(real, thr, window=8, onset_s=4000)
    assert det["A3"].false_alarms == 0
    assert det["A3"].first_after_onset_s is not None and det["A3"].first_after_onset_s < 4000 + 200
    assert all(d.false_alarms == 0 for d in det.values())


def test_moving_rms():
    np.testing.assert_allclose(residuals.moving_rms(np.array([3.0, 4.0, 0.0]), 2),
                               [3.0, np.sqrt(12.5), np.sqrt(8.0)])
