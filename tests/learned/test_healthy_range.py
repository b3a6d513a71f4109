"""A record that leaves what the reference's healthy runs covered is said to (wavelet_fdi.healthy_range, replay)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from phfdi.cli import main
from wavelet_fdi.healthy_range import RangeWatch, describe, healthy_ranges, outside_ranges
from wavelet_fdi.learned_detector import LearnedModel, learn

from .test_learned_cli import write_csv
from .test_learned_detector import CHANNELS, plant

PUMP_CHANNELS = ["acid_flow_ml_s", "base_flow_ml_s", "ph"]


def pump_run(rng: np.random.Generator, n: int, acid_settings: list[float], base_settings: list[float]) -> np.ndarray:
    """Pumps switching between their settings (0 = off) in stretches, a pH anywhere between 3 and 11."""
    acid = rng.choice(acid_settings, size=n // 50 + 1).repeat(50)[:n]
    base = rng.choice(base_settings, size=n // 50 + 1).repeat(50)[:n]
    ph = rng.uniform(3.0, 11.0, n)
    return np.column_stack([acid, base, ph])


@pytest.mark.parametrize("seed", range(20))
def test_a_pump_setting_no_healthy_run_had_is_found_and_nothing_else(seed):
    rng = np.random.default_rng(seed)
    ranges = healthy_ranges([pump_run(rng, 2000, [0.0, 3.59], [0.0, 1.29, 3.87]) for _ in range(3)], PUMP_CHANNELS)
    watched = pump_run(rng, 3000, [0.0, 3.59], [0.0, 1.29, 3.87])
    # hidden: from a drawn row on, for a drawn stretch, the base pump runs at a setting beyond its healthy ones
    start, length = int(rng.integers(0, 2500)), int(rng.integers(1, 500))
    setting = float(rng.uniform(4.2, 8.0))
    watched[start:start + length, 1] = setting
    watched[:, 2] += rng.normal(0, 0.01, len(watched))  # the pH's own jitter stays inside its range
    (o,) = outside_ranges(ranges, watched, PUMP_CHANNELS)
    assert o["channel"] == "base_flow_ml_s" and o["share"] == pytest.approx(length / len(watched))
    assert o["min"] == o["max"] == pytest.approx(setting)
    assert "base_flow_ml_s" in describe(o) and "0 or 1.29 to 3.87" in describe(o)


def test_off_is_a_state_of_its_own_and_a_setting_between_is_not_outside():
    healthy = np.array([[3.59, 1.29], [3.59, 3.87], [3.59, 0.0]])
    ranges = healthy_ranges([healthy], ["acid", "base"])
    assert ranges == {"acid": {"min": 3.59, "max": 3.59, "zero": False},
                      "base": {"min": 1.29, "max": 3.87, "zero": True}}
    # the acid never off while healthy: off is outside; the base between two healthy settings is not
    (o,) = outside_ranges(ranges, np.array([[0.0, 2.5], [3.59, 0.0], [3.6, 3.9]]), ["acid", "base"])
    assert o["channel"] == "acid" and o["share"] == pytest.approx(1 / 3) and o["max"] == 0.0
    # a narrow range keeps a tolerance of 5 % of a tenth of its size: 3.59 +- 0.018
    assert outside_ranges(ranges, np.array([[3.605, 2.0]]), ["acid", "base"]) == []
    assert [o["channel"] for o in outside_ranges(ranges, np.array([[3.62, 2.0]]), ["acid", "base"])] == ["acid"]


def test_missing_values_and_unknown_channels_are_not_outside():
    ranges = healthy_ranges([np.array([[1.0, np.nan], [2.0, np.nan]])], ["a", "b"])
    assert ranges["b"] == {"min": None, "max": None, "zero": False}
    assert outside_ranges(ranges, np.array([[np.nan, np.nan], [1.5, np.nan]]), ["a", "b"]) == []
    # a channel with no healthy value at all: any value is outside; a channel the ranges do not know: skipped
    assert [o["channel"] for o in outside_ranges(ranges, np.array([[1.5, 4.0, 9.0]]), ["a", "b", "c"])] == ["b"]


def test_the_model_file_keeps_the_ranges_and_an_old_file_has_none(tmp_path):
    x = plant(1200, 5)
    model = learn(x, CHANNELS)
    assert model.source["healthy_ranges"] == healthy_ranges([x], CHANNELS)
    path = tmp_path / "ref.json"
    model.save(path)
    assert LearnedModel.load(path).source["healthy_ranges"] == model.source["healthy_ranges"]
    d = json.loads(path.read_text())
    del d["source"]["healthy_ranges"]
    path.write_text(json.dumps(d))
    old = LearnedModel.load(path)
    assert outside_ranges(old.source.get("healthy_ranges") or {}, x * 100, CHANNELS) == []


def test_replay_says_where_the_record_leaves_the_healthy_range(tmp_path, capsys):
    healthy = write_csv(tmp_path / "healthy.csv", plant(1000, 22))
    x = plant(1500, 23)
    hi = x[:, 1].max() - x[:, 1].min()
    x[900:1200, 1] += 3 * hi  # a stretch far beyond the healthy pressure
    watched = write_csv(tmp_path / "watched.csv", x)
    ref = tmp_path / "ref.json"
    assert main(["calibrate", "--learn", str(healthy), "--out", str(ref)]) == 0
    said = capsys.readouterr().out  # the calibration says what it covered, channel by channel
    ranges = healthy_ranges([plant(1000, 22)], CHANNELS)
    lo, hi = ranges["pressure"]["min"], ranges["pressure"]["max"]
    assert "healthy ranges" in said and f"pressure {lo:.4g} to {hi:.4g}" in said
    assert main(["replay", str(watched), "--reference", str(ref), "--json"]) == 0
    out = capsys.readouterr()
    report = json.loads(out.out)
    names = [o["channel"] for o in report["outside_healthy_range"]]
    assert "pressure" in names
    assert next(o for o in report["outside_healthy_range"] if o["channel"] == "pressure")["share"] >= 300 / 1500
    assert "note: pressure left the range of the reference's healthy runs in" in out.err


@given(st.lists(st.integers(1, 400), min_size=1, max_size=8), st.integers(0, 2**31 - 1))
@settings(max_examples=40, deadline=None)
def test_a_stream_in_any_chunks_sums_up_to_the_whole_record(cuts, seed):
    """The detector node takes rows in chunks (RangeWatch); the offline replay the whole record (outside_ranges):
    the same channels, shares, extremes; each channel said new once, in the chunk where it first leaves."""
    rng = np.random.default_rng(seed)
    ranges = healthy_ranges([pump_run(rng, 1000, [0.0, 3.59], [0.0, 1.29, 3.87])], PUMP_CHANNELS)
    x = pump_run(rng, 3000, [0.0, 3.59, 4.31], [0.0, 1.29, 3.87, 6.45])
    watch = RangeWatch(ranges, PUMP_CHANNELS)
    bounds = np.cumsum([0, *cuts, len(x)])
    said = []
    for a, b in zip(bounds[:-1], bounds[1:]):
        said += [o["channel"] for o in watch.update(x[min(a, len(x)):min(b, len(x))])]
    assert watch.summary() == outside_ranges(ranges, x, PUMP_CHANNELS)
    assert sorted(said) == sorted(o["channel"] for o in watch.summary())


@pytest.mark.parametrize("damage, says", [
    ({"pressure": {"min": 1.0}}, "channel 'pressure'"),
    ({"pressure": {"min": 2.0, "max": 1.0, "zero": False}}, "min <= max"),
    ({"pressure": {"min": None, "max": 1.0, "zero": False}}, "both numbers or both null"),
    ([1, 2], "expected a mapping"),
])
def test_a_damaged_range_in_a_reference_file_is_one_line(tmp_path, capsys, damage, says):
    path = tmp_path / "ref.json"
    learn(plant(1200, 5), CHANNELS).save(path)
    d = json.loads(path.read_text())
    d["source"]["healthy_ranges"] = damage
    path.write_text(json.dumps(d))
    watched = write_csv(tmp_path / "watched.csv", plant(600, 6))
    assert main(["replay", str(watched), "--reference", str(path)]) == 2
    err = capsys.readouterr().err
    assert "source.healthy_ranges" in err and says in err and "Traceback" not in err


def _alarms(model, x, chunk):
    from wavelet_fdi.learned_detector import run_record

    _, _, det = run_record(model, np.arange(len(x), dtype=float), x, chunk=chunk)
    return [(a["alarm_id"], a["onset_index"], a["detection_index"], a["outside_healthy_range"]) for a in det.alarms]


@pytest.mark.parametrize("seed", (31, 32, 33))
def test_each_alarm_says_whether_its_window_left_the_healthy_range(seed):
    """A step beyond the healthy span of one channel at a drawn row: its alarm lists exactly the channels with a row
    outside their range between its onset and its detection (here that channel); the same alarm under ranges wide
    enough to hold it lists none. The same lists for any chunking (the window can span chunks)."""
    from dataclasses import replace

    from wavelet_fdi.healthy_range import outside_masks

    rng = np.random.default_rng(seed)
    model = learn(plant(3000, seed), CHANNELS)
    ranges = model.source["healthy_ranges"]
    c = CHANNELS.index("pressure")
    span = ranges["pressure"]["max"] - ranges["pressure"]["min"]
    onset = int(rng.integers(1500, 2500))
    x = plant(4000, seed + 100)
    x[onset:, c] += float(rng.uniform(0.8, 2.0)) * span
    got = _alarms(model, x, 4096)
    assert got and got[0][3] == ["pressure"], got
    for _, first, detected, names in got:
        masks = outside_masks(ranges, x[first:detected + 1], CHANNELS)
        assert names == [ch for ch in CHANNELS if masks[ch].any()]
    assert _alarms(model, x, 1) == _alarms(model, x, 97) == _alarms(model, x, None) == got
    wide = {ch: {"min": -1e9, "max": 1e9, "zero": True} for ch in CHANNELS}
    unaware = replace(model, source={**model.source, "healthy_ranges": wide})
    assert [(i, f, d) for i, f, d, _ in _alarms(unaware, x, 4096)] == [(i, f, d) for i, f, d, _ in got]
    assert all(names == [] for *_, names in _alarms(unaware, x, 4096))
