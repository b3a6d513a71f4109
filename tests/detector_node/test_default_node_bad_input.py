"""The loop graph's default detector node (the multichannel detector with the shipped physics reference, reading the
graph's own topics, as ``phfdi launch --detector`` starts it) alone, fed garbage over ROS by this test: each kind
of bad input is taken as missing or dropped and said, none raises an alarm, /fault_alarm stays bounded and returns to
OK when the inputs are whole again, and the node keeps running."""

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

#: the physics reference's warm-up after the valve command returns from a long gap (s, one sample per s)
WARMUP_S = 600
#: the healthy paper loop the feeder publishes, sample by sample (s); garbage replaces some of its values
RUN_S = 1600


@pytest.fixture(scope="module")
def healthy_run() -> dict[str, list[float]]:
    """A healthy paper run (the reference's own plant, its setpoint held): what the node is fed between the
    garbage, so that nothing but the garbage can move it."""
    from phfdi.loop import simulate
    from phfdi.scenario import load_scenario

    spec = load_scenario("paper", overrides=[f"duration_s={RUN_S}", "setpoints.ph.changes=[]", "seed=3"])
    run = simulate(spec)
    return {c: [float(v) for v in run[c]] for c in ("ph_measured", "level_measured_cm", "valve_command_pct",
                                                     "level_controller_output_pct", "ph_setpoint")}


class _Feeder:
    """This test's own node: publishes the loop graph's measurements and controller outputs, collects what the
    detector says on /fault_alarm and /diagnostics."""

    def __init__(self, context, detector: subprocess.Popen, run: dict[str, list[float]]) -> None:
        from diagnostic_msgs.msg import DiagnosticArray
        from phfdi_interfaces.msg import ControllerOutput, FaultAlarm, Measurement
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.node import Node

        from phfdi_base.ros.graph_node import DATA_QOS

        self.detector, self.run = detector, run
        self.node = Node("garbage_feeder", context=context)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self.pub_m = self.node.create_publisher(Measurement, T.MEASUREMENT.name, DATA_QOS)
        self.pub_o = self.node.create_publisher(ControllerOutput, T.CONTROLLER.name, DATA_QOS)
        self.alarms: list = []
        self.map_status: dict[str, str] = {}  # the detector's last 'channel map' status, key -> value
        self.node.create_subscription(FaultAlarm, T.FAULT_ALARM.name, self.alarms.append, DATA_QOS)
        self.node.create_subscription(DiagnosticArray, T.DIAGNOSTICS.name, self._on_diagnostics, DATA_QOS)
        self.Measurement, self.ControllerOutput = Measurement, ControllerOutput

    def _on_diagnostics(self, msg) -> None:
        for s in msg.status:
            if s.name.endswith("channel map"):
                self.map_status = {kv.key: kv.value for kv in s.values}

    def spin_until(self, condition, timeout_s: float = 60.0) -> None:
        deadline = time.monotonic() + timeout_s
        while not condition():
            assert self.detector.poll() is None, f"the detector node exited: {self.detector.communicate()[1]}"
            assert time.monotonic() < deadline, ("timed out waiting for the detector node", [a.message for a in self.alarms][-8:])
            self.executor.spin_once(timeout_sec=0.05)

    def measurement(self, sec: int, ph: float | None = None, nanosec: int = 0) -> None:
        """The run's measurement of second ``sec`` (its pH replaced by ``ph``)."""
        r = self.run
        msg = self.Measurement(ph=r["ph_measured"][sec] if ph is None else ph, level_cm=r["level_measured_cm"][sec])
        msg.stamp.sec, msg.stamp.nanosec = sec, nanosec
        self.pub_m.publish(msg)

    def output(self, sec: int, ph_pct: float | None = None, level_pct: float | None = None) -> None:
        """The run's controller output of second ``sec`` (its commands replaced where given)."""
        r = self.run
        msg = self.ControllerOutput(ph_setpoint=r["ph_setpoint"][sec],
                                    ph_output_pct=r["valve_command_pct"][sec] if ph_pct is None else ph_pct,
                                    level_setpoint_cm=0.0,
                                    level_output_pct=r["level_controller_output_pct"][sec] if level_pct is None
                                    else level_pct)
        msg.stamp.sec = sec
        self.pub_o.publish(msg)

    def sample(self, k: int, ph: float | None = None) -> None:
        self.measurement(k, ph)
        self.output(k)

    def samples_out(self) -> int:
        """Samples the detector put on its grid so far (its channel-map report)."""
        return int(self.map_status.get("samples", 0))

    def messages(self, text: str) -> list:
        return [a for a in self.alarms if text in a.message]


@pytest.fixture
def detector(ros_env, tmp_path):
    """The default detector node as the loop graph starts it, and the example subscriber, on the test's domain."""
    node = subprocess.Popen(node_cmd("wavelet_fdi.learned_node", reference="paper_physics", loop_graph_topics="true",
                                     scenario="paper", loop="ph", graph_nodes="[detector]", heartbeat_period_s="10.0",
                                     channel_map_report_period_s="0.2"),
                            env=ros_env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    example = subprocess.Popen([sys.executable, str(ROOT / "examples" / "print_fault_alarm.py")], env=ros_env,
                               stdout=open(tmp_path / "example.out", "w"), stderr=subprocess.STDOUT)
    yield node, example, tmp_path / "example.out"
    stop(example)
    stop(node)


@pytest.fixture
def feeder(detector, ros_domain, healthy_run):
    import rclpy

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=ros_domain)
    f = _Feeder(context, detector[0], healthy_run)
    f.spin_until(lambda: f.pub_m.get_subscription_count() >= 1 and f.pub_o.get_subscription_count() >= 1
                 and f.node.count_publishers(T.FAULT_ALARM.name) >= 1
                 and f.node.count_subscribers(T.FAULT_ALARM.name) >= 2, timeout_s=120)
    yield f
    close_context(context, f.node, f.executor)


def _finish(node: subprocess.Popen) -> dict:
    """SIGTERM; the node ends cleanly and its detector_done report."""
    node.send_signal(signal.SIGTERM)
    out, err = node.communicate(timeout=60)
    assert node.returncode == 0, err
    assert "Traceback" not in err, err
    done = [json.loads(line) for line in out.splitlines() if '"detector_done"' in line]
    assert done, out[-2000:]
    return done[0]


def test_garbage_is_taken_as_missing_said_and_survived(detector, feeder):
    node, example, example_out = detector
    for k in range(60):
        feeder.sample(k)
    feeder.spin_until(lambda: feeder.samples_out() >= 59)
    # the example's subscription may match the detector's writer later than ours did (reliable, volatile: nothing
    # published before is delivered): clean samples until it printed a heartbeat
    b = 60
    while not example_out.read_text().strip():
        assert b < 600, "the example subscriber received nothing"
        feeder.sample(b)
        b += 1
        feeder.spin_until(lambda: feeder.samples_out() >= b - 1)
    assert all(a.state == 0 for a in feeder.alarms), [a.message for a in feeder.alarms]  # clean so far: OK

    # unusable pH readings, one at a time: each taken as missing and said (an off-scale one with its value), then
    # back; each changes the state (OK to WARN and back), so each goes out at once, not held by the rate limit
    # (a sample goes out once a later one arrived: k + 2 lets k + 1 out)
    for k, bad, said in ((b, math.nan, "ph_measured: missing from"), (b + 3, math.inf, "ph_measured = inf: off"),
                         (b + 6, -40.0, "ph_measured = -40: off any plausible reading (-1 to 15)")):
        feeder.sample(k, ph=bad)
        feeder.sample(k + 1)
        feeder.sample(k + 2)
        feeder.spin_until(lambda: feeder.messages(said) and feeder.messages(f"back at {k + 1:g} s"))
        # WARN while it is missing (said alone), OK once back (the worker may take both samples in one batch)
        assert all(a.state == (0 if "back at" in a.message else 1) for a in feeder.messages(said))
        assert feeder.messages(f"back at {k + 1:g} s")[-1].state == 0
    b += 9
    feeder.sample(b)
    feeder.sample(b)  # the same stamp again
    feeder.sample(30)  # back in time
    feeder.measurement(b, nanosec=400_000_000)  # off the graph's sample grid
    feeder.output(b + 1, ph_pct=math.nan, level_pct=math.inf)  # commands that are not numbers
    feeder.measurement(b + 1)
    for k in range(b + 2, b + 30):  # the controller-output topic falls silent
        feeder.measurement(k)
    feeder.spin_until(lambda: feeder.messages("detection held"))
    held = feeder.messages("detection held")
    assert held[0].state == 1  # WARN on /fault_alarm while the valve command is missing

    for k in range(b + 30, b + 60):  # commands come back: the model restarts and warms up again
        feeder.sample(k)
    feeder.spin_until(lambda: feeder.samples_out() >= b + 58)
    # no change of state (WARN through the warm-up): it goes out when the rate limit lets it, at most 1 s later
    feeder.spin_until(lambda: feeder.messages("valve command back"), timeout_s=10)
    assert feeder.alarms[-1].state == 1  # still WARN: detection is held through the warm-up
    end = b + 60 + WARMUP_S + 30
    for k in range(b + 60, end):  # the warm-up ends: detection resumes, the state is OK again
        feeder.sample(k)
    feeder.spin_until(lambda: feeder.messages("detection resumed"), timeout_s=120)
    resumed = feeder.messages("detection resumed")[-1]
    assert resumed.state == 0, resumed.message
    feeder.spin_until(lambda: feeder.samples_out() >= end - 2, timeout_s=120)
    counts = feeder.map_status
    # the duplicate superseded, the one back in time late, the off-grid stamp dropped (per measured channel)
    assert "superseded 1," in counts["ph_measured counts"], counts["ph_measured counts"]
    assert "late 1," in counts["ph_measured counts"] and "off grid 1," in counts["ph_measured counts"]
    assert node.poll() is None  # still running

    report = _finish(node)
    assert report["alarms"] == [], report["alarms"]  # garbage is no fault
    assert report["samples"] >= end - 1
    stop(example)
    printed = example_out.read_text()
    assert "WARN ph: valve command missing for more than 10 s: detection held" in printed, printed[-3000:]


def test_gaps_go_out_on_fault_alarm_at_most_once_a_second(detector, feeder):
    """Thirty gaps in the stamps, each longer than the valve command's timeout, in well under a second of wall
    time: each holds detection and restarts the model (four input events a gap), and /fault_alarm carries them in
    at most one message per ``input_problem_period_s`` (1 s) of wall time, plus those that change the state, plus
    the last one on the way out."""
    node, _, _ = detector
    for k in range(60):
        feeder.sample(k)
    feeder.spin_until(lambda: feeder.samples_out() >= 59)
    before = len(feeder.alarms)
    t0 = time.monotonic()
    k = 59
    for _ in range(30):  # a jump of 20 samples (over the 10 s timeout), then two samples on the new stretch
        k += 20
        feeder.sample(k)
        feeder.sample(k + 1)
        k += 1
    feeder.spin_until(lambda: feeder.samples_out() >= k, timeout_s=30)
    # the held-back messages go out when due, with nothing following (the node pokes itself)
    feeder.spin_until(lambda: time.monotonic() - t0 >= 3.0, timeout_s=10)
    wall_s = time.monotonic() - t0
    inputs = [a for a in feeder.alarms[before:] if "valve command" in a.message]
    assert any("input events since the last report" in a.message for a in inputs), [a.message for a in inputs]
    # the first goes out at once (OK to WARN); after it the state stays WARN: at most one a second
    assert len(inputs) <= math.ceil(wall_s / 1.0) + 2, ([a.message for a in inputs], wall_s)
    assert all(a.state == 1 for a in inputs)  # WARN: no alarm was up
    assert node.poll() is None
    report = _finish(node)
    assert report["alarms"] == [], report["alarms"]
