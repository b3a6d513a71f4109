"""SKAB acceptance on the shared files: one configuration, the benchmark's protocol, F1 >= 0.85.

NAB is printed by benchmarks/skab.py, not asserted: the 40 asked for is not reached (docs/detector.md).
"""

import sys
from pathlib import Path

import numpy as np
import pytest

from phfdi.benchmarks import skab

pytestmark = pytest.mark.shared_data


@pytest.fixture(scope="module")
def files():
    from ..conftest import SHARED_DATA

    d = SHARED_DATA / "skab"
    if not d.is_dir():
        pytest.skip(f"{d} not found (set PHFDI_SHARED_DATA)")
    return [skab.read_skab_csv(p) for p in skab.find_files(d)]


def test_f1_on_the_shared_files(files):
    labelled = [f for f in files if f.labelled]
    assert len(labelled) >= 20
    result = skab.score("ours", skab.run_detector(skab.learned_detector(), labelled))
    assert result.binary.f1 >= 0.85, result.row()


def test_benchmark_script_writes_predictions_and_checks_causality(files, tmp_path):
    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
    try:
        import skab as script  # benchmarks/skab.py
    finally:
        sys.path.pop(0)
    data = tmp_path / "data"
    for f in [f for f in files if f.labelled][:2]:
        (data / f.group).mkdir(parents=True, exist_ok=True)
        (data / f.group / f.path.name).write_bytes(f.path.read_bytes())
    assert script.main([str(data), "--out", str(tmp_path / "out")]) == 0
    written = sorted((tmp_path / "out" / "predictions").rglob("*.csv"))
    assert len(written) == 2
    lines = written[0].read_text().splitlines()
    assert lines[0] == "datetime;anomaly;changepoint"
    first = [f for f in files if f.labelled][0]
    assert len(lines) - 1 == len(first.values) - skab.TRAIN_ROWS
    pred = np.array([int(x.split(";")[1]) for x in lines[1:]])
    assert set(np.unique(pred)) <= {0, 1}
