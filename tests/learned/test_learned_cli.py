"""phfdi calibrate --learn and phfdi replay --reference on measured records, and their bad inputs."""

from __future__ import annotations

import json

import numpy as np
import pytest

from phfdi.cli import main

from .test_learned_detector import CHANNELS, plant


def write_csv(path, x, extra_header=None, start="2021-05-01 00:00:00"):
    t0 = np.datetime64(start)
    cols = ["datetime", *CHANNELS, *(extra_header or [])]
    lines = [";".join(cols)]
    for i, row in enumerate(x):
        cells = ["" if not np.isfinite(v) else f"{v:.6g}" for v in row]
        lines.append(";".join([str(t0 + np.timedelta64(i, "s")).replace("T", " "), *cells]))
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("learned")
    rng = np.random.default_rng(11)
    x = plant(2600, 21)
    onset = int(rng.integers(1300, 2000))
    x[onset:, 1] += 10 * np.std(x[:400, 1])  # hidden from the detector: a step in "pressure"
    labels = (np.arange(len(x)) >= onset).astype(float)[:, None]
    faulty = write_csv(d / "faulty.csv", np.hstack((x, labels)), ["label"])
    healthy = write_csv(d / "healthy.csv", plant(1000, 22))
    return {"dir": d, "faulty": faulty, "healthy": healthy, "onset": onset}


def test_learn_then_replay_names_the_channel(files, capsys):
    ref = files["dir"] / "ref.json"
    assert main(["calibrate", "--learn", str(files["healthy"]), "--rows", "600", "--out", str(ref)]) == 0
    assert "wrote" in capsys.readouterr().out
    assert main(["replay", str(files["faulty"]), "--reference", str(ref), "--refit-rows", "400", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["channels"] == list(CHANNELS)  # the label column is not a channel of the reference
    (alarm,) = report["alarms"]
    assert files["onset"] <= alarm["detection_time"] <= files["onset"] + 120
    assert alarm["channels"][0] == "pressure" and alarm["contributions"]["pressure"]["share"] > 0.5
    # people's output names it too
    assert main(["replay", str(files["faulty"]), "--reference", str(ref), "--refit-rows", "400"]) == 0
    assert "channels: pressure" in capsys.readouterr().out


def one_error_line(capsys, argv) -> str:
    assert main(argv) == 2
    err = capsys.readouterr().err
    errors = [ln for ln in err.splitlines() if ": error: " in ln]  # reading notes may come before it
    assert len(errors) == 1 and "Traceback" not in err
    return errors[0]


def test_malformed_inputs_one_line_exit_2(files, tmp_path, capsys):
    ref = tmp_path / "ref.json"
    assert main(["calibrate", "--learn", str(files["healthy"]), "--out", str(ref)]) == 0
    capsys.readouterr()
    # a channel of the reference is not in the file
    short = tmp_path / "short.csv"
    short.write_text("datetime;flow;pressure\n2021-01-01 00:00:00;1;2\n2021-01-01 00:00:01;1;2\n")
    assert "current" in one_error_line(capsys, ["replay", str(short), "--reference", str(ref)])
    # text where numbers belong (the whole column)
    text = tmp_path / "text.csv"
    rows = ["datetime;" + ";".join(CHANNELS)] + [f"2021-01-01 00:00:{i:02d};1;2;3;x;5" for i in range(20)]
    text.write_text("\n".join(rows) + "\n")
    assert "vibration" in one_error_line(capsys, ["calibrate", "--learn", str(text), "--out", str(tmp_path / "a.json")])
    # a NaN stretch over the healthy rows
    x = plant(800, 3)
    x[100:400, 2] = np.nan
    gap = write_csv(tmp_path / "gap.csv", x)
    assert "'current' is missing" in one_error_line(capsys, ["calibrate", "--learn", str(gap), "--rows", "500",
                                                             "--out", str(tmp_path / "b.json")])
    # an empty file, a reference that is not one, a bad setting
    empty = tmp_path / "empty.csv"
    empty.write_text("")
    one_error_line(capsys, ["calibrate", "--learn", str(empty), "--out", str(tmp_path / "c.json")])
    bad = tmp_path / "bad.json"
    bad.write_text("[1, 2]")
    one_error_line(capsys, ["replay", str(files["faulty"]), "--reference", str(bad)])
    one_error_line(capsys, ["calibrate", "--learn", str(files["healthy"]), "--learned", "level=zero",
                            "--out", str(tmp_path / "d.json")])
    one_error_line(capsys, ["replay", str(files["faulty"]), "--refit-rows", "10"])


def test_nan_stretch_in_the_monitored_part_is_reported_not_fatal(files, tmp_path, capsys):
    ref = tmp_path / "ref.json"
    assert main(["calibrate", "--learn", str(files["healthy"]), "--out", str(ref)]) == 0
    x = plant(1500, 5)
    x[900:960, 0] = np.nan
    path = write_csv(tmp_path / "holes.csv", x)
    capsys.readouterr()
    assert main(["replay", str(path), "--reference", str(ref), "--refit-rows", "400", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    start, end = report["input_problems"]  # where the stretch begins and where it ends
    assert "flow: missing" in start["message"] and start["line"] == 902
    assert "flow: back" in end["message"] and end["line"] == 962


def test_a_measured_records_bag_replays_offline_as_its_csv(files, capsys):
    """``bag from-csv`` then ``replay BAG --reference``: the bag's /measured/sample read back as the record (its
    time, channels and the CSV's line numbers), the same alarms as the CSV's replay. It was refused before: "no
    /plant/measurement topic: not a bag of the phfdi graph"."""
    ref, bag = files["dir"] / "ref_bag.json", files["dir"] / "faulty.mcap"
    assert main(["calibrate", "--learn", str(files["healthy"]), "--rows", "600", "--out", str(ref)]) == 0
    assert main(["bag", "from-csv", str(files["faulty"]), str(bag), "--exclude", "label"]) == 0
    capsys.readouterr()
    assert main(["replay", str(files["faulty"]), "--reference", str(ref), "--json"]) == 0
    from_csv = json.loads(capsys.readouterr().out)
    assert main(["replay", str(bag), "--reference", str(ref), "--json"]) == 0
    from_bag = json.loads(capsys.readouterr().out)
    assert from_csv["alarms"] and from_csv["alarms"][0]["detection_stamp"], "no alarm (or stamp) to compare"
    keys = ("detection_time", "onset_time", "statistic", "channels", "detection_line", "where", "detection_stamp",
            "onset_stamp")
    assert [{k: a.get(k) for k in keys} for a in from_bag["alarms"]] == \
        [{k: a.get(k) for k in keys} for a in from_csv["alarms"]]
    assert from_bag["samples"] == from_csv["samples"] and from_bag["channels"] == from_csv["channels"]


def test_a_damaged_measured_bag_is_one_line(files, capsys):
    ref, bag = files["dir"] / "ref_cut.json", files["dir"] / "cut.mcap"
    assert main(["calibrate", "--learn", str(files["healthy"]), "--rows", "600", "--out", str(ref)]) == 0
    assert main(["bag", "from-csv", str(files["faulty"]), str(bag), "--exclude", "label"]) == 0
    data = bag.read_bytes()
    bag.write_bytes(data[: len(data) // 2])  # its writer killed half way
    capsys.readouterr()
    line = one_error_line(capsys, ["replay", str(bag), "--reference", str(ref)])
    assert str(bag) in line and "bag recover" in line, line


def test_every_detector_setting_is_an_option_of_its_own(files, tmp_path, capsys):
    """One CLI form for both detectors (issue 37): a learned setting is --NAME VALUE like the physics detector's;
    --level sets the detector being calibrated (it used to set only the physics one, silently ignored with --learn);
    an option of the other detector is refused in one line; the old --learned KEY=VALUE is still read, with a
    note, and a setting given both ways is refused."""
    ref = tmp_path / "ref.json"
    assert main(["calibrate", "--learn", str(files["healthy"]), "--level", "3", "--mean-h", "8", "--form", "oe",
                 "--out", str(ref)]) == 0
    settings = json.loads(ref.read_text())["settings"]
    assert (settings["level"], settings["mean_h"], settings["form"]) == (3, 8.0, "oe")
    assert settings["lags"] == 2 and settings["wavelet"] == "sym4"  # the others: the learned detector's defaults
    capsys.readouterr()

    old = tmp_path / "old.json"
    assert main(["calibrate", "--learn", str(files["healthy"]), "--learned", "mean_h=8", "--out", str(old)]) == 0
    assert "--learned KEY=VALUE is the old form" in capsys.readouterr().err
    assert json.loads(old.read_text())["settings"]["mean_h"] == 8.0

    assert "--channels" in one_error_line(capsys, ["calibrate", "--learn", str(files["healthy"]), "--channels",
                                                   "ph,level", "--out", str(tmp_path / "a.json")])
    # --arl0 is both detectors' (the false-alarm target): here it asks for thresholds the record is too short for
    assert "arl0_samples 1e+06: measuring the thresholds needs at least 8 windows" in one_error_line(
        capsys, ["calibrate", "--learn", str(files["healthy"]), "--arl0", "1e6", "--out", str(tmp_path / "a.json")])
    # the physics reference (phfdi calibrate's default) takes --mean-h over its design, but not the old form
    assert "--learned mean_h=8" in one_error_line(capsys, ["calibrate", "--learned", "mean_h=8", "--out",
                                                          str(tmp_path / "b.json")])
    assert "mean_h" in one_error_line(capsys, ["calibrate", "--learn", str(files["healthy"]), "--mean-h", "8",
                                               "--learned", "mean_h=7", "--out", str(tmp_path / "c.json")])
    assert "--level" in one_error_line(capsys, ["replay", str(files["faulty"]), "--reference", str(ref),
                                                "--level", "4"])
    assert not any((tmp_path / n).exists() for n in ("a.json", "b.json", "c.json"))
