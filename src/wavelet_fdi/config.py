"""Detector settings and the calibration file the detector loads.

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
from dataclasses import asdict, dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from phfdi_base.errors import UserError
from phfdi_base.yamlfile import read_mapping

from .filterbank import wavelet_filters
from .statistics import energy_reference, parse_statistic

CALIBRATION_DIR = Path(str(resources.files("wavelet_fdi"))) / "calibrations"
CHANNELS = ("ph", "level")


@dataclass
class DetectorSettings:
    """Design of the detector (units in the names; see docs/detector.md).

    Every field has a default (the shipped calibrations' design); the statistics it runs are
    :meth:`statistic_names`, each needing a threshold in the :class:`Calibration`.

    Examples
    --------
    >>> from wavelet_fdi import DetectorSettings
    >>> settings = DetectorSettings(level=3, warmup_s=300.0)
    >>> settings.statistic_names()
    ['ph.R.mean_up', 'ph.R.mean_down', 'ph.D1.energy', 'ph.D2.energy', 'ph.D3.energy', 'ph.A3.energy']
    """

    wavelet: str = "sym4"
    level: int = 3
    #: average run length to a false alarm of the whole detector, in samples
    arl0_samples: float = 1e5
    #: residual channels watched for detection ("ph", optionally "level")
    channels: tuple[str, ...] = ("ph",)
    #: watch the residual's own mean (R) besides the wavelet bands' energies; False: the paper's bands only
    raw_band: bool = True
    #: mean CUSUMs on the approximation band are designed for a residual mean shift of this many sigma
    mean_shift_sigma: float = 1.0
    #: energy CUSUMs are designed for this variance ratio
    variance_ratio: float = 4.0
    #: observer corrections, pH-solve guesses and state snapshots happen every this many samples
    block_samples: int = 256
    #: no alarms until this long after a start or a reset (the reference settles, the filters fill)
    warmup_s: float = 600.0
    #: time constant of the slow observer that removes model-plant mismatch; 0 switches it off
    observer_time_constant_s: float = 3600.0
    #: a gap in the time stamps longer than this resets the window; shorter gaps are bridged
    max_gap_s: float = 10.0
    #: the valve command may be missing this long before the detector stops trusting the reference
    command_timeout_s: float = 10.0
    #: an alarm clears after this long without a statistic crossing its threshold
    clear_after_s: float = 1800.0
    #: isolation runs this long after a detection (and again at each further delay given)
    isolation_delays_s: tuple[float, ...] = (300.0,)
    #: when the diagnosis is unsure (confidence below isolation_confidence or class unknown), isolate
    #: again, one isolation delay later each time, at most this many times
    isolation_retries: int = 2
    isolation_confidence: float = 0.9
    #: past samples kept for isolation (bounds memory)
    history_samples: int = 4096
    #: statistics are held this long after a setpoint change (0: off)
    setpoint_holdoff_s: float = 0.0

    def __post_init__(self) -> None:
        self.channels = tuple(self.channels)
        self.isolation_delays_s = tuple(float(d) for d in self.isolation_delays_s)
        for c in self.channels:
            if c not in CHANNELS:
                raise UserError(f"detector channel {c!r} unknown; use {', '.join(CHANNELS)}")
        if not self.arl0_samples > 1.0:
            raise UserError(f"arl0_samples must exceed 1, got {self.arl0_samples}")
        if self.block_samples < 8:
            raise UserError(f"block_samples must be at least 8, got {self.block_samples}")
        if self.history_samples < 2 * self.block_samples:
            raise UserError("history_samples must be at least twice block_samples")
        if not self.mean_shift_sigma > 0:
            raise UserError("mean_shift_sigma must be positive")
        if not self.variance_ratio > 1.0:
            raise UserError(f"variance_ratio must exceed 1, got {self.variance_ratio}")
        if not 1 <= self.level <= 10:
            raise UserError(f"wavelet level must be between 1 and 10, got {self.level}")
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
        """channel.band.kind for every CUSUM the detector runs.

        With ``raw_band`` (default): the residual's mean (R, up and down) and
        the energy of every wavelet band. Without it, the paper's bands only:
        the mean of AJ replaces R's. (AJ's mean is R's mean seen through a
        low-pass filter: the same information, later.)
        """
        out: list[str] = []
        a = f"A{self.level}"
        for ch in self.channels:
            if self.raw_band:
                out.extend((f"{ch}.R.mean_up", f"{ch}.R.mean_down"))
            for b in self.bands():
                if b == a and not self.raw_band:
                    out.extend((f"{ch}.{b}.mean_up", f"{ch}.{b}.mean_down"))
                out.append(f"{ch}.{b}.energy")
        return out

    def reference_value(self, name: str) -> float:
        """k of a statistic: the energy CUSUM's for variance_ratio; the mean CUSUM's for a shift of
        mean_shift_sigma residual standard deviations, which A_J carries 2^(J/2) times (its DC gain)."""
        _, band, kind = parse_statistic(name)
        if kind == "energy":
            return energy_reference(self.variance_ratio)
        gain = 1.0 if band == "R" else 2.0 ** (0.5 * self.level)
        return 0.5 * self.mean_shift_sigma * gain


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

    def save(self, path: str | Path) -> Path:
        """Write as YAML (.yaml/.yml) or JSON (.json)."""
        import yaml

        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        data = asdict(self)
        if path.suffix.lower() == ".json":
            path.write_text(json.dumps(data, indent=2) + "\n")
        elif path.suffix.lower() in (".yaml", ".yml"):
            path.write_text(yaml.safe_dump(data, sort_keys=False))
        else:
            raise UserError(f"cannot write a calibration to {path}: use a .yaml or .json file name")
        return path

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
