"""Streaming wavelet-residual fault detector (ROS-free core of the /fault_alarm node).

Per sample (see docs/detector.md):

1. inputs are put on the nominal sample grid (:mod:`wavelet_fdi.inputs`,
   which also defines what happens to bad input);
2. the healthy reference model (:mod:`wavelet_fdi.reference`) predicts the
   pH (and level) from the measured valve command; residual = measured -
   predicted;
3. a causal level-J stationary wavelet transform of each residual
   (:mod:`wavelet_fdi.filterbank`, PyWavelets filters) gives bands D1..DJ, AJ;
4. one-sided CUSUMs per band (:mod:`wavelet_fdi.statistics`): energy of
   every band, mean up and down of AJ, each against a threshold calibrated on
   healthy runs for the false-alarm target (:mod:`wavelet_fdi.calibration`);
5. a crossing raises an alarm (onset estimate, detection time, severity,
   dominant band, statistic and threshold); isolation
   (:mod:`wavelet_fdi.isolation`) names the fault some time later.

:class:`StreamingDetector` takes one sample (:meth:`~StreamingDetector.update`)
or a chunk (:meth:`~StreamingDetector.process`) and returns the events
(state changes) they caused. Any chunking of a record gives bit-identical
statistics and the same events: every recursion is evaluated left to right,
the reference's pH solve uses a per-block guess, and observer corrections,
snapshots and renormalisation happen at fixed sample indices. Memory is
bounded by ``history_samples``.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import TYPE_CHECKING, Any, Mapping

import numpy as np
import numpy.typing as npt

from .alarm_messages import exceedance
from .config import Calibration, DetectorSettings
from .filterbank import CausalSwt
from .history import History
from .inputs import InputRegularizer
from .isolation import FaultIsolator
from .reference import HealthyReference, KnownStart, ReferenceState
from .statistics import CusumBank, increments, parse_statistic

if TYPE_CHECKING:  # the schema (pydantic) is not needed to read a validated scenario
    from phfdi_base.spec import ScenarioSpec

WARMUP_OBSERVER_GAIN = 0.5  # fraction of a block's mean residual corrected per block during warm-up
OBSERVER_FREEZE_RATIO = 0.5  # no observer correction while a statistic is above this fraction of its threshold


@dataclass
class Alarm:
    """One detected fault episode. Times in seconds of the input's clock."""

    alarm_id: int
    onset_time_s: float
    detection_time_s: float
    statistic: str
    statistic_value: float
    threshold: float
    dominant_level: str
    #: mean normalised energy (coefficient / healthy sigma)^2 per pH band over onset..detection (1 = healthy)
    band_energy: dict[str, float]
    #: RMS of the pH residual over onset..detection (pH)
    severity_ph: float
    #: the same in healthy residual standard deviations
    severity_sigma: float
    fault_class: str = "pending"
    confidence: float = 0.0
    parameter: dict | None = None
    alternatives: list = field(default_factory=list)
    evidence: dict = field(default_factory=dict)
    isolation_time_s: float | None = None
    #: onset fitted by isolation (more accurate than the estimate at detection)
    onset_refined_s: float | None = None
    cleared_time_s: float | None = None
    #: when the episode ended: the first sample of the quiet stretch that cleared it (every statistic below
    #: clear_fraction of its threshold), or the last crossing when it cleared after clear_after_s without one
    episode_end_s: float | None = None
    onset_index: int = 0
    detection_index: int = 0

    def to_dict(self) -> dict:
        return asdict(self)

    def summary(self) -> dict:
        """The fields ``phfdi replay --json`` prints."""
        return {
            "onset_time": self.onset_refined_s if self.onset_refined_s is not None else self.onset_time_s,
            "onset_time_at_detection": self.onset_time_s,
            "detection_time": self.detection_time_s,
            "fault_class": self.fault_class,
            "severity": self.severity_ph,
            "severity_unit": "pH (RMS residual, onset to detection)",
            "confidence": self.confidence,
            "parameter": self.parameter,
            "statistic": self.statistic,
            "statistic_value": self.statistic_value,
            "threshold": self.threshold,
            "dominant_level": self.dominant_level,
            "alternatives": self.alternatives,
            "isolation_time": self.isolation_time_s,
            "cleared_time": self.cleared_time_s,
            "episode_end_time": self.episode_end_s,
        }


@dataclass
class Event:
    """A state change worth publishing: alarm raised, diagnosis, alarm cleared, input problem.

    Attributes
    ----------
    kind : {"alarm", "diagnosis", "cleared", "input"}
    time_s : float
        Time stamp of the sample that caused it (s).
    index : int
        That sample's index on the detector's grid.
    level : {"OK", "WARN", "ERROR"}
        Its diagnostic level (as on /diagnostics).
    message : str
        One line for a person.
    alarm : dict or None
        The alarm's summary (onset, detection, statistic, threshold, isolation) for alarm events.

    Examples
    --------
    >>> from wavelet_fdi import Event
    >>> Event("input", 12.0, 12, "WARN", "valve command missing").level
    'WARN'
    """

    kind: str  # "alarm" | "diagnosis" | "cleared" | "input"
    time_s: float
    index: int
    level: str  # diagnostic level: "OK", "WARN", "ERROR"
    message: str
    alarm: dict | None = None


def change_time_glr(u: np.ndarray, min_after: int = 3) -> int:
    """Most likely change position in u (healthy: N(0, 1)) to N(mu, s^2) for the last samples.

    Maximises m/2 (mean(u^2) - 1 - ln var(u)) over the m samples after the
    change (the generalised likelihood ratio for an unknown new mean and
    variance). Non-finite samples count as healthy zeros.
    """
    u = np.where(np.isfinite(u), u, 0.0)
    n = len(u)
    if n <= min_after:
        return 0
    s1 = np.cumsum(u[::-1])[::-1]
    s2 = np.cumsum((u * u)[::-1])[::-1]
    m = np.arange(n, 0, -1, dtype=float)
    var = np.maximum(s2 / m - (s1 / m) ** 2, 1e-12)
    llr = 0.5 * m * (s2 / m - 1.0 - np.log(var))
    llr[n - min_after + 1:] = -np.inf
    return int(np.argmax(llr))


class StreamingDetector:
    """Feed samples in time order; get events back. See the module docstring.

    Parameters
    ----------
    spec : ScenarioSpec
        The loop watched: its healthy reference model is built from the scenario's plant and valves.
    calibration : Calibration
        Noise levels and thresholds (:func:`~wavelet_fdi.config.load_default_calibration` or
        ``phfdi calibrate``); must match ``settings``.
    settings : DetectorSettings, optional
    isolate : bool
        Name the fault after an alarm (:mod:`wavelet_fdi.isolation`).
    record_trace : bool
        Keep every sample's residuals and statistics (:meth:`trace`; offline use only).

    Examples
    --------
    >>> from phfdi.loop import simulate
    >>> from phfdi.scenario import load_scenario
    >>> from wavelet_fdi import DetectorSettings, StreamingDetector, load_default_calibration
    >>> spec = load_scenario("paper", fault="friction", onset_s=800.0,
    ...                      overrides=["duration_s=1500", "setpoints.ph.initial=8", "setpoints.ph.changes=[]"])
    >>> run = simulate(spec)
    >>> settings = DetectorSettings(warmup_s=300.0)
    >>> detector = StreamingDetector(spec, load_default_calibration("paper", settings), settings, isolate=False)
    >>> events = detector.process({name: run[name] for name in ("time_s", "ph_measured", "valve_command_pct")})
    >>> [(e.kind, e.time_s > 800.0) for e in events], detector.state
    ([('alarm', True)], 'alarm')
    >>> detector.update(1500.0, 8.0, 30.0)  # one more sample: no new event
    []
    """

    def __init__(self, spec: ScenarioSpec, calibration: Calibration, settings: DetectorSettings | None = None,
                 isolate: bool = True, record_trace: bool = False, known: KnownStart | None = None) -> None:
        """``record_trace`` keeps every sample's residuals, coefficients and statistics (offline
        analysis, calibration and evaluation only: memory grows with the record); ``known``: the
        starting point and plant model already computed for ``spec`` (the detector node's part)."""
        self.settings = s = settings or DetectorSettings()
        calibration.check(s, spec.sample_time_s)
        self.calibration = calibration
        self.dt_s = spec.sample_time_s
        self.reference = HealthyReference(spec, known)
        self.names = s.statistic_names()
        self.k = np.array([s.reference_value(n) for n in self.names])
        self.h = np.array([calibration.thresholds[n] for n in self.names])
        self._parsed = [parse_statistic(n) for n in self.names]
        self.bands = s.bands()
        self._row = {b: i for i, b in enumerate(s.rows())}
        self.channels = s.channels
        self.swt = {ch: CausalSwt(s.wavelet, s.level) for ch in self._transformed_channels()}
        self.cusum = CusumBank(len(self.names))
        self.block = s.block_samples
        self.warmup_samples = max(int(math.ceil(s.warmup_s / self.dt_s)), self.swt["ph"].fill_samples)
        self.clear_samples = int(math.ceil(s.clear_after_s / self.dt_s))
        # 0 switches the quiet rule off: a stretch never reaches a length beyond any record
        self.quiet_samples = int(math.ceil(s.clear_quiet_s / self.dt_s)) if s.clear_quiet_s > 0 else 2**62
        self.holdoff_samples = int(math.ceil(s.setpoint_holdoff_s / self.dt_s))
        other = tuple(n for i, n in enumerate(self.reference.feed_names) if i != self.reference.valve_index)
        self.inputs = InputRegularizer(self.dt_s, max(1, int(round(s.max_gap_s / self.dt_s))),
                                       max(1, int(round(s.command_timeout_s / self.dt_s))), other)
        n_feeds = len(self.reference.feed_names)
        self.history = History(s.history_samples, {
            "t": 1, "ph": 1, "level": 1, "command": 1, "ph_pred": 1, "level_pred": 1, "monitor": 1,
            "flows": n_feeds, "opening": 1, "setpoint": 1, "coef": s.level + 2})
        self.snapshots: dict[int, ReferenceState] = {}
        self.isolator = None
        if isolate:

            self.isolator = FaultIsolator(spec, calibration, s, known)
        self.alarms: list[Alarm] = []
        self.state = "starting"
        self._initialized = False
        self._reset_index = 0
        self._warmup_end = 0
        self._guess = 7.0
        self._acc = np.zeros(4)  # block sums: pH residual, count, level residual, count
        self._last_confirm = -1
        self._loud_last = -1  # last sample where a statistic was at or above clear_fraction of its threshold
        self._due: list[tuple[int, int]] = []  # (global index, alarm id) isolations to run
        self._retries: dict[int, int] = {}  # alarm id -> isolations repeated because unsure
        self._isolated_at: dict[int, int] = {}  # alarm id -> last sample its isolation used
        self._sp_last = math.nan
        self._sp_change_index = -(10**12)
        self._s_last = np.zeros(len(self.names))
        self._stale_prev = False
        self.samples_processed = 0
        self.observer_corrections = 0
        self._trace: dict[str, list] | None = {} if record_trace else None

    def _transformed_channels(self) -> tuple[str, ...]:
        return tuple(dict.fromkeys(("ph",) + tuple(self.settings.channels)))

    # ---- public API ---------------------------------------------------------------------
    def update(self, t_s: float, ph_measured: float, valve_command_pct: float, level_measured_cm: float = math.nan,
               outlet_command_pct: float = math.nan, ph_setpoint: float = math.nan) -> list[Event]:
        """One sample; returns the events it caused (usually none)."""
        return self.process({"time_s": [t_s], "ph_measured": [ph_measured], "valve_command_pct": [valve_command_pct],
                             "level_measured_cm": [level_measured_cm],
                             "level_controller_output_pct": [outlet_command_pct], "ph_setpoint": [ph_setpoint]})

    def process(self, chunk: Mapping[str, npt.ArrayLike | None]) -> list[Event]:
        """A chunk of samples given as arrays named like run signals (time_s, ph_measured,
        valve_command_pct; optional level_measured_cm, level_controller_output_pct, ph_setpoint,
        <feed>_flow_ml_s of feeds the valve does not drive). Missing optional signals are NaN."""
        cols = {k: np.atleast_1d(np.asarray(v, dtype=float)) for k, v in chunk.items() if v is not None}
        if "time_s" not in cols:
            raise ValueError("a chunk needs time_s")
        n = len(cols["time_s"])
        cols = {k: v for k, v in cols.items() if len(v) == n}
        grid = self.inputs.push(cols)
        events: list[Event] = []
        i = 0
        while i < len(grid):
            if grid.reset[i] or not self._initialized:
                events += self._restart(grid, i)
            if grid.rewarm[i]:
                # the valve moved unseen: start again from the steady state of the returned command, re-aligned on
                # pH and level (a re-alignment alone left the buffer's total where the held command had put it)
                others = {f: float(v[i]) for f, v in grid.other_flows.items()}
                self.reference.initialize(float(grid.t_s[i]), float(grid.command[i]), float(grid.outlet_command[i]),
                                          float(grid.level[i]), others, float(grid.ph[i]))
                self._guess = self.reference.ph
                self._warmup_end = int(grid.index[i]) + self.warmup_samples
                events.append(Event("input", float(grid.t_s[i]), int(grid.index[i]), "WARN",
                                    "valve command back: reference warming up again"))
            gi = int(grid.index[i])
            end = min(len(grid), i + self.block - gi % self.block)
            flags = np.flatnonzero(grid.reset[i + 1:end] | grid.rewarm[i + 1:end])
            if len(flags):
                end = i + 1 + int(flags[0])
            stale = grid.stale[i:end]
            starts = np.flatnonzero(stale & ~np.concatenate(([self._stale_prev], stale[:-1])))
            if len(starts):
                k = i + int(starts[0])
                events.append(Event("input", float(grid.t_s[k]), int(grid.index[k]), "WARN",
                                    "valve command missing too long: detection held"))
            self._stale_prev = bool(stale[-1])
            events += self._segment(grid, i, end)
            i = end
        return events

    def flush(self) -> list[Event]:
        """End of a record: run pending isolations on the data there is."""
        events = []
        last = self.history.end - 1
        pending = list(dict.fromkeys(a for _, a in self._due))
        self._due.clear()
        for alarm_id in pending:
            if last > self._isolated_at.get(alarm_id, -1):  # only with data the last isolation lacked
                events += self._isolate(alarm_id, last)
        self._due.clear()
        return events

    def status(self) -> dict:
        """Heartbeat: state, worst statistic against its threshold, the active alarm."""
        ratio = self._s_last / self.h
        worst = int(np.argmax(ratio))
        active = self.alarms[-1] if self.alarms and self.state == "alarm" else None
        return {
            "state": self.state,
            "level": {"alarm": "ERROR", "inhibited": "WARN", "warmup": "OK", "ok": "OK"}.get(self.state, "OK"),
            "worst_statistic": self.names[worst],
            "worst_statistic_value": float(self._s_last[worst]),
            "worst_threshold": float(self.h[worst]),
            "alarm": active.summary() if active else None,
            "samples_processed": self.samples_processed,
        }

    def monitor(self) -> tuple[float, dict[str, float]]:
        """The last sample processed, for a live view: its time (s) and ``ph_residual``, ``level_residual_cm``
        (measured minus predicted; NaN where not measured) and every CUSUM statistic over its threshold
        (``ratio:<name>``; 1 raises the alarm). Time NaN before the first sample."""
        hist = self.history
        if hist.end == 0:
            return math.nan, {}
        row = {k: float(hist.read(hist.end - 1, hist.end, k)[0]) for k in ("t", "ph", "ph_pred", "level", "level_pred")}
        values = {"ph_residual": row["ph"] - row["ph_pred"], "level_residual_cm": row["level"] - row["level_pred"]}
        values.update({f"ratio:{n}": float(s / h) for n, s, h in zip(self.names, self._s_last, self.h)})
        return row["t"], values

    def diagnostics(self) -> dict:
        """Input health and internals for /diagnostics (numbers and flags only)."""
        d: dict[str, Any] = dict(self.inputs.counts)
        d.update({
            "state": self.state,
            "command_stale": self.inputs.command_stale,
            "sample_interval_s": self.inputs.measured_interval_s(),
            "sample_rate_mismatch": self.inputs.sample_rate_mismatch(),
            "nominal_sample_time_s": self.dt_s,
            "reference_resets": self.reference.resets,
            "observer_corrections": self.observer_corrections,
            "samples_processed": self.samples_processed,
            "alarms": len(self.alarms),
            "wavelet": self.settings.wavelet,
            "level": self.settings.level,
            "arl0_samples": self.settings.arl0_samples,
        })
        return d

    # ---- internals ----------------------------------------------------------------------
    def _restart(self, grid, i: int) -> list[Event]:
        """(Re)initialise the reference at sample i's inputs; filters and statistics from zero."""
        gi = int(grid.index[i])
        others = {f: float(v[i]) for f, v in grid.other_flows.items()}
        self.reference.initialize(float(grid.t_s[i]), float(grid.command[i]), float(grid.outlet_command[i]),
                                  float(grid.level[i]), others, float(grid.ph[i]))
        self._guess = self.reference.ph
        for f in self.swt.values():
            f.reset()
        self.cusum.restart(gi)
        self._s_last[:] = 0.0
        self._acc[:] = 0.0
        self._reset_index = gi
        self._warmup_end = gi + self.warmup_samples
        self.snapshots = {gi: self.reference.snapshot()}
        events = []
        if self._initialized:
            events.append(Event("input", float(grid.t_s[i]), gi, "WARN",
                                "gap or clock jump in the time stamps: window reset, reference warming up again"))
        if self.state == "alarm":
            events += self._clear(gi, float(grid.t_s[i]), "window reset")
        self.state = "warmup"
        self._initialized = True
        return events

    def _segment(self, grid, a: int, b: int) -> list[Event]:
        """Samples a..b-1 of the grid: all inside one block, no reset after a."""
        idx0 = int(grid.index[a])
        n = b - a
        t = grid.t_s[a:b]
        others = {f: v[a:b] for f, v in grid.other_flows.items()}
        pred = self.reference.advance(t, grid.command[a:b], grid.outlet_command[a:b], self._guess, others)
        ph, level = grid.ph[a:b], grid.level[a:b]
        r_ph = ph - pred.ph
        r_lv = level - pred.level_cm
        ok_ph = np.isfinite(r_ph)
        ok_lv = np.isfinite(r_lv)
        residual = {"ph": np.where(ok_ph, r_ph, 0.0), "level": np.where(ok_lv, r_lv, 0.0)}
        idx = idx0 + np.arange(n)
        live = grid.real[a:b] & ~grid.stale[a:b] & (idx >= self._warmup_end)
        if self.holdoff_samples:
            live &= ~self._holdoff(grid.setpoint[a:b], idx)
        mask = {"ph": live & ok_ph, "level": live & ok_lv}
        coefs = {}
        for ch, f in self.swt.items():
            out = f.process(residual[ch])
            coefs[ch] = np.vstack((out.details, out.approx[None, :], residual[ch][None, :]))
        z = np.empty((len(self.names), n))
        for row, (ch, band, kind) in enumerate(self._parsed):
            sigma = self.calibration.sigma[ch]["raw" if band == "R" else band]
            z[row] = np.where(mask[ch], increments(kind, coefs[ch][self._row[band]] / sigma, self.k[row]), 0.0)
        # block sums for the observer, accumulated left to right (chunking-independent)
        sel = live & ok_ph
        sel_l = live & ok_lv
        for col, vals in ((0, np.where(sel, r_ph, 0.0)), (1, sel.astype(float)),
                          (2, np.where(sel_l, r_lv, 0.0)), (3, sel_l.astype(float))):
            self._acc[col] = np.cumsum(np.concatenate(([self._acc[col]], vals)))[-1]
        self.history.write(idx0, {
            "t": t, "ph": ph, "level": level, "command": grid.command[a:b], "ph_pred": pred.ph,
            "level_pred": pred.level_cm, "monitor": mask["ph"].astype(float), "flows": pred.flows,
            "opening": pred.openings, "setpoint": grid.setpoint[a:b], "coef": coefs["ph"].T})
        events = self._statistics(z, idx0, t)
        if self._trace is not None:
            self._record(idx, t, ph, pred, residual, mask, coefs, z)
        self.samples_processed += n
        if self.state == "warmup" and idx0 + n > self._warmup_end:
            self.state = "ok"
        if grid.stale[b - 1] and self.state != "alarm":
            self.state = "inhibited"
        elif self.state == "inhibited" and not grid.stale[b - 1]:
            self.state = "warmup" if idx0 + n <= self._warmup_end else "ok"
        last = idx0 + n - 1
        if self.state == "alarm" and last >= self._last_confirm + self.clear_samples:
            events += self._clear(self._last_confirm + self.clear_samples,
                                  float(t[min(n - 1, self._last_confirm + self.clear_samples - idx0)]),
                                  "no threshold crossing for clear_after_s")
        events += self._run_due(last)
        if (last + 1) % self.block == 0:
            self._end_block(last + 1, float(pred.ph[-1]))
        return events

    def _record(self, idx, t, ph, pred, residual, mask, coefs, z) -> None:
        tr = self._trace
        assert tr is not None, "called with record_trace=True only"
        for key, val in (("index", idx), ("time_s", t), ("ph_measured", ph), ("ph_predicted", pred.ph),
                         ("level_predicted_cm", pred.level_cm), ("ph_residual", residual["ph"]),
                         ("level_residual_cm", residual["level"]), ("ph_monitored", mask["ph"]),
                         ("level_monitored", mask["level"]), ("increments", z.T)):
            tr.setdefault(key, []).append(np.asarray(val))
        for ch, c in coefs.items():
            tr.setdefault(f"{ch}_coefficients", []).append(c.T)

    def trace(self) -> dict[str, np.ndarray]:
        """Per-sample record (needs ``record_trace=True``): residuals, coefficients (N, J+2: D1..DJ,
        AJ, R = the residual) per channel, monitored masks, CUSUM increments (N, n_statistics) in :attr:`names` order."""
        if self._trace is None:
            raise ValueError("detector was built without record_trace=True")
        return {k: np.concatenate(v) for k, v in self._trace.items()}

    def _holdoff(self, setpoint: np.ndarray, idx: np.ndarray) -> np.ndarray:
        """True where a setpoint change happened less than setpoint_holdoff_s ago."""
        held = np.empty(len(setpoint), dtype=bool)
        for k, (sp, i) in enumerate(zip(setpoint.tolist(), idx.tolist())):
            if math.isfinite(sp):
                if math.isfinite(self._sp_last) and sp != self._sp_last:
                    self._sp_change_index = i
                self._sp_last = sp
            held[k] = i - self._sp_change_index < self.holdoff_samples
        return held

    def _statistics(self, z: np.ndarray, idx0: int, t: np.ndarray) -> list[Event]:
        events = []
        pos = 0
        n = z.shape[1]
        while pos < n:
            saved = (self.cusum.c.copy(), self.cusum.m.copy(), self.cusum.last_zero.copy())
            s_val = self.cusum.update(z[:, pos:], idx0 + pos)
            over = s_val > self.h[:, None]
            cols = np.flatnonzero(over.any(axis=0))
            if not len(cols):
                self._s_last = s_val[:, -1]
                events += self._track_quiet(s_val, idx0 + pos, t[pos:])
                break
            c = int(cols[0])
            # redo up to the crossing so the change-time estimate sees only samples up to it
            self.cusum.c, self.cusum.m, self.cusum.last_zero = saved
            s_val = self.cusum.update(z[:, pos:pos + c + 1], idx0 + pos)
            events += self._track_quiet(s_val, idx0 + pos, t[pos:pos + c + 1])
            col = s_val[:, -1]
            row = int(np.argmax(np.where(over[:, c], col / self.h, -np.inf)))
            gi = idx0 + pos + c
            events += self._crossing(row, float(col[row]), int(self.cusum.last_zero[row]), gi, float(t[pos + c]))
            self.cusum.restart(gi)
            self._s_last = np.zeros(len(self.names))
            pos += c + 1
        return events

    def _run_due(self, last: int) -> list[Event]:
        """Run the isolations due at or before sample ``last`` in sample order (a retry one schedules may be due
        too): before a clear inside a chunk they must run as they would have sample by sample."""
        events: list[Event] = []
        while True:
            ready = sorted(d for d in self._due if d[0] <= last)
            if not ready:
                return events
            self._due.remove(ready[0])
            events += self._isolate(ready[0][1], ready[0][0])

    def _track_quiet(self, s_val: np.ndarray, first: int, t: np.ndarray) -> list[Event]:
        """Clear the alarm where every statistic has stayed below clear_fraction of its threshold for
        clear_quiet_s: the statistics fell back, the fault is gone (sample by sample, so any chunking clears at
        the same sample). The episode ends at the first sample of that quiet stretch."""
        loud = (s_val >= self.settings.clear_fraction * self.h[:, None]).any(axis=0)
        gi = first + np.arange(s_val.shape[1])
        last_loud = np.maximum.accumulate(np.where(loud, gi, self._loud_last))
        self._loud_last = int(last_loud[-1])
        if self.state != "alarm":
            return []
        quiet = np.flatnonzero((gi - last_loud >= self.quiet_samples) & (gi > self._last_confirm))
        if not len(quiet):
            return []
        j = int(quiet[0])
        events = self._run_due(int(gi[j]))  # isolations due before the clear, as sample by sample
        end = self.history.read(int(last_loud[j]) + 1, int(last_loud[j]) + 2, "t")
        end_t = float(end[0]) if len(end) and math.isfinite(end[0]) else float(t[j]) - self.quiet_samples * self.dt_s
        return events + self._clear(int(gi[j]), float(t[j]), f"every statistic below {self.settings.clear_fraction:g} "
                                    f"of its threshold for {self.settings.clear_quiet_s:g} s (since {end_t:g} s)", end_t)

    def _crossing(self, row: int, value: float, last_zero: int, gi: int, t_s: float) -> list[Event]:
        events: list[Event] = []
        if self.state == "alarm":
            if gi - self._last_confirm <= self.clear_samples:
                self._last_confirm = gi
                return events
            events += self._clear(self._last_confirm + self.clear_samples, t_s, "no threshold crossing for clear_after_s")
        ch, band, kind = self._parsed[row]
        # change time: the Gaussian mean-and-variance GLR on the raw pH residual, searched from a
        # filter length before the CUSUM's last zero (the band's filter smears the change)
        lo = max(last_zero - 2 * self.swt["ph"].fill_samples, self._reset_index, self.history.start)
        onset = lo + change_time_glr((self.history.read(lo, gi + 1, "ph") - self.history.read(lo, gi + 1, "ph_pred"))
                                     / self.calibration.sigma["ph"]["raw"])
        t_hist = self.history.read(onset, onset + 1, "t")
        onset_t = float(t_hist[0]) if len(t_hist) and math.isfinite(t_hist[0]) else t_s - (gi - onset) * self.dt_s
        r = self.history.read(onset, gi + 1, "ph") - self.history.read(onset, gi + 1, "ph_pred")
        r = r[np.isfinite(r)]
        sev = float(np.sqrt(np.mean(r**2))) if len(r) else math.nan
        sigma = self.calibration.sigma["ph"]["raw"]
        coef = self.history.read(onset, gi + 1, "coef")
        mon = self.history.read(onset, gi + 1, "monitor") > 0
        energy = {}
        for j, b in enumerate(self.bands):
            u = coef[mon, j] / self.calibration.sigma["ph"][b] if mon.any() else np.array([math.nan])
            energy[b] = float(np.mean(u**2))
        dominant = max(energy, key=lambda b: energy[b] if math.isfinite(energy[b]) else -1.0)
        alarm = Alarm(len(self.alarms) + 1, onset_t, t_s, self.names[row], value, float(self.h[row]), dominant,
                      energy, sev, sev / sigma if sigma > 0 else math.nan, onset_index=onset, detection_index=gi)
        self.alarms.append(alarm)
        self.state = "alarm"
        self._last_confirm = gi
        if self.isolator is not None:
            for d in self.settings.isolation_delays_s:
                self._due.append((gi + int(round(d / self.dt_s)), alarm.alarm_id))
        events.append(Event("alarm", t_s, gi, "ERROR",
                            f"fault detected by {alarm.statistic} ({exceedance(value, alarm.threshold)}); "
                            f"onset estimate {onset_t:g} s", alarm.summary()))
        return events

    def _clear(self, gi: int, t_s: float, why: str, episode_end_s: float | None = None) -> list[Event]:
        alarm = self.alarms[-1]
        alarm.cleared_time_s = t_s
        if episode_end_s is None:  # cleared for want of a crossing: the episode ended at its last one
            last = self.history.read(self._last_confirm, self._last_confirm + 1, "t")
            episode_end_s = float(last[0]) if len(last) and math.isfinite(last[0]) else None
        alarm.episode_end_s = episode_end_s
        self.state = "ok"
        self._due = [(d, a) for d, a in self._due if a != alarm.alarm_id]
        return [Event("cleared", t_s, gi, "OK", f"alarm {alarm.alarm_id} cleared: {why}", alarm.summary())]

    def _isolate(self, alarm_id: int, end_index: int) -> list[Event]:
        alarm = self.alarms[alarm_id - 1]
        if alarm.cleared_time_s is not None or self.isolator is None:
            return []
        start = alarm.onset_index
        snaps = [k for k in self.snapshots if k <= start and k >= self.history.start]
        if not snaps:
            return []
        snap_index = max(snaps)
        result = self.isolator.isolate(self.history, self.snapshots[snap_index], snap_index, alarm.onset_index,
                                       end_index)
        self._isolated_at[alarm_id] = end_index
        s = self.settings
        unsure = result is None or result.fault_class == "unknown" or result.confidence < s.isolation_confidence
        if unsure and self._retries.get(alarm_id, 0) < s.isolation_retries and s.isolation_delays_s:
            # more data may separate the candidates (a stuck valve slips, a limit cycle develops)
            self._retries[alarm_id] = self._retries.get(alarm_id, 0) + 1
            self._due.append((end_index + int(round(s.isolation_delays_s[-1] / self.dt_s)), alarm_id))
        if result is None:
            return []
        t_end = self.history.read(end_index, end_index + 1, "t")
        alarm.isolation_time_s = float(t_end[0]) if len(t_end) else None
        alarm.fault_class = result.fault_class
        alarm.confidence = result.confidence
        alarm.parameter = result.parameter
        alarm.alternatives = result.alternatives
        alarm.evidence = result.evidence
        alarm.onset_refined_s = result.evidence.get("onset_fit_s")
        return [Event("diagnosis", alarm.isolation_time_s or math.nan, end_index, "ERROR",
                      f"alarm {alarm.alarm_id}: most likely {result.fault_class} "
                      f"(confidence {result.confidence:.2f})", alarm.summary())]

    def _end_block(self, next_index: int, last_pred_ph: float) -> None:
        """Block boundary: observer correction, pH-solve guess, snapshot, bounded statistics."""
        s = self.settings
        ph_sum, ph_n, lv_sum, lv_n = self._acc
        self._acc[:] = 0.0
        warm = next_index <= self._warmup_end
        gain = WARMUP_OBSERVER_GAIN if warm else (
            min(1.0, self.block * self.dt_s / s.observer_time_constant_s) if s.observer_time_constant_s > 0 else 0.0)
        busy = self.state in ("alarm", "inhibited") or np.any(self._s_last > OBSERVER_FREEZE_RATIO * self.h)
        if gain > 0.0 and not busy and ph_n >= self.block // 2:
            self.reference.correct(gain * ph_sum / ph_n, gain * lv_sum / lv_n if lv_n >= self.block // 2 else 0.0)
            self.observer_corrections += 1
            self._guess = self.reference.ph
        elif math.isfinite(last_pred_ph):
            self._guess = last_pred_ph
        self.cusum.renormalise()
        self.snapshots[next_index] = self.reference.snapshot()
        for k in [k for k in self.snapshots if k < self.history.start]:
            del self.snapshots[k]
