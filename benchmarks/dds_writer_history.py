"""Memory of a reliable keep-all writer whose reader lags: a high-water mark, or growth?

Explains the steps in the loop nodes' memory in benchmarks/soak.py. A publisher
process sends phfdi_interfaces/PlantState every millisecond (reliable, keep
all, as every data topic of the graph) to a reader process; the reader is
stopped with SIGSTOP for 1, 1, 3, 3 and 6 s (what a loaded machine does to a
process), and the publisher's RssAnon is printed after each stall. A writer
holds every sample its reader has not acknowledged; if its memory only follows
the longest stall so far, equal stalls add nothing.

    .venv/bin/python benchmarks/dds_writer_history.py
    .venv/bin/python benchmarks/dds_writer_history.py --stalls 2 2 4 --period-ms 0.5
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import time
from pathlib import Path


def anon_kb(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("RssAnon"):
            return int(line.split()[1])
    raise RuntimeError(f"no RssAnon for pid {pid}")


def child(role: str, period_s: float) -> int:
    from phfdi_base.ros.env import ensure_localhost

    ensure_localhost()
    import rclpy
    from phfdi_interfaces.msg import PlantState
    from rclpy.experimental import EventsExecutor
    from rclpy.signals import SignalHandlerOptions

    from phfdi_base.ros.graph_node import DATA_QOS

    stop: list[int] = []
    signal.signal(signal.SIGTERM, lambda signum, _frame: stop.append(signum))
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node(f"history_{role}")
    try:
        if role == "pub":
            pub = node.create_publisher(PlantState, "/history_test", DATA_QOS)
            while pub.get_subscription_count() == 0 and not stop:
                time.sleep(0.05)
            print("matched", flush=True)
            msg = PlantState(feed_names=["acid", "base", "buffer"], feed_flows_ml_s=[1.0, 2.0, 3.0])
            k = 0
            while not stop:
                msg.stamp.sec = k
                pub.publish(msg)
                k += 1
                time.sleep(period_s)
            return 0
        node.create_subscription(PlantState, "/history_test", lambda m: None, DATA_QOS)
        executor = EventsExecutor()
        executor.add_node(node)
        while not stop:
            executor.spin_once(timeout_sec=0.1)
        return 0
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--stalls", type=float, nargs="+", default=[1, 1, 3, 3, 6], help="reader stalls (s)")
    ap.add_argument("--period-ms", type=float, default=1.0, help="publishing period (ms)")
    ap.add_argument("--role", choices=("pub", "sub"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.role:
        return child(args.role, args.period_ms / 1000)

    from phfdi_base.ros.env import graph_env, reserve_domain_id

    with reserve_domain_id() as lease:
        env = graph_env(lease.domain_id)
        cmd = [sys.executable, __file__, "--period-ms", str(args.period_ms), "--role"]
        reader = subprocess.Popen(cmd + ["sub"], env=env)
        writer = subprocess.Popen(cmd + ["pub"], env=env, stdout=subprocess.PIPE, text=True)
        try:
            if writer.stdout.readline().strip() != "matched":
                print("the publisher did not start", file=sys.stderr)
                return 1
            time.sleep(5)
            base = anon_kb(writer.pid)
            print(f"ROS domain {lease.domain_id}; publisher RssAnon after 5 s steady: {base} kB")
            for stall in args.stalls:
                before = anon_kb(writer.pid)
                os.kill(reader.pid, signal.SIGSTOP)
                time.sleep(stall)
                os.kill(reader.pid, signal.SIGCONT)
                time.sleep(4)
                after = anon_kb(writer.pid)
                print(f"reader stalled {stall:g} s: publisher RssAnon {after} kB ({(after - before) / 1024:+.2f} MiB; "
                      f"{(after - base) / 1024:+.2f} MiB since the start)", flush=True)
        finally:
            for p in (writer, reader):
                if p.poll() is None:
                    os.kill(p.pid, signal.SIGCONT)
                    p.terminate()
            for p in (writer, reader):
                try:
                    p.wait(10)
                except subprocess.TimeoutExpired:
                    p.kill()
                    p.wait()
    return 0


if __name__ == "__main__":
    sys.exit(main())
