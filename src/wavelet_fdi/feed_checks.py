"""Feed checks: a reading that moves against the only feed that runs.

In a stirred vessel fed by one strong reagent the pH can move one way only: acid alone lowers it or leaves it
(the reaction invariant falls toward the acid's strength, and an overflow's dilution pulls it the same way),
base alone raises it. A probe whose reading rises while only acid runs (or falls while only base runs) is
wrong, whatever the reagents' strengths, the vessel's contents or the titration curve: no calibration and no
model enters the test. It is what finds a probe that drifts up on a strong acid's plateau, where the tracking
filter follows the drift as a weaker acid and the band statistics see nothing (a 1 pH/min drift in the
shared acid runs: three of five onsets raised nothing at all, two only a deviation no fault explained).

The statistic (:func:`against_feed_t`): over the last ``window`` samples, the least-squares slope of the reading's
batch means (``BATCH_SAMPLES`` readings each) against time, signed against the running feed, over its standard
error from the means' own residuals about their line. Batch means because the pumps' stroke ripple correlates
the readings over a few samples: their errors are nearly independent where the readings' are not (under AR(1)
noise of correlation 0.3 the rate at the 1e-3 level was 1.9e-3 with batch means, 1.1e-2 with plain least
squares on the readings and 8.3e-3 with a Newey-West error, tried first; docs/detector.md).
Testable samples: exactly one feed has run (recorded flow above 0) in every row of the window and for
``settle_s`` before it (the mixing zone and the probe's lag: a reading still rising from the base that stopped
is no evidence), the window's readings are all finite, and an earlier window of the same stretch had the reading
moving with the feed or level (statistic <= 0): the previous feed's transient, which decays through the mixing
and probe lags while the new feed's effect grows, is over once the net slope has turned (it turns once). Why the
turn and not only the settle time: on simulated days with mixing and probe twice to four times slower than the
rig's fitted ones (zone 25-40 s, probe 6-10 s), healthy on/off runs read up to t = 47 after 30 s of settling; with
the turn, 5.2 at most (the level is 7.7). What it costs: a drift already under way when the feed started running
alone is not tested in that stretch.

**The design rate.** Assumptions, stated: (1) while one feed runs the true pH is monotone in that feed's
direction (well mixed, no other reagent, no unrecorded feed); (2) the reading's error about it is stationary
over the window, Gaussian and correlated over much less than a batch. Under them the statistic is at most a
t with ``window / BATCH_SAMPLES - 2`` degrees of freedom (at most: a pH that moves with the feed only lowers it),
and the level is its quantile for the stated probability per sample (``against_feed_per_sample``, 1e-6 for the
estimator: 7.74 at 64 samples, 16 batches, 14 d.f.). A crossing is judged ``gap`` samples later by the
reference's namer (:meth:`wavelet_fdi.learned_detector.LearnedDetector._check_feed`): it becomes a fault alarm
when a probe offset or drift against the feed explains the window better than any healthy re-adaptation
(:func:`wavelet_fdi.estimator_isolation.isolate`); else it is counted and dropped.

What it cannot tell apart: a feed that runs while recorded off (the other pump leaking or running unrecorded)
moves the reading against the recorded feed exactly as a drifting probe does. With one pH probe and the pump
commands as the flows, the reading is the only evidence; the alarm names the probe and says so.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: the span of a pump's recent flow a feed state holds (s): three times the rig's mixing zone's time constant as
#: fitted (5-11 s, docs/diagnosis.md); the estimator's change test holds its pump states as long
SETTLE_S = 30.0
#: the slope's window (samples): the naming's own first window (AFTER_DETECTION_SAMPLES), fixed before any run
#: was scored with this test
WINDOW_SAMPLES = 64
#: readings per batch mean: the statistic regresses the window's batch means, whose errors are nearly independent
#: where the reading's are correlated over a sample or two (the pumps' stroke ripple keeps its phase 0.45-0.65 s,
#: rigsim.day): with AR(1) errors of correlation 0.3 the rate beyond the 1e-3 level is 1.9e-3 (plain least squares
#: on the readings: 1.1e-2), measured in tests/learned/test_feed_checks.py
BATCH_SAMPLES = 4
#: the reading's resolution floor for the standard error (pH): a meter's 0.01 step, uniform (a window of identical
#: readings has a zero residual, not a zero uncertainty)
RESOLUTION_PH = 0.01


def feed_codes(flows: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Per row, the direction of the only feed that runs (-1 acid, +1 base), 0 when none or several run or a flow
    is missing."""
    q = np.asarray(flows, dtype=float)
    on = np.nan_to_num(q, nan=0.0) > 0
    single = (on.sum(axis=1) == 1) & np.isfinite(q).all(axis=1)
    return np.where(single, (on * np.sign(np.asarray(directions, dtype=float))[None, :]).sum(axis=1), 0).astype(int)


def level(per_sample: float, window: int = WINDOW_SAMPLES) -> float:
    """The statistic's level for a stated probability per healthy sample: the t quantile with (batches - 2) d.f.

    >>> round(level(1e-6), 2)
    7.74
    """
    from scipy.stats import t as t_distribution  # here: scipy.stats takes about 1 s to import (node start-up)

    return float(t_distribution.isf(per_sample, window // BATCH_SAMPLES - 2))


def against_feed_t(readings: np.ndarray, codes: np.ndarray) -> np.ndarray:
    """The statistic of each window (rows of ``readings``, (n, window)), signed against ``codes`` (n,): the slope of
    the window's batch means (``BATCH_SAMPLES`` readings each) over its standard error from their own residual
    variance, positive when the reading moves against the feed. A t with (batches - 2) degrees of freedom for
    Gaussian noise about a straight line whose correlation is short against a batch.

    >>> rng = np.random.default_rng(0)
    >>> up = np.arange(64) * 0.01 + rng.normal(0, 0.02, 64)  # rising 0.01 pH a sample
    >>> [round(float(v), 1) for v in against_feed_t(np.vstack([up, up]), np.array([-1, 1]))]
    [74.1, -74.1]
    """
    y = np.asarray(readings, dtype=float)
    n, w = y.shape
    batches = w // BATCH_SAMPLES
    return _batch_means_t(y[:, :batches * BATCH_SAMPLES].reshape(n, batches, BATCH_SAMPLES).mean(axis=2), codes)


def _batch_means_t(means: np.ndarray, codes: np.ndarray) -> np.ndarray:
    """:func:`against_feed_t` from the windows' batch means (n, batches), oldest first."""
    batches = means.shape[1]
    tt = np.arange(batches) - (batches - 1) / 2.0
    sxx = float(tt @ tt)
    slope = means @ tt / sxx
    resid = means - means.mean(axis=1, keepdims=True) - slope[:, None] * tt
    floor = RESOLUTION_PH**2 / 12.0 / BATCH_SAMPLES
    variance = np.maximum((resid * resid).sum(axis=1) / (batches - 2.0), floor)
    return -np.asarray(codes) * slope / np.sqrt(variance / sxx)


def reading_rate_ph_per_min(t_s: np.ndarray, reading: np.ndarray) -> float:
    """The reading's least-squares slope over these samples (pH/min; NaN readings left out, 0 with under 2).

    >>> round(reading_rate_ph_per_min(np.arange(10) * 0.5, 7.0 + np.arange(10) * 0.01), 3)
    1.2
    """
    ok = np.isfinite(t_s) & np.isfinite(reading)
    if ok.sum() < 2:
        return 0.0
    return float(np.polyfit(t_s[ok], reading[ok], 1)[0] * 60.0)


@dataclass(frozen=True)
class FeedCheck:
    """One crossing: the window's last sample (global index, time), its first, the feed's direction, the value, and
    since when (s) that feed had been the only one running (the stretch it belongs to)."""

    index: int
    time_s: float
    first_index: int
    direction: int
    value: float
    since_s: float


class FeedChecks:
    """The crossings waiting for their judgement, found chunk by chunk (any chunking finds the same ones).

    ``directions``: per feed column (the rows' first columns) -1 for an acid, +1 for a base; the reading is the
    column after them. ``gap``: samples after a crossing before the next may be noted (and after which it is due).

    Examples
    --------
    >>> import numpy as np
    >>> checks = FeedChecks(level=5.25, directions=(-1, 1), gap=64, settle_s=3.0)
    >>> t = np.arange(400) * 0.35
    >>> ph = 3.0 + np.where(t > 60, (t - 60) / 60, 0.0) + np.random.default_rng(1).normal(0, 0.02, 400)
    >>> rows = np.column_stack([np.full(400, 4.3), np.zeros(400), ph])  # acid alone, the reading rising from 60 s
    >>> checks.scan(t[:150], rows[:150], first_index=0, from_index=0)
    >>> checks.scan(t[150:], rows[150:], first_index=150, from_index=0)
    >>> [(c.index, c.direction) for c in checks.pending][:1]
    [(194, -1)]
    """

    def __init__(self, level: float, directions: tuple[int, ...], gap: int, settle_s: float = SETTLE_S,
                 window: int = WINDOW_SAMPLES) -> None:
        self.level = float(level)
        self.directions = np.asarray(directions, dtype=float)
        self.settle_s = float(settle_s)
        self.gap = int(gap)
        self.window = int(window)
        self.pending: list[FeedCheck] = []
        self.checked = 0  # crossings judged
        self.faults = 0  # of them, the ones that became fault alarms
        self._last = -(1 << 62)
        self._hist_t = np.empty(0)
        self._hist_y = np.empty(0)
        self._code = 0  # the last row's feed code, and since when (time) it held
        self._since_s = np.nan
        # the stretch of the last tested window, and whether the reading had turned with its feed by its end
        self._turned_since = np.nan
        self._turned = False

    def scan(self, t: np.ndarray, rows: np.ndarray, first_index: int, from_index: int) -> None:
        """Note the crossings among these rows (global index of the first: ``first_index``), none before global
        index ``from_index`` and none within ``gap`` samples after the last one."""
        if not self.level or not len(rows):
            return
        m = len(self.directions)
        t = np.asarray(t, dtype=float)
        rows = np.asarray(rows, dtype=float)
        codes = feed_codes(rows[:, :m], self.directions)
        since = self._run_starts(t, codes)
        w = self.window
        all_t = np.concatenate([self._hist_t, t])
        all_y = np.concatenate([self._hist_y, rows[:, m]])
        h = len(self._hist_t)
        self._hist_t, self._hist_y = all_t[-(w - 1):], all_y[-(w - 1):]
        k = np.arange(len(rows))
        pos = h + k  # each row's place in all_*
        full = pos >= w - 1
        first_t = np.where(full, all_t[np.maximum(pos - (w - 1), 0)], np.nan)
        testable = full & (codes != 0) & (first_t - since >= self.settle_s)
        if not testable.any():
            return
        # each window's batch means: the mean of the BATCH_SAMPLES readings ending at every place (the same sums
        # whatever the chunking), taken every BATCH_SAMPLES places back from the window's last
        b = BATCH_SAMPLES
        ends = pos[testable]
        moving = np.convolve(all_y, np.full(b, 1.0 / b), mode="valid")  # moving[j]: readings j..j+b-1
        back = np.arange(w // b - 1, -1, -1) * b
        means = moving[ends[:, None] - back[None, :] - (b - 1)]
        finite = np.isfinite(means).all(axis=1)
        rows_tested = k[testable][finite]
        z = _batch_means_t(means[finite], codes[rows_tested])
        crossed = (z > self.level) & self._turned_before(z, since[rows_tested])
        for i, value in zip(rows_tested[crossed], z[crossed]):
            g = first_index + int(i)
            if g < from_index or g - self._last < self.gap:
                continue
            self.pending.append(FeedCheck(g, float(t[i]), g - (w - 1), int(codes[i]), float(value), float(since[i])))
            self._last = g

    def _turned_before(self, z: np.ndarray, since: np.ndarray) -> np.ndarray:
        """Per tested window (in order), whether an earlier tested window of the same stretch (its feed running
        alone since the same time) had the reading moving with the feed or level (statistic <= 0), this chunk's or
        an earlier one's: the previous feed's transient is over (it decays through mixing and probe lags while the
        new feed's effect grows: the net slope turns once)."""
        with_feed = z <= 0.0
        new_stretch = np.r_[True, since[1:] != since[:-1]]
        group = np.cumsum(new_stretch) - 1
        before: np.ndarray = np.cumsum(with_feed) - with_feed  # windows with the feed before each, in the chunk
        turned = before - before[new_stretch][group] > 0
        turned |= (since == self._turned_since) & self._turned  # the stretch the last chunk ended in
        self._turned_since, self._turned = float(since[-1]), bool(turned[-1] or with_feed[-1])
        return turned

    def _run_starts(self, t: np.ndarray, codes: np.ndarray) -> np.ndarray:
        """Per row, the time its feed code has held since (the record's first row for a code it started with:
        what ran before the record is unknown)."""
        n = len(codes)
        changed = np.r_[codes[0] != self._code or np.isnan(self._since_s), codes[1:] != codes[:-1]]
        start_t = np.where(changed, t, np.nan)
        if not changed[0]:
            start_t[0] = self._since_s
        idx = np.maximum.accumulate(np.where(np.isfinite(start_t), np.arange(n), 0))
        since = start_t[idx]
        self._code, self._since_s = int(codes[-1]), float(since[-1])
        return since

    def due(self, upto: int, after: int, final: bool = False) -> list[FeedCheck]:
        """The crossings whose judgement window (``after`` samples from the crossing) ended by global index
        ``upto`` (``final``: all of them), taken off the list."""
        out = [c for c in self.pending if final or c.index + after <= upto]
        self.pending = [c for c in self.pending if c not in out]
        return out
