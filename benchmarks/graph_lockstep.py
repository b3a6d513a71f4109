"""Benchmark: the paper scenario through the ROS 2 node graph in lock-step.

Runs the scenario once in-process (phfdi.loop.simulate) and once through the
graph (plant, controllers, valve and recorder as separate processes, started
by the launcher), and prints: the graph's wall time for the samples (sample 0
to the last, as the plant measured it; start-up reported apart), its
real-time factor, the ratio to the in-process run measured here, and per
topic the messages the nodes published against those in the bag (no loss).

    .venv/bin/python benchmarks/graph_lockstep.py                       # 10000 s paper scenario
    .venv/bin/python benchmarks/graph_lockstep.py --executor single_threaded
    .venv/bin/python benchmarks/graph_lockstep.py --duration 2000 --repeat 3
    .venv/bin/python benchmarks/graph_lockstep.py --detector --repeat 2   # + the fault detector node

With --detector each repetition runs the graph without and then with the
detector node (an observer): the wall times side by side, the slowest
twentieth of the run against the median one (an observer that stalled the
ring, e.g. during its 1-3 s isolation, would show there), and the detector's
processing lag. In the paper scenario the fault comes at 70 % of the run, the
isolation 300 s later: the twentieths from 65 to 80 % are printed.

Target: at least 1000 x real time through the graph (10000 s in under 10 s).
Timing depends on what else runs on the machine: quote numbers with their load.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="paper")
    ap.add_argument("--fault", default="backlash")
    ap.add_argument("--duration", type=float, default=None, help="override duration_s (s)")
    ap.add_argument("--executor", choices=("events", "single_threaded"), default="events")
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--no-record", action="store_true", help="run without the recorder")
    ap.add_argument("--detector", action="store_true", help="compare runs without and with the detector node")
    args = ap.parse_args()

    from phfdi.loop import simulate
    from phfdi.ros.launcher import Launcher, loop_graph
    from phfdi.scenario import load_scenario

    overrides = []
    if args.duration is not None:
        overrides.append(f"duration_s={args.duration}")
        if args.scenario == "paper" and args.duration <= 5000:
            overrides.append(f"setpoints.ph.changes.0.at_s={args.duration / 2}")
    onset = args.duration * 0.7 if args.duration is not None else None
    spec = load_scenario(args.scenario, fault=args.fault, overrides=overrides, onset_s=onset)
    t = time.perf_counter()
    simulate(spec)
    in_process_s = time.perf_counter() - t
    n = int(spec.duration_s / spec.sample_time_s + 1e-9) + 1
    print(f"scenario {spec.name}: {n} samples of {spec.sample_time_s:g} s ({spec.duration_s:g} s simulated)")
    print(f"in-process simulate:   {in_process_s:6.2f} s  = {spec.duration_s / in_process_s:8.0f} x real time")
    load = os.getloadavg()
    print(f"load average before the graph: {load[0]:.2f} (1 min) on {os.cpu_count()} cores")

    with tempfile.TemporaryDirectory(prefix="phfdi-bench-") as tmp:
        runs = [(i, d) for i in range(args.repeat) for d in ((None, {}) if args.detector else (None,))]
        for i, detector in runs:
            bag = None if args.no_record else Path(tmp) / f"bench{i}.mcap"
            nodes = loop_graph(args.scenario, args.fault, onset, overrides, bag, 0.0, args.executor,
                               detector=detector)
            steps: list[tuple[float, float]] = []  # (wall, fraction done): the plant's progress events
            result = Launcher(nodes, status=lambda s: None,
                              progress=lambda f: steps.append((time.monotonic(), f))).run()
            if detector is not None or args.detector:
                print(f"{'with' if detector is not None else 'without'} the detector node:")
                _print_detector(steps, result)
            if result.status != 0:
                print(f"graph run failed: {result.failure or result.notes}", file=sys.stderr)
                return 1
            print(f"graph ({args.executor}, {'no recorder' if bag is None else 'recorded'}): "
                  f"{result.run_wall_s:6.2f} s  = {result.real_time_factor:8.0f} x real time, "
                  f"{result.run_wall_s / in_process_s:5.1f} x the in-process time; "
                  f"start-up (processes to connected graph) {result.connect_s:.1f} s")
            if result.bag is not None:
                recorded = {t["topic"]: t["count"] for t in result.bag["topics"]}
                print(f"  {'topic':26s} {'published':>10s} {'recorded':>10s}")
                lost = 0
                for topic, count in recorded.items():
                    pub = result.published.get(topic, 0)
                    lost += pub - count
                    print(f"  {topic:26s} {pub:10d} {count:10d}")
                print(f"  lost: {lost} messages")
    print(f"load average after: {os.getloadavg()[0]:.2f}")
    return 0


def _print_detector(steps: list[tuple[float, float]], result) -> None:
    """Wall time of each twentieth of the run (the plant reports every 5 %), and the detector's lag."""
    import statistics

    # the last step ends with the plant's final flush (waits for acknowledgements): left out
    d = [(b[0] - a[0], b[1]) for a, b in zip(steps, steps[1:]) if b[1] > a[1] and b[1] < 1.0]
    if len(d) >= 3:
        slowest = max(d)
        print(f"  twentieths of the run: median {statistics.median(x for x, _ in d):.2f} s, slowest "
              f"{slowest[0]:.2f} s (ending at {100 * slowest[1]:.0f} %); "
              + ", ".join(f"{x:.2f} s to {100 * f:.0f} %" for x, f in d if 0.65 <= f <= 0.8))
    done = [e for e in result.node_events.get("detector", []) if e["event"] == "detector_done"]
    if done:
        lag = done[-1]["lag"]
        print(f"  detector: lag median {lag['lag_median_s'] * 1e3:.0f} ms, p99 {lag['lag_p99_s'] * 1e3:.0f} ms, "
              f"max {lag['lag_max_s'] * 1e3:.0f} ms; {lag['samples_per_call']:.1f} samples per core call (at "
              f"most {lag['max_samples_per_call']}); alarms at "
              + (", ".join(f"{a['detection_time']:g} s ({a['fault_class']})" for a in done[-1]["alarms"]) or "-"))


if __name__ == "__main__":
    sys.exit(main())
