"""The paper loop's physics as a reference kind of the multichannel detector (issue 37: one detector core).

``physics``: the healthy plant and valves of a scenario (:class:`~wavelet_fdi.reference.HealthyReference`, the same
model the physics detector :class:`~wavelet_fdi.detector.StreamingDetector` runs) driven by the record's measured
valve commands; the residuals are the measured pH (and level, where a controller holds it) minus the model's
prediction, divided by the scenario's sensor noise, so that :class:`~wavelet_fdi.learned_detector.LearnedDetector`
watches them like any other reference's.

What the stream does, per sample, in the order of the record:

* at the first row it starts the model at the steady state of that row's commands and re-aligns it on the measured
  pH and level (:meth:`HealthyReference.initialize`);
* during the warm-up (``warmup_s``, :attr:`lags`: the detector gives no residual to its statistics before) it pulls
  the model's state toward the measurements at every block boundary by half of the block's mean residual, as the
  physics detector does: a plant need not sit at the steady state of its first commands;
* after it the model runs open loop. Slow mismatch is the multichannel detector's observer's (on the
  approximation band, frozen while an alarm is up), not the model's: a reference stream does not know when the
  detector is in alarm, and an observer that moved the model during a fault would learn the fault;
* the pH solve starts from a guess fixed per block of ``block_samples`` (by global sample index), so that any
  chunking of a record gives bit-identical residuals.

A missing command (NaN) holds the valve's last position, as the core valve does; a missing measurement gives a NaN
residual (the detector counts it as healthy and reports it). An alarm's fault is named by the physics detector's
isolation (:mod:`wavelet_fdi.physics_naming`, the kind's ``NAMERS`` entry), :data:`NAMING_AFTER_S` after the
detection. What this kind does not do, and the physics detector does: the set-point hold-off, re-aligning
after a command was missing for long, and naming again when the first naming was unsure.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from phfdi_base.errors import UserError

from .reference import HealthyReference

if TYPE_CHECKING:  # the schema (pydantic) is not needed to read a validated scenario
    from phfdi_base.spec import ScenarioSpec

    from .config import DetectorSettings, LearnedSettings

KIND = "physics"
COMMAND, OUTLET, PH, LEVEL = "valve_command_pct", "level_controller_output_pct", "ph_measured", "level_measured_cm"
#: share of a block's mean residual the warm-up moves the model's state by (the physics detector's warm-up gain)
WARMUP_GAIN = 0.5
#: time after a detection at which the fault is named (the physics detector's isolation delay, DetectorSettings)
NAMING_AFTER_S = 300.0


def design_settings(physics: DetectorSettings | None = None, sample_time_s: float = 1.0, **given: Any
                    ) -> LearnedSettings:
    """The multichannel detector's settings that carry the physics detector's design (its
    :class:`~wavelet_fdi.config.DetectorSettings`): the same wavelet and level; the residual's own mean (R) and AJ's
    mean designed for a shift of ``mean_shift_sigma`` (k half of it: in the residual's sigmas for R, in AJ's for AJ,
    where a shift of white noise reads 2^(J/2) times larger); energy CUSUMs for its ``variance_ratio`` on every band,
    the detail bands and AJ, as its own; its block
    (``block_samples``: an alarm clears only after a whole block without a crossing, so a valve that sticks and
    slips keeps one alarm up rather than raising one per slip); and its false-alarm target ``arl0_samples``, for
    which :func:`~wavelet_fdi.learned_detector.calibrate_bands` measures every threshold. ``given``: any setting
    of :class:`~wavelet_fdi.config.LearnedSettings` set otherwise."""
    from .config import DetectorSettings, LearnedSettings

    d = physics or DetectorSettings()
    design = dict(wavelet=d.wavelet, level=d.level, mean_k=0.5 * d.mean_shift_sigma * 2.0 ** (d.level / 2.0),
                  residual_mean_k=0.5 * d.mean_shift_sigma, energy_variance_ratio=d.variance_ratio,
                  aj_energy_variance_ratio=d.variance_ratio,
                  arl0_samples=d.arl0_samples, block_samples=d.block_samples, sample_time_s=float(sample_time_s))
    return LearnedSettings(**{**design, **given})


def _noise(value: float | None) -> float:
    """A sensor's noise standard deviation as the residual's unit (1 when the scenario says none)."""
    return float(value) if value is not None and math.isfinite(value) and value > 0 else 1.0


@dataclass(frozen=True)
class PhysicsReference:
    """A scenario's healthy loop, run on the record's measured commands (module docstring).

    Examples
    --------
    >>> from phfdi.scenario import load_scenario
    >>> ref = PhysicsReference.from_spec(load_scenario("paper"))
    >>> ref.channels
    ('valve_command_pct', 'level_controller_output_pct', 'ph_measured', 'level_measured_cm')
    >>> ref.residual_channels
    ('ph_measured', 'level_measured_cm')
    """

    scenario: dict  # a validated scenario (phfdi_base.spec.ScenarioSpec), as its file holds it
    warmup_s: float = 600.0
    block_samples: int = 256
    #: watch the level's residual too (where a controller holds the level); False: the pH alone, as the physics
    #: detector does by default (its ``channels``)
    watch_level: bool = True
    spec: Any = field(default=None, compare=False, repr=False)

    kind = KIND

    def __post_init__(self) -> None:
        if not (math.isfinite(self.warmup_s) and self.warmup_s >= 0):
            raise UserError(f"physics reference: warmup_s must be >= 0, got {self.warmup_s}")
        if int(self.block_samples) < 1:
            raise UserError(f"physics reference: block_samples must be >= 1, got {self.block_samples}")
        if self.spec is None:
            from phfdi_base.spec import validate_scenario  # the reference file's scenario, checked by its schema

            object.__setattr__(self, "spec", validate_scenario(self.scenario, "physics reference: scenario"))

    @classmethod
    def from_spec(cls, spec: ScenarioSpec, warmup_s: float = 600.0, block_samples: int = 256,
                  watch_level: bool = True) -> "PhysicsReference":
        """The reference of a validated scenario (its faults are dropped: the reference is the healthy loop)."""
        healthy = spec.model_copy(update={"faults": []})
        return cls(healthy.model_dump(mode="json"), float(warmup_s), int(block_samples), bool(watch_level), healthy)

    # ---- the protocol every reference kind shares ------------------------------------------
    @property
    def has_level(self) -> bool:
        return self.spec.setpoints.level_cm is not None

    @property
    def channels(self) -> tuple[str, ...]:
        """The record's channels this reference reads, in the order of the rows it is given."""
        return (COMMAND, OUTLET, PH, LEVEL) if self.has_level else (COMMAND, PH)

    @property
    def residual_channels(self) -> tuple[str, ...]:
        return (PH, LEVEL) if self.has_level and self.watch_level else (PH,)

    @property
    def naming_after_samples(self) -> int:
        """Samples after a detection the detector waits before naming the fault (the physics detector's isolation
        delay, :data:`NAMING_AFTER_S`: a stick-slip shows over a few controller cycles)."""
        return int(round(NAMING_AFTER_S / self.spec.sample_time_s))

    @property
    def lags(self) -> int:
        """Samples before the first residual the detector's statistics use: the model's warm-up."""
        return int(math.ceil(self.warmup_s / self.spec.sample_time_s))

    @property
    def sensor_noise(self) -> dict[str, float]:
        """The scenario's sensor noise standard deviations (1 where it says none), by channel ("ph", "level")."""
        s = self.spec.sensors
        return {"ph": _noise(s.ph.noise_std), "level": _noise(s.level.noise_std)}

    @property
    def noise(self) -> np.ndarray:
        """Each residual channel's unit: the scenario's sensor noise standard deviation."""
        sigma = self.sensor_noise
        return np.array([sigma["ph"]] + ([sigma["level"]] if len(self.residual_channels) > 1 else []))

    def new_state(self) -> "PhysicsStream":
        return PhysicsStream(self)

    def residuals(self, t_s: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """Residuals of a whole record (a fresh stream)."""
        return self.new_state().residuals(t_s, rows)

    def to_dict(self) -> dict:
        return {"kind": KIND, "scenario": self.scenario, "warmup_s": self.warmup_s,
                "block_samples": self.block_samples, "watch_level": self.watch_level}

    @classmethod
    def from_dict(cls, d: dict, where: str = "reference") -> "PhysicsReference":
        try:
            return cls(dict(d["scenario"]), float(d.get("warmup_s", 600.0)), int(d.get("block_samples", 256)),
                       bool(d.get("watch_level", True)))
        except (KeyError, TypeError, ValueError) as exc:
            raise UserError(f"{where}: not a physics reference ({exc})") from None


class PhysicsStream:
    """The model's state between chunks of one record (:meth:`residuals` keeps it)."""

    def __init__(self, ref: PhysicsReference, keep: bool = False) -> None:
        """``keep``: also keep every sample's prediction and a model snapshot at every block boundary
        (:attr:`kept`; what naming a fault re-runs the model for)."""
        self.ref = ref
        self.model = HealthyReference(ref.spec)
        self.kept: dict[str, Any] | None = ({"ph_pred": [], "level_pred": [], "flows": [], "opening": [],
                                              "snapshots": {}} if keep else None)
        self.index = 0  # global index of the next row
        self._guess = 7.0
        self._acc = np.zeros(4)  # this block's sums: pH residual, count, level residual, count
        self._last_pred = math.nan  # the last finite pH predicted (the next block's guess after the warm-up)
        self._unit = ref.noise

    def residuals(self, t_s: np.ndarray | None, rows: np.ndarray) -> np.ndarray:
        """The next rows' residuals (n, 1 or 2) in sensor-noise units; any chunking gives the same."""
        rows = np.atleast_2d(np.asarray(rows, dtype=float))
        n = len(rows)
        if t_s is None:
            t_s = (self.index + np.arange(n)) * self.ref.spec.sample_time_s
        t_s = np.asarray(t_s, dtype=float)
        out = np.empty((n, len(self.ref.residual_channels)))
        i = 0
        while i < n:
            if self.index == 0:
                self._start(float(t_s[i]), rows[i])
            if self.kept is not None and self.index % self.ref.block_samples == 0:
                self.kept["snapshots"][self.index] = self.model.snapshot()
            block = self.ref.block_samples
            end = min(n, i + block - self.index % block)
            out[i:end] = self._segment(t_s[i:end], rows[i:end])
            self.index += end - i
            if self.index % block == 0:
                self._end_block()
            i = end
        return out

    def columns(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Rows in the reference's channel order as (valve command, level-controller output, pH, level); NaN for
        the level's two where the scenario holds no level."""
        if self.ref.has_level:
            return rows[:, 0], rows[:, 1], rows[:, 2], rows[:, 3]
        nan = np.full(len(rows), math.nan)
        return rows[:, 0], nan, rows[:, 1], nan

    def _start(self, t0: float, row: np.ndarray) -> None:
        cmd, outlet, ph, level = (float(v[0]) for v in self.columns(row[None, :]))
        self.model.initialize(t0, cmd, outlet, level, None, ph)
        self._guess = self.model.ph

    def _segment(self, t: np.ndarray, rows: np.ndarray) -> np.ndarray:
        cmd, outlet, ph, level = self.columns(rows)
        pred = self.model.advance(t, cmd, outlet, self._guess)
        if self.kept is not None:
            for key, v in (("ph_pred", pred.ph), ("level_pred", pred.level_cm), ("flows", pred.flows),
                           ("opening", pred.openings)):
                self.kept[key].append(np.asarray(v, dtype=float))
        r_ph = ph - pred.ph
        r_lv = level - pred.level_cm
        for col, r in ((0, r_ph), (2, r_lv)):
            ok = np.isfinite(r)
            self._acc[col] += float(np.sum(r[ok]))
            self._acc[col + 1] += int(np.sum(ok))
        last = pred.ph[np.isfinite(pred.ph)]
        self._last_pred = float(last[-1]) if len(last) else math.nan
        res = np.column_stack([r_ph, r_lv]) if len(self._unit) > 1 else r_ph[:, None]
        return res / self._unit

    def _end_block(self) -> None:
        """Block boundary: the warm-up's pull toward the measurements, and the next block's pH-solve guess."""
        ph_sum, ph_n, lv_sum, lv_n = self._acc
        self._acc[:] = 0.0
        half = self.ref.block_samples // 2
        if self.index <= self.ref.lags and ph_n >= half:
            self.model.correct(WARMUP_GAIN * ph_sum / ph_n, WARMUP_GAIN * lv_sum / lv_n if lv_n >= half else 0.0)
            self._guess = self.model.ph
        elif math.isfinite(self._last_pred):
            self._guess = self._last_pred
