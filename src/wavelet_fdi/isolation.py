"""Fault isolation: which fault explains the residual, and how big it is.

A bank of hypotheses, each the healthy reference with one fault from the
cores injected at the estimated onset (:class:`phfdi_base.blocks.Injected`):
one per fault of the catalogue (:mod:`phfdi_base.faults`) that acts on the
valve stem or the pH probe, fitted over its main parameter's search range.
Built in:

=============  ==================================================  =====================
class          model (core block)                                  main parameter
=============  ==================================================  =====================
backlash       valve ``backlash``                                  width_pct
friction       valve ``coulomb_viscous_friction`` (mobility grid)  coulomb_pct
deadzone       valve ``deadzone`` about 0 % (the library's form)   width_pct
saturation     valve ``saturation`` 0..high                        high_pct
stiction       valve ``stiction`` (J/S grid)                       s_pct
probe_delay    pH sensor ``sensor_delay``                          delay_s
=============  ==================================================  =====================

Each is re-simulated from the reference state saved before the onset, driven
by the same measured commands; its parameter and the onset are fitted by
minimising J = SSR_pH / sigma_pH^2 + SSR_level / sigma_level^2 over the
samples since the onset: grids over each class's parameter and a scan of the
onset, screened with a fast linearised bank (:class:`FastBank`), then the
three best classes re-simulated exactly with the core. Classes are
ranked by BIC (J + k ln m, k free parameters); the confidence is the reported
class's likelihood share exp(-J/2) / sum exp(-J/2) (equal priors), so classes
the data cannot separate share it. When even the best model leaves a channel's residual far from
white noise of the calibrated level (its J per sample above a chi-square
bound) the class is ``unknown``, with the share of residual variance left
unexplained as its confidence.

What cannot be told apart, and why (see docs/detector.md): nested models
(stiction with J = 0 is backlash; friction with a fast stem is a backlash
of width 2c) -- BIC then prefers the simpler one; deadzone (library form) and
saturation both cap the valve at 50 % once the controller winds up: only the
transient right after the onset separates them; a constant valve offset and a
pH sensor bias look alike except through the small level residual.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

import ph_plant_sim.sensors  # noqa: F401  (registers the probe's faults)
import valve_actuator.blocks  # noqa: F401  (registers the valve's faults)
from phfdi_base.blocks import Chain, Injected, make_block
from phfdi_base.faults import Fault, faults

from .history import History
from .reference import HealthyReference, KnownStart, ReferenceState

if TYPE_CHECKING:  # the schema (pydantic) is not needed to read a validated scenario
    from phfdi_base.spec import ScenarioSpec

GRID_POINTS = 7
FINE_POINTS = 11
#: refinement of the best classes: (onset scan before, after), parameter range +-, grid points;
#: abrupt faults need the parameter to 0.1 % (a dead-zone 0.5 % off leaves 5 sigma^2 per sample)
ZOOM = (((40, 20), 0.3, 31), ((3, 3), 0.04, 17), ((1, 1), 0.005, 11), ((0, 0), 0.0006, 11))
GOF_RELATIVE = 1.3  # J/m tolerated above 1 for model and onset errors
GOF_SIGMAS = 5.0


@dataclass(frozen=True)
class Hypothesis:
    fault_class: str
    block: str
    param: str
    unit: str
    low: float
    high: float
    log_scale: bool = True
    site: str = "valve"  # "valve" or "ph_sensor"
    #: variants of a second parameter: name -> values; each is fitted, the best kept
    variants: tuple[tuple[str, float], ...] = ()
    fixed: tuple[tuple[str, float], ...] = ()
    #: the second parameter is this fraction of the main one (stiction's J = ratio x S)
    ratio_param: str = ""


#: the search over a fault's second parameter (by its name; the bounds are the catalogue's): values tried as
#: variants, each fitted and the best kept; or ratios to the main parameter (stiction's J = ratio x S)
VARIANTS: dict[str, tuple[float, ...]] = {"mobility_per_s": (0.03, 0.1, 0.3)}
RATIOS: dict[str, tuple[float, ...]] = {"j_pct": (1.0 / 3.0, 2.0 / 3.0)}
#: where a hypothesis can act: the bank re-simulates the valve's stem or the pH probe
SITES = ("valve", "ph_sensor")


def hypothesis(fault: Fault) -> Hypothesis | None:
    """The hypothesis of a catalogued fault: its main parameter over the catalogue's search range, a second
    parameter by :data:`VARIANTS` or :data:`RATIOS`, the others at their preset values; None if the bank
    cannot model it."""
    main = fault.main
    if not fault.isolate or main is None or fault.site not in SITES:
        return None
    r = main.fit_range("isolation")
    variants: tuple[tuple[str, float], ...] = ()
    ratio_param = ""
    for p in fault.params[1:]:
        if not variants and p.name in VARIANTS:
            variants = tuple((p.name, v) for v in VARIANTS[p.name])
        elif not variants and p.name in RATIOS:
            variants, ratio_param = tuple(("j_ratio", v) for v in RATIOS[p.name]), p.name
    varied = {name for name, _ in variants} | {ratio_param}
    fixed = tuple((p.name, p.paper) for p in fault.params[1:] if p.paper is not None and p.name not in varied)
    return Hypothesis(fault.name, fault.block, main.name, main.unit, r.low, r.high, r.log, fault.site, variants,
                      fixed, ratio_param)


def hypotheses() -> tuple[Hypothesis, ...]:
    """One hypothesis per catalogued fault the bank can model, in the catalogue's order."""
    return tuple(h for h in map(hypothesis, faults().values()) if h is not None)


def classes() -> tuple[str, ...]:
    """The answers isolation can give: each hypothesis's class, then ``unknown``."""
    return tuple(h.fault_class for h in hypotheses()) + ("unknown",)


@dataclass
class IsolationResult:
    fault_class: str
    confidence: float
    parameter: dict | None
    alternatives: list = field(default_factory=list)
    evidence: dict = field(default_factory=dict)


@dataclass
class Window:
    """History samples from the snapshot to the end of the isolation window."""

    t: np.ndarray
    ph: np.ndarray
    level: np.ndarray
    command: np.ndarray
    flows: np.ndarray
    opening: np.ndarray
    setpoint: np.ndarray
    coef: np.ndarray
    onset: int  # position of the onset within the window
    guess: float


class FastBank:
    """Many hypotheses at once, for the search; exact re-simulation confirms the winners.

    Composition obeys c_(k+1) = alpha_k c_k + beta_k F_k with scalar alpha,
    beta from the core plant's per-sample map (:meth:`CstrPlant.sample_map`)
    evaluated at the measured volume. The valve's flow enters F linearly, so
    a hypothesis with valve flow q changes the composition by
    c_valve y_k with y_(k+1) = alpha_k y_k + beta_k (q_k - q0_k): one scalar
    recursion per hypothesis, run for all hypotheses together, then one
    vectorised pH solve. Driving the volume by the measured level makes this
    nearly exact for the true hypothesis (the real volume already carries the
    fault's flow change).
    """

    def __init__(self, ref: HealthyReference, w: Window, snapshot: ReferenceState, volume_ml: np.ndarray) -> None:
        plant = ref.plant
        n = len(w.t)
        q_in = w.flows.sum(axis=1)
        self.alpha = np.empty(n)
        self.beta = np.empty(n)
        for k in range(n):
            v0 = float(volume_ml[k])
            v1, _, a, b, _, _ = plant.sample_map(v0, float(q_in[k]), float(w.opening[k]), ref.dt_s)
            if k + 1 < n:  # the measured next volume carries the true inflow, the map the healthy one
                v1 = float(volume_ml[k + 1])
            self.alpha[k] = a * v0 / v1
            self.beta[k] = b / v1
        c_feed = np.asarray(plant.feed_conc, dtype=float)
        f0 = np.zeros((n, c_feed.shape[1]))
        for j in range(c_feed.shape[0]):
            f0 += w.flows[:, j:j + 1] * c_feed[j]
        c = np.empty((n, c_feed.shape[1]))
        c[0] = np.asarray(snapshot.amounts_mmol) / snapshot.volume_ml
        for k in range(n - 1):
            c[k + 1] = self.alpha[k] * c[k] + self.beta[k] * f0[k]
        self.c0 = c
        self.c_valve = c_feed[ref.valve_index]
        self.q0 = w.flows[:, ref.valve_index]
        self.q0_command = snapshot.valve_command_pct
        self.balance = plant.balance
        self.guess = np.where(np.isfinite(w.ph), w.ph, 7.0)
        self.ph0 = self.balance.ph_array(c, guess=self.guess)

    def ph(self, q: np.ndarray) -> np.ndarray:
        """pH (K, N) for valve flows q (K, N)."""
        k_hyp, n = q.shape
        dq = q - self.q0
        y = np.zeros((k_hyp, n))
        for k in range(n - 1):
            y[:, k + 1] = self.alpha[k] * y[:, k] + self.beta[k] * dq[:, k]
        conc = self.c0[None, :, :] + y[:, :, None] * self.c_valve[None, None, :]
        guess = np.broadcast_to(self.guess, (k_hyp, n)).reshape(-1)
        return self.balance.ph_array(conc.reshape(k_hyp * n, -1), guess=guess).reshape(k_hyp, n)


@dataclass
class Candidate:
    hyp: Hypothesis
    variant: tuple[str, float]
    theta: float
    onset: int  # position in the window
    cost: float = math.inf

    def params(self) -> dict[str, float]:
        params = dict(self.hyp.fixed)
        params[self.hyp.param] = self.theta
        name, value = self.variant
        if name == "j_ratio":
            params[self.hyp.ratio_param] = value * self.theta
        elif name:
            params[name] = value
        return params

    def reported(self) -> dict[str, float]:
        out = {self.hyp.param: self.theta}
        if self.variant[0]:
            out[self.variant[0]] = self.variant[1]
        return out


class FaultIsolator:
    """Fits every hypothesis of :func:`hypotheses` to the data since the onset; see the module docstring."""

    #: onset candidates scanned for the best classes: this many samples before .. after the estimate
    ONSET_BEFORE = ZOOM[0][0][0]
    CONFIRMED = 3
    REFINED = 5

    def __init__(self, spec: ScenarioSpec, sigma_ph: float, sigma_level_cm: float, level: int,
                 known: KnownStart | None = None) -> None:
        """``sigma_ph`` and ``sigma_level_cm``: the residuals' healthy standard deviations (the fits' cost unit; the
        band energies the evidence reports are in units of ``sigma_ph`` too); ``level``: the wavelet level of the
        coefficients the history holds (D1..DJ, AJ, then the residual)."""
        self.reference = HealthyReference(spec, known)  # its own copy: re-simulations never touch the detector's
        self.hypotheses = hypotheses()
        self.dt_s = spec.sample_time_s
        self.sigma_ph = float(sigma_ph)
        self.sigma_level = float(sigma_level_cm)
        self.bands = [f"D{j}" for j in range(1, level + 1)] + [f"A{level}"]
        self.band_sigma = {b: self.sigma_ph for b in self.bands}
        self.simulations = 0
        self.hypotheses_screened = 0

    # ---- entry --------------------------------------------------------------------------
    def isolate(self, history: History, snapshot: ReferenceState, snap_index: int, onset_index: int,
                end_index: int) -> IsolationResult | None:
        w = self._window(history, snap_index, onset_index, end_index)
        if w is None:
            return None
        healthy = self._exact(w, snapshot, None)
        if not np.all(np.isfinite(healthy[0])):
            return None
        area = self.reference.plant.tank.area_cm2
        level_ok = np.isfinite(w.level) & (w.level > 0.0) if self.reference.has_level else np.zeros(len(w.t), bool)
        volume = np.where(level_ok, w.level * area, healthy[2])
        try:
            bank = FastBank(self.reference, w, snapshot, volume)
        except (FloatingPointError, ValueError):
            return None
        cands = self._search(w, bank)
        top = cands[: self.CONFIRMED]
        start = max(0, w.onset - self.ONSET_BEFORE)  # every cost over the same samples
        preds = [self._candidate_prediction(w, snapshot, c, healthy) for c in top]
        best = int(np.argmin([self._cost(w, p, start) for p in preds]))
        if not self._fits(w, preds[best], start):
            # stick-slip models are rugged in (onset, parameter) jointly: search both at once
            c = self._rescue(w, bank, top[best], start)
            pred = self._candidate_prediction(w, snapshot, c, healthy)
            if self._cost(w, pred, start) < self._cost(w, preds[best], start):
                top[best], preds[best] = c, pred
        confirmed = [(c, self._cost(w, p, start), self._ph_share(w, p, start)) for c, p in zip(top, preds)]
        return self._decide(w, confirmed, self._cost(w, healthy, start), cands, start)

    def _fits(self, w: Window, pred, start: int) -> bool:
        m_ph = self._samples(w, start)[0]
        return self._ph_share(w, pred, start) / max(m_ph, 1) <= GOF_RELATIVE + GOF_SIGMAS * math.sqrt(2.0 / max(m_ph, 1))

    def _rescue(self, w: Window, bank: FastBank, c: Candidate, start: int) -> Candidate:
        """Joint grid over onset (+-15 samples), parameter (+-6 %) and the class's variants."""
        n = len(w.t)
        onsets = range(max(1, c.onset - 15), min(n - 8, c.onset + 15) + 1)
        thetas = _grid(max(c.hyp.low, c.theta / 1.06), min(c.hyp.high, c.theta * 1.06), c.hyp.log_scale, 13)
        variants = c.hyp.variants or (("", math.nan),)
        grid = [Candidate(c.hyp, v, float(th), o) for v in variants for o in onsets for th in thetas]
        self._screen(w, bank, grid, start)
        b = min(grid + [c], key=lambda x: x.cost)
        fine = [Candidate(b.hyp, b.variant, float(th), b.onset)
                for th in _grid(max(b.hyp.low, b.theta / 1.01), min(b.hyp.high, b.theta * 1.01), b.hyp.log_scale, 11)]
        self._screen(w, bank, fine, start)
        return min(fine + [b], key=lambda x: x.cost)

    # ---- data ---------------------------------------------------------------------------
    def _window(self, history: History, a: int, onset: int, b: int) -> Window | None:
        b = b + 1
        if b - onset < 8 or a > onset:
            return None
        read = lambda name: history.read(a, b, name)  # noqa: E731
        w = Window(read("t"), read("ph"), read("level"), read("command"), read("flows"), read("opening"),
                   read("setpoint"), read("coef"), onset - a, 7.0)
        if len(w.t) != b - a or not np.all(np.isfinite(w.flows)) or not np.all(np.isfinite(w.opening)):
            return None
        pred0 = history.read(a, a + 1, "ph_pred")
        w.guess = float(pred0[0]) if len(pred0) and math.isfinite(pred0[0]) else 7.0
        return w

    # ---- exact re-simulation with the core ------------------------------------------------
    def _exact(self, w: Window, snapshot: ReferenceState, block, onset: int | None = None):
        """(pH, level, volume) of the core plant from the snapshot with an optional valve block."""
        ref = self.reference
        ref.restore(snapshot)
        flows = w.flows
        if block is not None:
            valve = ref.new_valve(Chain([Injected(block, float(w.t[onset]))]))
            valve.reset(snapshot.valve_command_pct)
            flows = flows.copy()
            flows[:, ref.valve_index] = ref.valve_flows(valve, w.command, w.t)
        pred = ref.run_flows(flows, w.opening, w.guess)
        self.simulations += 1
        return pred.ph, pred.level_cm, pred.level_cm * ref.plant.tank.area_cm2

    def _delayed(self, w: Window, ph: np.ndarray, block, onset: int) -> np.ndarray:
        sensor = Chain([Injected(block, float(w.t[onset]))])
        sensor.reset(float(ph[0]))
        return np.array([sensor.step(float(x), float(t)) for x, t in zip(ph.tolist(), w.t.tolist())])

    def _candidate_prediction(self, w: Window, snapshot: ReferenceState, c: Candidate, healthy):
        block = make_block(c.hyp.block, c.params(), dt_s=self.dt_s)
        if c.hyp.site == "ph_sensor":
            return self._delayed(w, healthy[0], block, c.onset), healthy[1]
        ph, level, _ = self._exact(w, snapshot, block, c.onset)
        return ph, level

    def _cost(self, w: Window, pred, onset: int) -> float:
        """J = SSR/sigma^2 of pH and level from the onset on; infinite where the model failed."""
        sl = slice(onset, None)
        if not (np.all(np.isfinite(pred[0][sl])) and np.all(np.isfinite(pred[1][sl]))):
            return math.inf
        r = w.ph[sl] - pred[0][sl]
        r = r[np.isfinite(r)]
        cost = float(np.sum(r * r)) / self.sigma_ph**2
        rl = w.level[sl] - pred[1][sl]
        rl = rl[np.isfinite(rl)]
        if len(rl) and self.sigma_level > 0:
            cost += float(np.sum(rl * rl)) / self.sigma_level**2
        return cost if math.isfinite(cost) else math.inf

    def _samples(self, w: Window, onset: int) -> tuple[int, int]:
        """(pH samples, level samples) from the onset on."""
        sl = slice(onset, None)
        return int(np.count_nonzero(np.isfinite(w.ph[sl]))), int(np.count_nonzero(np.isfinite(w.level[sl])))

    def _ph_share(self, w: Window, pred, onset: int) -> float:
        """The pH part of J from the onset on."""
        r = w.ph[onset:] - pred[0][onset:]
        r = r[np.isfinite(r)]
        return float(np.sum(r * r)) / self.sigma_ph**2

    # ---- search with the fast bank -------------------------------------------------------
    def _screen(self, w: Window, bank: FastBank, cands: list[Candidate], cost_from: int) -> None:
        """Fast pH-only cost of each candidate from sample ``cost_from`` on (in place)."""
        valve = [c for c in cands if c.hyp.site == "valve"]
        if valve:
            q = np.repeat(bank.q0[None, :], len(valve), axis=0)
            ref = self.reference
            for i, c in enumerate(valve):
                # before its onset a hypothesis is the healthy valve; from it, the block starts at rest
                # on the last finite command (what phfdi_base.blocks.Injected does)
                v = ref.new_valve(Chain([make_block(c.hyp.block, c.params(), dt_s=self.dt_s)]))
                v.reset(_last_finite(w.command[:c.onset], bank.q0_command))
                q[i, c.onset:] = ref.valve_flows(v, w.command[c.onset:], w.t[c.onset:])
            ph = bank.ph(q)
            for i, c in enumerate(valve):
                c.cost = self._ph_cost(w, ph[i], cost_from)
        for c in cands:
            if c.hyp.site == "ph_sensor":
                block = make_block(c.hyp.block, c.params(), dt_s=self.dt_s)
                c.cost = self._ph_cost(w, self._delayed(w, bank.ph0, block, c.onset), cost_from)
        self.hypotheses_screened += len(cands)

    def _ph_cost(self, w: Window, ph: np.ndarray, start: int) -> float:
        r = w.ph[start:] - ph[start:]
        r = r[np.isfinite(r)]
        c = float(np.sum(r * r)) / self.sigma_ph**2
        return c if math.isfinite(c) else math.inf

    def _search(self, w: Window, bank: FastBank) -> list[Candidate]:
        """Best candidate per class, best first.

        Coarse grid per class and variant, a finer grid between the best
        point's neighbours; then, for the best classes, the onset is scanned
        sample by sample and the parameter re-gridded around its value, twice
        (the costs of stick-slip models are rugged in both, so grids rather
        than a local search).
        """
        onset = w.onset
        n = len(w.t)
        start = max(0, onset - self.ONSET_BEFORE)  # costs compare from the earliest onset scanned
        variants = [(h, v) for h in self.hypotheses for v in (h.variants or (("", math.nan),))]
        cands = [Candidate(h, v, float(th), onset) for h, v in variants
                 for th in _grid(h.low, h.high, h.log_scale, GRID_POINTS)]
        self._screen(w, bank, cands, start)
        ranges = []
        for i in range(len(variants)):
            mine = cands[i * GRID_POINTS:(i + 1) * GRID_POINTS]
            j = int(np.argmin([c.cost for c in mine]))
            ranges.append((mine[j], mine[max(j - 1, 0)].theta, mine[min(j + 1, GRID_POINTS - 1)].theta))
        best = self._regrid(w, bank, ranges, FINE_POINTS, start)
        # refine the best variants (not only each class's best: a second parameter's grid value
        # that loses before the onset is refined may win after)
        best.sort(key=lambda c: c.cost)
        top = best[: self.REFINED]
        for cls in dict.fromkeys(c.hyp.fault_class for c in best[: self.CONFIRMED * 2]):
            if not any(c.hyp.fault_class == cls for c in top):
                top.append(next(c for c in best if c.hyp.fault_class == cls))
        rest = [c for c in best if c not in top]
        for (before, after), rel, points in ZOOM:
            scans = [[Candidate(c.hyp, c.variant, c.theta, o)
                      for o in range(max(1, c.onset - before), min(n - 8, c.onset + after) + 1)] for c in top]
            self._screen(w, bank, [x for sc in scans for x in sc], start)
            ranges = []
            for c, sc in zip(top, scans):
                b = min(sc + [c], key=lambda x: x.cost)
                half = rel * (b.hyp.high - b.hyp.low) / 4.0
                span = (b.theta / (1 + rel), b.theta * (1 + rel)) if b.hyp.log_scale else (b.theta - half,
                                                                                             b.theta + half)
                ranges.append((b, max(span[0], b.hyp.low), min(span[1], b.hyp.high)))
            top = self._regrid(w, bank, ranges, points, start)
        per_class: dict[str, Candidate] = {}
        for c in sorted(top, key=lambda c: c.cost) + sorted(rest, key=lambda c: c.cost):
            per_class.setdefault(c.hyp.fault_class, c)
        return list(per_class.values())

    def _regrid(self, w: Window, bank: FastBank, items: list[tuple[Candidate, float, float]], points: int,
                start: int) -> list[Candidate]:
        """For each (candidate, low, high): the best of the candidate and a grid of its parameter."""
        grids = [[Candidate(c.hyp, c.variant, float(th), c.onset) for th in _grid(lo, hi, c.hyp.log_scale, points)]
                 for c, lo, hi in items]
        self._screen(w, bank, [x for g in grids for x in g], start)
        return [min(g + [c], key=lambda x: x.cost) for g, (c, _, _) in zip(grids, items)]

    # ---- decision ------------------------------------------------------------------------
    def _decide(self, w: Window, confirmed: list[tuple[Candidate, float, float]], h0_cost: float,
                ranked: list[Candidate], start: int) -> IsolationResult:
        m_ph, m_lv = self._samples(w, start)
        m = max(m_ph + m_lv, 1)
        costs = {c.hyp.fault_class: cost for c, cost, _ in confirmed}
        n_free = {c.hyp.fault_class: 1 + (1 if c.hyp.variants else 0) + 1 for c, _, _ in confirmed}  # + onset
        bic = {k: v + n_free[k] * math.log(m) for k, v in costs.items()}
        bic["healthy"] = h0_cost
        # confidence: likelihoods of the fitted classes (equal priors, no complexity penalty: when
        # the data cannot separate nested models, e.g. a valve stuck all through the window, the
        # confidence says so); the class reported is the BIC-best (the simplest adequate one)
        cost_all = dict(costs, healthy=h0_cost)
        c_min = min(cost_all.values())
        weights = {k: math.exp(-0.5 * (v - c_min)) if math.isfinite(v) else 0.0 for k, v in cost_all.items()}
        total = sum(weights.values())
        post = {k: v / total for k, v in weights.items()}
        best_c, best_cost, best_ph = min(confirmed, key=lambda cc: bic[cc[0].hyp.fault_class])
        # goodness of fit per channel: the best model must leave white noise of the calibrated level
        m_best_ph, m_best_lv = m_ph, m_lv
        gof = {"ph": best_ph / max(m_best_ph, 1)}
        limit = {"ph": GOF_RELATIVE + GOF_SIGMAS * math.sqrt(2.0 / max(m_best_ph, 1))}
        if m_best_lv:
            gof["level"] = (best_cost - best_ph) / m_best_lv
            limit["level"] = GOF_RELATIVE + GOF_SIGMAS * math.sqrt(2.0 / m_best_lv)
        alternatives = [{"fault_class": c.hyp.fault_class, "probability": post[c.hyp.fault_class],
                         "cost_per_sample": cost / m, "parameters": c.reported(),
                         "onset_time_s": float(w.t[c.onset])}
                        for c, cost, _ in sorted(confirmed, key=lambda cc: bic[cc[0].hyp.fault_class])]
        evidence = self._evidence(w, best_c.onset)
        evidence.update({"samples": m, "healthy_cost_per_sample": h0_cost / m,
                         "goodness_of_fit": gof, "goodness_of_fit_limit": limit,
                         "healthy_probability": post["healthy"], "onset_fit_s": float(w.t[best_c.onset]),
                         "screened": {c.hyp.fault_class: c.cost / m for c in ranked}})
        hyp = best_c.hyp
        parameter = {"name": hyp.param, "value": best_c.theta, "unit": hyp.unit, "fault_class": hyp.fault_class}
        worst = max(gof[k] / limit[k] for k in gof)
        if worst > 1.0 or post["healthy"] > 0.5:
            ratio = max(gof.values())
            unexplained = max(0.0, min(1.0, 1.0 - 1.0 / ratio)) if ratio > 0 else 0.0
            return IsolationResult("unknown", unexplained, parameter, alternatives, evidence)
        return IsolationResult(hyp.fault_class, post[hyp.fault_class], parameter, alternatives, evidence)

    def _evidence(self, w: Window, onset: int) -> dict:
        """Signature of the controller output and the residual since the onset (reported, not decided on)."""
        sl = slice(onset, None)
        cmd = w.command[sl]
        cmd = cmd[np.isfinite(cmd)]
        out: dict = {}
        if len(cmd) > 2:
            out["command_at_limit_fraction"] = float(np.mean((cmd <= 0.5) | (cmd >= 99.5)))
            d = np.diff(cmd)
            d = d[np.abs(d) > 0.05]
            out["command_reversals"] = int(np.sum(np.diff(np.sign(d)) != 0)) if len(d) > 1 else 0
            out["command_range_pct"] = float(np.ptp(cmd))
        coef = w.coef[sl]
        ok = np.all(np.isfinite(coef), axis=1)
        if ok.any():
            out["band_energy"] = {b: float(np.mean((coef[ok, j] / self.band_sigma[b]) ** 2))
                                  for j, b in enumerate(self.bands)}
        a = coef[ok, len(self.bands) - 1] if ok.any() else np.empty(0)  # AJ
        if len(a) > 16:
            x = a - np.mean(a)
            crossings = np.flatnonzero(np.diff(np.sign(x)) != 0)
            if len(crossings) >= 3:
                out["oscillation_period_s"] = float(2.0 * np.mean(np.diff(crossings)) * self.dt_s)
        return out


def _last_finite(x: np.ndarray, default: float) -> float:
    fin = np.flatnonzero(np.isfinite(x))
    return float(x[fin[-1]]) if len(fin) else default


def _grid(low: float, high: float, log_scale: bool, n: int) -> np.ndarray:
    return np.exp(np.linspace(math.log(low), math.log(high), n)) if log_scale else np.linspace(low, high, n)
