"""The rig detector on the simulated rig (issue 34): calibrated on the five recorded operations replayed on five
simulated days, it meets operations none of them had. Healthy, they are deviations outside calibration (WARN),
never fault alarms; with a probe fault the controller itself sees (the rig simulator's probe-fault hook, onset
drawn from the test's own generator), a confirmed fault after the onset.
"""

from __future__ import annotations

import numpy as np
import pytest

from phfdi.benchmarks.rig_detection import CHANNELS
from phfdi.benchmarks.rig_unseen import CALIBRATION_DAYS, SHARED_OPERATIONS
from phfdi.estimator import fit_estimator, start_from_model
from phfdi.rigsim import ProbeFault, simulate_run
from wavelet_fdi.learned_detector import LearnedModel, run_record


@pytest.fixture(scope="module")
def calibrated() -> LearnedModel:
    runs = [simulate_run(op, seed=day, day=day).measured(CHANNELS) for op, day in zip(SHARED_OPERATIONS,
                                                                                      CALIBRATION_DAYS)]
    return fit_estimator(runs, start_from_model("rig_flask"))


def _alarms(model: LearnedModel, run) -> list[dict]:
    rec = run.measured(CHANNELS)
    _, _, det = run_record(model, rec.time_s, rec.x)
    return det.alarms


def test_on_off_control_never_seen_is_outside_calibration_not_a_fault(calibrated):
    """On/off control of both pumps and of the acid pump (each on a day of its own): the reference deviates (the
    test checks that it tested something) and no deviation is a fault alarm."""
    deviations = []
    for op, seed in (("on_off_both", 8), ("on_off_acid", 19), ("on_off_base", 6)):
        deviations += _alarms(calibrated, simulate_run(op, seed))
    assert deviations, "no deviation: this test would test nothing"
    faults = [(a["detection_time"], a["isolation"]["fault_class"]) for a in deviations if a["verdict"] == "fault"]
    assert not faults


@pytest.mark.parametrize("op,seed", [("pi_base", 71), ("on_off_base", 72)])
def test_a_probe_bias_the_controller_acts_on_is_a_confirmed_fault(calibrated, op, seed):
    """A 0.4 pH bias on the reading a controller acts on (it moves the flask by about the bias): a fault alarm
    after the onset, named a probe offset; no fault alarm before."""
    healthy = simulate_run(op, seed)
    t0, t1 = float(healthy.time_s[0]), float(healthy.time_s[-1])
    onset = round(t0 + float(np.random.default_rng(seed).uniform(0.3, 0.6)) * (t1 - t0), 1)
    alarms = _alarms(calibrated, simulate_run(op, seed, probe_fault=ProbeFault("probe_bias", onset, 0.4, seed=seed)))
    faults = [a for a in alarms if a["verdict"] == "fault"]
    assert not [a for a in faults if a["detection_time"] < onset]
    assert faults, [(a["detection_time"], a["verdict"], a["isolation"]["fault_class"]) for a in alarms]
    assert faults[0]["isolation"]["fault_class"] in ("probe_offset", "probe_drift"), faults[0]["isolation"]
