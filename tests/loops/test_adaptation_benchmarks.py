"""benchmarks/stiction_same_interval.py and stiction_coral.py: the shipped index is reproduced, the map moves
a pool onto the training loops' moments."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

import valve_actuator.blocks  # noqa: F401  (registers the valve blocks)
from phfdi.loopdiag.deadband import deadband_evidence
from phfdi.loopdiag.synthetic import SyntheticLoop, acceptance_cases, simulate_loop

ROOT = Path(__file__).resolve().parents[2]


def _load(name: str):
    sys.path.insert(0, str(ROOT / "benchmarks"))  # their shared helpers (stiction_information_bound)
    try:
        spec = importlib.util.spec_from_file_location(name, ROOT / "benchmarks" / f"{name}.py")
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
    finally:
        sys.path.remove(str(ROOT / "benchmarks"))
    return mod


@pytest.mark.parametrize("case", ["stiction", "healthy"])
def test_the_shipped_variant_is_the_screens_index(case):
    bench = _load("stiction_same_interval")
    run = simulate_loop(acceptance_cases()[case].loop)
    shipped = bench.indices(run["op_pct"], run["pv"], "self_regulating")[0]
    assert shipped == pytest.approx(deadband_evidence(run["op_pct"], run["pv"], "self_regulating").value, abs=1e-12)


def test_a_same_interval_model_that_fits_the_controller_exactly_is_undefined():
    # a PI controller acting once per record sample, no rounding: OP's changes at lags 0 and 1 with PV's give PV's
    # change exactly (the controller's equation), so the lag-0 variants have no index; the shipped one has
    bench = _load("stiction_same_interval")
    run = simulate_loop(SyntheticLoop(valve=("stiction", {"s_pct": 2.0, "j_pct": 2.0}), load_walk_std=0.3, seed=3))
    shipped, lag0, nuisance = bench.indices(run["op_pct"], run["pv"], "self_regulating")
    assert np.isfinite(shipped) and shipped > 0.0
    assert np.isinf(lag0) and np.isinf(nuisance)


def test_coral_moves_the_pool_onto_the_sources_mean_and_covariance():
    bench = _load("stiction_coral")
    rng = np.random.default_rng(5)
    source = rng.normal(size=(400, 3)) @ np.array([[1.0, 0.5, 0.0], [0.0, 2.0, 0.3], [0.0, 0.0, 0.7]]) + [1, 2, 3]
    pool = rng.normal(size=(59, 3)) * [0.1, 3.0, 1.0] - 4.0
    moved = bench.coral_map(source, pool, diagonal=False, eps=0.0)(pool)
    assert np.allclose(moved.mean(0), source.mean(0))
    assert np.allclose(np.cov(moved, rowvar=False), np.cov(source, rowvar=False), rtol=1e-6)
    diag = bench.coral_map(source, pool, diagonal=True, eps=0.0)(pool)
    assert np.allclose(diag.mean(0), source.mean(0)) and np.allclose(diag.std(0), source.std(0))
    # a large eps on both diagonals leaves the covariance alone: the map only moves the pool's mean
    shift = bench.coral_map(source, pool, diagonal=False, eps=1e9)(pool)
    assert np.allclose(shift.mean(0), source.mean(0))
    assert np.allclose(np.cov(shift, rowvar=False), np.cov(pool, rowvar=False), rtol=1e-3, atol=1e-6)
