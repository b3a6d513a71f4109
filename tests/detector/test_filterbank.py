"""The causal filter bank is PyWavelets' stationary wavelet transform, delayed, and chunking-proof."""

from __future__ import annotations

import numpy as np
import pytest
import pywt

from wavelet_fdi.filterbank import CausalSwt, coefficient_residuals


@pytest.mark.parametrize("wavelet", ["sym4", "db8"])
@pytest.mark.parametrize("level", [1, 3, 4])
def test_equals_pywt_swt_delayed(wavelet, level):
    rng = np.random.default_rng(3)
    n = 1024
    x = rng.standard_normal(n)
    out = CausalSwt(wavelet, level).process(x)
    ref = pywt.swt(x, wavelet, level=level, trim_approx=False, norm=False)  # [(cA_J, cD_J), ..., (cA_1, cD_1)]
    taps = len(pywt.Wavelet(wavelet).dec_lo)
    interior = slice(taps * 2**level, n)
    for j in range(1, level + 1):
        ca, cd = ref[level - j]
        shift = taps // 2 * (2**j - 1)
        np.testing.assert_allclose(out.details[j - 1][interior], np.roll(cd, shift)[interior], atol=1e-12)
        if j == level:
            np.testing.assert_allclose(out.approx[interior], np.roll(ca, shift)[interior], atol=1e-12)


def test_white_noise_keeps_its_standard_deviation_in_every_band():
    x = np.random.default_rng(0).standard_normal(200_000) * 0.01
    out = CausalSwt("sym4", 3).process(x)
    for band in list(out.details) + [out.approx]:
        assert np.std(band[100:]) == pytest.approx(0.01, rel=0.02)


@pytest.mark.parametrize("chunk", [1, 7, 64])
def test_chunked_equals_whole_bit_for_bit(chunk):
    x = np.random.default_rng(1).standard_normal(700)
    whole = CausalSwt("db8", 3).process(x)
    bank = CausalSwt("db8", 3)
    parts = [bank.process(x[a:a + chunk]) for a in range(0, len(x), chunk)]
    assert np.array_equal(np.hstack([p.details for p in parts]), whole.details)
    assert np.array_equal(np.concatenate([p.approx for p in parts]), whole.approx)


def test_paper_coefficient_residuals_are_the_residuals_coefficients():
    rng = np.random.default_rng(2)
    measured = np.cumsum(rng.standard_normal(512)) * 0.01 + 8.0
    predicted = measured - 0.05 * np.sin(np.arange(512) / 20.0)
    res = coefficient_residuals(measured, predicted, "sym4", 3)
    direct = pywt.wavedec(measured - predicted, "sym4", level=3)
    assert set(res["residual"]) == {"D1", "D2", "D3", "A3"}
    np.testing.assert_allclose(res["residual"]["A3"], direct[0], atol=1e-12)
    np.testing.assert_allclose(res["residual"]["D1"], direct[3], atol=1e-12)


def test_unknown_or_non_orthogonal_wavelet_is_refused():
    with pytest.raises(ValueError, match="unknown wavelet"):
        CausalSwt("nonesuch", 3)
    with pytest.raises(ValueError, match="not orthogonal"):
        CausalSwt("bior3.5", 3)
