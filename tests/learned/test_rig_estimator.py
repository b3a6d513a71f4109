"""The estimator reference on the real pH rig, through the commands a user types (issue 21): calibrate on four
shared runs, replay the fifth healthy (no alarm) and with a probe fault hidden in it by ``phfdi inject`` (an
alarm after the onset, none before). The detector reads only the CSV; the truth file is never given to it.
Held out: the closed-loop run (the rig's own controller switching the base pump), onset at its middle."""

from __future__ import annotations

import json

import pytest

from phfdi.cli import main
from tests.conftest import SHARED_DATA

HELD_OUT = "2025.02.24-005_control_pH7_from_basic.csv"


@pytest.fixture(scope="module")
def fold(tmp_path_factory):
    rig = SHARED_DATA / "ph_rig"
    if not rig.is_dir():
        pytest.skip(f"real data folder not found at {SHARED_DATA} (set PHFDI_SHARED_DATA)")
    runs = sorted(str(p) for p in rig.glob("*.csv") if p.name != HELD_OUT)
    assert len(runs) == 4
    out = tmp_path_factory.mktemp("rig")
    ref = out / "rig.json"
    assert main(["calibrate", "--estimator", *runs, "--map", "ph_rig", "--out", str(ref)]) == 0
    return rig / HELD_OUT, ref, out


def _alarms(capsys, record, ref) -> list[dict]:
    capsys.readouterr()
    assert main(["replay", str(record), "--map", "ph_rig", "--reference", str(ref), "--json"]) == 0
    return json.loads(capsys.readouterr().out)["alarms"]


def test_the_held_out_healthy_run_raises_no_alarm(fold, capsys):
    record, ref, _ = fold
    assert _alarms(capsys, record, ref) == []


@pytest.mark.parametrize("kind,size", [("probe_bias", "1.0"), ("probe_frozen", "0")])
def test_a_hidden_probe_fault_is_found_after_its_onset(fold, capsys, kind, size):
    record, ref, out = fold
    onset = 503.0  # the middle of the run's 1004 s
    faulty = out / f"{kind}.csv"
    assert main(["inject", str(record), "--map", "ph_rig", "--fault", kind, "--onset", str(onset), "--size", size,
                 "--out", str(faulty)]) == 0
    alarms = _alarms(capsys, faulty, ref)
    assert alarms, f"{kind}: no alarm"
    assert alarms[0]["detection_time"] >= onset, f"{kind}: an alarm before the onset"
    assert alarms[0]["detection_time"] - onset < 120.0
