"""Continuous stirred tank neutralization reactor with level dynamics.

State: liquid volume V (mL) and the amount n_i (mmol) of each conserved
component. With feed flows q_j (mL/s) of concentrations c_ij (mol/L) held
constant over a sample and outflow q_out(V):

    dV/dt   = sum_j q_j - q_out(V)
    dn_i/dt = sum_j q_j c_ij - q_out(V) n_i / V

(mL x mol/L = mmol.) The pH is algebraic: the root of the charge balance at
c_i = n_i / V (:mod:`ph_plant_sim.chemistry`). Using reaction invariants
removes the fast acid-base reactions, so the ODE is *not* stiff: its rates
are the dilution rate Q/V and the outlet's level sensitivity, both slow
(time constants of tens of seconds in the presets).

Integration: classical RK4 with the sample split into ``n`` sub-steps so that
``rate * h <= 0.05``, where ``rate`` bounds the Jacobian's spectral radius
(Q_in/V + q_out/V + dq_out/dV). For the linear part the local error of one
sub-step is (rate*h)^5/120 <= 2.6e-9 of the transient's amplitude; a test
checks runs against scipy's Radau at rtol 1e-11. The state is kept in
amounts, and RK4 preserves linear invariants, so volume and every component
balance in-flow minus out-flow to rounding (cumulative flows are integrated
with the same stages; a test checks the balance).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

from scipy.optimize import brentq

from .chemistry import Chemistry

RK4_RATE_STEP = 0.05  # bound on rate * sub-step


@dataclass
class Feed:
    """An inlet stream: what it carries and its nominal (or maximum) flow."""

    name: str
    recipe: dict[str, float]  # compound -> mol/L
    flow_ml_s: float


@dataclass
class GravityOutlet:
    """Gravity drain q = opening * cv * (h + z)^n (mL/s, h in cm); opening in [0, 1].

    Henson & Seborg's outlet is cv = 4.59, z = 11.5 cm, n = 0.607, fully open.
    """

    cv: float
    z_cm: float
    n: float

    def flow(self, level_cm: float, opening: float) -> float:
        head = level_cm + self.z_cm
        return opening * self.cv * head**self.n if head > 0.0 else 0.0

    def dflow_dlevel(self, level_cm: float, opening: float) -> float:
        head = level_cm + self.z_cm
        return opening * self.cv * self.n * head ** (self.n - 1.0) if head > 0.0 else 0.0

    def level_for_flow(self, flow_ml_s: float, opening: float) -> float:
        """Steady level at which the drain passes ``flow_ml_s``."""
        return (flow_ml_s / (opening * self.cv)) ** (1.0 / self.n) - self.z_cm


@dataclass
class Tank:
    """Vessel geometry. ``overflow=True``: constant volume, outflow equals inflow."""

    area_cm2: float
    outlet: GravityOutlet | None = None
    overflow: bool = False
    volume_ml: float | None = None  # overflow vessels: their fixed liquid volume

    def __post_init__(self) -> None:
        if self.overflow and (self.volume_ml is None or self.volume_ml <= 0):
            raise ValueError("an overflow vessel needs a positive volume_ml")
        if not self.overflow and self.outlet is None:
            raise ValueError("a vessel without overflow needs an outlet")


@dataclass
class PlantState:
    volume_ml: float
    amounts_mmol: list[float]
    ph: float = 7.0
    # cumulative flows since the start, for balance checks
    volume_in_ml: float = 0.0
    volume_out_ml: float = 0.0
    amounts_in_mmol: list[float] = field(default_factory=list)
    amounts_out_mmol: list[float] = field(default_factory=list)


class CstrPlant:
    """The neutralization tank. Advance it one sample at a time with :meth:`step`."""

    def __init__(self, chemistry: Chemistry, feeds: Sequence[Feed], tank: Tank) -> None:
        self.chemistry = chemistry
        self.feeds = list(feeds)
        self.tank = tank
        self.feed_conc = [chemistry.concentrations(f.recipe) for f in self.feeds]
        self.n_comp = len(chemistry.components)
        self.balance = chemistry.charge_balance()
        self.state = PlantState(1.0, [0.0] * self.n_comp)

    # ---- initial conditions -------------------------------------------------
    def mixed_inflow(self, flows_ml_s: Sequence[float]) -> list[float]:
        """Concentrations (mol/L) of the mixed inflow: the tank's steady composition."""
        q = sum(flows_ml_s)
        if q <= 0:
            raise ValueError("total inflow must be positive for a steady state")
        return [sum(fl * c[i] for fl, c in zip(flows_ml_s, self.feed_conc)) / q for i in range(self.n_comp)]

    def set_state(self, conc_mol_l: Sequence[float], level_cm: float | None = None) -> None:
        """Set composition and level (level ignored for an overflow vessel)."""
        volume = self.tank.volume_ml if self.tank.overflow else level_cm * self.tank.area_cm2
        if volume is None or volume <= 0:
            raise ValueError("initial liquid volume must be positive")
        self.state = PlantState(
            volume,
            [c * volume for c in conc_mol_l],
            amounts_in_mmol=[0.0] * self.n_comp,
            amounts_out_mmol=[0.0] * self.n_comp,
        )
        self.state.ph = self.balance.ph(self.concentrations)

    def set_steady_state(self, flows_ml_s: Sequence[float], outlet_opening: float = 1.0) -> None:
        """Start at the steady state of constant flows and outlet opening."""
        conc = self.mixed_inflow(flows_ml_s)
        level = None
        if not self.tank.overflow:
            level = self.tank.outlet.level_for_flow(sum(flows_ml_s), outlet_opening)
        self.set_state(conc, level)

    def steady_ph(self, flows_ml_s: Sequence[float]) -> float:
        return self.balance.ph(self.mixed_inflow(flows_ml_s))

    def flow_for_ph(self, target_ph: float, feed_index: int, flows_ml_s: Sequence[float],
                    max_flow_ml_s: float) -> float:
        """Flow of one feed that gives ``target_ph`` at steady state (others fixed)."""
        flows = list(flows_ml_s)

        def excess(q: float) -> float:
            flows[feed_index] = q
            return self.steady_ph(flows) - target_ph

        lo, hi = 1e-9, max_flow_ml_s
        if excess(lo) * excess(hi) > 0:
            raise ValueError(f"pH {target_ph} is not reachable with feed "
                             f"{self.feeds[feed_index].name!r} between 0 and {max_flow_ml_s} mL/s")
        return brentq(excess, lo, hi, xtol=1e-12)

    # ---- outputs --------------------------------------------------------------
    @property
    def concentrations(self) -> list[float]:
        v = self.state.volume_ml
        return [n / v for n in self.state.amounts_mmol]

    @property
    def ph(self) -> float:
        return self.state.ph

    @property
    def volume_ml(self) -> float:
        return self.state.volume_ml

    @property
    def level_cm(self) -> float:
        return self.state.volume_ml / self.tank.area_cm2

    def outlet_flow(self, flows_ml_s: Sequence[float], outlet_opening: float) -> float:
        if self.tank.overflow:
            return sum(flows_ml_s)
        return self.tank.outlet.flow(self.level_cm, outlet_opening)

    # ---- dynamics ---------------------------------------------------------------
    def step(self, flows_ml_s: Sequence[float], outlet_opening: float, dt_s: float) -> None:
        """Integrate over one sample with flows and outlet opening held constant."""
        q_in = 0.0
        f_in = [0.0] * self.n_comp
        for fl, c in zip(flows_ml_s, self.feed_conc):
            if fl < 0.0:
                raise ValueError(f"negative feed flow {fl}")
            q_in += fl
            for i in range(self.n_comp):
                f_in[i] += fl * c[i]
        s = self.state
        if self.tank.overflow:
            self._step_overflow(q_in, f_in, dt_s)
        else:
            self._step_gravity(q_in, f_in, outlet_opening, dt_s)
        s.volume_in_ml += q_in * dt_s
        for i in range(self.n_comp):
            s.amounts_in_mmol[i] += f_in[i] * dt_s
        s.ph = self.balance.ph(self.concentrations, guess=s.ph)

    def _step_overflow(self, q_in: float, f_in: list[float], dt_s: float) -> None:
        # Constant volume: dn/dt = F - q n / V is linear with constant
        # coefficients, solved exactly over the sample.
        s = self.state
        v = s.volume_ml
        if q_in <= 0.0:
            return
        decay = math.exp(-q_in * dt_s / v)
        for i in range(self.n_comp):
            n_eq = f_in[i] * v / q_in
            n_new = n_eq + (s.amounts_mmol[i] - n_eq) * decay
            # out = in - accumulation, exact for this linear ODE
            s.amounts_out_mmol[i] += f_in[i] * dt_s - (n_new - s.amounts_mmol[i])
            s.amounts_mmol[i] = n_new
        s.volume_out_ml += q_in * dt_s

    def _step_gravity(self, q_in: float, f_in: list[float], opening: float, dt_s: float) -> None:
        s = self.state
        outlet = self.tank.outlet
        area = self.tank.area_cm2
        m = self.n_comp
        v = s.volume_ml
        level = v / area
        rate = (q_in + outlet.flow(level, opening)) / v + outlet.dflow_dlevel(level, opening) / area
        n_sub = max(1, math.ceil(rate * dt_s / RK4_RATE_STEP))
        h = dt_s / n_sub
        half = 0.5 * h
        w = h / 6.0
        cv, z, expo = outlet.cv * opening, outlet.z_cm, outlet.n

        def q_out(v_: float) -> float:
            head = v_ / area + z
            return cv * head**expo if head > 0.0 else 0.0

        # The volume ODE does not depend on composition: run its RK4 stages
        # first. Each component obeys dn/dt = F - k(t) n with the same
        # k = q_out / V for all, so every RK4 stage value is affine in (n, F):
        # n_j = a_j n + b_j F. Tracking the scalars (a, b) gives the exact RK4
        # result for all components at the cost of one.
        amounts = s.amounts_mmol
        out_n = [0.0] * m
        out_v = 0.0
        for _ in range(n_sub):
            q1 = q_out(v)
            v2 = v + half * (q_in - q1)
            q2 = q_out(v2)
            v3 = v + half * (q_in - q2)
            q3 = q_out(v3)
            v4 = v + h * (q_in - q3)
            q4 = q_out(v4)
            k1, k2, k3, k4 = q1 / v, q2 / v2, q3 / v3, q4 / v4
            # stage 1: n1 = n
            a2, b2 = 1.0 - half * k1, half
            a3, b3 = 1.0 - half * k2 * a2, half * (1.0 - k2 * b2)
            a4, b4 = 1.0 - h * k3 * a3, h * (1.0 - k3 * b3)
            # out-flow rate of a component at stage j: k_j n_j
            oa = w * (k1 + 2.0 * k2 * a2 + 2.0 * k3 * a3 + k4 * a4)
            ob = w * (2.0 * k2 * b2 + 2.0 * k3 * b3 + k4 * b4)
            a_new = 1.0 - oa
            b_new = h - ob  # n' = n + h F - (oa n + ob F)
            for i in range(m):
                n_i, f_i = amounts[i], f_in[i]
                out_n[i] += oa * n_i + ob * f_i
                amounts[i] = a_new * n_i + b_new * f_i
            out_v += w * (q1 + 2.0 * q2 + 2.0 * q3 + q4)
            v += w * ((q_in - q1) + 2.0 * (q_in - q2) + 2.0 * (q_in - q3) + (q_in - q4))
        if not v > 0.0:
            raise FloatingPointError("tank ran dry: liquid volume reached zero")
        s.volume_ml = v
        s.volume_out_ml += out_v
        for i in range(m):
            s.amounts_out_mmol[i] += out_n[i]
