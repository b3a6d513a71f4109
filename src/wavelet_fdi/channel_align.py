"""Channels arriving on separate topics, put onto the detector's sample grid (ROS-free: the node and any replay
use the same code).

The grid is t_k = t_0 + k * dt: dt is the reference's sample time (to the ns: :func:`grid_period_ns`), t_0 the
stamp of the first message taken. The detector gets each sample's time in seconds from the first sample (as the
offline replay gets a record's times from its first row); :attr:`ChannelAligner.origin_ns` says where that is on
the plant's clock. With ``hold`` the time of sample k is k * dt. With ``sequence`` it is the stamp its messages
carry (the first channel, in map order, whose stamps come from the message: a header or a stamp field) minus the
origin, the first sample's stamp: the plant's own times, gaps included, as the offline replay of the record has
them; a sample without such a stamp, or whose stamp does not come after the previous sample's, is one dt after
the previous sample (counted: :attr:`ChannelAligner.stamps_not_increasing`). Channels stamped on receipt only
(std_msgs' numbers) give sample k the time k * dt: receive times faster than real time say nothing.

Two rules (the channel map's ``align``):

``hold`` (default; a plant at real time, channels at any rates)
    A message stamped s belongs to sample k = round((s - t_0) / dt) (the nearest grid point, so a stamp
    off by less than half a period lands on its own sample). Sample k takes each channel's latest value
    of sample k or before (zero-order hold); a value is held for at most ``hold_samples`` samples, after
    that the channel is missing (NaN) in the sample. Sample k goes out once every channel has delivered a
    message of a later sample (then nothing stamped k can still come in order), or ``max_wait_s`` of wall
    time after the first message of a later sample arrived (a late or silent channel does not stop the
    detector: it is held or missing). A message for a sample that went out already is late: dropped and
    counted; so is one stamped before the grid or more than ``MAX_AHEAD_SAMPLES`` ahead of it. A message more
    than ``hold_samples + 1`` samples ahead of its channel's latest is a jump, taken only once the channel's next
    message follows it (else dropped and counted: one stray stamped far ahead must not move the grid there).
``sequence`` (a plant or replayer that publishes every channel once per sample, at any speed)
    The k-th message of each channel belongs to sample k, whatever its stamp: sample k goes out once every
    channel has delivered its k-th message, or ``max_wait_s`` of wall time after the oldest waiting message
    arrived, without the channels that have not (missing, NaN). Faster than real time or in lock-step,
    receive-time stamps say nothing about which row a value belongs to; the order does (reliable topics
    keep it per topic).

:func:`align_messages` runs a whole list of messages through the same code (a replay, a test).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Iterable, Sequence

import numpy as np

from phfdi_base.stamps import stamp_seconds

from .channel_map import ALIGN_RULES


def grid_period_ns(sample_time_s: float) -> int:
    """The grid's period: the reference's sample time to the nanosecond (a learned reference's sample time is
    the median of a record's time steps, e.g. 0.34700000000202635 s, which no stamp can hit exactly).

    >>> grid_period_ns(0.34700000000202635), grid_period_ns(1.0)
    (347000000, 1000000000)
    """
    if not (math.isfinite(sample_time_s) and sample_time_s >= 1e-9):
        raise ValueError(f"sample time {sample_time_s} s is not a positive number of nanoseconds")
    return round(sample_time_s * 1e9)


#: hold: a stamp this many samples past the next sample is taken for a clock that jumped (dropped, counted)
MAX_AHEAD_SAMPLES = 100_000


@dataclass
class ChannelCounts:
    """What happened to one channel's messages (all counts since the start)."""

    received: int = 0
    used: int = 0  # values that went into a sample
    late: int = 0  # hold: for a sample already out, before the grid or far ahead: dropped
    superseded: int = 0  # hold: a newer value of the same sample replaced it
    jumps_dropped: int = 0  # hold: a message far ahead of the channel's own stream that the next one did not follow
    off_grid: int = 0  # hold: stamped further off its grid point than the map's grid_tolerance: dropped
    invalid_stamps: int = 0  # a stamp that is no time (nanoseconds outside 0..1e9, or before 0 s): dropped
    held: int = 0  # samples that took an earlier value (zero-order hold)
    missing: int = 0  # samples that went out without this channel (NaN)
    last_stamp_ns: int | None = None


@dataclass
class ChannelAligner:
    """Messages of ``n_channels`` channels in, rows on the grid out (:meth:`add`, then :meth:`take`)."""

    n_channels: int
    dt_ns: int
    rule: str = "hold"
    max_wait_s: float = 5.0
    hold_samples: int = 5
    origin_ns: int | None = None
    #: hold: how far off its grid point (fraction of dt) a stamp may lie (0.5: any, the nearest point)
    grid_tolerance: float = 0.5
    #: sequence: per channel, whether its stamps are the message's own (a header or stamp field; not receive times)
    stamped: tuple[bool, ...] = ()
    counts: list[ChannelCounts] = field(init=False)
    samples_out: int = 0
    waited_out: int = 0  # samples that went out after max_wait_s without every channel
    stamps_not_increasing: int = 0  # sequence: samples whose stamp was not after the previous sample's (put dt on)

    def __post_init__(self) -> None:
        if self.rule not in ALIGN_RULES:
            raise ValueError(f"align rule must be one of {ALIGN_RULES}, got {self.rule!r}")
        if self.dt_ns <= 0 or self.n_channels < 1:
            raise ValueError("dt_ns and n_channels must be positive")
        self.counts = [ChannelCounts() for _ in range(self.n_channels)]
        # hold: values not yet used, per channel (sample, value); the highest sample seen; the last value used
        self._pending: list[list[tuple[int, float]]] = [[] for _ in range(self.n_channels)]
        self._top = [-1] * self.n_channels
        self._last: list[tuple[int, float] | None] = [None] * self.n_channels
        self._advances: deque[tuple[int, float]] = deque()  # (sample now seen, wall time): when samples fell due
        # per channel, a message far ahead of its stream not yet followed by the next one: (sample, value, wall time)
        self._jump: list[tuple[int, float, float] | None] = [None] * self.n_channels
        self._seen_top = -1
        # sequence: per channel (value, wall time of arrival, stamp ns); the time of the last sample out (ns from
        # the origin); whether sample times come from the stamps
        self._fifo: list[deque[tuple[float, float, int]]] = [deque() for _ in range(self.n_channels)]
        self._last_t_ns: int | None = None
        self._by_stamp = self.rule == "sequence" and any(self.stamped)
        if self.stamped and len(self.stamped) != self.n_channels:
            raise ValueError("stamped needs one flag per channel")

    @property
    def times_from_stamps(self) -> bool:
        """Sample times from the messages' stamps (sequence with a stamped channel), else on the grid."""
        return self._by_stamp

    # ---- in ------------------------------------------------------------------------------------
    def add(self, channel: int, stamp_ns: int, value: float, now_s: float) -> None:
        """One channel value stamped ``stamp_ns`` (header or receive time), taken at wall time ``now_s``."""
        counts = self.counts[channel]
        counts.received += 1
        counts.last_stamp_ns = stamp_ns
        if self.origin_ns is None and not self._by_stamp:  # by stamp: the first sample's stamp, when it goes out
            self.origin_ns = stamp_ns
        if self.rule == "sequence":
            self._fifo[channel].append((value, now_s, stamp_ns))
            return
        assert self.origin_ns is not None  # hold: set by the first message
        k = (stamp_ns - self.origin_ns + self.dt_ns // 2) // self.dt_ns
        if self.grid_tolerance < 0.5 and abs(stamp_ns - self.origin_ns - k * self.dt_ns) > self.grid_tolerance * self.dt_ns:
            counts.off_grid += 1
            return
        for sample, v, t in self._admitted(channel, k, value, now_s):
            if sample < self.samples_out or sample > self.samples_out + MAX_AHEAD_SAMPLES:
                counts.late += 1
            else:
                self._take(channel, sample, v, t)

    def _admitted(self, channel: int, k: int, value: float, now_s: float) -> list[tuple[int, float, float]]:
        """hold: the messages taken now. One more than ``hold_samples + 1`` samples ahead of the channel's own latest
        is a jump: kept aside until the channel's next message says whether its stream went there (stamped from
        there to ``hold_samples + 1`` after it: both are taken) or not (a stray from another clock or a wrong
        stamp: dropped and counted, ``jumps_dropped``). One stray stamped far ahead would otherwise move the grid
        there, and every real sample after it would come late."""
        reach = self.hold_samples + 1
        jump, self._jump[channel] = self._jump[channel], None
        if jump is not None:
            if jump[0] <= k <= jump[0] + reach:
                return [jump, (k, value, now_s)]
            self.counts[channel].jumps_dropped += 1
        top = self._top[channel]
        if top >= 0 and k > top + reach:
            self._jump[channel] = (k, value, now_s)
            return []
        return [(k, value, now_s)]

    def _take(self, channel: int, k: int, value: float, now_s: float) -> None:
        self._pending[channel].append((k, value))
        self._top[channel] = max(self._top[channel], k)
        if k > self._seen_top:
            self._seen_top = k
            self._advances.append((k, now_s))

    def invalid_stamp(self, channel: int) -> None:
        """A message whose stamp is no time: counted, dropped."""
        self.counts[channel].received += 1
        self.counts[channel].invalid_stamps += 1

    def off_grid(self, at_least: int = 10) -> list[int]:
        """hold: channels whose every message (``at_least`` of them) fell outside the grid: stamps on another
        clock than the first message's (e.g. header stamps of the plant's time beside receive times)."""
        return [c for c, n in enumerate(self.counts) if n.received >= at_least and n.late == n.received]

    # ---- out -----------------------------------------------------------------------------------
    def take(self, now_s: float) -> list[tuple[float, np.ndarray]]:
        """The samples that are complete, or have waited ``max_wait_s``: (seconds from the first sample, row)."""
        return self._emit(now_s, final=False)

    def _sample_time_ns(self, stamp_ns: int | None) -> int:
        """The time of the sample going out (ns from the origin): its stamp, else one dt after the last sample."""
        k = self.samples_out
        if not self._by_stamp:
            return k * self.dt_ns
        if stamp_ns is not None and self.origin_ns is None:
            self.origin_ns = stamp_ns - k * self.dt_ns  # samples before it (none stamped) lie on the grid
        nxt = k * self.dt_ns if self._last_t_ns is None else self._last_t_ns + self.dt_ns
        if stamp_ns is None or self.origin_ns is None:
            t_ns = nxt
        elif self._last_t_ns is not None and stamp_ns - self.origin_ns <= self._last_t_ns:
            self.stamps_not_increasing += 1
            t_ns = nxt
        else:
            t_ns = stamp_ns - self.origin_ns
        self._last_t_ns = t_ns
        return t_ns

    def flush(self) -> list[tuple[float, np.ndarray]]:
        """At the end of the stream: every sample begun, without waiting (missing channels NaN); a jump no message
        followed is taken (the stream ended there: nothing says it did not go there)."""
        for c, jump in enumerate(self._jump):
            self._jump[c] = None
            if jump is not None and self.samples_out <= jump[0] <= self.samples_out + MAX_AHEAD_SAMPLES:
                self._take(c, *jump)
        return self._emit(math.inf, final=True)

    def _emit(self, now_s: float, final: bool) -> list[tuple[float, np.ndarray]]:
        out: list[tuple[float, np.ndarray]] = []
        while True:
            stamp: list[int] = []  # sequence: the stamp of the sample's first stamped channel, if any
            row = self._next_sequence(now_s, final, stamp) if self.rule == "sequence" else self._next_hold(now_s,
                                                                                                             final)
            if row is None:
                return out
            out.append((stamp_seconds(self._sample_time_ns(stamp[0] if stamp else None)), row))
            self.samples_out += 1

    def _next_sequence(self, now_s: float, final: bool, stamp: list[int]) -> np.ndarray | None:
        waiting = [q for q in self._fifo if q]
        if not waiting:
            return None
        complete = len(waiting) == self.n_channels
        if not (complete or final or now_s - min(q[0][1] for q in waiting) >= self.max_wait_s):
            return None
        if not complete:
            self.waited_out += 1
        row = np.full(self.n_channels, np.nan)
        for c, q in enumerate(self._fifo):
            if q:
                value, _, stamp_ns = q.popleft()
                row[c] = value
                self.counts[c].used += 1
                if self._by_stamp and self.stamped[c] and not stamp:
                    stamp.append(stamp_ns)
            else:
                self.counts[c].missing += 1
        return row

    def _next_hold(self, now_s: float, final: bool) -> np.ndarray | None:
        k = self.samples_out
        if self._seen_top < k + (0 if final else 1):
            return None  # nothing of a later sample yet (at the end: nothing of this one either)
        while self._advances and self._advances[0][0] <= k:
            self._advances.popleft()
        complete = all(top > k for top in self._top)
        due_s = self._advances[0][1] if self._advances else now_s
        if not (complete or final or now_s - due_s >= self.max_wait_s):
            return None
        if not complete and not final:
            self.waited_out += 1
        return np.array([self._value(c, k) for c in range(self.n_channels)])

    def _value(self, c: int, k: int) -> float:
        """Channel c's value in sample k: its latest of sample k or before, else the held one, else NaN."""
        counts, pending = self.counts[c], self._pending[c]
        mine = [p for p in pending if p[0] <= k]
        if mine:
            self._pending[c] = [p for p in pending if p[0] > k]
            best = max(range(len(mine)), key=lambda i: (mine[i][0], i))  # latest sample, then latest arrival
            counts.used += 1
            counts.superseded += len(mine) - 1
            self._last[c] = mine[best]
            return mine[best][1]
        last = self._last[c]
        if last is not None and k - last[0] <= self.hold_samples:
            counts.held += 1
            return last[1]
        counts.missing += 1
        return math.nan


def align_messages(messages: Iterable[tuple[int, int, float, float]], n_channels: int, dt_ns: int,
                   rule: str = "hold", max_wait_s: float = 5.0, hold_samples: int = 5,
                   stamped: Sequence[bool] = (), grid_tolerance: float = 0.5
                   ) -> tuple[np.ndarray, np.ndarray, ChannelAligner]:
    """Messages (channel, stamp ns, value, arrival wall time s) in arrival order through one aligner, then its
    end: the times (s from the first sample), the rows (n, n_channels) and the aligner (its counts)."""
    aligner = ChannelAligner(n_channels, dt_ns, rule, max_wait_s, hold_samples, stamped=tuple(stamped),
                             grid_tolerance=grid_tolerance)
    out: list[tuple[float, np.ndarray]] = []
    for channel, stamp_ns, value, now_s in messages:
        aligner.add(channel, stamp_ns, value, now_s)
        out += aligner.take(now_s)
    out += aligner.flush()
    return _stack(out, n_channels) + (aligner,)


def _stack(out: Sequence[tuple[float, np.ndarray]], m: int) -> tuple[np.ndarray, np.ndarray]:
    if not out:
        return np.zeros(0), np.zeros((0, m))
    return np.array([t for t, _ in out]), np.vstack([r for _, r in out])
