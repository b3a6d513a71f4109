"""The SKAB protocol on small hand-made files: reading, the 400-row split, predictions written, bad input."""

import numpy as np
import pytest

from phfdi.benchmarks import skab
from phfdi_base.errors import UserError

HEADER = "datetime;" + ";".join(skab.SENSOR_COLUMNS) + ";anomaly;changepoint"


def write_file(path, n=500, onset=450, bad_cell=None):
    lines = [HEADER]
    for i in range(n):
        vals = [f"{0.1 * k + (1.0 if i >= onset else 0.0):.3f}" for k in range(8)]
        if bad_cell == i:
            vals[3] = "oops"
        a = 1 if i >= onset else 0
        c = 1 if i == onset else 0
        lines.append(f"2020-03-09 10:{i // 60:02d}:{i % 60:02d};" + ";".join(vals) + f";{a};{c}")
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")
    return path


def test_split_labels_and_predictions_written(tmp_path):
    f = skab.read_skab_csv(write_file(tmp_path / "data" / "g" / "1.csv"))
    assert f.values.shape == (500, 8) and f.labelled and f.key == "g/1"
    assert f.time_s[1] - f.time_s[0] == 1.0

    seen = {}

    def oracle_free(train, test, t_s):  # a mean-shift rule: sees only sensor rows
        seen["train"], seen["test"] = train.shape, test.shape
        return (test[:, 0] > train[:, 0].mean() + 0.5).astype(int)

    res = skab.run_detector(oracle_free, [f])
    assert seen == {"train": (400, 8), "test": (100, 8)}
    b = skab.score("rule", res)
    assert b.binary.f1 == 1.0 and b.nab.scores["standard"] == pytest.approx(100.0)
    (p,) = skab.write_predictions(res, tmp_path / "out")
    lines = p.read_text().splitlines()
    assert lines[0] == "datetime;anomaly;changepoint" and len(lines) == 101
    assert lines[51] == "2020-03-09 10:07:30;1;1" and lines[52].endswith(";1;0")


def test_text_in_a_numeric_cell_names_line_and_column(tmp_path):
    p = write_file(tmp_path / "g" / "1.csv", bad_cell=7)
    with pytest.raises(UserError, match=r"line 9, column 'Pressure'"):
        skab.read_skab_csv(p)


def test_missing_column_and_empty_file(tmp_path):
    p = tmp_path / "x.csv"
    p.write_text("datetime;Current\n2020-01-01 00:00:00;1\n")
    with pytest.raises(UserError, match="no such column"):
        skab.read_skab_csv(p)
    p.write_text("")
    with pytest.raises(UserError, match="empty file"):
        skab.read_skab_csv(p)


def test_trivial_baselines():
    train, test = np.zeros((400, 8)), np.zeros((50, 8))
    assert skab.null_detector(train, test, np.arange(50.0)).sum() == 0
    assert skab.always_detector(train, test, np.arange(50.0)).sum() == 50
    tog = skab.random_toggler(0.5, seed=1)(train, test, np.arange(50.0))
    assert set(np.unique(tog)) == {0, 1}
