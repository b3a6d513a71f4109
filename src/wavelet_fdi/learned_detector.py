"""Multichannel wavelet-CUSUM detector on the residuals of a learned healthy reference (ROS-free core).

Per sample, for every channel c of a measured record (docs/detector.md, "Measured data"):

1. the learned reference (:mod:`wavelet_fdi.reference_learned`) predicts x_c from its own
   past and the other channels; r_c = residual in healthy standard deviations;
2. a causal stationary wavelet transform (:class:`~wavelet_fdi.filterbank.CausalSwt`,
   PyWavelets filters) splits r_c into detail bands D1..DJ and the approximation AJ;
3. a slow observer removes what is left of the channel's drift from AJ: a bias
   b_c, corrected every ``block_samples`` by ``block_samples / observer_time_constant_s``
   of the block's mean deviation, frozen while an alarm is up or any statistic is above
   ``freeze_ratio`` of its threshold (a fault is not learned as the new healthy);
4. every band is divided by its healthy RMS (measured on the healthy rows,
   :func:`calibrate`): u = AJ deviation, d_j = D_j coefficient;
5. one-sided CUSUMs (:class:`~wavelet_fdi.statistics.CusumBank`) of every registered kind
   (:mod:`wavelet_fdi.learned_statistics`): mean up (u - k) and down (-u - k) on AJ, and, if
   enabled, energy up (d_j^2 - k_e) and down on each detail band and repeated readings;
   an alarm is raised when one crosses its threshold h (in healthy sigmas);
6. while the alarm is up the CUSUMs restart at every block boundary, so they measure
   whether the fault is still there (not how long it has been); the alarm clears once a
   full ``block_samples`` has passed without a crossing. Every alarm names the channels
   and bands that carry it: each statistic's S/h at the detection (its share of the sum)
   and, when it clears, over the whole episode.

Any chunking of a record gives the same residuals, statistics, states and events: the
observer and the restarts act at fixed global sample indices, every recursion runs left
to right. Bad rows: a missing value (NaN) of a channel counts as healthy for its
statistics and is reported once per stretch (an ``input`` event); the record reader
(:mod:`phfdi.records`) is where text cells and broken files are refused.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace
from functools import partial
from pathlib import Path
from typing import Sequence

import numpy as np
import numpy.typing as npt

from phfdi_base.errors import UserError

from .calibration import excess_tail_threshold, tail_threshold, window_maxima
from .config import ARL_WINDOW_SAMPLES, CALIBRATION_DIR, LEARNED_FORMS, LearnedSettings  # noqa: F401  (LearnedSettings also imported from here)
from .feed_checks import FeedCheck, FeedChecks
from .feed_checks import level as feed_level
from .filterbank import CausalSwt
from .healthy_range import checked_ranges, healthy_ranges, outside_masks
from .learned_statistics import LEARNED_STATISTICS, Chunk, LearnedStatistic, Repeats
from .reference_learned import LearnedReference, load_json, save_json
from .reference_oe import OutputErrorReference
from .references import LOOKS, NAMERS, Reference, reference_from_dict
from .repeat_test import RepeatTest
from .spike_checks import Spike, SpikeChecks
from .statistics import CusumBank, parse_statistic

FORMAT = "phfdi-learned-detector/1"
TIME_RING = 1 << 16
NAMING_RING = 1 << 13  # rows kept for naming an alarm's fault (about 48 min at the rig's 0.35 s)
#: a longer chunk is processed in parts of this many rows (the same events: any chunking gives them), so that the
#: ring, filled with a part's rows before its blocks run, still holds every row a naming window reaches back to
MAX_PART_ROWS = 1024
NAMING_WINDOW = NAMING_RING - MAX_PART_ROWS
NAMING_AFTER = 64  # samples after a detection that the naming window takes in


@dataclass
class LearnedModel:
    """What ``phfdi calibrate --learn`` writes: the reference, the healthy band sigmas, the settings.

    Made by :func:`learn`; saved and read as JSON.

    Examples
    --------
    >>> import numpy as np
    >>> from wavelet_fdi import learn
    >>> healthy = np.random.default_rng(1).normal(size=(4000, 2))
    >>> model = learn(healthy, ["flow", "pressure"])
    >>> model.channels, model.band_sigma.shape  # channels x (D1, D2, A2)
    (('flow', 'pressure'), (2, 3))
    """

    reference: Reference  # any kind of wavelet_fdi.references
    settings: LearnedSettings
    #: healthy RMS per residual channel (rows) and band (columns D1..DJ, AJ), residual-sigma units
    band_sigma: np.ndarray
    source: dict = field(default_factory=dict)
    #: thresholds measured for ``settings.arl0_samples`` (:func:`calibrate_bands`), by statistic name; a statistic
    #: not here keeps its declared threshold
    thresholds: dict = field(default_factory=dict)

    @property
    def channels(self) -> tuple[str, ...]:
        """The record's channels the reference reads."""
        return self.reference.channels

    @property
    def residual_channels(self) -> tuple[str, ...]:
        """The channels the detector watches (each with its bands and statistics)."""
        return self.reference.residual_channels

    def to_dict(self) -> dict:
        return {"format": FORMAT, "settings": asdict(self.settings), "reference": self.reference.to_dict(),
                "band_sigma": {c: dict(zip(self.settings.bands(), map(float, row)))
                               for c, row in zip(self.residual_channels, self.band_sigma)},
                "source": self.source, **({"thresholds": dict(self.thresholds)} if self.thresholds else {})}

    def save(self, path: str | Path, overwrite: bool = True) -> None:
        save_json(path, self.to_dict(), overwrite)

    @classmethod
    def load(cls, path: str | Path) -> "LearnedModel":
        """A reference file, or the name of one shipped with the detector when no such file exists
        (:func:`shipped_reference_path`: ``paper_physics``, the paper loop's physics kind)."""
        shipped = shipped_reference_path(str(path)) if not Path(path).exists() else None
        if shipped is None and not Path(path).exists():
            names = sorted(f.stem for f in CALIBRATION_DIR.glob("*.json"))
            raise UserError(f"{path}: no such reference file (shipped, by name: {', '.join(names) or 'none'}; "
                            f"make one with phfdi calibrate: --learn, --estimator, or a physics reference without either)")
        d = load_json(shipped or path, FORMAT)
        return cls.from_dict(d, str(path))

    @classmethod
    def from_dict(cls, d: dict, where: str = "model") -> "LearnedModel":
        settings = LearnedSettings.from_dict(dict(d.get("settings") or {}))
        ref = reference_from_dict(d.get("reference") or {}, where)
        try:
            bs = d["band_sigma"]
            sigma = np.array([[float(bs[c][b]) for b in settings.bands()] for c in ref.residual_channels])
        except (KeyError, TypeError, ValueError) as exc:
            raise UserError(f"{where}: band_sigma missing or incomplete ({exc})") from None
        if not (np.all(np.isfinite(sigma)) and np.all(sigma > 0)):
            raise UserError(f"{where}: band_sigma must be positive numbers")
        source = dict(d.get("source") or {})
        if "healthy_ranges" in source:  # kept since 2026-11-29; a file from before has none
            source["healthy_ranges"] = checked_ranges(source["healthy_ranges"], f"{where}: source.healthy_ranges")
        return cls(ref, settings, sigma, source, _checked_thresholds(d.get("thresholds") or {}, where))


def shipped_reference_path(name: str) -> Path | None:
    """The reference file shipped under this name (``wavelet_fdi/calibrations/<name>.json``), None if there is none.
    Shipped: ``paper_physics`` (``phfdi calibrate --scenario paper``: the paper loop's healthy plant and
    valves, thresholds measured on the healthy runs of seeds 1001-1016 for the physics detector's design).

    >>> shipped_reference_path("paper_physics").name, shipped_reference_path("my_plant.json")
    ('paper_physics.json', None)
    """
    if not name or Path(name).name != name or name.endswith(".json"):
        return None  # a path: the caller's file, not a shipped name
    path = CALIBRATION_DIR / f"{name}.json"
    return path if path.is_file() else None


def _checked_thresholds(d: dict, where: str) -> dict[str, float]:
    """A model file's measured thresholds: statistic name -> a positive number."""
    try:
        out = {str(k): float(v) for k, v in dict(d).items()}
    except (TypeError, ValueError) as exc:
        raise UserError(f"{where}: thresholds must map statistic names to numbers ({exc})") from None
    bad = sorted(k for k, v in out.items() if not (math.isfinite(v) and v > 0))
    if bad:
        raise UserError(f"{where}: threshold of {bad[0]} must be a positive number")
    return out


def fit_reference(x_healthy: np.ndarray, channels: Sequence[str], settings: LearnedSettings) -> Reference:
    """The learned reference of ``settings.form`` fitted on healthy rows (n, m)."""
    s = settings
    if s.form == "oe":
        return OutputErrorReference.fit(x_healthy, channels, s.lags, s.ridge_own, s.ridge_cross,
                                        s.correction_samples)
    return LearnedReference.fit(x_healthy, channels, s.lags, s.ridge_own, s.ridge_cross)


def learn(x_healthy: np.ndarray, channels: Sequence[str], settings: LearnedSettings | None = None,
          source: dict | None = None) -> LearnedModel:
    """Fit the reference on healthy rows and measure each band's healthy RMS on the same rows.

    Parameters
    ----------
    x_healthy : ndarray (n, m)
        Rows of a healthy record, one column per channel, sampled every ``settings.sample_time_s``.
    channels : sequence of str
        The m channel names.
    settings : LearnedSettings, optional
    source : dict, optional
        What the rows came from (kept in the model).

    Returns
    -------
    LearnedModel

    Raises
    ------
    UserError
        Too few rows to calibrate the bands.

    Examples
    --------
    >>> import numpy as np
    >>> from wavelet_fdi import learn
    >>> model = learn(np.random.default_rng(1).normal(size=(4000, 2)), ["flow", "pressure"])
    >>> model.source["healthy_rows"]
    4000
    """
    s = (settings or LearnedSettings()).check()
    ref = fit_reference(x_healthy, channels, s)
    src = {"healthy_rows": int(len(x_healthy)), **(source or {})}
    return calibrate_bands(ref, [(np.arange(len(x_healthy)) * s.sample_time_s, x_healthy)], s, src)


def calibrate_bands(reference: Reference, runs: Sequence[tuple[np.ndarray, np.ndarray]],
                    settings: LearnedSettings, source: dict | None = None,
                    run_references: Sequence[Reference] | None = None) -> LearnedModel:
    """A detector model for ``reference``: each residual band's healthy RMS measured on healthy runs.

    Every run (time_s, rows in ``reference.channels`` order) goes through a fresh detector; the bands
    after each run's warm-up are pooled. Works for every reference kind (:mod:`wavelet_fdi.references`).
    ``run_references``: the reference each run's residuals come from (one per run; e.g. each fitted without
    its run, so that the bands measure what a day the reference has not seen looks like); default
    ``reference`` for all. The source keeps each channel's healthy range (``healthy_ranges``,
    :mod:`wavelet_fdi.healthy_range`).
    """
    source = {**(source or {}), "healthy_ranges": healthy_ranges([rows for _, rows in runs], reference.channels)}
    s = settings.check()
    m = len(reference.residual_channels)
    refs = list(run_references) if run_references is not None else [reference] * len(runs)
    if len(refs) != len(runs):
        raise ValueError(f"{len(refs)} run references for {len(runs)} runs")
    pooled = []
    for (t, rows), ref in zip(runs, refs):
        provisional = LearnedModel(ref, s, np.ones((m, s.level + 1)), dict(source or {}))
        det = LearnedDetector(provisional, alarms=False, record_trace=True)
        det.process(t, rows)
        pooled.append(det.trace()["coef"][det.fill_samples:])  # (n, m, J+1), AJ already observer-corrected
    coef = np.concatenate(pooled) if pooled else np.empty((0, m, s.level + 1))
    fill = LearnedDetector(LearnedModel(reference, s, np.ones((m, s.level + 1)))).fill_samples
    if len(coef) < 8 * s.block_samples:
        rows_in = sum(len(r) for _, r in runs)
        raise UserError(f"the healthy part has {rows_in} rows; calibrating the bands needs at least "
                        f"{fill + 8 * s.block_samples} after each run's first {fill} "
                        f"(more rows, a lower level or smaller blocks)")
    coef = np.where(np.isfinite(coef), coef, np.nan)
    sigma = np.sqrt(np.nanmean(coef ** 2, axis=0))
    sigma = np.where(np.isfinite(sigma) & (sigma > 1e-9), sigma, 1.0)
    if s.spike_per_sample > 0:
        s = replace(s, spike_sigma=measured_spike_level(runs, refs, s.spike_per_sample))
    model = LearnedModel(reference, s, sigma, dict(source or {}))
    if s.arl0_samples > 0:
        model.thresholds = measured_thresholds(model, runs, refs)
    return model


def measured_thresholds(model: LearnedModel, runs: Sequence[tuple[np.ndarray, np.ndarray]],
                        run_references: Sequence[Reference]) -> dict[str, float]:
    """Each statistic's threshold for the model's false-alarm target (``settings.arl0_samples``), measured on the
    healthy runs as the physics detector's calibration measures its own (:mod:`wavelet_fdi.calibration`): every
    run through the calibrated detector (no alarms), each statistic's increments after the warm-up cut into
    windows of :data:`~wavelet_fdi.config.ARL_WINDOW_SAMPLES` with a CUSUM restarted in each, an exponential fit
    to the upper tail of the windows' maxima, and h where P(max > h) = window / (ARL0 x the number of
    statistics): an alarm of any statistic within a window has probability about window / ARL0 (Bonferroni,
    conservative where the statistics are correlated). A statistic whose CUSUM stays at zero in most healthy
    windows has no tail to fit and keeps its declared threshold (it is then not part of the stated rate). Needs 8
    windows' worth of healthy rows after the warm-ups."""
    s = model.settings
    per_stat: list[list[np.ndarray]] = []
    for (t, rows), ref in zip(runs, run_references):
        det = LearnedDetector(LearnedModel(ref, s, model.band_sigma, model.source), alarms=False, record_trace=True)
        det.process(t, rows)
        z = det.trace()["increments"][det.fill_samples:]
        if not per_stat:
            per_stat = [[] for _ in det.stat_names]
            names = det.stat_names
        for j in range(len(names)):
            per_stat[j].append(window_maxima(z[:, j], ARL_WINDOW_SAMPLES))
    windows = sum(len(m) for m in per_stat[0]) if per_stat else 0
    if windows < 8:
        raise UserError(f"arl0_samples {s.arl0_samples:g}: measuring the thresholds needs at least 8 windows of "
                        f"{ARL_WINDOW_SAMPLES} healthy rows after the runs' warm-ups, these runs give {windows} "
                        "(more or longer healthy runs, or arl0_samples 0 for the declared thresholds)")
    p_target = ARL_WINDOW_SAMPLES / (s.arl0_samples * len(per_stat))
    out = {}
    for name, parts in zip(names, per_stat):
        maxima = np.concatenate(parts)
        if np.count_nonzero(maxima > 0.0) < len(maxima) / 2:
            # the statistic stays at zero in most healthy windows (its k is far above the healthy values): no tail
            # to fit, and a threshold from the few nonzero maxima would make it fire on one sample; it keeps its
            # declared threshold
            continue
        out[name] = tail_threshold(maxima, p_target).threshold
    return out


def measured_spike_level(runs: Sequence[tuple[np.ndarray, np.ndarray]], run_references: Sequence[Reference],
                         per_sample: float) -> float:
    """The spike checks' level (:mod:`wavelet_fdi.spike_checks`): the residual magnitude a healthy sample exceeds
    with probability ``per_sample``, measured on every run's residuals from its reference (before the reference's
    limit where it has one): the empirical 90th percentile u and beyond it an exponential tail with the mean
    excess as its scale, never below half a sigma, as the estimator's confirmation margins are placed
    (:func:`~wavelet_fdi.calibration.excess_tail_threshold`)."""
    values: list[np.ndarray] = []
    for (t, rows), ref in zip(runs, run_references):
        stream = ref.new_state()
        r = stream.residuals(t, rows)
        r = getattr(stream, "last_unlimited", r)
        values.append(np.abs(r[np.isfinite(r)]))
    v = np.concatenate(values) if values else np.empty(0)
    try:
        return float(excess_tail_threshold(v.tolist(), per_sample)["threshold"])
    except ValueError as exc:
        raise UserError(f"spike_per_sample {per_sample:g}: {exc}") from None


@dataclass
class LearnedEvent:
    """A state change: a fault alarm raised or cleared, a deviation being checked or found outside calibration,
    or an input problem.

    Kinds: ``alarm`` (ERROR: a fault; with a confirming reference, the fault hypothesis beat healthy operation
    re-adapted), ``deviation`` (WARN: a statistic crossed its threshold, a confirming reference checks over
    the next samples whether a fault explains it), ``outside_calibration`` (WARN: none does: the plant runs
    where the calibration never went, or the model misses something), ``named`` (the name of an alarm of a
    reference that names but does not confirm), ``cleared`` (OK), ``input`` (WARN). ``announce`` False: a
    repeat within ``outside_hold_s`` of the last deviation outside calibration, kept but not to be shown as a
    new state (the detector node does not publish it).
    """

    kind: str
    time_s: float
    index: int
    level: str  # "OK" | "WARN" | "ERROR"
    message: str
    alarm: dict | None = None
    announce: bool = True


class LearnedDetector:
    """Feed rows of a measured record in time order; get events (and per-row alarm states) back.

    ``alarms`` False: statistics only (calibration runs); ``name_faults`` False: alarms are raised and cleared but
    no fault is named (a reference that names faults does not; one that confirms them raises plain alarms).

    Examples
    --------
    >>> import numpy as np
    >>> from wavelet_fdi import LearnedDetector, learn
    >>> rows = np.random.default_rng(1).normal(size=(6000, 2))
    >>> detector = LearnedDetector(learn(rows[:4000], ["flow", "pressure"]))
    >>> faulty = rows[4000:].copy()
    >>> faulty[1000:, 0] += 3.0  # the flow shifts by three standard deviations
    >>> events, states = detector.process(np.arange(2000.0), faulty)
    >>> [(e.kind, e.index > 1000) for e in events], int(states[-1])
    ([('alarm', True)], 1)
    """

    def __init__(self, model: LearnedModel, alarms: bool = True, record_trace: bool = False,
                 name_faults: bool = True) -> None:
        self.model = model
        self.settings = s = model.settings.check()
        self.inputs = model.channels  # what the rows hold
        self.channels = model.residual_channels  # what is watched
        m = len(self.channels)
        self.m = m
        self.stream = model.reference.new_state()
        self.swt = CausalSwt(s.wavelet, s.level, channels=m)
        self.gain = 2.0 ** (s.level / 2.0)  # DC gain of AJ
        self.fill_samples = self.swt.fill_samples + model.reference.lags
        # "raw": a statistic on the channel's reading itself; "R": on the reference's residual itself
        self.bands = s.bands() + ["raw", "R"]
        self._init_statistics(s, m)
        self._measured_thresholds(model)
        self.alarms_enabled = alarms
        self.bias = np.zeros(m)
        self._acc = np.zeros(m)
        self._acc_n = 0
        self.in_alarm = False
        self._last_crossing = -1
        self._holdoff = False  # an alarm cleared in this block: no new one before the next block boundary
        self._peak = np.zeros(m)  # per channel, the largest |AJ deviation| of the alarm so far
        self._rebase = 0  # 1: an alarm cleared in this block; 2: learning the new level over this block
        self._alarm: dict | None = None
        self._episode = np.zeros(len(self.stat_names))
        self.alarms: list[dict] = []
        self._missing_open = np.zeros(m, dtype=bool)
        self._missing_since = np.zeros(m, dtype=np.int64)  # global index where each open missing stretch began
        self._stream_holds = False  # the reference stream held detection at the last row (its notices say why)
        self.samples_processed = 0
        self._last_t = math.nan  # the last row's time, residuals and statistics over thresholds (monitor)
        self._last_residual = np.full(m, np.nan)
        self._last_ratio = np.zeros(len(self.stat_names))
        self._times = np.full(TIME_RING, np.nan)  # times of the last TIME_RING samples (onset times)
        self._trace: dict[str, list] | None = ({"coef": [], "stat": [], "state": [], "increments": [],
                                                "residual": []}
                                               if record_trace else None)
        self._init_naming(model, alarms and name_faults)

    def _init_statistics(self, s: LearnedSettings, m: int) -> None:
        """The CUSUM statistics: every registered kind that has rows under these settings
        (:mod:`wavelet_fdi.learned_statistics`), each row "value - k" against its threshold h."""
        self.statistics: list[LearnedStatistic] = []
        self._slices: list[slice] = []
        names: list[str] = []
        k: list[float] = []
        h: list[float] = []
        chan: list[int] = []
        band: list[int] = []
        by_level: list[bool] = []
        for cls in LEARNED_STATISTICS.values():
            stat = cls(self)
            rows = stat.rows()
            if not rows:
                continue
            self.statistics.append(stat)
            self._slices.append(slice(len(names), len(names) + len(rows)))
            for r in rows:
                names.append(f"{self.channels[r.channel]}.{self.bands[r.band]}.{r.kind}")
                chan.append(r.channel)
                band.append(r.band)
            k += [stat.reference_value()] * len(rows)
            h += [stat.threshold()] * len(rows)
            by_level += [stat.holds_by_level] * len(rows)
        self.stat_names = names
        self.k = np.array(k)
        self.h = np.array(h)
        self.stat_channel = np.array(chan, dtype=int)
        self.stat_band = np.array(band, dtype=int)
        self._by_level = np.flatnonzero(by_level)  # rows held by their channel's level (clear_fraction)
        self.cusum = CusumBank(len(names))

    def _measured_thresholds(self, model: LearnedModel) -> None:
        """The thresholds the model measured for its false-alarm target replace the declared ones."""
        unknown = sorted(set(model.thresholds) - set(self.stat_names))
        if unknown:
            raise UserError(f"the model has a threshold for {unknown[0]}, a statistic these settings do not run")
        for i, name in enumerate(self.stat_names):
            if name in model.thresholds:
                self.h[i] = float(model.thresholds[name])

    @property
    def repeats(self) -> RepeatTest | None:
        """The repeats test (None: off)."""
        return next((st.test for st in self.statistics if isinstance(st, Repeats)), None)

    def _init_naming(self, model: LearnedModel, alarms: bool) -> None:
        """The namer, its rings of recent rows, the confirmation state and the healthy runs' ranges."""
        # a reference that can name the fault behind an alarm (wavelet_fdi.references: ``name_fault``) gets the
        # last NAMING_RING rows and, NAMING_AFTER samples after each detection, names it (a "named" event)
        namer = NAMERS.get(getattr(model.reference, "kind", ""))
        self.namer = partial(namer, model.reference) if namer is not None and alarms else None
        self._ring_t = np.full(NAMING_RING, np.nan) if self.namer else np.empty(0)
        self._ring_x = np.full((NAMING_RING, len(self.inputs)), np.nan) if self.namer else np.empty((0, 0))
        self._to_name: list[dict] = []
        self._named: list[int] = []
        # a deviation not confirmed that stays up is looked at again with more rows after its detection (the
        # reference's looks; its confirmation has a margin for each): the ones waiting for their next look
        looks = LOOKS.get(getattr(model.reference, "kind", ""))
        # samples after a detection the first naming waits for: the reference's own (a stick-slip shows over a few
        # controller cycles) or NAMING_AFTER
        self._naming_after = int(getattr(model.reference, "naming_after_samples", NAMING_AFTER))
        self._looks: tuple[int, ...] = (tuple(looks(model.reference)) if looks and self.namer
                                        else (self._naming_after,))
        self._relook: list[dict] = []
        # a confirming reference (its namer says whether a fault explains an alarm): alarms start as deviations
        self.confirming = self.namer is not None and bool(getattr(model.reference, "confirm", None))
        # names made at the row they are due (not at the next block boundary): see _naming_due
        self._exact_naming = (self.namer is not None and not self.confirming
                              and self._naming_after >= model.settings.block_samples)
        # a confirming reference's spikes (one innovation beyond spike_sigma, before the reference's limit) are each
        # judged once as a step of the reading (wavelet_fdi.spike_checks)
        self.spikes = SpikeChecks(model.settings.spike_sigma if self.confirming else 0.0, self._naming_after)
        # a confirming reference that knows its feeds' directions: a reading moving against the only feed that runs
        # is judged once as a probe offset or drift (wavelet_fdi.feed_checks)
        directions = getattr(model.reference, "feed_directions", None)
        per_sample = model.settings.against_feed_per_sample
        self.feed_checks = FeedChecks(feed_level(per_sample) if self.confirming and directions and per_sample > 0
                                      else 0.0, tuple(directions or ()), self._naming_after)
        self._feed_fault_stretch: tuple[int, float] | None = None  # the feed stretch a confirmed crossing was in
        self._last_outside_t = -math.inf  # the last deviation outside calibration (the announcements' hold)
        # per channel the last sample beyond the healthy runs' range (an alarm whose window holds one says so)
        self._ranges = model.source.get("healthy_ranges") or {}
        self._last_outside: dict[str, int] = {}

    # ---- public API ------------------------------------------------------------------
    def process(self, t_s: npt.ArrayLike, x: npt.ArrayLike) -> tuple[list[LearnedEvent], np.ndarray]:
        """Rows x (n, m) at times t_s; returns the events and the alarm state (0/1) of each row."""
        rows = np.asarray(x, dtype=float)
        t = np.asarray(t_s, dtype=float)
        if rows.ndim != 2 or rows.shape[1] != len(self.inputs):
            raise UserError(f"expected rows x {len(self.inputs)} channels ({', '.join(self.inputs)}), "
                            f"got shape {rows.shape}")
        if len(t) != len(rows):
            raise UserError(f"{len(t)} time stamps for {len(rows)} rows")
        if len(rows) > MAX_PART_ROWS and self.namer is not None:
            parts = [self.process(t[a:a + MAX_PART_ROWS], rows[a:a + MAX_PART_ROWS])
                     for a in range(0, len(rows), MAX_PART_ROWS)]
            return [e for ev, _ in parts for e in ev], np.concatenate([st for _, st in parts])
        events: list[LearnedEvent] = []
        states = np.zeros(len(rows), dtype=np.int8)
        if not len(rows):
            return events, states
        g = self.samples_processed + np.arange(len(rows))
        self._times[g % TIME_RING] = t
        r = self.stream.residuals(t, rows)
        if self.spikes.level:
            self.spikes.scan(getattr(self.stream, "last_unlimited", r), t, self.samples_processed, self.fill_samples)
        if self.feed_checks.level:
            self.feed_checks.scan(t, rows, self.samples_processed, self.fill_samples)
        self._last_t, self._last_residual = float(t[-1]), r[-1].copy()
        missing = ~np.isfinite(r)
        held = getattr(self.stream, "last_held", None)  # rows the reference held by its own rule (its notices say why)
        events += self._stream_notices(t)
        events += self._missing_events(missing if held is None else missing & ~held[:, None], t)
        events += self._hold_events(t)
        out = self.swt.process(np.where(missing, 0.0, r))
        details, approx = out.details, out.approx  # (J, n, m), (n, m)
        sig = self.model.band_sigma  # (m, J+1)
        d_norm = details / sig[:, :-1].T[:, None, :]  # (J, n, m)
        a_raw = approx / self.gain  # AJ in residual units (DC gain removed)
        b = self.settings.block_samples
        n = len(rows)
        chunk = Chunk(a_raw, d_norm, missing, bool(missing.any()), np.where(missing, 0.0, r))
        for stat in self.statistics:
            stat.prepare(chunk, rows)
        if self.namer is not None:
            self._keep(t, rows)
        pos = 0
        while pos < n:
            done = self.samples_processed + pos  # rows processed so far: blocks are aligned to them
            due = self._naming_due()
            if self.namer is not None and (done % b == 0 or (due is not None and due <= done)):
                # alarms whose naming window ended by this block boundary (or, see _naming_due, at this very row)
                # are named (confirmed or not) before the rows after it run: at global indices, so that any
                # chunking names them, and decides the announcement of a later deviation, in the same order
                events += self._name_faults(done, final=False)
                due = self._naming_due()
            end = min(n, pos + (b - done % b))
            if due is not None and done < due < self.samples_processed + end:
                end = due - self.samples_processed  # stop at the row the naming is due, not at the block's end
            ev = self._block(t, pos, end, chunk, states)
            events += ev
            pos = end
        if self._ranges:
            self._mark_outside(rows, events)
        if self.namer is not None:
            events.sort(key=lambda e: e.index)  # in sample order, as a chunk of one row at a time gives them
        self.samples_processed += n
        return events, states

    def finish(self) -> list[LearnedEvent]:
        """The record ended: name every alarm still waiting for its NAMING_AFTER samples with what there is."""
        if self.namer is None or not self.samples_processed:
            return []
        return self._name_faults(self.samples_processed, final=True)

    def _keep(self, t: np.ndarray, rows: np.ndarray) -> None:
        """The rows into the ring the naming windows are read from."""
        idx = (self.samples_processed + np.arange(len(rows))) % NAMING_RING
        self._ring_t[idx] = t
        self._ring_x[idx] = rows

    def _name_faults(self, upto: int, final: bool) -> list[LearnedEvent]:
        """Name each alarm whose window (to NAMING_AFTER samples after its detection) ended by global index
        ``upto`` (``final``: every alarm, with the rows there are)."""
        namer = self.namer
        assert namer is not None, "called only for a reference that names faults"
        for a in self.alarms[len(self._named_ids()):]:
            self._to_name.append(a)
        events = []
        for spike in self.spikes.due(upto, self._naming_after, final):
            events += self._check_spike(spike, upto)
        for check in self.feed_checks.due(upto, self._naming_after, final):
            events += self._check_feed(check, upto)
        for a in list(self._relook):
            events += self._look_again(a, upto)
        for a in list(self._to_name):
            end = a["detection_index"] + self._naming_after
            if end > upto and not final:
                continue
            end = min(end, upto)
            first = max(0, end - NAMING_WINDOW)
            k = (np.arange(first, end)) % NAMING_RING
            iso = namer(self._ring_t[k], self._ring_x[k], a["onset_index"] - first,
                             a["detection_index"] - first, a["statistic"])
            _take_naming(a, iso)
            self._to_name.remove(a)
            self._named.append(a["alarm_id"])
            if self.confirming:
                # made at this block boundary: a deviation that cleared after its window ended but before the
                # boundary has its clearing event out already, so the verdict comes after it, not before
                at = max(end - 1, int(a.get("cleared_index", -1)))
                events += self._verdict(a, iso, float(self._ring_t[at % NAMING_RING]), at)
                self._wait_for_next_look(a, iso, 0, end)
                continue
            events.append(self._named_event(a, iso, end))
            self._name_again_later(a, iso, 0, end)
        return events

    def _check_spike(self, spike: Spike, upto: int) -> list[LearnedEvent]:
        """A spike's window ended: a fault alarm when the namer confirms that the reading stepped there (the jump;
        wavelet_fdi.spike_checks), else nothing but the count. A deviation raised about the spike (detected at it
        or after) is judged on its own, with the same rule for a step: no second alarm for one fault. A deviation
        up since before the spike and not confirmed is judged on its own window, which need not start at the step:
        a step the spike check confirms makes it this fault alarm (as a look that confirms it would)."""
        assert self.namer is not None, "spikes are checked only for a reference that names faults"
        end = min(spike.index + self._naming_after, upto)
        if any(spike.index <= a["detection_index"] < end for a in self.alarms):
            return []
        first = max(0, end - NAMING_WINDOW)
        k = np.arange(first, end) % NAMING_RING
        name = f"{self.channels[spike.channel]}.R.spike"
        iso = self.namer(self._ring_t[k], self._ring_x[k], spike.index - first, spike.index - first, name)
        self.spikes.checked += 1
        stepped = iso.get("confirmed") and "jump" in (iso.get("confirmation") or {}).get("confirmed_by", ())
        up = self._alarm if self.in_alarm else None
        if not stepped or (up is not None and up.get("verdict") == "fault"):
            return []
        self.spikes.steps += 1
        at = end - 1
        t_now = float(self._ring_t[at % NAMING_RING])
        if up is not None:
            return self._confirmed_by_check(up, iso, t_now, at)
        why = (f"the reading stepped at {spike.time_s:g} s (one innovation of {abs(spike.sigma):.1f} sigma, beyond "
               f"the spike level {self.spikes.level:g})")
        return self._checked_alarm(name, "R", (spike.index, spike.time_s), (spike.index, spike.time_s),
                                   (abs(spike.sigma), self.spikes.level), iso, t_now, at, why)

    def _check_feed(self, check: FeedCheck, upto: int) -> list[LearnedEvent]:
        """A reading that moved against the only feed (wavelet_fdi.feed_checks), its window ended: judged by the
        namer on the test's window and the samples after it. Confirmed (a probe offset or drift against the feed
        beats every healthy re-adaptation), it turns the deviation that is up into a fault alarm, or is a fault
        alarm of its own; else it is counted and dropped. Nothing is judged while a fault alarm is up, nor after a
        confirmed crossing in the same stretch of the same feed running alone (a probe that keeps drifting crosses
        again and again: one fault, one alarm)."""
        assert self.namer is not None, "feed checks are made only for a reference that names faults"
        if self._feed_fault_stretch == (check.direction, check.since_s):
            return []
        up = self._alarm if self.in_alarm else None
        if up is not None and up.get("verdict") == "fault":
            return []
        end = min(check.index + self._naming_after, upto)
        first = max(0, end - NAMING_WINDOW)
        k = np.arange(first, end) % NAMING_RING
        ph = self.channels[0]
        name = f"{ph}.raw.against_feed"
        iso = self.namer(self._ring_t[k], self._ring_x[k], max(check.first_index - first, 0), check.index - first,
                         name)
        self.feed_checks.checked += 1
        if not iso.get("confirmed") or "against_feed" not in (iso.get("confirmation") or {}).get("confirmed_by", ()):
            return []
        self.feed_checks.faults += 1
        self._feed_fault_stretch = (check.direction, check.since_s)
        at = end - 1
        t_now = float(self._ring_t[at % NAMING_RING])
        feed = "acid" if check.direction < 0 else "base"
        since = float(self._times[check.first_index % TIME_RING])
        why = (f"the reading moved against the only feed that ran ({feed}) from {since:g} s (t = {check.value:.1f} at "
               f"{check.time_s:g} s, level {self.feed_checks.level:.2f})")
        iso = {**iso, "against_feed": {"first_time": since,
                                       "time": check.time_s, "t": round(check.value, 3),
                                       "level": round(self.feed_checks.level, 3), "feed_direction": check.direction}}
        if up is not None:
            return self._confirmed_by_check(up, iso, t_now, at)
        return self._checked_alarm(name, "raw", (check.index, check.time_s), (check.first_index, since),
                                   (check.value, self.feed_checks.level), iso, t_now, at, why)

    def _checked_alarm(self, name: str, band: str, detected: tuple[int, float], onset: tuple[int, float],
                       value: tuple[float, float], iso: dict, t_now: float, at: int, why: str) -> list[LearnedEvent]:
        """A fault alarm of a check's own (a spike that was a step, a reading against the feed; no deviation up):
        ``detected`` and ``onset`` as (global index, time), ``value`` as (the check's value, its level); up from
        here, held as any other alarm while a statistic crosses, cleared after a quiet block."""
        ch = parse_statistic(name)[0]
        alarm_id = len(self.alarms) + 1
        a = {"alarm_id": alarm_id, "detection_time": detected[1], "detection_index": detected[0],
             "onset_index": onset[0], "onset_time": onset[1], "statistic": name, "statistic_value": value[0],
             "threshold": value[1], "channels": [ch], "contributions": {ch: {"share": 1.0, "bands": {band: 1.0}}},
             "cleared_time": None, "isolation": iso, "outside_healthy_range": [], "verdict": "fault",
             "confirmed_time": t_now, "confirmed_index": at}
        self.alarms.append(a)
        self._named.append(alarm_id)
        self.in_alarm, self._alarm, self._last_crossing = True, a, at
        self._episode[:] = 0.0
        self._peak = np.zeros(self.m)
        size = f"{iso['size']:g} {iso['unit']}".strip()
        return [LearnedEvent("alarm", t_now, at, "ERROR",
                             f"alarm {alarm_id}: {iso['family']} fault, {iso['description']} ({size}); {why}",
                             dict(a))]

    def _confirmed_by_check(self, up: dict, iso: dict, t_now: float, at: int) -> list[LearnedEvent]:
        """A check (a spike that was a step, a reading against the feed) confirmed a fault while a deviation not
        confirmed is up: the deviation is this fault, a fault alarm as a look that confirms it would make it (its
        WARN stays in the log; it is named no more)."""
        for waiting in (self._to_name, self._relook):
            if up in waiting:
                waiting.remove(up)
        if up["alarm_id"] not in self._named:
            self._named.append(up["alarm_id"])
        _take_naming(up, iso)
        return self._verdict(up, iso, t_now, at)

    def _named_event(self, a: dict, iso: dict, end: int) -> LearnedEvent:
        when = float(self._ring_t[(end - 1) % NAMING_RING])
        if iso.get("family") == "none":  # no hypothesis explains it: say so, not "none fault (0 )"
            text = f"alarm {a['alarm_id']} not named: {iso['description']}"
        else:
            size = f" ({iso['size']:g} {iso['unit']})" if iso.get("unit") else ""
            text = f"alarm {a['alarm_id']} named: {iso['family']} fault, {iso['description']}{size}"
        return LearnedEvent("named", when, end - 1, "ERROR" if self.in_alarm else "OK", text, dict(a))

    def _name_again_later(self, a: dict, iso: dict, look: int, end: int) -> None:
        """A naming that is unsure (the namer says ``name_again``: more samples may separate its candidates, as a
        stuck valve slips or a limit cycle develops) is made again at the reference's next look, while the alarm
        is up; the last naming stands."""
        if iso.get("name_again") and look + 1 < len(self._looks) and a.get("cleared_index") is None:
            a["look"] = look + 1
            self._relook.append(a)

    def _wait_for_next_look(self, a: dict, iso: dict, look: int, end: int) -> None:
        """After look ``look`` (its window ended at global index ``end``): a deviation no fault explained that is
        still up then waits for the next look, if the reference has one and the namer did not say another look
        cannot help (``look_again``)."""
        cleared = a.get("cleared_index")
        again = not iso.get("confirmed", True) and iso.get("look_again", True)
        if again and look + 1 < len(self._looks) and (cleared is None or cleared >= end):
            a["look"] = look + 1
            self._relook.append(a)

    def _look_again(self, a: dict, upto: int) -> list[LearnedEvent]:
        """The next look at a deviation not confirmed so far, once its longer window ended by global index
        ``upto`` (a record that ends first leaves the last look's verdict standing). A look that confirms it turns
        it into a fault alarm (the WARN before it stays in the log); one that does not is only recorded on the
        deviation (``looks``)."""
        look = int(a["look"])
        after = self._looks[look]
        end = a["detection_index"] + after
        if not self.confirming and a.get("cleared_index") is not None:
            self._relook.remove(a)  # a naming is made again only while its alarm is up: the last one stands
            return []
        if end > upto:
            return []
        self._relook.remove(a)
        first = max(0, end - NAMING_WINDOW)
        k = (np.arange(first, end)) % NAMING_RING
        assert self.namer is not None, "looks are made only by a reference that names faults"
        iso = self.namer(self._ring_t[k], self._ring_x[k], a["onset_index"] - first, a["detection_index"] - first,
                         a["statistic"], after=after)
        if not self.confirming:  # a naming made again with more samples
            a.setdefault("namings", []).append(a.get("isolation"))
            _take_naming(a, iso)
            self._name_again_later(a, iso, look, end)
            return [self._named_event(a, iso, end)]
        conf = iso.get("confirmation") or {}
        a.setdefault("looks", []).append({"after_samples": after, "confirmed": bool(iso.get("confirmed")),
                                          "statistics": conf.get("statistics")})
        if not iso.get("confirmed"):
            self._wait_for_next_look(a, iso, look, end)
            return []
        _take_naming(a, iso)
        at = max(end - 1, int(a.get("cleared_index", -1)))
        return self._verdict(a, iso, float(self._ring_t[at % NAMING_RING]), at)

    def _verdict(self, a: dict, iso: dict, t_s: float, index: int) -> list[LearnedEvent]:
        """A deviation checked: a fault alarm (ERROR, always announced; followed by its clearing when the
        deviation has already ended) or a deviation outside calibration (WARN, announced as its deviation was)."""
        size = f"{iso['size']:g} {iso['unit']}".strip()
        still_up = self.in_alarm and self._alarm is a
        if iso.get("confirmed", True):
            a.update(verdict="fault", confirmed_time=t_s, confirmed_index=int(index))
            out = [LearnedEvent("alarm", t_s, index, "ERROR",
                                f"alarm {a['alarm_id']}: {iso['family']} fault, {iso['description']} ({size}); "
                                f"{a['statistic']} crossed its threshold at {a['detection_time']:g} s", dict(a))]
            if not still_up:
                out.append(LearnedEvent("cleared", t_s, index, "OK", f"alarm {a['alarm_id']} cleared: the "
                                        f"deviation had ended at {a.get('cleared_time', t_s):g} s", dict(a)))
            return out
        a["verdict"] = "outside calibration"
        self._last_outside_t = t_s
        why = (f"its best healthy explanation: {iso['description']} ({size})" if iso["family"] != "none"
               else "and no healthy explanation fits either")
        return [LearnedEvent("outside_calibration", t_s, index, "WARN" if still_up else "OK",
                             f"deviation {a['alarm_id']} outside calibration: no fault hypothesis explains it by the "
                             f"calibrated margin, {why}", dict(a), announce=a.get("announced", True))]

    def _naming_due(self) -> int | None:
        """The global row index at which the next naming of a reference that names but does not confirm (the
        physics kind) is due: its first naming or a naming made again. The detector names there, not at the next
        block boundary, so that a live subscriber hears the name ``naming_after_samples`` after the detection, not
        up to a block later. Only where the first naming waits at least a block: an alarm raised inside a block is
        then due after that block's end, so every chunking stops at the same rows. None: no naming is waiting,
        or names are made at block boundaries (a confirming reference, or one that names sooner than a block)."""
        if not self._exact_naming:
            return None
        first = [a["detection_index"] + self._naming_after for a in self.alarms
                 if a["alarm_id"] not in self._named]
        again = [a["detection_index"] + self._looks[int(a["look"])] for a in self._relook
                 if a.get("cleared_index") is None]
        return min(first + again) if first or again else None

    def _named_ids(self) -> list[int]:
        return self._named + [a["alarm_id"] for a in self._to_name]

    def monitor(self) -> tuple[float, dict[str, float]]:
        """The last row processed, for a live view: its time (s), each residual (``residual:<channel>``, in the
        reference's units: healthy or sensor-noise sigmas; NaN where held or missing) and every statistic over its
        threshold (``ratio:<name>``; 1 raises the alarm). Time NaN before the first row.

        >>> import numpy as np
        >>> from wavelet_fdi import LearnedDetector, learn
        >>> rows = np.random.default_rng(1).normal(size=(3000, 2))
        >>> detector = LearnedDetector(learn(rows[:2000], ["flow", "pressure"]))
        >>> _ = detector.process(np.arange(1000.0), rows[2000:])
        >>> t, values = detector.monitor()
        >>> t, sorted(values)[:3], bool(np.isfinite(values["residual:flow"]))
        (999.0, ['ratio:flow.A2.mean_down', 'ratio:flow.A2.mean_up', 'ratio:pressure.A2.mean_down'], True)
        """
        values = {f"residual:{c}": float(v) for c, v in zip(self.channels, self._last_residual)}
        values.update({f"ratio:{n}": float(v) for n, v in zip(self.stat_names, self._last_ratio)})
        return self._last_t, values

    def trace(self) -> dict[str, np.ndarray]:
        if self._trace is None:
            raise RuntimeError("the detector was built without record_trace")
        return {k: (np.concatenate(v) if v else np.empty(0)) for k, v in self._trace.items()}

    # ---- one block (observer constant inside) -------------------------------------------
    def _block(self, t, i0, i1, c: Chunk, states) -> list[LearnedEvent]:
        s = self.settings
        g0 = self.samples_processed + i0
        d_norm, missing = c.d_norm, c.missing
        dev = c.a_raw[i0:i1] - self.bias  # (nb, m) AJ deviation from the learned healthy level
        sig = self.model.band_sigma
        u = dev * self.gain / sig[:, -1]
        if c.gappy:
            u = np.where(missing[i0:i1], 0.0, u)
        nb = i1 - i0
        vals = np.empty((len(self.stat_names), nb))
        for stat, rows in zip(self.statistics, self._slices):
            stat.values(vals[rows], c, i0, i1, g0, u)
        z = vals - self.k[:, None]
        warm = g0 < self.fill_samples
        if warm:  # filters not yet filled: no evidence either way
            cut = min(nb, self.fill_samples - g0)
            z[:, :cut] = -self.k[:, None]
        events: list[LearnedEvent] = []
        S = self.cusum.update(z, g0)
        ratio = S / self.h[:, None]
        self._last_ratio = ratio[:, -1].copy()
        cross = (ratio > 1.0).any(axis=0)
        if self._trace is not None:
            coef = np.concatenate((d_norm[:, i0:i1, :].transpose(1, 2, 0) * sig[:, :-1],
                                   (dev * self.gain)[:, :, None]), axis=2)
            self._trace["coef"].append(np.where(missing[i0:i1][:, :, None], np.nan, coef))
            self._trace["stat"].append(ratio.T.copy())
            self._trace["increments"].append(z.T.copy())  # value - k per statistic (the warm-up's at -k)
            # the residual less the observer's level (what R watches), NaN where missing or held
            assert c.residual is not None, "process passes the residuals"
            self._trace["residual"].append(np.where(missing[i0:i1], np.nan, c.residual[i0:i1] - self.bias))
        if self.alarms_enabled:
            events += self._alarm_logic(t, i0, i1, g0, ratio, cross, states, np.abs(u))
        if self._trace is not None:
            self._trace["state"].append(states[i0:i1].copy())
        # observer: block sums of the deviation; correction at block boundaries when not frozen
        ok = ~missing[i0:i1]
        self._acc = _running_sum(self._acc, np.where(ok, dev, 0.0), axis=0)
        self._acc_n += nb
        at_boundary = (g0 + nb) % s.block_samples == 0
        if at_boundary:
            frozen = self.alarms_enabled and (self.in_alarm or bool((ratio[:, -1] > s.freeze_ratio).any()))
            tau = s.observer_alarm_time_constant_s if frozen else s.observer_time_constant_s
            block_warm = g0 + nb - s.block_samples < self.fill_samples  # by global index: chunking-proof
            if self._rebase == 2 and self._acc_n:
                # the block after an alarm cleared because its channels came most of the way back: what is
                # left of the offset is the new healthy level (else it would raise the alarm again)
                self.bias = self.bias + self._acc / self._acc_n
            elif s.observer_time_constant_s > 0 and tau > 0 and not block_warm and self._acc_n:
                gain = min(1.0, s.block_samples * s.sample_time_s / tau)
                self.bias = self.bias + gain * self._acc / self._acc_n
            self._acc[:] = 0.0
            self._acc_n = 0
            for stat, rows in zip(self.statistics, self._slices):
                stat.end_block(ratio[rows, -1], self.in_alarm)
            if self.in_alarm or self._holdoff:
                self.cusum.restart(g0 + nb - 1)
                self._holdoff = False
            if self._rebase == 1:  # the clear's block is over: learn the new level over the next full block
                self._rebase, self._holdoff = 2, True
            elif self._rebase == 2:
                self._rebase = 0
            self.cusum.renormalise()
        return events

    def _holding(self, j: int, ratio: np.ndarray, absu: np.ndarray) -> np.ndarray:
        """In alarm, samples j.. of the block that still carry the fault: a statistic above its threshold,
        and for the mean statistics a deviation of at least clear_fraction of the episode's peak on its
        channel (a channel that came most of the way back does not hold the alarm by a small offset)."""
        rho = self.settings.clear_fraction
        above = ratio[:, j:] > 1.0
        if rho <= 0.0:
            return np.any(above, axis=0)
        a = absu[j:]  # (n, m)
        peak = np.maximum(np.maximum.accumulate(a, axis=0), self._peak)  # running peak per channel
        strong = (a >= rho * peak).T  # (m, n)
        ok = above.copy()
        ok[self._by_level] &= strong[self.stat_channel[self._by_level]]
        return np.any(ok, axis=0)

    def _alarm_logic(self, t, i0, i1, g0, ratio, cross, states, absu) -> list[LearnedEvent]:
        s = self.settings
        events: list[LearnedEvent] = []
        nb = i1 - i0
        j = 0
        while j < nb:
            if not self.in_alarm:
                if self._holdoff:
                    break
                hit = np.flatnonzero(cross[j:])
                if not len(hit):
                    break
                j += int(hit[0])
                self.in_alarm = True
                self._last_crossing = g0 + j
                self._episode[:] = 0.0
                self._peak = np.zeros(self.m)
                self._alarm = self._raise(t[i0 + j], g0 + j, ratio[:, j])
                events.append(self._raised_event(float(t[i0 + j]), g0 + j))
            # in alarm: held while a crossing happened in the last block_samples samples
            idx = np.arange(j, nb)
            hold = self._holding(j, ratio, absu)
            last = np.where(hold, g0 + idx, -1)
            last = np.maximum(np.maximum.accumulate(last), self._last_crossing)
            quiet = (g0 + idx) - last >= s.block_samples
            if quiet.any():
                q = int(np.argmax(quiet))
                jc = j + q
                states[i0 + j:i0 + jc] = 1
                self._episode = _running_sum(self._episode, np.clip(ratio[:, j:jc], 0.0, None), axis=1)
                events.append(self._clear(t[i0 + jc], g0 + jc))
                self.in_alarm = False
                self._holdoff = True
                if self.settings.clear_fraction > 0.0:
                    self._rebase = 1
                break
            states[i0 + j:i1] = 1
            self._episode = _running_sum(self._episode, np.clip(ratio[:, j:], 0.0, None), axis=1)
            self._last_crossing = int(last[-1])
            self._peak = np.maximum(self._peak, absu[j:].max(axis=0))
            break
        return events

    # ---- alarms -----------------------------------------------------------------------
    def _contributions(self, ratio: np.ndarray) -> dict:
        w = np.clip(ratio, 0.0, None)
        tot = float(w.sum()) or 1.0
        per_channel: dict[str, dict] = {}
        for i, name in enumerate(self.stat_names):
            ch = self.channels[self.stat_channel[i]]
            band = self.bands[self.stat_band[i]]
            d = per_channel.setdefault(ch, {"share": 0.0, "bands": {}})
            d["share"] += float(w[i]) / tot
            d["bands"][band] = d["bands"].get(band, 0.0) + float(w[i]) / tot
        ranked = sorted(per_channel.items(), key=lambda kv: -kv[1]["share"])
        return {ch: {"share": round(v["share"], 4), "bands": {b: round(x, 4) for b, x in v["bands"].items() if x > 0}}
                for ch, v in ranked if v["share"] > 0}

    def _raise(self, t_s: float, index: int, ratio: np.ndarray) -> dict:
        top = int(np.argmax(ratio))
        cont = self._contributions(ratio)
        onset = min(self.cusum.last_zero_at(top, int(index)) + 1, int(index))
        onset_t = float(self._times[onset % TIME_RING]) if index - onset < TIME_RING else math.nan
        alarm = {"alarm_id": len(self.alarms) + 1, "detection_time": float(t_s), "detection_index": int(index),
                 "onset_index": onset, "onset_time": onset_t if math.isfinite(onset_t) else None,
                 "statistic": self.stat_names[top],
                 "statistic_value": float(ratio[top] * self.h[top]), "threshold": float(self.h[top]),
                 "channels": list(cont), "contributions": cont, "cleared_time": None}
        self.alarms.append(alarm)
        return alarm

    def _mark_outside(self, rows: np.ndarray, events: list[LearnedEvent]) -> None:
        """Each alarm raised in these rows lists the channels that left the healthy runs' range between its onset
        and its detection (``outside_healthy_range``; its message says so): there the reference extrapolates, and
        the alarm may be the reference's rather than the plant's. Any chunking gives the same lists."""
        g0 = self.samples_processed
        masks = outside_masks(self._ranges, rows, self.inputs)
        raised = "deviation" if self.confirming else "alarm"  # the event of the crossing itself
        for ev in events:
            if ev.kind != raised or ev.alarm is None:
                continue
            a = ev.alarm
            onset = int(a["detection_index"] if a.get("onset_index") is None else a["onset_index"])
            lo, hi = max(onset, g0) - g0, int(a["detection_index"]) - g0 + 1
            names = [c for c, bad in masks.items() if self._last_outside.get(c, -1) >= onset or bool(bad[lo:hi].any())]
            # the alarm as kept, and as every event of these rows carries it (a clearing in the same rows too)
            for x in [*self.alarms, *(e.alarm for e in events if e.alarm is not None)]:
                if x["alarm_id"] == a["alarm_id"]:
                    x["outside_healthy_range"] = names
            if names:
                ev.message += f"; beyond the healthy runs' range then: {', '.join(names)}"
        for c, bad in masks.items():
            hit = np.flatnonzero(bad)
            if len(hit):
                self._last_outside[c] = g0 + int(hit[-1])

    def _raised_event(self, t_s: float, index: int) -> LearnedEvent:
        """The event of a statistic crossing: a fault alarm, or with a confirming reference a deviation to be
        checked (not announced within ``outside_hold_s`` of the last deviation outside calibration)."""
        a = self._alarm
        assert a is not None, "called in alarm only"
        top = ", ".join(f"{c} {v['share']:.0%}" for c, v in list(a["contributions"].items())[:3])
        if not self.confirming:
            return LearnedEvent("alarm", t_s, index, "ERROR",
                                f"alarm {a['alarm_id']}: {a['statistic']} crossed its threshold; channels: {top}", dict(a))
        a["verdict"] = "pending"
        a["announced"] = t_s - self._last_outside_t >= self.settings.outside_hold_s
        return LearnedEvent("deviation", t_s, index, "WARN",
                            f"deviation {a['alarm_id']}: {a['statistic']} crossed its threshold; channels: {top}; "
                            f"checking whether a fault explains it", dict(a), announce=a["announced"])

    def _clear(self, t_s: float, index: int) -> LearnedEvent:
        a = self._alarm
        assert a is not None, "called in alarm only"
        a["cleared_time"] = float(t_s)
        a["cleared_index"] = int(index)
        a["episode_contributions"] = self._contributions(self._episode)
        what = "alarm" if a.get("verdict", "fault") == "fault" else "deviation"
        return LearnedEvent("cleared", float(t_s), int(index), "OK",
                            f"{what} {a['alarm_id']} cleared: no statistic above its threshold for "
                            f"{self.settings.block_samples} samples", dict(a), announce=a.get("announced", True))

    def _stream_notices(self, t: np.ndarray) -> list[LearnedEvent]:
        """What the reference stream did on these rows by its own rule (the physics kind: detection held while the
        valve command is missing, the model restarted when it returns), as input events."""
        notices = getattr(self.stream, "notices", None)
        if not notices:
            return []
        out = [LearnedEvent("input", float(t[index - self.samples_processed]), index, "WARN", text)
               for index, text in notices]
        notices.clear()
        return out

    def _missing_events(self, missing: np.ndarray, t: np.ndarray) -> list[LearnedEvent]:
        """Each channel's stretch of missing residuals: said where it begins (WARN) and where it ends (OK)."""
        out = []
        for c in np.flatnonzero(missing.any(axis=0) | self._missing_open):
            col = missing[:, c]
            before = np.concatenate(([self._missing_open[c]], col[:-1]))
            for i in np.flatnonzero(col != before):
                index = self.samples_processed + int(i)
                if col[i]:
                    self._missing_since[c] = index
                    out.append(LearnedEvent("input", float(t[i]), index, "WARN",
                                            f"{self.channels[c]}: missing from {t[i]:g} s (counted as healthy "
                                            f"until it returns)"))
                else:
                    n = index - int(self._missing_since[c])
                    out.append(LearnedEvent("input", float(t[i]), index, "OK",
                                            f"{self.channels[c]}: back at {t[i]:g} s after {n} sample"
                                            f"{'s' if n != 1 else ''} missing"))
            self._missing_open[c] = bool(col[-1])
        out.sort(key=lambda e: e.index)
        return out

    def _hold_events(self, t: np.ndarray) -> list[LearnedEvent]:
        """Where the reference stream's hold of detection (its own rule: a missing valve command, a restart's
        warm-up) ended in these rows: detection resumes (OK)."""
        held = getattr(self.stream, "last_held", None)
        holding = getattr(self.stream, "holding", None)
        if held is None or holding is None or not len(held):
            return []
        was, self._stream_holds = self._stream_holds, bool(holding)
        if not was or self._stream_holds:
            return []
        last_held = np.flatnonzero(held)
        i = min(int(last_held[-1]) + 1 if len(last_held) else 0, len(held) - 1)
        return [LearnedEvent("input", float(t[i]), self.samples_processed + i, "OK",
                             f"detection resumed at {t[i]:g} s")]

    @property
    def input_problem(self) -> str:
        """What keeps the detector from watching every channel after the last row ('' when nothing): channels
        missing, detection held by the reference's own rule."""
        parts = [f"{c} missing" for c, o in zip(self.channels, self._missing_open) if o]
        if self._stream_holds:
            parts.append("detection held")
        return ", ".join(parts)


def _take_naming(a: dict, iso: dict) -> None:
    """An alarm's naming: kept under ``isolation``; where the namer fits the onset (``onset_time``, s: the physics
    kind's isolation), that is the alarm's onset from then on, the statistic's kept as ``statistic_onset_time``."""
    a["isolation"] = iso
    onset = iso.get("onset_time")
    if onset is not None and math.isfinite(float(onset)):
        a.setdefault("statistic_onset_time", a.get("onset_time"))
        a["onset_time"] = float(onset)


def _running_sum(total: np.ndarray, values: np.ndarray, axis: int) -> np.ndarray:
    """``total`` plus ``values`` summed along ``axis`` one sample after another (np.cumsum adds in order;
    ndarray.sum adds pairwise), so that a block split across two chunks sums to the same last bit."""
    if values.shape[axis] == 0:
        return total
    stacked = np.concatenate((np.expand_dims(total, axis), values), axis=axis)
    return np.take(np.cumsum(stacked, axis=axis), -1, axis=axis)


def run_record(model: LearnedModel, t_s: np.ndarray, x: np.ndarray, chunk: int | None = 4096,
               record_trace: bool = False, alarms: bool = True, name_faults: bool = True
               ) -> tuple[list[LearnedEvent], np.ndarray, LearnedDetector]:
    """A whole record through a fresh detector, in chunks of ``chunk`` rows (None: at once; the
    result is the same, chunks of a few thousand rows are fastest); ``record_trace``: the detector keeps its
    trace (:meth:`LearnedDetector.trace`; memory grows with the record); ``name_faults`` False: detection only;
    ``alarms`` False: statistics only, as
    calibration runs them (no alarm, no naming).

    Returns
    -------
    events : list of LearnedEvent
    states : ndarray of int8
        Each row's alarm state (0/1).
    detector : LearnedDetector
        The detector after the record (its alarms, counters).

    Examples
    --------
    >>> import numpy as np
    >>> from wavelet_fdi import learn, run_record
    >>> rows = np.random.default_rng(1).normal(size=(6000, 2))
    >>> model = learn(rows[:4000], ["flow", "pressure"])
    >>> events, states, _ = run_record(model, np.arange(2000.0), rows[4000:])
    >>> events, int(states.max())  # healthy rows: no alarm
    ([], 0)
    """
    det = LearnedDetector(model, alarms=alarms, record_trace=record_trace, name_faults=name_faults)
    n = len(x)
    step = n if not chunk else int(chunk)
    events, states = [], []
    for a in range(0, n, max(step, 1)):
        ev, st = det.process(t_s[a:a + step], x[a:a + step])
        events += ev
        states.append(st)
    events += det.finish()
    return events, (np.concatenate(states) if states else np.zeros(0, dtype=np.int8)), det
