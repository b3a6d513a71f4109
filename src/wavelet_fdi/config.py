"""Detector settings (the physics detector's and the learned and estimator detector's, each declared once with
:func:`setting`) and the calibration file the detector loads.

Settings are design choices (wavelet, level, false-alarm target, windows);
the calibration holds what is measured on healthy runs: the residual's
standard deviation per channel and wavelet band and each statistic's
threshold for the false-alarm target. ``phfdi calibrate`` writes it;
``wavelet_fdi/calibrations/<scenario>_<wavelet>_L<level>.yaml`` ship with
the package.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field, fields
from importlib import resources
from pathlib import Path
from typing import Any, get_type_hints

from phfdi_base.errors import UserError
from phfdi_base.outputs import write_text
from phfdi_base.yamlfile import read_mapping

from .filterbank import wavelet_filters
from .statistics import STATISTICS, parse_statistic

CALIBRATION_DIR = Path(str(resources.files("wavelet_fdi"))) / "calibrations"
CHANNELS = ("ph", "level")
#: samples per window in which a threshold calibration restarts the CUSUMs and takes their maxima
ARL_WINDOW_SAMPLES = 1000


def setting(default: Any, help: str, *, range: tuple[float, float] | None = None, option: str | None = None,
            exposed: bool = False) -> Any:
    """A detector setting, declared once: default, help and allowed range. ``exposed`` settings are also an
    option of ``phfdi calibrate``, ``replay`` and ``evaluate`` (``--<option or name>``) and a parameter of the
    detector node; :func:`setting_specs` derives those, and the docs table (:func:`settings_table_markdown`)."""
    return field(default=default, metadata={"help": help, "range": range, "option": option, "exposed": exposed})


@dataclass
class DetectorSettings:
    """Design of the detector (units in the names; see docs/detector.md, "Detector settings").

    Every field has a default (the shipped calibrations' design); the statistics it runs are
    :meth:`statistic_names`, each needing a threshold in the :class:`Calibration`. Each field is declared
    once here, with its help and range; the CLI options and node parameters are derived from it.

    Examples
    --------
    >>> from wavelet_fdi import DetectorSettings
    >>> settings = DetectorSettings(level=3, warmup_s=300.0)
    >>> settings.statistic_names()
    ['ph.R.mean_up', 'ph.R.mean_down', 'ph.D1.energy', 'ph.D2.energy', 'ph.D3.energy', 'ph.A3.energy']
    """

    wavelet: str = setting("sym4", "PyWavelets orthogonal wavelet of the filter bank (sym4, db8, ...); the "
                                   "calibration must match", exposed=True)
    level: int = setting(3, "wavelet decomposition level", range=(1, 10), exposed=True)
    arl0_samples: float = setting(1e5, "false-alarm target: average run length to a false alarm of the whole "
                                       "detector (samples); the calibration must match", range=(10.0, 1e12),
                                  option="arl0", exposed=True)
    channels: tuple[str, ...] = setting(("ph",), "residual channels watched: ph, or ph and level", exposed=True)
    raw_band: bool = setting(True, "watch the residual's own mean (R) besides the wavelet bands' energies; "
                                   "false: the paper's bands only (the mean of AJ instead of R's)")
    statistics: tuple[str, ...] = setting(("mean_up", "mean_down", "energy"),
                                          "kinds of CUSUM statistic run (wavelet_fdi.statistics.STATISTICS)")
    mean_shift_sigma: float = setting(1.0, "the mean CUSUMs are designed for a residual mean shift of this many "
                                           "sigma", range=(1e-3, 1e3))
    variance_ratio: float = setting(4.0, "the energy CUSUMs are designed for this variance ratio (above 1)",
                                    range=(1.0, 1e6))
    block_samples: int = setting(256, "observer corrections, pH-solve guesses and state snapshots happen every "
                                      "this many samples", range=(8, 1_000_000))
    warmup_s: float = setting(600.0, "no alarms until this long after a start or a reset (the reference "
                                     "settles, the filters fill), s", range=(0.0, 1e9))
    observer_time_constant_s: float = setting(3600.0, "time constant of the slow observer that removes "
                                                      "model-plant mismatch, s; 0 switches it off", range=(0.0, 1e9))
    max_gap_s: float = setting(10.0, "a gap in the time stamps longer than this resets the window; shorter gaps "
                                     "are bridged, s", range=(0.0, 1e9))
    command_timeout_s: float = setting(10.0, "the valve command may be missing this long before the detector "
                                             "stops trusting the reference, s", range=(0.0, 1e9))
    clear_after_s: float = setting(1800.0, "an alarm clears after this long without a statistic crossing its "
                                           "threshold, s", range=(0.0, 1e9))
    clear_quiet_s: float = setting(120.0, "an alarm also clears once every statistic has stayed below "
                                          "clear_fraction of its threshold this long (the statistics fell back; "
                                          "0: off), s", range=(0.0, 1e9))
    clear_fraction: float = setting(0.5, "the fraction of its threshold a statistic must stay below for "
                                         "clear_quiet_s", range=(0.0, 1.0))
    isolation_delays_s: tuple[float, ...] = setting((300.0,), "isolation runs this long after a detection (and "
                                                              "again at each further delay given), s")
    isolation_retries: int = setting(2, "when the diagnosis is unsure, isolate again one isolation delay later, "
                                        "at most this many times", range=(0, 100))
    isolation_confidence: float = setting(0.9, "below this confidence (or class unknown) the diagnosis is "
                                               "unsure", range=(0.0, 1.0))
    history_samples: int = setting(4096, "past samples kept for isolation (bounds memory); at least twice "
                                         "block_samples", range=(16, 100_000_000))
    setpoint_holdoff_s: float = setting(0.0, "statistics are held this long after a setpoint change (0: off), s",
                                        range=(0.0, 1e9))

    def __post_init__(self) -> None:
        self.channels = tuple(self.channels)
        self.statistics = tuple(self.statistics)
        self.isolation_delays_s = tuple(float(d) for d in self.isolation_delays_s)
        check_declared_ranges(self, "detector setting")
        for c in self.channels:
            if c not in CHANNELS:
                raise UserError(f"detector channel {c!r} unknown; use {', '.join(CHANNELS)}")
        for kind in self.statistics:
            if kind not in STATISTICS:
                raise UserError(f"statistic kind {kind!r} unknown; registered: {', '.join(STATISTICS)}")
        if not self.variance_ratio > 1.0:
            raise UserError(f"variance_ratio must exceed 1, got {self.variance_ratio}")
        if self.history_samples < 2 * self.block_samples:
            raise UserError("history_samples must be at least twice block_samples")
        try:
            wavelet_filters(self.wavelet)
        except ValueError as exc:
            raise UserError(str(exc)) from None

    def bands(self) -> list[str]:
        """Wavelet bands D1..DJ, AJ."""
        return [f"D{j}" for j in range(1, self.level + 1)] + [f"A{self.level}"]

    def rows(self) -> list[str]:
        """Rows of the detector's coefficient arrays: the wavelet bands, then R (the residual itself)."""
        return self.bands() + ["R"]

    def statistic_names(self) -> list[str]:
        """channel.band.kind for every CUSUM the detector runs: per channel, R's statistics then each band's
        (D1..DJ, AJ), within a band in the order of :attr:`statistics`.

        With the defaults (``raw_band``): the residual's mean (R, up and down) and the energy of every wavelet
        band. Without ``raw_band``, the paper's bands only: the mean of AJ replaces R's.
        """
        stats = [STATISTICS[kind] for kind in self.statistics]
        return [f"{ch}.{row}.{st.kind}" for ch in self.channels for row in ["R", *self.bands()]
                for st in stats if row in st.rows(self)]

    def reference_value(self, name: str) -> float:
        """k of a statistic (its class's design: a mean shift of mean_shift_sigma residual standard deviations,
        a variance ratio of variance_ratio, ...)."""
        _, band, kind = parse_statistic(name)
        return STATISTICS[kind].reference_value(self, band)

    def threshold_group(self, name: str) -> list[str]:
        """The statistics sharing a threshold with ``name`` (same channel, band and group), in run order."""
        ch, band, kind = parse_statistic(name)
        group = STATISTICS[kind].group or kind
        return [n for n in self.statistic_names() if parse_statistic(n)[:2] == (ch, band)
                and (STATISTICS[parse_statistic(n)[2]].group or parse_statistic(n)[2]) == group]


#: learned reference forms (LearnedSettings.form)
LEARNED_FORMS = ("arx", "oe")


@dataclass
class LearnedSettings:
    """Design of the learned detector; every threshold in healthy standard deviations of its band.

    The defaults were chosen on SKAB's valve1 files and scored held out on its other files
    (benchmarks/skab_select.py; docs/detector.md): one configuration for every record.

    Examples
    --------
    >>> from wavelet_fdi import LearnedSettings
    >>> settings = LearnedSettings()  # checked when made: the defaults are valid
    >>> settings.wavelet, settings.level
    ('sym4', 2)
    """

    wavelet: str = setting("sym4", "PyWavelets orthogonal wavelet of the stationary filter bank")
    level: int = setting(2, "wavelet decomposition level", range=(1, 8))
    lags: int = setting(2, "own lags of each channel in the learned reference")
    ridge_own: float = setting(1.0, "ridge penalty on a channel's own lags (standardised units)")
    ridge_cross: float = setting(10.0, "ridge penalty on the other channels' lags (standardised units)")
    form: str = setting("arx", "form of the learned reference: arx (own lags measured, wavelet_fdi.reference_learned) "
                               "or oe (output error: own lags simulated, pulled toward the measurement over "
                               "correction_samples samples; wavelet_fdi.reference_oe), which keeps a sensor fault in "
                               "its channel's residual")
    correction_samples: float = setting(100.0, "oe: samples over which the simulated lags are pulled toward the "
                                               "measurement (0: pure simulation, else at least 1)")
    mean_k: float = setting(5.0, "mean CUSUMs on AJ: reference value k (healthy sigmas of AJ)", range=(0.0, math.inf))
    mean_h: float = setting(5.0, "mean CUSUMs on AJ: threshold h (healthy sigmas of AJ), above 0")
    residual_mean_k: float = setting(0.0, "mean CUSUMs on each residual itself (the physics detector's R): reference "
                                          "value k, residual sigmas, half the shift they are designed for (0: off)",
                                     range=(0.0, math.inf))
    residual_mean_h: float = setting(20.0, "those CUSUMs' threshold, above 0 (measured instead with arl0_samples)")
    spike_sigma: float = setting(0.0, "spike checks (a reference that confirms its alarms, the estimator): one "
                                      "residual beyond this many healthy sigmas, read before the reference's limit "
                                      "(clip_sigma), is judged once as a step of the reading "
                                      "(wavelet_fdi.spike_checks); 0: off. phfdi calibrate --estimator measures it "
                                      "for spike_per_sample",
                                 range=(0.0, math.inf))
    spike_per_sample: float = setting(0.0, "the spike checks' design: the probability that a healthy sample crosses "
                                           "it; above 0, calibrating measures spike_sigma for it on the healthy "
                                           "runs' residuals (each run's from the reference it was scored by; "
                                           "exponential tail beyond their 90th percentile); 0: spike_sigma as given",
                                      range=(0.0, 0.1))
    against_feed_per_sample: float = setting(0.0, "feed checks (a reference that confirms its alarms and knows its "
                                                  "feeds' directions, the estimator): the probability that a healthy "
                                                  "sample's reading moves against the only feed that runs by the test's "
                                                  "level (wavelet_fdi.feed_checks: a t of the slope of the reading's "
                                                  "batch means, its level the t quantile); 0: off",
                                             range=(0.0, 0.1))
    energy_variance_ratio: float = setting(0.0, "energy CUSUMs on the detail bands designed for this variance "
                                                "ratio, above 1 (0: off)")
    energy_h: float = setting(20.0, "energy CUSUMs' threshold, above 0")
    energy_baseline_time_constant_s: float = setting(
        0.0, "the energy CUSUMs' scale: 0, the calibrated band sigma pooled over the healthy runs; above 0, a scale "
             "of this run learned from its own detail bands (the mean of d^2 over the blocks so far, then moving "
             "with this time constant, s), frozen while an energy statistic is above freeze_ratio of its threshold "
             "and kept within energy_variance_ratio of the calibrated one: a plant whose healthy noise differs "
             "from day to day is compared with itself, and a fault faster than the time constant is not absorbed",
        range=(0.0, math.inf))
    energy_down_variance_ratio: float = setting(0.0, "energy-decrease CUSUMs on the detail bands designed for this "
                                                     "variance ratio, between 0 and 1 (a probe that freezes or turns "
                                                     "sluggish loses its noise; 0: off)")
    energy_down_h: float = setting(20.0, "energy-decrease CUSUMs' threshold, above 0")
    repeat_probability: float = setting(0.0, "repeats CUSUM on each watched channel's raw reading "
                                             "(wavelet_fdi.repeat_test), designed for a stale reading that repeats "
                                             "its previous value in this share of the samples, against the run's own "
                                             "repeat share (learned with energy_baseline_time_constant_s, 120 s when "
                                             "that is 0); 0: off, else below 1")
    repeat_h: float = setting(20.0, "repeats CUSUM's threshold (an in-control run length of at least e^h samples), "
                                    "above 0")
    observer_time_constant_s: float = setting(300.0, "observer on AJ: time constant, s (0: off)",
                                              range=(0.0, math.inf))
    freeze_ratio: float = setting(0.5, "the observer and the energy scale freeze above this fraction of a "
                                       "threshold, in (0, 1]")
    observer_alarm_time_constant_s: float = setting(
        10000.0, "while an alarm is up the observer keeps learning with this (longer) time constant, s, so that a "
                 "lasting new operating point stops alarming eventually (0: frozen until the alarm clears)",
        range=(0.0, math.inf))
    block_samples: int = setting(32, "observer updates and in-alarm CUSUM restarts happen every this many samples; "
                                     "an alarm clears after this many samples without a crossing",
                                 range=(1, math.inf))
    clear_fraction: float = setting(0.2, "in alarm, a mean statistic holds the alarm only while its channel's AJ "
                                         "deviation is at least this fraction of the episode's peak on that channel "
                                         "(0: any crossing holds it), in [0, 1)")
    sample_time_s: float = setting(1.0, "nominal sample time of the record, s, above 0")
    arl0_samples: float = setting(0.0, "0: every statistic's threshold as declared (mean_h, energy_h, ...); above 0: "
                                       "each statistic's threshold measured on the healthy runs the bands are "
                                       "calibrated on, for this average run length to a false alarm of the whole "
                                       "detector, samples (window maxima of CUSUMs restarted every 1000 samples, "
                                       "exponential tail, the target split evenly over the statistics: the physics "
                                       "detector's calibration, wavelet_fdi.calibration)", range=(0.0, math.inf),
                                  option="arl0")
    outside_hold_s: float = setting(300.0, "with a reference that confirms its alarms (the estimator): a deviation "
                                           "no fault hypothesis explains is announced once (outside calibration, "
                                           "WARN); the next ones only after this long without one, s (each is "
                                           "still kept and counted)", range=(0.0, math.inf))
    aj_energy_variance_ratio: float = setting(0.0, "energy CUSUMs on AJ (u^2 - k, u its deviation in healthy sigmas: "
                                                   "the physics detector's approximation-band energy, which a slow "
                                                   "change of the residual's spread or a probe's lag shows in) designed "
                                                   "for this variance ratio, above 1 (0: off)")
    aj_energy_h: float = setting(20.0, "those CUSUMs' threshold, above 0 (measured instead with arl0_samples)")

    def __post_init__(self) -> None:
        self.check()  # refused when made, as DetectorSettings are: a bad value never reaches a detector

    def check(self) -> "LearnedSettings":
        """Every value within its declared range, and the rules a range cannot say (an open end, an "off")."""
        check_declared_ranges(self, "learned-detector setting")
        try:
            wavelet_filters(self.wavelet)
        except ValueError as exc:
            raise UserError(str(exc)) from None
        if self.form not in LEARNED_FORMS:
            raise UserError(f"form must be one of {', '.join(LEARNED_FORMS)}, got {self.form!r}")
        if self.correction_samples < 0 or 0 < self.correction_samples < 1:
            raise UserError("correction_samples must be 0 (pure simulation) or at least 1")
        if not self.mean_h > 0:
            raise UserError("mean_h must be > 0")
        if self.energy_variance_ratio and not self.energy_variance_ratio > 1.0:
            raise UserError("energy_variance_ratio must be 0 (off) or above 1")
        if self.aj_energy_variance_ratio and not self.aj_energy_variance_ratio > 1.0:
            raise UserError("aj_energy_variance_ratio must be 0 (off) or above 1")
        if self.energy_down_variance_ratio and not 0.0 < self.energy_down_variance_ratio < 1.0:
            raise UserError("energy_down_variance_ratio must be 0 (off) or between 0 and 1")
        if not (self.energy_h > 0 and self.energy_down_h > 0 and self.repeat_h > 0 and self.residual_mean_h > 0
                and self.aj_energy_h > 0):
            raise UserError("energy_h, energy_down_h, repeat_h, residual_mean_h and aj_energy_h must be positive")
        if not 0.0 <= self.repeat_probability < 1.0:
            raise UserError("repeat_probability must be 0 (off) or between 0 and 1")
        if not 0 < self.freeze_ratio <= 1:
            raise UserError("freeze_ratio must be in (0, 1]")
        if not self.sample_time_s > 0:
            raise UserError("sample_time_s must be positive")
        if not 0.0 <= self.clear_fraction < 1.0:
            raise UserError("clear_fraction must be in [0, 1)")
        if self.arl0_samples and not (ARL_WINDOW_SAMPLES <= self.arl0_samples < math.inf):
            raise UserError(f"arl0_samples must be 0 (thresholds as declared) or at least {ARL_WINDOW_SAMPLES} (the "
                            "window its calibration measures CUSUM maxima in), finite")
        return self

    @classmethod
    def from_dict(cls, d: dict) -> "LearnedSettings":
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise UserError(f"unknown learned-detector setting(s): {', '.join(unknown)}")
        return cls(**d)  # checked when made

    def bands(self) -> list[str]:
        return [f"D{j + 1}" for j in range(self.level)] + [f"A{self.level}"]


@dataclass(frozen=True)
class SettingSpec:
    """One detector setting as declared in :class:`DetectorSettings`."""

    name: str
    type: Any
    default: Any
    help: str
    range: tuple[float, float] | None
    option: str | None
    exposed: bool

    @property
    def flag(self) -> str:
        """The CLI option: ``--arl0``, ``--wavelet``, ..."""
        return "--" + (self.option or self.name).replace("_", "-")

    @property
    def is_list(self) -> bool:
        return isinstance(self.default, tuple)


def setting_specs(exposed_only: bool = False, of: type = DetectorSettings) -> list[SettingSpec]:
    """Every setting a settings class declares with :func:`setting` (default: the physics detector's; the learned
    detector's are ``of=LearnedSettings``), or only those exposed as CLI options and node parameters, in
    declaration order."""
    hints = get_type_hints(of)
    out = [SettingSpec(f.name, hints[f.name], f.default, f.metadata["help"], f.metadata["range"],
                       f.metadata["option"], f.metadata["exposed"]) for f in fields(of)]
    return [s for s in out if s.exposed or not exposed_only]


def check_declared_ranges(settings: Any, what: str) -> None:
    """Every value of ``settings`` (a settings dataclass) within its declared range; ``what`` names the settings in
    the message ("detector setting", "learned-detector setting")."""
    for spec in setting_specs(of=type(settings)):
        _check_range(spec, getattr(settings, spec.name), what)


def settings_from_values(values: dict[str, Any], base: DetectorSettings | None = None) -> DetectorSettings:
    """Settings from option or parameter values (a list setting as a list or a comma-separated string), the
    others from ``base`` (or the defaults): the one conversion the CLI and the node share.

    >>> settings_from_values({"level": 2, "channels": "ph, level"}).channels
    ('ph', 'level')
    """
    out = dict(asdict(base)) if base is not None else {}
    for spec in setting_specs():
        if spec.name not in values:
            continue
        v = values[spec.name]
        if spec.is_list and isinstance(v, str):
            v = tuple(c.strip() for c in v.split(",") if c.strip())
        out[spec.name] = tuple(v) if spec.is_list else v
    return DetectorSettings(**out)


def _check_range(spec: SettingSpec, value: Any, what: str = "detector setting") -> None:
    if spec.range is None:
        return
    lo, hi = spec.range
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not (lo <= value <= hi):
        raise UserError(f"{what} {spec.name} must be a number in {_shown_range(spec)}, got {value!r}")


def _shown_range(spec: SettingSpec) -> str:
    if spec.range is None:
        return ""
    lo, hi = spec.range
    ends = [("" if math.isinf(v) else f"{int(v)}" if spec.type is int else f"{v:g}") for v in (lo, hi)]
    return f"{ends[0]}..{ends[1]}"


def settings_table_markdown(of: type = DetectorSettings, option_form: str | None = None) -> str:
    """The docs table of every setting ``of`` declares (docs/detector.md holds the physics and the learned
    detector's; a test checks they are current). ``option_form``: how every setting is given on the command
    line, ``{flag}`` standing for its option (the learned detector's: ``{flag}`` of ``phfdi calibrate``) and ``{name}``
    for its name; default: the exposed settings' own options and node parameters."""
    lines = ["| setting | default | range | option / node parameter | what |", "|---|---|---|---|---|"]
    for s in setting_specs(of=of):
        default = ", ".join(map(str, s.default)) if s.is_list else str(s.default).lower() if isinstance(
            s.default, bool) else f"{s.default:g}" if isinstance(s.default, float) else str(s.default)
        rng = _shown_range(s)
        where = f"`{option_form.format(name=s.name, flag=s.flag)}`" if option_form else f"`{s.flag}`, `{s.name}`" if s.exposed \
            else ""
        lines.append(f"| `{s.name}` | {default} | {rng} | {where} | {s.help} |")
    return "\n".join(lines) + "\n"


def _positive(x: object) -> bool:
    """A finite number above 0 (not a bool)."""
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) and x > 0


@dataclass
class Calibration:
    """Measured on healthy runs: noise levels and thresholds for a false-alarm target.

    ``phfdi calibrate`` writes one (YAML or JSON, :meth:`save`, :meth:`load`); one per shipped scenario
    comes with the package (:func:`load_default_calibration`). :meth:`check` says whether it fits a
    detector's settings and sample time.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> from wavelet_fdi import Calibration, DetectorSettings, load_default_calibration
    >>> calibration = load_default_calibration("paper", DetectorSettings())
    >>> calibration.check(DetectorSettings(), 1.0)  # fits: no error
    >>> path = calibration.save(Path(tempfile.mkdtemp()) / "paper.json")
    >>> Calibration.load(path).thresholds == calibration.thresholds
    True
    """

    scenario: str
    wavelet: str
    level: int
    sample_time_s: float
    arl0_samples: float
    #: channel -> band (and "raw") -> standard deviation of the healthy residual's coefficients
    sigma: dict[str, dict[str, float]]
    #: statistic name -> threshold
    thresholds: dict[str, float]
    #: design values the thresholds belong to, as in the file: the CUSUMs' design numbers, ``channels`` (a
    #: list of names) and ``raw_band`` (a bool)
    design: dict[str, Any] = field(default_factory=dict)
    seeds: list[int] = field(default_factory=list)
    #: recorded healthy runs it was made from (empty: simulated with ``seeds``)
    sources: list[str] = field(default_factory=list)
    healthy_samples: int = 0
    window_samples: int = 0
    method: str = ""
    tail_fits: dict[str, dict[str, float]] = field(default_factory=dict)
    peers: dict[str, dict] = field(default_factory=dict)
    version: int = 1

    def check(self, settings: DetectorSettings, sample_time_s: float) -> None:
        """Raise a UserError if the calibration does not belong to these settings."""
        if (self.wavelet, self.level) != (settings.wavelet, settings.level):
            raise UserError(f"calibration is for {self.wavelet} level {self.level}, detector uses "
                            f"{settings.wavelet} level {settings.level}: run phfdi calibrate for it")
        if abs(self.sample_time_s - sample_time_s) > 1e-9 * sample_time_s:
            raise UserError(f"calibration is for a {self.sample_time_s:g} s sample time, the scenario samples "
                            f"every {sample_time_s:g} s: run phfdi calibrate for it")
        missing = [s for s in settings.statistic_names() if s not in self.thresholds]
        if missing:
            raise UserError(f"calibration has no threshold for {missing[0]}: run phfdi calibrate with the "
                            f"same channels")
        channels = self.design.get("channels")
        if channels is not None and tuple(channels) != tuple(settings.channels):
            raise UserError(f"calibration is for channels {', '.join(channels)}, detector watches "
                            f"{', '.join(settings.channels)}: run phfdi calibrate with the same channels")
        if "raw_band" in self.design and bool(self.design["raw_band"]) != settings.raw_band:
            raise UserError(f"calibration was made with raw_band = {bool(self.design['raw_band'])}, detector "
                            f"uses {settings.raw_band}: run phfdi calibrate with the same settings")
        for ch in settings.channels:
            absent = [b for b in ("raw", *settings.bands()) if b not in self.sigma.get(ch, {})]
            if absent:
                raise UserError(f"calibration has no noise level for the {ch} channel's {absent[0]} band: run "
                                f"phfdi calibrate with the same settings")
        for key in ("mean_shift_sigma", "variance_ratio", "arl0_samples"):
            if key in self.design and abs(self.design[key] - getattr(settings, key)) > 1e-12 * abs(self.design[key]):
                raise UserError(f"calibration was made for {key} = {self.design[key]:g}, detector uses "
                                f"{getattr(settings, key):g}: run phfdi calibrate with the same settings")

    def save(self, path: str | Path, overwrite: bool = True) -> Path:
        """Write as YAML (.yaml/.yml) or JSON (.json), atomically (phfdi_base.outputs)."""
        import yaml

        path = Path(path)
        data = asdict(self)
        if path.suffix.lower() == ".json":
            text = json.dumps(data, indent=2) + "\n"
        elif path.suffix.lower() in (".yaml", ".yml"):
            text = yaml.safe_dump(data, sort_keys=False)
        else:
            raise UserError(f"cannot write a calibration to {path}: use a .yaml or .json file name")
        return write_text(path, text, overwrite)

    @classmethod
    def load(cls, path: str | Path) -> "Calibration":
        path = Path(path)
        if path.suffix.lower() == ".json":
            try:
                data = json.loads(path.read_text(encoding="utf-8"))
            except (FileNotFoundError, IsADirectoryError):
                raise UserError(f"no such calibration file: {path}") from None
            except (UnicodeDecodeError, json.JSONDecodeError) as exc:
                raise UserError(f"{path}: not a calibration file ({type(exc).__name__})") from None
        else:
            data = read_mapping(path, "calibration file",
                                "a mapping: not a calibration file written by phfdi calibrate")
        if not isinstance(data, dict):
            raise UserError(f"{path}: not a calibration file (expected a mapping)")
        try:
            cal = cls(**data)
        except TypeError as exc:
            raise UserError(f"{path}: not a calibration file ({exc})") from None
        cal._validate(path)
        return cal

    def _validate(self, path: Path) -> None:
        """Types and ranges of what the detector reads: one line naming the first bad key."""
        def bad(key: str, what: str) -> UserError:
            return UserError(f"{path}: not a calibration file ({key}: expected {what})")

        for key in ("scenario", "wavelet"):
            if not isinstance(getattr(self, key), str):
                raise bad(key, "a name")
        if not isinstance(self.level, int) or isinstance(self.level, bool) or not 1 <= self.level <= 12:
            raise bad("level", "an integer 1..12")
        for key in ("sample_time_s", "arl0_samples"):
            if not _positive(getattr(self, key)):
                raise bad(key, "a positive number")
        for key, table in (("sigma", self.sigma), ("thresholds", self.thresholds), ("design", self.design),
                           ("tail_fits", self.tail_fits), ("peers", self.peers)):
            if not isinstance(table, dict):
                raise bad(key, "a mapping")
        for ch, bands in self.sigma.items():
            if not isinstance(bands, dict) or not all(_positive(v) for v in bands.values()):
                raise bad(f"sigma.{ch}", "a mapping band: positive number")
        for name, h in self.thresholds.items():
            if not _positive(h):
                raise bad(f"thresholds.{name}", "a positive number")
        for key in ("mean_shift_sigma", "variance_ratio", "arl0_samples"):
            if key in self.design and not _positive(self.design[key]):
                raise bad(f"design.{key}", "a positive number")
        channels = self.design.get("channels")
        if channels is not None and not (isinstance(channels, list) and all(isinstance(c, str) for c in channels)):
            raise bad("design.channels", "a list of channel names")


def default_calibration_path(scenario: str, wavelet: str, level: int) -> Path:
    return CALIBRATION_DIR / f"{scenario}_{wavelet}_L{level}.yaml"


def load_default_calibration(scenario: str, settings: DetectorSettings) -> Calibration:
    """The calibration shipped for a scenario and the settings' wavelet and level.

    Raises
    ------
    UserError
        None is shipped for them (the message lists the shipped ones and the ``phfdi calibrate`` command
        that makes one).

    Examples
    --------
    >>> from wavelet_fdi import DetectorSettings, load_default_calibration
    >>> calibration = load_default_calibration("paper", DetectorSettings())
    >>> calibration.wavelet, calibration.level
    ('sym4', 3)
    """
    path = default_calibration_path(scenario, settings.wavelet, settings.level)
    if not path.exists():
        shipped = sorted(p.stem for p in CALIBRATION_DIR.glob("*.yaml")) if CALIBRATION_DIR.is_dir() else []
        raise UserError(f"no shipped calibration for scenario {scenario!r} with {settings.wavelet} level "
                        f"{settings.level} (shipped: {', '.join(shipped) or 'none'}); make one with "
                        f"phfdi calibrate --scenario {scenario} --wavelet {settings.wavelet} "
                        f"--level {settings.level} --out FILE and pass --calibration FILE")
    return Calibration.load(path)
