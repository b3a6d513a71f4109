"""phfdi inject: faults hidden in a measured record change only their own cells from the onset on, by their
size, and the result reads back with the same column map; refusals are one line and leave no file."""

from __future__ import annotations

import csv
import json
import math
import os

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from phfdi.commands.common import shipped_map
from phfdi.inject import inject_fault, sidecar_path
from phfdi.records import read_record
from phfdi_base.errors import UserError

from .conftest import rig_like_csv

PH, ACID_PCT, BASE_PCT, ACID_FLOW, BASE_FLOW, TIME = 6, 2, 3, 4, 5, 1


def rows_of(data: bytes) -> list[list[str]]:
    return [line.split(",") for line in data.decode().splitlines()[1:]]


def column(data: bytes, i: int) -> np.ndarray:
    return np.array([float(r[i]) for r in rows_of(data)])


def onset_in(path, fraction: float = 0.5) -> float:
    t = column(path.read_bytes(), TIME)
    return float(t[0] + fraction * (t[-1] - t[0]))


def inject(path, kind, size=None, fraction=0.5, **kw):
    onset_s = onset_in(path, fraction)
    data, truth = inject_fault(path, kind, onset_s, size, **kw)
    original = path.read_bytes()
    after = column(original, TIME) >= onset_s
    return original, data, truth, after


def assert_only_columns_changed(original: bytes, data: bytes, after: np.ndarray, columns: set[int]) -> None:
    old_lines, new_lines = original.decode().splitlines(True), data.decode().splitlines(True)
    assert len(old_lines) == len(new_lines) and old_lines[0] == new_lines[0]
    for k, (a, b) in enumerate(zip(old_lines[1:], new_lines[1:])):
        if not after[k]:
            assert a == b, f"row {k} before the onset changed"
        changed = {i for i, (x, y) in enumerate(zip(a.split(","), b.split(","))) if x != y}
        assert changed <= columns, f"row {k}: columns {changed} changed"


# ---- sensor faults ------------------------------------------------------------------------------------
@pytest.mark.parametrize("size", [0.3, -1.25])
def test_probe_bias_is_exactly_the_size_after_rounding(rig_file, size):
    original, data, truth, after = inject(rig_file, "probe_bias", size)
    assert_only_columns_changed(original, data, after, {PH})
    old, new = column(original, PH), column(data, PH)
    inside = after & (old + size > 0) & (old + size < 14)
    assert np.allclose(new[inside] - old[inside], size, atol=1e-9)
    assert np.array_equal(new[~after], old[~after]) and new.min() >= 0 and new.max() <= 14
    assert truth["kind"] == "probe_bias" and truth["family"] == "sensor" and truth["unit"] == "pH"
    assert truth["channels"] == ["pH"] and truth["onset_index"] == int(np.argmax(after))


def test_probe_frozen_holds_the_onset_value(rig_file):
    original, data, truth, after = inject(rig_file, "probe_frozen")
    new, k0 = column(data, PH), int(np.argmax(after))
    assert np.all(new[after] == column(original, PH)[k0]) and truth["size"] == 0.0


def test_probe_drift_is_a_ramp_in_ph_per_minute(rig_file):
    original, data, truth, after = inject(rig_file, "probe_drift", 0.5)
    t = column(original, TIME)[after] - truth["onset_s"]
    added = column(data, PH)[after] - column(original, PH)[after]
    inside = column(data, PH)[after] < 14.0  # clipped at pH 14
    assert inside.sum() > 100
    assert np.allclose(added[inside], 0.5 * t[inside] / 60.0, atol=0.005 + 1e-9)
    assert truth["unit"] == "pH/min"


def test_probe_gain_turns_about_ph_7(rig_file):
    original, data, _, after = inject(rig_file, "probe_gain", 0.2)
    old, new = column(original, PH)[after], column(data, PH)[after]
    assert np.allclose(new - 7.0, 1.2 * (old - 7.0), atol=0.005 + 1e-9)
    assert np.all(new[old == 7.0] == 7.0)


def test_probe_noise_has_its_std_and_is_seeded(rig_file):
    original, data, truth, after = inject(rig_file, "probe_noise", 0.2, seed=11)
    added = column(data, PH)[after] - column(original, PH)[after]
    # std of n >= 500 draws is within 10 % of the true one (its relative error is about 1/sqrt(2n) = 3 %);
    # rounding to 0.01 adds 0.003 pH std
    assert added.size >= 500 and abs(added.std() - 0.2) < 0.02 and abs(added.mean()) < 0.03
    assert inject_fault(rig_file, "probe_noise", truth["onset_s"], 0.2, seed=11)[0] == data
    assert inject_fault(rig_file, "probe_noise", truth["onset_s"], 0.2, seed=12)[0] != data
    assert truth["seed"] == 11


def test_probe_lag_step_response_has_its_time_constant(tmp_path):
    dt_s, tau_s, step_s = 0.5, 10.0, 50.0
    path = rig_like_csv(tmp_path / "step.csv", n=300, dt_s=dt_s, ph=lambda t: 9.0 if t >= step_s else 4.0)
    data, truth = inject_fault(path, "probe_lag", 10.0, tau_s)
    t, y = column(data, TIME), column(data, PH)
    assert np.all(y[t < step_s] == 4.0)  # the lag starts at the onset's value: no jump at the onset
    m = np.arange(int(np.sum(t >= step_s)))
    expected = 4.0 + 5.0 * (1.0 - np.exp(-dt_s * (m + 1) / tau_s))  # zero-order hold, exact at dt
    assert np.allclose(y[t >= step_s], expected, atol=0.005 + 1e-9)
    reached = t[np.argmax(y >= 4.0 + 5.0 * (1 - math.exp(-1)))] - step_s
    assert abs(reached - tau_s) <= dt_s
    assert "mean sample interval" in truth["discretisation"]


# ---- pump faults ---------------------------------------------------------------------------------------
def flow_per_pct(data: bytes, flow_i: int, pct_i: int) -> float:
    flow, pct = column(data, flow_i), column(data, pct_i)
    return float(np.median(flow[pct > 0] / pct[pct > 0]))


@pytest.mark.parametrize("kind, size, pump", [("pump_low", 0.2, "acid"), ("pump_high", 0.3, "base"),
                                              ("pump_low", 0.1, "base")])
def test_pump_gain_faults_change_that_pumps_two_columns_proportionally(rig_file, kind, size, pump):
    original, data, truth, after = inject(rig_file, kind, size, pump=pump)
    pct_i, flow_i = (ACID_PCT, ACID_FLOW) if pump == "acid" else (BASE_PCT, BASE_FLOW)
    assert_only_columns_changed(original, data, after, {pct_i, flow_i})
    factor = 1 / (1 - size) if kind == "pump_low" else 1 / (1 + size)
    old_flow, new_flow = column(original, flow_i), column(data, flow_i)
    assert np.allclose(new_flow[after], old_flow[after] * factor, atol=0.005 + 1e-9)
    assert np.allclose(column(data, pct_i)[after], column(original, pct_i)[after] * factor, atol=0.005 + 1e-9)
    ratio = flow_per_pct(original, flow_i, pct_i)
    assert np.allclose(new_flow, ratio * column(data, pct_i), atol=0.02)  # proportional within the rounding
    assert truth["family"] == "actuator" and truth["pump"] == pump and truth["unit"] == "fraction"
    names = next(csv.reader([original.decode().splitlines()[0]]))
    assert truth["channels"] == [names[pct_i], names[flow_i]]


def test_pump_stuck_writes_a_flow_only_where_the_pump_was_off(rig_file):
    original, data, truth, after = inject(rig_file, "pump_stuck", 2.0, pump="base", fraction=0.3)
    assert_only_columns_changed(original, data, after, {BASE_PCT, BASE_FLOW})
    old, new, pct = column(original, BASE_FLOW), column(data, BASE_FLOW), column(data, BASE_PCT)
    off = after & (old == 0)
    assert off.any() and np.all(new[off] == 2.0) and np.array_equal(new[~off], old[~off])
    assert np.allclose(pct[off], 2.0 / flow_per_pct(original, BASE_FLOW, BASE_PCT), atol=0.005 + 1e-9)
    assert truth["unit"] == "mL/s" and truth["rows_changed"] == int(off.sum())


# ---- refusals ---------------------------------------------------------------------------------------
def test_a_fault_that_changes_nothing_is_refused(rig_file, tmp_path):
    with pytest.raises(UserError, match="pump_stuck would change nothing: the acid pump runs"):
        inject_fault(rig_file, "pump_stuck", onset_in(rig_file), 2.0, pump="acid")
    off = rig_like_csv(tmp_path / "off.csv", n=100)
    off.write_text(off.read_text().replace(",4.31,", ",0.00,").replace(",60.00,", ",0.00,"))
    with pytest.raises(UserError, match="pump_low would change nothing: the acid pump is off"):
        inject_fault(off, "pump_low", onset_in(off), 0.2, pump="acid")
    with pytest.raises(UserError, match="would change no cell"):
        inject_fault(rig_file, "probe_bias", onset_in(rig_file), 0.001)


def test_cli_writes_the_file_and_its_truth(rig_file, tmp_path, run_cli):
    out = tmp_path / "faulty.csv"
    status, stdout, err = run_cli("inject", rig_file, "--fault", "probe_bias", "--onset", onset_in(rig_file),
                                  "--size", "0.3", "--out", out, "--json")
    truth = json.loads(stdout)
    assert status == 0 and err == "" and json.loads(sidecar_path(out).read_text()) == truth
    assert truth["source_sha256"] and truth["onset_s"] == onset_in(rig_file) and truth["description"]
    rig_map = shipped_map("ph_rig")  # read_record takes a map file; the name ph_rig is the CLI's
    before, after = read_record(rig_file, rig_map), read_record(out, rig_map)
    assert len(after) == len(before) and np.array_equal(after.time_s, before.time_s)
    assert len(after.notes) == len(before.notes)
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith("faulty")) == \
        ["faulty.csv", "faulty.csv.fault.json"]


def one_error_line(status: int, err: str) -> str:
    lines = err.strip().splitlines()
    assert status == 2 and len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def test_cli_refusals_are_one_line_and_leave_no_file(rig_file, tmp_path, run_cli):
    base = ["inject", rig_file, "--fault", "probe_bias", "--size", "0.3"]
    line = one_error_line(*run_cli(*base, "--onset", "1e6", "--out", tmp_path / "a.csv")[::2])
    assert "--onset 1000000.0 s is outside the record" in line
    line = one_error_line(*run_cli("inject", rig_file, "--fault", "pump_stuck", "--pump", "acid", "--size", "1",
                                   "--onset", onset_in(rig_file), "--out", tmp_path / "a.csv")[::2])
    assert "would change nothing" in line
    (tmp_path / "blocker").write_text("a file, not a folder")
    line = one_error_line(*run_cli(*base, "--onset", onset_in(rig_file), "--out", tmp_path / "blocker" / "a.csv")[::2])
    assert line.endswith(f"{tmp_path / 'blocker'} is a file, not a folder"), line
    assert {p.name for p in tmp_path.iterdir()} <= {"blocker", "rig.csv"}  # rig.csv: the synthetic record


def test_existing_output_needs_overwrite(rig_file, tmp_path, run_cli):
    out = tmp_path / "a.csv"
    out.write_text("keep me\n")
    args = ["inject", rig_file, "--fault", "probe_bias", "--size", "0.3", "--onset", onset_in(rig_file), "--out", out]
    assert "exists; give --overwrite" in one_error_line(*run_cli(*args)[::2])
    assert out.read_text() == "keep me\n" and not sidecar_path(out).exists()
    assert run_cli(*args, "--overwrite")[0] == 0 and out.read_text() != "keep me\n"


def test_a_failed_write_leaves_nothing_partial(rig_file, tmp_path, run_cli, monkeypatch):
    def full_disk(fd):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "fsync", full_disk)
    out = tmp_path / "sub" / "a.csv"
    out.parent.mkdir()
    line = one_error_line(*run_cli("inject", rig_file, "--fault", "probe_bias", "--size", "0.3", "--onset",
                                   onset_in(rig_file), "--out", out)[::2])
    # the truth is placed first (a faulty file never stands without it): its write is the one that fails
    assert line == f"phfdi inject: error: cannot write {sidecar_path(out)}: No space left on device"
    assert list(out.parent.iterdir()) == []


def test_sidecar_failure_removes_the_new_csv(rig_file, tmp_path, monkeypatch):
    from phfdi import inject as mod

    def failing(real):
        def place(src, dst):
            if str(dst).endswith(".fault.json"):
                raise OSError(5, "Input/output error")
            real(src, dst)
        return place

    data, truth = inject_fault(rig_file, "probe_bias", onset_in(rig_file), 0.3)
    # the one writer (phfdi_base.outputs) places a new file with a hard link, a replaced one with a rename
    monkeypatch.setattr(os, "link", failing(os.link))
    monkeypatch.setattr(os, "replace", failing(os.replace))
    with pytest.raises(UserError, match="cannot write .*a.csv.fault.json: Input/output error"):
        mod.write_injected(tmp_path / "a.csv", data, truth)
    assert {p.name for p in tmp_path.iterdir()} <= {"rig.csv"}


def test_help_names_units_and_record_time(capsys):
    from phfdi.cli import main

    with pytest.raises(SystemExit) as exc:
        main(["inject", "--help"])
    text = capsys.readouterr().out
    assert exc.value.code == 0 and "example" in text and "record's time" in text
    for unit in ("to 14 pH]", "to 14 pH/min]", "at most 14 pH (std)]", "at most 86400 s]", "below 1 (a fraction)]",
                 "at most 1000 mL/s]"):
        assert unit in text


# ---- property: nothing before the onset moves ----------------------------------------------------------
@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(fraction=st.floats(0.0, 1.0), size=st.floats(-0.9, 3.0).filter(lambda s: abs(s) >= 0.01),
       kind=st.sampled_from(["probe_bias", "probe_gain", "probe_drift"]))
def test_rows_before_the_onset_are_byte_identical(tmp_path_factory, fraction, size, kind):
    path = PROPERTY_FILE.get("path") or PROPERTY_FILE.setdefault(
        "path", rig_like_csv(tmp_path_factory.mktemp("prop") / "rig.csv", n=200))
    onset_s = onset_in(path, fraction)
    try:
        data, truth = inject_fault(path, kind, onset_s, size)
    except UserError as exc:  # e.g. a drift too slow to move one 0.01 step before the end
        assert "would change no cell" in str(exc)
        return
    old, new = path.read_bytes().splitlines(True), data.splitlines(True)
    k = truth["onset_line"] - 1
    assert len(old) == len(new) and old[:k] == new[:k] and truth["first_changed_line"] >= truth["onset_line"]


PROPERTY_FILE: dict = {}


@pytest.mark.shared_data
@pytest.mark.parametrize("name", ["2025.02.24-001_add_base_pH9.5-11.5.csv", "2025.02.24-005_control_pH7_from_basic.csv",
                                  "2025.02.24-add_acid_pH7-3.csv", "2025.03.03-001_acid_to_base_titration.csv",
                                  "2025.04.07-001-base_to_acid_titration.csv"])
def test_every_rig_record_reads_back_with_its_map(shared_data, name, tmp_path):
    from phfdi.inject import write_injected

    path, rig_map = shared_data / "ph_rig" / name, shipped_map("ph_rig")
    data, truth = inject_fault(path, "probe_noise", onset_in(path, 0.25), 0.05, seed=3)
    out, _ = write_injected(tmp_path / name, data, truth)
    before, after = read_record(path, rig_map), read_record(out, rig_map)
    assert len(after) == len(before) and np.array_equal(after.time_s, before.time_s)
    assert np.array_equal(after.signals["base_flow_ml_s"], before.signals["base_flow_ml_s"])
    k = truth["onset_index"]
    assert np.array_equal(after.signals["ph_measured"][:k], before.signals["ph_measured"][:k])
    assert not np.array_equal(after.signals["ph_measured"][k:], before.signals["ph_measured"][k:])
