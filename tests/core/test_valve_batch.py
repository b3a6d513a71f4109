"""valve_actuator.batch: many blocks over one command sequence give, row by row, exactly what
stepping each block sample by sample gives (the valve-model fits rely on it)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from valve_actuator.batch import positions
from valve_actuator.blocks import Backlash, CoulombViscousFriction, DeadZone, Quantization, Saturation, Stiction


def _stepped(block, u):
    block.reset(float(u[0]))
    return np.array([block.step(float(x), 0.0) for x in u])


def _command(seed: int, n: int = 300) -> np.ndarray:
    """A command that ramps, holds, reverses and jumps, like a PI output on a sticky loop."""
    rng = np.random.default_rng(seed)
    moves = rng.normal(0.0, 0.4, n) * (rng.random(n) < 0.7)  # 30 % of samples hold the command
    moves[rng.random(n) < 0.03] *= 15.0
    u = 50.0 + np.cumsum(moves)
    rounded = rng.random(n) < 0.1
    u[rounded] = np.round(u[rounded], 1)  # repeated levels: exact holds and returns
    return u


width = st.floats(0.0, 8.0, allow_nan=False)
severity = st.sampled_from([1.0, 0.5, 0.37])


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10_000), s=st.lists(st.tuples(width, st.floats(0.0, 1.5), severity), min_size=1,
                                               max_size=6))
def test_stiction_rows_equal_the_stepped_block(seed, s):
    u = _command(seed)
    blocks = [Stiction(s_pct=w, j_pct=w * f, severity=sev) for w, f, sev in s]
    got = positions(blocks, u)
    for row, (w, f, sev) in zip(got, s):
        np.testing.assert_array_equal(row, _stepped(Stiction(s_pct=w, j_pct=w * f, severity=sev), u))


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10_000), widths=st.lists(st.tuples(width, severity), min_size=1, max_size=6))
def test_backlash_and_deadzone_rows_equal_the_stepped_blocks(seed, widths):
    u = _command(seed)
    makers = [lambda w, sv: Backlash(width_pct=w, severity=sv),
              lambda w, sv: DeadZone(width_pct=w, severity=sv),
              lambda w, sv: DeadZone(width_pct=w, center_pct=49.0 + w, severity=sv)]
    blocks = [mk(w, sv) for w, sv in widths for mk in makers]
    got = positions(blocks, u)
    ref = [mk(w, sv) for w, sv in widths for mk in makers]
    for row, b in zip(got, ref):
        np.testing.assert_array_equal(row, _stepped(b, u))


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10_000), step=st.floats(0.01, 5.0), offset=st.floats(-3.0, 3.0),
       limit=st.floats(1.0, 99.0), sev=severity)
def test_static_blocks_and_others_equal_the_stepped_blocks(seed, step, offset, limit, sev):
    u = _command(seed)
    u[::17] = 50.0 + step * 0.5  # exact ties of the quantiser land on both sides
    make = [lambda: Quantization(step_pct=step, offset_pct=offset, severity=sev),
            lambda: Quantization(step_pct=step),
            lambda: Saturation(high_pct=limit, severity=sev),
            lambda: Saturation(low_pct=limit * 0.5),
            lambda: CoulombViscousFriction(coulomb_pct=step, dt_s=4.0)]  # no batched rule: stepped
    got = positions([m() for m in make], u)
    for row, m in zip(got, make):
        np.testing.assert_array_equal(row, _stepped(m(), u))


def test_mixed_kinds_keep_their_order():
    u = _command(3)
    blocks = [Stiction(s_pct=2.0, j_pct=0.5), Backlash(width_pct=1.0), Stiction(s_pct=1.0, j_pct=1.0)]
    got = positions(blocks, u)
    assert got.shape == (3, len(u))
    np.testing.assert_array_equal(got[1], _stepped(Backlash(width_pct=1.0), u))
    np.testing.assert_array_equal(got[2], _stepped(Stiction(s_pct=1.0, j_pct=1.0), u))
    assert not np.array_equal(got[0], got[2])  # a sticky valve of S = 2 % lags the command
