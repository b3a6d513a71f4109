"""Detector speed: offline replay throughput, per-sample latency, fault naming time, memory.

    .venv/bin/python benchmarks/detector.py            # about a minute

The detector is the one every command runs: the multichannel detector (``wavelet_fdi.learned_detector``) with the
physics reference shipped for the paper scenario (``paper_physics``), as ``phfdi replay`` runs a paper record.
Prints figures (no pass/fail): the lead re-measures on a quiet machine. Throughput includes the healthy reference
model (the core plant, stepped per sample with CstrPlant.simulate_flows on blocks of samples). On a shared machine
each throughput figure is the best of three interleaved repetitions.
"""

from __future__ import annotations

import platform
import sys
import time

import numpy as np

from phfdi.loop import simulate
from phfdi.replay import shipped_physics_model
from phfdi.scenario import load_scenario
from wavelet_fdi.learned_detector import LearnedDetector, run_record


def main() -> int:
    print(f"python {platform.python_version()} on {platform.machine()}")
    spec = load_scenario("paper", fault="healthy")
    run = simulate(spec)
    n = len(run)
    t0 = time.perf_counter()
    model, _ = shipped_physics_model(spec)
    LearnedDetector(model)
    print(f"detector construction (the shipped reference read): {time.perf_counter() - t0:.3f} s")
    t_s = np.asarray(run.time_s, float)
    rows = np.column_stack([np.asarray(run[c], float) for c in model.channels])

    # 1. offline replay of a healthy 10000-sample run (no alarm, so no naming), and the reference alone
    def replay(chunk: int) -> float:
        t0 = time.perf_counter()
        run_record(model, t_s, rows, chunk)
        return time.perf_counter() - t0

    def reference_only() -> float:
        t0 = time.perf_counter()
        model.reference.residuals(t_s, rows)
        return time.perf_counter() - t0

    best: dict[str, float] = {}
    for _ in range(3):  # interleaved, so that all see the same machine load on average
        for name, fn in (("4096", lambda: replay(4096)), ("256", lambda: replay(256)),
                         ("reference", reference_only)):
            best[name] = min(best.get(name, np.inf), fn())
    best["10"] = replay(10)
    best["1"] = replay(1)
    for name in ("4096", "256", "10", "1"):
        t = best[name]
        print(f"replay, {name:>4s} samples per call: {n / t:8.0f} samples/s ({1e6 * t / n:7.1f} us/sample)")
    t = best["reference"]
    print(f"  {'physics reference alone':30s} {n / t:8.0f} samples/s ({1e6 * t / n:7.1f} us/sample)")

    # 2. per-sample latency of process() with one row (a node calling the core once per message)
    det = LearnedDetector(model)
    lat = []
    for k in range(3000):
        t0 = time.perf_counter()
        det.process(t_s[k:k + 1], rows[k:k + 1])
        lat.append(time.perf_counter() - t0)
    lat_us = 1e6 * np.array(lat)
    print(f"process() of one row: median {np.median(lat_us):.0f} us, p99 {np.percentile(lat_us, 99):.0f} us, "
          f"max {lat_us.max():.0f} us")

    # 3. naming, once per alarm (backlash at 7000 s): the same record with and without naming
    faulty = simulate(load_scenario("paper", fault="backlash"))
    f_rows = np.column_stack([np.asarray(faulty[c], float) for c in model.channels])
    f_t = np.asarray(faulty.time_s, float)
    t0 = time.perf_counter()
    _, _, named = run_record(model, f_t, f_rows)
    total = time.perf_counter() - t0
    t0 = time.perf_counter()
    run_record(model, f_t, f_rows, name_faults=False)
    t_plain = time.perf_counter() - t0
    first = named.alarms[0] if named.alarms else {}
    print(f"naming of one alarm (backlash): {total - t_plain:.2f} s; named "
          f"{(first.get('isolation') or {}).get('fault_class', 'nothing')}")

    # 4. memory: the detector's state is bounded: rings of fixed size (times, and the rows kept for naming)
    rings = sum(a.nbytes for a in (named._times, named._ring_t, named._ring_x))
    print(f"rings of recent samples: {rings / 1024:.0f} KiB, whatever the record's length")
    return 0


if __name__ == "__main__":
    sys.exit(main())
