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

from .chemistry import Chemistry

#: sub-steps of one sample beyond which the flows cannot be physical (a refused input, not a long loop)
MAX_SUBSTEPS = 100_000
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

    @property
    def gravity_outlet(self) -> GravityOutlet:
        """The outlet of a vessel without overflow (there always is one: checked at construction)."""
        if self.outlet is None:
            raise ValueError("an overflow vessel has no gravity outlet")
        return self.outlet


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
    """The neutralization tank (a continuously stirred tank reactor). Advance it one sample at a time with
    :meth:`step`.

    Parameters
    ----------
    chemistry : Chemistry
        The components and their acid-base equilibria.
    feeds : sequence of Feed
        The inflows (name, recipe, nominal flow in mL/s).
    tank : Tank
        The vessel (area, volume, overflow or gravity outlet).

    Examples
    --------
    >>> from ph_plant_sim import build_plant, load_plant_model
    >>> plant = build_plant(load_plant_model("paper"))
    >>> plant.set_steady_state([9.82, 2.0, 15.6], 0.427)
    >>> round(plant.ph, 1)
    12.0
    >>> plant.step([12.0, 2.0, 15.6], 0.427, 1.0)  # more acid for one second
    >>> plant.ph < 12.0
    True
    """

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
        volume = self.tank.volume_ml if self.tank.overflow or level_cm is None else level_cm * self.tank.area_cm2
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
            level = self.tank.gravity_outlet.level_for_flow(sum(flows_ml_s), outlet_opening)
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
        from scipy.optimize import brentq  # here: a plant node that never solves for a flow starts ~0.5 s sooner

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
        return self.tank.gravity_outlet.flow(self.level_cm, outlet_opening)

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
        outlet = self.tank.gravity_outlet
        area = self.tank.area_cm2
        level = v / area
        rate = (q_in + outlet.flow(level, opening)) / v + outlet.dflow_dlevel(level, opening) / area
        n_sub = max(1, math.ceil(rate * dt_s / RK4_RATE_STEP))
        if n_sub > MAX_SUBSTEPS:  # e.g. a flow of 1e20 mL/s from a damaged record: refuse instead of looping for ever
            raise ValueError(f"the flows ({q_in:g} mL/s in) turn the tank over {rate * dt_s:.3g} times in one "
                             f"{dt_s:g} s sample, beyond {MAX_SUBSTEPS} integration sub-steps: check the flows' unit")
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
            oa, ob = rk4_outflow_map(q1 / v, q2 / v2, q3 / v3, q4 / v4, h)
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



def record_sample_maps(tank: Tank, volume0_ml: float, q_in: np.ndarray, openings: np.ndarray | float,
                       dt_s: float, volume_guess_ml: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """:meth:`CstrPlant.sample_map` for every sample of a record, vectorised over time.

    For model fitting, where one record is simulated many times. ``q_in``:
    (N,) total inflow (mL/s), ``openings``: (N,) or scalar, held over each
    sample. Returns ``volume`` (N + 1,) and ``coef`` (N, 4) = (a, b, oa, ob).

    The overflow vessel's maps are closed-form. The gravity vessel's volume
    V_k+1 = f(V_k) is sequential; instead of N Python calls, the whole
    trajectory is solved as one system V_k+1 - f(V_k) = 0 by Newton's
    method: f and f' are evaluated for all samples at once with numpy (the
    operations of ``_gravity_map``), and each correction is the linear
    recurrence dV_k+1 = f'(V_k) dV_k - r_k. ``volume_guess_ml`` (N + 1,), a
    nearby trajectory, saves iterations. It stops when every sample meets its
    map to rounding (tests check against N calls of ``sample_map`` to
    1e-12); if it does not get there, the sequential path runs.
    """
    q_in = np.asarray(q_in, dtype=float)
    n = len(q_in)
    openings = np.broadcast_to(np.asarray(openings, dtype=float), (n,))
    if tank.overflow:
        v = float(volume0_ml)
        flowing = q_in > 0.0
        q_safe = np.where(flowing, q_in, 1.0)
        a = np.where(flowing, np.exp(-q_safe * dt_s / v), 1.0)
        b = np.where(flowing, (1.0 - a) * v / q_safe, 0.0)
        coef = np.column_stack([a, b, 1.0 - a, np.where(flowing, dt_s - b, 0.0)])
        return np.full(n + 1, v), coef
    if volume_guess_ml is not None and len(volume_guess_ml) == n + 1:
        volume = np.array(volume_guess_ml, dtype=float)
    else:
        volume = np.full(n + 1, float(volume0_ml))
    volume[0] = volume0_ml
    previous = math.inf
    for _ in range(30):
        if not np.all(volume > 0.0):
            break  # the sequential path says where the tank ran dry
        v_next, coef, slope = _gravity_maps(tank, volume[:-1], q_in, openings, dt_s)
        if slope is None:
            break  # sub-stepping too fine for the vectorised path
        resid = volume[1:] - v_next
        worst = float(np.max(np.abs(resid)))
        # done at rounding level: each sample within a few ulps of its map, or no longer improving near it
        done = worst <= 1e-15 * np.max(volume) or (worst <= 1e-12 * np.max(volume) and worst >= 0.5 * previous)
        previous = worst
        if done:
            volume[1:] = v_next  # each sample now exactly its map of the previous one's value
            if np.all(v_next > 0.0):
                return volume, coef
            break
        volume[1:] += affine_recurrence(slope, -resid, 0.0)[1:]
    return _sequential_maps(tank, volume0_ml, q_in, openings, dt_s)


def _sequential_maps(tank: Tank, volume0_ml: float, q_in: np.ndarray, openings: np.ndarray,
                     dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    plant = CstrPlant.__new__(CstrPlant)
    plant.tank = tank
    volume = np.empty(len(q_in) + 1)
    coef = np.empty((len(q_in), 4))
    v = volume[0] = float(volume0_ml)
    for k, (q, o) in enumerate(zip(q_in.tolist(), openings.tolist())):
        v, _, a, b, oa, ob = plant.sample_map(v, q, o, dt_s)
        volume[k + 1] = v
        coef[k] = (a, b, oa, ob)
    return volume, coef


def rk4_outflow_map(k1, k2, k3, k4, h):
    """One RK4 sub-step of dn/dt = F - k(t) n as an affine map: the out-flow is oa n + ob F.

    ``k1..k4``: the stage values of k = q_out / V (1/s); ``h``: the sub-step (s). Every stage value of n is
    affine in (n, F), n_j = a_j n + b_j F; the out-flow over the sub-step is h/6 * sum_j c_j k_j n_j
    (c = 1, 2, 2, 1), and the new amount n + h F - out, i.e. a = 1 - oa, b = h - ob. Scalars or numpy arrays
    alike: :meth:`CstrPlant.step` and :meth:`CstrPlant.simulate_flows` share this arithmetic.

    Examples
    --------
    >>> import math
    >>> oa, ob = rk4_outflow_map(0.01, 0.01, 0.01, 0.01, 1.0)  # constant k: oa = 1 - exp(-k h) to O((k h)^5)
    >>> abs(oa - (1.0 - math.exp(-0.01))) < 1e-11
    True
    """
    half, w = 0.5 * h, h / 6.0
    a2, b2 = 1.0 - half * k1, half
    a3, b3 = 1.0 - half * k2 * a2, half * (1.0 - k2 * b2)
    a4, b4 = 1.0 - h * k3 * a3, h * (1.0 - k3 * b3)
    oa = w * (k1 + 2.0 * k2 * a2 + 2.0 * k3 * a3 + k4 * a4)
    ob = w * (2.0 * k2 * b2 + 2.0 * k3 * b3 + k4 * b4)
    return oa, ob


def _gravity_maps(tank: Tank, v: np.ndarray, q_in: np.ndarray, opening: np.ndarray, dt_s: float):
    """Element-wise :meth:`CstrPlant._gravity_map`: (V', (a, b, oa, ob), dV'/dV) per sample.

    The slope is None when the vectorised path does not apply (a head at or
    below zero, or more than 64 sub-steps).
    """
    outlet, area = tank.gravity_outlet, tank.area_cm2
    cv_full, z, expo = outlet.cv, outlet.z_cm, outlet.n
    head = v / area + z
    if not np.all(head > 0.0):
        return v, None, None
    rate = (q_in + opening * cv_full * head**expo) / v + opening * cv_full * expo * head ** (expo - 1.0) / area
    n_sub = np.maximum(1, np.ceil(rate * dt_s / RK4_RATE_STEP)).astype(int)
    most = int(n_sub.max())
    if most > 64:
        return v, None, None
    h = dt_s / n_sub
    half = 0.5 * h
    w = h / 6.0
    cv = cv_full * opening
    dcv = cv * expo / area

    def q_out(v_):
        hd = v_ / area + z
        root = hd ** (expo - 1.0)  # one power for flow and slope: hd**expo = hd * root to an ulp
        return cv * (hd * root), dcv * root

    a_tot, b_tot = np.ones_like(v), np.zeros_like(v)
    oa_tot, ob_tot = np.zeros_like(v), np.zeros_like(v)
    dv = np.ones_like(v)  # d v / d v0 through the sub-steps
    for j in range(most):
        q1, d1 = q_out(v)
        v2 = v + half * (q_in - q1)
        q2, d2 = q_out(v2)
        v3 = v + half * (q_in - q2)
        q3, d3 = q_out(v3)
        v4 = v + h * (q_in - q3)
        q4, d4 = q_out(v4)
        oa, ob = rk4_outflow_map(q1 / v, q2 / v2, q3 / v3, q4 / v4, h)
        v_new = v + w * ((q_in - q1) + 2.0 * (q_in - q2) + 2.0 * (q_in - q3) + (q_in - q4))
        # derivative of the volume stage chain (RK4 of dv/dt = q_in - q_out(v))
        e2 = 1.0 - half * d1
        e3 = 1.0 - half * d2 * e2
        e4 = 1.0 - h * d3 * e3
        dv_new = dv * (1.0 - w * (d1 + 2.0 * d2 * e2 + 2.0 * d3 * e3 + d4 * e4))
        if most == 1:
            return v_new, np.column_stack([1.0 - oa, h - ob, oa, ob]), dv_new
        live = j < n_sub
        oa_tot = np.where(live, oa_tot + oa * a_tot, oa_tot)
        ob_tot = np.where(live, ob_tot + (oa * b_tot + ob), ob_tot)
        a_tot, b_tot = (np.where(live, (1.0 - oa) * a_tot, a_tot),
                        np.where(live, (1.0 - oa) * b_tot + (h - ob), b_tot))
        v = np.where(live, v_new, v)
        dv = np.where(live, dv_new, dv)
    return v, np.column_stack([a_tot, b_tot, oa_tot, ob_tot]), dv


def affine_recurrence(gain: np.ndarray, drive: np.ndarray, x0: float | np.ndarray,
                      chunk: int = 256) -> np.ndarray:
    """x_k+1 = gain_k x_k + drive_k for k = 0..N-1, vectorised over time; returns x (N + 1, ...).

    ``gain``: (N,) in [0, 1] (a decay per sample); ``drive``: (N,) or
    (N, m), then ``x0`` (m,). Within chunks of samples the solution is
    x_k = P_k (x_c + sum_j drive_j / P_j+1) with P the running product of
    the gains; chunks whose product would underflow are stepped one sample
    at a time. Agrees with the sequential recursion to rounding (about
    ``chunk`` ulps).
    """
    gain = np.asarray(gain, dtype=float)
    drive = np.asarray(drive, dtype=float)
    n = len(gain)
    squeeze = drive.ndim == 1
    d2 = drive[:, None] if squeeze else drive
    x = np.empty((n + 1, d2.shape[1]))
    x[0] = x0
    start = 0
    while start < n:
        stop = min(n, start + chunk)
        g = gain[start:stop]
        p = np.cumprod(g)
        if p[-1] > 1e-200:
            pj = p[:, None]
            x[start + 1:stop + 1] = pj * (x[start] + np.cumsum(d2[start:stop] / pj, axis=0))
        else:
            for k in range(start, stop):
                x[k + 1] = gain[k] * x[k] + d2[k]
        start = stop
    return x[:, 0] if squeeze else x
