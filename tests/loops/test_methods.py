"""The building blocks on signals whose answer is known: identification, oscillation, PI law, baselines."""

from __future__ import annotations

import math

import numpy as np
import pytest

from phfdi.loopdiag.baselines import cross_correlation, he_curve_fit, horch_oddness
from phfdi.loopdiag.controller import estimate_pi
from phfdi.loopdiag.identify import Split, fit_arx, fit_lag_model, prediction_nrmse
from phfdi.loopdiag.oscillation import detect_oscillation
from pi_controllers.pi import PIController


def foptd_response(u, gain, tau_s, delay, dt_s):
    a = math.exp(-dt_s / tau_s)
    x = np.zeros(len(u))
    for k in range(1, len(u)):
        x[k] = a * x[k - 1] + gain * (1 - a) * (u[max(k - 1 - delay, 0)] - u[0])
    return x


@pytest.fixture
def rng():
    return np.random.default_rng(7)


def test_foptd_identified_from_open_loop_data(rng):
    dt = 5.0
    u = 50 + np.repeat(rng.choice([-3.0, 3.0], 60), 12)
    y = 20 + foptd_response(u, 1.8, 40.0, 3, dt) + 0.02 * rng.standard_normal(len(u))
    m = fit_lag_model(u, y, dt, Split.of(len(u)), integrating=False)
    assert m.params["gain"] == pytest.approx(1.8, rel=0.05)
    assert m.params["time_constant_s"] == pytest.approx(40.0, rel=0.3)
    assert m.params["dead_time_s"] == pytest.approx(15.0, abs=dt)
    assert m.nrmse_validation < 0.1


def test_integrating_process_identified(rng):
    dt = 10.0
    u = 30 + np.repeat(rng.choice([-2.0, 2.0], 50), 15)
    y = 5 + np.cumsum(0.004 * (u - 30)) * dt + 0.01 * rng.standard_normal(len(u))
    m = fit_lag_model(u, y, dt, Split.of(len(u)), integrating=True)
    assert m.structure == "integrating"
    assert m.params["gain"] == pytest.approx(0.004, rel=0.1)
    assert m.nrmse_validation < 0.2


def test_wrong_gain_sign_is_refused(rng):
    dt = 5.0
    u = 50 + np.repeat(rng.choice([-3.0, 3.0], 60), 12)
    y = foptd_response(u, 1.8, 40.0, 3, dt)
    free = fit_lag_model(u, y, dt, Split.of(len(u)), False)
    forced = fit_lag_model(u, y, dt, Split.of(len(u)), False, gain_sign=-1)
    assert free.params["gain"] > 0 and forced.params["gain"] <= 0.0
    assert forced.nrmse_validation > 0.8 > 0.1 > free.nrmse_validation


def test_arx_has_no_feedthrough_and_scores_by_simulation(rng):
    dt = 5.0
    u = 50 + np.repeat(rng.choice([-3.0, 3.0], 60), 12)
    y = foptd_response(u, 1.8, 40.0, 3, dt) + 0.02 * rng.standard_normal(len(u))
    m = fit_arx(u, y, dt, Split.of(len(u)))
    assert m.params["dead_time_s"] >= dt and m.params["stable"]
    assert m.params["gain"] == pytest.approx(1.8, rel=0.1)
    assert m.nrmse_validation < 0.15


def test_prediction_nrmse_is_one_for_persistence():
    y = np.sin(np.arange(300) / 10)
    assert prediction_nrmse(y, np.zeros(300), (1, 2, 4)) == pytest.approx(1.0)
    assert prediction_nrmse(y, y + 3.0, (1, 2, 4)) == pytest.approx(0.0, abs=1e-12)


def test_oscillation_detected_only_when_regular(rng):
    t = np.arange(800)
    sp = np.zeros(800)
    osc = detect_oscillation(np.sin(2 * np.pi * t / 50) + 0.3 * rng.standard_normal(800), sp, 10.0)
    assert osc.oscillating and osc.period_s == pytest.approx(500.0, rel=0.05) and osc.regularity > 1
    noise = detect_oscillation(rng.standard_normal(800), sp, 10.0)
    assert not noise.oscillating


def test_pi_law_and_action_recovered(rng):
    dt = 2.0
    pi = PIController(kp=1.3, ti_s=40.0, dt_s=dt, action="direct", u_min=-1e9, u_max=1e9)
    pv = np.cumsum(rng.standard_normal(500)) * 0.1
    sp = np.where(np.arange(500) > 250, 1.0, 0.0)
    pi.reset(0.0, sp[0], pv[0])
    op = np.array([pi.step(s, p) for s, p in zip(sp, pv)])
    est = estimate_pi(op, pv, sp, dt)
    assert est.action == "direct" and est.gain_sign == -1
    assert est.kc == pytest.approx(-1.3, rel=0.05) and est.ti_s == pytest.approx(40.0, rel=0.1)


def test_horch_oddness_tells_odd_from_even():
    t = np.arange(600)
    u = np.sin(2 * np.pi * t / 60)
    lags, r_even = cross_correlation(u, -u, 60)
    lags, r_odd = cross_correlation(u, np.cos(2 * np.pi * t / 60), 60)
    assert horch_oddness(r_even, lags) < 0.1
    assert horch_oddness(r_odd, lags) > 0.9


def test_he_index_high_for_triangles_low_for_sines():
    t = np.arange(1200)
    period = 80
    tri = 2 * np.abs(2 * ((t / period) % 1) - 1) - 1
    sine = np.sin(2 * np.pi * t / period)
    sp = np.zeros(len(t))
    # self-regulating: the test fits OP; PV only supplies the oscillation test
    he_tri = he_curve_fit(tri, sine, sp, 1.0, "self_regulating")
    he_sine = he_curve_fit(sine, sine, sp, 1.0, "self_regulating")
    assert he_tri.decision == "stiction" and he_tri.index > 0.6
    assert he_sine.decision == "no_stiction" and he_sine.index < 0.4
