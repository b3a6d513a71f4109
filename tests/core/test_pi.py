"""PI controller: action, anti-windup, bumpless changes."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pi_controllers.pi import PIController


def first_order_loop(ctrl: PIController, sp, n=600, gain=1.0, tau=20.0, dt=1.0, u0=0.0):
    """PV of gain/(tau s + 1), exact discretisation, under the controller."""
    y = gain * u0
    a = math.exp(-dt / tau)
    ctrl.reset(u0, sp(0), y)
    us, ys, integ = [], [], []
    for k in range(n):
        u = ctrl.step(sp(k * dt), y)
        us.append(u)
        ys.append(y)
        integ.append(ctrl._i)
        y = a * y + (1 - a) * gain * u
    return np.array(us), np.array(ys), np.array(integ)


def test_reverse_action_raises_output_when_pv_is_low_and_direct_lowers_it():
    rev = PIController(kp=2.0, ti_s=10.0, action="reverse")
    rev.reset(50.0, 10.0, 10.0)
    assert rev.step(10.0, 9.0) > 50.0
    direct = PIController(kp=2.0, ti_s=10.0, action="direct")
    direct.reset(50.0, 10.0, 10.0)
    assert direct.step(10.0, 9.0) < 50.0


def test_integral_removes_steady_offset():
    us, ys, _ = first_order_loop(PIController(kp=1.0, ti_s=20.0), lambda t: 40.0, n=800, u0=10.0)
    assert ys[-1] == pytest.approx(40.0, abs=1e-3)


def _saturating_run(antiwindup):
    # setpoint unreachable (needs u = 150 %) for 300 s, then back to a reachable value
    sp = lambda t: 150.0 if t < 300 else 50.0  # noqa: E731
    ctrl = PIController(kp=1.0, ti_s=20.0, antiwindup=antiwindup, u_max=100.0)
    return first_order_loop(ctrl, sp, n=1200, u0=50.0)


def _recovery_time(ys, t0=300, band=1.0):
    err = np.abs(ys[t0:] - 50.0)
    last_out = np.nonzero(err > band)[0]
    return int(last_out[-1]) + 1 if len(last_out) else 0


@pytest.mark.parametrize("scheme", ["back_calculation", "conditional"])
def test_antiwindup_keeps_integral_bounded_and_recovers_faster(scheme):
    us_aw, ys_aw, i_aw = _saturating_run(scheme)
    us_no, ys_no, i_no = _saturating_run("none")
    # without anti-windup the integral winds far past the output limit
    assert i_no[299] > 400.0
    # with it, the integral stays near the limit (the P term is small there)
    assert i_aw[299] < 105.0
    assert np.all(us_aw <= 100.0) and np.all(us_aw >= 0.0)
    t_aw, t_no = _recovery_time(ys_aw), _recovery_time(ys_no)
    assert t_aw < 0.5 * t_no, (t_aw, t_no)


def test_tuning_change_is_bumpless():
    ctrl = PIController(kp=2.0, ti_s=30.0)
    ctrl.reset(40.0, 7.0, 6.5)
    u_before = ctrl.step(7.0, 6.5)
    ctrl.set_tuning(kp=6.0, ti_s=10.0)
    u_after = ctrl.step(7.0, 6.5)
    # only one sample of integral action separates them, no proportional kick
    assert abs(u_after - u_before) < 6.0 * 0.5 / 10.0 + 1e-12


def test_manual_to_auto_is_bumpless():
    ctrl = PIController(kp=3.0, ti_s=10.0)
    ctrl.reset(20.0, 8.0, 8.0)
    ctrl.set_manual(63.0)
    assert ctrl.step(8.0, 7.2) == 63.0
    ctrl.set_auto()
    assert ctrl.step(8.0, 7.2) == pytest.approx(63.0)  # no bump at the switch
    assert ctrl.step(8.0, 7.2) == pytest.approx(63.0 + 3.0 * 0.8 / 10.0)  # then integral action


def test_setpoint_weight_zero_removes_the_proportional_kick():
    soft = PIController(kp=5.0, ti_s=100.0, setpoint_weight=0.0)
    hard = PIController(kp=5.0, ti_s=100.0)
    for c in (soft, hard):
        c.reset(50.0, 10.0, 10.0)
    assert hard.step(12.0, 10.0) - 50.0 == pytest.approx(5.0 * 2.0 + 0.0)
    assert soft.step(12.0, 10.0) == pytest.approx(50.0)


def test_bad_tuning_is_refused_with_the_name():
    with pytest.raises(ValueError, match="ti_s must be positive"):
        PIController(kp=1.0, ti_s=0.0)
    with pytest.raises(ValueError, match="u_min must be below u_max"):
        PIController(kp=1.0, ti_s=1.0, u_min=10, u_max=5)
