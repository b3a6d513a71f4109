"""The detector node against a 100 Hz measurement stream: does it keep up, and how late are its results?

    .venv/bin/python benchmarks/detector_node.py                 # 60 s at 100 Hz (about 75 s)
    .venv/bin/python benchmarks/detector_node.py --rate 200 --seconds 30

Starts the detector node as the loop graph runs it (python -m wavelet_fdi.learned_node, its own process, the
shipped physics reference paper_physics on the graph's own topics) on a ROS domain of its own with LOCALHOST
discovery, and publishes from this process /plant/measurement and /controller/output at the given wall rate: the
samples of a simulated paper run (pH 8 from 200 s) with a backlash fault (so one alarm and its naming, which fits the
physics detector's fault models, fall inside the measurement window). Prints (no pass/fail; the lead re-measures on
a quiet machine):

* backlog: samples published minus samples the detector's core processed (its heartbeat, once per second of
  simulated time, says how many), over the run; a sample goes onto the node's grid once the next one arrived
  (the channel map's hold rule), so one sample of backlog is the rule;
* alarm latency: publication of the sample that raised the alarm to the /fault_alarm message reaching this process;
* CPU of the node process (fraction of one core).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import signal
import subprocess
import sys
import threading
import time

from phfdi_base.ros.env import ensure_localhost, graph_env, reserve_domain_id

ensure_localhost()  # before rclpy starts DDS in this process


def _cpu_s(pid: int) -> float:
    fields = open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rate", type=float, default=100.0, help="samples per second of wall time (default 100)")
    ap.add_argument("--seconds", type=float, default=60.0, help="how long to publish (default 60)")
    ap.add_argument("--onset", type=float, default=2000.0, help="backlash onset (s of simulated time; after "
                                                                "the detector's 600 s warm-up)")
    args = ap.parse_args()
    n = int(args.rate * args.seconds)

    from phfdi.loop import simulate
    from phfdi.scenario import load_scenario

    spec = load_scenario("paper", fault="backlash", onset_s=args.onset,
                         overrides=[f"duration_s={n - 1}", "setpoints.ph.changes=[{at_s: 200, value: 8.0}]"])
    run = simulate(spec)
    print(f"python {platform.python_version()} on {platform.machine()}, {os.cpu_count()} cores, "
          f"load average {os.getloadavg()[0]:.1f}")
    print(f"stream: {n} samples of {spec.name} (backlash from {args.onset:g} s) at {args.rate:g} Hz wall "
          f"for {args.seconds:g} s")

    lease = reserve_domain_id()
    env = graph_env(lease.domain_id)
    params = {"reference": "paper_physics", "loop_graph_topics": "true", "loop": "ph", "scenario": "paper",
              "graph_nodes": "[detector]", "heartbeat_period_s": "1.0"}
    node = subprocess.Popen([sys.executable, "-m", "wavelet_fdi.learned_node", "--ros-args",
                             *(x for k, v in params.items() for x in ("-p", f"{k}:={v}"))],
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        return _measure(args, run, n, lease.domain_id, node)
    finally:
        if node.poll() is None:
            node.kill()
            node.wait()
        lease.release()


def _measure(args, run, n: int, domain_id: int, node: subprocess.Popen) -> int:
    import re

    import numpy as np
    import rclpy
    from phfdi_interfaces.msg import ControllerOutput, FaultAlarm, Measurement
    from rclpy.executors import SingleThreadedExecutor

    from phfdi_base.ros.graph_node import DATA_QOS

    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=domain_id)
    me = rclpy.create_node("stream_100hz", context=ctx)
    pub_m = me.create_publisher(Measurement, "/plant/measurement", DATA_QOS)
    pub_o = me.create_publisher(ControllerOutput, "/controller/output", DATA_QOS)
    processed: list[tuple[float, int]] = []  # (wall, samples the detector reported processed)
    alarm_at: list[float] = []
    published_at = np.full(n, np.nan)

    def on_alarm(msg) -> None:
        heartbeat = re.search(r"; (\d+) samples$", msg.message)  # the core's count, in each heartbeat
        if heartbeat:
            processed.append((time.monotonic(), int(heartbeat.group(1))))
        if msg.state == FaultAlarm.ALARM and not alarm_at:
            alarm_at.append(time.monotonic())
            alarm_at.append(msg.detection_time.sec)

    me.create_subscription(FaultAlarm, "/fault_alarm", on_alarm, DATA_QOS)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(me)
    spinning = threading.Event()
    spinning.set()

    def spin() -> None:
        while spinning.is_set():
            executor.spin_once(timeout_sec=0.05)

    thread = threading.Thread(target=spin, daemon=True)
    thread.start()
    t_wait = time.monotonic()
    while not (pub_m.get_subscription_count() and pub_o.get_subscription_count()
               and me.count_publishers("/fault_alarm")):
        if time.monotonic() - t_wait > 120 or node.poll() is not None:
            print("the detector node did not come up", file=sys.stderr)
            return 1
        time.sleep(0.05)
    time.sleep(1.0)  # both ends matched

    sig = {k: run[k] for k in ("ph_measured", "level_measured_cm", "ph_setpoint", "ph_controller_output_pct",
                               "level_controller_output_pct")}
    m, o = Measurement(), ControllerOutput()
    cpu0, wall0 = _cpu_s(node.pid), time.monotonic()
    period = 1.0 / args.rate
    late = 0
    backlog: list[tuple[float, int]] = []
    for k in range(n):
        due = wall0 + k * period
        delay = due - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        elif delay < -period:
            late += 1
        m.stamp.sec = o.stamp.sec = k
        m.ph, m.level_cm = float(sig["ph_measured"][k]), float(sig["level_measured_cm"][k])
        o.ph_setpoint, o.ph_output_pct = float(sig["ph_setpoint"][k]), float(sig["ph_controller_output_pct"][k])
        o.level_setpoint_cm, o.level_output_pct = 30.0, float(sig["level_controller_output_pct"][k])
        published_at[k] = time.monotonic()
        pub_m.publish(m)
        pub_o.publish(o)
        if processed and k % int(args.rate) == 0:
            backlog.append((time.monotonic() - wall0, k + 1 - processed[-1][1]))
    publish_s = time.monotonic() - wall0
    t_end = time.monotonic()
    while (not processed or processed[-1][1] < n - 1) and time.monotonic() - t_end < 60:
        time.sleep(0.05)
    drained_s = time.monotonic() - t_end
    cpu = _cpu_s(node.pid) - cpu0
    wall = time.monotonic() - wall0
    node.send_signal(signal.SIGTERM)
    out, _ = node.communicate(timeout=60)
    spinning.clear()
    thread.join()
    me.destroy_node()
    rclpy.try_shutdown(context=ctx)

    done = [json.loads(line) for line in out.splitlines() if '"detector_done"' in line]
    named = [a.get("isolation", {}).get("fault_class") for a in done[-1]["alarms"]] if done else []
    b = np.array([x for _, x in backlog]) if backlog else np.array([0])
    print(f"published {n} samples in {publish_s:.1f} s ({n / publish_s:.1f} Hz achieved; {late} sent more than "
          f"one period late)")
    print(f"backlog (published - processed, sampled once per second): median {np.median(b):.0f}, "
          f"max {b.max():.0f} samples; all processed {drained_s:.2f} s after the last publication")
    if alarm_at:
        k = int(alarm_at[1])
        print(f"alarm: detection at sample {k} (t = {k} s simulated, onset {args.onset:g} s); /fault_alarm "
              f"received {1e3 * (alarm_at[0] - published_at[k]):.0f} ms after that sample was published; "
              f"named {', '.join(str(c) for c in named) or 'nothing'}")
    else:
        print("alarm: none received")
    print(f"node CPU: {cpu:.1f} s over {wall:.1f} s = {100 * cpu / wall:.0f} % of one core "
          f"(both threads, DDS included)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
