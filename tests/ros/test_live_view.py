"""The live view: ``phfdi launch --foxglove PORT`` serves the graph over the Foxglove WebSocket protocol.

A real paced launch with the detector; a WebSocket client of this test speaks the protocol (serverInfo,
advertise, subscribe, binary message data) while the graph runs. foxglove-sdk 0.30 names the protocol
``foxglove.sdk.v1`` (the former ``foxglove.websocket.v1``, which it refuses: checked below).
"""

from __future__ import annotations

import json
import math
import signal
import socket
import struct
import subprocess
import time
from contextlib import ExitStack

import numpy as np
import pytest
from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect

from phfdi import bagio
from phfdi.loop import simulate
from phfdi.scenario import load_scenario
from phfdi_base import live_view
from phfdi_base import topics as T

from .conftest import SHORT_OVERRIDES, SHORT_RUN, node_cmd, phfdi_cmd, read_until

pytestmark = [pytest.mark.ros, pytest.mark.timeout(400)]

SUBPROTOCOL = "foxglove.sdk.v1"
CHANNELS = {"/plant/measurement", "/controller/output", "/valve/state", "/detector/monitor", "/fault_alarm"}
#: the default detector's statistics (the multichannel detector with the paper's physics reference: pH alone)
STATISTICS = {"ph_measured_R_mean_up", "ph_measured_R_mean_down", "ph_measured_A3_mean_up", "ph_measured_A3_mean_down",
              "ph_measured_D1_energy", "ph_measured_D2_energy", "ph_measured_D3_energy", "ph_measured_A3_aj_energy"}
#: messages per per-sample channel the client waits for (the run has 601 samples)
ENOUGH = 30


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class FoxgloveClient:
    """The client side of the protocol, as Foxglove speaks it: JSON text frames, binary message data."""

    def __init__(self, port: int, timeout_s: float = 30.0) -> None:
        self._stack = ExitStack()
        self.ws = self._stack.enter_context(connect(f"ws://127.0.0.1:{port}", subprotocols=[SUBPROTOCOL],
                                                    open_timeout=timeout_s))
        self.server_info = json.loads(self.ws.recv(timeout=timeout_s))
        self.channels: dict[int, dict] = {}
        while not self.channels:  # the channels exist before the server starts: advertised right after serverInfo
            op = json.loads(self.ws.recv(timeout=timeout_s))
            if op["op"] == "advertise":
                self.channels = {c["id"]: c for c in op["channels"]}

    def subscribe_all(self) -> None:
        # subscription id = channel id, so a message's subscription names its channel
        self.ws.send(json.dumps({"op": "subscribe",
                                 "subscriptions": [{"id": cid, "channelId": cid} for cid in self.channels]}))

    def message(self, timeout_s: float) -> tuple[str, int, dict] | None:
        """The next message data: (topic, log time ns, decoded JSON); None for a text frame."""
        frame = self.ws.recv(timeout=timeout_s)
        if not isinstance(frame, bytes):
            return None
        opcode, sub_id, log_time_ns = struct.unpack_from("<BIQ", frame)
        assert opcode == 1  # message data
        return self.channels[sub_id]["topic"], log_time_ns, json.loads(frame[13:])

    def close(self) -> None:
        self._stack.close()


def _collect(client: FoxgloveClient, proc: subprocess.Popen, timeout_s: float) -> dict[str, list]:
    """Messages per topic, each with whether the launch was still running when it came."""
    got: dict[str, list] = {t: [] for t in CHANNELS}
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        per_sample_done = all(len(got[t]) >= ENOUGH for t in CHANNELS - {"/fault_alarm"})
        if per_sample_done and got["/fault_alarm"]:
            break
        item = client.message(timeout_s=max(1.0, deadline - time.monotonic()))
        if item is not None:
            topic, log_time_ns, data = item
            got[topic].append((log_time_ns, data, proc.poll() is None))
    return got


@pytest.fixture(scope="module")
def live_run(tmp_path_factory):
    """One paced launch (20 x real time: 30 s) with the detector, recorded, served on a free port."""
    tmp = tmp_path_factory.mktemp("live")
    port = free_port()
    bag = tmp / "run.mcap"
    proc = subprocess.Popen(phfdi_cmd("launch", *SHORT_RUN, "--detector", "--record", str(bag), "--pace", "20",
                                      "--foxglove", str(port), "--json", "--log-dir", str(tmp / "logs")),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        read_until(proc, f"live view: open ws://127.0.0.1:{port}", timeout_s=180)
        client = FoxgloveClient(port)
        client.subscribe_all()
        got = _collect(client, proc, timeout_s=120)
        client.close()
        out, err = proc.communicate(timeout=240)
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
            proc.wait(timeout=60)
    return {"proc": proc, "out": out, "err": getattr(proc, "stderr_seen", "") + err, "client": client, "got": got,
            "bag": bag, "port": port}


def test_the_server_advertises_the_live_views_channels_with_json_schemas(live_run):
    client = live_run["client"]
    assert client.server_info["op"] == "serverInfo" and client.server_info["name"] == "phfdi graph"
    channels = {c["topic"]: c for c in client.channels.values()}
    assert set(channels) == CHANNELS
    for topic, c in channels.items():
        assert c["encoding"] == "json" and c["schemaEncoding"] == "jsonschema"
        schema = json.loads(c["schema"])
        assert c["schemaName"] == schema["title"] == live_view.SCHEMAS[topic]["title"]
        assert schema["type"] == "object" and "time_s" in schema["properties"]
    assert {"ph", "level_cm"} <= set(json.loads(channels["/plant/measurement"]["schema"])["properties"])
    assert {"ph_command_pct", "ph_position_pct"} <= set(json.loads(channels["/valve/state"]["schema"])["properties"])
    monitor = json.loads(channels["/detector/monitor"]["schema"])["properties"]
    assert {"ph_residual", "level_residual_cm", "ratio", "worst_ratio", "limit"} <= set(monitor)


def test_messages_arrive_while_the_graph_runs_with_plausible_values(live_run):
    got = live_run["got"]
    for topic in CHANNELS - {"/fault_alarm"}:
        assert len(got[topic]) >= ENOUGH, (topic, len(got[topic]), live_run["err"])
    assert got["/fault_alarm"], live_run["err"]
    for topic, items in got.items():
        assert any(running for _, _, running in items), f"{topic}: nothing received while the launch ran"
        for log_time_ns, data, _ in items:  # stamped with the simulated time of their sample
            assert log_time_ns == round(data["time_s"] * 1e9) and 0.0 <= data["time_s"] <= 600.0
    for _, m, _ in got["/plant/measurement"]:
        assert 0.0 < m["ph"] < 14.0 and 0.0 < m["level_cm"] < 100.0
    for _, c, _ in got["/controller/output"]:
        assert c["ph_setpoint"] in (12.0, 8.0) and -2.5 <= c["ph_output_pct"] <= 106.25
    for _, v, _ in got["/valve/state"]:  # backlash 0.7 % of span from 300 s: the stem lags by at most half of it
        assert -2.5 <= v["ph_command_pct"] <= 106.25
        assert abs(v["ph_position_pct"] - v["ph_command_pct"]) <= 0.35 + 1e-9
    for _, d, _ in got["/detector/monitor"]:
        assert set(d["ratio"]) == STATISTICS and d["limit"] == 1.0
        assert all(r is not None and 0.0 <= r < 10.0 for r in d["ratio"].values())
        assert d["worst_ratio"] == max(d["ratio"].values())
        assert abs(d["ph_residual"]) < 1.0 and d.get("level_residual_cm") is None  # the pH is watched alone
    for _, a, _ in got["/fault_alarm"]:
        assert live_view.ALARM_STATES[a["state"]] == a["state_name"]
        assert a["threshold"] > 0 and math.isclose(a["ratio"], a["statistic"] / a["threshold"])


def test_the_view_carries_the_recorded_values(live_run):
    """What the client got is what the graph published: the bag's values at the same stamps."""
    run = bagio.load_run(live_run["bag"])
    by_time = {round(t * 1e9): i for i, t in enumerate(run.time_s)}
    for _, m, _ in live_run["got"]["/plant/measurement"]:
        i = by_time[round(m["time_s"] * 1e9)]
        assert m["ph"] == run["ph_measured"][i] and m["level_cm"] == run["level_measured_cm"][i]
    for _, v, _ in live_run["got"]["/valve/state"]:
        i = by_time[round(v["time_s"] * 1e9)]
        assert v["ph_command_pct"] == run["valve_command_pct"][i]
        assert v["ph_position_pct"] == run["valve_position_pct"][i]


def test_the_launch_ends_cleanly_and_its_bag_is_unchanged_by_the_view(live_run):
    proc = live_run["proc"]
    assert proc.returncode == 0, live_run["err"]
    summary = json.loads(live_run["out"])
    assert summary["failure"] is None and summary["samples"] == summary["of"] == 601
    counts = summary["bag"]["counts"]
    assert set(counts) == {t.name for t in T.RECORDED}  # /detector/monitor is not recorded
    assert all(counts[t.name] == 601 for t in T.RECORDED if t.per_sample)
    expected = simulate(load_scenario("paper", overrides=SHORT_OVERRIDES))
    got = bagio.load_run(live_run["bag"])
    for name in expected.names:
        diff = np.abs(got[name] - expected[name])
        assert np.all((diff <= 1e-9) | (np.isnan(got[name]) & np.isnan(expected[name]))), name


def test_the_old_subprotocol_name_is_refused_by_foxglove_sdk():
    """Why the client says foxglove.sdk.v1: foxglove-sdk answers foxglove.websocket.v1 alone with HTTP 400."""
    view = live_view.LiveView(port=0)
    try:
        with pytest.raises(InvalidStatus), connect(f"ws://127.0.0.1:{view.port}",
                                                   subprotocols=["foxglove.websocket.v1"], open_timeout=10):
            pass
    finally:
        view.stop()


def _listening_socket() -> tuple[socket.socket, int]:
    s = socket.create_server(("127.0.0.1", 0))
    return s, s.getsockname()[1]


def test_a_port_in_use_stops_the_launch_with_one_line_before_any_node_starts():
    taken, port = _listening_socket()
    with taken:
        proc = subprocess.run(phfdi_cmd("launch", *SHORT_RUN, "--detector", "--foxglove", str(port)),
                              capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2, proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert f"--foxglove {port}" in lines[0] and "already in use" in lines[0]


def test_the_live_view_alone_serves_its_channels_and_refuses_a_taken_port_with_one_line(ros_env):
    """The live view's bridge started alone (beside a graph or a detector node of one's own, as the physics
    detector's node once served its own view): it serves the graph's channels, and a second one asking for the
    same port is refused in one line while the first runs on."""
    port = free_port()
    proc = subprocess.Popen(node_cmd("phfdi.ros.live_bridge", graph_nodes="[foxglove]", port=str(port)),
                            env=ros_env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        client = _connect_when_up(port, proc, timeout_s=120)
        topics = {c["topic"] for c in client.channels.values()}
        client.close()
        assert topics == CHANNELS
        second = subprocess.run(node_cmd("phfdi.ros.live_bridge", graph_nodes="[foxglove]", port=str(port)),
                                env=ros_env, capture_output=True, text=True, timeout=120)
        assert second.returncode == 2, second.stderr
        lines = [ln for ln in second.stderr.splitlines() if ln.strip()]
        assert len(lines) == 1 and "already in use" in lines[0], second.stderr
        assert proc.poll() is None  # the running one is untouched
    finally:
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=60)
    assert proc.returncode == 0, proc.stderr.read()


def _connect_when_up(port: int, proc: subprocess.Popen, timeout_s: float) -> FoxgloveClient:
    deadline = time.monotonic() + timeout_s
    while True:
        assert proc.poll() is None, proc.stderr.read()
        try:
            return FoxgloveClient(port)
        except OSError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.2)
