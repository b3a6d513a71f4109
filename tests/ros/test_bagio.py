"""Bags without ROS processes: run <-> bag round trip, truncated bag recovery, load_run on run files."""

from __future__ import annotations

import subprocess

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.records import Chunk, Message
from mcap.stream_reader import StreamReader, breakup_chunk

from phfdi import bagio
from phfdi.loop import simulate
from phfdi.scenario import load_scenario
from phfdi_base import topics as T
from phfdi_base.errors import UserError

from .conftest import SHORT_OVERRIDES, phfdi_cmd


@pytest.fixture(scope="module")
def short_run():
    return simulate(load_scenario("paper", overrides=SHORT_OVERRIDES))


@pytest.fixture(scope="module")
def bag(short_run, tmp_path_factory):
    return bagio.write_run(short_run, tmp_path_factory.mktemp("bag") / "run.mcap")


def test_write_run_then_load_run_gives_the_run_back(short_run, bag):
    back = bagio.load_run(bag)
    assert back.names == short_run.names
    for name in short_run.names:
        assert np.array_equal(back[name], short_run[name], equal_nan=True), name
    assert back.metadata["scenario"] == short_run.metadata["scenario"]


def test_load_run_reads_run_files_too(short_run, tmp_path):
    for suffix in (".csv", ".parquet"):
        path = short_run.save(tmp_path / f"run{suffix}")
        assert np.allclose(bagio.load_run(path)["ph_measured"], short_run["ph_measured"])
    other = tmp_path / "run.txt"
    other.write_text("not a run")
    with pytest.raises(UserError, match="expected .mcap"):
        bagio.load_run(other)


def _chunks(path):
    """(end offset, message count) of each chunk, in file order."""
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    with open(path, "rb") as f:
        chunks = [r for r in StreamReader(f, emit_chunks=True).records if isinstance(r, Chunk)]
    ends = [ci.chunk_start_offset + ci.chunk_length for ci in summary.chunk_indexes]
    counts = [sum(isinstance(r, Message) for r in breakup_chunk(c)) for c in chunks]
    assert len(ends) == len(counts) > 5
    return ends, counts


def test_a_truncated_bag_is_recovered_up_to_its_last_complete_chunk(bag, tmp_path):
    ends, counts = _chunks(bag)
    data = bag.read_bytes()
    j = len(ends) // 2
    cut = ends[j] + (ends[j + 1] - ends[j]) // 2  # in the middle of chunk j + 1
    truncated = tmp_path / "killed.mcap"
    truncated.write_bytes(data[:cut])
    info = bagio.bag_info(truncated)
    assert not info["finished"]
    fixed = tmp_path / "fixed.mcap"
    out = subprocess.run(phfdi_cmd("bag", "recover", str(truncated), str(fixed)), capture_output=True, text=True,
                         timeout=60)
    assert out.returncode == 0, out.stderr
    recovered = bagio.bag_info(fixed)
    assert recovered["finished"]
    assert recovered["messages"] == sum(counts[: j + 1])
    run = bagio.load_run(fixed)  # readable as a run, the last sample may lack some topics
    assert 0 < len(run) <= 601
    assert "phfdi_run" in recovered["metadata"]


def test_recover_refuses_to_overwrite_its_input(bag):
    with pytest.raises(UserError, match="other than the input"):
        bagio.recover(bag, bag)


def test_bag_topics_carry_the_graph_types(bag):
    info = bagio.bag_info(bag)
    types = {t["topic"]: t["type"] for t in info["topics"]}
    assert types == {t.name: t.type for t in T.RECORDED if t.per_sample}
