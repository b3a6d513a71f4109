"""phfdi replay / calibrate / evaluate from the command line."""

from __future__ import annotations

import json

import numpy as np
import pytest

from phfdi.cli import main
from phfdi.loop import simulate
from wavelet_fdi.learned_detector import LearnedModel

from .detector_helpers import short_spec


@pytest.fixture(scope="module")
def backlash_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("runs") / "backlash.parquet"
    simulate(short_spec("backlash", onset_s=1000.0, duration_s=1500.0)).save(path)
    return path


def test_replay_json_lists_the_alarm_with_its_diagnosis(backlash_file, capsys):
    # the run carries its scenario (shortened paper loop); warm-up and isolation delay shortened
    assert main(["replay", str(backlash_file), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["notes"] == [] and report["file"] == str(backlash_file)
    alarms = report["alarms"]
    assert len(alarms) == 1 and report["reference"] == "paper_physics"  # the shipped physics reference, by default
    a = alarms[0]
    for key in ("onset_time", "detection_time", "statistic", "contributions", "isolation"):
        assert key in a
    assert 1000.0 <= a["detection_time"] < 1200.0
    iso = a["isolation"]
    assert iso["fault_class"] == "backlash" and iso["parameter"]["name"] == "width_pct" and iso["confidence"] > 0.9


def test_replay_of_a_bag_gives_the_alarms_of_the_run_it_holds(backlash_file, tmp_path, capsys):
    """phfdi replay BAG.mcap reads the bag through phfdi.bagio.load_run (no ROS process needed):
    the run written as a bag of the graph's topics replays to the same alarms as the run file."""
    from phfdi.bagio import write_run
    from phfdi.records import read_run

    bag = write_run(read_run(backlash_file), tmp_path / "run.mcap")
    assert main(["replay", str(backlash_file), "--json"]) == 0
    from_file = json.loads(capsys.readouterr().out)
    assert main(["replay", str(bag), "--json"]) == 0
    from_bag = json.loads(capsys.readouterr().out)
    assert from_bag["alarms"] == from_file["alarms"] and from_bag["alarms"][0]["isolation"]["fault_class"] == "backlash"
    assert from_bag["notes"] == from_file["notes"] == []


def test_replay_of_a_csv_without_metadata_uses_the_scenario_option(backlash_file, tmp_path, capsys):
    from phfdi.records import read_run

    csv = read_run(backlash_file).to_csv(tmp_path / "run.csv")
    # a CSV carries no scenario: the paper preset is assumed (its 5000 s setpoint change
    # never comes in this 1500 s run, whose own setpoint moved at 200 s); detection only
    assert main(["replay", str(csv), "--no-isolation"]) == 0
    out = capsys.readouterr().out
    # the backlash from 1000 s detected, and not named (--no-isolation)
    assert out.startswith("alarm 1: detected 10") and "named" not in out, out


def test_no_isolation_detects_as_the_default_and_names_nothing(backlash_file, capsys):
    """--no-isolation runs the default detector (the shipped physics reference) without its naming: the same
    detections, no fault named (before 2026-12-07 it switched to the physics detector)."""
    assert main(["replay", str(backlash_file), "--json"]) == 0
    named = json.loads(capsys.readouterr().out)["alarms"]
    assert main(["replay", str(backlash_file), "--json", "--no-isolation"]) == 0
    detected = json.loads(capsys.readouterr().out)["alarms"]
    assert named and named[0]["isolation"]["fault_class"] == "backlash"
    assert [(a["detection_time"], a["statistic"]) for a in detected] == \
        [(a["detection_time"], a["statistic"]) for a in named]
    assert all(a.get("isolation") is None for a in detected)


@pytest.mark.parametrize("args, message", [
    (["replay", "nope.csv"], "no such file"),
    (["replay", "run.mcap"], "cannot read the bag"),
    (["replay", "{run}", "--wavelet", "db4"], "phfdi calibrate"),
    (["replay", "{run}", "--calibration", "my.yaml"], "make a physics reference"),
])
def test_user_errors_are_one_line_with_exit_status_2(args, message, backlash_file, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "run.mcap").write_bytes(b"")
    args = [a.replace("{run}", str(backlash_file)) for a in args]
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0] and "Traceback" not in err[0]


def test_calibrate_with_the_level_channel_and_replay_with_it(tmp_path, backlash_file, capsys):
    """phfdi calibrate (the physics reference, the default mode since 2026-12-07) with --channels ph,level watches
    the level too; replay --reference finds the backlash with it."""
    out = tmp_path / "ref.json"
    assert main(["calibrate", "--seeds", "1001-1002", "--set", "duration_s=6000", "--channels", "ph,level",
                 "--out", str(out)]) == 0
    model = LearnedModel.load(out)
    assert model.reference.kind == "physics" and model.source["runs"] == ["seed 1001", "seed 1002"]
    assert model.residual_channels == ("ph_measured", "level_measured_cm")
    assert {"level_measured_cm.R.mean_up", "level_measured_cm.D1.energy"} <= set(model.thresholds)
    capsys.readouterr()
    assert main(["replay", str(backlash_file), "--json", "--no-isolation", "--reference", str(out)]) == 0
    alarms = json.loads(capsys.readouterr().out)["alarms"]
    assert alarms and alarms[0]["detection_time"] >= 1000.0


def test_calibrate_on_recorded_runs(tmp_path, capsys):
    """A plant's own healthy recordings (here: simulated ones saved to files) set the physics reference's noise and
    thresholds: the pH residual's healthy RMS is the sensor's noise (1 in its units)."""
    files = []
    for seed in (2001, 2002):
        path = tmp_path / f"healthy{seed}.parquet"
        simulate(short_spec("healthy", duration_s=5000.0, seed=seed)).save(path)
        files.append(str(path))
    out = tmp_path / "plant.json"
    overrides = ["--set", "duration_s=5000", "--set", "setpoints.ph.changes=[{at_s: 200, value: 8.0}]"]
    assert main(["calibrate", "--runs", *files, *overrides, "--out", str(out)]) == 0
    model = LearnedModel.load(out)
    assert model.source["runs"] == files
    # in sensor-noise units: the healthy model leaves the noise, about 1 in every band of the orthonormal wavelet
    assert model.band_sigma.shape == (1, len(model.settings.bands()))
    assert np.allclose(model.band_sigma, 1.0, rtol=0.1), model.band_sigma


@pytest.mark.parametrize("command", ["replay", "evaluate", "calibrate"])
def test_help_says_what_it_does_with_an_example(command, capsys):
    with pytest.raises(SystemExit) as exc:
        main([command, "--help"])
    assert exc.value.code == 0
    assert f"phfdi {command}" in capsys.readouterr().out.split("examples:")[1]


def test_a_closed_pipe_ends_the_command_quietly(backlash_file):
    """`phfdi replay FILE --json | head -c 1`: the reader is gone before the report is written; one quiet exit
    (141 = 128 + SIGPIPE, as a shell reports it), no BrokenPipeError traceback."""
    import os
    import subprocess
    import sys

    r, w = os.pipe()
    os.close(r)  # the reader is gone before the command writes anything
    try:
        proc = subprocess.run([sys.executable, "-m", "phfdi.cli", "replay", str(backlash_file), "--json"],
                              stdout=w, stderr=subprocess.PIPE, text=True, timeout=120)
    finally:
        os.close(w)
    assert proc.returncode == 141, proc.stderr
    assert "Traceback" not in proc.stderr and "BrokenPipe" not in proc.stderr, proc.stderr
