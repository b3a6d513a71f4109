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

import numpy as np
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
    def _inflow(self, flows_ml_s: Sequence[float]) -> tuple[float, list[float]]:
        q_in = 0.0
        f_in = [0.0] * self.n_comp
        for fl, c in zip(flows_ml_s, self.feed_conc):
            if not fl >= 0.0:
                raise ValueError(f"feed flow must be non-negative and finite, got {fl}")
            q_in += fl
            for i in range(self.n_comp):
                f_in[i] += fl * c[i]
        return q_in, f_in

    def sample_map(self, volume_ml: float, q_in: float, opening: float,
                   dt_s: float) -> tuple[float, float, float, float, float, float]:
        """How one sample moves the state, for any composition.

        Returns (V', out_V, a, b, oa, ob): with inputs held, every component
        amount n and inflow rate F evolve as n' = a n + b F and leave as
        out = oa n + ob F over the sample (exact for the overflow vessel, RK4
        for the gravity tank). The volume ODE does not depend on composition,
        so one scalar pass serves every component.
        """
        if self.tank.overflow:
            v = volume_ml
            if q_in <= 0.0:
                return v, 0.0, 1.0, 0.0, 0.0, 0.0
            a = math.exp(-q_in * dt_s / v)
            b = (1.0 - a) * v / q_in
            return v, q_in * dt_s, a, b, 1.0 - a, dt_s - b
        return self._gravity_map(volume_ml, q_in, opening, dt_s)

    def _gravity_map(self, v: float, q_in: float, opening: float, dt_s: float):
        outlet = self.tank.outlet
        area = self.tank.area_cm2
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

        # Each component obeys dn/dt = F - k(t) n with the same k = q_out / V,
        # so every RK4 stage value is affine in (n, F): n_j = a_j n + b_j F.
        a_tot, b_tot, oa_tot, ob_tot = 1.0, 0.0, 0.0, 0.0
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
            a2, b2 = 1.0 - half * k1, half
            a3, b3 = 1.0 - half * k2 * a2, half * (1.0 - k2 * b2)
            a4, b4 = 1.0 - h * k3 * a3, h * (1.0 - k3 * b3)
            # out-flow over the sub-step: w * sum_j c_j k_j n_j (c = 1, 2, 2, 1)
            oa = w * (k1 + 2.0 * k2 * a2 + 2.0 * k3 * a3 + k4 * a4)
            ob = w * (2.0 * k2 * b2 + 2.0 * k3 * b3 + k4 * b4)
            # compose with the sub-steps so far: n = a_tot n0 + b_tot F
            oa_tot += oa * a_tot
            ob_tot += oa * b_tot + ob
            a_tot, b_tot = (1.0 - oa) * a_tot, (1.0 - oa) * b_tot + (h - ob)
            out_v += w * (q1 + 2.0 * q2 + 2.0 * q3 + q4)
            v += w * ((q_in - q1) + 2.0 * (q_in - q2) + 2.0 * (q_in - q3) + (q_in - q4))
        if not v > 0.0:
            raise FloatingPointError("tank ran dry: liquid volume reached zero")
        return v, out_v, a_tot, b_tot, oa_tot, ob_tot

    def step(self, flows_ml_s: Sequence[float], outlet_opening: float, dt_s: float) -> None:
        """Integrate over one sample with flows and outlet opening held constant."""
        q_in, f_in = self._inflow(flows_ml_s)
        s = self.state
        v_new, out_v, a, b, oa, ob = self.sample_map(s.volume_ml, q_in, outlet_opening, dt_s)
        amounts = s.amounts_mmol
        for i in range(self.n_comp):
            n_i, f_i = amounts[i], f_in[i]
            s.amounts_out_mmol[i] += oa * n_i + ob * f_i
            amounts[i] = a * n_i + b * f_i
            s.amounts_in_mmol[i] += f_i * dt_s
        s.volume_ml = v_new
        s.volume_out_ml += out_v
        s.volume_in_ml += q_in * dt_s
        s.ph = self.balance.ph(self.concentrations, guess=s.ph)

    def simulate_flows(self, flows_ml_s: np.ndarray, openings: np.ndarray | float,
                       dt_s: float) -> dict[str, np.ndarray]:
        """Open-loop run from the current state over N samples of held inputs.

        ``flows_ml_s``: (N, n_feeds); ``openings``: (N,) or a scalar. Returns
        arrays of N + 1 samples (the current state first): ``volume_ml``,
        ``level_cm``, ``conc_mol_l`` (N + 1, n_components) and ``ph``. Leaves
        the plant at the final state. The same arithmetic as N calls of
        :meth:`step` (tests check to 1e-12), with the pH solved for all samples
        at once, so it is several times faster.
        """
        flows = np.asarray(flows_ml_s, dtype=float)
        n = len(flows)
        open_arr = np.broadcast_to(np.asarray(openings, dtype=float), (n,))
        if flows.ndim != 2 or flows.shape[1] != len(self.feeds):
            raise ValueError(f"flows must have shape (N, {len(self.feeds)})")
        if not np.all(flows >= 0.0):
            raise ValueError("feed flows must be non-negative and finite")
        conc_feed = np.asarray(self.feed_conc, dtype=float)  # (n_feeds, m)
        q_in = flows.sum(axis=1)
        f_in = flows @ conc_feed  # (N, m) inflow rates, mmol/s
        s = self.state
        volume = np.empty(n + 1)
        volume[0] = s.volume_ml
        coef = np.empty((n, 4))
        v = s.volume_ml
        out_v_total = 0.0
        for k in range(n):
            v, out_v, a, b, oa, ob = self.sample_map(v, float(q_in[k]), float(open_arr[k]), dt_s)
            volume[k + 1] = v
            coef[k] = (a, b, oa, ob)
            out_v_total += out_v
        amounts = np.empty((n + 1, self.n_comp))
        amounts[0] = s.amounts_mmol
        a_col, b_col = coef[:, 0].tolist(), coef[:, 1].tolist()
        for i in range(self.n_comp):
            col = amounts[:, i]
            f_col = f_in[:, i].tolist()
            x = float(col[0])
            out = [x]
            for k in range(n):
                x = a_col[k] * x + b_col[k] * f_col[k]
                out.append(x)
            col[:] = out
        for i in range(self.n_comp):
            s.amounts_out_mmol[i] += float(np.sum(coef[:, 2] * amounts[:-1, i] + coef[:, 3] * f_in[:, i]))
            s.amounts_in_mmol[i] += float(np.sum(f_in[:, i]) * dt_s)
        conc = amounts / volume[:, None]
        ph = self.balance.ph_array(conc, guess=s.ph)
        s.volume_ml = float(volume[-1])
        s.amounts_mmol = amounts[-1].tolist()
        s.volume_out_ml += out_v_total
        s.volume_in_ml += float(q_in.sum() * dt_s)
        s.ph = float(ph[-1])
        return {"volume_ml": volume, "level_cm": volume / self.tank.area_cm2, "conc_mol_l": conc, "ph": ph}
