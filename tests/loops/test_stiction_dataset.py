"""The stiction classifier's data set and shipped model are current and reproducible, and come from simulation only.

benchmarks/stiction_dataset.py computes the screen's features of the domain-randomised simulated loops (minutes,
Dask) into benchmarks/results/stiction_dataset.json, and benchmarks/train_stiction_classifier.py trains the
shipped model from it. Here, cheaply: a few rows are computed again from the generator and must match the file
(neither the generator nor the features have changed under it), training from the file must give the shipped
model back, and the whole pipeline - draw, simulate, screen, train, calibrate, set the operating point - runs on a
small set of other seeds.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from phfdi.loopdiag.classifier import HARD_NEGATIVES, NO_STICTION_BELOW, SIM_FALSE_CALL, load_model, train_simulated
from phfdi.loopdiag.dataset import simulated_data, simulated_row, train_from_rows
from phfdi.loopdiag.domain import draw_domain_loops
from phfdi.loopdiag.features import FEATURE_NAMES

ROOT = Path(__file__).resolve().parents[2]
DATASET = ROOT / "benchmarks" / "results" / "stiction_dataset.json"


@pytest.fixture(scope="module")
def dataset() -> dict:
    return json.loads(DATASET.read_text())


def test_only_simulated_loops_train_the_model(dataset):
    assert dataset["features"] == list(FEATURE_NAMES)
    assert {r["source"] for r in dataset["rows"]} == {"train", "calibration"}
    assert dataset["generator"] == "phfdi.loopdiag.domain"
    assert all(r["name"].startswith(("TRAIN", "CAL")) for r in dataset["rows"])


@pytest.mark.parametrize("source, prefix", [("train", "TRAIN"), ("calibration", "CAL")])
def test_rows_are_current(dataset, source, prefix):
    rows = [r for r in dataset["rows"] if r["source"] == source]
    loops, _ = draw_domain_loops(len(rows), dataset["seeds"][source], prefix, limit=3)
    for (loop, _run), cached in zip(loops, rows[:3]):
        fresh = simulated_row(loop, source)
        assert fresh["name"] == cached["name"] and fresh["stiction"] == cached["stiction"]
        assert fresh["loop_class"] == cached["loop_class"] and fresh["slips"] == cached["slips"]
        assert np.allclose(fresh["features"], cached["features"], rtol=1e-9, atol=1e-9)


def test_training_from_the_data_set_gives_the_shipped_model(dataset):
    model = train_from_rows(dataset["rows"])
    shipped = load_model()
    assert shipped.features == list(FEATURE_NAMES) and shipped.info["trained_on"].startswith("simulated loops only")
    assert np.allclose(model.weights, shipped.weights, atol=1e-6) and model.bias == pytest.approx(shipped.bias, abs=1e-6)
    assert np.allclose(model.mean, shipped.mean) and np.allclose(model.scale, shipped.scale)
    assert np.allclose(model.calibration, shipped.calibration, atol=1e-6)
    assert np.allclose(model.band, shipped.band, atol=1e-9)


def test_the_pipeline_on_a_small_set_of_other_seeds():
    """Draw, simulate, screen, train, calibrate and set the operating point on 60 + 40 loops of seeds no data set
    uses: the model has the screen's features, "no stiction" below even odds, and its operating point keeps the
    calibration loops' false calls (and the hard negatives') within the stated rate."""
    train = [simulated_row(d, "train") for d, _ in draw_domain_loops(60, 91, "T")[0]]
    cal_loops = draw_domain_loops(40, 92, "C")[0]
    cal = [simulated_row(d, "calibration") for d, _ in cal_loops]
    hard = np.array([r["loop_class"] in HARD_NEGATIVES for r in cal])
    model = train_simulated(simulated_data(train), simulated_data(cal), hard)
    assert model.features == list(FEATURE_NAMES) and model.band[0] == NO_STICTION_BELOW <= model.band[1] < 1.0
    d = simulated_data(cal)
    calls = model.call(model.calibrated(d.x))
    assert np.mean(calls[~d.y] == "stiction") <= SIM_FALSE_CALL
    assert np.mean(calls[~d.y & hard] == "stiction") <= SIM_FALSE_CALL
    # the weights follow the published signs (a feature may end at 0, never against its paper's reading)
    signs = np.array([1 if s > 0 else -1 for s in (model.signs or [])])
    assert np.all(model.weights * signs >= 0)


def test_a_sticky_valve_shows_by_three_slips_or_one_after_a_long_stand():
    """The label's rule (domain.sticking_shows): break-aways are counted from the simulated stem, and one slip
    after a stand of LONG_STAND samples shows as much as MIN_SLIPS short ones; one short stand does not."""
    from phfdi.loopdiag.domain import LONG_STAND, MIN_SLIPS, stands, sticking_shows

    op = np.linspace(40.0, 60.0, 200)  # OP creeping the whole time

    def stem_of(stand_lengths: list[int]) -> np.ndarray:
        stem, k = op.copy(), 10
        for n in stand_lengths:  # the stem holds for n samples, then catches OP up
            stem[k:k + n + 1] = stem[k]
            k += n + 5
        return stem

    assert stands(stem_of([3, LONG_STAND]), op) == [3, LONG_STAND]
    assert not sticking_shows(stem_of([3]), op)
    assert not sticking_shows(stem_of([3] * (MIN_SLIPS - 1)), op)
    assert sticking_shows(stem_of([3] * MIN_SLIPS), op)
    assert sticking_shows(stem_of([LONG_STAND]), op)
    assert not sticking_shows(stem_of([LONG_STAND - 1]), op)
    assert not sticking_shows(op.copy(), op)
