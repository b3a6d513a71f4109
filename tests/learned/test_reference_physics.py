"""The paper loop's physics as a reference kind of the multichannel detector (wavelet_fdi.reference_physics)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from phfdi.loop import simulate
from phfdi.scenario import load_scenario
from phfdi_base.errors import UserError
from wavelet_fdi.learned_detector import LearnedSettings, calibrate_bands, run_record
from wavelet_fdi.reference_physics import PhysicsReference
from wavelet_fdi.references import reference_from_dict

SHORT = ["duration_s=3000", "setpoints.ph.initial=8", "setpoints.ph.changes=[]"]
ONSET_S = 2000.0


def record(seed: int, fault: str = "healthy") -> tuple[PhysicsReference, np.ndarray, np.ndarray]:
    spec = load_scenario("paper", fault=fault, overrides=SHORT + [f"seed={seed}"],
                         onset_s=None if fault == "healthy" else ONSET_S)
    run = simulate(spec)
    ref = PhysicsReference.from_spec(spec)
    return ref, np.asarray(run.time_s, float), np.column_stack([np.asarray(run[c], float) for c in ref.channels])


def test_healthy_residuals_are_the_sensor_noise_and_any_chunking_gives_them():
    ref, t, x = record(11)
    r = ref.residuals(t, x)
    after = r[ref.lags:]
    assert r.shape == (len(t), 2)
    assert np.all(np.abs(np.std(after, axis=0) - 1.0) < 0.1) and np.all(np.abs(np.mean(after, axis=0)) < 0.1)
    stream = ref.new_state()
    parts = [stream.residuals(t[a:a + 333], x[a:a + 333]) for a in range(0, len(t), 333)]
    assert np.array_equal(np.concatenate(parts), r, equal_nan=True)
    # the reference file's entry gives the same reference
    again = reference_from_dict(ref.to_dict())
    assert isinstance(again, PhysicsReference) and np.array_equal(again.residuals(t, x), r, equal_nan=True)


def test_the_multichannel_detector_on_the_physics_finds_a_sticky_valve_and_only_after_it():
    ref, _, _ = record(12)
    runs = [record(s)[1:] for s in (13, 14)]
    model = calibrate_bands(ref, runs, LearnedSettings(level=3, sample_time_s=1.0))
    _, t, x = record(15, "stiction")
    events, _, _ = run_record(model, t, x)
    alarms = [e.time_s for e in events if e.kind == "alarm"]
    assert alarms and alarms[0] >= ONSET_S, alarms
    _, t, x = record(16)
    assert not [e for e in run_record(model, t, x)[0] if e.kind == "alarm"]


@pytest.mark.parametrize("fault,params", [("backlash", {"width_pct": 1.0}), ("deadzone", {"width_pct": 100.0})])
def test_an_alarm_is_named_by_the_physics_detectors_isolation(fault, params):
    """The kind's namer re-runs its model from the ring's first row and fits every valve and probe hypothesis from
    the last snapshot before the onset: the fault is named, with its size, 300 s after the detection."""
    ref, _, _ = record(21)
    ref = PhysicsReference.from_spec(ref.spec, watch_level=False)
    model = calibrate_bands(ref, [record(s)[1:] for s in (22, 23)],
                            LearnedSettings(level=3, residual_mean_k=0.5, sample_time_s=1.0))
    spec = load_scenario("paper", fault=fault, overrides=SHORT + ["seed=24"] +
                         [f"faults.0.params.{k}={v}" for k, v in params.items()], onset_s=ONSET_S)
    run = simulate(spec)
    x = np.column_stack([np.asarray(run[c], float) for c in ref.channels])
    events, _, det = run_record(model, np.asarray(run.time_s, float), x)
    named = [e for e in events if e.kind == "named"]
    assert named and det.alarms[0]["detection_time"] >= ONSET_S
    iso = det.alarms[0]["isolation"]
    assert iso["fault_class"] == fault and iso["family"] == "actuator", iso
    assert named[0].time_s == pytest.approx(det.alarms[0]["detection_time"] + 300.0, abs=1.0)
    main = next(iter(params))
    assert iso["size"] == pytest.approx(params[main], rel=0.3) and iso["unit"] == "% of span"


def test_a_command_missing_for_long_holds_detection_and_restarts_the_model():
    """A setpoint step while the valve command is missing: the valve moves unseen. Past command_timeout_s the kind
    holds its residuals and says so; when the command returns it restarts its model on the measurements and warms
    up again, so the healthy run gives no fault alarm (holding the last command raised two on each of four such
    runs, seeds 34-37, before: one in the gap, one after it); any chunking gives the same events; a gap within the
    timeout is bridged by the last command, unreported."""
    def run(seed: int, step: bool) -> tuple[np.ndarray, np.ndarray]:
        changes = "[{at_s: 1500, value: 8.5}]" if step else "[]"
        spec = load_scenario("paper", fault="healthy", overrides=["duration_s=4000", "setpoints.ph.initial=8",
                                                                  f"setpoints.ph.changes={changes}", f"seed={seed}"])
        rec = simulate(spec)
        return np.asarray(rec.time_s, float), np.column_stack([np.asarray(rec[c], float) for c in ref.channels])

    ref = PhysicsReference.from_spec(record(31)[0].spec, watch_level=False)
    model = calibrate_bands(ref, [run(s, False) for s in (32, 33)],
                            LearnedSettings(level=3, residual_mean_k=0.5, sample_time_s=1.0))
    t, x = run(34, True)
    x[(t >= 1200.0) & (t < 2400.0), 0] = np.nan
    events, _, det = run_record(model, t, x)
    assert not det.alarms, det.alarms
    said = [(e.time_s, e.message.split(":")[0]) for e in events]
    assert said == [(1210.0, "valve command missing for more than 10 s"),
                    (2400.0, "valve command back"),
                    (3000.0, "detection resumed at 3000 s")], said  # the measurement is not blamed
    assert [e.level for e in events] == ["WARN", "WARN", "OK"] and det.input_problem == ""
    r = ref.residuals(t, x)[:, 0]
    assert np.all(np.isnan(r[(t >= 1210.0) & (t < 3000.0)])) and np.all(np.isfinite(r[t >= 3000.0]))
    assert np.std(r[t >= 3000.0]) < 1.3  # the restarted model follows the plant: the sensor's noise again
    chunked = run_record(model, t, x, chunk=333)[0]
    assert [(e.kind, e.index, e.message) for e in chunked] == [(e.kind, e.index, e.message) for e in events]
    t, x = run(35, True)
    x[(t >= 3300.0) & (t < 3308.0), 0] = np.nan  # 8 s, in a steady stretch: within the 10 s timeout
    events, _, det = run_record(model, t, x)
    assert not events and not det.alarms


def test_the_setpoint_hold_off_holds_the_residuals_after_each_setpoint_change_and_nowhere_else():
    """setpoint_holdoff_s (off by default, as in the physics detector): the residuals are held that long after each
    pH setpoint change; elsewhere they are the residuals without it. On, the reference reads ph_setpoint; its file
    keeps the setting; any chunking gives the same."""
    spec = load_scenario("paper", fault="healthy", overrides=[
        "duration_s=3000", "setpoints.ph.initial=8", "seed=41",
        "setpoints.ph.changes=[{at_s: 1000, value: 8.5}, {at_s: 2000, value: 8}]"])
    run = simulate(spec)
    t = np.asarray(run.time_s, float)
    off, on = PhysicsReference.from_spec(spec), PhysicsReference.from_spec(spec, setpoint_holdoff_s=150.0)
    assert "ph_setpoint" not in off.channels and on.channels == off.channels + ("ph_setpoint",)
    x_off, x_on = (np.column_stack([np.asarray(run[c], float) for c in ref.channels]) for ref in (off, on))
    r_off, r_on = off.residuals(t, x_off), on.residuals(t, x_on)
    setpoint = np.asarray(run["ph_setpoint"], float)
    changes = np.flatnonzero(np.diff(setpoint) != 0) + 1
    assert len(changes) == 2
    since = np.arange(len(t))[:, None] - changes[None, :]
    held = ((since >= 0) & (since < 150)).any(axis=1)
    assert np.all(np.isnan(r_on[held])) and np.array_equal(r_on[~held], r_off[~held], equal_nan=True)
    stream = on.new_state()
    parts = [stream.residuals(t[a:a + 97], x_on[a:a + 97]) for a in range(0, len(t), 97)]
    assert np.array_equal(np.concatenate(parts), r_on, equal_nan=True)
    again = reference_from_dict(on.to_dict())
    assert again.channels == on.channels and np.array_equal(again.residuals(t, x_on), r_on, equal_nan=True)


def test_the_shipped_physics_reference_is_the_paper_loop_with_the_physics_detectors_design():
    """paper_physics, shipped (phfdi calibrate --scenario paper --out
    src/wavelet_fdi/calibrations/paper_physics.json; run that again if this fails): the paper scenario as it is now,
    the physics detector's design, a threshold for every statistic, measured on seeds no evaluation uses; taken by
    name wherever a reference file is (a file of that name, where one exists, comes first)."""
    from phfdi.study.evaluation import EvalConfig
    from wavelet_fdi.learned_detector import LearnedDetector, LearnedModel
    from wavelet_fdi.reference_physics import design_settings

    model = LearnedModel.load("paper_physics")
    healthy = PhysicsReference.from_spec(load_scenario("paper", fault="healthy"), watch_level=False)
    assert model.reference.to_dict() == healthy.to_dict()
    assert model.settings == design_settings(1.0)
    assert set(model.thresholds) == set(LearnedDetector(model).stat_names)
    seeds = {int(run.split()[1]) for run in model.source["runs"]}
    assert seeds == set(range(1001, 1017))
    assert not seeds & (set(EvalConfig().eval_seeds) | set(EvalConfig().healthy_seeds))
    with pytest.raises(UserError, match="no_such_reference"):
        LearnedModel.load("no_such_reference")


def test_a_reference_entry_that_is_not_a_scenario_is_one_clear_refusal():
    ref, _, _ = record(17)
    bad = {**ref.to_dict(), "scenario": {**ref.scenario, "sample_time_s": -1.0}}
    with pytest.raises(UserError, match="physics reference: scenario: sample_time_s: Input should be greater than 0"):
        reference_from_dict(bad)
    with pytest.raises(UserError, match="not a physics reference"):
        reference_from_dict({"kind": "physics"})
    with pytest.raises(UserError, match="warmup_s must be >= 0"):
        PhysicsReference(ref.scenario, warmup_s=-1.0)
    with pytest.raises(UserError, match="naming_after_s must be > 0"):
        PhysicsReference(ref.scenario, naming_after_s=0.0)


def test_the_naming_delay_is_the_references_and_its_file_keeps_it():
    """naming_after_s (the physics detector's isolation delay): the detector names that long after a detection; a
    file written before it existed reads the default, 300 s."""
    ref, _, _ = record(17)
    short = PhysicsReference.from_spec(ref.spec, naming_after_s=150.0)
    assert short.naming_after_samples == 150 and ref.naming_after_samples == 300
    assert reference_from_dict(short.to_dict()) == short
    old = {k: v for k, v in ref.to_dict().items() if k != "naming_after_s"}
    assert reference_from_dict(old).naming_after_s == 300.0


#: a plant the shipped reference was not calibrated on: the acid valve's capacity 45 mL/s instead of 40
BIGGER_VALVE = "valves.ph.max_flow_ml_s=45"


def test_a_physics_reference_follows_the_plant_of_the_record_it_watches(tmp_path, capsys):
    """A record that says its own scenario (a simulated run) is watched with that scenario's plant, its band scales
    and thresholds the calibration's, and a note says so: the shipped paper reference on a healthy run of a bigger
    acid valve predicted the pH 175 sensor sigmas off and raised an alarm. A replay of the record says it, and raises
    none; a record of the calibrated scenario itself is watched as calibrated."""
    import json

    from phfdi.cli import main
    from wavelet_fdi.learned_detector import LearnedModel
    from wavelet_fdi.reference_physics import follow_scenario

    model = LearnedModel.load("paper_physics")
    spec = load_scenario("paper", fault="healthy", overrides=SHORT + [BIGGER_VALVE, "seed=21"])
    run = simulate(spec)
    t = np.asarray(run.time_s, float)
    rows = np.column_stack([np.asarray(run[c], float) for c in model.channels])
    followed, note = follow_scenario(model, spec)
    assert note is not None and "valves.ph.max_flow_ml_s differs from scenario 'paper'" in note
    assert followed.band_sigma is model.band_sigma and followed.thresholds == model.thresholds
    lags = model.reference.lags
    as_calibrated = model.reference.residuals(t, rows)[lags:, 0]
    own = followed.reference.residuals(t, rows)[lags:, 0]
    assert abs(np.mean(as_calibrated)) > 10.0  # the effect: the calibrated plant is not this run's
    assert abs(np.mean(own)) < 0.2 and 0.8 < np.std(own) < 1.25  # the run's own plant: the sensor noise
    same, none = follow_scenario(model, load_scenario("paper", fault="stiction", overrides=SHORT, onset_s=ONSET_S))
    assert same is model and none is None  # setpoints, duration and faults are not the model's
    path = tmp_path / "bigger_valve.parquet"
    run.save(path)
    capsys.readouterr()
    assert main(["replay", str(path), "--reference", "paper_physics", "--json"]) == 0
    document = json.loads(capsys.readouterr().out)
    assert document["alarms"] == [] and any("follows the record's own scenario" in n for n in document["notes"])


def test_calibrate_physics_writes_a_model_replay_watches_and_names_with(tmp_path, capsys):
    """phfdi calibrate (a physics reference, its default): the scenario's physics calibrated on simulated healthy
    runs, written as a detector model file; phfdi replay --reference then detects a sticky valve in a simulated run
    and names it."""
    from phfdi.cli import main

    short = [x for o in SHORT for x in ("--set", o)]
    model = tmp_path / "physics.json"
    assert main(["calibrate", "--physics", "--seeds", "1001-1004", *short, "--out", str(model)]) == 0
    assert "ph_measured.R.mean_up" in capsys.readouterr().out
    run = tmp_path / "sticky.csv"
    assert main(["simulate", "--fault", "stiction", *short, "--onset", str(ONSET_S), "--out", str(run)]) == 0
    capsys.readouterr()
    assert main(["replay", str(run), "--reference", str(model), "--json"]) == 0
    import json

    alarms = json.loads(capsys.readouterr().out)["alarms"]
    assert alarms and alarms[0]["detection_time"] >= ONSET_S
    assert alarms[0]["isolation"]["fault_class"] == "stiction", alarms[0]["isolation"]
    # too few healthy rows for the thresholds' tails: one line, nothing written
    assert main(["calibrate", "--physics", "--seeds", "1001-1002", *short, "--out", str(tmp_path / "b.json")]) == 2
    assert "needs at least 8 windows" in capsys.readouterr().err and not (tmp_path / "b.json").exists()


@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(gaps=st.lists(st.tuples(st.integers(0, 1199), st.integers(1, 40)), max_size=4), chunk=st.integers(1, 400))
def test_any_chunking_gives_the_same_residuals_and_notices_whatever_the_command_gaps(gaps, chunk):
    """Command gaps of any length anywhere (within the 10 s timeout or beyond it, at the start, back to back),
    fed in chunks of any size: the residuals, held rows and notices of the whole record at once."""
    ref, t, x = _short_record()
    x = x.copy()
    for start, length in gaps:
        x[start:start + length, 0] = np.nan
    whole = ref.new_state()
    r = whole.residuals(t, x)
    held = whole.last_held.copy()
    stream = ref.new_state()
    parts, held_parts = [], []
    for a in range(0, len(t), chunk):
        parts.append(stream.residuals(t[a:a + chunk], x[a:a + chunk]))
        held_parts.append(stream.last_held.copy())
    assert np.array_equal(np.concatenate(parts), r, equal_nan=True)
    assert np.array_equal(np.concatenate(held_parts), held)
    assert stream.notices == whole.notices
    assert np.all(np.isnan(r[held]))


_SHORT_RECORD: list = []


def _short_record():
    """A 1200 s healthy paper run (setpoint step at 600 s), made once for the property test."""
    if not _SHORT_RECORD:
        spec = load_scenario("paper", fault="healthy", overrides=[
            "duration_s=1200", "setpoints.ph.initial=8", "setpoints.ph.changes=[{at_s: 600, value: 8.5}]", "seed=51"])
        run = simulate(spec)
        ref = PhysicsReference.from_spec(spec, warmup_s=300.0, block_samples=64)
        _SHORT_RECORD.append((ref, np.asarray(run.time_s, float),
                              np.column_stack([np.asarray(run[c], float) for c in ref.channels])))
    return _SHORT_RECORD[0]
