"""The "reference kind" recipe of docs/architecture.md, followed in this one file: a class with the reference
protocol's members and one entry in ``wavelet_fdi.references.KINDS``. Nothing else is edited, and the detector
model file, ``phfdi replay --reference`` and the detector then take the new kind.

The toy kind standardises each channel by its healthy mean and standard deviation (no dynamics): enough to show
a step hidden in one channel is found on that channel and a healthy record raises nothing.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from phfdi.cli import main
from wavelet_fdi import references
from wavelet_fdi.learned_detector import LearnedSettings, calibrate_bands

CHANNELS = ("flow_l_min", "pressure_bar")


class _Standardised:
    """Each channel's residual: (x - healthy mean) / healthy standard deviation."""

    kind = "toy_standardised"
    lags = 0

    def __init__(self, channels: tuple[str, ...], mean: np.ndarray, std: np.ndarray) -> None:
        self._channels, self.mean, self.std = tuple(channels), np.asarray(mean, float), np.asarray(std, float)

    @property
    def channels(self) -> tuple[str, ...]:
        return self._channels

    @property
    def residual_channels(self) -> tuple[str, ...]:
        return self._channels

    def new_state(self) -> "_Standardised":
        return self  # no state to keep between chunks

    def residuals(self, t_s, rows) -> np.ndarray:
        return (np.asarray(rows, float) - self.mean) / self.std

    def to_dict(self) -> dict:
        return {"kind": self.kind, "channels": list(self._channels), "mean": self.mean.tolist(),
                "std": self.std.tolist()}

    @classmethod
    def from_dict(cls, d: dict, where: str = "reference") -> "_Standardised":
        return cls(tuple(d["channels"]), np.array(d["mean"]), np.array(d["std"]))


def _rows(n: int, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).normal([20.0, 3.0], [0.5, 0.05], size=(n, 2))


def _csv(path, rows):
    lines = ["time_s," + ",".join(CHANNELS)] + [f"{i}," + ",".join(f"{v:.6g}" for v in r) for i, r in enumerate(rows)]
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture
def toy_model(tmp_path, monkeypatch):
    monkeypatch.setitem(references.KINDS, _Standardised.kind, _Standardised)  # the recipe's one registration
    healthy = _rows(3000, 1)
    ref = _Standardised(CHANNELS, healthy.mean(axis=0), healthy.std(axis=0))
    model = calibrate_bands(ref, [(np.arange(len(healthy), dtype=float), healthy)], LearnedSettings())
    path = tmp_path / "toy.json"
    model.save(path)
    return path


def test_a_new_reference_kind_is_taken_by_the_model_file_and_replay(toy_model, tmp_path, capsys):
    assert json.loads(toy_model.read_text())["reference"]["kind"] == "toy_standardised"
    faulty = _rows(2400, 2)
    onset = 1500
    faulty[onset:, 1] += 0.5  # hidden: pressure 10 healthy standard deviations up
    assert main(["replay", str(_csv(tmp_path / "faulty.csv", faulty)), "--reference", str(toy_model), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["channels"] == list(CHANNELS)
    (alarm,) = report["alarms"]
    assert onset <= alarm["detection_time"] <= onset + 120, alarm["detection_time"]
    assert alarm["channels"][0] == "pressure_bar"

    assert main(["replay", str(_csv(tmp_path / "healthy.csv", _rows(2400, 3))), "--reference", str(toy_model),
                 "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["alarms"] == []


def test_without_its_registration_the_kind_is_refused_in_one_line(toy_model, tmp_path, monkeypatch, capsys):
    monkeypatch.delitem(references.KINDS, _Standardised.kind)
    assert main(["replay", str(_csv(tmp_path / "h.csv", _rows(600, 4))), "--reference", str(toy_model)]) == 2
    err = capsys.readouterr().err
    assert "unknown reference kind 'toy_standardised'" in err and "Traceback" not in err


def test_a_namer_unsure_of_its_first_naming_names_again_at_the_kinds_next_look(monkeypatch):
    """A kind that names faults (one entry in NAMERS) and gives looks (one in LOOKS): a naming that says
    ``name_again`` is made again at the next look while the alarm is up; the last one stands, the earlier are kept."""
    calls = []

    def namer(ref, t_s, rows, onset_index, detection_index, statistic, after=None):
        calls.append(len(rows) - detection_index)  # samples after the detection the window holds
        sure = len(calls) > 1
        return {"family": "sensor", "fault_class": "toy_step" if sure else "toy_unsure", "description": "a step",
                "size": 0.5, "unit": "bar", "confirmed": True, "name_again": not sure}

    monkeypatch.setitem(references.KINDS, _Standardised.kind, _Standardised)
    monkeypatch.setitem(references.NAMERS, _Standardised.kind, namer)
    monkeypatch.setitem(references.LOOKS, _Standardised.kind, lambda ref: (64, 128, 192))
    healthy = _rows(3000, 1)
    ref = _Standardised(CHANNELS, healthy.mean(axis=0), healthy.std(axis=0))
    model = calibrate_bands(ref, [(np.arange(len(healthy), dtype=float), healthy)], LearnedSettings())
    faulty = _rows(2400, 2)
    faulty[1500:, 1] += 0.5  # stays to the end: the alarm stays up
    from wavelet_fdi.learned_detector import run_record

    events, _, det = run_record(model, np.arange(2400.0), faulty)
    named = [e for e in events if e.kind == "named"]
    assert len(named) == 2 and len(calls) == 2, (named, calls)
    assert calls == [64, 128]  # the second look, not a third: the second naming was sure
    (alarm,) = det.alarms
    assert alarm["isolation"]["fault_class"] == "toy_step" and alarm["namings"][0]["fault_class"] == "toy_unsure"
    assert named[1].index - named[0].index == 64
