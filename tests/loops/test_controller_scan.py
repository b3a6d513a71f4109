"""SyntheticLoop.scan_s: a controller scanning faster than the historian samples, as a DCS does."""

from __future__ import annotations

import importlib.util
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from phfdi.loopdiag.synthetic import SyntheticLoop, _per_scan, simulate_loop

ROOT = Path(__file__).resolve().parents[2]
STICKY = SyntheticLoop(valve=("stiction", {"s_pct": 3.0, "j_pct": 1.0}), dt_s=10.0, duration_s=3000.0, ti_s=30.0,
                       setpoint_steps=[(100.0, 52.0), (1500.0, 49.0)])
COLUMNS = ("time_s", "op_pct", "pv", "sp", "stem_pct")


def test_a_scan_at_every_sample_is_the_loop_without_a_scan():
    plain, every = simulate_loop(STICKY), simulate_loop(replace(STICKY, scan_s=STICKY.dt_s))
    for name in COLUMNS:
        np.testing.assert_array_equal(plain[name], every[name])


def test_the_record_keeps_every_tenth_scan_at_the_sample_time():
    # no per-sample figures to convert here, so the record is the 1 s loop read every 10 s
    fast = simulate_loop(replace(STICKY, scan_s=1.0))
    fine = simulate_loop(replace(STICKY, dt_s=1.0))
    assert len(fast) == len(simulate_loop(STICKY)) == 300
    assert fast.dt_s == 10.0 and fast.metadata["sample_time_s"] == 10.0
    for name in COLUMNS:
        np.testing.assert_array_equal(fast[name], fine[name][::10])
    # the stem sticks between the record's samples too: it moves in fewer samples than OP does
    assert np.sum(np.diff(fast["stem_pct"]) != 0) < np.sum(np.diff(fast["op_pct"]) != 0)


def test_the_poles_stay_per_record_sample():
    # gain 0: PV is pv0 plus the measurement noise alone, and SP wanders; 7500 samples put the standard error of a
    # lag-1 autocorrelation near 0.01, so 0.05 is five of them (the per-scan pole unconverted would give 0.8 ** 10)
    spec = SyntheticLoop(gain=0.0, dt_s=10.0, scan_s=2.0, duration_s=75_000.0, noise_std=1.0, noise_pole=0.8,
                         sp_ar_std=1.0, sp_ar_pole=0.9, seed=7)
    run = simulate_loop(spec)

    def acf1(x):
        x = np.asarray(x, float) - np.mean(x)
        return float(x[:-1] @ x[1:] / (x @ x))

    assert abs(acf1(run["pv"]) - 0.8) < 0.05
    assert abs(acf1(run["sp"]) - 0.9) < 0.05


def test_a_random_walk_load_keeps_its_growth_per_record_sample():
    per_scan = _per_scan(replace(STICKY, load_walk_std=0.3, scan_s=2.5), 4)
    assert per_scan.dt_s == 2.5 and per_scan.scan_s == 0.0
    # four scans of std 0.15 add up to one sample's variance of 0.3 ** 2
    assert 4 * per_scan.load_walk_std ** 2 == pytest.approx(0.3 ** 2)


@pytest.mark.parametrize("scan_s", [-1.0, 3.0, 20.0, float("nan")])
def test_a_scan_that_does_not_divide_the_sample_time_is_refused(scan_s):
    with pytest.raises(ValueError, match="scan_s"):
        simulate_loop(replace(STICKY, scan_s=scan_s))


def test_the_lag0_correlation_reads_a_proportional_answer(monkeypatch):
    monkeypatch.syspath_prepend(str(ROOT / "benchmarks"))  # the benchmark draws its loops as its sibling does
    spec = importlib.util.spec_from_file_location("stiction_domain_shift",
                                                  ROOT / "benchmarks" / "stiction_domain_shift.py")
    shift = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(shift)
    rng = np.random.default_rng(3)
    pv = np.cumsum(rng.standard_normal(500))
    assert shift.lag0_correlation(-2.0 * pv + 5.0, pv) == pytest.approx(1.0)
    other = np.cumsum(rng.standard_normal(500))
    assert shift.lag0_correlation(other, pv) < 0.2  # independent changes: standard error 0.045, seeded
