"""Thresholds for a false-alarm target: the tail-fit method every calibration uses (wavelet_fdi.calibration)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from phfdi_base.errors import UserError
from wavelet_fdi.calibration import tail_threshold, window_maxima


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
