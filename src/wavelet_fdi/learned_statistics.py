"""The learned detector's statistics: one registered class per kind, as the physics detector's are.

Every statistic of :class:`~wavelet_fdi.learned_detector.LearnedDetector` is a one-sided CUSUM of "value - k"
against a threshold h. A kind says which rows it watches (a channel and a band: D1..DJ, AJ, ``raw``, the channel's
reading itself, or ``R``, the reference's residual itself), its k and h (from
:class:`~wavelet_fdi.config.LearnedSettings`), and each block's values; a kind that adapts to the run (the
energy's run scale, the repeats' share) does so at the block's end, frozen while an alarm is up or one of its own
rows is above ``freeze_ratio`` of its threshold (a fault is not learned as the run's normal). The detector runs
every registered kind that has rows, in registration order
(the order of its statistics' names, alarms and traces).

A new statistic is one subclass of :class:`LearnedStatistic` decorated ``@register_learned_statistic`` (here or
in your own module); ``tests/learned/test_learned_statistic_recipe.py`` adds one in that file alone.

Examples
--------
>>> list(LEARNED_STATISTICS)
['mean', 'energy', 'energy_down', 'repeats', 'residual_mean', 'aj_energy']
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Any, ClassVar, Protocol

import numpy as np

from .repeat_test import RepeatTest
from .statistics import energy_decrease_reference, energy_reference

#: blocks of a run the run-adapted energy scale learns from (a running mean, never frozen) before the energy
#: CUSUMs look at it: 4 blocks of 32 samples estimate a variance to about 12 % (sqrt(2 / 128))
ENERGY_WARMUP_BLOCKS = 4
#: the repeats test's time constant for the run's repeat share when the energy test sets none (s)
REPEAT_TIME_CONSTANT_S = 120.0


class LearnedDetectorView(Protocol):
    """What a statistic reads of its detector (:class:`~wavelet_fdi.learned_detector.LearnedDetector`)."""

    settings: Any  # LearnedSettings
    m: int  # watched channels
    channels: tuple[str, ...]  # the watched (residual) channels
    inputs: tuple[str, ...]  # the rows' columns
    fill_samples: int  # samples before the filters are filled
    bias: np.ndarray  # (m,) the observer's estimate of each channel's healthy level, residual units


@dataclass
class Chunk:
    """What one ``process`` call of the detector computed for all its blocks."""

    a_raw: np.ndarray  # (n, m) AJ in residual units
    d_norm: np.ndarray  # (J, n, m) detail coefficients over their healthy sigma
    missing: np.ndarray  # (n, m)
    gappy: bool  # any sample missing
    residual: np.ndarray | None = None  # (n, m) the reference's residuals (healthy sigmas; 0 where missing)

    @cached_property
    def e2(self) -> np.ndarray:
        """(m*J, n) the detail bands' d^2, channel-major as the energy rows: once a chunk, for every kind."""
        n_bands, n, m = self.d_norm.shape
        return self.d_norm.transpose(2, 0, 1).reshape(m * n_bands, n) ** 2

    @cached_property
    def miss(self) -> np.ndarray:
        """(m*J, n) missing flags in the rows of :attr:`e2`."""
        return np.repeat(self.missing.T, self.d_norm.shape[0], axis=0)


@dataclass(frozen=True)
class StatisticRow:
    """One CUSUM: the watched channel (index into the detector's ``channels``), the band (index into its
    ``bands``: D1..DJ, AJ, raw) and the kind its name ends with (``CHANNEL.BAND.KIND``)."""

    channel: int
    band: int
    kind: str


class LearnedStatistic:
    """One kind of statistic of the learned detector, made for one detector (it may keep run state).

    Subclasses set :attr:`kind` and define :meth:`rows`, :meth:`reference_value`, :meth:`threshold` and
    :meth:`values`; :meth:`prepare` and :meth:`end_block` when the kind needs a whole chunk or adapts to the run.
    """

    kind: ClassVar[str] = ""
    #: its rows hold an alarm only while their channel's AJ deviation stays within ``clear_fraction`` of the
    #: episode's peak (a mean shift that came most of the way back does not hold it by a small offset)
    holds_by_level: ClassVar[bool] = False

    def __init__(self, detector: LearnedDetectorView) -> None:
        self.detector = detector
        self.settings = detector.settings

    def rows(self) -> list[StatisticRow]:
        """The CUSUMs of this kind, in order; none: the kind is off under these settings."""
        raise NotImplementedError

    def reference_value(self) -> float:
        """k: subtracted from every value (a value below k is evidence of health)."""
        raise NotImplementedError

    def threshold(self) -> float:
        """h, in the statistic's own units."""
        raise NotImplementedError

    def prepare(self, chunk: Chunk, rows: np.ndarray) -> None:
        """Once per ``process`` call, before its blocks: ``rows`` are the call's raw rows (inputs' order)."""

    def values(self, out: np.ndarray, chunk: Chunk, i0: int, i1: int, g0: int, u: np.ndarray) -> None:
        """Write the values of samples i0..i1 of the chunk (global index of i0: g0) into ``out`` (rows, i1 - i0);
        ``u`` (i1 - i0, m) is each channel's AJ deviation in healthy sigmas."""
        raise NotImplementedError

    def end_block(self, last_ratio: np.ndarray, in_alarm: bool) -> None:
        """At a block boundary: ``last_ratio`` is each of this kind's rows' S/h at the block's last sample."""


#: kind -> class, in the order the detector lists its statistics
LEARNED_STATISTICS: dict[str, type[LearnedStatistic]] = {}


def register_learned_statistic(cls: type[LearnedStatistic]) -> type[LearnedStatistic]:
    """Class decorator: the learned detector runs this kind (one kind, one class)."""
    if not cls.kind or cls.kind in LEARNED_STATISTICS:
        raise ValueError(f"learned statistic kind {cls.kind!r} is empty or already registered")
    LEARNED_STATISTICS[cls.kind] = cls
    return cls


@register_learned_statistic
class MeanShift(LearnedStatistic):
    """A mean shift of AJ, up (u - k) and down (-u - k) on every channel: k = ``mean_k``, h = ``mean_h``."""

    kind = "mean"
    holds_by_level = True

    def rows(self) -> list[StatisticRow]:
        return [StatisticRow(c, self.band(), direction) for c in range(self.detector.m)
                for direction in ("mean_up", "mean_down")]

    def band(self) -> int:
        """The band watched: AJ."""
        return self.settings.level

    def reference_value(self) -> float:
        return self.settings.mean_k

    def threshold(self) -> float:
        return self.settings.mean_h

    def deviation(self, chunk: Chunk, i0: int, i1: int, u: np.ndarray) -> np.ndarray:
        """(i1 - i0, m): each channel's deviation from its healthy level, in healthy sigmas."""
        return u

    def values(self, out, chunk, i0, i1, g0, u) -> None:
        d = self.deviation(chunk, i0, i1, u)
        out[0::2] = d.T
        out[1::2] = -d.T


@register_learned_statistic
class EnergyIncrease(LearnedStatistic):
    """A variance increase by ``energy_variance_ratio`` rho on every detail band (d^2 - k_e), against the run's own
    scale where ``energy_baseline_time_constant_s`` > 0 (robust: a sample counts at most rho)."""

    kind = "energy"

    def __init__(self, detector: LearnedDetectorView) -> None:
        super().__init__(detector)
        s = self.settings
        self.adapted = s.energy_variance_ratio > 1.0 and s.energy_baseline_time_constant_s > 0
        # the run-adapted scale per (channel, detail band), channel-major as the rows, in calibrated variances
        self.scale = np.ones(detector.m * s.level)
        # this block's d^2 (0 where not used) and which were used, by position in the block: summed once at its
        # boundary, so any chunking sums the same numbers in the same order
        self._e2_block = np.zeros((detector.m * s.level, s.block_samples))
        self._e2_used = np.zeros((detector.m * s.level, s.block_samples))  # 1.0: used
        self.blocks = 0  # blocks the scale has learned from

    def rows(self) -> list[StatisticRow]:
        s = self.settings
        if not s.energy_variance_ratio > 1.0:
            return []
        return [StatisticRow(c, j, "energy") for c in range(self.detector.m) for j in range(s.level)]

    def reference_value(self) -> float:
        return energy_reference(self.settings.energy_variance_ratio)

    def threshold(self) -> float:
        return self.settings.energy_h

    def values(self, out, chunk, i0, i1, g0, u) -> None:
        e2, miss = chunk.e2[:, i0:i1], chunk.miss[:, i0:i1]  # a missing sample is healthy
        e2_up = self._against_run_scale(e2, miss if chunk.gappy else None, g0) if self.adapted else e2
        out[:] = np.where(miss, 0.0, e2_up) if chunk.gappy else e2_up

    def _against_run_scale(self, e2: np.ndarray, miss: np.ndarray | None, g0: int) -> np.ndarray:
        """The detail bands' d^2 against the run's own scale, and robust: a sample counts at most as the design
        variance ratio rho (one outlier moves the CUSUM by at most rho - k; a noisier probe keeps adding). Adds the
        samples to the block's sums the scale learns from (``miss``: None, none missing)."""
        s = self.settings
        fill = self.detector.fill_samples
        at = g0 % s.block_samples  # a call never crosses a block boundary
        nb = e2.shape[1]
        if miss is None and g0 >= fill:  # every sample used (the usual case: fewer numpy calls)
            self._e2_block[:, at:at + nb] = e2
            self._e2_used[:, at:at + nb] = 1.0
        else:
            used = np.ones_like(e2, dtype=bool) if miss is None else ~miss
            if g0 < fill:
                used = used & (g0 + np.arange(nb) >= fill)
            self._e2_block[:, at:at + nb] = np.where(used, e2, 0.0)
            self._e2_used[:, at:at + nb] = used
        if self.blocks < ENERGY_WARMUP_BLOCKS:  # the run's scale is still being learned
            return np.full_like(e2, self.reference_value())  # no evidence either way
        return np.minimum(e2 / self.scale[:, None], s.energy_variance_ratio)

    def end_block(self, last_ratio: np.ndarray, in_alarm: bool) -> None:
        """Move each band's scale toward the block's mean d^2 (the running mean over the first blocks, then gain
        block time / time constant), unless frozen. Kept within the design variance ratio rho of the calibrated
        scale (1/rho..rho): a probe noisy from the start is still compared with the healthy runs, and a quantised
        plateau, whose detail bands read zero, does not make the next healthy sample a variance ratio without
        bound."""
        s = self.settings
        if not self.adapted:
            return
        if self.blocks >= ENERGY_WARMUP_BLOCKS and (in_alarm or last_ratio.max() > s.freeze_ratio):
            return  # frozen (the block's arrays are overwritten by the next block: every position is written)
        n_used = self._e2_used.sum(axis=1)  # few small numpy calls: this runs every block (the rig's 1e5 samples/s)
        half = max(1, s.block_samples // 2)
        if n_used.max() < half:
            return
        self.blocks += 1
        gain = max(1.0 / self.blocks, min(1.0, s.block_samples * s.sample_time_s / s.energy_baseline_time_constant_s))
        scale = self.scale
        new = scale + gain * (self._e2_block.sum(axis=1) / np.maximum(n_used, 1.0) - scale)
        if n_used.min() < half:  # a band mostly missing in this block keeps its scale
            new = np.where(n_used >= half, new, scale)
        rho = s.energy_variance_ratio
        self.scale = np.minimum(np.maximum(new, 1.0 / rho), rho)


@register_learned_statistic
class EnergyDecrease(LearnedStatistic):
    """A variance decrease to ``energy_down_variance_ratio`` rho < 1 on every detail band: the log-likelihood ratio
    k - d^2 with k = ln(1/rho) / (1/rho - 1), kept as value -d^2 minus reference -k (every row is "value - k")."""

    kind = "energy_down"

    def rows(self) -> list[StatisticRow]:
        s = self.settings
        if not 0.0 < s.energy_down_variance_ratio < 1.0:
            return []
        return [StatisticRow(c, j, "energy_down") for c in range(self.detector.m) for j in range(s.level)]

    def reference_value(self) -> float:
        return -energy_decrease_reference(self.settings.energy_down_variance_ratio)

    def threshold(self) -> float:
        return self.settings.energy_down_h

    def values(self, out, chunk, i0, i1, g0, u) -> None:
        e2 = chunk.e2[:, i0:i1]
        out[:] = np.where(chunk.miss[:, i0:i1], -1.0, -e2) if chunk.gappy else -e2


@register_learned_statistic
class Repeats(LearnedStatistic):
    """Readings that repeat more often than the run's own share (a frozen or stuck transmitter): one CUSUM per
    watched channel that is a column of the rows (:class:`~wavelet_fdi.repeat_test.RepeatTest`), on ``raw``."""

    kind = "repeats"

    def __init__(self, detector: LearnedDetectorView) -> None:
        super().__init__(detector)
        s = self.settings
        self.watched = [c for c, ch in enumerate(detector.channels) if ch in detector.inputs]
        self.columns = [detector.inputs.index(detector.channels[c]) for c in self.watched]
        self.test: RepeatTest | None = None
        if s.repeat_probability > 0.0 and self.watched:
            tau = s.energy_baseline_time_constant_s or REPEAT_TIME_CONSTANT_S
            gain = min(1.0, s.block_samples * s.sample_time_s / tau)
            self.test = RepeatTest(len(self.watched), s.repeat_probability, ENERGY_WARMUP_BLOCKS, gain,
                                   min_valid=max(1, s.block_samples // 2))
        self._indicators: np.ndarray | None = None

    def rows(self) -> list[StatisticRow]:
        if self.test is None:
            return []
        return [StatisticRow(c, self.settings.level + 1, "repeats") for c in self.watched]

    def reference_value(self) -> float:
        return 0.0  # the increments are the log-likelihood ratios themselves

    def threshold(self) -> float:
        return self.settings.repeat_h

    def prepare(self, chunk, rows) -> None:
        assert self.test is not None, "prepared only when on"
        self._indicators = self.test.indicators(rows[:, self.columns])

    def values(self, out, chunk, i0, i1, g0, u) -> None:
        assert self.test is not None and self._indicators is not None, "prepared before its blocks"
        self.test.increments(self._indicators[:, i0:i1], out=out)

    def end_block(self, last_ratio: np.ndarray, in_alarm: bool) -> None:
        assert self.test is not None, "called only when on"
        self.test.adapt(in_alarm or max(last_ratio.tolist()) > self.settings.freeze_ratio)


@register_learned_statistic
class ResidualMean(MeanShift):
    """A mean shift of the residual itself, not of a band, up and down on every channel, less the observer's level:
    the physics detector's R statistic. AJ's mean is a local mean over about 2^J samples that lags a step by about
    as much; the residual's own mean sees it at once, at the price of its full noise. k = ``residual_mean_k`` in the
    residual's healthy sigmas (half the shift it is designed for; 0: off), h = ``residual_mean_h``."""

    kind = "residual_mean"

    def rows(self) -> list[StatisticRow]:
        return super().rows() if self.settings.residual_mean_k else []

    def band(self) -> int:
        """The band watched: R, after D1..DJ, AJ and raw."""
        return self.settings.level + 2

    def reference_value(self) -> float:
        return self.settings.residual_mean_k

    def threshold(self) -> float:
        return self.settings.residual_mean_h

    def deviation(self, chunk: Chunk, i0: int, i1: int, u: np.ndarray) -> np.ndarray:
        assert chunk.residual is not None, "the detector passes its residuals"
        r = chunk.residual[i0:i1] - self.detector.bias
        return np.where(chunk.missing[i0:i1], 0.0, r) if chunk.gappy else r


@register_learned_statistic
class ApproximationEnergy(LearnedStatistic):
    """A variance increase by ``aj_energy_variance_ratio`` rho of AJ on every channel (u^2 - k, u its deviation from
    the observer's level in healthy sigmas of AJ, k = ln(rho) / (1 - 1/rho)): the physics detector's energy of the
    approximation band. AJ's mean CUSUMs see a shift that stays on one side; a slow change that swings both ways
    (a probe whose lag grows lets the slow residual swing wider with every setpoint move) leaves them near zero and
    raises this. k as the detail bands' energy; h = ``aj_energy_h``. It reads AJ's level, as the mean statistics do,
    so it is held by that level as they are (``clear_fraction``): a channel that came most of the way back does not
    hold an alarm by the small offset an observer learned while it was up."""

    kind = "aj_energy"
    holds_by_level = True

    def rows(self) -> list[StatisticRow]:
        if not self.settings.aj_energy_variance_ratio > 1.0:
            return []
        return [StatisticRow(c, self.settings.level, self.kind) for c in range(self.detector.m)]

    def reference_value(self) -> float:
        return energy_reference(self.settings.aj_energy_variance_ratio)

    def threshold(self) -> float:
        return self.settings.aj_energy_h

    def values(self, out, chunk, i0, i1, g0, u) -> None:
        out[:] = (u * u).T  # u is 0 where a sample is missing: it reads healthy
