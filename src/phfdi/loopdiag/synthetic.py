"""Closed loops with known faults: a PI controller, a valve block, a FOPTD or integrating process.

The acceptance tests and docs/loop_diagnosis.md diagnose these runs and compare with the truth.
The controller is :class:`pi_controllers.pi.PIController` and the valve nonlinearities are the
blocks of :mod:`valve_actuator.blocks` (the same code the pH simulator runs). The process is
simulated exactly for a piecewise-constant stem position (zero-order hold):

    FOPTD:        x(k+1) = a x(k) + K (1 - a) (v(k - d) - v0),   a = exp(-dt / tau)
    integrating:  x(k+1) = x(k) + K dt (v(k - d) - v0)
    PV(k) = pv0 + x(k) + disturbance(k) + noise(k)

with d the dead time in samples and v0 the stem position at the start (the loop starts at rest).
Loads enter at the process input (in % of stem travel): a random walk, a first-order filtered
noise, steps, ramps and an oscillation of a given waveform (an upstream loop cycling: a sine, a
square wave, a triangle or a sawtooth); the recorded PV may be rounded to the historian's
resolution, and the historian may compress PV and OP (step-hold: a value is stored only when it has
moved more than a dead-band from the last stored one; the controller sees the uncompressed PV).
Optional, for the domain-randomised training loops (:mod:`.domain`): a second lag in series with
the first, coloured (AR(1)) measurement noise, OP rounded as the historian stores it, and a setpoint
that wanders like a cascade master's output (an AR(1) process around the stepped setpoint). With
these left at their defaults the record is the one the earlier simulator gave, sample for sample.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import overload

import numpy as np
from scipy.signal import lfilter

import valve_actuator.blocks  # noqa: F401  (registers the valve blocks)
from phfdi.records.record import Record
from phfdi_base.blocks import make_block
from pi_controllers.pi import PIController


@dataclass
class SyntheticLoop:
    """One closed loop; ``valve`` is ``(block name, params)`` of :mod:`valve_actuator.blocks` or None.

    Examples
    --------
    >>> from phfdi.loopdiag import SyntheticLoop, simulate_loop
    >>> loop = SyntheticLoop(valve=("backlash", {"width_pct": 2.0}), duration_s=1200.0)
    >>> simulate_loop(loop).names
    ['op_pct', 'pv', 'sp', 'stem_pct']
    """

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
    load_ar_std: float = 0.0  # first-order filtered (AR(1)) load at the process input (% stationary std)
    load_ar_pole: float = 0.95  # its pole (per sample)
    load_steps: list[tuple[float, float]] = field(default_factory=list)  # (time s, load step %) at the input
    load_ramps: list[tuple[float, float, float]] = field(default_factory=list)  # (start s, duration s, change %)
    pv_quantum: float = 0.0  # PV as the historian stores it: rounded to this step (0: not rounded)
    pv_compression: float = 0.0  # historian compression dead-band of PV (PV units; 0: none)
    op_compression: float = 0.0  # historian compression dead-band of OP (%; 0: none)
    noise_std: float = 0.05
    noise_pole: float = 0.0  # AR(1) pole of the measurement noise (0: white); noise_std is its stationary std
    time_constant2_s: float = 0.0  # a second lag in series (s; 0: first order)
    #: an oscillating load at the process input: (amplitude % of travel, period s, waveform, phase rad);
    #: waveform one of :data:`WAVEFORMS`
    input_oscillation: tuple[float, float, str, float] | None = None
    op_quantum: float = 0.0  # OP as the historian stores it: rounded to this step (%; 0: not rounded)
    sp_ar_std: float = 0.0  # a setpoint wandering like a cascade master's output: AR(1) stationary std
    sp_ar_pole: float = 0.99  # its pole (per sample)
    #: the PI controller's scan (s); 0: every record sample (``dt_s``). A DCS scans its loops in a second or
    #: less while a historian keeps a value every 10 s or so: with ``scan_s`` below ``dt_s`` the loop runs at
    #: the scan and the record keeps every (dt_s / scan_s)-th value (a whole number). The per-sample figures above
    #: (load_walk_std, the poles) stay per record sample: they are converted to the scan
    scan_s: float = 0.0
    seed: int = 1
    loop_tag: str = "SYN"


#: waveforms of an oscillating load (:attr:`SyntheticLoop.input_oscillation`), each of peak 1
WAVEFORMS = ("sine", "square", "triangle", "sawtooth")


@overload
def waveform(name: str, phase: np.ndarray) -> np.ndarray: ...
@overload
def waveform(name: str, phase: float) -> float: ...
def waveform(name: str, phase: np.ndarray | float) -> np.ndarray | float:
    """A periodic waveform of period 2 pi and peak 1: a sine, a square wave with soft edges (an upstream
    sticky valve's slips seen through a lag), a triangle or a sawtooth."""
    if name == "sine":
        return np.sin(phase)
    if name == "square":
        return np.tanh(4.0 * np.sin(phase)) / math.tanh(4.0)
    frac = np.mod(np.asarray(phase, float) / (2 * math.pi), 1.0)
    if name == "triangle":
        return 1.0 - 4.0 * np.abs(frac - 0.5)
    if name == "sawtooth":
        return 2.0 * frac - 1.0
    raise ValueError(f"unknown waveform {name!r}; one of {WAVEFORMS}")


def simulate_loop(spec: SyntheticLoop) -> Record:
    """The closed loop's historian record: time_s, op_pct, pv, sp, and the truth stem_pct.

    Examples
    --------
    >>> from phfdi.loopdiag import SyntheticLoop, simulate_loop
    >>> run = simulate_loop(SyntheticLoop(duration_s=1200.0, dt_s=4.0))
    >>> len(run), run.metadata["loop_tag"]
    (300, 'SYN')
    """
    ratio = scans_per_sample(spec)
    if ratio > 1:
        return _snapshots(simulate_loop(_per_scan(spec, ratio)), ratio, spec)
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
    ar = 0.0
    ar_gain = spec.load_ar_std * math.sqrt(max(1.0 - spec.load_ar_pole ** 2, 0.0))
    load_steps = sorted(spec.load_steps)
    step_load = 0.0
    extra = _Extras(spec, n)
    out = {k: np.empty(n) for k in ("time_s", "op_pct", "pv", "sp", "stem_pct")}
    for k in range(n):
        t = k * spec.dt_s
        while steps and steps[0][0] <= t:
            sp_now = steps.pop(0)[1]
        while load_steps and load_steps[0][0] <= t:
            step_load += load_steps.pop(0)[1]
        dist = spec.disturbance_amplitude * math.sin(2 * math.pi * t / spec.disturbance_period_s)
        e_noise = rng.standard_normal()
        if extra.on:
            e_noise = extra.noise(e_noise)
        pv = spec.pv0 + (extra.lag2(x) if extra.on else x) + dist + spec.noise_std * e_noise
        if spec.pv_quantum > 0:
            pv = spec.pv_quantum * round(pv / spec.pv_quantum)
        sp_k = sp_now + extra.sp[k] if extra.on else sp_now
        op = pi.step(sp_k, pv)
        v = valve.step(op, t) if valve is not None else op
        v_hist.append(v)
        ramp_load = sum(dv * min(max((t - t0) / dur, 0.0), 1.0) for t0, dur, dv in spec.load_ramps)
        v_in = v_hist[-1 - d] + load + ar + step_load + ramp_load
        if extra.on:
            v_in += extra.osc[k]
        load += spec.load_walk_std * rng.standard_normal()
        if ar_gain > 0:
            ar = spec.load_ar_pole * ar + ar_gain * rng.standard_normal()
        if spec.process == "integrating":
            x = x + spec.gain * spec.dt_s * (v_in - spec.op0_pct)
        else:
            x = a * x + spec.gain * (1 - a) * (v_in - spec.op0_pct)
        for key, val in (("time_s", t), ("op_pct", op), ("pv", pv), ("sp", sp_k), ("stem_pct", v)):
            out[key][k] = val
    if spec.op_quantum > 0:
        out["op_pct"] = spec.op_quantum * np.round(out["op_pct"] / spec.op_quantum)
    if spec.pv_compression > 0:
        out["pv"] = compress(out["pv"], spec.pv_compression)
    if spec.op_compression > 0:
        out["op_pct"] = compress(out["op_pct"], spec.op_compression)
    meta = {"loop_tag": spec.loop_tag, "file": f"synthetic:{spec.loop_tag}", "sample_time_s": spec.dt_s,
            "units": {"op_pct": "%", "pv": "PV units", "sp": "PV units"},
            "process_type": "integrating" if spec.process == "integrating" else "self_regulating",
            "synthetic": {"valve": spec.valve, "kp": spec.kp, "ti_s": spec.ti_s}, "notes": []}
    return Record.of(out, meta)


def scans_per_sample(spec: SyntheticLoop) -> int:
    """How many controller scans one record sample spans (1 when ``scan_s`` is 0 or ``dt_s``).

    Raises
    ------
    ValueError
        ``scan_s`` negative, longer than ``dt_s``, or not a whole fraction of it.
    """
    if spec.scan_s == 0.0 or spec.scan_s == spec.dt_s:
        return 1
    ratio = spec.dt_s / spec.scan_s if math.isfinite(spec.scan_s) and spec.scan_s > 0 else -1.0
    if ratio < 1.0 or abs(ratio - round(ratio)) > 1e-6 * ratio:
        raise ValueError(f"scan_s {spec.scan_s} s must divide the sample time dt_s {spec.dt_s} s a whole number "
                         "of times (0: scan at every sample)")
    return int(round(ratio))


def _per_scan(spec: SyntheticLoop, ratio: int) -> SyntheticLoop:
    """The same loop stepped at its scan: the per-sample random walk and poles converted so that, per record
    sample, the load's variance growth and the correlations stay those of ``spec``."""
    def pole(p: float) -> float:
        return float(p) ** (1.0 / ratio) if p > 0 else float(p)

    return replace(spec, dt_s=spec.dt_s / ratio, scan_s=0.0, load_walk_std=spec.load_walk_std / math.sqrt(ratio),
                   load_ar_pole=pole(spec.load_ar_pole), sp_ar_pole=pole(spec.sp_ar_pole),
                   noise_pole=pole(spec.noise_pole))


def _snapshots(fine: Record, ratio: int, spec: SyntheticLoop) -> Record:
    """Every ``ratio``-th scan of a loop run at its scan: the historian's record at ``spec.dt_s``."""
    cols = {k: np.asarray(fine[k])[::ratio] for k in ("op_pct", "pv", "sp", "stem_pct")}
    cols["time_s"] = np.asarray(fine.time_s)[::ratio]
    meta = dict(fine.metadata)
    meta["sample_time_s"] = spec.dt_s
    meta["synthetic"] = dict(meta["synthetic"], scan_s=spec.scan_s)
    return Record.of(cols, meta)


class _Extras:
    """The optional parts of :func:`simulate_loop` (second lag, coloured noise, oscillating load, wandering
    setpoint), kept apart so that a loop without them draws the same random numbers as before. Their own
    random numbers come from a second stream seeded from the loop's seed."""

    def __init__(self, spec: SyntheticLoop, n: int) -> None:
        self.on = bool(spec.time_constant2_s > 0 or spec.noise_pole > 0 or spec.input_oscillation
                       or spec.sp_ar_std > 0)
        self.a2 = math.exp(-spec.dt_s / spec.time_constant2_s) if spec.time_constant2_s > 0 else 0.0
        self.x2 = 0.0
        self.pole = float(spec.noise_pole)
        self.colour: float | None = None
        k = np.arange(n) * spec.dt_s
        self.osc: np.ndarray = np.zeros(n)
        if spec.input_oscillation:
            amp, period_s, wave, phase = spec.input_oscillation
            self.osc = amp * waveform(wave, 2 * math.pi * k / period_s + phase)
        self.sp = np.zeros(n)
        if spec.sp_ar_std > 0:
            rng = np.random.default_rng([spec.seed, 1])
            g = spec.sp_ar_std * math.sqrt(max(1.0 - spec.sp_ar_pole ** 2, 0.0))
            self.sp = lfilter([g], [1.0, -spec.sp_ar_pole], rng.standard_normal(n))

    def lag2(self, x: float) -> float:
        """The second lag's output (x of the first lag in, unit gain)."""
        self.x2 = self.a2 * self.x2 + (1.0 - self.a2) * x if self.a2 > 0 else x
        return self.x2

    def noise(self, e: float) -> float:
        """Unit-variance AR(1) measurement noise driven by e (e itself when white)."""
        if self.pole <= 0:
            return e
        # the first sample from the stationary distribution, then the recursion
        self.colour = e if self.colour is None else self.pole * self.colour + math.sqrt(1.0 - self.pole ** 2) * e
        return self.colour


def compress(x: np.ndarray, deadband: float) -> np.ndarray:
    """A historian's dead-band compression as the record shows it, step-hold: each sample repeats the
    last stored value until the signal has moved more than ``deadband`` from it."""
    out = np.empty_like(x)
    last = x[0]
    for i, v in enumerate(x):
        if abs(v - last) > deadband:
            last = v
        out[i] = last
    return out


def steps_every(period_s: float, duration_s: float, center: float, size: float) -> list[tuple[float, float]]:
    """Setpoint up and down by ``size`` around ``center`` every ``period_s`` (first step after one period)."""
    out = []
    t, up = period_s, True
    while t < duration_s:
        out.append((t, center + (size if up else -size)))
        t += period_s
        up = not up
    return out


@dataclass(frozen=True)
class Case:
    """A synthetic loop and what the diagnosis must say about it."""

    loop: SyntheticLoop
    cause: str
    parameters: dict = field(default_factory=dict)


def acceptance_cases(duration_s: float = 3000.0) -> dict[str, Case]:
    """The loops of the acceptance tests and of docs/loop_diagnosis.md (FOPTD K 1.5, tau 60 s,
    dead time 8 s, PI Kp 0.8 %/unit, Ti 60 s, sampled at 4 s, PV noise 0.05 unless stated)."""
    d = duration_s
    sp_steps = steps_every(500, d, 50, 3)
    return {
        "stiction": Case(SyntheticLoop(valve=("stiction", {"s_pct": 3.0, "j_pct": 1.0}), ti_s=30,
                                       setpoint_steps=[(100, 52), (1500, 49)], loop_tag="SYN_STICTION"),
                         "stiction", {"s_pct": 3.0, "j_pct": 1.0}),
        "stiction_no_offset": Case(SyntheticLoop(valve=("stiction", {"s_pct": 2.0, "j_pct": 2.0}), ti_s=30,
                                                 setpoint_steps=[(100, 52), (1500, 49)],
                                                 loop_tag="SYN_STICTION_J_EQ_S"),
                                   "stiction", {"s_pct": 2.0, "j_pct": 2.0}),
        "stiction_level": Case(SyntheticLoop(process="integrating", gain=0.02, time_constant_s=20.0, kp=3.0,
                                             ti_s=300.0, valve=("stiction", {"s_pct": 2.0, "j_pct": 0.5}),
                                             setpoint_steps=[(100, 51)], loop_tag="SYN_LIC_STICTION"),
                               "stiction", {"s_pct": 2.0, "j_pct": 0.5}),
        "backlash": Case(SyntheticLoop(valve=("backlash", {"width_pct": 2.0}), setpoint_steps=sp_steps,
                                       loop_tag="SYN_BACKLASH"), "backlash", {"width_pct": 2.0}),
        "deadzone": Case(SyntheticLoop(valve=("deadzone", {"width_pct": 3.0}), setpoint_steps=sp_steps,
                                       loop_tag="SYN_DEADZONE"), "deadzone", {"width_pct": 3.0, "center_pct": 50.0}),
        "saturation": Case(SyntheticLoop(valve=("saturation", {"low_pct": 0.0, "high_pct": 54.0}),
                                         setpoint_steps=steps_every(500, d, 50, 8), loop_tag="SYN_SATURATION"),
                           "saturation", {"high_pct": 54.0}),
        "quantization": Case(SyntheticLoop(valve=("quantization", {"step_pct": 1.5}), setpoint_steps=sp_steps,
                                           loop_tag="SYN_QUANTIZATION"), "quantization", {"step_pct": 1.5}),
        "external_disturbance": Case(SyntheticLoop(disturbance_amplitude=1.0, disturbance_period_s=200,
                                                   setpoint_steps=steps_every(1000, d, 50, 2),
                                                   loop_tag="SYN_EXTERNAL"), "external_disturbance"),
        "aggressive_tuning": Case(SyntheticLoop(kp=2.6, ti_s=20, load_walk_std=0.2,
                                                setpoint_steps=steps_every(1000, d, 50, 2),
                                                loop_tag="SYN_AGGRESSIVE"), "aggressive_tuning"),
        "healthy": Case(SyntheticLoop(setpoint_steps=sp_steps, loop_tag="SYN_HEALTHY"), "none"),
    }


def weakness_cases(duration_s: float = 3000.0) -> dict[str, Case]:
    """Loops the diagnosis is known to get wrong (docs/loop_diagnosis.md, Limitations): a healthy
    valve whose OP keeps compensating a random-walk load looks like a dead-band, because the
    load cancels the effect of OP's small moves on PV."""
    return {
        "healthy_with_load_walk": Case(SyntheticLoop(setpoint_steps=steps_every(500, duration_s, 50, 3),
                                                     load_walk_std=0.05, loop_tag="SYN_HEALTHY_LOAD"), "none"),
    }
