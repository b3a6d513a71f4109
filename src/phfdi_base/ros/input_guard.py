"""Stamp checks at the inputs of the lock-step nodes: which message is the next sample, and what became of the
rest (no rclpy here: :class:`phfdi_base.ros.graph_node.GraphNode` publishes and logs what this decides).

In lock-step a node takes exactly the next sample: k == last + 1 (the plant: the sample it waits for). A
message stamped from the future (k > last + 1), the past or again (k <= last), off the sample grid, or with
an invalid stamp (negative seconds, nanoseconds not below 1e9) is dropped, counted by reason and never
becomes the node's clock. Before this, one stray message with a future stamp on the graph's domain became
the controllers' clock and every real sample after it was "not newer": the loop stalled for good.

What cannot be told apart: a stray with exactly the next expected stamp. Messages carry no run id, and rclpy
(Jazzy) gives a callback no writer identity (its message info holds source and reception times and the
writer's sequence number, no GID); a sequence number does not tell two runs apart either (another graph's
writer numbers sample k the same).

Examples
--------
>>> guard = InputGuard(dt_ns=500_000_000, clock=iter(range(100)).__next__)
>>> guard.check(0, 0, last=-1)            # sample 0, the first one
(0, None)
>>> guard.check(5, 0, last=0)             # 5 s = sample 10: from the future
(None, 'future')
>>> guard.check(0, 0, last=0), guard.check(0, 250_000_000, last=0), guard.check(-1, 0, last=0)
((None, 'duplicate'), (None, 'off_grid'), (None, 'invalid_stamp'))
>>> guard.drop("future", "a measurement stamped 5.000000000 s (sample 10) while waiting for sample 1")
'dropped a measurement stamped 5.000000000 s (sample 10) while waiting for sample 1 (future stamp; 1 so far)'
>>> guard.counts["future"], guard.total
(1, 1)
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

from phfdi_base.stamps import join_ns, sample_index, valid_stamp

__all__ = ["REASONS", "REASON_TEXT", "InputGuard"]

#: why an input was dropped (the keys of the counts on /diagnostics)
REASONS = ("future", "past", "duplicate", "off_grid", "invalid_stamp")
REASON_TEXT = {"future": "future stamp", "past": "stamp older than the last sample",
               "duplicate": "stamp of the last sample again", "off_grid": "stamp off the sample grid",
               "invalid_stamp": "invalid stamp"}
#: a reason's log line repeats at most this often (wall s): the first drop of each reason is logged at once
LOG_REPEAT_S = 10.0
#: the counts go on /diagnostics at most this often (wall s), whenever they changed
REPORT_PERIOD_S = 1.0


class InputGuard:
    """Decides which input is the next sample; counts the others by reason; says when to log and report.

    ``clock``: wall seconds (monotonic), for the log and report rate limits only.
    """

    def __init__(self, dt_ns: int, clock: Callable[[], float] = time.monotonic) -> None:
        self.dt_ns = dt_ns
        self.clock = clock
        self.counts = dict.fromkeys(REASONS, 0)
        self.total = 0
        self.last_dropped = ""  # the last dropped input, in words
        self._logged_at = dict.fromkeys(REASONS, -math.inf)
        self._reported_total = 0
        self._reported_at = -math.inf

    def check(self, sec: int, nanosec: int, last: int, waiting: bool = True) -> tuple[int | None, str | None]:
        """(k, None) when the stamp is sample ``last + 1`` and the node is ``waiting`` for it, else
        (None, reason). Not waiting (the plant between two samples): every input is a stray."""
        if not valid_stamp(sec, nanosec):
            return None, "invalid_stamp"
        k = sample_index(join_ns(sec, nanosec), self.dt_ns)
        if k is None:
            return None, "off_grid"
        if k == last + 1 and waiting:
            return k, None
        return None, "future" if k > last else "duplicate" if k == last else "past"

    def drop(self, reason: str, what: str) -> str | None:
        """Count a dropped input; the log line to write now (once per reason, then at most every
        :data:`LOG_REPEAT_S` s with the count), or None."""
        self.counts[reason] += 1
        self.total += 1
        self.last_dropped = what
        now = self.clock()
        if now - self._logged_at[reason] < LOG_REPEAT_S:
            return None
        self._logged_at[reason] = now
        return f"dropped {what} ({REASON_TEXT[reason]}; {self.counts[reason]} so far)"

    @property
    def pending(self) -> bool:
        """The counts changed since they were last reported."""
        return self.total != self._reported_total

    def report_due(self) -> bool:
        """The counts changed and the last report is :data:`REPORT_PERIOD_S` old (the caller then publishes
        them and calls :meth:`reported`)."""
        return self.pending and self.clock() - self._reported_at >= REPORT_PERIOD_S

    def reported(self) -> None:
        self._reported_total = self.total
        self._reported_at = self.clock()

    def summary(self) -> str:
        if not self.total:
            return "every input was the next sample"
        counted = ", ".join(f"{self.counts[r]} {REASON_TEXT[r]}" for r in REASONS if self.counts[r])
        return f"{self.total} stray input(s) dropped ({counted}); last: {self.last_dropped}"
