"""The multichannel detector's settings (:class:`LearnedSettings`, every reference kind's: physics, learned and
estimator), each declared once with :func:`setting`: default, help and range. The CLI options (``phfdi calibrate
--NAME VALUE``), the docs table (:func:`settings_table_markdown`) and the range checks are derived from it. What
is measured on healthy runs (band noise, thresholds) is the reference file's (``phfdi calibrate``); files shipped
with the package are in :data:`CALIBRATION_DIR`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from importlib import resources
from pathlib import Path
from typing import Any, get_type_hints

from phfdi_base.errors import UserError

from .filterbank import wavelet_filters

#: the reference files shipped with the package (``LearnedModel.load`` takes them by name: paper_physics, ...)
CALIBRATION_DIR = Path(str(resources.files("wavelet_fdi"))) / "calibrations"
#: samples per window in which a threshold calibration restarts the CUSUMs and takes their maxima
ARL_WINDOW_SAMPLES = 1000


def setting(default: Any, help: str, *, range: tuple[float, float] | None = None, option: str | None = None) -> Any:
    """A detector setting, declared once: default, help and allowed range; ``option``: its CLI option's name where
    it is not the setting's (``--arl0``). :func:`setting_specs` derives the options of ``phfdi calibrate`` and
    ``evaluate`` from it, and the docs table (:func:`settings_table_markdown`)."""
    return field(default=default, metadata={"help": help, "range": range, "option": option})


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
        self.check()  # refused when made: a bad value never reaches a detector

    def check(self) -> "LearnedSettings":
        """Every value within its declared range, and the rules a range cannot say (an open end, an "off")."""
        check_declared_ranges(self, "detector setting")
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
            raise UserError(f"unknown detector setting(s): {', '.join(unknown)}")
        return cls(**d)  # checked when made

    def bands(self) -> list[str]:
        return [f"D{j + 1}" for j in range(self.level)] + [f"A{self.level}"]


@dataclass(frozen=True)
class SettingSpec:
    """One detector setting as declared in :class:`LearnedSettings`."""

    name: str
    type: Any
    default: Any
    help: str
    range: tuple[float, float] | None
    option: str | None

    @property
    def flag(self) -> str:
        """The CLI option: ``--arl0``, ``--wavelet``, ..."""
        return "--" + (self.option or self.name).replace("_", "-")


def setting_specs(of: type = LearnedSettings) -> list[SettingSpec]:
    """Every setting a settings class declares with :func:`setting`, in declaration order."""
    hints = get_type_hints(of)
    return [SettingSpec(f.name, hints[f.name], f.default, f.metadata["help"], f.metadata["range"],
                        f.metadata["option"]) for f in fields(of)]


def check_declared_ranges(settings: Any, what: str) -> None:
    """Every value of ``settings`` (a settings dataclass) within its declared range; ``what`` names the settings in
    the message ("detector setting")."""
    for spec in setting_specs(of=type(settings)):
        _check_range(spec, getattr(settings, spec.name), what)


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


def settings_table_markdown(of: type = LearnedSettings, option_form: str = "{flag}") -> str:
    """The docs table of every setting ``of`` declares (docs/detector.md holds it; a test checks it is current).
    ``option_form``: how a setting is given on the command line, ``{flag}`` standing for its option and ``{name}``
    for its name."""
    lines = ["| setting | default | range | option | what |", "|---|---|---|---|---|"]
    for s in setting_specs(of=of):
        default = str(s.default).lower() if isinstance(s.default, bool) else f"{s.default:g}" \
            if isinstance(s.default, float) else str(s.default)
        where = f"`{option_form.format(name=s.name, flag=s.flag)}`"
        lines.append(f"| `{s.name}` | {default} | {_shown_range(s)} | {where} | {s.help} |")
    return "\n".join(lines) + "\n"
