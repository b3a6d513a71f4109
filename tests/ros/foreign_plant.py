"""A stand-in for a plant that is not ours (run as its own process by tests/ros/test_foreign_topics.py).

    python -m tests.ros.foreign_plant DOMAIN_ID SPEC.json

SPEC.json: ``{"topics": [...], "rows": [[...], ...], "pace_hz": 0, "float32": [...]}``. Publishes each column of
the rows as std_msgs/Float64 (std_msgs/Float32 on the topics listed in ``float32``) on its own topic (no header,
no stamp: what a plant's driver often does), row after row: with ``pace_hz`` 0 as fast as its readers take them
(reliable, keep all: a writer waits for a reader that falls behind, nothing is lost, each topic keeps its order),
else at that many rows per second of wall time (``wait_samples``: then until the node's /diagnostics say it has
put that many samples on its grid). It listens to /fault_alarm meanwhile. Prints one JSON line
``{"event": "published", ...}`` when every row is acknowledged, then keeps listening until SIGTERM and prints
``{"event": "alarms", "received": [...], "diagnostics": [...]}`` with every /fault_alarm it received and every
``detector: channel map`` status of /diagnostics (level, message, values).

With ``"stamped": {"t0_ns": T0, "dt_ns": DT, "topics": [{"topic", "type", "field", "columns", "names"}, ...]}`` it
publishes stamped messages instead, row k stamped T0 + k * DT (T0 + ``stamps_ns[k]`` when given:
a record's own times): sensor_msgs/FluidPressure or Temperature (header,
``field`` = column ``columns[0]``) or phfdi_interfaces/MeasuredSample (its stamp; ``names`` = ``columns``).
"""

from __future__ import annotations

import json
import signal
import sys
import time

#: a reader that takes longer than this to acknowledge the last row has stopped: the plant gives up
ACK_TIMEOUT_S = 120.0


def main(domain_id: int, spec_path: str) -> int:
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from phfdi_interfaces.msg import FaultAlarm, MeasuredSample
    from rclpy.duration import Duration
    from rclpy.signals import SignalHandlerOptions
    from std_msgs.msg import Float32, Float64

    from phfdi_base.ros.env import ensure_localhost
    from phfdi_base.ros.graph_node import DATA_QOS
    from phfdi_base.stamps import time_ns

    spec = json.loads(open(spec_path).read())
    ensure_localhost()
    stop: list[int] = []
    signal.signal(signal.SIGTERM, lambda signum, _frame: stop.append(signum))
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain_id, signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node("foreign_plant", context=context)
    executor = rclpy.executors.SingleThreadedExecutor(context=context)
    executor.add_node(node)
    float32 = set(spec.get("float32", []))
    senders = stamped_senders(node, spec["stamped"]) if "stamped" in spec else [
        (node.create_publisher(t, topic, DATA_QOS), lambda row, k, i=i, t=t: t(data=float(row[i])))
        for i, (topic, t) in enumerate((topic, Float32 if topic in float32 else Float64) for topic in spec["topics"])]
    pubs = [pub for pub, _ in senders]
    received: list[dict] = []
    diagnostics: list[dict] = []
    ranges: list[dict] = []  # the node's "healthy range" statuses

    def on_diagnostics(m: DiagnosticArray) -> None:
        for s in m.status:
            d = {"level": int.from_bytes(s.level, "little") if isinstance(s.level, bytes) else int(s.level),
                 "message": s.message, "values": {v.key: v.value for v in s.values}}
            if s.name.endswith("channel map"):
                diagnostics.append(d)
            elif s.name.endswith("healthy range"):
                ranges.append(d)

    def on_alarm(m: FaultAlarm) -> None:
        received.append({"state": int(m.state), "stamp_ns": time_ns(m.stamp), "detection_ns": time_ns(m.detection_time),
                         "onset_ns": time_ns(m.onset_time), "statistic": m.statistic, "threshold": m.threshold,
                         "statistic_name": m.statistic_name,
                         "channels": list(m.channels), "channel_shares": list(m.channel_shares),
                         "channel_bands": list(m.channel_bands), "fault_class": m.fault_class,
                         "severity": m.severity, "message": m.message})

    monitor: list[dict] = []  # /detector/monitor, when the node publishes it

    def on_monitor(m: MeasuredSample) -> None:
        monitor.append({"stamp_ns": time_ns(m.stamp), **dict(zip(m.names, m.values))})

    node.create_subscription(FaultAlarm, "/fault_alarm", on_alarm, DATA_QOS)
    node.create_subscription(MeasuredSample, "/detector/monitor", on_monitor, DATA_QOS)
    node.create_subscription(DiagnosticArray, "/diagnostics", on_diagnostics, DATA_QOS)
    deadline = time.monotonic() + 120.0
    # a topic published as another type than the detector reads is never matched: wait for the others
    while any(p.get_subscription_count() < 1 for p in pubs if p.topic_name not in float32):
        if time.monotonic() > deadline or stop:
            print(json.dumps({"error": "no reader on " + ", ".join(
                p.topic_name for p in pubs if p.get_subscription_count() < 1)}), flush=True)
            return 1
        executor.spin_once(timeout_sec=0.05)
    pace_hz = float(spec.get("pace_hz", 0))
    t0 = time.monotonic()
    for k, row in enumerate(spec["rows"]):
        if stop:
            break
        if pace_hz > 0:
            while time.monotonic() < t0 + k / pace_hz:
                executor.spin_once(timeout_sec=max(0.0, min(0.05, t0 + k / pace_hz - time.monotonic())))
        for pub, build in senders:
            pub.publish(build(row, k))
        executor.spin_once(timeout_sec=0.0)
    acked = all(p.wait_for_all_acked(Duration(seconds=ACK_TIMEOUT_S)) for p in pubs)
    wall_s = time.monotonic() - t0
    # acknowledged is in the node's reader, not yet taken: with wait_samples, wait until the node's /diagnostics
    # says it has put that many samples on its grid (its stop then has nothing left in its readers to take)
    deadline = time.monotonic() + ACK_TIMEOUT_S
    while (spec.get("wait_samples") and not stop and time.monotonic() < deadline
           and int(diagnostics[-1]["values"]["samples"] if diagnostics else 0) < spec["wait_samples"]):
        executor.spin_once(timeout_sec=0.1)
    node_samples = int(diagnostics[-1]["values"]["samples"]) if diagnostics else None
    print(json.dumps({"event": "published", "rows": len(spec["rows"]), "topics": len(pubs), "acked": acked,
                      "wall_s": round(wall_s, 3), "node_samples": node_samples}), flush=True)
    while not stop:
        executor.spin_once(timeout_sec=0.1)
    deadline = time.monotonic() + 2.0  # what the readers already hold
    while time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
    print(json.dumps({"event": "alarms", "received": received, "diagnostics": diagnostics,
                      "healthy_range": ranges, "monitor": monitor}), flush=True)
    node.destroy_node()
    executor.shutdown()
    rclpy.try_shutdown(context=context)
    context.destroy()
    return 0


def stamped_senders(node, stamped: dict) -> list:
    """(publisher, build(row, k)) of stamped messages: row k stamped t0_ns + k * dt_ns."""
    from phfdi_interfaces.msg import MeasuredSample
    from sensor_msgs.msg import FluidPressure, Temperature

    from phfdi_base.ros.graph_node import DATA_QOS, to_time

    t0_ns, dt_ns = int(stamped["t0_ns"]), int(stamped["dt_ns"])
    stamps = stamped.get("stamps_ns")  # row k's own stamp (a record's times, gaps included), else on the grid

    def stamp_of(k: int):
        return to_time(t0_ns + (stamps[k] if stamps else k * dt_ns))

    senders = []
    for t in stamped["topics"]:
        cols = t["columns"]
        if t["type"] == "phfdi_interfaces/msg/MeasuredSample":
            def build(row, k, cols=cols, names=t["names"]):
                return MeasuredSample(stamp=stamp_of(k), names=names,
                                      values=[float(row[c]) for c in cols])
            mtype = MeasuredSample
        else:
            mtype = {"sensor_msgs/msg/FluidPressure": FluidPressure, "sensor_msgs/msg/Temperature": Temperature}[t["type"]]

            def build(row, k, cols=cols, mtype=mtype, field=t["field"]):
                msg = mtype()
                msg.header.stamp = stamp_of(k)
                setattr(msg, field, float(row[cols[0]]))
                return msg
        senders.append((node.create_publisher(mtype, t["topic"], DATA_QOS), build))
    return senders


if __name__ == "__main__":
    sys.exit(main(int(sys.argv[1]), sys.argv[2]))
