"""Fuzz every reader and every command that takes a file (issue 15): random bytes, truncated and mutated copies
of real files. Nothing may escape but a UserError (one line, exit 2), and a file that is read must say what was
repaired: every sample differs from its source cell only where a note says why.

Examples are bounded and derandomised (the same inputs on every run) so the whole file takes well under a minute;
PHFDI_FUZZ_SCALE=N runs N times as many, freshly random.
"""

from __future__ import annotations

import atexit
import io
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import warnings
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from phfdi_base.errors import UserError

from .conftest import SHORT

#: PHFDI_FUZZ_SCALE=10 runs ten times the examples with fresh random inputs (a deeper search than CI's)
SCALE = int(os.environ.get("PHFDI_FUZZ_SCALE", "1"))
FUZZ = settings(max_examples=80 * SCALE, deadline=None, derandomize=SCALE == 1, database=None,
                suppress_health_check=list(HealthCheck))
FEW = settings(FUZZ, max_examples=12 * SCALE)

CELLS = [b"nan", b"NaN", b"inf", b"-inf", b"", b"x", b"1e400", b"-0", b"\xff\xfe", b"\x00", b"\"", b"2024-13-45",
         b"1,5", b";", b"\t", b"\r", b"NA", b"99999999999999999999"]


# ---- mutations ------------------------------------------------------------------------------
#: edits, the ones a real file suffers most (a cell, a repeated or misplaced line) more often than damage
OPS = ["cell"] * 4 + ["dupline"] * 2 + ["swaplines", "truncate", "flip", "insert", "delete"]


@st.composite
def mutated(draw, data: bytes) -> bytes:
    """A copy of ``data`` with a few random edits: truncation, byte flips, inserted or deleted spans, lines
    repeated or swapped (repeated stamps, time going back) and cells replaced by what real files hold."""
    for _ in range(draw(st.integers(1, 3))):
        op = draw(st.sampled_from(OPS))
        n = len(data)
        if n == 0:
            break
        i = draw(st.integers(0, n - 1))
        if op == "truncate":
            data = data[:i]
        elif op == "flip":
            data = data[:i] + bytes([draw(st.integers(0, 255))]) + data[i + 1:]
        elif op == "insert":
            data = data[:i] + draw(st.binary(max_size=12) | st.sampled_from(CELLS)) + data[i:]
        elif op == "delete":
            data = data[:i] + data[i + draw(st.integers(1, 64)):]
        else:
            data = _line_edit(draw, data, op)
    return data


def _line_edit(draw, data: bytes, op: str) -> bytes:
    lines = data.split(b"\n")
    if len(lines) < 3:
        return data
    k = draw(st.integers(1, len(lines) - 2))
    if op == "dupline":
        lines.insert(k, lines[k])
    elif op == "swaplines":
        j = draw(st.integers(1, len(lines) - 2))
        lines[k], lines[j] = lines[j], lines[k]
    else:
        sep = b"\t" if b"\t" in lines[k] else b";" if b";" in lines[k] else b","
        cells = lines[k].split(sep)
        cells[draw(st.integers(0, len(cells) - 1))] = draw(st.sampled_from(CELLS))
        lines[k] = sep.join(cells)
    return b"\n".join(lines)


#: one folder per test process, emptied before each example and removed at exit (no litter in /tmp)
FOLDER = Path(tempfile.mkdtemp(prefix="phfdi-fuzz-"))
atexit.register(shutil.rmtree, FOLDER, True)


def _file(data: bytes, name: str) -> Path:
    """``data`` as the only file of this process's fuzz folder (what the last example wrote is removed)."""
    for old in FOLDER.iterdir():
        if old.is_dir():
            shutil.rmtree(old, ignore_errors=True)
        else:
            old.unlink()
    path = FOLDER / name
    path.write_bytes(data)
    return path


def _variant(draw, seeds: dict, names: list[str]) -> Path:
    """A random-bytes file or a mutated copy of one of the seeds, under the seed's file name."""
    names = [n for n in names if n in seeds]
    name = draw(st.sampled_from(names))
    if draw(st.integers(0, 9)) == 0:
        return _file(draw(st.binary(max_size=400)), name)
    return _file(draw(mutated(seeds[name].read_bytes())), name)


# ---- the oracle: a record read must account for every difference from its source --------------------
def check_record(rec) -> None:
    """Every sample equals its source cell, or a note says why (missing, averaged, re-spaced, flagged)."""
    from phfdi.records.cells import parse_stamps, to_numbers
    from phfdi.records.sources import read_table

    assert len(rec) >= 1 and all(len(v) == len(rec) for v in rec.signals.values())
    assert not any(np.isinf(v).any() for v in rec.signals.values())
    edges = [0, *rec.boundaries, len(rec)]
    for a, b in zip(edges[:-1], edges[1:]):
        assert np.all(np.diff(rec.time_s[a:b]) > 0), "time must increase within a segment"
    text = "\n".join(rec.notes)
    table = read_table(Path(rec.path), rec.metadata.get("encoding"))
    row_of = {int(line): i for i, line in enumerate(table.lines)}
    rows = np.array([row_of[int(line)] for line in rec.lines])
    if len(rec) < len(table):
        assert any(w in text for w in ("dropped", "averaged", "duplicate")), text
    if table.where == "line" and "PROCESSDATA" not in Path(rec.path).read_text("latin-1")[:20]:
        text_lines = re.split(r"\r\n|\r|\n", Path(rec.path).read_text("latin-1"))  # what csv counts as lines
        physical = [ln for ln in text_lines if re.sub(r'[,;\t" ]', "", ln).strip()]  # ",,,," is a blank row
        if len(table) < len(physical) - 1:  # lines that are not rows of their own
            assert "runs over" in text, text
    for name, values in rec.signals.items():
        src = to_numbers(table.columns[rec.columns[name]]).values[rows]
        factor = 1.0  # maps with units are not fuzzed here: signals are in the file's numbers
        changed = ~((values == src * factor) | (np.isnan(values) & np.isnan(src)))
        if changed.any():
            assert "averaged" in text or "flagged bad" in text, (name, text)
        if (np.isnan(values) & ~np.isnan(src)).any():
            assert "flagged bad" in text or "averaged" in text, (name, text)
        if np.isnan(values).any():
            assert repr(rec.columns[name]) in text, (name, text)
    time_col = next((c for c in table.columns if c.lower() in ("time_s", "timestamp", "time", "datetime",
                                                               "date")), None)
    if time_col is not None:
        t, fmt = parse_stamps(table.columns[time_col])
        if fmt is None and not np.array_equal(rec.time_s, t[rows]):
            assert "re-spaced" in text, text


READERS_FILES = ["run.csv", "run.parquet", "run.mcap", "ph_rig.csv", "skab.csv", "loop.txt"]


@FUZZ
@given(data=st.data(), policy=st.sampled_from(["run", "historian"]))
def test_read_record_never_raises_but_read_error_and_says_every_repair(seeds, data, policy):
    from phfdi.records import read_record

    path = _variant(data.draw, seeds, READERS_FILES)
    try:
        rec = read_record(path, policy=policy)
    except UserError as exc:
        assert "\n" not in str(exc) and str(path) in str(exc) or str(exc).startswith(("no such", "a run"))
        return
    check_record(rec)


@FUZZ
@given(data=st.data())
def test_project_readers_raise_only_user_errors(seeds, data):
    """records.read_run, bagio.load_run/bag_info, diagnosis.load_record, loopdiag.read_loop on the same inputs."""
    from phfdi import bagio
    from phfdi.diagnosis.data import load_record
    from phfdi.loopdiag.readers import read_loop
    from phfdi.records import read_run

    path = _variant(data.draw, seeds, READERS_FILES)
    reader = data.draw(st.sampled_from(["run", "bag", "info", "diagnosis", "loop"]))
    call = {"run": read_run, "bag": bagio.load_run, "info": bagio.bag_info, "diagnosis": load_record,
            "loop": read_loop}[reader]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            out = call(path)
        except UserError as exc:
            assert "\n" not in str(exc)
            return
    if reader == "diagnosis":
        assert np.all(np.isfinite(out.time_s)) and all(np.isfinite(v).all() for v in out.outputs.values())
    if reader == "loop":
        assert all(np.isfinite(out[k]).all() for k in ("op_pct", "pv"))


@FUZZ
@given(data=st.data())
def test_yaml_files_raise_only_user_errors(seeds, data):
    """Scenarios, column maps (both forms), a detector's reference file (the shipped physics reference)."""
    from phfdi.loopdiag.readers import parse_loop_columns
    from phfdi.records import ColumnMap
    from phfdi.scenario import load_scenario
    from wavelet_fdi.learned_detector import LearnedModel

    path = _variant(data.draw, seeds, ["scenario.yaml", "map.yaml", "loopmap.yaml", "reference.json"])
    loader = {"scenario.yaml": load_scenario, "map.yaml": ColumnMap.load, "loopmap.yaml": parse_loop_columns,
              "reference.json": LearnedModel.load}[path.name]
    try:
        loader(str(path))
    except UserError as exc:
        assert "\n" not in str(exc)


# ---- the CLI in process ------------------------------------------------------------------------
def run_main(*argv: object) -> tuple[int, str, str]:
    from phfdi.cli import main

    out, err = io.StringIO(), io.StringIO()
    with redirect_stdout(out), redirect_stderr(err), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            status = main([str(a) for a in argv])
        except SystemExit as exc:  # argparse: usage errors
            status = exc.code
    return int(status), out.getvalue(), err.getvalue()


def assert_clean_exit(status: int, err: str) -> None:
    assert status in (0, 2), (status, err)
    assert "Traceback" not in err
    if status == 2:  # one error line; the others are the reader's notes or progress
        lines = [ln for ln in err.strip().split("\n") if ln.strip()]
        errors = [ln for ln in lines if ": error: " in ln or ln.startswith("phfdi loop-diagnose: /")]
        assert len(errors) == 1, err
        assert all(ln in errors or ": note: " in ln or " %  (" in ln for ln in lines), err


SET = [x for o in SHORT for x in ("--set", o)]
CLI_CASES = {
    "replay": (["run.csv", "run.parquet", "run.mcap", "ph_rig.csv"], lambda f, o: ["replay", f, "--no-isolation"]),
    "calibrate": (["run.csv", "run.parquet", "run.mcap"],
                  lambda f, o: ["calibrate", "--runs", f, *SET, "--out", o / "c.json", "--overwrite"]),
    "diagnose": (["run.csv", "run.parquet", "run.mcap"],
                 lambda f, o: ["diagnose", "--data", f, "--candidates", "sensor_bias", "--no-pairs", "--workers",
                               "1", "--quiet", "--out", o, "--overwrite"]),
    "loop-diagnose": (["loop.txt", "run.csv"], lambda f, o: ["loop-diagnose", f, "--no-baselines", "--causes",
                                                             "stiction", "--workers", "1", "--columns",
                                                             "op=valve_command_pct,pv=ph_measured,time=time_s"
                                                             if f.endswith(".csv") else "op=X.MV,pv=X.PV"]),
    "bag": (["run.mcap"], lambda f, o: ["bag", "to-run", f, o / "r.csv", "--overwrite"]),
    "bag-info": (["run.mcap"], lambda f, o: ["bag", "info", f]),
    "bag-from-csv": (["skab.csv", "run.csv", "run.parquet"], lambda f, o: ["bag", "from-csv", f, o / "b.mcap", "--overwrite"]),
    "bag-recover": (["run.mcap"], lambda f, o: ["bag", "recover", f, o / "r.mcap", "--overwrite"]),
    "simulate-inputs": (["run.csv"], lambda f, o: ["simulate", "--inputs", f, "--out", o / "o.csv", "--overwrite"]),
    "scenario": (["scenario.yaml"], lambda f, o: ["simulate", "--scenario", f, *SET]),
    "replay-map": (["map.yaml"], lambda f, o: ["replay", "{ph_rig}", "--map", f, "--no-isolation"]),
    "loop-columns": (["loopmap.yaml"], lambda f, o: ["loop-diagnose", "{loop}", "--columns", f, "--no-baselines",
                                                     "--causes", "stiction", "--workers", "1"]),
}


#: examples per command: the ones that simulate or fit on success get fewer
EXAMPLES = {"calibrate": 5, "diagnose": 6, "loop-diagnose": 6, "loop-columns": 6, "scenario": 8}


@pytest.mark.parametrize("case", sorted(CLI_CASES))
def test_cli_entries_exit_0_or_one_line_exit_2(seeds, case):
    names, argv = CLI_CASES[case]
    if not any(n in seeds for n in names):
        pytest.skip("real data folder not found (set PHFDI_SHARED_DATA)")
    subs = {"{ph_rig}": seeds.get("ph_rig.csv"), "{run}": seeds["run.parquet"], "{loop}": seeds.get("loop.txt")}

    @settings(FEW, max_examples=EXAMPLES.get(case, 12) * SCALE)
    @given(data=st.data())
    def check(data):
        path = _variant(data.draw, seeds, names)
        args = [str(subs.get(a, a)) if isinstance(a, str) else a for a in argv(str(path), path.parent)]
        if "None" in args:
            return
        status, out, err = run_main(*args)
        assert_clean_exit(status, err)
        if status == 0 and case == "replay":
            from phfdi.replay import load_any

            assert "note:" in err or load_any(path).metadata["notes"] == []

    check()


def test_replay_json_lists_exactly_the_readers_notes(seeds):
    """On success the answer names every repair: replay --json's notes are the reader's."""
    from phfdi.records import read_record

    @FEW
    @given(data=st.data())
    def check(data):
        path = _variant(data.draw, seeds, ["run.csv"])
        status, out, err = run_main("replay", path, "--json", "--no-isolation")
        assert_clean_exit(status, err)
        if status == 0:
            rep = json.loads(out)
            rec = read_record(path, policy="run", required=("ph_measured",))
            assert rep["notes"] == rec.note_lines() and rep["samples"] == len(rec)
            assert all(f"note: {n}" in err for n in rep["notes"])

    check()


@pytest.mark.parametrize("name, data, command", [
    ("r.csv", b"time_s,ph_measured\n0,7\n1,\x81\x8d\n", "diagnose"),
    ("r.parquet", b"PAR1\x00\x00garbage", "replay"),
    ("r.mcap", b"\x89MCAP0\r\n", "replay"),
])
def test_the_installed_command_on_damaged_files(name, data, command, tmp_path):
    """A few through a real process: the console entry exits 2 with one line, no traceback."""
    path = tmp_path / name
    path.write_bytes(data)
    argv = ["diagnose", "--data", path, "--out", tmp_path / "o"] if command == "diagnose" else ["replay", path]
    proc = subprocess.run([sys.executable, "-m", "phfdi.cli", *map(str, argv)], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1 and str(path) in proc.stderr
