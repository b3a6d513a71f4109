"""Threshold rules against hand-computed cases, and the three-step denoiser."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from phfdi.study import denoise
from phfdi.study.multisignal import decompose


def test_universal_threshold_hand_case():
    # sqrt(2 ln 100) = sqrt(9.21034) = 3.03485
    assert denoise.universal_threshold(100) == pytest.approx(3.034854, abs=1e-6)


def test_minimax_threshold_hand_cases():
    assert denoise.minimax_threshold(32) == 0.0
    assert denoise.minimax_threshold(64) == pytest.approx(0.3936 + 0.1829 * 6)     # 1.4910
    assert denoise.minimax_threshold(1024) == pytest.approx(0.3936 + 0.1829 * 10)  # 2.2226


def test_sure_threshold_hand_case():
    # x = (0.1, 0.2, 3, 4): risk(k) = (n - 2k + sum_{i<=k} x_(i)^2 + (n - k) x_(k)^2) / n
    # k=1: (4-2+0.01+0.03)/4 = 0.51; k=2: (4-4+0.05+0.08)/4 = 0.0325; k=3: 4.0125; k=4: 5.2625 -> 0.2
    assert denoise.sure_threshold(np.array([3.0, -0.2, 4.0, 0.1])) == pytest.approx(0.2)
    # x = (0.5, -1, 2, 3): risks 0.75, 0.8125, 1.8125, 2.5625 -> 0.5
    assert denoise.sure_threshold(np.array([0.5, -1.0, 2.0, 3.0])) == pytest.approx(0.5)


def _sure_risk(x: np.ndarray, t: float) -> float:
    """Stein's unbiased risk of soft thresholding at t, unit noise: n - 2 #{|x| <= t} + sum min(x^2, t^2)."""
    return len(x) - 2 * np.sum(np.abs(x) <= t) + np.sum(np.minimum(x * x, t * t))


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(-6, 6, allow_nan=False), min_size=2, max_size=40))
def test_sure_threshold_minimises_the_risk_over_candidates(values):
    x = np.round(np.array(values), 6)  # squares of subnormals underflow; that is not what this checks
    t = float(denoise.sure_threshold(x))
    best = min(_sure_risk(x, abs(v)) for v in x)
    assert _sure_risk(x, t) == pytest.approx(best, abs=1e-9)


def test_heursure_hand_cases():
    # weak signal: (||x||^2 - n) / n = (4 - 4) / 4 = 0 < log2(4)^1.5 / 2 = 1.414 -> universal sqrt(2 ln 4)
    assert denoise.heursure_threshold(np.array([1.0, -1.0, 1.0, -1.0])) == pytest.approx(math.sqrt(2 * math.log(4)))
    # strong signal: eta = (0.01 + 0.04 + 100 + 100 - 4) / 4 = 49.01 -> min(SURE, universal)
    x = np.array([0.1, 0.2, 10.0, 10.0])
    assert denoise.heursure_threshold(x) == pytest.approx(min(denoise.sure_threshold(x), math.sqrt(2 * math.log(4))))


def test_noise_sigma_is_the_mad_over_0_6745():
    assert denoise.noise_sigma(np.array([1.0, -1.0, 2.0, -2.0, 3.0]))[0] == pytest.approx(2.0 / 0.6745)


@pytest.mark.parametrize("rule", denoise.RULES)
@pytest.mark.parametrize("shrink", ["soft", "hard"])
def test_denoise_thresholds_each_level_with_its_own_noise(rule, shrink):
    rng = np.random.default_rng(4)
    x = np.sin(np.linspace(0, 6, 512))[None, :] * 5 + rng.normal(0, [[0.1], [0.3]], size=(2, 512))
    dec = decompose(x, "sym4", 4)
    out = denoise.denoise(dec, rule, shrink, noise="level")
    n_all = sum(dec.lengths()[:-1])
    for j, d in enumerate(dec.cd):
        sigma = denoise.noise_sigma(d)
        np.testing.assert_allclose(out.sigma[:, j], sigma)
        if rule == "universal":
            np.testing.assert_allclose(out.thresholds[:, j], denoise.universal_threshold(n_all) * sigma)
        elif rule == "minimax":
            np.testing.assert_allclose(out.thresholds[:, j], denoise.minimax_threshold(n_all) * sigma)
        elif rule == "sure":
            np.testing.assert_allclose(out.thresholds[:, j], denoise.sure_threshold(d / sigma[:, None]) * sigma)
        kept = out.decomposition.cd[j]
        thr = out.thresholds[:, j][:, None]
        # PyWavelets keeps a coefficient equal to the threshold under hard thresholding
        assert np.all(kept[np.abs(d) < thr] == 0)
        big = np.abs(d) >= thr
        expected = np.sign(d) * (np.abs(d) - thr) if shrink == "soft" else d
        np.testing.assert_allclose(kept[big], expected[big])
    np.testing.assert_array_equal(out.decomposition.ca, dec.ca)  # the approximation is untouched


def test_denoising_brings_a_noisy_signal_closer_to_the_truth():
    rng = np.random.default_rng(5)
    t = np.linspace(0, 1, 1024)
    truth = np.where(t < 0.5, 2.0, -1.0) + np.sin(2 * np.pi * 3 * t)
    noisy = truth + rng.normal(0, 0.3, size=(4, t.size))
    dec = decompose(noisy, "sym4", 5)
    for rule in ("universal", "sure", "minimax"):
        clean = denoise.denoise(dec, rule, "soft").signals
        assert np.sqrt(np.mean((clean - truth) ** 2)) < 0.6 * np.sqrt(np.mean((noisy - truth) ** 2))


def test_bad_rule_names():
    dec = decompose(np.zeros((1, 64)), "haar", 2)
    with pytest.raises(ValueError, match="rule"):
        denoise.denoise(dec, "visu")
    with pytest.raises(ValueError, match="soft"):
        denoise.denoise(dec, "sure", "medium")
