"""The detector node alone, fed garbage over ROS by this test: it reports it on /diagnostics and keeps running."""

from __future__ import annotations

import json
import math
import signal
import subprocess
import sys
import time

import pytest

from phfdi_base import topics as T

from ..ros.conftest import close_context
from .conftest import ROOT, node_cmd, stop

pytestmark = [pytest.mark.ros, pytest.mark.timeout(300)]


class _Feeder:
    """This test's own node: publishes measurements and controller outputs, collects what the detector says."""

    def __init__(self, context, detector: subprocess.Popen) -> None:
        from diagnostic_msgs.msg import DiagnosticArray
        from phfdi_interfaces.msg import ControllerOutput, FaultAlarm, Measurement
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.node import Node

        from phfdi_base.ros.graph_node import DATA_QOS

        self.detector = detector
        self.node = Node("garbage_feeder", context=context)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self.pub_m = self.node.create_publisher(Measurement, T.MEASUREMENT.name, DATA_QOS)
        self.pub_o = self.node.create_publisher(ControllerOutput, T.CONTROLLER.name, DATA_QOS)
        self.alarms: list = []
        self.inputs: list[dict] = []  # the detector's input status, key -> value, as published
        self.messages: list[str] = []  # the same status's message
        self.levels: list[int] = []
        self.node.create_subscription(FaultAlarm, T.FAULT_ALARM.name, self.alarms.append, DATA_QOS)
        self.node.create_subscription(DiagnosticArray, T.DIAGNOSTICS.name, self._on_diagnostics, DATA_QOS)
        self.Measurement, self.ControllerOutput = Measurement, ControllerOutput

    def _on_diagnostics(self, msg) -> None:
        for s in msg.status:
            if s.name == "detector: ph loop inputs":
                self.inputs.append({kv.key: kv.value for kv in s.values})
                self.messages.append(s.message)
                self.levels.append(int.from_bytes(s.level, "little") if isinstance(s.level, bytes) else s.level)

    def spin_until(self, condition, timeout_s: float = 60.0) -> None:
        deadline = time.monotonic() + timeout_s
        while not condition():
            assert self.detector.poll() is None, f"the detector node exited: {self.detector.communicate()[1]}"
            assert time.monotonic() < deadline, "timed out waiting for the detector node"
            self.executor.spin_once(timeout_sec=0.05)

    def measurement(self, sec: int, ph: float, level_cm: float = 30.0, nanosec: int = 0) -> None:
        msg = self.Measurement(ph=ph, level_cm=level_cm)
        msg.stamp.sec, msg.stamp.nanosec = sec, nanosec
        self.pub_m.publish(msg)

    def output(self, sec: int, ph_pct: float = 40.0, level_pct: float = 50.0) -> None:
        msg = self.ControllerOutput(ph_setpoint=8.0, ph_output_pct=ph_pct, level_setpoint_cm=30.0,
                                    level_output_pct=level_pct)
        msg.stamp.sec = sec
        self.pub_o.publish(msg)

    def sample(self, k: int, ph: float = 8.0) -> None:
        self.measurement(k, ph)
        self.output(k)

    def counter(self, key: str) -> int:
        return int(self.inputs[-1][key]) if self.inputs else 0


@pytest.fixture
def detector(ros_env, tmp_path):
    """The detector node and the example subscriber (examples/print_fault_alarm.py) on the test's domain."""
    node = subprocess.Popen(node_cmd("wavelet_fdi.node", graph_nodes="[detector]", heartbeat_period_s="10.0",
                                     diagnostics_period_s="1.0", pairing_timeout_s="0.3"),
                            env=ros_env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    example = subprocess.Popen([sys.executable, str(ROOT / "examples" / "print_fault_alarm.py")], env=ros_env,
                               stdout=open(tmp_path / "example.out", "w"), stderr=subprocess.STDOUT)
    yield node, example, tmp_path / "example.out"
    stop(example)
    stop(node)


@pytest.fixture
def feeder(detector, ros_domain):
    import rclpy

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=ros_domain)
    f = _Feeder(context, detector[0])
    # both directions matched (reliable delivery from the first sample), the example subscribed too
    f.spin_until(lambda: f.pub_m.get_subscription_count() >= 1 and f.pub_o.get_subscription_count() >= 1
                 and f.node.count_publishers(T.FAULT_ALARM.name) >= 1
                 and f.node.count_subscribers(T.FAULT_ALARM.name) >= 2, timeout_s=120)
    yield f
    close_context(context, f.node, f.executor)


def test_garbage_is_counted_reported_and_survived(detector, feeder):
    node, example, example_out = detector
    for k in range(60):
        feeder.sample(k)
    feeder.spin_until(lambda: feeder.counter("samples_used") == 60)
    assert feeder.counter("nonfinite_ph") == 0 and feeder.levels[-1] == 0  # clean so far: OK
    # the example's subscription may match the detector's writer later than ours did (reliable, volatile:
    # nothing published before is delivered): clean samples until it printed a heartbeat
    b = 60
    while not example_out.read_text().strip():
        assert b < 600, "the example subscriber received nothing"
        feeder.sample(b)
        b += 1
        feeder.spin_until(lambda: feeder.counter("samples_used") >= b - 1)

    feeder.sample(b, ph=math.nan)
    feeder.sample(b + 1, ph=math.inf)
    feeder.sample(b + 2, ph=-40.0)  # outside any pH scale
    feeder.sample(b + 2)  # the same stamp again
    feeder.sample(30)  # back in time
    feeder.sample(b + 3)
    feeder.measurement(b + 3, 8.0, nanosec=400_000_000)  # off the grid, on a slot already filled (a faster rate)
    feeder.output(b + 4, ph_pct=math.nan, level_pct=math.inf)  # commands that are not numbers
    feeder.measurement(b + 4, 8.0)
    for k in range(b + 5, b + 30):  # the controller-output topic falls silent
        feeder.measurement(k, 8.0)
    # b + 4 with NaN commands, b + 5 .. b + 28 without any (b + 29 waits for a later measurement)
    feeder.spin_until(lambda: feeder.counter("nonfinite_command") >= 25)
    counts = feeder.inputs[-1]
    assert int(counts["nonfinite_ph"]) == 2 and int(counts["out_of_range_ph"]) == 1
    # missing pH is held, not fed as a number, and /diagnostics says so in words
    assert int(counts["ph_samples_held"]) == 3
    assert "3 pH samples missing or out of range: held (no residual; statistics not fed)" in feeder.messages[-1]
    assert int(counts["duplicate_stamps"]) == 1 and int(counts["out_of_order"]) == 1
    assert int(counts["extra_samples"]) == 1
    assert int(counts["nonfinite_command"]) == 25 and int(counts["nonfinite_outlet_command"]) == 1
    assert int(counts["commands_missing"]) >= 24
    assert int(counts["command_stale_episodes"]) == 1 and counts["command_stale"] == "True"
    assert 1 in feeder.levels[-3:]  # WARN
    held = [a for a in feeder.alarms if "valve command missing" in a.message]
    assert held and held[0].state == 1  # WARN on /fault_alarm

    for k in range(b + 30, b + 60):  # commands come back
        feeder.sample(k)
    feeder.spin_until(lambda: feeder.counter("samples_used") >= b + 52)
    assert feeder.inputs[-1]["command_stale"] == "False"
    assert any("valve command back" in a.message for a in feeder.alarms)
    assert node.poll() is None  # still running

    node.send_signal(signal.SIGTERM)
    out, err = node.communicate(timeout=60)
    assert node.returncode == 0, err
    assert "Traceback" not in err
    done = [json.loads(line) for line in out.splitlines() if '"detector_done"' in line]
    assert done and done[0]["samples"] >= b + 52 and done[0]["diagnostics"]["nonfinite_ph"] == 2
    stop(example)
    printed = example_out.read_text()
    assert "WARN ph: valve command missing too long" in printed


def test_window_resets_go_out_on_fault_alarm_at_most_once_a_second(detector, feeder):
    """Thirty real gaps in the stamps in well under a second of wall time: each restarts the window (counted
    exactly), and /fault_alarm carries them in at most one message per ``input_problem_period_s`` (1 s) of wall
    time plus the last one on the way out, each with the counts so far."""
    node, _, _ = detector
    k = 0
    for k in range(60):
        feeder.sample(k)
    feeder.spin_until(lambda: feeder.counter("samples_used") == 60)
    t0 = time.monotonic()
    for _ in range(30):  # a jump of 20 samples (over max_gap), then two samples on the new stretch
        k += 20
        feeder.sample(k)
        feeder.sample(k + 1)
        k += 1
    # the last of them goes out when due, with nothing following (the node pokes itself)
    feeder.spin_until(lambda: any("gap_resets 30" in a.message for a in feeder.alarms), timeout_s=30)
    wall_s = time.monotonic() - t0
    resets = [a for a in feeder.alarms if "window reset" in a.message]
    assert 1 <= len(resets) <= math.ceil(wall_s / 1.0) + 1, ([a.message for a in resets], wall_s)
    assert len(resets) < 30 and any("events since the last report" in a.message for a in resets)
    assert all(a.state == 1 for a in resets)  # WARN: no alarm was up
    assert feeder.counter("gap_resets") == 30 and node.poll() is None
