"""The repeats CUSUM (``repeat_probability``, wavelet_fdi.repeat_test): a quantised reading that stops dithering
across its steps (frozen, or behind a lag) is found within seconds of its onset, against the run's own repeat
share; healthy quantised readings from far below to far above one step of noise do not alarm; any chunking gives
the same bits. The fault's kind, onset and size are drawn per seed and never given to the detector."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

from phfdi_base.errors import UserError
from wavelet_fdi.learned_detector import LearnedDetector, LearnedSettings, learn, run_record
from wavelet_fdi.repeat_test import RepeatTest, neutral_share

DT_S = 0.35  # the rig's sample time
STEP_PH = 0.01  # the rig's meter resolution
N = 3000


def settings(p1: float = 0.9) -> LearnedSettings:
    return LearnedSettings(sample_time_s=DT_S, repeat_probability=p1)


def true_ph(n: int, rng: np.random.Generator) -> np.ndarray:
    """A slowly moving pH: a slow sine and a small random walk."""
    t = np.arange(n) * DT_S
    return 7.0 + 0.5 * np.sin(2 * np.pi * t / rng.uniform(200.0, 2000.0)) + np.cumsum(rng.normal(0.0, 0.002, n))


def quantised(x: np.ndarray) -> np.ndarray:
    return np.round(x / STEP_PH) * STEP_PH


def model():
    rng = np.random.default_rng(5)
    return learn(quantised(true_ph(4000, rng) + 0.04 * rng.normal(size=4000))[:, None], ["ph"], settings())


def repeats_alarms(det: LearnedDetector) -> list[dict]:
    return [a for a in det.alarms if a["statistic"] == "ph.raw.repeats"]


@pytest.mark.parametrize("seed", range(6))
def test_a_stale_reading_hidden_in_a_quantised_one_is_found_within_seconds(seed):
    """Frozen at the onset value, or behind a first-order lag of 5 to 30 s, on a probe whose noise is 1.5 to 6
    steps: an alarm on the repeats statistic within 40 samples (14 s) of the onset, none before. On 200 other
    seeds: no failure, the slowest detection 22 samples after the onset."""
    rng = np.random.default_rng(900 + seed)
    onset = int(rng.integers(800, 2400))
    sigma = float(rng.uniform(0.015, 0.06))
    truth = true_ph(N, rng)
    measured = truth + sigma * rng.normal(size=N)
    if seed % 2:  # frozen
        measured[onset:] = measured[onset]
    else:  # sluggish: tau dy/dt = x - y from the onset
        a = float(np.exp(-DT_S / rng.uniform(5.0, 30.0)))
        measured[onset:] = lfilter([1.0 - a], [1.0, -a], measured[onset:], zi=[a * measured[onset]])[0]
    det = LearnedDetector(model())
    det.process(np.arange(N) * DT_S, quantised(measured)[:, None])
    found = repeats_alarms(det)
    assert all(a["detection_index"] >= onset for a in det.alarms), (onset, det.alarms[:1])
    assert found and found[0]["detection_index"] < onset + 40, (onset, sigma, found[:1])


@pytest.mark.parametrize("sigma_steps", [0.3, 0.5, 1.0, 2.0, 4.0, 10.0])
def test_healthy_quantised_readings_do_not_alarm_from_far_below_to_far_above_one_step_of_noise(sigma_steps):
    """Ten runs of 5000 samples at each noise level (the run's own repeat share from about 0.03 to 0.7): no repeats
    alarm. Margin, measured on 60 other seeds per level: the largest statistic 0.55 to 0.69 of the threshold. In
    an earlier sweep (20 runs at each of 11 noise levels) one run reached 0.99: eleven identical readings in a row
    at 2 steps of noise, where the slow pH sat on a step (a chance of about 1e-7 a sample there)."""
    m = model()
    for seed in range(10):
        rng = np.random.default_rng(1000 * seed + int(10 * sigma_steps))
        x = quantised(true_ph(5000, rng) + sigma_steps * STEP_PH * rng.normal(size=5000))
        det = LearnedDetector(m)
        det.process(np.arange(5000) * DT_S, x[:, None])
        assert repeats_alarms(det) == [], (sigma_steps, seed, det.repeats.p0)


def test_the_share_is_the_runs_own_and_a_fault_is_not_learned_as_it():
    """A run whose healthy share is 0.35 (noise half a step) with a frozen reading from sample 2000: no alarm
    before, an alarm after, and the learned share stays near the healthy one while the alarm is up."""
    rng = np.random.default_rng(77)
    x = quantised(true_ph(N, rng) + 0.5 * STEP_PH * rng.normal(size=N))
    x[2000:] = x[2000]
    det = LearnedDetector(model())
    det.process(np.arange(N) * DT_S, x[:, None])
    found = repeats_alarms(det)
    assert found and 2000 <= found[0]["detection_index"] < 2040, found[:1]
    assert 0.2 < det.repeats.p0[0] < 0.5, det.repeats.p0


def test_a_finely_resolved_reading_with_one_chance_repeat_is_no_stale_probe():
    """A reading that never repeats (no quantisation) learns a share of 0 and is held at P0_MIN: three repeats in
    a row add 3 ln(0.9 / 0.02) = 11.4, below the threshold 20."""
    rng = np.random.default_rng(3)
    x = true_ph(N, rng) + 0.04 * rng.normal(size=N)
    x[1500:1504] = x[1500]
    det = LearnedDetector(model())
    det.process(np.arange(N) * DT_S, x[:, None])
    assert repeats_alarms(det) == []
    x[1500:1520] = x[1500]  # twenty in a row is a frozen probe
    det = LearnedDetector(model())
    det.process(np.arange(N) * DT_S, x[:, None])
    assert repeats_alarms(det) and 1500 <= repeats_alarms(det)[0]["detection_index"] < 1520


def test_missing_readings_are_no_evidence():
    t = RepeatTest(1, 0.9, warmup_blocks=1, gain=0.1)
    t.increments(t.indicators(np.arange(10.0)[:, None]))  # ten changes (the first has none before it)
    t.increments(np.array([[1.0]]))  # and one repeat
    t.adapt(frozen=False)
    assert t.p0[0] == pytest.approx(1.0 / 11.0)
    r = t.indicators(np.array([[1.0], [np.nan], [np.nan], [1.0], [1.0]]))
    z = t.increments(r)[0]
    assert z[0] == pytest.approx(np.log(0.1 / (10.0 / 11.0)))  # 1.0 after 9.0: a change
    assert z[1:3].tolist() == [0.0, 0.0]  # a missing reading: no evidence
    assert z[3] == pytest.approx(np.log(0.1 / (10.0 / 11.0)))  # the first after a gap has nothing to repeat
    assert z[4] == pytest.approx(np.log(0.9 * 11.0))  # a repeat


def test_any_chunking_gives_the_same_statistic_to_the_last_bit():
    rng = np.random.default_rng(8)
    x = quantised(true_ph(N, rng) + 0.02 * rng.normal(size=N))
    x[2100:] = x[2100]
    m = model()
    ref = LearnedDetector(m, record_trace=True)
    ref.process(np.arange(N) * DT_S, x[:, None])
    for chunk in (1, 7, 33, 500):
        _, _, det = run_record(m, np.arange(N) * DT_S, x[:, None], chunk=chunk)
        assert det.alarms == ref.alarms
        assert det.repeats.p0 == ref.repeats.p0


def test_neutral_share_and_settings():
    assert neutral_share(0.1, 0.9) == pytest.approx(np.log(9.0) / (np.log(9.0) + np.log(9.0)))
    assert LearnedSettings.from_dict({}).repeat_probability == 0.0  # files from before: off
    with pytest.raises(UserError, match="repeat_probability"):
        LearnedSettings(repeat_probability=1.0).check()
    off = learn(np.random.default_rng(1).normal(size=(2000, 1)), ["x"], LearnedSettings(sample_time_s=DT_S))
    assert LearnedDetector(off).repeats is None
