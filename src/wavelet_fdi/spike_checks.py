"""Spike checks: a probe that stepped where a tracking filter follows it within a sample.

The estimator reference (:mod:`wavelet_fdi.reference_estimator`) is a Kalman filter whose state uncertainty is
large where the pumps move the pH fast for what the curve says, on a strong acid's plateau above all. A probe
that steps there by 1 pH gives one innovation of 20 to 40 sigma and then none above 2: the filter has followed
the step into its state (its gate holds the first reading beyond the level until the second, still there,
confirms it: the state then follows as before). The band statistics read the residual limited to
``clip_sigma`` (4), so the step moves them no more than a 4 sigma outlier does, and nothing is raised (a 1 pH
offset at pH 3.7 of the April titration: no deviation at all, leave-one-out). Over a window after the step the
offset cannot be told from the acid pumped at 10^-b of its strength (pH = -log10 [H+] with [H+] linear in the
acid added), so only the step itself tells them apart (:func:`wavelet_fdi.estimator_isolation.isolate`, the
jump).

A spike is a sample whose innovation, before the limit, exceeds ``spike_sigma``: the level held-out innovations
of the calibration runs exceed with the stated probability per sample (``spike_per_sample``,
:func:`wavelet_fdi.learned_detector.measured_spike_level`). A spike opens no deviation and moves no statistic:
``NAMING_AFTER`` samples later the reference's namer judges a window starting at it, and only an offset the
reading stepped into (the jump beyond its margin, the reading stepped once by at least half the offset named)
becomes a fault alarm. A spike that is no step (an outlier, a noisy probe, a steep passage) is counted and
dropped: the band statistics, which it did not touch, go on judging the rest (a spike opening a deviation of its
own held them and restarted their sums: a noisy probe was then judged on its first few seconds, against a past
that already held its noise by the next spike, and 2 of 24 noisy probes were lost on unseen simulated days).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Spike:
    """One sample beyond the level: where (global sample index), when, on which residual channel, how large."""

    index: int
    time_s: float
    channel: int
    sigma: float


class SpikeChecks:
    """The spikes waiting for their window, found chunk by chunk (any chunking finds the same ones).

    Examples
    --------
    >>> import numpy as np
    >>> checks = SpikeChecks(level=8.0, gap=64)
    >>> z = np.zeros((200, 1)); z[[50, 60, 150], 0] = [20.0, 9.0, -12.0]
    >>> checks.scan(z, np.arange(200.0), first_index=0, from_index=10)
    >>> [(s.index, s.sigma) for s in checks.pending]  # 60 lies within the gap after 50
    [(50, 20.0), (150, -12.0)]
    >>> [s.index for s in checks.due(upto=120, after=64)], [s.index for s in checks.pending]
    ([50], [150])
    """

    def __init__(self, level: float, gap: int) -> None:
        self.level = float(level)
        self.gap = int(gap)
        self.pending: list[Spike] = []
        self._last = -(1 << 62)
        self.checked = 0  # spikes judged
        self.steps = 0  # of them, steps that became fault alarms

    def scan(self, unlimited: np.ndarray, t: np.ndarray, first_index: int, from_index: int) -> None:
        """Note the spikes among these rows (innovations before the limit, (n, channels); global index of the
        first: ``first_index``), none before global index ``from_index`` (the detector's warm-up) and none within
        ``gap`` samples after the last one (a step the filter follows over a few samples is one step)."""
        if not self.level or not len(unlimited):
            return
        z = np.nan_to_num(np.asarray(unlimited, dtype=float))
        for i in np.flatnonzero((np.abs(z) > self.level).any(axis=1)):
            g = first_index + int(i)
            if g < from_index or g - self._last < self.gap:
                continue
            ch = int(np.argmax(np.abs(z[i])))
            self.pending.append(Spike(g, float(t[i]), ch, float(z[i, ch])))
            self._last = g

    def due(self, upto: int, after: int, final: bool = False) -> list[Spike]:
        """The spikes whose window (``after`` samples from the spike) ended by global index ``upto`` (``final``:
        all of them), taken off the list."""
        out = [s for s in self.pending if final or s.index + after <= upto]
        self.pending = [s for s in self.pending if s not in out]
        return out
