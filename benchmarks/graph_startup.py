"""Benchmark: graph start-up, processes started to graph connected, and the CPU the nodes spent on it.

Launches the loop graph (plant, controllers, valve, recorder, + the detector with --detector) on a short
scenario (--duration, default 200 s simulated, the setpoint step and the backlash fault moved inside it, so
that the run itself costs little) --repeat times and prints per launch: the wall time from starting the
processes to the connected graph (the launcher's connect_s) and the CPU seconds (user + system) all node
processes used in total. On a loaded machine the wall time follows the load; the CPU seconds are the steadier
figure of what start-up costs. ``--phases`` adds where each node's start-up went (median over the launches, s
after the launcher started the processes): spawned, imports done (interpreter and imports), rclpy.init done,
node built (part read, endpoints made), own endpoints matched with every peer, graph connected.

    .venv/bin/python benchmarks/graph_startup.py --repeat 3 --detector
    .venv/bin/python benchmarks/graph_startup.py --repeat 3 --reference paper_physics   # the multichannel node
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import sys


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--duration", type=float, default=200.0, help="simulated seconds of each run")
    ap.add_argument("--detector", action="store_true", help="add the fault detector node")
    ap.add_argument("--reference", default=None, metavar="REF",
                    help="the detector is the multichannel detector's node with this reference (a file, or "
                         "paper_physics); implies --detector")
    ap.add_argument("--no-record", action="store_true", help="run without the recorder")
    ap.add_argument("--phases", action="store_true", help="print each node's start-up steps (median)")
    ap.add_argument("--domain-id", type=int, default=None, help="ROS domain of the launches (default: a free one)")
    args = ap.parse_args()

    import tempfile
    from pathlib import Path

    from phfdi.ros.launcher import Launcher, loop_graph

    walls, cpus, phases = [], [], []
    with tempfile.TemporaryDirectory(prefix="phfdi-startup-") as tmp:
        for i in range(args.repeat):
            bag = None if args.no_record else Path(tmp) / f"run{i}.mcap"
            before = resource.getrusage(resource.RUSAGE_CHILDREN)
            overrides = [f"duration_s={args.duration:g}", f"setpoints.ph.changes.0.at_s={args.duration / 4:g}"]
            nodes = loop_graph("paper", "backlash", args.duration / 2, overrides, bag,
                               detector=({"reference": args.reference} if args.reference else
                                         {} if args.detector else None))
            result = Launcher(nodes, domain_id=args.domain_id, status=lambda s: None).run()
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            if result.status != 0:
                print(f"launch failed: {result.failure or result.notes}", file=sys.stderr)
                return 1
            cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
            walls.append(result.connect_s)
            cpus.append(cpu)
            phases.append((getattr(result, "startup", {}), getattr(result, "startup_cpu", {})))
            print(f"launch {i + 1}: {len(nodes)} nodes, start-up (processes to connected graph) {result.connect_s:.2f} s"
                  f" wall, {cpu:.2f} s CPU of all nodes (whole run of {args.duration:g} s simulated); "
                  f"load average {os.getloadavg()[0]:.1f}")
    print(f"start-up wall: median {statistics.median(walls):.2f} s, range {min(walls):.2f}-{max(walls):.2f} s; "
          f"node CPU: median {statistics.median(cpus):.2f} s, range {min(cpus):.2f}-{max(cpus):.2f} s")
    if args.phases:
        print_phases(phases)
    return 0


STEPS = ("spawned", "main", "init", "built", "matched", "connected")


def print_phases(launches: list[tuple[dict, dict]]) -> None:
    """Median per node and step: wall s after the processes were started, and the node's CPU s by then
    (steps a node did not report: '-')."""
    print("start-up steps (main: imports done, init: rclpy.init done, built: node made, matched: own endpoints "
          "matched), median of the launches")
    for title, which in (("wall s after the launcher started the processes", 0), ("the node's CPU s by then", 1)):
        print(title)
        print(f"  {'node':12s}" + "".join(f"{s:>10s}" for s in STEPS))
        names = sorted({n for launch in launches for n in launch[which]})
        for name in names:
            cells = []
            for step in STEPS:
                values = [launch[which][name][step] for launch in launches if step in launch[which].get(name, {})]
                cells.append(f"{statistics.median(values):10.2f}" if values else f"{'-':>10s}")
            print(f"  {name:12s}" + "".join(cells))


if __name__ == "__main__":
    sys.exit(main())
