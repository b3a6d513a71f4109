"""The paper's data sets, simulated with the project's closed loop (:func:`phfdi.loop.simulate`).

Section 6 set: the healthy loop and the four fault types the paper analyses
(backlash, Coulomb-viscous friction, dead-zone, saturation), seven variants
each = 35 rows. Variant i of every class uses noise seed ``seed + i``, so
row i of a fault and row i of the healthy loop share their noise; the fault
variants also scale the paper's severity by 0.8 .. 1.2. In that range every
fault keeps the effect the paper shows: dead-zone and saturation both keep
the valve below the 64 % that pH 8 needs (the loop parks near pH 10.2),
friction makes the loop cycle, backlash adds a small limit cycle. A milder
dead-zone or saturation (factor below about 0.72) lets the loop reach pH 8
and would look healthy.

Faults act from t = 0 in the Section 6 set: the paper's Section 6 analyses
the responses of its Section 5 (Figures 19 to 27), where each fault is
present for the whole run; with an onset at 7000 s, 70 % of every faulty
row would be a healthy response and the clustering would mostly see noise.
Section 7 (residuals, change points) uses the paper's onset of 7000 s.

Importing this module needs the whole project (phfdi); the analysis modules
do not.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from phfdi.faults import catalogue, fault_library
from phfdi.loop import simulate
from phfdi.scenario import load_scenario

#: the classes of the paper's Section 6, in its order
PAPER_CLASSES = ("healthy", "backlash", "friction", "deadzone", "saturation")
#: the paper's grouping of them into three clusters (Figure 35)
PAPER_GROUPING = {"friction": 0, "healthy": 1, "backlash": 1, "deadzone": 2, "saturation": 2}
#: a variant's severity factor scales the fault's main parameter (from the fault catalogue); saturation moves
#: its upper limit from 100 % (factor 0) towards the library's value (factor 1) and beyond
SEVERITY_FACTORS = tuple(float(f) for f in np.linspace(0.8, 1.2, 7))


@dataclass(frozen=True)
class Variant:
    """One row of the set: its class, name, severity factor, seed and scenario overrides."""

    label: str
    name: str
    factor: float
    seed: int
    overrides: tuple[str, ...]
    onset_s: float | None


def severity_overrides(fault: str, factor: float) -> list[str]:
    """``--set`` overrides scaling the library fault's main parameter (its severity) by ``factor``."""
    main = catalogue()[fault].main if fault != "healthy" else None
    if main is None:
        return []
    params = fault_library()[fault].get("params", {})
    value = float(params[main.name])
    if fault == "saturation" and main.name == "high_pct":
        scaled = 100.0 - factor * (100.0 - value)
        scaled = min(max(scaled, float(params.get("low_pct", 0.0)) + 1.0), 100.0)
    else:
        scaled = factor * value
    return [f"faults.0.params.{main.name}={scaled:.6g}"]


def section6_variants(n_variants: int = 7, onset_s: float = 0.0, base_seed: int = 1,
                      classes: Sequence[str] = PAPER_CLASSES,
                      factors: Sequence[float] | None = None) -> list[Variant]:
    """Rows of the Section 6 set: ``n_variants`` per class, severity factors spread over 0.8 .. 1.2."""
    if n_variants < 1:
        raise ValueError("n_variants must be at least 1")
    if factors is None:
        factors = [1.0] if n_variants == 1 else list(np.linspace(0.8, 1.2, n_variants))
    out = []
    for label in classes:
        for i in range(n_variants):
            factor = 1.0 if label == "healthy" else float(factors[i])
            seed = base_seed + i
            name = f"{label}-s{seed}" if label == "healthy" else f"{label}-x{factor:.2f}-s{seed}"
            out.append(Variant(label, name, factor, seed, tuple(severity_overrides(label, factor)),
                               None if label == "healthy" else onset_s))
    return out


def section7_variants(onset_s: float = 7000.0, faults: Sequence[str] = ("backlash", "friction"),
                      seed: int = 1, reference_seed: int = 2, calibration_seed: int = 3) -> list[Variant]:
    """Runs of Section 7: each fault from ``onset_s`` and its healthy twin (same seed), plus the healthy
    reference (own seed) and a second healthy run for calibrating alarm thresholds."""
    out = [Variant("healthy", f"healthy-s{seed}", 1.0, seed, (), None)]
    out += [Variant(f, f"{f}-onset{onset_s:g}-s{seed}", 1.0, seed, (), onset_s) for f in faults]
    out += [Variant("healthy", f"healthy-s{s}", 1.0, s, (), None) for s in (reference_seed, calibration_seed)]
    return out


def _simulate_one(args: tuple) -> object:
    variant, scenario, overrides = args

    spec = load_scenario(scenario, fault=variant.label,
                         overrides=[f"seed={variant.seed}", *variant.overrides, *overrides],
                         onset_s=variant.onset_s)
    run = simulate(spec)
    run.metadata.update({"label": variant.label, "name": variant.name, "severity_factor": variant.factor})
    return run


def simulate_variants(variants: Sequence[Variant], scenario: str = "paper", overrides: Sequence[str] = (),
                      jobs: int = 1, progress: Callable[[float], None] | None = None) -> list:
    """Simulate every variant (in ``jobs`` processes); runs in the order given."""
    tasks = [(v, scenario, tuple(overrides)) for v in variants]
    runs: list = [None] * len(tasks)
    if jobs <= 1 or len(tasks) == 1:
        for i, t in enumerate(tasks):
            runs[i] = _simulate_one(t)
            if progress:
                progress((i + 1) / len(tasks))
        return runs
    from concurrent.futures import ProcessPoolExecutor, as_completed

    with ProcessPoolExecutor(max_workers=jobs) as pool:
        futures = {pool.submit(_simulate_one, t): i for i, t in enumerate(tasks)}
        for done, fut in enumerate(as_completed(futures), 1):
            runs[futures[fut]] = fut.result()
            if progress:
                progress(done / len(tasks))
    return runs
