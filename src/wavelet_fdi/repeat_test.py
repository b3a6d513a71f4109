"""A reading that stops changing: the Bernoulli CUSUM of exact repeats (a frozen or sluggish sensor).

A healthy quantised reading is dithered across its steps by its own noise: the rig's pH meter (0.01 pH) repeats
its previous value in 7 to 13 % of the samples of the shared runs (at most 20 % over any 128 samples). A frozen
reading repeats in every sample; a probe turned sluggish (a lag of 10 to 30 s) smooths its noise below one step
and repeats in 75 to 100 % of the samples of its first 20 s. The wavelet energy-decrease statistic sees the same
loss of noise, but it needs about 44 s at a complete loss (docs/detector.md); counting repeats sees it in a few
seconds.

Per watched channel, r_k = 1 when the raw reading x_k equals x_(k-1) (0 when x_(k-1) is missing; no evidence
when x_k is), and the CUSUM
of the log-likelihood ratio of Bernoulli(p1) against Bernoulli(p0) (the Bernoulli CUSUM, Reynolds & Stoumbos
1999):

    z_k = r_k ln(p1 / p0) + (1 - r_k) ln((1 - p1) / (1 - p0))

p1 is the design (``LearnedSettings.repeat_probability``: a stale reading repeats in at least this share of the
samples); p0 is this run's own repeat share, learned the way the energy test learns the run's noise: the running
share over the first ``ENERGY_WARMUP_BLOCKS`` blocks (the statistic waits for it), then moving with the
energy baseline's time constant, frozen while the statistic is above ``freeze_ratio`` of its threshold or an
alarm is up (a frozen probe is not learned as the run's normal). Why the run's own: the repeat share is the
quantisation step over the noise, and the noise differs fourfold from day to day. p0 is kept at least
``P0_MIN`` (a finely resolved reading that never repeats would make one chance repeat decisive), and where it
exceeds ``P0_MAX_SHARE`` of p1 the channel repeats too often for the test to tell a stale reading from a healthy
one: it then reports no evidence (the increment of a change, negative). The threshold is a false-alarm rate:
the CUSUM of a log-likelihood ratio has an in-control average run length of at least e^h samples when p0 is
right (Lorden 1971), and a healthy stretch that repeats more often than p0 still drifts downward until its share
passes the neutral point (0.39 for p0 = 0.1 and p1 = 0.75).

Any chunking gives the same increments: the last reading is kept between calls, and the share adapts from
integer counts at the global block boundaries.
"""

from __future__ import annotations

import math

import numpy as np

#: the smallest repeat share assumed of a healthy reading
P0_MIN = 0.02
#: above this share of p1 the run's own repeat share leaves the test nothing to tell
P0_MAX_SHARE = 2.0 / 3.0


class RepeatTest:
    """Increments of the repeats CUSUM for ``m`` channels, with the run's own repeat share (module docstring).

    Examples
    --------
    >>> test = RepeatTest(1, design_probability=0.75, warmup_blocks=1, gain=0.1)
    >>> r = test.indicators(np.array([[1.0], [1.0], [1.01], [1.02]]))
    >>> r[0].tolist()  # the first reading has none before it
    [0.0, 1.0, 0.0, 0.0]
    >>> test.increments(r).tolist()  # nothing learned yet: no evidence
    [[0.0, 0.0, 0.0, 0.0]]
    >>> test.adapt(frozen=False)
    >>> test.p0[0]
    0.25
    >>> [round(float(z), 2) for z in test.increments(np.array([[1.0, 0.0]]))[0]]  # ln(0.75/0.25), ln(0.25/0.75)
    [1.1, -1.1]
    """

    def __init__(self, m: int, design_probability: float, warmup_blocks: int, gain: float,
                 min_valid: int = 1) -> None:
        if not 0.0 < design_probability < 1.0:
            raise ValueError(f"design repeat probability must be between 0 and 1, got {design_probability}")
        self.p1 = design_probability
        self.warmup_blocks = warmup_blocks
        self.gain = gain  # per block, after the warm-up
        self.min_valid = min_valid  # a block with fewer valid samples on a channel keeps its share
        self.m = m
        self.p0 = [P0_MIN] * m  # the run's repeat share per channel
        self.blocks = 0  # blocks the share has learned from
        self._last = np.full(m, np.nan)
        # this block's counts per channel (integers: any chunking sums them exactly): missing samples, repeats
        self._n = 0
        self._missing = [0] * m
        self._repeats = [0] * m
        self._gappy = False  # the last indicators held a missing sample
        self._levels()

    # per-channel state in plain Python lists and floats: this runs every block, and a numpy call on a
    # 32-sample block costs 1-2 us (the rig's 1e5 samples/s)
    def _levels(self) -> None:
        """The increments of a change (down) and of a repeat (down + span) for the current shares."""
        down, span = [], []
        for p in self.p0:
            p = max(p, P0_MIN)
            d = math.log((1.0 - self.p1) / (1.0 - p))
            # where repeats are too common for the test to tell, a repeat is no evidence either
            u = d if p > P0_MAX_SHARE * self.p1 else math.log(self.p1 / p)
            down.append(d)
            span.append(u - d)
        one = self.m == 1  # a float broadcasts without building an array
        self._down = down[0] if one else np.array(down)[:, None]
        self._span = span[0] if one else np.array(span)[:, None]

    def indicators(self, raw: np.ndarray) -> np.ndarray:
        """r (m, n) for readings raw (n, m): 1.0 where a reading equals the previous one (across calls), 0.0 where
        it differs or has none before it (the record's first, or the first after a missing one), NaN where it is
        missing."""
        cur = np.ascontiguousarray(raw.T)
        prev = np.empty_like(cur)
        prev[:, 0] = self._last
        prev[:, 1:] = cur[:, :-1]
        self._last = cur[:, -1].copy()
        r = (cur == prev).astype(float)
        missing = np.isnan(cur)
        self._gappy = bool(missing.any())
        if self._gappy:
            r[missing] = np.nan
        return r

    def increments(self, r: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """z (m, n) for indicators r (m, n), counted into the block's share; a missing sample is no evidence.
        ``out``: where to write z (the detector's statistics rows)."""
        self._n += r.shape[1]
        valid = None
        if self._gappy:
            valid = np.isfinite(r)
            r = np.where(valid, r, 0.0)
            self._missing = [a + r.shape[1] - int(b) for a, b in zip(self._missing, valid.sum(axis=1))]
        counts = [np.count_nonzero(r)] if self.m == 1 else np.count_nonzero(r, axis=1).tolist()
        self._repeats = [a + int(b) for a, b in zip(self._repeats, counts)]
        z = np.empty_like(r) if out is None else out
        if self.blocks < self.warmup_blocks:
            z[:] = 0.0  # the run's share is still being learned: no evidence either way
            return z
        np.multiply(r, self._span, out=z)  # r is 0 or 1: down + span for a repeat
        z += self._down
        if valid is not None:
            z[~valid] = 0.0
        return z

    def adapt(self, frozen: bool) -> None:
        """At a block boundary: move the run's share toward this block's (unless frozen), and start the next."""
        if not frozen or self.blocks < self.warmup_blocks:
            valid = [self._n - k for k in self._missing]
            if max(valid) >= self.min_valid:
                self.blocks += 1
                g = max(1.0 / self.blocks, self.gain)  # the running mean first, then the time constant
                self.p0 = [p + g * (k / v - p) if v >= self.min_valid else p
                           for p, k, v in zip(self.p0, self._repeats, valid)]
                self._levels()
        self._n = 0
        self._missing = [0] * self.m
        self._repeats = [0] * self.m


def neutral_share(p0: float, p1: float) -> float:
    """The repeat share at which the CUSUM's expected increment is zero (above it a stretch drifts upward)."""
    up, down = math.log(p1 / p0), math.log((1.0 - p0) / (1.0 - p1))
    return down / (up + down)
