"""The energy CUSUM against the run's own noise (``energy_baseline_time_constant_s``): a plant whose healthy noise
differs from the calibration runs' is compared with itself, a probe that turns noisy is found, a rise slower than
the time constant is absorbed and a faster one is not, one outlier is not a noisy probe, and any chunking gives
the same bits. The fault's onset and size are drawn per seed and never given to the detector."""

from __future__ import annotations

import json

import numpy as np
import pytest

from wavelet_fdi.learned_detector import LearnedSettings, learn, run_record

DT_S = 0.35  # the rig's sample time: a block (32 samples, 11 s) is a tenth of the time constant
TAU_S = 120.0


def settings(adapted: bool = True) -> LearnedSettings:
    return LearnedSettings(sample_time_s=DT_S, energy_variance_ratio=4.0,
                           energy_baseline_time_constant_s=TAU_S if adapted else 0.0)


def noise(n: int, seed: int, std: np.ndarray | float = 1.0) -> np.ndarray:
    """Two channels of white noise about 5 and 7 (a probe's own noise is white)."""
    rng = np.random.default_rng(seed)
    return np.column_stack([5.0 + std * rng.normal(size=n), 7.0 + rng.normal(size=n)])


def model(adapted: bool = True):
    return learn(noise(4000, 11), ["ph", "level"], settings(adapted))


def alarms(m, x: np.ndarray, chunk: int | None = None) -> list[dict]:
    _, _, det = run_record(m, np.arange(len(x)) * DT_S, x, chunk=chunk)
    return det.alarms


def test_a_run_noisier_than_the_calibration_runs_is_compared_with_itself():
    """Healthy noise 1.8 times the calibration runs' (3.2 times the variance, within the design ratio): the
    calibrated scale raises an alarm on it, the run's own scale does not."""
    x = noise(3000, 21, std=1.8)
    assert alarms(model(adapted=False), x), "the calibrated scale saw nothing: the test shows nothing"
    assert alarms(model(), x) == []


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_probe_that_turns_noisy_is_found_after_its_onset_on_its_channel(seed):
    from wavelet_fdi.learned_detector import LearnedDetector

    rng = np.random.default_rng(300 + seed)
    onset = int(rng.integers(1000, 2000))
    factor = float(rng.uniform(3.0, 5.0))  # the noise's standard deviation grows this much
    std = np.where(np.arange(3000) >= onset, 1.5 * factor, 1.5)  # on a run already noisier than calibrated
    det = LearnedDetector(model(), record_trace=True)
    det.process(np.arange(3000) * DT_S, noise(3000, 40 + seed, std=std))
    assert det.alarms and onset <= det.alarms[0]["detection_index"] < onset + 60, (onset, det.alarms[:1])
    # the noise statistic of the noisy channel crosses (the mean ones may too: the noise reaches AJ), the other
    # channel's does not
    stat = det.trace()["stat"]
    crossed = np.flatnonzero(stat[:, det.stat_names.index("ph.D1.energy")] > 1.0)
    assert crossed.size and onset <= crossed[0] < onset + 60, (onset, crossed[:1])
    assert not (stat[:, [det.stat_names.index(f"level.D{j}.energy") for j in (1, 2)]] > 1.0).any()


def test_a_rise_slower_than_the_time_constant_is_absorbed_and_a_faster_one_is_not():
    """The same rise of the noise's standard deviation from 0.6 to 1.5 of the calibration runs' (6.25 times the
    variance; both ends within the design ratio of the calibrated scale), over 20 time constants and as a step."""
    n, start = 12000, 1000
    k = np.arange(n)
    slow = 0.6 + 0.9 * np.clip((k - start) / (20 * TAU_S / DT_S), 0.0, 1.0)  # over 6860 samples
    assert alarms(model(), noise(n, 51, std=slow)) == []
    step = np.where(k >= start, 1.5, 0.6)
    found = alarms(model(), noise(n, 51, std=step))
    assert found and start <= found[0]["detection_index"] < start + 60, found[:1]


def test_one_outlier_is_not_a_noisy_probe():
    """Each sample counts at most as the design variance ratio: one reading 40 sigma off moves the statistic by
    less than its threshold."""
    x = noise(3000, 61)
    x[1500, 0] += 40.0
    assert not [a for a in alarms(model(), x) if a["statistic"].endswith(".energy")]


def test_any_chunking_gives_the_same_alarms_to_the_last_bit():
    std = np.where(np.arange(3000) >= 1700, 4.0, 1.5)
    m = model()
    outs = [json.dumps(alarms(m, noise(3000, 71, std=std), chunk), sort_keys=True) for chunk in (None, 1, 7, 33, 500)]
    assert json.loads(outs[0]), "no alarm: nothing to compare"
    assert all(o == outs[0] for o in outs[1:])


def test_a_model_file_without_the_setting_reads_as_before():
    from wavelet_fdi.learned_detector import LearnedModel

    d = model().to_dict()
    d["settings"].pop("energy_baseline_time_constant_s")
    assert LearnedModel.from_dict(d).settings.energy_baseline_time_constant_s == 0.0
