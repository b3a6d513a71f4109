"""Synthetic loops for training and checking the stiction classifier (the project's own simulator).

:func:`draw_loops` draws closed loops from :func:`phfdi.loopdiag.synthetic.simulate_loop` across the
conditions a refinery historian shows, the same for loops with a sticky valve (Kano et al. 2004
model, :class:`valve_actuator.blocks.Stiction`) and with a healthy one, so that no condition tells
the label by itself:

* process: self-regulating (first order plus dead time, time constant 0.3 to 20 samples, dead
  time 0 to 8 samples, dead-time dominant included) or integrating (a level, with a short lag);
* tuning: SIMC-style (Skogestad 2003) with the closed-loop time constant 0.3 to 3 times the dead
  time or lag, i.e. from aggressive (oscillating) to sluggish;
* disturbances: a random-walk load, a first-order filtered load, load steps, a sinusoidal
  disturbance on PV, setpoint steps (each loop gets none, one or two of these), each about as
  large in % of valve travel as the valve faults (loads of 0.1 to 1 %, steps and sinusoids of 0.2 to
  3 %): a record whose PV is dominated by a disturbance many times the valve's stiction shows no
  stiction to any method, and its label would only be noise;
* measurement: white noise of 0.02 to 0.3 % of span in PV units, and in a third of the loops PV
  rounded to the historian's resolution;
* stiction: half of the sticky valves follow Kano et al.'s model (S from 0.3 to 6 % of span, J from
  0 to 1.2 S), half He et al.'s (2007: fs from 0.3 to 6 %, fd from 0 to fs), which sticks again
  after every slip; the Hammerstein features fit Kano's model only, so the He valves check that
  the classifier does not merely recognise its own model.

Records are 751 samples at 10 s, like the shared refinery records. Every draw is reproducible from
its seed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from phfdi.run import Run

from .synthetic import SyntheticLoop, simulate_loop

DT_S = 10.0
SAMPLES = 751
CONDITIONS = ("load_walk", "load_ar", "load_steps", "sine_disturbance", "setpoint_steps")
#: a loop drawn with no disturbance condition is listed under this one
QUIET = "quiet"


@dataclass(frozen=True)
class DrawnLoop:
    spec: SyntheticLoop
    stiction: bool
    conditions: tuple[str, ...]
    process_type: str

    @property
    def group(self) -> str:
        return self.spec.loop_tag


def _logu(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def draw_spec(rng: np.random.Generator, stiction: bool, tag: str) -> DrawnLoop:
    """One loop (see the module docstring for the ranges)."""
    dt = DT_S
    duration = SAMPLES * dt
    integrating = rng.random() < 0.35
    theta_n = int(rng.integers(0, 9)) if not integrating else int(rng.integers(0, 4))
    aggr = _logu(rng, 0.3, 3.0)  # closed-loop time constant over the dead time / lag
    if integrating:
        gain = _logu(rng, 0.0005, 0.01)  # PV units per % per s
        tau = _logu(rng, 0.3, 3.0) * dt
        theta = theta_n * dt
        lam = aggr * (theta + tau + dt)
        kp = 1.0 / (gain * (lam + theta + tau))
        ti = 4.0 * (lam + theta + tau) * _logu(rng, 0.6, 1.6)
    else:
        gain = _logu(rng, 0.3, 3.0)  # PV units per %
        tau = _logu(rng, 0.3, 20.0) * dt
        theta = theta_n * dt
        lam = aggr * max(theta + dt, 0.3 * tau)
        kp = tau / (gain * (lam + theta + 0.5 * dt)) * _logu(rng, 0.7, 1.4)
        ti = min(tau, 4.0 * (lam + theta + dt)) * _logu(rng, 0.5, 2.0)
        ti = max(ti, dt)
    pv_scale = gain * (1.0 if not integrating else 30.0 * dt)  # PV units per % of travel (over ~30 samples)
    n_cond = int(rng.integers(0, 3))
    conditions = tuple(sorted(rng.choice(CONDITIONS, size=n_cond, replace=False).tolist())) or (QUIET,)
    kw: dict = {}
    if "load_walk" in conditions:
        kw["load_walk_std"] = _logu(rng, 0.005, 0.05)
    if "load_ar" in conditions:
        kw["load_ar_std"] = _logu(rng, 0.1, 1.0)
        kw["load_ar_pole"] = float(rng.uniform(0.8, 0.99))
    if "load_steps" in conditions:
        times = np.sort(rng.uniform(0.05, 0.9, int(rng.integers(1, 5)))) * duration
        kw["load_steps"] = [(float(t), float(rng.choice([-1, 1]) * rng.uniform(0.5, 3.0))) for t in times]
    if "sine_disturbance" in conditions:
        kw["disturbance_amplitude"] = float(pv_scale * rng.uniform(0.2, 1.5))
        kw["disturbance_period_s"] = float(rng.uniform(10, 80) * dt)
    sp_steps = []
    if "setpoint_steps" in conditions:
        times = np.sort(rng.uniform(0.05, 0.9, int(rng.integers(1, 4)))) * duration
        sp = 50.0
        for t in times:
            sp = 50.0 + float(rng.choice([-1, 1]) * pv_scale * rng.uniform(0.5, 3.0))
            sp_steps.append((float(t), sp))
    else:
        # a loop at rest with a sticky valve never slips: historian records start mid-operation
        sp_steps.append((float(rng.uniform(0.0, 0.05) * duration), 50.0 + float(pv_scale * rng.uniform(0.2, 1.0))))
    noise = float(pv_scale * _logu(rng, 0.02, 0.3))
    quantum = float(noise * rng.uniform(0.5, 3.0)) if rng.random() < 0.33 else 0.0
    valve = None
    if stiction:
        s = _logu(rng, 0.3, 6.0)
        if rng.random() < 0.5:
            valve = ("stiction", {"s_pct": s, "j_pct": s * float(rng.uniform(0.0, 1.2))})
        else:
            valve = ("stiction_he", {"fs_pct": s, "fd_pct": s * float(rng.uniform(0.0, 1.0))})
    spec = SyntheticLoop(process="integrating" if integrating else "foptd", gain=gain, time_constant_s=tau,
                         dead_time_s=theta, dt_s=dt, duration_s=duration, kp=kp, ti_s=ti, valve=valve,
                         setpoint_steps=sp_steps, noise_std=noise, pv_quantum=quantum,
                         seed=int(rng.integers(0, 2 ** 31 - 1)), loop_tag=tag, **kw)
    return DrawnLoop(spec, stiction, conditions, "integrating" if integrating else "self_regulating")


def usable(run: Run) -> bool:
    """A loop an operator would run: OP not pinned at a limit for more than a fifth of the record,
    PV not diverging."""
    op = run["op_pct"]
    at_limit = float(np.mean((op <= 0.01) | (op >= 99.99)))
    return at_limit < 0.2 and bool(np.all(np.isfinite(run["pv"])))


def draw_loops(n: int, seed: int, prefix: str = "SYN") -> list[tuple[DrawnLoop, Run]]:
    """n loops, half with stiction (alternating), each simulated; unusable draws are redrawn."""
    rng = np.random.default_rng(seed)
    out = []
    i = 0
    while len(out) < n:
        stiction = len(out) % 2 == 0
        loop = draw_spec(rng, stiction, f"{prefix}{seed}_{len(out):04d}")
        i += 1
        run = simulate_loop(loop.spec)
        run.metadata["process_type"] = loop.process_type
        if usable(run):
            out.append((loop, run))
        if i > 20 * n:
            raise RuntimeError("the generator keeps drawing unusable loops")
    return out
