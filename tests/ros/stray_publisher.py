"""A stray writer on a running graph's domain (run as its own process by tests/ros/test_stray_messages.py).

    python -m tests.ros.stray_publisher DOMAIN_ID N_SAMPLES ROUNDS BURST_CYCLES

Publishes, on /plant/measurement, /controller/output and /valve/state, messages with stamps that can never be
the next sample of the ring: from the future beyond the run's end, from the past, off the sample grid and
invalid. Every stray carries the payload MARK, so the test can tell it from the graph's own messages in the bag.
Then a burst of stamp garbage for the detector (a far-future stamp, then 11 past ones: a window reset and a
clock reset in the detector's input stage per cycle). Prints one JSON line with what it published.
"""

from __future__ import annotations

import json
import sys
import time

#: the payload of every stray (no real pH, level, command or flow is this)
MARK = -77.0
#: the detector's clock-reset needs more than max_gap_s / dt (10) samples going back in a row
BACKWARDS_RUN = 11


def main(domain_id: int, n_samples: int, rounds: int, burst_cycles: int) -> int:
    import rclpy
    from phfdi_interfaces.msg import ControllerOutput, Measurement, ValveState
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from phfdi_base.ros.env import ensure_localhost
    from phfdi_base.ros.graph_node import DATA_QOS
    from phfdi_base.topics import CONTROLLER, MEASUREMENT, VALVE_STATE

    ensure_localhost()
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain_id)
    node = rclpy.create_node("stray_publisher", context=context)
    executor = rclpy.executors.SingleThreadedExecutor(context=context)
    executor.add_node(node)
    types = {MEASUREMENT.name: Measurement, CONTROLLER.name: ControllerOutput, VALVE_STATE.name: ValveState}
    pubs = {topic: node.create_publisher(t, topic, DATA_QOS) for topic, t in types.items()}
    # readers that must have matched before a stray is sure to reach them: the ring node that takes the topic, the
    # detector and the recorder (/valve/state: the plant and the recorder), and on /plant/measurement this process's
    # own sample watcher below, which the count includes (counting 3 there let the first round out before the
    # controllers had matched, once in a full suite: they counted 5 of the 6 rounds)
    readers = {MEASUREMENT.name: 4, CONTROLLER.name: 3, VALVE_STATE.name: 2}
    seen = [-1]  # the newest sample the plant published (best effort: never holds the plant's writer up)
    node.create_subscription(Measurement, MEASUREMENT.name, lambda m: seen.__setitem__(0, max(seen[0], m.stamp.sec)),
                             QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT))
    deadline = time.monotonic() + 60.0
    while (any(p.get_subscription_count() < readers[t] for t, p in pubs.items()) or seen[0] < 10):
        if time.monotonic() > deadline:
            print(json.dumps({"error": "not matched", "seen": seen[0],
                              "readers": {t: p.get_subscription_count() for t, p in pubs.items()}}), flush=True)
            return 1
        executor.spin_once(timeout_sec=0.05)
    published = {t: 0 for t in pubs}

    def send(topic: str, sec: int, nanosec: int = 0) -> None:
        msg = types[topic]()
        msg.stamp.sec, msg.stamp.nanosec = sec, nanosec
        if topic == MEASUREMENT.name:
            msg.ph, msg.level_cm = MARK, MARK
        elif topic == CONTROLLER.name:
            msg.ph_output_pct, msg.level_output_pct, msg.ph_setpoint = MARK, MARK, MARK
        else:
            msg.ph_flow_ml_s, msg.ph_position_pct, msg.ph_command_pct = MARK, MARK, MARK
        pubs[topic].publish(msg)
        published[topic] += 1

    first_seen = seen[0]
    before_zero = dict.fromkeys(pubs, 0)
    for r in range(rounds):
        executor.spin_once(timeout_sec=0.0)
        k = seen[0]  # every ring node has taken k - 1 by now: k - 5 is behind all of them
        for topic in pubs:
            send(topic, n_samples + 1 + r)  # the future, beyond the run's end: never the next sample
            send(topic, k - 5)  # the past
            send(topic, k, 500_000_000)  # off the grid (dt = 1 s)
            send(topic, k, 1_500_000_000)  # invalid: nanoseconds not below 1e9 (joined, on the grid)
            send(topic, k + 1, 2_000_000_000)  # invalid, and joined the ring's next sample or later
            send(topic, -3)  # invalid: before time 0 (no place in a bag either: the recorder leaves it out)
            before_zero[topic] += 1
        time.sleep(0.25)
    k = seen[0]
    for c in range(burst_cycles):  # stamp garbage for the detector (and the controllers and valve)
        for topic in (MEASUREMENT.name, CONTROLLER.name):
            send(topic, 10 * n_samples + 1000 * c)
            for _ in range(BACKWARDS_RUN):
                send(topic, max(k - 5, 0))
    acked = all(p.wait_for_all_acked(rclpy.duration.Duration(seconds=10.0)) for p in pubs.values())
    print(json.dumps({"published": published, "before_zero": before_zero, "acked": acked, "first_seen": first_seen,
                      "last_seen": seen[0]}),
          flush=True)
    node.destroy_node()
    executor.shutdown()
    rclpy.try_shutdown(context=context)
    context.destroy()
    return 0


if __name__ == "__main__":
    sys.exit(main(*(int(a) for a in sys.argv[1:5])))
