"""A file format is registered in one place (phfdi.records.formats) and every reader takes it from there."""

from __future__ import annotations

import numpy as np
import pytest

from phfdi.loopdiag.plantwide import expand
from phfdi.records import read_record, read_run
from phfdi.records.formats import FORMATS, Format, Table, format_of, register_format, unregister_format


def read_toy(path, data, encoding):
    """A toy format: 'name=v1 v2 v3' per line, time in the line 'time_s=...'."""
    text = (data or path.read_bytes()).decode(encoding or "utf-8")
    columns = {k: np.array([float(x) for x in v.split()]) for k, v in
               (line.split("=", 1) for line in text.splitlines() if line.strip())}
    n = len(next(iter(columns.values())))
    return Table(str(path), columns, np.arange(1, n + 1), "sample", {"toy": True})


@pytest.fixture
def toy():
    fmt = register_format(Format("toy", (".toy",), read_toy, historian=4))
    yield fmt
    unregister_format("toy")
    assert "toy" not in FORMATS


def test_a_registered_format_is_read_by_every_reader(toy, tmp_path):
    path = tmp_path / "loop.toy"
    path.write_text("time_s=0 1 2 3\nph_measured=7 7.1 7.1 7.3\nvalve_command_pct=50 51 52 53\n")
    assert format_of(path) is toy
    record = read_record(path)
    assert record.signals["ph_measured"].tolist() == [7.0, 7.1, 7.1, 7.3] and record.metadata["toy"]
    run = read_run(path)
    assert run["valve_command_pct"].tolist() == [50, 51, 52, 53] and run["time_s"].tolist() == [0, 1, 2, 3]
    assert [job.path for job in expand([str(tmp_path)])] == [str(path)]  # the loop diagnosis's folder scan


def test_a_file_no_format_claims_is_read_as_text(tmp_path):
    path = tmp_path / "loop.toy"
    path.write_text("time_s,ph_measured\n0,7\n1,7.1\n")
    assert format_of(path).name == "csv" and read_record(path).signals["ph_measured"].tolist() == [7.0, 7.1]
