"""docs/architecture.md, "A statistic of the learned detector": a new kind is one class in one file.

The toy kind here is registered in this file alone; the learned detector then runs it on every channel, names it
``CHANNEL.raw.KIND`` in its statistics, its traces and its alarms, and its alarm has the onset of its own CUSUM. A
contract test holds every registered kind to the protocol, and the order of the shipped kinds' statistics (their
names, alarms and traces read by position) is pinned.
"""

from __future__ import annotations

import numpy as np
import pytest

from wavelet_fdi.learned_detector import LearnedDetector, LearnedSettings, learn
from wavelet_fdi.learned_statistics import (
    LEARNED_STATISTICS,
    LearnedStatistic,
    StatisticRow,
    register_learned_statistic,
)

LIMIT = 20.0  # the toy's alarm limit on a channel's raw reading


class AboveLimit(LearnedStatistic):
    """Toy: readings above LIMIT (1 per sample above it; k 0.5, so a CUSUM grows by 0.5 a sample above it)."""

    kind = "above_limit"

    def rows(self) -> list[StatisticRow]:
        raw = self.settings.level + 1
        return [StatisticRow(c, raw, self.kind) for c in range(self.detector.m)]

    def reference_value(self) -> float:
        return 0.5

    def threshold(self) -> float:
        return 10.0

    def prepare(self, chunk, rows) -> None:
        self._above = (rows > LIMIT).T.astype(float)  # the raw rows: what a reading is, not its residual

    def values(self, out, chunk, i0, i1, g0, u) -> None:
        out[:] = self._above[:, i0:i1]


@pytest.fixture
def toy_kind():
    register_learned_statistic(AboveLimit)
    yield AboveLimit
    LEARNED_STATISTICS.pop(AboveLimit.kind)  # the registry is global: other tests run the shipped kinds only


def healthy(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.column_stack([5.0 + rng.normal(size=n), 7.0 + rng.normal(size=n)])


def test_a_registered_kind_is_run_named_and_raises_its_own_alarm(toy_kind):
    model = learn(healthy(4000, 1), ["flow", "pressure"], LearnedSettings(mean_h=1e6, energy_variance_ratio=0.0))
    x = healthy(3000, 2)
    x[2000:, 1] += 20.0  # the pressure reads above the limit from row 2000 (the mean CUSUMs are off: h 1e6)
    det = LearnedDetector(model, record_trace=True)
    assert det.stat_names[-2:] == ["flow.raw.above_limit", "pressure.raw.above_limit"]
    det.process(np.arange(3000.0), x)
    stat = det.trace()["stat"]
    toy = det.stat_names.index("pressure.raw.above_limit")
    assert not (stat[:2000, toy] > 1.0).any()
    assert det.alarms and det.alarms[0]["statistic"] == "pressure.raw.above_limit", det.alarms[:1]
    # 10 / 0.5 = 20 samples above the limit cross h; the onset is the CUSUM's last zero
    assert det.alarms[0]["detection_index"] == 2020 and det.alarms[0]["onset_index"] == 2000
    assert list(det.alarms[0]["contributions"]) == ["pressure"]


def test_without_the_toy_the_detector_runs_the_shipped_kinds_only():
    model = learn(healthy(4000, 1), ["flow", "pressure"])
    assert not [n for n in LearnedDetector(model).stat_names if n.endswith(".above_limit")]


def test_the_shipped_kinds_statistics_keep_their_order():
    """Mean up and down per channel, then energy up per channel and band, energy down likewise, then repeats: the
    order alarms, traces and calibration files were made with."""
    s = LearnedSettings(level=2, energy_variance_ratio=4.0, energy_down_variance_ratio=0.25, repeat_probability=0.5)
    det = LearnedDetector(learn(healthy(4000, 1), ["a", "b"], s))
    assert det.stat_names == [
        "a.A2.mean_up", "a.A2.mean_down", "b.A2.mean_up", "b.A2.mean_down",
        "a.D1.energy", "a.D2.energy", "b.D1.energy", "b.D2.energy",
        "a.D1.energy_down", "a.D2.energy_down", "b.D1.energy_down", "b.D2.energy_down",
        "a.raw.repeats", "b.raw.repeats"]
    assert det.h.tolist() == [s.mean_h] * 4 + [s.energy_h] * 4 + [s.energy_down_h] * 4 + [s.repeat_h] * 2


def test_the_residual_mean_sees_a_step_before_the_approximation_band_does():
    """The residual's own mean (R, residual_mean_k) against AJ's mean: on a step of 3 healthy sigmas in one channel
    it crosses first, since AJ, a local mean over about 2^J samples, lags the step."""
    s = LearnedSettings(level=3, mean_k=1.5 * 2 ** 1.5, mean_h=20.0, residual_mean_k=1.5, residual_mean_h=20.0)
    model = learn(healthy(6000, 1), ["a", "b"], s)
    x = healthy(3000, 4)
    x[2000:, 1] += 3.0 * np.std(healthy(6000, 1)[:, 1])
    det = LearnedDetector(model, record_trace=True)
    det.process(np.arange(3000.0), x)
    ratio = det.trace()["stat"]
    first = {name: int(np.argmax(ratio[2000:, det.stat_names.index(name)] > 1.0))
             for name in ("b.R.mean_up", "b.A3.mean_up")}
    assert 0 < first["b.R.mean_up"] < first["b.A3.mean_up"], first
    assert det.alarms and det.alarms[0]["statistic"] == "b.R.mean_up"


def test_the_approximation_energy_sees_a_slow_swing_the_mean_cusums_miss():
    """AJ's energy (aj_energy_variance_ratio, the physics detector's approximation-band energy) against AJ's mean
    CUSUMs, each threshold measured for ARL0 1e5 on the same healthy rows: a slow zero-mean swing of one channel (a
    square wave moving AJ by +-1 of its healthy sigmas, 64-sample half-period) raises the energy row, while with
    the energy off the same record raises no alarm (fixed seeds: the same numbers every run)."""
    s = dict(level=3, mean_k=1.5 * 2 ** 1.5, arl0_samples=1e5)
    base = healthy(20000, 1)
    off = learn(base, ["a", "b"], LearnedSettings(**s))
    on = learn(base, ["a", "b"], LearnedSettings(**s, aj_energy_variance_ratio=4.0))
    assert set(on.thresholds) >= {"a.A3.aj_energy", "b.A3.aj_energy"}  # measured, not the declared 20
    x = healthy(8000, 5)
    swing = np.where((np.arange(6000) // 64) % 2 == 0, 1.0, -1.0)
    x[2000:, 1] += off.band_sigma[1, -1] / 2 ** 1.5 * swing  # AJ reads a level 2^(J/2) times: +-1 of its sigmas
    quiet = LearnedDetector(off)
    quiet.process(np.arange(8000.0), x)
    assert not quiet.alarms, quiet.alarms[:1]
    det = LearnedDetector(on)
    assert det.stat_names[-2:] == ["a.A3.aj_energy", "b.A3.aj_energy"]
    det.process(np.arange(8000.0), x)
    assert det.alarms and det.alarms[0]["statistic"] == "b.A3.aj_energy", det.alarms[:1]
    assert 2000 < det.alarms[0]["detection_index"] < 4000


@pytest.mark.parametrize("kind", list(LEARNED_STATISTICS))
def test_every_kind_keeps_the_protocol(kind):
    """Rows inside the detector's channels and bands, k finite, h positive, values of the asked shape and finite on
    healthy rows."""
    s = LearnedSettings(level=2, energy_variance_ratio=4.0, energy_down_variance_ratio=0.25, repeat_probability=0.5,
                        residual_mean_k=0.5, aj_energy_variance_ratio=4.0)
    det = LearnedDetector(learn(healthy(4000, 1), ["a", "b"], s))
    stat = next(st for st in det.statistics if st.kind == kind)
    rows = stat.rows()
    assert rows and all(0 <= r.channel < det.m and 0 <= r.band < len(det.bands) for r in rows)
    assert np.isfinite(stat.reference_value()) and stat.threshold() > 0
    det.process(np.arange(300.0), healthy(300, 3))
    assert stat in det.statistics and np.isfinite(det.cusum.value).all()
