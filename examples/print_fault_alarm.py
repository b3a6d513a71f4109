"""Subscribe to /fault_alarm and print every message: the smallest ROS 2 user of the detector.

Run it beside a graph that has the detector, on the graph's ROS domain, with
DDS kept on this machine:

    .venv/bin/phfdi launch --fault backlash --detector --domain-id 42 --pace 50 &
    ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST ROS_DOMAIN_ID=42 .venv/bin/python examples/print_fault_alarm.py

Prints one line per message: each state change, the naming of a fault, and the detector's heartbeat (every
60 s of simulated time). From the two commands above (2026-12-07, the default detector with the shipped physics
reference), among the heartbeats:

    [  7020.0 s] OK ph: OK: worst statistic ph_measured.R.mean_down 4.8 of threshold 11.9; 7021 samples
    [  7027.0 s] ALARM ph: alarm 1: ph_measured.R.mean_down crossed its threshold; channels: ph_measured 100%
    [  7080.0 s] ALARM ph: ALARM: worst statistic ph_measured.A3.aj_energy 6377.2 of threshold 162.7; 7081 samples
    [  7326.0 s] ALARM ph backlash (confidence 1.00) since 7000 s, severity 0.698 % of span: alarm 1 named: ...

(the last line goes on "actuator fault, backlash (0.6984 % of span)": the naming, 300 s after the detection).

The QoS matches the graph's data topics (reliable, keep all), so no message is
missed once the subscription has matched. Stop it with Ctrl-C.
"""

import os
import sys

if os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST") != "LOCALHOST":
    sys.exit("set ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST: the graph's DDS traffic stays on this machine")
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"  # before rclpy starts DDS

import rclpy  # noqa: E402
from phfdi_interfaces.msg import FaultAlarm  # noqa: E402
from rclpy.executors import ExternalShutdownException  # noqa: E402
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402

QOS = QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE,
                 durability=DurabilityPolicy.VOLATILE)
STATES = {FaultAlarm.OK: "OK", FaultAlarm.WARN: "WARN", FaultAlarm.ALARM: "ALARM"}


def seconds(t) -> float:
    return t.sec + t.nanosec * 1e-9


def describe(msg: FaultAlarm) -> str:
    head = f"[{seconds(msg.stamp):8.1f} s] {STATES.get(msg.state, msg.state)} {msg.loop}"
    if msg.state == FaultAlarm.ALARM and msg.fault_class not in ("", "pending"):
        head += (f" {msg.fault_class} (confidence {msg.confidence:.2f}) since {seconds(msg.onset_time):g} s, "
                 f"severity {msg.severity:.3g} {msg.severity_unit}")
    return f"{head}: {msg.message}"


def main() -> None:
    rclpy.init()
    node = rclpy.create_node("print_fault_alarm")
    node.create_subscription(FaultAlarm, "/fault_alarm", lambda msg: print(describe(msg), flush=True), QOS)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
