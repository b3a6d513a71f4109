"""Residual statistics: noise floor, whiteness, shape of a misfit, scales, the significance tests."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

from phfdi.diagnosis.residual import (
    characterise,
    input_correlation,
    ljung_box,
    noise_floor,
    scale_energy,
    significance,
    significance_f,
)


@pytest.fixture
def rng():
    return np.random.default_rng(11)


def test_noise_floor_finds_white_noise_under_a_smooth_signal(rng):
    t = np.arange(5000.0)
    y = 8 + 2 * np.sin(t / 200) + rng.normal(0, 0.01, len(t))
    assert noise_floor(y) == pytest.approx(0.01, rel=0.1)


def test_ljung_box_tells_white_from_coloured(rng):
    e = rng.normal(size=3000)
    assert ljung_box(e)["white"]
    assert not ljung_box(lfilter([1.0], [1.0, -0.8], e))["white"]


@pytest.mark.parametrize("n", [1000, 10000])
def test_structure_index_measures_the_structured_share_whatever_the_length(rng, n):
    """A slow error holding a share f of the variance gives an index near 20 f^2 at any record length."""
    white = rng.normal(size=n)
    assert ljung_box(white)["structure"] < 0.03
    slow = np.sin(2 * np.pi * np.arange(n) / 400.0)
    for share in (0.05, 0.2):
        e = np.sqrt(1 - share) * white + np.sqrt(share) * slow / np.std(slow)
        assert ljung_box(e)["structure"] == pytest.approx(20 * share ** 2, rel=0.35, abs=0.02)


@pytest.mark.parametrize("kind", ["offset", "gain", "lag"])
def test_characterise_names_the_shape(rng, kind):
    t = np.arange(3000.0)
    sim = 9 + np.sin(t / 80) + 0.5 * np.sin(t / 23)
    noise = rng.normal(0, 0.01, len(t))
    meas = {"offset": sim + 0.3, "gain": 9 + 1.3 * (sim - 9), "lag": np.r_[np.full(12, sim[0]), sim[:-12]]}[kind]
    out = characterise(meas + noise, sim, t, 0.01, "pH")
    assert out["findings"][0]["kind"] == kind, out["findings"]
    if kind == "lag":
        assert out["lag_s"] == pytest.approx(12.0)
    if kind == "offset":
        assert out["offset"] == pytest.approx(0.3, abs=0.01)


def test_characterise_white_residual(rng):
    t = np.arange(2000.0)
    sim = 9 + np.sin(t / 80)
    out = characterise(sim + rng.normal(0, 0.01, len(t)), sim, t, 0.01, "pH")
    assert [f["kind"] for f in out["findings"]] == ["white"]


def test_scale_energy_locates_a_period(rng):
    t = np.arange(4096.0)
    e = np.sin(2 * np.pi * t / 100.0)
    shares = scale_energy(e, 1.0)
    best = max((s for s in shares if s["level"] != "approximation"), key=lambda s: s["share"])
    lo, hi = best["period_s"]
    assert lo <= 100.0 <= 2 * hi  # the band holding (about) the sine's period


def test_input_correlation_finds_missing_dynamics(rng):
    u = np.repeat(rng.uniform(0, 1, 60), 50)
    e = 0.5 * np.r_[np.zeros(7), np.diff(u, prepend=u[0])[:-7]] + rng.normal(0, 0.01, len(u))
    out = input_correlation(e, {"valve_command_pct": u}, 1.0)["valve_command_pct"]
    assert out["significant"] and out["lag_s"] == pytest.approx(7.0)


def test_significance_tests(rng):
    nominal = (1.0 + rng.normal(0, 1, 2000)) ** 2 + 4.0
    same = (1.0 + rng.normal(0, 1, 2000)) ** 2 + 4.0
    better = rng.normal(0, 1, 2000) ** 2
    assert significance(nominal, better) < 1e-6
    assert significance(nominal, same) > 0.01
    assert significance_f(nominal, better, 0.0, 1) < 1e-6
    # a strongly coloured candidate error leaves few effective samples: weak evidence
    assert significance_f(nominal * 1.02, nominal, 0.995, 1) > 0.01
