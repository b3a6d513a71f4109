"""Calibrating the detector on healthy runs: simulate them (or read them), run the detector's front end, fit.

Step 1 of the procedure in :mod:`wavelet_fdi.calibration`: the healthy runs
of a scenario simulated with each calibration seed (or read from files), each
run through the detector's front end (residuals and wavelet coefficients, no
alarms); the statistics of steps 2-5 are the core's
(:func:`wavelet_fdi.calibration.calibrate_from_traces`).
"""

from __future__ import annotations

from typing import Callable, Sequence

import numpy as np

from phfdi.loop import simulate
from phfdi.replay import load_any, run_chunks
from phfdi.scenario import load_scenario
from phfdi_base.spec import ScenarioSpec
from wavelet_fdi.calibration import DEFAULT_CALIBRATION_SEEDS, calibrate_from_traces, provisional
from wavelet_fdi.config import Calibration, DetectorSettings
from wavelet_fdi.detector import StreamingDetector

__all__ = ["calibrate", "calibrate_from_runs", "front_end_trace", "healthy_traces", "scenario_for_seed"]


def front_end_trace(spec: ScenarioSpec, run, settings: DetectorSettings) -> dict[str, np.ndarray]:
    """Residuals and coefficients of one healthy run through the detector's front end (no alarms)."""
    both = DetectorSettings(**{**settings.__dict__, "channels": ("ph", "level")})
    det = StreamingDetector(spec, provisional(both, spec.name, spec.sample_time_s), both, isolate=False,
                            record_trace=True)
    run_chunks(det, run)
    return det.trace()


def healthy_traces(spec_for_seed: Callable[[int], ScenarioSpec], seeds: Sequence[int], settings: DetectorSettings,
                   progress: Callable[[float], None] | None = None) -> list[dict[str, np.ndarray]]:
    """Front-end traces (residuals, coefficients) of simulated healthy runs, one per seed."""
    out = []
    for i, seed in enumerate(seeds):
        spec = spec_for_seed(seed)
        out.append(front_end_trace(spec, simulate(spec), settings))
        if progress:
            progress((i + 1) / len(seeds))
    return out


def calibrate_from_runs(paths: Sequence[str], spec: ScenarioSpec, settings: DetectorSettings | None = None,
                        progress: Callable[[float], None] | None = None, runs: Sequence | None = None) -> Calibration:
    """Calibrate on recorded healthy runs of a plant (its model: ``spec``) instead of simulations.

    ``runs``: the runs of ``paths`` already read (e.g. with a column map); read here when None."""
    settings = settings or DetectorSettings()
    traces = []
    for i, path in enumerate(paths):
        traces.append(front_end_trace(spec, runs[i] if runs is not None else load_any(path), settings))
        if progress:
            progress((i + 1) / len(paths))
    cal = calibrate_from_traces(traces, settings, spec.name, spec.sample_time_s, [])
    cal.sources = [str(p) for p in paths]
    return cal


def scenario_for_seed(scenario: str, overrides: Sequence[str] = ()) -> Callable[[int], ScenarioSpec]:
    def spec(seed: int) -> ScenarioSpec:
        return load_scenario(scenario, fault="healthy", overrides=list(overrides) + [f"seed={seed}"])

    return spec


def calibrate(scenario: str = "paper", settings: DetectorSettings | None = None,
              seeds: Sequence[int] = DEFAULT_CALIBRATION_SEEDS, overrides: Sequence[str] = (),
              progress: Callable[[float], None] | None = None) -> Calibration:
    """Calibrate the detector on healthy runs of a scenario (see the module docstring)."""
    settings = settings or DetectorSettings()
    make = scenario_for_seed(scenario, overrides)
    traces = healthy_traces(make, seeds, settings, progress)
    dt = make(seeds[0]).sample_time_s
    return calibrate_from_traces(traces, settings, scenario, dt, seeds)
