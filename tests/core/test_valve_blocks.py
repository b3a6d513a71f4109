"""Each valve nonlinearity's input-output characteristic, and the valve around them."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from phfdi_base.blocks import Chain, Injected, make_block
from valve_actuator.blocks import (
    Backlash,
    Blocking,
    CoulombViscousFriction,
    DeadZone,
    Leakage,
    Quantization,
    Saturation,
    Stiction,
)
from valve_actuator.valve import Valve, inherent_characteristic


def drive(block, xs, t0=0.0, dt=1.0):
    block.reset(xs[0])
    return np.array([block.step(x, t0 + k * dt) for k, x in enumerate(xs)])


def triangle(lo, hi, n_half):
    up = np.linspace(lo, hi, n_half)
    return np.concatenate([up, up[::-1][1:], up[1:]])


# ---- backlash -----------------------------------------------------------------------
def test_backlash_follows_with_half_width_lag_and_ignores_small_reversals():
    d = 4.0
    xs = triangle(20.0, 60.0, 401)
    ys = drive(Backlash(d), xs)
    up = np.diff(xs) > 0
    # moving up after the first half-width: output = input - d/2
    assert np.allclose(ys[50:400], xs[50:400] - d / 2)
    # at the reversal the output holds until the input has come back d
    top = 400
    held = ys[top: top + 40]
    assert np.allclose(held, ys[top])
    assert np.allclose(ys[top + 41: 790], xs[top + 41: 790] + d / 2)
    assert up.sum() > 0


@settings(max_examples=200, deadline=None)
@given(d=st.floats(0.1, 10.0), start=st.floats(10, 90), wiggle=st.floats(0.0, 0.99))
def test_backlash_reversal_smaller_than_width_leaves_output_unchanged(d, start, wiggle):
    b = Backlash(d)
    b.reset(start)
    y0 = b.step(start + d, 0.0)  # move up: y = start + d/2
    # reverse by less than d: output unchanged
    y1 = b.step(start + d - wiggle * d, 1.0)
    assert y1 == pytest.approx(y0)


# ---- dead-zone ------------------------------------------------------------------------
def test_deadzone_static_characteristic():
    dz = DeadZone(width_pct=10.0, center_pct=50.0)
    xs = np.linspace(0, 100, 1001)
    ys = np.array([dz.step(x, 0.0) for x in xs])
    inside = np.abs(xs - 50) <= 5
    assert np.all(ys[inside] == 50.0)
    assert np.allclose(ys[xs > 55], xs[xs > 55] - 5)
    assert np.allclose(ys[xs < 45], xs[xs < 45] + 5)
    # no phase lag: the same input gives the same output both ways
    back = np.array([dz.step(x, 0.0) for x in xs[::-1]])[::-1]
    assert np.array_equal(ys, back)


def test_deadzone_centre_defaults_to_rest_point():
    dz = DeadZone(width_pct=2.0)
    dz.reset(37.0)
    assert dz.step(37.9, 0) == 37.0 and dz.step(36.2, 0) == 37.0 and dz.step(40.0, 0) == 39.0


# ---- saturation -------------------------------------------------------------------------
def test_saturation_clips_and_scales_with_severity():
    s = Saturation(0.0, 50.0)
    assert [s.step(x, 0) for x in (-5, 20, 50, 80)] == [0.0, 20.0, 50.0, 50.0]
    s.severity = 0.5  # halfway from [0, 100] to [0, 50]
    assert s.step(90, 0) == 75.0
    with pytest.raises(ValueError, match="limits"):
        Saturation(60.0, 50.0)


# ---- Coulomb + viscous friction ----------------------------------------------------------
def test_friction_holds_small_steps_and_creeps_with_viscous_time_constant():
    f = CoulombViscousFriction(coulomb_pct=1.0, mobility_per_s=0.1, dt_s=1.0)
    f.reset(50.0)
    assert f.step(50.9, 0) == 50.0  # below Coulomb force: no motion
    ys = [f.step(60.0, k) for k in range(1, 200)]
    # approaches command - c exponentially with tau = 1/mobility = 10 s
    target = 59.0
    assert ys[0] == pytest.approx(target + (50.0 - target) * math.exp(-0.1))
    assert ys[9] == pytest.approx(target + (50.0 - target) * math.exp(-1.0), rel=1e-12)
    assert ys[-1] == pytest.approx(target, abs=1e-6)


def test_friction_quasi_static_ramp_trails_by_coulomb_plus_velocity_lag():
    f = CoulombViscousFriction(coulomb_pct=1.0, mobility_per_s=0.1, dt_s=1.0)
    ramp = 0.05  # %/s
    xs = 20.0 + ramp * np.arange(2000)
    ys = drive(f, xs)
    lag = xs[-1] - ys[-1]
    # steady lag = c + v / mobility (first-order tracking of a ramp)
    assert lag == pytest.approx(1.0 + ramp / 0.1, rel=0.02)


# ---- stiction (Kano 2004) ------------------------------------------------------------------
def _sine_response(s, j):
    t = np.arange(0, 400)
    xs = 50 + 10 * np.sin(2 * np.pi * t / 200)
    return xs, drive(Stiction(s, j), xs)


def test_stiction_j0_is_a_pure_deadband():
    xs, ys = _sine_response(4.0, 0.0)
    xb = drive(Backlash(4.0), xs)
    assert np.max(np.abs(ys[60:] - xb[60:])) < 1e-9


@pytest.mark.parametrize("s,j,kind", [(4.0, 2.0, "undershoot"), (4.0, 4.0, "no offset"), (4.0, 6.0, "overshoot")])
def test_stiction_slip_jump_cases(s, j, kind):
    st_block = Stiction(s, j)
    st_block.reset(50.0)
    # ramp up slowly: first the valve sticks (dead-band + stick-band S), then slips by J
    ys, xs = [], []
    for k in range(1, 200):
        x = 50.0 + 0.1 * k
        xs.append(x)
        ys.append(st_block.step(x, k))
    xs, ys = np.array(xs), np.array(ys)
    moved = np.nonzero(ys != 50.0)[0][0]
    assert xs[moved] - 50.0 > s - 1e-9  # command travelled more than S before the first slip
    offset = xs[moved + 5] - ys[moved + 5]  # while moving, position = command - (S - J)/2
    assert offset == pytest.approx((s - j) / 2, abs=1e-9)
    jump = ys[moved] - 50.0
    if kind == "undershoot":
        assert xs[moved] > ys[moved]
    elif kind == "no offset":
        assert ys[moved] == pytest.approx(xs[moved])
    else:
        assert ys[moved] > xs[moved]
    assert jump > 0


def test_stiction_stops_and_restarts_in_same_direction_with_stick_band_j():
    st_block = Stiction(4.0, 1.0)
    st_block.reset(50.0)
    for k in range(1, 80):
        st_block.step(50.0 + 0.1 * k, k)  # moving up, x = 57.9
    y_moving = st_block.step(57.9, 80)  # command stops: valve sticks
    assert st_block.step(58.8, 81) == y_moving  # +0.9 < J: still stuck
    assert st_block.step(59.1, 82) > y_moving  # +1.2 > J: slips


# ---- others ----------------------------------------------------------------------------------
def test_blocking_freezes_at_onset_position():
    chain = Chain([Injected(Blocking(), onset_s=10.0)])
    chain.reset(30.0)
    ys = [chain.step(30.0 + k, float(k)) for k in range(20)]
    assert ys[:10] == [30.0 + k for k in range(10)]
    assert all(y == 39.0 for y in ys[10:])  # the position it had when the fault struck


def test_quantization():
    q = Quantization(2.5)
    assert [q.step(x, 0) for x in (0.0, 1.2, 1.3, 51.0)] == [0.0, 0.0, 2.5, 50.0]


def test_leakage_passes_flow_when_shut_and_max_when_open():
    leak = Leakage(flow_ml_s=2.0, max_flow_ml_s=40.0)
    assert leak.step(0.0, 0) == 2.0
    assert leak.step(40.0, 0) == 40.0


def test_injected_ramp_scales_severity_and_is_bumpless():
    inj = Injected(Backlash(4.0), onset_s=100.0, ramp_s=100.0)
    inj.reset(50.0)
    assert inj.step(60.0, 50.0) == 60.0  # before the onset: pass-through
    assert inj.severity_at(150.0) == 0.5
    y = inj.step(61.0, 150.0)  # half severity: width 2, follows 1 behind
    assert y == pytest.approx(60.0)


def test_make_block_names_bad_parameters():
    with pytest.raises(ValueError, match="width_pct must be non-negative"):
        make_block("backlash", {"width_pct": -1})
    with pytest.raises(ValueError, match="unknown parameter 'widht_pct'"):
        make_block("backlash", {"widht_pct": 1})
    with pytest.raises(ValueError, match="unknown block type"):
        make_block("no_such_block", {})


# ---- the valve -------------------------------------------------------------------------------
def test_inherent_characteristics():
    assert inherent_characteristic(50.0, "linear") == 0.5
    r = 50.0
    f = [inherent_characteristic(p, "equal_percentage", r) for p in (25.0, 50.0, 75.0, 100.0)]
    # equal position increments give equal flow ratios
    assert f[1] / f[0] == pytest.approx(f[2] / f[1]) == pytest.approx(f[3] / f[2])
    assert f[3] == 1.0 and inherent_characteristic(0.0, "equal_percentage") == 0.0


def test_valve_holds_position_on_non_finite_command():
    v = Valve(max_flow_ml_s=40.0)
    v.reset(30.0)
    out = v.step(35.0, 0.0)
    for bad in (math.nan, math.inf, -math.inf):
        held = v.step(bad, 1.0)
        assert held.position_pct == out.position_pct
    assert v.rejected_commands == 3
    assert v.step(36.0, 2.0).flow_ml_s == pytest.approx(14.4)


def test_he_stiction_sticks_within_fs_slips_and_lags_by_fd():
    from valve_actuator.blocks import HeStiction

    b = make_block("stiction_he", {"fs_pct": 2.0, "fd_pct": 0.5})
    assert isinstance(b, HeStiction)
    b.reset(50.0)
    ramp = 50.0 + 0.1 * np.arange(1, 60)
    y = np.array([b.step(float(u), 0.0) for u in ramp])
    # stuck until the command has moved by more than fs, then slips to u - fd
    first = int(np.argmax(y > 50.0))
    assert ramp[first] - 50.0 == pytest.approx(2.1, abs=1e-9)
    assert y[first] == pytest.approx(ramp[first] - 0.5)
    # on a ramp it sticks again after each slip: jumps of fs - fd, lagging by fd to fs
    jumps = np.diff(y)[np.diff(y) > 0]
    assert len(jumps) >= 3 and np.allclose(jumps, 1.6)
    lag = ramp - y
    assert np.all(lag[first:] >= 0.5 - 1e-9) and np.all(lag[first:] <= 2.0 + 1e-9)
    # a reversal must work through fs + fd before the stem moves back
    b.reset(50.0)
    for u in (51.0, 52.1):
        b.step(u, 0.0)  # slips at 52.1 to 51.6, residual +fd
    held = [b.step(52.1 - d, 0.0) for d in (0.5, 1.0, 2.0, 2.5)]
    assert all(v == pytest.approx(51.6) for v in held)
    assert b.step(52.1 - 2.6, 0.0) == pytest.approx(51.6 - (2.6 - 0.5) + 0.5)
    with pytest.raises(ValueError, match="fd_pct"):
        HeStiction(fs_pct=1.0, fd_pct=2.0)
