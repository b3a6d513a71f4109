"""A stray writer on a running graph's domain: the lock-step ring drops and counts what is not its next sample,
the detector takes no stray's place on its grid and its /fault_alarm stays bounded, the run ends as if nothing
happened (real processes throughout).

Before: one message stamped in the future became the controllers' clock and the ring stalled for good; stamp
garbage made the detector publish one /fault_alarm per clock reset (the physics detector's node, retired on
2026-12-07), and then moved the grid of the multichannel detector's node (the graph's detector since) past the run's
end."""

from __future__ import annotations

import functools
import json
import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from phfdi import bagio
from phfdi.loop import simulate
from phfdi.scenario import load_scenario
from phfdi_base import topics as T

from .conftest import (
    domain_of,
    ownerless_shm_files,
    phfdi_cmd,
    processes_with,
    read_until,
    shm_files_used,
    stale_shm_files,
)
from .stray_publisher import MARK

pytestmark = [pytest.mark.ros, pytest.mark.timeout(300)]

DURATION_S = 200  # 201 samples of 1 s; at 10 x real time about 20 s of wall time (the strays must all be sent
# while the ring runs: the publisher's own start-up takes seconds on a loaded machine)
N = DURATION_S + 1
OVERRIDES = [f"duration_s={DURATION_S}", "setpoints.ph.changes.0.at_s=50"]
ROUNDS = 6  # rounds of 6 strays on each of the three ring topics
BURST = 20  # cycles of stamp garbage (1 future + 11 past stamps) on the detector's two inputs
#: the detector's channels (the shipped physics reference's), each read from a topic the strays reach
CHANNELS = ("valve_command_pct", "level_controller_output_pct", "ph_measured", "level_measured_cm")


@pytest.fixture(scope="module")
def disturbed(tmp_path_factory):
    """One paced launch with the graph's detector, and a stray writer on its domain while it runs."""
    return launch_disturbed(tmp_path_factory.mktemp("stray"), ["--detector"])


def launch_disturbed(tmp: Path, detector_args: list[str]) -> dict:
    """One paced launch with a detector (``detector_args`` of phfdi launch), and a stray writer on its domain while
    it runs."""
    bag, logs = tmp / "run.mcap", tmp / "logs"
    before = ownerless_shm_files()
    t0 = time.monotonic()
    cmd = ["launch", "--fault", "backlash", "--onset", "100", "--pace", "10", *detector_args,
           "--record", str(bag), "--log-dir", str(logs), "--json"]
    for o in OVERRIDES:
        cmd += ["--set", o]
    launch = subprocess.Popen(phfdi_cmd(*cmd), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        seen = read_until(launch, "graph connected", timeout_s=120)
        domain = domain_of(seen)
        used = shm_files_used(processes_with(str(logs)))
        stray = subprocess.run([sys.executable, "-m", "tests.ros.stray_publisher", str(domain), str(N), str(ROUNDS),
                                str(BURST)], capture_output=True, text=True, timeout=120)
        out, err = launch.communicate(timeout=120)
    finally:
        if launch.poll() is None:
            launch.kill()
            launch.communicate()
    wall_s = time.monotonic() - t0
    return {"launch_rc": launch.returncode, "summary": out, "stderr": seen + err, "stray": stray, "bag": bag,
            "logs": logs, "wall_s": wall_s, "shm": (domain, used, before)}


def _stray_report(disturbed) -> dict:
    stray = disturbed["stray"]
    assert stray.returncode == 0, stray.stdout + stray.stderr
    report = json.loads(stray.stdout.splitlines()[-1])
    assert report["acked"], report  # every stray reached every matched reader
    assert report["first_seen"] < N - 1, "the strays came after the run: they tested nothing"
    # every stray was sent while the ring still ran (else the nodes that should count them were gone)
    assert report["last_seen"] < N - 1, report
    return report


@functools.lru_cache(maxsize=1)  # the module's tests read the one bag
def _messages(bag) -> dict[str, list]:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    out: dict[str, list] = {}
    with open(bag, "rb") as f:
        for _schema, channel, _message, msg in make_reader(f, decoder_factories=[DecoderFactory()]) \
                .iter_decoded_messages():
            out.setdefault(channel.topic, []).append(msg)
    return out


def _is_stray(topic: str, msg) -> bool:
    value = {T.MEASUREMENT.name: lambda m: m.ph, T.CONTROLLER.name: lambda m: m.ph_output_pct,
             T.VALVE_STATE.name: lambda m: m.ph_flow_ml_s}.get(topic)
    return value is not None and value(msg) == MARK


def test_the_ring_runs_to_the_end_and_equals_the_undisturbed_run(disturbed):
    """What a stray could not enter (every stamp it used is never the ring's next sample) leaves the run as the
    in-process loop computes it: each ring topic holds samples 0..200 once, equal to ``simulate`` to 1e-9."""
    report = _stray_report(disturbed)
    assert disturbed["launch_rc"] == 0, disturbed["stderr"]
    summary = json.loads(disturbed["summary"])
    assert summary["samples"] == summary["of"] == N, summary  # not stalled
    assert "Traceback" not in disturbed["stderr"]
    info = bagio.bag_info(disturbed["bag"])
    assert info["finished"], info
    msgs = _messages(disturbed["bag"])
    # the recorder heard the strays too: they really were on the graph's domain; those stamped before 0 s have no
    # place in a bag (MCAP log times are unsigned): left out and counted in the recorder's closing event
    for topic, n in report["published"].items():
        assert sum(_is_stray(topic, m) for m in msgs[topic]) == n - report["before_zero"][topic], topic
    closed = [json.loads(ln) for ln in (disturbed["logs"] / "recorder.stdout").read_text().splitlines()
              if '"closed"' in ln]
    assert closed and closed[-1]["unrecordable"] == report["before_zero"], closed
    expected = simulate(load_scenario("paper", fault="backlash", onset_s=100.0, overrides=OVERRIDES))
    assert len(expected) == N
    fields = {T.MEASUREMENT.name: {"ph": "ph_measured", "level_cm": "level_measured_cm"},
              T.CONTROLLER.name: {"ph_output_pct": "ph_controller_output_pct", "ph_setpoint": "ph_setpoint"},
              T.VALVE_STATE.name: {"ph_position_pct": "valve_position_pct"},
              T.PLANT_STATE.name: {"ph": "ph_true", "level_cm": "level_true_cm"}}
    for topic, names in fields.items():
        real = [m for m in msgs[topic] if not _is_stray(topic, m)]
        assert [m.stamp.sec for m in real] == list(range(N)) and all(m.stamp.nanosec == 0 for m in real), topic
        for field, signal in names.items():
            got = np.array([getattr(m, field) for m in real])
            diff = np.abs(got - expected[signal])
            assert np.all(diff <= 1e-9), f"{topic} {field}: max difference {diff.max()}"
    assert expected["fault_severity"][expected.time_s >= 100].min() == 1.0  # the fault was on: a real run


def test_every_ring_node_counts_its_strays_on_diagnostics(disturbed):
    _stray_report(disturbed)
    msgs = _messages(disturbed["bag"])
    last: dict[str, dict[str, str]] = {}
    levels: dict[str, set] = {}
    for array in msgs[T.DIAGNOSTICS.name]:
        for s in array.status:
            if s.name.endswith(": inputs"):
                last[s.name] = {kv.key: kv.value for kv in s.values}
                levels.setdefault(s.name, set()).add(s.level)
    # each node's strays: future, past, off the grid, invalid (3 per round: two joined would be the next
    # sample or a later one, one before 0 s); the burst reaches the controllers
    # (/plant/measurement) and the valve (/controller/output), not the plant (/valve/state)
    burst = {"controllers": BURST, "valve": BURST, "plant": 0}
    for node, b in burst.items():
        counts = last[f"{node}: inputs"]
        assert int(counts["future"]) == ROUNDS + b, (node, counts)
        assert int(counts["past"]) == ROUNDS + 11 * b and int(counts["duplicate"]) == 0, (node, counts)
        assert int(counts["off_grid"]) == ROUNDS and int(counts["invalid_stamp"]) == 3 * ROUNDS, (node, counts)
        assert int(counts["dropped"]) == 6 * ROUNDS + 12 * b, (node, counts)
        assert levels[f"{node}: inputs"] == {1}, (node, levels)  # WARN: published only once strays were seen
    # the counts went out at most about once a second (plus the last ones on the way out), not once per stray
    n_reports = sum(1 for a in msgs[T.DIAGNOSTICS.name] for s in a.status if s.name == "controllers: inputs")
    assert n_reports <= disturbed["wall_s"] / 1.0 + 2, n_reports
    # and the log said so without a flood: one line per reason, then at most one per 10 s
    log = (disturbed["logs"] / "controllers.stderr").read_text() if (disturbed["logs"] / "controllers.stderr").exists() \
        else ""
    dropped_lines = [ln for ln in log.splitlines() if "dropped a measurement" in ln]
    assert 1 <= len(dropped_lines) <= 5 * (1 + disturbed["wall_s"] / 10.0), dropped_lines


def test_the_detector_uses_every_real_sample_and_no_stray(disturbed):
    _stray_report(disturbed)
    assert disturbed["launch_rc"] == 0, disturbed["stderr"]
    assert "Traceback" not in disturbed["stderr"]
    done = [json.loads(ln) for ln in (disturbed["logs"] / "detector.stdout").read_text().splitlines()
            if '"detector_done"' in ln]
    assert done, "the detector did not finish"
    report = done[-1]
    assert report["samples"] == N, report["samples"]
    counts = report["channel_map"]["counts"]
    for channel in CHANNELS:
        c = counts[channel]
        # each sample on the grid is a real one: none missing, none held
        assert c["used"] == N and c["missing"] == 0 and c["held"] == 0, (channel, c)
        # per round: one stamped beyond the run's end (a jump its stream never followed), one off the grid, three
        # that are no time; per burst cycle one far ahead (the 11 past ones come late)
        assert c["jumps_dropped"] == ROUNDS + BURST, (channel, c)
        assert c["off_grid"] == ROUNDS and c["invalid_stamps"] == 3 * ROUNDS, (channel, c)
    # no stray's value (-77 on every field) went into a sample: it would lie far outside the healthy runs' range
    assert report["outside_healthy_range"] == [], report["outside_healthy_range"]
    assert report["alarms"] == []  # 200 s of a run is inside the reference's 600 s warm-up: nothing to raise


def test_the_detectors_fault_alarm_stays_bounded(disturbed):
    _stray_report(disturbed)
    alarms = _messages(disturbed["bag"])[T.FAULT_ALARM.name]
    assert all(a.state == 0 for a in alarms), [a.message for a in alarms if a.state]
    # heartbeats, one per 60 s of simulated time (+ the first and the last), and the state at the start: the strays
    # change nothing the detector says (they are counted on /diagnostics, 'detector: channel map')
    assert len(alarms) <= math.ceil(DURATION_S / 60) + 3, [a.message for a in alarms]


def test_no_shared_memory_is_left_behind(disturbed):
    assert disturbed["launch_rc"] == 0, disturbed["stderr"]
    assert stale_shm_files(*disturbed["shm"]) == []


def test_every_diagnostics_status_falls_in_one_aggregator_group(disturbed):
    """config/diagnostic_aggregator.yaml groups the graph's /diagnostics (GenericAnalyzer's ``startswith``
    matching, emulated here: no diagnostic_aggregator on this machine): each status of the recorded run in exactly
    one group, and every group used."""
    import yaml

    path = Path(__file__).resolve().parents[2] / "config" / "diagnostic_aggregator.yaml"
    config = yaml.safe_load(path.read_text())["analyzers"]["ros__parameters"]
    groups = {key: g["startswith"] for key, g in config.items() if isinstance(g, dict)}
    names = {s.name for a in _messages(disturbed["bag"])[T.DIAGNOSTICS.name] for s in a.status}
    assert {"plant: inputs", "controllers: inputs", "valve: inputs", "detector: channel map"} <= names, names
    used = set()
    for name in names:
        hits = [key for key, prefixes in groups.items() if any(name.startswith(p) for p in prefixes)]
        assert len(hits) == 1, (name, hits)
        used |= set(hits)
    assert used == set(groups), (used, groups)
