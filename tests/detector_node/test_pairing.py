"""The node's pairing of measurement k with controller output k, under any arrival order."""

from __future__ import annotations

import math

from hypothesis import given, settings
from hypothesis import strategies as st

from phfdi_base.stamps import time_on_grid_s
from wavelet_fdi.node import Pairing


def _feed(pairing: Pairing, arrivals: list[tuple[str, int]], clock_step_s: float = 0.1) -> list[tuple]:
    rows, now = [], 0.0
    for kind, k in arrivals:
        now += clock_step_s
        if kind == "m":
            rows += pairing.measurement(k, 7.0 + k, 30.0, now)
        else:
            rows += pairing.output(k, (float(k), 50.0, 8.0), now)
    return rows + pairing.drain()


@st.composite
def two_topics(draw, n_max: int = 40):
    """Measurements in stamp order; the outputs in stamp order too (one writer), each published after
    its measurement but delivered any number of measurements later; some never come."""
    n = draw(st.integers(1, n_max))
    sent = [k for k in range(n) if draw(st.booleans()) or draw(st.booleans())]  # about 3 in 4 sent
    events = [("m", k, float(k)) for k in range(n)]
    t = 0.0
    for k in sent:
        t = max(t, k + 0.5) + draw(st.floats(0.0, 10.0))  # arrival times stay in order
        events.append(("o", k, t))
    events.sort(key=lambda e: e[2])
    return [(kind, k) for kind, k, _ in events], set(sent)


@settings(max_examples=300, deadline=None)
@given(two_topics())
def test_every_output_that_comes_is_paired_however_late(case):
    arrivals, sent = case
    pairing = Pairing(window=1, timeout_s=math.inf)
    rows = _feed(pairing, arrivals)
    assert [r[0] for r in rows] == sorted(r[0] for r in rows)  # measurement order kept
    for r in rows:
        if r[0] in sent:
            assert r[3] is not None and r[3][0] == float(r[0])  # with its own output
        else:
            assert r[3] is None  # NaN commands: the core counts them
    assert pairing.counts["commands_missing"] == len(rows) - len(sent)


def test_an_output_with_a_later_stamp_gives_up_the_missing_one_at_once():
    pairing = Pairing(window=1, timeout_s=math.inf)
    pairing.measurement(0, 7.0, 30.0, 0.0)
    pairing.measurement(1, 7.0, 30.0, 0.1)
    first, second = pairing.output(1, (1.0, 50.0, 8.0), 0.2)  # output 0 was never sent
    assert first[0] == 0 and first[3] is None
    assert second[0] == 1 and second[3][0] == 1.0


def test_wall_time_grace_keeps_a_reordered_output():
    """Window 1 alone loses an output overtaken by the next measurement; 0.5 s of grace keeps it."""
    arrivals = [("m", 0), ("m", 1), ("o", 0), ("o", 1)]
    strict = Pairing(window=1, timeout_s=0.0)
    rows = _feed(strict, arrivals)
    assert rows[0][3] is None and strict.counts["late_controller_outputs"] == 1
    graceful = Pairing(window=1, timeout_s=0.5)
    rows = _feed(graceful, arrivals)  # the output comes 0.1 s after the next measurement
    assert [r[3][0] for r in rows] == [0.0, 1.0]


def test_a_silent_controller_topic_passes_nan_commands_after_the_window_and_the_grace():
    pairing = Pairing(window=1, timeout_s=0.5)
    assert pairing.measurement(0, 7.0, 30.0, 0.0) == []
    assert pairing.measurement(1, 7.0, 30.0, 0.1) == []  # sample 0 still within its grace
    assert pairing.expire(0.4) == []
    (row,) = pairing.expire(0.6)  # sample 0 waited 0.5 s and one measurement came after it
    assert row[0] == 0 and row[3] is None
    assert pairing.counts["commands_missing"] == 1
    assert [r[0] for r in pairing.drain()] == [1]


def test_unpaired_outputs_are_bounded_and_counted():
    pairing = Pairing(window=1)
    for k in range(Pairing.EARLY_LIMIT + 10):
        pairing.output(10**6 + k, (1.0, 2.0, 3.0), 0.0)
    assert len(pairing.early) == Pairing.EARLY_LIMIT
    assert pairing.counts["unpaired_controller_outputs"] == 10


def test_sample_times_equal_the_bag_readers():
    """k * dt on the grid (as phfdi.bagio.load_run), so live and offline replay see the same floats."""
    dt_ns = 100_000_000
    assert time_on_grid_s(7 * dt_ns, dt_ns, 0.1) == 7 * 0.1
    assert time_on_grid_s(7 * dt_ns + 5, dt_ns, 0.1) == (7 * dt_ns + 5) * 1e-9


def _paired_run(pairing: Pairing, n: int) -> list[tuple]:
    rows = []
    for k in range(n):
        rows += pairing.measurement(k, 7.0, 30.0, 0.1 * k)
        rows += pairing.output(k, (float(k), 50.0, 8.0), 0.1 * k + 0.05)
    return rows


def test_a_future_stray_with_a_matching_stray_output_is_dropped_not_passed_on():
    """Strays on both topics with one future stamp pair with each other; two older measurements behind the
    measurement still show it cannot be this writer's next sample (its stamp would become the detector's clock)."""
    pairing = Pairing(window=1, timeout_s=10.0)
    rows = _paired_run(pairing, 5)
    future = 10**12
    rows += pairing.measurement(future, -77.0, -77.0, 1.0)
    rows += pairing.output(future, (-77.0, -77.0, -77.0), 1.01)  # arrives before the older measurements
    rows += pairing.measurement(2, -77.0, -77.0, 1.02)  # the past
    rows += pairing.measurement(4_500, -77.0, -77.0, 1.03)  # off the grid, still behind the future one
    rows += pairing.drain()
    assert future not in [r[0] for r in rows]
    assert pairing.counts["stray_measurements"] == 1


def test_a_real_gap_is_passed_on_once_later_samples_follow_or_the_stream_pauses():
    pairing = Pairing(window=1, timeout_s=0.5)
    rows = _paired_run(pairing, 5)
    gap = 10
    rows += pairing.measurement(gap, 7.0, 30.0, 1.0)
    rows += pairing.output(gap, (1.0, 50.0, 8.0), 1.01)
    assert rows[-1][0] == 4  # held: is it a stray?
    assert [r[0] for r in pairing.expire(1.6)] == [gap]  # the stream paused: passed on after the grace
    rows = pairing.measurement(gap + 10, 7.0, 30.0, 2.0) + pairing.output(gap + 10, (1.0, 50.0, 8.0), 2.0)
    rows += pairing.measurement(gap + 11, 7.0, 30.0, 2.1) + pairing.output(gap + 11, (1.0, 50.0, 8.0), 2.1)
    rows += pairing.measurement(gap + 12, 7.0, 30.0, 2.2) + pairing.output(gap + 12, (1.0, 50.0, 8.0), 2.2)
    assert [r[0] for r in rows] == [gap + 10, gap + 11, gap + 12]  # newer ones behind it: a real gap
    assert pairing.counts["stray_measurements"] == 0
