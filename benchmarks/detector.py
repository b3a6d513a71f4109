"""Detector speed: offline replay throughput, per-sample latency, isolation time, memory.

    .venv/bin/python benchmarks/detector.py            # about a minute

Prints figures (no pass/fail): the lead re-measures on a quiet machine.
Throughput includes the healthy reference model (the core plant, stepped
per sample with CstrPlant.simulate_flows on blocks of samples). On a shared
machine each throughput figure is the best of three interleaved repetitions.
"""

from __future__ import annotations

import platform
import sys
import time

import numpy as np

from phfdi.loop import simulate
from phfdi.replay import detector_inputs, run_chunks
from phfdi.scenario import load_scenario
from wavelet_fdi.config import DetectorSettings, load_default_calibration
from wavelet_fdi.detector import StreamingDetector
from wavelet_fdi.reference import HealthyReference


def main() -> int:
    print(f"python {platform.python_version()} on {platform.machine()}")
    spec = load_scenario("paper", fault="healthy")
    run = simulate(spec)
    n = len(run)
    settings = DetectorSettings()
    cal = load_default_calibration("paper", settings)

    t0 = time.perf_counter()
    StreamingDetector(spec, cal, settings)
    print(f"detector construction: {time.perf_counter() - t0:.3f} s")

    # 1. offline replay of a healthy 10000-sample run (no alarm, so no isolation), and its parts
    def replay(chunk: int) -> float:
        det = StreamingDetector(spec, cal, settings)
        t0 = time.perf_counter()
        run_chunks(det, run, chunk)
        return time.perf_counter() - t0

    ref = HealthyReference(spec)
    cols = detector_inputs(run, ref.feed_names, ref.valve_feed)

    def reference_only() -> float:
        ref.initialize(0.0, cols["valve_command_pct"][0], cols["level_controller_output_pct"][0],
                       cols["level_measured_cm"][0], ph=cols["ph_measured"][0])
        t0 = time.perf_counter()
        for a in range(0, n, 256):
            sl = slice(a, a + 256)
            ref.advance(cols["time_s"][sl], cols["valve_command_pct"][sl],
                        cols["level_controller_output_pct"][sl], 8.0)
        return time.perf_counter() - t0

    plant = ref.plant
    q = np.full(n, 27.0)

    def plant_map_only() -> float:
        v = plant.volume_ml
        t0 = time.perf_counter()
        for k in range(n):
            v = plant.sample_map(v, float(q[k]), 0.5, 1.0)[0]
        return time.perf_counter() - t0

    best: dict[str, float] = {}
    for _ in range(3):  # interleaved, so that all see the same machine load on average
        for name, fn in (("4096", lambda: replay(4096)), ("256", lambda: replay(256)),
                         ("reference", reference_only), ("sample_map", plant_map_only)):
            best[name] = min(best.get(name, np.inf), fn())
    best["10"] = replay(10)
    best["1"] = replay(1)
    for name in ("4096", "256", "10", "1"):
        t = best[name]
        print(f"replay, {name:>4s} samples per call: {n / t:8.0f} samples/s ({1e6 * t / n:7.1f} us/sample)")
    for name, label in (("reference", "healthy reference model alone"), ("sample_map", "CstrPlant.sample_map alone")):
        t = best[name]
        print(f"  {label:30s} {n / t:8.0f} samples/s ({1e6 * t / n:7.1f} us/sample)")

    # 2. per-sample latency of update() (a node calling the core once per message)
    det = StreamingDetector(spec, cal, settings)
    lat = []
    for k in range(3000):
        t0 = time.perf_counter()
        det.update(float(run.time_s[k]), float(run["ph_measured"][k]), float(run["valve_command_pct"][k]),
                   float(run["level_measured_cm"][k]), float(run["level_controller_output_pct"][k]),
                   float(run["ph_setpoint"][k]))
        lat.append(time.perf_counter() - t0)
    lat_us = 1e6 * np.array(lat)
    print(f"update() per sample: median {np.median(lat_us):.0f} us, p99 {np.percentile(lat_us, 99):.0f} us, "
          f"max {lat_us.max():.0f} us")

    # 3. isolation, once per alarm (backlash at 7000 s)
    faulty = simulate(load_scenario("paper", fault="backlash"))
    det = StreamingDetector(spec, cal, settings)
    t0 = time.perf_counter()
    run_chunks(det, faulty, flush=False)
    total = time.perf_counter() - t0
    plain = StreamingDetector(spec, cal, settings, isolate=False)
    t0 = time.perf_counter()
    run_chunks(plain, faulty, flush=False)
    t_plain = time.perf_counter() - t0
    print(f"isolation of one alarm (backlash): {total - t_plain:.2f} s "
          f"({det.isolator.hypotheses_screened} hypotheses screened, {det.isolator.simulations} exact "
          f"re-simulations); result {det.alarms[0].fault_class}")

    # 4. memory: the state is bounded by history_samples
    hist = sum(a.nbytes for a in det.history.data.values())
    print(f"history buffers: {hist / 1024:.0f} KiB for {settings.history_samples} samples; "
          f"snapshots kept: {len(det.snapshots)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
