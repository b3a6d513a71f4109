"""From raw, possibly broken sample streams to a regular grid of samples.

The detector works on the nominal sample grid t_anchor + k dt. Each raw
sample goes to slot k = floor((t - t_anchor) / dt + 1/2). What happens to
bad input (every case is counted in :attr:`InputRegularizer.counts`; none
raises):

============================  ==========================================================
non-finite or absurd stamp    dropped (``bad_time``; absurd: 2^50 samples from the first)
same time stamp again         dropped (``duplicate_stamps``)
time stamp going backwards    dropped (``out_of_order``); after more than max_gap
                              such samples in a row, each later than the one before,
                              the stream is taken to have a new clock: re-anchored and
                              the window reset (``time_resets``); repeated or shuffled
                              past stamps (strays) are no clock
faster sample rate            samples landing in an already filled slot are dropped
                              (``extra_samples``): the stream is decimated to the grid
gap up to max_gap samples     the missing slots are bridged: commands interpolated between
                              the samples around the gap (the valve kept receiving commands
                              the detector did not see; holding them instead misleads the
                              reference during setpoint transients), no measurement
                              (``missing_samples``)
gap over max_gap samples      window reset: reference re-initialised, filters and
                              statistics restarted, warm-up again (``gap_resets``)
slower sample rate            shows as bridged gaps; flagged when the median interval
                              of the last 31 samples is off by more than 10 %
                              (``sample_rate_mismatch``)
NaN/inf or out-of-range pH    sample kept for the reference, no residual (imputed 0 in
                              the filters, statistics not updated; ``nonfinite_ph``,
                              ``out_of_range_ph``)
inf or out-of-range level     same for the level channel (``bad_level``; range 0..1e4 cm);
                              NaN: no level reading (a plant without level sensor)
NaN/inf valve command         the reference valve holds its position (``nonfinite_command``);
                              missing for longer than command_timeout: the reference can
                              no longer be trusted: statistics held (``command_stale``)
                              until commands return, then warm-up again
inf outlet command            the outlet valve holds (``nonfinite_outlet_command``); NaN: not
                              given, the outlet valve holds too
============================  ==========================================================
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

#: raw input signals (names from the run catalogue); other feeds' flows may be added as <feed>_flow_ml_s
INPUT_SIGNALS = ("time_s", "ph_measured", "valve_command_pct", "level_measured_cm",
                 "level_controller_output_pct", "ph_setpoint")
PH_RANGE = (-1.0, 15.0)
LEVEL_RANGE_CM = (0.0, 1e4)
RATE_WINDOW = 31
RATE_TOLERANCE = 0.1
MAX_SLOT = 2**50  # samples from the anchor; further stamps are rejected as bad


@dataclass
class GridBatch:
    """Grid samples produced from one raw chunk (all arrays of equal length)."""

    index: np.ndarray  # global grid index (int64), consecutive
    t_s: np.ndarray
    ph: np.ndarray  # NaN where unusable
    command: np.ndarray  # NaN where missing (the valve holds)
    level: np.ndarray
    outlet_command: np.ndarray
    setpoint: np.ndarray
    other_flows: dict[str, np.ndarray]
    real: np.ndarray  # a received sample (False: a bridged slot)
    reset: np.ndarray  # restart the window before this sample
    stale: np.ndarray  # valve command missing for too long
    rewarm: np.ndarray  # commands came back after being stale: warm up again from here

    def __len__(self) -> int:
        return len(self.index)


def concat(a: GridBatch, b: GridBatch) -> GridBatch:
    keys = ("index", "t_s", "ph", "command", "level", "outlet_command", "setpoint", "real", "reset", "stale", "rewarm")
    merged = {k: np.concatenate((getattr(a, k), getattr(b, k))) for k in keys}
    others = {f: np.concatenate((a.other_flows.get(f, np.full(len(a), np.nan)), b.other_flows.get(f, np.full(len(b), np.nan))))
              for f in set(a.other_flows) | set(b.other_flows)}
    return GridBatch(other_flows=others, **merged)


@dataclass
class InputRegularizer:
    dt_s: float
    max_gap_samples: int
    command_timeout_samples: int
    other_feeds: tuple[str, ...] = ()
    counts: dict[str, int] = field(default_factory=dict)
    _anchor: float | None = None
    _last_slot: int = -1
    _last_t: float = -math.inf
    _last_raw_t: float = -math.inf
    _next_index: int = 0
    _backwards_run: int = 0
    _backwards_last_t: float = math.inf  # the last sample of that run
    _cmd_missing_run: int = 0
    _stale: bool = False
    _intervals: deque = field(default_factory=lambda: deque(maxlen=RATE_WINDOW))
    _last_inputs: tuple = (math.nan, math.nan, {})

    COUNTERS = ("samples_received", "samples_used", "bad_time", "duplicate_stamps", "out_of_order",
                "extra_samples", "missing_samples", "gaps_bridged", "gap_resets", "time_resets",
                "nonfinite_ph", "out_of_range_ph", "bad_level", "nonfinite_command",
                "nonfinite_outlet_command", "command_stale_episodes")

    def __post_init__(self) -> None:
        for c in self.COUNTERS:
            self.counts.setdefault(c, 0)

    # ---- status ---------------------------------------------------------------------
    @property
    def command_stale(self) -> bool:
        return self._stale

    def measured_interval_s(self) -> float | None:
        return float(np.median(self._intervals)) if self._intervals else None

    def sample_rate_mismatch(self) -> bool:
        m = self.measured_interval_s()
        return m is not None and len(self._intervals) >= RATE_WINDOW and abs(m - self.dt_s) > RATE_TOLERANCE * self.dt_s

    # ---- main entry --------------------------------------------------------------------
    def push(self, cols: dict[str, np.ndarray]) -> GridBatch:
        t = cols["time_s"]
        n = len(t)
        self.counts["samples_received"] += n
        if self._anchor is None and n > 1:
            # the first sample anchors the grid; the rest may then take the fast path
            head = self._slow_path({k: v[:1] for k, v in cols.items()})
            self.counts["samples_received"] -= n - 1
            tail = self.push({k: v[1:] for k, v in cols.items()})
            return concat(head, tail)
        fast = self._fast_path(cols)
        if fast is not None:
            return fast
        return self._slow_path(cols)

    def _columns(self, cols: dict[str, np.ndarray], n: int):
        nan = np.full(n, np.nan)
        get = lambda k: np.asarray(cols[k], dtype=float) if k in cols and cols[k] is not None else nan  # noqa: E731
        others = {f: get(f"{f}_flow_ml_s") for f in self.other_feeds if f"{f}_flow_ml_s" in cols}
        return (get("ph_measured"), get("valve_command_pct"), get("level_measured_cm"),
                get("level_controller_output_pct"), get("ph_setpoint"), others)

    def _fast_path(self, cols: dict[str, np.ndarray]) -> GridBatch | None:
        """A clean chunk (on-grid stamps, finite pH and command, no stale command) in one go."""
        t = np.asarray(cols["time_s"], dtype=float)
        n = len(t)
        if n == 0 or self._anchor is None or self._stale or self._backwards_run:
            return None
        if not np.all(np.isfinite(t)) or self._last_slot + n >= MAX_SLOT:
            return None
        slots = np.floor((t - self._anchor) / self.dt_s + 0.5)
        expected = self._last_slot + 1 + np.arange(n)
        if (not np.array_equal(slots, expected) or not t[0] > self._last_t or not t[0] >= self._last_raw_t
                or np.any(np.diff(t) <= 0.0)):
            return None
        ph, cmd, level, ocmd, sp, others = self._columns(cols, n)
        if not (np.all(np.isfinite(cmd)) and np.all(np.isfinite(ph)) and np.all((ph >= PH_RANGE[0]) & (ph <= PH_RANGE[1]))):
            return None
        lvl_ok = (level > LEVEL_RANGE_CM[0]) & (level < LEVEL_RANGE_CM[1])
        lvl_bad = int(np.count_nonzero(~lvl_ok & ~np.isnan(level)))
        oc_bad = int(np.count_nonzero(np.isinf(ocmd)))
        self.counts["bad_level"] += lvl_bad
        self.counts["nonfinite_outlet_command"] += oc_bad
        self.counts["samples_used"] += n
        first = [t[0] - self._last_raw_t] if t[0] > self._last_raw_t else []
        self._intervals.extend(np.concatenate((first, np.diff(t)))[-RATE_WINDOW:].tolist())
        self._last_raw_t = float(t[-1])
        self._last_slot = int(slots[-1])
        self._last_t = float(t[-1])
        self._cmd_missing_run = 0
        self._last_inputs = (float(cmd[-1]), float(ocmd[-1]) if math.isfinite(ocmd[-1]) else math.nan,
                             {f: float(v[-1]) for f, v in others.items()})
        index = self._next_index + np.arange(n, dtype=np.int64)
        self._next_index += n
        false = np.zeros(n, dtype=bool)
        return GridBatch(index, t.copy(), ph, cmd, np.where(lvl_ok, level, np.nan),
                         np.where(np.isfinite(ocmd), ocmd, np.nan), sp, others,
                         np.ones(n, dtype=bool), false, false.copy(), false.copy())

    def _slow_path(self, cols: dict[str, np.ndarray]) -> GridBatch:
        """Sample by sample: place each on the grid (or drop it), bridge short gaps, check the values."""
        t_arr = np.asarray(cols["time_s"], dtype=float)
        n = len(t_arr)
        ph, cmd, level, ocmd, sp, others = self._columns(cols, n)
        out: dict[str, list] = {k: [] for k in ("index", "t", "ph", "cmd", "level", "ocmd", "sp", "real",
                                                "reset", "stale", "rewarm")}
        out_other: dict[str, list] = {f: [] for f in others}
        c = self.counts
        for i in range(n):
            t = float(t_arr[i])
            placed = self._place(t)
            if placed is None:
                continue
            slot, reset = placed
            gap = slot - self._last_slot - 1
            if not reset and gap > self.max_gap_samples:
                c["gap_resets"] += 1
                reset = True
            elif not reset and gap > 0:
                now = (float(cmd[i]), float(ocmd[i]), {f: float(v[i]) for f, v in others.items()})
                self._bridge(out, out_other, gap, now)
            self._last_slot = slot
            self._last_t = t
            c["samples_used"] += 1
            p, u, lv, oc = self._checked(float(ph[i]), float(cmd[i]), float(level[i]), float(ocmd[i]))
            self._emit(out, out_other, t, p, u, lv, oc, float(sp[i]),
                       {f: float(v[i]) for f, v in others.items()}, True, reset)
        return self._batch(out, out_other)

    def _place(self, t: float) -> tuple[int, bool] | None:
        """Grid slot of a raw time stamp and whether the window restarts there; None: the sample is dropped."""
        c = self.counts
        if not math.isfinite(t):
            c["bad_time"] += 1
            return None
        reset = False
        if self._anchor is None:
            self._anchor, self._last_slot, reset = t, -1, True
        position = (t - self._anchor) / self.dt_s
        if not abs(position) < MAX_SLOT:  # beyond any real clock: as unusable as NaN
            c["bad_time"] += 1
            return None
        if t > self._last_raw_t:  # the sender's own rate, dropped samples included
            self._intervals.append(t - self._last_raw_t)
        self._last_raw_t = t
        slot = math.floor(position + 0.5)
        if t <= self._last_t or slot <= self._last_slot:
            # a new clock runs forward: a sample behind the stream counts toward one only when it is later than
            # the one behind it before (a burst of stray stamps from the past, repeated or shuffled, is no clock
            # and must not restart the window while the real stream goes on)
            ahead_of_run = self._backwards_run == 0 or t > self._backwards_last_t
            if t < self._last_t and ahead_of_run and self._backwards_run >= self.max_gap_samples:
                # a new clock (a restarted recording, a bag looping): start over on it
                c["time_resets"] += 1
                self._anchor, self._last_slot, self._last_t, reset = t, -1, -math.inf, True
                slot = 0
            elif t < self._last_t:
                self._backwards_run = self._backwards_run + 1 if ahead_of_run else 1
                self._backwards_last_t = t
                c["out_of_order"] += 1
                return None
            else:
                c["duplicate_stamps" if t == self._last_t else "extra_samples"] += 1
                return None
        self._backwards_run = 0
        return slot, reset

    def _bridge(self, out: dict[str, list], out_other: dict[str, list], gap: int, now: tuple) -> None:
        """The ``gap`` missing slots before a sample: commands interpolated, no measurement."""
        assert self._anchor is not None  # a sample was placed before
        self.counts["gaps_bridged"] += 1
        self.counts["missing_samples"] += gap
        for g in range(1, gap + 1):
            w = g / (gap + 1)
            u, oc, fl = self._between(now, w)
            self._emit(out, out_other, self._anchor + (self._last_slot + g) * self.dt_s,
                       math.nan, u, math.nan, oc, math.nan, fl, False, False)

    def _checked(self, ph: float, cmd: float, level: float, ocmd: float) -> tuple[float, float, float, float]:
        """pH, valve command, level and outlet command of a sample, NaN where unusable (counted)."""
        c = self.counts
        if not math.isfinite(ph):
            c["nonfinite_ph"] += 1
            ph = math.nan
        elif not PH_RANGE[0] <= ph <= PH_RANGE[1]:
            c["out_of_range_ph"] += 1
            ph = math.nan
        if not LEVEL_RANGE_CM[0] < level < LEVEL_RANGE_CM[1]:
            c["bad_level"] += 1 if not math.isnan(level) else 0
            level = math.nan
        if not math.isfinite(ocmd):
            c["nonfinite_outlet_command"] += 1 if not math.isnan(ocmd) else 0
            ocmd = math.nan
        if not math.isfinite(cmd):
            c["nonfinite_command"] += 1
            cmd = math.nan
        return ph, cmd, level, ocmd

    @staticmethod
    def _batch(out: dict[str, list], out_other: dict[str, list]) -> GridBatch:
        m = len(out["index"])
        return GridBatch(np.asarray(out["index"], dtype=np.int64), np.asarray(out["t"], dtype=float),
                         np.asarray(out["ph"], dtype=float), np.asarray(out["cmd"], dtype=float),
                         np.asarray(out["level"], dtype=float), np.asarray(out["ocmd"], dtype=float),
                         np.asarray(out["sp"], dtype=float),
                         {f: np.asarray(v, dtype=float) for f, v in out_other.items()},
                         np.asarray(out["real"], dtype=bool).reshape(m), np.asarray(out["reset"], dtype=bool).reshape(m),
                         np.asarray(out["stale"], dtype=bool).reshape(m), np.asarray(out["rewarm"], dtype=bool).reshape(m))

    def _between(self, now: tuple, w: float) -> tuple[float, float, dict]:
        """Inputs a fraction w of the way from the last emitted sample to ``now`` (NaN if either is)."""
        def lerp(a: float, b: float) -> float:
            return a + w * (b - a) if math.isfinite(a) and math.isfinite(b) else math.nan

        last_u, last_oc, last_fl = self._last_inputs
        return (lerp(last_u, now[0]), lerp(last_oc, now[1]),
                {f: lerp(last_fl.get(f, math.nan), v) for f, v in now[2].items()})

    def _emit(self, out, out_other, t, ph, cmd, level, ocmd, sp, others, real, reset) -> None:
        """One grid sample; tracks how long the valve command has been missing."""
        rewarm = False
        if reset:
            self._cmd_missing_run = 0
            self._stale = False
        if math.isfinite(cmd):
            if self._stale:
                rewarm = True
            self._cmd_missing_run = 0
            self._stale = False
        else:
            self._cmd_missing_run += 1
            if not self._stale and self._cmd_missing_run > self.command_timeout_samples:
                self._stale = True
                self.counts["command_stale_episodes"] += 1
        out["index"].append(self._next_index)
        self._next_index += 1
        out["t"].append(t)
        out["ph"].append(ph)
        out["cmd"].append(cmd)
        out["level"].append(level)
        out["ocmd"].append(ocmd)
        out["sp"].append(sp)
        out["real"].append(real)
        out["reset"].append(reset)
        out["stale"].append(self._stale)
        out["rewarm"].append(rewarm)
        for f, lst in out_other.items():
            lst.append(others.get(f, math.nan))
        if real:
            self._last_inputs = (cmd, ocmd, dict(others))


#: the input guard's counters that mean bad input (not the samples it counted, not the gaps it bridged), in its
#: order: what the detector node reports at once when one grows and what replay lists as input problems
INPUT_PROBLEMS: tuple[str, ...] = tuple(c for c in InputRegularizer.COUNTERS
                                        if c not in ("samples_received", "samples_used", "gaps_bridged"))


def input_problems(diagnostics: dict, extra: tuple[str, ...] = ()) -> dict[str, int]:
    """The bad-input counters of a detector's diagnostics (:data:`INPUT_PROBLEMS`, then ``extra``) that are not
    zero, in the diagnostics' order."""
    names = set(INPUT_PROBLEMS) | set(extra)
    return {k: v for k, v in diagnostics.items() if k in names and v}
