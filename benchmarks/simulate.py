"""Benchmark: the in-process 10000 s paper scenario at 1 s sampling.

Target (issue 2): at least 20000 x real time (under 0.5 s).
Usage: .venv/bin/python benchmarks/simulate.py [--repeat N] [--fault NAME]
Prints the best and median wall time of N runs and the real-time factor,
plus the batch open-loop plant path (CstrPlant.simulate_flows) on the same inputs.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from phfdi.loop import build_parts, simulate
from phfdi.scenario import load_scenario


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--fault", default="backlash")
    args = ap.parse_args()
    spec = load_scenario("paper", fault=args.fault)
    times = []
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        run = simulate(spec)
        times.append(time.perf_counter() - t0)
    sim_s = spec.duration_s
    best, med = min(times), statistics.median(times)
    print(f"closed loop, paper scenario with {args.fault}, {len(run)} samples ({sim_s:.0f} s simulated):")
    print(f"  wall time best {best:.3f} s, median {med:.3f} s over {args.repeat} runs")
    print(f"  real-time factor best {sim_s / best:,.0f} x, median {sim_s / med:,.0f} x (target >= 20,000 x)")
    print(f"  per sample: {1e6 * best / len(run):.1f} us")

    parts = build_parts(spec)
    plant = parts.process.plant
    flows = np.column_stack([run[f"{f.name}_flow_ml_s"] for f in plant.feeds])[:-1]
    openings = run["outlet_valve_position_pct"][:-1] / 100.0
    t0 = time.perf_counter()
    plant.simulate_flows(flows, openings, spec.sample_time_s)
    batch = time.perf_counter() - t0
    print(f"open-loop plant, batch path (simulate_flows): {batch:.3f} s for {len(flows)} samples "
          f"({sim_s / batch:,.0f} x real time)")


if __name__ == "__main__":
    main()
