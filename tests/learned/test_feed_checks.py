"""Feed checks (wavelet_fdi.feed_checks): a reading that moves against the only feed that runs.

The level's rate is checked where its assumptions hold (Gaussian noise about a pH that the feed holds level or
moves its own way, correlated over at most a sample or two) on independent windows, by a binomial rule; the
check finds a reading that rises under acid alone and leaves the same reading under base alone; any chunking finds
the same crossings.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import binom

from wavelet_fdi.feed_checks import BATCH_SAMPLES, WINDOW_SAMPLES, FeedChecks, against_feed_t, feed_codes, level

WINDOWS = 20_000


def _ar1(rng: np.random.Generator, n: int, rho: float) -> np.ndarray:
    e = rng.standard_normal((n, WINDOW_SAMPLES))
    for k in range(1, WINDOW_SAMPLES):
        e[:, k] = rho * e[:, k - 1] + np.sqrt(1.0 - rho * rho) * e[:, k]
    return e


@pytest.mark.parametrize("rho, allowed", [(0.0, 1.0), (0.3, 2.5)])
@pytest.mark.parametrize("seed", [11, 12])
def test_the_level_keeps_its_rate_where_its_assumptions_hold(seed, rho, allowed):
    """20 000 independent windows of Gaussian noise (0.05 pH) about a level pH under acid alone (the exact null;
    a pH falling with the acid only lowers the statistic): the share beyond the 1e-3 level is at most ``allowed``
    times 1e-3, by a binomial rule that a statistic keeping that rate fails with probability 1e-4 per draw (two
    seeds per case: under 1 in 1000 runs). White noise is the assumption itself (measured rate 1.1e-3 at 40 000
    windows); AR(1) noise of correlation 0.3, beyond it, is the stroke ripple's kind (measured 1.9e-3; plain least
    squares on the readings, without batch means, gave 1.1e-2)."""
    rng = np.random.default_rng(seed)
    y = 7.0 + 0.05 * _ar1(rng, WINDOWS, rho)
    z = against_feed_t(y, -np.ones(WINDOWS, dtype=int))
    beyond = int((z > level(1e-3)).sum())
    assert beyond <= binom.isf(1e-4, WINDOWS, allowed * 1e-3), beyond


def test_a_ph_that_moves_with_the_feed_never_crosses():
    """The pH falling under acid at a tenth of the noise per batch (nearly level): below the level in every window
    of 20 000."""
    rng = np.random.default_rng(3)
    fall = -0.005 * np.arange(WINDOW_SAMPLES) / BATCH_SAMPLES
    z = against_feed_t(7.0 + fall + 0.05 * rng.standard_normal((WINDOWS, WINDOW_SAMPLES)),
                       -np.ones(WINDOWS, dtype=int))
    assert (z < level(1e-6)).all(), float(z.max())


def _acid_run(rise_from_s: float | None, n: int = 800, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(n) * 0.35
    ph = 3.5 - 0.002 * t + np.random.default_rng(seed).normal(0.0, 0.03, n)
    if rise_from_s is not None:
        ph += np.where(t > rise_from_s, (t - rise_from_s) * 0.5 / 60.0, 0.0)  # 0.5 pH/min up
    return t, np.column_stack([np.full(n, 4.3), np.zeros(n), ph])


def _crossings(t: np.ndarray, rows: np.ndarray, chunk: int, directions=(-1, 1)) -> list[tuple[int, int]]:
    checks = FeedChecks(level(1e-6), directions, gap=64)
    for a in range(0, len(t), chunk):
        checks.scan(t[a:a + chunk], rows[a:a + chunk], first_index=a, from_index=0)
    return [(c.index, c.direction) for c in checks.pending]


def test_a_reading_rising_under_acid_alone_is_found_and_the_same_under_base_is_not():
    """A reading rising 0.5 pH/min from 150 s while acid alone runs: a crossing after 150 s and none before; the
    same reading with the feed called a base (which raises the pH) crosses nothing; the healthy run nothing."""
    t, rows = _acid_run(150.0)
    found = _crossings(t, rows, len(t))
    assert found and all(t[i] > 150.0 and d == -1 for i, d in found), found
    assert _crossings(t, rows, len(t), directions=(1, -1)) == []
    assert _crossings(*_acid_run(None), len(t)) == []


def test_a_stretch_is_tested_once_settled_and_turned_with_its_feed():
    """The base ran until 100 s; after it the reading goes on rising toward where the base was taking it (the
    mixing zone and the probe lag it, here with a 40 s time constant, longer than the settle time) and then falls
    with the acid; from 300 s it drifts up. Nothing crosses before 300 s (the transient against the acid is no
    evidence: tested only once a window of the stretch showed the reading moving with the acid; on the settle time
    alone it read t = 28.7 at 156 s), a crossing follows
    the drift. A reading that rises from the stretch's start and never turns with the feed is never tested."""
    t, rows = _acid_run(300.0, n=1400)
    rows[t < 100.0, 1] = 3.0  # both pumps until 100 s
    rows[:, 2] += np.where(t >= 100.0, 1.5 * (1.0 - np.exp(-(t - 100.0) / 40.0)), 0.0)  # the base's transient
    codes = feed_codes(rows[:, :2], np.array([-1, 1]))
    assert (codes[t < 100.0] == 0).all() and (codes[t >= 100.0] == -1).all()
    found = _crossings(t, rows, len(t))
    assert found and all(t[i] > 300.0 for i, _ in found), found
    without = FeedChecks(-1e9, (-1, 1), gap=1)  # every window tested and turned, with its value
    without.scan(t, rows, first_index=0, from_index=0)
    assert min(c.time_s for c in without.pending) - (WINDOW_SAMPLES - 1) * 0.35 >= 100.0 + 30.0 - 1e-9
    rising = _acid_run(0.0)  # rising from the record's first row: never seen moving with the acid
    assert _crossings(*rising, len(rising[0])) == []


def test_any_chunking_finds_the_same_crossings():
    t, rows = _acid_run(120.0, n=1200, seed=4)
    whole = _crossings(t, rows, len(t))
    assert whole
    for chunk in (1, 33, 257):
        assert _crossings(t, rows, chunk) == whole, chunk


def test_the_streaming_statistic_is_the_windows_one():
    """What the streaming checks compare with the level is :func:`against_feed_t` of the window's readings."""
    t, rows = _acid_run(120.0, n=600, seed=5)
    checks = FeedChecks(-1e9, (-1, 1), gap=1)  # every tested sample noted, with its value
    checks.scan(t, rows, first_index=0, from_index=0)
    assert checks.pending
    ends = np.array([c.index for c in checks.pending])
    windows = np.stack([rows[e - WINDOW_SAMPLES + 1:e + 1, 2] for e in ends])
    expected = against_feed_t(windows, np.array([c.direction for c in checks.pending]))
    np.testing.assert_allclose([c.value for c in checks.pending], expected, rtol=1e-9, atol=1e-9)
