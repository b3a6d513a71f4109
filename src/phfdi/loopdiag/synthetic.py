"""Closed loops with known faults: a PI controller, a valve block, a FOPTD or integrating process.

The acceptance tests and docs/loop_diagnosis.md diagnose these runs and compare with the truth.
The controller is :class:`pi_controllers.pi.PIController` and the valve nonlinearities are the
blocks of :mod:`valve_actuator.blocks` (the same code the pH simulator runs). The process is
simulated exactly for a piecewise-constant stem position (zero-order hold):

    FOPTD:        x(k+1) = a x(k) + K (1 - a) (v(k - d) - v0),   a = exp(-dt / tau)
    integrating:  x(k+1) = x(k) + K dt (v(k - d) - v0)
    PV(k) = pv0 + x(k) + disturbance(k) + noise(k)

with d the dead time in samples and v0 the stem position at the start (the loop starts at rest).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from phfdi.blocks import make_block
from phfdi.run import Run
from pi_controllers.pi import PIController

import valve_actuator.blocks  # noqa: F401  (registers the valve blocks)


@dataclass
class SyntheticLoop:
    """One closed loop; ``valve`` is ``(block name, params)`` of :mod:`valve_actuator.blocks` or None."""

    process: str = "foptd"  # or "integrating"
    gain: float = 1.5  # PV units per % of stem travel (per % per s when integrating)
    time_constant_s: float = 60.0
    dead_time_s: float = 8.0
    dt_s: float = 4.0
    duration_s: float = 3000.0
    kp: float = 0.8  # % per PV unit
    ti_s: float = 60.0
    valve: tuple[str, dict] | None = None
    op0_pct: float = 50.0
    pv0: float = 50.0
    setpoint_steps: list[tuple[float, float]] = field(default_factory=list)  # (time s, setpoint)
    disturbance_amplitude: float = 0.0  # sinusoid added to PV
    disturbance_period_s: float = 300.0
    load_walk_std: float = 0.0  # random-walk load at the process input (% per sample)
    noise_std: float = 0.05
    seed: int = 1
    loop_tag: str = "SYN"


def simulate_loop(spec: SyntheticLoop) -> Run:
    """The closed loop's historian record: time_s, op_pct, pv, sp, and the truth stem_pct."""
    rng = np.random.default_rng(spec.seed)
    n = int(round(spec.duration_s / spec.dt_s))
    d = int(round(spec.dead_time_s / spec.dt_s))
    a = math.exp(-spec.dt_s / spec.time_constant_s) if spec.time_constant_s > 0 else 0.0
    valve = make_block(spec.valve[0], spec.valve[1]) if spec.valve else None
    pi = PIController(kp=spec.kp, ti_s=spec.ti_s, dt_s=spec.dt_s,
                      action="reverse" if spec.gain > 0 else "direct")
    sp_now = spec.pv0
    pi.reset(spec.op0_pct, sp_now, spec.pv0)
    if valve is not None:
        valve.reset(spec.op0_pct)
    steps = sorted(spec.setpoint_steps)
    v_hist = [spec.op0_pct] * (d + 1)
    x = 0.0
    load = 0.0
    out = {k: np.empty(n) for k in ("time_s", "op_pct", "pv", "sp", "stem_pct")}
    for k in range(n):
        t = k * spec.dt_s
        while steps and steps[0][0] <= t:
            sp_now = steps.pop(0)[1]
        dist = spec.disturbance_amplitude * math.sin(2 * math.pi * t / spec.disturbance_period_s)
        pv = spec.pv0 + x + dist + spec.noise_std * rng.standard_normal()
        op = pi.step(sp_now, pv)
        v = valve.step(op, t) if valve is not None else op
        v_hist.append(v)
        v_in = v_hist[-1 - d] + load
        load += spec.load_walk_std * rng.standard_normal()
        if spec.process == "integrating":
            x = x + spec.gain * spec.dt_s * (v_in - spec.op0_pct)
        else:
            x = a * x + spec.gain * (1 - a) * (v_in - spec.op0_pct)
        for key, val in (("time_s", t), ("op_pct", op), ("pv", pv), ("sp", sp_now), ("stem_pct", v)):
            out[key][k] = val
    meta = {"loop_tag": spec.loop_tag, "file": f"synthetic:{spec.loop_tag}", "sample_time_s": spec.dt_s,
            "units": {"op_pct": "%", "pv": "PV units", "sp": "PV units"},
            "process_type": "integrating" if spec.process == "integrating" else "self_regulating",
            "synthetic": {"valve": spec.valve, "kp": spec.kp, "ti_s": spec.ti_s}, "notes": []}
    return Run(out, meta)


def steps_every(period_s: float, duration_s: float, center: float, size: float) -> list[tuple[float, float]]:
    """Setpoint up and down by ``size`` around ``center`` every ``period_s`` (first step after one period)."""
    out = []
    t, up = period_s, True
    while t < duration_s:
        out.append((t, center + (size if up else -size)))
        t += period_s
        up = not up
    return out
