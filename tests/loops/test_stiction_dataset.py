"""The stiction classifier's data set and shipped model are current and reproducible.

benchmarks/stiction_dataset.py computes the features of the 59 labelled records and of the
synthetic loops (minutes, Dask) into benchmarks/results/stiction_dataset.json, and
benchmarks/train_stiction_classifier.py trains the shipped model from it. Here, cheaply: a few rows
are computed again and must match the file (the features have not changed under it), and training
from the file must give the shipped model back.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from phfdi.loopdiag.classifier import Data, load_model, train
from phfdi.loopdiag.dataset import real_row, synthetic_row
from phfdi.loopdiag.evaluate import read_labels
from phfdi.loopdiag.features import FEATURE_NAMES, FEATURE_SIGNS
from phfdi.loopdiag.training import draw_loops

ROOT = Path(__file__).resolve().parents[2]
DATASET = ROOT / "benchmarks" / "results" / "stiction_dataset.json"
RECHECK = ("stiction/stic_2411FIC20102_0609_0957.txt", "no_stiction/stic_2111LIC31102B_0824_0008.txt")


@pytest.fixture(scope="module")
def dataset() -> dict:
    return json.loads(DATASET.read_text())


@pytest.mark.parametrize("rel", RECHECK)
def test_real_rows_are_current(shared_data, dataset, rel):
    folder = shared_data / "plant_loops"
    if not (folder / "labels.csv").is_file():
        pytest.skip(f"no labels.csv in {folder}")
    item = next(x for x in read_labels(folder / "labels.csv") if x.file.endswith(rel))
    fresh = real_row(item, str(folder))
    cached = next(r for r in dataset["rows"] if r["name"] == rel)
    assert fresh["stiction"] == cached["stiction"] and fresh["group"] == cached["group"]
    assert np.allclose(fresh["features"], cached["features"], atol=1e-6)


def test_synthetic_rows_are_current(dataset):
    loop, _ = draw_loops(1, dataset["train_seed"], "SYN")[0]
    fresh = synthetic_row(loop)
    cached = next(r for r in dataset["rows"] if r["name"] == loop.group)
    assert fresh["stiction"] == cached["stiction"]
    assert np.allclose(fresh["features"], cached["features"], atol=1e-6)


def test_training_from_the_data_set_gives_the_shipped_model(dataset):
    assert dataset["features"] == list(FEATURE_NAMES)
    rows = [r for r in dataset["rows"] if not r.get("error") and r["source"] in ("real", "synthetic")]
    d = Data(np.array([r["features"] for r in rows]), np.array([r["stiction"] for r in rows]),
             [r["group"] for r in rows], np.array([r["source"] == "real" for r in rows]), list(FEATURE_NAMES),
             list(FEATURE_SIGNS))
    model = train(d)  # the default criterion, as benchmarks/train_stiction_classifier.py ships
    shipped = load_model()
    assert np.allclose(model.weights, shipped.weights, atol=1e-6)
    assert model.threshold == pytest.approx(shipped.threshold, abs=1e-9)
    assert np.allclose(model.mean, shipped.mean) and np.allclose(model.scale, shipped.scale)
