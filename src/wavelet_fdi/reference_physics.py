"""The paper loop's physics as a reference kind of the multichannel detector (issue 37: one detector core).

``physics``: the healthy plant and valves of a scenario (:class:`~wavelet_fdi.reference.HealthyReference`, the same
model the paper's physics detector ran, retired on 2026-12-07 for this kind) driven by the record's measured
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

A missing command (NaN) holds the valve's last position, as the core valve does, for up to ``command_timeout_s``;
missing longer, the valve may have moved unseen, so the model cannot be trusted: its residuals are NaN (the
detector counts them as healthy, holding detection) until the command returns, and then the model restarts on that
row as at a record's start (steady state of its commands, re-aligned on the measured pH and level) and warms up again
for ``warmup_s`` (NaN residuals, the warm-up's pulls at block boundaries). The stream says both in
:attr:`PhysicsStream.notices`, and marks the rows it holds in :attr:`PhysicsStream.last_held` (the detector reports
them with that reason, not as a missing measurement). A missing measurement gives a NaN residual (the detector counts
it as healthy and reports it). An alarm's fault is named by the physics detector's isolation
(:mod:`wavelet_fdi.physics_naming`, the kind's ``NAMERS`` entry), :data:`NAMING_AFTER_S` after the detection.
``setpoint_holdoff_s`` (off by default, as in the physics detector) holds the residuals that long after a pH
setpoint change (the model still runs; for a plant whose model follows setpoint transients poorly); on, the reference
reads ``ph_setpoint`` too.
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

    from .config import LearnedSettings

KIND = "physics"
COMMAND, OUTLET, PH, LEVEL = "valve_command_pct", "level_controller_output_pct", "ph_measured", "level_measured_cm"
SETPOINT = "ph_setpoint"
#: share of a block's mean residual the warm-up moves the model's state by (the physics detector's warm-up gain)
WARMUP_GAIN = 0.5
#: time after a detection at which the fault is named by default (the physics detector's isolation delay)
NAMING_AFTER_S = 300.0
#: the reference's own block: pH-solve guesses and the warm-up's pulls every this many samples (the detector's block
#: in the design too)
BLOCK_SAMPLES = 256
#: the physics detector's design, which :func:`design_settings` carries over: its filter bank (wavelet, level), the
#: residual mean shift its mean CUSUMs are designed for (residual sigmas), the variance ratio of its energy CUSUMs,
#: its false-alarm target (samples) and block (samples)
PHYSICS_DESIGN: dict[str, Any] = {"wavelet": "sym4", "level": 3, "mean_shift_sigma": 1.0, "variance_ratio": 4.0,
                                  "arl0_samples": 1e5, "block_samples": BLOCK_SAMPLES}


#: readings no plant gives (a pH off any pH scale, a level below the tank's bottom or absurdly high): a broken
#: reading, taken as missing (the physics detector's input check)
MEASUREMENT_RANGES = {"ph_measured": (-1.0, 15.0), "level_measured_cm": (0.0, 1e4)}
#: the scenario's settings the healthy model runs on (the commands are the record's, so the controllers, setpoints,
#: duration and seed are not among them)
MODEL_KEYS = ("plant", "sample_time_s", "valves", "sensors", "feeds", "plugins")


def _differences(a: Any, b: Any, where: str) -> list[str]:
    """Dotted paths where two parsed scenario values differ (dicts compared key by key)."""
    if isinstance(a, dict) and isinstance(b, dict):
        return [k for key in sorted(set(a) | set(b)) for k in _differences(a.get(key), b.get(key), f"{where}.{key}")]
    return [] if a == b else [where]


def follow_scenario(model: Any, spec: ScenarioSpec, what: str = "record") -> tuple[Any, str | None]:
    """A detector model (:class:`~wavelet_fdi.learned_detector.LearnedModel`) whose physics reference runs
    ``spec``'s plant where it differs from the scenario it was calibrated on, and a note saying so (None: no
    change; other reference kinds are returned as they are). Its band scales and thresholds stay the calibration's,
    as the physics detector keeps its shipped calibration for a scenario's variants."""
    ref = model.reference
    if getattr(ref, "kind", None) != KIND:
        return model, None
    followed, changed = ref.for_scenario(spec)
    if not changed:
        return model, None
    from dataclasses import replace

    shown = ", ".join(changed[:4]) + (f" and {len(changed) - 4} more" if len(changed) > 4 else "")
    verb = "differs" if len(changed) == 1 else "differ"
    return replace(model, reference=followed), (
        f"the physics reference's model follows the {what}'s own scenario ({shown} {verb} from scenario "
        f"{ref.spec.name!r}, which its band scales and thresholds were calibrated on)")


def design_settings(sample_time_s: float = 1.0, **given: Any) -> LearnedSettings:
    """The multichannel detector's settings that carry the physics detector's design (:data:`PHYSICS_DESIGN`): the
    same wavelet and level; the residual's own mean (R) and AJ's mean designed for a shift of ``mean_shift_sigma``
    (k half of it: in the residual's sigmas for R, in AJ's for AJ, where a shift of white noise reads 2^(J/2) times
    larger); energy CUSUMs for its ``variance_ratio`` on every band, the detail bands and AJ, as its own; its block
    (``block_samples``: an alarm clears only after a whole block without a crossing, so a valve that sticks and
    slips keeps one alarm up rather than raising one per slip); and its false-alarm target ``arl0_samples``, for
    which :func:`~wavelet_fdi.learned_detector.calibrate_bands` measures every threshold. ``given``: any setting
    of :class:`~wavelet_fdi.config.LearnedSettings` set otherwise (a ``level`` given moves AJ's k with it)."""
    from .config import LearnedSettings

    d = PHYSICS_DESIGN
    level = int(given.get("level", d["level"]))
    design = dict(wavelet=d["wavelet"], level=level, mean_k=0.5 * d["mean_shift_sigma"] * 2.0 ** (level / 2.0),
                  residual_mean_k=0.5 * d["mean_shift_sigma"], energy_variance_ratio=d["variance_ratio"],
                  aj_energy_variance_ratio=d["variance_ratio"], arl0_samples=d["arl0_samples"],
                  block_samples=d["block_samples"], sample_time_s=float(sample_time_s))
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
    block_samples: int = BLOCK_SAMPLES
    #: watch the level's residual too (where a controller holds the level); False: the pH alone, as the physics
    #: detector does by default (its ``channels``)
    watch_level: bool = True
    #: a valve command missing longer than this holds detection and restarts the model when it returns (the
    #: physics detector's ``command_timeout_s``)
    command_timeout_s: float = 10.0
    #: residuals are held this long after a pH setpoint change (0: off, the default; the physics detector's
    #: ``setpoint_holdoff_s``); on, the reference reads the record's ``ph_setpoint`` too
    setpoint_holdoff_s: float = 0.0
    spec: Any = field(default=None, compare=False, repr=False)
    #: the fault is named this long after a detection (and again as long after that while the naming is unsure;
    #: the physics detector's ``isolation_delays_s``): long enough for a stick-slip to show over a few controller
    #: cycles, short enough that the fit's window holds little else
    naming_after_s: float = NAMING_AFTER_S

    kind = KIND

    def __post_init__(self) -> None:
        if not (math.isfinite(self.warmup_s) and self.warmup_s >= 0):
            raise UserError(f"physics reference: warmup_s must be >= 0, got {self.warmup_s}")
        if int(self.block_samples) < 1:
            raise UserError(f"physics reference: block_samples must be >= 1, got {self.block_samples}")
        for name in ("command_timeout_s", "setpoint_holdoff_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise UserError(f"physics reference: {name} must be >= 0, got {value}")
        if not (math.isfinite(self.naming_after_s) and self.naming_after_s > 0):
            raise UserError(f"physics reference: naming_after_s must be > 0, got {self.naming_after_s}")
        if self.spec is None:
            from phfdi_base.spec import validate_scenario  # the reference file's scenario, checked by its schema

            object.__setattr__(self, "spec", validate_scenario(self.scenario, "physics reference: scenario"))

    @classmethod
    def from_spec(cls, spec: ScenarioSpec, warmup_s: float = 600.0, block_samples: int = BLOCK_SAMPLES,
                  watch_level: bool = True, command_timeout_s: float = 10.0,
                  setpoint_holdoff_s: float = 0.0, naming_after_s: float = NAMING_AFTER_S) -> "PhysicsReference":
        """The reference of a validated scenario (its faults are dropped: the reference is the healthy loop)."""
        healthy = spec.model_copy(update={"faults": []})
        return cls(healthy.model_dump(mode="json"), float(warmup_s), int(block_samples), bool(watch_level),
                   float(command_timeout_s), float(setpoint_holdoff_s), healthy, float(naming_after_s))

    def for_scenario(self, spec: ScenarioSpec) -> tuple["PhysicsReference", list[str]]:
        """This reference with ``spec``'s healthy loop as its model (its options kept), and the settings of the
        model that differ (:data:`MODEL_KEYS`, dotted: ``valves.ph.max_flow_ml_s``); itself and ``[]`` when
        none does. A record that says its own scenario (a simulated run, a bag of the loop graph) is watched with
        that scenario's plant, as the physics detector watches it, rather than with the one calibrated on."""
        mine = self.spec.model_copy(update={"faults": []}).model_dump(mode="json")
        theirs = spec.model_copy(update={"faults": []}).model_dump(mode="json")
        changed = [k for key in MODEL_KEYS for k in _differences(mine.get(key), theirs.get(key), key)]
        if not changed:
            return self, []
        return PhysicsReference.from_spec(spec, self.warmup_s, self.block_samples, self.watch_level,
                                          self.command_timeout_s, self.setpoint_holdoff_s,
                                          self.naming_after_s), changed

    # ---- the protocol every reference kind shares ------------------------------------------
    @property
    def has_level(self) -> bool:
        return self.spec.setpoints.level_cm is not None

    @property
    def channels(self) -> tuple[str, ...]:
        """The record's channels this reference reads, in the order of the rows it is given (the setpoint last,
        read only for the hold-off)."""
        plant = (COMMAND, OUTLET, PH, LEVEL) if self.has_level else (COMMAND, PH)
        return plant + ((SETPOINT,) if self.setpoint_holdoff_s > 0 else ())

    @property
    def residual_channels(self) -> tuple[str, ...]:
        return (PH, LEVEL) if self.has_level and self.watch_level else (PH,)

    @property
    def naming_after_samples(self) -> int:
        """Samples after a detection the detector waits before naming the fault (:attr:`naming_after_s`)."""
        return max(1, int(round(self.naming_after_s / self.spec.sample_time_s)))

    @property
    def lags(self) -> int:
        """Samples before the first residual the detector's statistics use: the model's warm-up."""
        return int(math.ceil(self.warmup_s / self.spec.sample_time_s))

    @property
    def command_timeout_samples(self) -> int:
        """Consecutive samples without a valve command after which detection is held (at least 1)."""
        return max(1, int(round(self.command_timeout_s / self.spec.sample_time_s)))

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
                "block_samples": self.block_samples, "watch_level": self.watch_level,
                "command_timeout_s": self.command_timeout_s, "setpoint_holdoff_s": self.setpoint_holdoff_s,
                "naming_after_s": self.naming_after_s}

    @classmethod
    def from_dict(cls, d: dict, where: str = "reference") -> "PhysicsReference":
        try:
            return cls(dict(d["scenario"]), float(d.get("warmup_s", 600.0)),
                       int(d.get("block_samples", BLOCK_SAMPLES)),
                       bool(d.get("watch_level", True)), float(d.get("command_timeout_s", 10.0)),
                       float(d.get("setpoint_holdoff_s", 0.0)), None,
                       float(d.get("naming_after_s", NAMING_AFTER_S)))
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
        self._warm_end = ref.lags  # the warm-up's pulls run at block boundaries up to this global index
        self._missing_for = 0  # rows without a valve command just before the next row
        self._hold_until = 0  # rows before this global index give no residual (warming up after a restart)
        self._setpoint = math.nan  # the last finite pH setpoint seen
        self._setpoint_changed = -(10**12)  # global index of the last setpoint change
        #: (global row index, what the stream did) for the detector to report: detection held, model restarted
        self.notices: list[tuple[int, str]] = []
        self._bad_before: dict[str, bool] = {}  # per measurement: the last row's reading was off any plausible one
        #: the last call's rows whose residual the stream held (NaN by its own rule, not a missing measurement)
        self.last_held = np.zeros(0, dtype=bool)

    def residuals(self, t_s: np.ndarray | None, rows: np.ndarray) -> np.ndarray:
        """The next rows' residuals (n, 1 or 2) in sensor-noise units; any chunking gives the same."""
        rows = np.atleast_2d(np.asarray(rows, dtype=float))
        n = len(rows)
        if t_s is None:
            t_s = (self.index + np.arange(n)) * self.ref.spec.sample_time_s
        t_s = np.asarray(t_s, dtype=float)
        if n == 0:
            self.last_held = np.zeros(0, dtype=bool)
            return np.empty((0, len(self.ref.residual_channels)))
        rows = self._measurements_checked(rows)
        stale, restart = self._command_gaps(rows[:, 0])
        was_stale = np.concatenate(([self._missing_for > self.ref.command_timeout_samples], stale[:-1]))
        for k in np.flatnonzero(stale & ~was_stale):
            self.notices.append((self.index + int(k), f"valve command missing for more than "
                                                      f"{self.ref.command_timeout_s:g} s: detection held"))
        out = np.empty((n, len(self.ref.residual_channels)))
        held = np.zeros(n, dtype=bool)
        i = 0
        while i < n:
            if self.index == 0:
                self._start(float(t_s[i]), rows[i])
            elif restart[i]:
                self._restart(float(t_s[i]), rows[i])
            if self.kept is not None and (self.index % self.ref.block_samples == 0 or restart[i]):
                self.kept["snapshots"][self.index] = self.model.snapshot()
            block = self.ref.block_samples
            end = min(n, i + block - self.index % block)
            later = np.flatnonzero(restart[i + 1:end])
            end = i + 1 + int(later[0]) if len(later) else end
            out[i:end] = self._segment(t_s[i:end], rows[i:end])
            held[i:end] = stale[i:end] | (self.index + np.arange(end - i) < self._hold_until)
            self.index += end - i
            if self.index % block == 0:
                self._end_block()
            i = end
        self._missing_for = self._missing_after(rows[:, 0])
        if self.ref.setpoint_holdoff_s > 0:
            held |= self._after_setpoint_change(rows[:, -1], self.index - n)
        self.notices.sort(key=lambda notice: notice[0])
        out[held] = math.nan
        self.last_held = held
        return out

    def _measurements_checked(self, rows: np.ndarray) -> np.ndarray:
        """The rows with a pH off any pH scale or a level off any tank (:data:`MEASUREMENT_RANGES`) as missing (NaN):
        such a value is a broken reading, not a plant state, and would put a residual of thousands of sensor sigmas
        into the statistics. Each stretch of them is said in :attr:`notices`."""
        out = None
        for channel, (low, high) in MEASUREMENT_RANGES.items():
            col = self.ref.channels.index(channel) if channel in self.ref.channels else None
            if col is None:
                continue
            v = rows[:, col]
            bad = ~np.isnan(v) & ~((v >= low) & (v <= high))
            if not bad.any():
                self._bad_before[channel] = False
                continue
            before = np.concatenate(([self._bad_before.get(channel, False)], bad[:-1]))
            for k in np.flatnonzero(bad & ~before):
                self.notices.append((self.index + int(k), f"{channel} = {v[k]:g}: off any plausible reading "
                                                           f"({low:g} to {high:g}); taken as missing"))
            self._bad_before[channel] = bool(bad[-1])
            out = rows.copy() if out is None else out
            out[bad, col] = math.nan
        return rows if out is None else out

    @property
    def holding(self) -> bool:
        """Detection is held after the last row by the stream's own rule: the valve command missing too long, or
        the model warming up again after it returned (not the setpoint hold-off, which is operation)."""
        return self._missing_for > self.ref.command_timeout_samples or self.index < self._hold_until

    def _command_gaps(self, command: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per row: the command has been missing longer than the timeout (stale), and the command is back after
        such a stretch (restart), counting the rows missing before this call."""
        n = len(command)
        ok = np.isfinite(command)
        pos = np.arange(n)
        last_ok = np.maximum.accumulate(np.where(ok, pos, -1))
        run = np.where(last_ok >= 0, pos - last_ok, pos + 1 + self._missing_for)  # rows missing, this one included
        limit = self.ref.command_timeout_samples
        stale = run > limit
        before = np.concatenate(([self._missing_for], run[:-1]))  # rows missing just before each row
        return stale, ok & (before > limit)

    def _after_setpoint_change(self, setpoint: np.ndarray, first: int) -> np.ndarray:
        """Per row: a pH setpoint change (between finite values) happened less than ``setpoint_holdoff_s`` ago."""
        finite = np.flatnonzero(np.isfinite(setpoint))
        values = setpoint[finite]
        before = np.concatenate(([self._setpoint], values[:-1]))
        changes = finite[np.isfinite(before) & (values != before)]
        last = np.full(len(setpoint), self._setpoint_changed, dtype=np.int64)
        last[changes] = first + changes
        last = np.maximum.accumulate(last)
        if len(values):
            self._setpoint = float(values[-1])
        if len(last):
            self._setpoint_changed = int(last[-1])
        limit = int(math.ceil(self.ref.setpoint_holdoff_s / self.ref.spec.sample_time_s))
        return first + np.arange(len(setpoint)) - last < limit

    def _missing_after(self, command: np.ndarray) -> int:
        ok = np.flatnonzero(np.isfinite(command))
        return len(command) - 1 - int(ok[-1]) if len(ok) else self._missing_for + len(command)

    def _restart(self, t_s: float, row: np.ndarray) -> None:
        """The command is back after a long gap: the model starts again on this row, as at a record's start, and
        warms up again (no residual, the warm-up's pulls) for ``warmup_s``."""
        self._start(t_s, row)
        self._acc[:] = 0.0
        self._hold_until = self._warm_end = self.index + self.ref.lags
        self.notices.append((self.index, f"valve command back: the model restarts on the measurements and warms up "
                                         f"again for {self.ref.warmup_s:g} s"))

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
        if self.index <= self._warm_end and ph_n >= half:
            self.model.correct(WARMUP_GAIN * ph_sum / ph_n, WARMUP_GAIN * lv_sum / lv_n if lv_n >= half else 0.0)
            self._guess = self.model.ph
        elif math.isfinite(self._last_pred):
            self._guess = self._last_pred
