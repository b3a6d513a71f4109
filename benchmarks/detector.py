"""Detector speed: offline replay throughput, per-sample latency, isolation time, memory.

    .venv/bin/python benchmarks/detector.py            # about a minute

Prints figures (no pass/fail): the lead re-measures on a quiet machine.
Throughput includes the healthy reference model (the core plant, stepped
per sample with CstrPlant.simulate_flows on blocks of samples).
"""

from __future__ import annotations

import platform
import sys
import time

import numpy as np

from phfdi.loop import simulate
from phfdi.scenario import load_scenario
from wavelet_fdi.config import DetectorSettings, load_default_calibration
from wavelet_fdi.detector import StreamingDetector
from wavelet_fdi.reference import HealthyReference
from wavelet_fdi.replay import detector_inputs, run_chunks


def best_of(fn, repeat: int = 3) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def main() -> int:
    print(f"python {platform.python_version()} on {platform.machine()}, {platform.processor() or 'cpu'}")
    spec = load_scenario("paper", fault="healthy")
    run = simulate(spec)
    n = len(run)
    settings = DetectorSettings()
    cal = load_default_calibration("paper", settings)

    # 1. offline replay, whole detector, healthy run (no alarm, so no isolation); construction apart
    t_build = best_of(lambda: StreamingDetector(spec, cal, settings))
    print(f"detector construction (scenario, plant, operating point, isolator): {t_build:.2f} s")

    def replay(chunk: int) -> float:
        det = StreamingDetector(spec, cal, settings)
        t0 = time.perf_counter()
        run_chunks(det, run, chunk)
        return time.perf_counter() - t0

    for chunk in (4096, 256, 10, 1):
        t = min(replay(chunk) for _ in range(2 if chunk > 1 else 1))
        print(f"replay, chunks of {chunk:5d} samples: {n / t:9.0f} samples/s ({1e6 * t / n:7.1f} us/sample)")

    # 2. where the time goes: the reference model alone, and the core plant's per-sample map alone
    ref = HealthyReference(spec)
    cols = detector_inputs(run, ref.feed_names, ref.valve_feed)

    def reference_only():
        ref.initialize(0.0, cols["valve_command_pct"][0], cols["level_controller_output_pct"][0],
                       cols["level_measured_cm"][0], ph=cols["ph_measured"][0])
        for a in range(0, n, 256):
            sl = slice(a, a + 256)
            ref.advance(cols["time_s"][sl], cols["valve_command_pct"][sl], cols["level_controller_output_pct"][sl], 8.0)

    t_ref = best_of(reference_only)
    plant = ref.plant
    q = np.full(n, 27.0)

    def plant_map_only():
        v = plant.volume_ml
        for k in range(n):
            v = plant.sample_map(v, float(q[k]), 0.5, 1.0)[0]

    t_map = best_of(plant_map_only)
    print(f"  healthy reference model alone:   {n / t_ref:9.0f} samples/s ({1e6 * t_ref / n:6.1f} us/sample)")
    print(f"  of which CstrPlant.sample_map:   {n / t_map:9.0f} samples/s ({1e6 * t_map / n:6.1f} us/sample)")

    # 3. per-sample latency of update() (what a node calling it per message sees)
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
          f"max {lat_us.max():.0f} us (block boundaries every {settings.block_samples} samples)")

    # 4. isolation, once per alarm (backlash at 7000 s)
    faulty = simulate(load_scenario("paper", fault="backlash"))
    det = StreamingDetector(spec, cal, settings)
    t0 = time.perf_counter()
    run_chunks(det, faulty, flush=False)
    total = time.perf_counter() - t0
    t_plain = best_of(lambda: run_chunks(StreamingDetector(spec, cal, settings, isolate=False), faulty, flush=False), 1)
    print(f"isolation of one alarm (backlash): {total - t_plain:.2f} s "
          f"({det.isolator.hypotheses_screened} hypotheses screened, {det.isolator.simulations} exact "
          f"re-simulations); result {det.alarms[0].fault_class}")

    # 5. memory: the state is bounded by history_samples
    hist = sum(a.nbytes for a in det.history.data.values())
    print(f"history buffers: {hist / 1024:.0f} KiB for {settings.history_samples} samples; "
          f"snapshots kept: {len(det.snapshots)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
