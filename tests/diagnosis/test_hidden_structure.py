"""Hide a structural effect of a real dosing rig in simulated data; the diagnosis must name it with its parameter.

The plant is the teaching-lab rig's model (``rig_flask``: H2SO4 and NaOH pumped into a stirred overflow flask,
1 L here). The acid pump steps between rates, the base pump doses in on/off pulses at several speeds (the
excitation a pump curve and a dead time need), and the pH meter reads with noise. Hidden, one at a time: a mixing
zone the base is dosed into, a dead time of the base line, the base pump's delivery curve, carbonate carried by the
base. Only a CSV (neutral name; time, both measured pump flows, pH) and the nominal model reach `phfdi diagnose`,
through its command line; the candidates it chooses among include the structural ones and the usual causes a rig
engineer would suspect first (probe delay and lag, reagent strength, a buffer, the flask volume). A fresh seed per
run (printed; PHFDI_HIDDEN_SEED reproduces).
"""

from __future__ import annotations

import numpy as np
import pytest
from hidden_cases import fresh_draws  # (conftest puts this folder on sys.path; other tests import this module by name)

from phfdi.diagnosis.model import nominal_raw
from phfdi.diagnosis.residual import noise_floor
from phfdi.loop import simulate_open_loop
from phfdi.records.record import Record
from phfdi_base.spec import validate_scenario

DT_S = 1.0
DURATION_S = 700.0
NOISE_PH = 0.02
NOMINAL = ["plant.tank.volume_ml=1000"]
CANDIDATES = ["mixing_zone", "feed_delay", "pump_curve", "carbonate", "sensor_delay", "sensor_lag",
              "reagent_concentration", "buffer", "holdup"]


def inputs(rng) -> Record:
    """Acid steps between 2 and 6 mL/s; base pulses of 15..50 s at 2..6.45 mL/s, 30..110 s apart."""
    t = np.arange(0.0, DURATION_S + DT_S / 2, DT_S)
    acid = np.empty_like(t)
    k = 0
    while k < len(t):
        n = int(rng.uniform(80, 160) / DT_S)
        acid[k:k + n] = rng.uniform(2.0, 6.0)
        k += n
    base = np.zeros_like(t)
    k = int(rng.uniform(20, 60) / DT_S)
    while k < len(t):
        n = int(rng.uniform(15, 50) / DT_S)
        base[k:k + n] = rng.choice([2.0, 3.5, 5.0, 6.45])
        k += n + int(rng.uniform(30, 110) / DT_S)
    return Record.of({"time_s": t, "acid_flow_ml_s": acid, "base_flow_ml_s": base})


def balanced_inputs(rng) -> Record:
    """Acid steps as in :func:`inputs`; base pulses 20..60 s apart at 2..6.45 mL/s, each long enough to deliver
    0.6..1.8 times the acid (in equivalents of the nominal strengths) that flowed since the last, the first also
    1.0..1.4 times the acid the flask starts with: an on/off pH loop's duty cycle, swinging the flask's pH through
    neutral again and again."""
    raw = nominal_raw("rig_flask", NOMINAL)
    acid_eq = 2.0 * raw["plant"]["feeds"]["acid"]["recipe"]["H2SO4"]  # mol/L of protons
    base_eq = raw["plant"]["feeds"]["base"]["recipe"]["NaOH"]
    stock = rng.uniform(1.0, 1.4) * raw["plant"]["tank"]["volume_ml"] * acid_eq  # mmol: the flask starts acidic
    run = inputs(rng)
    t, acid = run["time_s"], run["acid_flow_ml_s"]
    base = np.zeros_like(t)
    k = gap = int(rng.uniform(10, 40) / DT_S)
    while k < len(t):
        q = float(rng.choice([2.0, 3.5, 5.0, 6.45]))
        due = (rng.uniform(0.6, 1.8) * float(np.sum(acid[max(0, k - gap):k])) * DT_S * acid_eq + stock) / (q * base_eq)
        stock = 0.0
        gap = int(rng.uniform(20, 60) / DT_S)
        n = max(1, int(round(due / DT_S)))
        base[k:k + n] = q
        k += n + gap
    return Record.of({"time_s": t, "acid_flow_ml_s": acid, "base_flow_ml_s": base})


def draw(rng, cause: str) -> tuple[dict, str, float, float]:
    """(scenario edit, main parameter, true value, tolerance)."""
    if cause == "mixing_zone":
        v = float(rng.uniform(20.0, 60.0))  # 2..6 % of the flask
        x = float(rng.uniform(3.0, 8.0))  # mL/s: a few times the inflow
        return ({"mixing": {"zone_volume_ml": v, "exchange_ml_s": x, "feeds": ["base"]}},
                "zone_volume_ml", v, 0.25 * v)
    if cause == "feed_delay":
        d = float(rng.uniform(8.0, 20.0))  # below about 7 s some draws move the pH by less than 3 x the noise
        return {"line": [{"type": "line_delay", "params": {"delay_s": d}}]}, "delay_s", d, max(1.0, 0.1 * d)
    if cause == "pump_curve":
        thr = float(rng.uniform(0.6, 1.4))
        gain = float(rng.choice([rng.uniform(0.75, 0.9), rng.uniform(1.1, 1.25)]))
        return ({"line": [{"type": "pump_curve", "params": {"gain": gain, "threshold_ml_s": thr}}]},
                "threshold_ml_s", thr, 0.2)
    if cause == "carbonate":
        c = float(rng.uniform(0.002, 0.006))  # mol/L carbonate in 20 mM caustic
        return {"carbonate": c}, "conc_mol_l", c, 0.2 * c
    if cause == "pump_lag":
        up = float(rng.uniform(6.0, 15.0))  # s: a diaphragm pump's slow start against the line's compliance
        down = float(rng.uniform(1.0, 4.0))
        return ({"line": [{"type": "pump_lag", "params": {"tau_start_s": up, "tau_stop_s": down}}]},
                "tau_start_s", up, max(1.0, 0.2 * up))
    if cause == "sensor_second_order":
        t1 = float(rng.uniform(8.0, 20.0))  # s: a fouled junction (slow) behind the glass membrane (fast)
        t2 = float(rng.uniform(0.4, 1.0)) * t1
        return ({"sensor": [{"type": "sensor_second_order", "params": {"tau1_s": t1, "tau2_s": t2}}]},
                "tau1_s", max(t1, t2), 0.25 * max(t1, t2))
    if cause == "tanks_in_series":
        n = int(rng.integers(2, 6))  # 2..5 compartments: between a stirred flask and a long tube
        return {"series": n}, "n_tanks", float(n), 0.5
    if cause == "co2_absorption":
        kla = float(rng.uniform(0.004, 0.012))  # 1/s: faster than the flask's turnover (about 0.004 1/s)
        ceq = float(rng.uniform(0.002, 0.005))  # mol/L
        return {"air": (kla, ceq)}, "equilibrium_mol_l", ceq, 0.3 * ceq
    if cause == "flask_contents":
        pka = float(rng.uniform(6.9, 8.5))  # a phosphate-like buffer, away from carbonate's 6.35 and 10.33
        conc = float(rng.uniform(0.5e-3, 2e-3))  # mol/L in the flask's own water at the start
        return {"contents": (conc, pka)}, "pka", pka, 0.1
    raise ValueError(cause)


def make_case(rng, cause: str, folder, truth: dict | None = None, balanced: bool = False):
    """The record's CSV and (main parameter, true value, tolerance); ``truth`` (the test's own) gets the edit;
    ``balanced``: the excitation of :func:`balanced_inputs` (always for the flask's contents)."""
    raw = nominal_raw("rig_flask", NOMINAL)
    raw["sensors"]["ph"]["noise_std"] = 0.0
    edit, main, value, tol = draw(rng, cause) if cause != "none" else ({}, "", 0.0, 0.0)
    if truth is not None:
        truth.update(edit)
    if "mixing" in edit:
        raw["plant"]["mixing"] = edit["mixing"]
    if "line" in edit:
        raw["plant"]["feeds"]["base"]["line"] = edit["line"]
    if "series" in edit:
        from phfdi.diagnosis.catalogue import _set_series

        _set_series(raw, edit["series"])
    if "air" in edit:
        from phfdi.diagnosis.catalogue import _set_air_exchange

        _set_air_exchange(raw, *edit["air"])
    if "sensor" in edit:
        raw["sensors"]["ph"]["extra"] = edit["sensor"]
    if "carbonate" in edit:
        from phfdi.diagnosis.catalogue import _add_carbonate

        _add_carbonate(raw, "base", edit["carbonate"])
    if "contents" in edit:  # the flask starts holding a weak acid of its own, which then washes out
        from phfdi.diagnosis.catalogue import _set_contents

        _set_contents(raw, "weak_acid", *edit["contents"])
    raw["duration_s"] = DURATION_S
    # A draw of the pulses can leave the effect within 3 x the noise of the nominal model (a feed dead time of
    # 9.2 s moved the pH by 2.35 x the noise in seed 3598687396: most pulses ended in excess base, where the pH
    # hardly moves): such a record tests nothing, so the pulses and the noise are drawn again (the effect kept).
    for _ in range(10):
        # what the flask holds at the start washes out within a few residence times (about 200 s): base dosed as an
        # on/off pH loop doses it swings the pH through the buffer's range several times meanwhile
        inp = balanced_inputs(rng) if balanced or cause == "flask_contents" else inputs(rng)
        run = simulate_open_loop(validate_scenario(raw), inp)
        # what the probe reads (noise-free) when the probe's dynamics are the hidden effect, else the flask's pH
        clean = run["ph_measured"] if "sensor" in edit else run["ph_true"]
        ph = clean + rng.normal(0.0, NOISE_PH, len(clean))
        if cause == "none" or _nominal_misfit(inp, ph) > 3.0:
            break
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "record.csv"
    cols = {"time_s": inp["time_s"], "acid_flow_ml_s": inp["acid_flow_ml_s"], "base_flow_ml_s": inp["base_flow_ml_s"],
            "ph_measured": ph}
    np.savetxt(path, np.column_stack(list(cols.values())), delimiter=",", header=",".join(cols), comments="",
               fmt="%.6g")
    return path, main, value, tol


def _nominal_misfit(inp: Record, ph: np.ndarray) -> float:
    """The nominal model's held-out error over the noise floor, as `phfdi diagnose` reports it
    (``nominal.combined_rmse_over_noise``: blocks 2, 4, 6, 8 of 8, the floor estimated from the data)."""
    raw = nominal_raw("rig_flask", NOMINAL)
    raw["sensors"]["ph"]["noise_std"] = 0.0
    raw["duration_s"] = DURATION_S
    sim = simulate_open_loop(validate_scenario(raw), inp)["ph_measured"]
    held_out = (np.arange(len(ph)) * 8 // len(ph)) % 2 == 1
    return float(np.sqrt(np.mean((ph - sim)[held_out] ** 2))) / noise_floor(ph)


#: a vessel's structure competes with the other ways its response can be slow, late or buffered
VESSEL = ["tanks_in_series", "co2_absorption", "mixing_zone", "feed_delay", "sensor_lag", "sensor_delay", "holdup",
          "reagent_concentration", "carbonate", "buffer"]
#: the dynamics candidates compete with each other and with the usual suspects of a slow or late response
DYNAMICS = ["pump_lag", "feed_delay", "sensor_second_order", "sensor_lag", "sensor_delay", "probe_asymmetric_lag",
            "holdup", "reagent_concentration"]


def _diagnose(diagnose_json, path, tmp_path, candidates=CANDIDATES) -> dict:
    return diagnose_json("--data", path, "--model", "rig_flask", "--set", NOMINAL[0],
                         "--candidates", *candidates, "--no-pairs", "--out", tmp_path / "report")


#: each side of a reported 95 % interval stretched to 99.9 % (normal quantiles 3.29 / 1.96)
TO_999 = 3.2905267314919255 / 1.959963984540054


def _at_the_floor_or_as_good_as_the_data_allow(rep: dict, cause: str, main: str, value: float, tol: float,
                                               what: str) -> None:
    """The named fit reaches the noise floor held out (explained, or within 5 x it), or it is as good as the data
    allow: the truth is inside its interval (stretched from 95 % to 99.9 %), and the 95 % interval is within the
    tolerance.

    Physics: at 1 s sampling the pH crosses equivalence between two samples after a pulse edge, and at such a
    sample a dead time 0.2 s off, a pump's start lag or threshold a few per cent off, misses by up to 100 x the
    noise. The training blocks pin the parameter only as well as their own crossings allow, while one or two
    held-out crossings make the held-out error of a fit that is right to the data's resolution 5..10 x the noise
    (feed dead time, seed 585102819: 10.28 s fitted for 10.11 s, training error 322.7 there against 323.6 at the
    truth, 4.9 x held out; seed 3534516178: 16.95 s for 17.09 s, 310.5 against 315.0, 10.3 x; pump start lag,
    seed 1173253412: 9.29 s for 9.27 s, 361.2 against 363.7, 5.6 x, where the truth scores 1.03 x held out).
    The training error at the fit is below the truth's: no search can do better on these data. The interval is
    stretched because a 95 % interval leaves out the truth of a right fit in one draw in 20 by its definition
    (seed 3534516178: interval [16.86, 17.04] s, the truth 3.0 of its standard deviations from the fit; the
    training error's rise from the fit to the truth, 4.5 at a noise variance of 0.89, says 2.3).
    """
    interval = next(r["confidence_intervals"][main] for r in rep["ranking"] if r["cause"] == cause)
    fitted = rep["parameters"][main]
    lo, hi = fitted - TO_999 * (fitted - interval[0]), fitted + TO_999 * (interval[1] - fitted)
    resolved = lo <= value <= hi and interval[1] - interval[0] <= 2 * tol
    assert rep["verdict"] == "explained" or rep["validation_rmse_over_noise"] < 5.0 or resolved, \
        f"{what}: {rep['reason']} (95 % interval {interval})"


@pytest.mark.parametrize("cause", ["mixing_zone", "feed_delay", "pump_curve", "carbonate"])
@fresh_draws
def test_structural_effect_is_named_with_its_parameter(hidden_rng, diagnose_json, tmp_path, cause):
    path, main, value, tol = make_case(hidden_rng, cause, tmp_path / "data")
    rep = _diagnose(diagnose_json, path, tmp_path)
    what = f"hidden {cause} {main} = {value:.4g}"
    assert rep["nominal"]["combined_rmse_over_noise"] > 3.0, f"{what}: the effect is too small to test"
    # named, with its parameter; the fit gets within a few times the noise floor (a pump curve or a mixing zone
    # in strong acid-strong base sits in a narrow valley where the polish may stop short of the floor: then
    # the verdict is not_explained with this closest cause, docs/diagnosis.md)
    assert rep["cause"] == cause, f"{what}: named {rep['cause']} ({rep['reason']})"
    fitted = rep["parameters"][main]
    _at_the_floor_or_as_good_as_the_data_allow(rep, cause, main, value, tol, what)
    assert abs(fitted - value) <= tol, f"{what}: fitted {fitted:.4g} +- {tol:.3g}"
    assert rep["fixed"]["feed"] == "base", f"{what}: found on the {rep['fixed']['feed']} feed"


@fresh_draws
def test_no_structural_effect_comes_back_none(hidden_rng, diagnose_json, tmp_path):
    path, *_ = make_case(hidden_rng, "none", tmp_path / "data")
    rep = _diagnose(diagnose_json, path, tmp_path)
    assert rep["verdict"] == "none", rep["reason"]
    assert rep["cause"] == "none"


@pytest.mark.parametrize("cause", ["pump_lag", "sensor_second_order"])
@fresh_draws
def test_dynamics_of_pump_or_probe_is_named_with_its_parameter(hidden_rng, diagnose_json, tmp_path, cause):
    """A pump's slow start (on/off dosing) and a probe with two lags: each among the other ways a response comes
    late or slow (a line dead time, one probe lag or delay, an asymmetric probe, the holdup, the reagent strength)."""
    path, main, value, tol = make_case(hidden_rng, cause, tmp_path / "data")
    rep = _diagnose(diagnose_json, path, tmp_path, DYNAMICS)
    what = f"hidden {cause} {main} = {value:.4g}"
    assert rep["nominal"]["combined_rmse_over_noise"] > 3.0, f"{what}: the effect is too small to test"
    assert rep["cause"] == cause, f"{what}: named {rep['cause']} ({rep['reason']})"
    _at_the_floor_or_as_good_as_the_data_allow(rep, cause, main, value, tol, what)
    fitted = rep["parameters"][main]
    assert abs(fitted - value) <= tol, f"{what}: fitted {fitted:.4g} +- {tol:.3g}"
    if cause == "pump_lag":
        assert rep["fixed"]["feed"] == "base", f"{what}: found on the {rep['fixed']['feed']} feed"


@pytest.mark.parametrize("cause", ["tanks_in_series", "co2_absorption"])
@fresh_draws
def test_vessel_structure_is_named_with_its_parameter(hidden_rng, diagnose_json, tmp_path, cause):
    """A plug-flow-like flask (compartments in series) and CO2 taken up from the air, among the other ways the
    flask's response is late, slow or buffered (mixing zone, dead time, probe lag, volume, reagent strength,
    carbonate in the caustic, a weak acid in a feed)."""
    path, main, value, tol = make_case(hidden_rng, cause, tmp_path / "data")
    rep = _diagnose(diagnose_json, path, tmp_path, VESSEL)
    what = f"hidden {cause} {main} = {value:.4g}"
    assert rep["nominal"]["combined_rmse_over_noise"] > 3.0, f"{what}: the effect is too small to test"
    assert rep["cause"] == cause, f"{what}: named {rep['cause']} ({rep['reason']})"
    assert rep["verdict"] == "explained" or rep["validation_rmse_over_noise"] < 5.0, f"{what}: {rep['reason']}"
    fitted = rep["parameters"][main]
    assert abs(fitted - value) <= tol, f"{what}: fitted {fitted:.4g} +- {tol:.3g}"


#: what the flask holds at the start competes with the other ways a rig's response is buffered or slow: a weak
#: acid carried by a feed, carbonate in the caustic, CO2 from the air, the flask volume, the reagent strength, the
#: probe's lag and a feed line's dead time
CONTENTS = ["flask_contents", "buffer", "carbonate", "co2_absorption", "holdup", "reagent_concentration",
            "sensor_lag", "feed_delay"]


@fresh_draws
def test_flask_contents_are_named_with_their_pka_and_amount(hidden_rng, diagnose_json, tmp_path):
    """The flask starts holding a weak acid of its own (pKa 6.9..8.5, 0.5..2 mM) that then washes out; the record
    starts where the inputs put it, so its start pH is fitted (``--initial fit``, as for the rig's runs)."""
    edit: dict = {}
    path, main, value, tol = make_case(hidden_rng, "flask_contents", tmp_path / "data", edit)
    rep = diagnose_json("--data", path, "--model", "rig_flask", "--set", NOMINAL[0], "--initial", "fit",
                        "--candidates", *CONTENTS, "--no-pairs", "--out", tmp_path / "report")
    truth = edit["contents"][0]
    what = f"hidden flask contents pKa {value:.3f}, {1e3 * truth:.3f} mM"
    assert rep["nominal"]["combined_rmse_over_noise"] > 3.0, f"{what}: the effect is too small to test"
    assert rep["cause"] == "flask_contents", f"{what}: named {rep['cause']} ({rep['reason']})"
    assert rep["fixed"]["species"] == "weak_acid", f"{what}: named {rep['fixed']}"
    assert rep["verdict"] == "explained" or rep["validation_rmse_over_noise"] < 5.0, f"{what}: {rep['reason']}"
    assert abs(rep["parameters"]["pka"] - value) <= tol, f"{what}: fitted pKa {rep['parameters']['pka']:.3f}"
    # the amount is the record's own (a per-record parameter, named after the record): within 10 %, or, where the
    # draw cannot pin it that well, inside the interval the diagnosis reports (stretched to 99.9 %). A buffer near
    # the top of the drawn pKa range trades its amount against its pKa over the few swings the record has before
    # it washes out (seed 2516608233: pKa 8.388, 1.94 mM; fitted 8.477, 2.35 mM, 95 % interval [1.28, 4.33] mM,
    # held out at the noise floor, 0.86 x)
    conc = {k: v for k, v in rep["parameters"].items() if k.startswith("conc_mol_l[")}
    assert len(conc) == 1, f"{what}: fitted {conc}"
    (key, fitted), = conc.items()
    lo, hi = rep["confidence_intervals"][key]
    inside = fitted - TO_999 * (fitted - lo) <= truth <= fitted + TO_999 * (hi - fitted)
    assert abs(fitted - truth) <= 0.1 * truth or inside, f"{what}: fitted {fitted:.4g} [{lo:.4g}, {hi:.4g}]"


@fresh_draws
def test_no_flask_contents_with_a_fitted_start_comes_back_none(hidden_rng, diagnose_json, tmp_path):
    path, *_ = make_case(hidden_rng, "none", tmp_path / "data", balanced=True)
    rep = diagnose_json("--data", path, "--model", "rig_flask", "--set", NOMINAL[0], "--initial", "fit",
                        "--candidates", *CONTENTS, "--no-pairs", "--out", tmp_path / "report")
    assert rep["verdict"] == "none", rep["reason"]
    assert rep["cause"] == "none"
