"""The estimator reference (wavelet_fdi.reference_estimator): a Kalman filter on the reaction invariant.

Synthetic runs come from the filter's own physics with a known truth (strengths, noise); the real-rig tests
fit on four shared runs and replay the fifth with a fault hidden by phfdi.inject (no draw: fixed onsets, so
each test passes or fails the same way every run).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from phfdi_base.errors import UserError
from wavelet_fdi.estimator_fit import fit_reference
from wavelet_fdi.learned_detector import LearnedModel, LearnedSettings, calibrate_bands, run_record
from wavelet_fdi.reference_estimator import EstimatorReference, Feed, NoiseModel
from wavelet_fdi.references import reference_from_dict

DT_S = 0.35
NOISE = NoiseModel(probe_noise_ph=0.03, rate_rel_std=0.05, walk_ph_per_sqrt_s=0.001)


def flask(volume_ml: float = 1000.0, base_mM: float = 50.0, **kw) -> EstimatorReference:
    return EstimatorReference((Feed("acid_flow_ml_s", -20.0), Feed("base_flow_ml_s", base_mM)), "ph_measured",
                              volume_ml, noise=NOISE, **kw)


def simulate(ref: EstimatorReference, n: int, base_flow, true_factor=lambda k: 1.0, ph0: float = 11.0,
             seed: int = 1, fault_ph=None, factor_of_ph=lambda ph: 1.0, lag_s: float = 0.0,
             acid_flow_ml_s: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """A run of the reference's own physics (exact steps), pH read with noise and the meter's 0.01 resolution.
    ``true_factor(k)``, ``factor_of_ph(ph)``: the caustic's true strength over the model's, by sample and by pH;
    ``lag_s``: the probe reads the flask through a first-order lag (mixing, the probe's response)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * DT_S
    qb = np.array([base_flow(k) for k in range(n)], dtype=float)
    qa = np.full(n, acid_flow_ml_s)
    x = float(ref.x_of_ph(np.array([ph0]))[0])
    ph = np.empty(n)
    for k in range(n):
        if k:
            d = (qa[k - 1] + qb[k - 1]) / ref.volume_ml
            strength = ref.feeds[1].strength_mM * true_factor(k) * factor_of_ph(ph[k - 1])
            u = (-20.0 * qa[k - 1] + strength * qb[k - 1]) / ref.volume_ml
            x = u / d + (x - u / d) * math.exp(-d * DT_S)
        ph[k] = ref.ph_of_x(x)
    if lag_s > 0:
        a = math.exp(-DT_S / lag_s)
        for k in range(1, n):
            ph[k] = a * ph[k - 1] + (1.0 - a) * ph[k]
    ph = ph + rng.normal(0.0, 0.03, n)
    if fault_ph is not None:
        ph = fault_ph(t, ph)
    ph = np.round(ph, 2)
    return t, np.column_stack((qa, qb, ph))


def test_healthy_innovations_have_unit_variance_and_any_chunking_gives_the_same_residuals():
    ref = flask()
    t, rows = simulate(ref, 3000, lambda k: 3.0 if (k // 600) % 2 == 0 else 1.0)
    whole = ref.residuals(t, rows)
    assert whole.shape == (3000, 1)
    assert 0.8 < float(np.nanstd(whole[10:])) < 1.25
    stream = ref.new_state()
    cuts = [0, 1, 7, 500, 1501, 2999, 3000]
    parts = np.vstack([stream.residuals(t[a:b], rows[a:b]) for a, b in zip(cuts, cuts[1:])])
    np.testing.assert_array_equal(parts, whole)


def test_a_strength_error_is_absorbed_at_the_stated_time_constant():
    """The caustic is 30 % stronger than the model says from the start: the factor converges at about
    adapt_time_constant_s of pump-on time (within 5 % after 5 of them, not yet after a fifth of one)."""
    ref = flask(adapt_time_constant_s=60.0)
    n = int(5 * 60.0 / DT_S) + 64
    t, rows = simulate(ref, n, lambda k: 2.0, true_factor=lambda k: 1.3, ph0=11.5)
    early = ref.new_state()
    early.residuals(t[:int(12 / DT_S)], rows[:int(12 / DT_S)])
    assert early.factors[1] < 1.15
    late = ref.new_state()
    late.residuals(t, rows)
    assert late.factors[1] == pytest.approx(1.3, rel=0.05)
    assert late.factors[0] == pytest.approx(1.0, abs=0.05)  # the acid was right and stays right


def _model(ref: EstimatorReference, seed0: int) -> LearnedModel:
    runs = [simulate(ref, 2400, lambda k: 2.0 if (k // 300) % 2 == 0 else 0.5, seed=seed0 + i, ph0=10.8 + 0.2 * i)
            for i in range(3)]
    return calibrate_bands(ref, runs, LearnedSettings(sample_time_s=DT_S, observer_time_constant_s=60.0,
                                                      energy_down_variance_ratio=0.05))


def _alarm_times(model: LearnedModel, t: np.ndarray, rows: np.ndarray) -> list[float]:
    events, _, _ = run_record(model, t, rows)
    return [e.time_s for e in events if e.kind == "alarm"]


def test_a_pump_fault_faster_than_the_adaptation_is_not_absorbed():
    """The base pump suddenly stops delivering what is recorded (a blocked line) at 420 s. The strength
    adaptation (time constant 120 s of pump-on time) absorbs a strength error at that pace, so for the first
    100 s after the onset the innovations keep the fault: their mean is below -0.5 sigma (healthy before it:
    within 0.3 sigma of zero) and the base factor has absorbed less than half of the loss (above 0.5)."""
    ref = flask(adapt_time_constant_s=120.0)
    onset = 1200
    flow = lambda k: 2.0 if (k // 300) % 2 == 0 else 0.5  # noqa: E731
    t, faulty = simulate(ref, 2400, flow, true_factor=lambda k: 0.0 if k >= onset else 1.0, seed=7, ph0=11.0)
    stream = ref.new_state()
    r = stream.residuals(t[:onset], faulty[:onset])[:, 0]
    assert abs(float(np.mean(r[100:]))) < 0.3
    after = int(100 / DT_S)
    r_after = stream.residuals(t[onset:onset + after], faulty[onset:onset + after])[:, 0]
    assert float(np.mean(r_after)) < -0.5
    assert stream.factors[1] > 0.5


@pytest.mark.parametrize("fault", ["bias", "frozen"])
def test_probe_faults_raise_an_alarm_after_the_onset_only(fault):
    ref = flask()
    model = _model(ref, 200)
    onset = 1400
    if fault == "bias":
        def change(t, ph):
            return np.where(np.arange(len(ph)) >= onset, ph + 0.3, ph)
    else:
        def change(t, ph):
            return np.where(np.arange(len(ph)) >= onset, ph[onset], ph)
    flow = lambda k: 2.0 if (k // 300) % 2 == 0 else 0.5  # noqa: E731
    t, rows = simulate(ref, 2400, flow, seed=9, fault_ph=change)
    times = _alarm_times(model, t, rows)
    assert times and times[0] >= t[onset]


def test_file_round_trip_and_kinds():
    ref = flask()
    t, rows = simulate(ref, 800, lambda k: 1.0)
    back = reference_from_dict(ref.to_dict())
    np.testing.assert_array_equal(back.new_state().residuals(t, rows), ref.residuals(t, rows))
    assert reference_from_dict({**ref.to_dict(), "correct": False}).correct is False
    with pytest.raises(UserError, match="unknown reference kind"):
        reference_from_dict({"kind": "crystal ball"})
    with pytest.raises(UserError, match="not an estimator reference"):
        reference_from_dict({"kind": "estimator", "feeds": []})


def test_open_loop_is_the_same_physics_never_corrected():
    ref = flask(correct=False)
    t, rows = simulate(ref, 600, lambda k: 1.0)
    stream = ref.new_state()
    stream.residuals(t, rows)
    assert stream.factors == [1.0, 1.0]  # nothing to adapt from
    # the state is the simulation: pH(x) follows the model from the first reading
    assert ref.ph_of_x(stream.x) == pytest.approx(rows[-1, 2], abs=0.15)


def test_the_fit_recovers_the_strength_ratio_of_synthetic_runs():
    truth = flask(base_mM=50.0)
    runs = [simulate(truth, 1500, lambda k: 2.0 if (k // 250) % 2 == 0 else 0.5, seed=30 + i, ph0=11.0)
            for i in range(2)]
    start = flask(base_mM=30.0)
    fitted = fit_reference(runs, start, max_evaluations=200)
    ratio = fitted.feeds[1].strength_mM / fitted.volume_ml
    assert ratio == pytest.approx(50.0 / 1000.0, rel=0.2)
    assert fitted.noise.probe_noise_ph == pytest.approx(0.03, rel=0.35)


def biased_run(onset: int = 1400, bias_ph: float = 0.5) -> tuple[LearnedModel, np.ndarray, np.ndarray]:
    """A detector model of the synthetic flask and a run of it whose reading is off by ``bias_ph`` from sample
    ``onset`` on."""
    ref = flask()
    flow = lambda k: 2.0 if (k // 300) % 2 == 0 else 0.5  # noqa: E731
    t, rows = simulate(ref, 2400, flow, seed=11,
                       fault_ph=lambda t, ph: np.where(np.arange(len(ph)) >= onset, ph + bias_ph, ph))
    return _model(ref, 300), t, rows


def test_alarms_are_named_the_same_whatever_the_chunking():
    """The detector names an estimator alarm NAMING_AFTER samples after its detection from the rows it kept:
    the same family, class and size for any chunking of the record (the node gets rows a few at a time)."""
    model, t, rows = biased_run()
    whole, _, _ = run_record(model, t, rows, chunk=None)
    named = [e for e in whole if e.kind == "named"]
    assert named and named[0].alarm["isolation"]["family"] == "sensor"
    assert named[0].alarm["isolation"]["fault_class"] == "probe_bias"
    for chunk in (1, 7, 500):
        again, _, _ = run_record(model, t, rows, chunk=chunk)
        assert [(e.kind, e.index, e.message) for e in again] == [(e.kind, e.index, e.message) for e in whole]



def _zoned_run(ref: EstimatorReference, n: int, seed: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Base pumped in 350 s bursts against a steady acid, pH swinging 2..12; the base acts at half its strength
    while the pH is above 9 (a buffer the curve lacks takes the rest): an apparent strength that depends on pH."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * DT_S
    qb = np.where((np.arange(n) // 1000) % 2 == 0, 4.0, 0.0)
    qa = np.full(n, 2.0)
    x = float(ref.x_of_ph(np.array([7.0]))[0])
    ph = np.empty(n)
    for k in range(n):
        if k:
            f = 0.5 if ref.ph_of_x(x) >= 9.0 else 1.0
            d = (qa[k - 1] + qb[k - 1]) / ref.volume_ml
            u = (-20.0 * qa[k - 1] + ref.feeds[1].strength_mM * f * qb[k - 1]) / ref.volume_ml
            x = u / d + (x - u / d) * math.exp(-d * DT_S)
        ph[k] = ref.ph_of_x(x)
    return t, np.column_stack((qa, qb, np.round(ph + rng.normal(0.0, 0.03, n), 2)))


def test_each_ph_zone_learns_its_own_apparent_strength():
    """Hidden: the base's apparent strength is 0.5 above pH 9 and 1.0 below. With the zones (pH 5 and 9) the basic
    zone's base factor learns 0.5 and the acid zone's stays at 1.0, and the innovations of the run's second half
    have unit scale; one factor for all pH carries the basic side's 0.5 into the acid side (what happened on the
    rig's April titration), and the same innovations spread half as wide again."""
    ref = flask(adapt_time_constant_s=60.0)
    t, rows = _zoned_run(ref, 8000)
    zoned = ref.new_state()
    z = zoned.residuals(t, rows)[:, 0]
    acid_zone, _, basic_zone = zoned.zone_factors
    assert basic_zone[1] == pytest.approx(0.5, abs=0.05)
    assert acid_zone[1] == pytest.approx(1.0, abs=0.05)
    one = ref.with_values(adapt_zones_ph=()).new_state()
    z1 = one.residuals(t, rows)[:, 0]
    rms = lambda r: float(np.sqrt(np.mean(r[len(r) // 2:] ** 2)))  # noqa: E731
    assert rms(z) < 1.1
    assert rms(z1) > 1.3 * rms(z)


def test_the_residual_is_limited_and_files_before_the_zones_keep_their_residual():
    """The residual is the standardised innovation in x, limited to +-clip_sigma; a reference file written before
    2026-11-28 (no zones, innovation or clip keys) reads as what it was: one factor, the pH innovation, no limit."""
    ref = flask()
    t, rows = simulate(ref, 1200, lambda k: 2.0)
    rows[600:, 2] = np.clip(rows[600:, 2] + 1.5, 0.0, 14.0)  # a probe that jumps by 1.5 pH
    r = ref.residuals(t, rows)[:, 0]
    assert float(np.max(np.abs(r))) == pytest.approx(4.0)
    old = {k: v for k, v in ref.to_dict().items() if k not in ("adapt_zones_ph", "innovation", "clip_sigma")}
    back = reference_from_dict(old)
    assert (back.adapt_zones_ph, back.innovation, back.clip_sigma) == ((), "ph", 0.0)
    assert float(np.max(np.abs(back.residuals(t, rows)[:, 0]))) > 4.0
    assert reference_from_dict(ref.to_dict()).to_dict() == ref.to_dict()
    with pytest.raises(UserError, match="adapt_zones_ph"):
        flask(adapt_zones_ph=(9.0, 5.0))
    with pytest.raises(UserError, match="innovation"):
        flask(innovation="volts")


@pytest.mark.parametrize("variant", ["zones, x innovation", "one zone, ph innovation", "open loop", "gated"])
def test_the_compiled_recursion_is_the_written_one(variant):
    """The filter runs compiled (wavelet_fdi.estimator_kernel, Numba); the same function interpreted by Python must
    give the same residuals, likelihood, factors, adaptation trace and state to the last bit (no fast-math, no
    reordering): on a run with pH zones, pumps switching, missing flows and readings, in three chunks."""
    from wavelet_fdi import estimator_kernel

    ref = flask(adapt_time_constant_s=60.0)
    if variant == "one zone, ph innovation":
        ref = ref.with_values(adapt_zones_ph=(), innovation="ph", clip_sigma=0.0)
    elif variant == "open loop":
        ref = ref.with_values(correct=False)
    elif variant == "gated":
        ref = ref.with_values(gate_sigma=4.0)
    t, rows = _zoned_run(ref, 3000)
    if variant == "gated":  # lone glitches (one at a chunk's end), a step, and two glitches in a row
        rows[[300, 1776, 2400], 2] += 1.5
        rows[2000:, 2] -= 0.8
        rows[[2600, 2601], 2] += 2.0
    rows[[5, 700, 701], 1] = np.nan  # a flow missing: held
    rows[[0, 1, 1500], 2] = np.nan  # readings missing: the state starts at the first and predicts through the other

    def run(kernel):
        stream = ref.new_state()
        stream.adapt_trace = []
        saved, estimator_kernel._COMPILED = estimator_kernel._COMPILED, kernel
        try:
            r = np.vstack([stream.residuals(t[a:b], rows[a:b]) for a, b in ((0, 1), (1, 1777), (1777, 3000))])
        finally:
            estimator_kernel._COMPILED = saved
        return r, stream

    compiled = estimator_kernel.compiled()
    r_c, s_c = run(compiled)
    r_i, s_i = run(estimator_kernel._run)
    assert np.isfinite(r_c[2:]).sum() > 2900  # it ran
    assert (len(s_c.adapt_trace) > 10) == ref.correct  # and adapted (open loop: nothing corrected, nothing learned)
    np.testing.assert_array_equal(r_c, r_i)
    if variant == "gated":
        assert s_c.held == s_i.held
    assert (s_c.nll, s_c.x, s_c.p, s_c.zone_factors, s_c.adapt_trace) == (s_i.nll, s_i.x, s_i.p, s_i.zone_factors,
                                                                           s_i.adapt_trace)


def _gate_run(n: int = 1200) -> tuple[EstimatorReference, np.ndarray, np.ndarray]:
    # nothing adapting: the state is x and P alone; the gate above the run's largest innovation (11.7 sigma: the
    # base's strength the model gets wrong above pH 9, not adapted)
    ref = flask(adapt_time_constant_s=0.0, gate_sigma=12.5)
    t, rows = _zoned_run(ref, n)
    return ref, t, rows


def test_the_gate_drops_a_lone_glitch_as_a_missing_reading():
    """One reading 2 pH off and back at the next: held at the gate, and dropped when the next reading is back
    within it. The filter's state afterwards is exactly that of the same run with the reading missing (ungated,
    the state jumped toward the glitch); its own innovation is still reported (what the spike check reads)."""
    ref, t, rows = _gate_run()
    glitch, missing = rows.copy(), rows.copy()
    glitch[600, 2] -= 2.0
    missing[600, 2] = np.nan
    g, m_ = ref.new_state(), ref.new_state()
    r = g.residuals(t, glitch)
    m_.residuals(t, missing)
    assert abs(g.last_unlimited[600, 0]) > 12.5, "the glitch is within the gate: nothing tested"
    assert (g.x, g.p) == (m_.x, m_.p)
    ungated = ref.with_values(gate_sigma=0.0).new_state()
    ungated.residuals(t, glitch)
    assert abs(ungated.x - m_.x) > 0 and r[600, 0] == pytest.approx(-4.0)


def test_the_gate_follows_a_step_as_the_ungated_filter_does():
    """The reading steps 2 pH and stays (the filter here follows over tens of samples, every innovation beyond the
    gate): each reading is held, confirmed by the next and its update made after all, so every innovation is the
    ungated filter's to the last bit, whatever the chunking (a held reading at a chunk's end waits for the next
    chunk), and the state is the ungated one's but for the one reading still held."""
    ref, t, rows = _gate_run()
    rows[600:, 2] += 2.0
    ungated = ref.with_values(gate_sigma=0.0).new_state()
    r_u = ungated.residuals(t, rows)
    u_unlimited = ungated.last_unlimited
    for cut in (601, 900):
        gated = ref.new_state()
        r_g = np.vstack([gated.residuals(t[:cut], rows[:cut]), gated.residuals(t[cut:], rows[cut:])])
        np.testing.assert_array_equal(r_g, r_u)
        np.testing.assert_array_equal(gated.last_unlimited, u_unlimited[cut:])
        assert abs(u_unlimited[-1, 0]) > 12.5 and gated.held[2] != 0.0, "the last reading is not held: nothing tested"
        nu, sv, _ = gated.held
        gain = gated.p / sv  # the held reading's update, as the next reading would make it
        assert (gated.x + gain * nu, (1.0 - gain) * gated.p) == pytest.approx((ungated.x, ungated.p), rel=1e-12)
