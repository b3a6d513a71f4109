"""The rig's flask on the plant core: chemistry, overflow vessel, a mixing zone at the probe, CO2 from the air.

Everything chemical is :mod:`ph_plant_sim`'s: the components and the charge balance
(:class:`~ph_plant_sim.chemistry.Chemistry`), the overflow vessel's exact per-sample map
(:meth:`~ph_plant_sim.plant.CstrPlant.sample_map`), the probe zone's model
(:class:`~ph_plant_sim.mixing.MixingZone`: a zone of fixed volume exchanging with the bulk both ways, the
probe reading the zone) and the air exchange's relaxation (:class:`~ph_plant_sim.exchange.AirExchange`).

What this module adds is speed for a closed loop, which must step one sample at a time: the core computes a
zone's sample map with ``scipy.linalg.expm`` (80 us a sample here, 1-10 ms under load); the rig's zone
receives no feed (the probe sits away from the inlets: the pH a detector sees lags the bulk, it does not
overshoot it), so its map is a 2 x 2 compartment matrix whose exponential and input integral have a closed form
(Sylvester's formula over its two real eigenvalues). :meth:`RigFlask.transition` gives the same numbers as
:func:`ph_plant_sim.mixing.zone_transition` (tests check to 1e-12) at a few microseconds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from ph_plant_sim.chemistry import Chemistry, Component
from ph_plant_sim.exchange import AirExchange
from ph_plant_sim.mixing import MixingZone
from ph_plant_sim.plant import CstrPlant, Feed, Tank

from .day import RigDay

#: the background buffer's component and compound names in the chemistry (a monoprotic weak acid HB)
BUFFER = "background"
BUFFER_COMPOUND = "HB"


@dataclass(frozen=True)
class Transition:
    """One sample's map of the zone and bulk concentrations: [z, b]' = e [z, b] + p [0, f] with f the feeds'
    inflow per bulk volume (mol/L/s). ``e`` and ``p`` (2 x 2) are exp(M dt) and its integral over the sample."""

    e: np.ndarray
    p: np.ndarray


class RigFlask:
    """The flask of one :class:`~phfdi.rigsim.day.RigDay`: the core's plant objects and a fast sample step.

    Components (in the chemistry's order): sulfate (the acid), the background buffer, sodium (the base),
    carbonate (CO2 carried by the caustic and taken up from the air).
    """

    def __init__(self, day: RigDay) -> None:
        self.day = day
        acid = {"H2SO4": -day.acid_strength_mM / 2000.0, BUFFER_COMPOUND: day.buffer_mM / 1000.0}
        base = {"NaOH": day.base_strength_mM / 1000.0, "CO2": day.carbonate_per_naoh * day.base_strength_mM / 1000.0,
                BUFFER_COMPOUND: day.buffer_mM / 1000.0}
        chemistry = Chemistry.for_streams([acid, base], extra_components=[Component(BUFFER, 0, (day.buffer_pka,))],
                                          extra_compounds={BUFFER_COMPOUND: {BUFFER: 1.0}})
        self.plant = CstrPlant(chemistry, [Feed("acid", acid, 0.0), Feed("base", base, 0.0)],
                               Tank(area_cm2=80.0, overflow=True, volume_ml=day.volume_ml))
        zone_ml = day.zone_volume_fraction * day.volume_ml
        self.zone = MixingZone(zone_volume_ml=zone_ml, exchange_ml_s=zone_ml / day.zone_tau_s, feeds=())
        self.air = AirExchange("carbonate", day.co2_kla_per_s, day.co2_equilibrium_mM / 1000.0)
        self.balance = self.plant.balance
        self.names = chemistry.names
        self.carbonate = self.names.index("carbonate")
        self.feed_conc = np.asarray(self.plant.feed_conc, dtype=float)  # (2 feeds, components), mol/L
        self._cache: dict[tuple[float, float], Transition] = {}
        # the strong ions' charge per component (mol of charge per mol): sodium +1, sulfate fully dissociated -2
        self._charge = np.array([{"sodium": 1.0, "sulfate": -2.0}.get(n, 0.0) for n in self.names])

    @property
    def volume_ml(self) -> float:
        return self.day.volume_ml

    # ---- start -----------------------------------------------------------------------------------
    def start_composition(self, ph: float) -> np.ndarray:
        """The flask's concentrations (mol/L) at a run's start pH: the strong ions and background buffer of a
        mix of the two feeds in the proportion that gives ``ph``, with the carbonate the flask took up while it
        stood (the day's ``flask_carbonate_mM`` and the air's level) in place of the caustic's. (The recorded
        acid addition falls from pH 7.2 to 4 in 8 s: a flask started as a plain mix of the feeds, which holds
        the caustic's carbonate, cannot.) A basic flask holds caustic in excess, and its carbonate with it.
        A pH beyond what the feeds can make gives the nearer feed."""
        held = np.zeros(len(self.names))
        held[self.carbonate] = self.air.equilibrium_mol_l + self.day.flask_carbonate_mM / 1000.0
        acid, base = self.feed_conc[0].copy(), self.feed_conc[1].copy()
        acid[self.carbonate] = base[self.carbonate] = 0.0
        acid, base = acid + held, base + held

        def ph_of(w: float) -> float:
            return self.balance.ph(((1.0 - w) * acid + w * base).tolist())

        if ph <= ph_of(0.0):
            mix = acid
        elif ph >= ph_of(1.0):
            mix = base
        else:
            w = brentq(lambda w: ph_of(w) - ph, 0.0, 1.0, xtol=1e-15)
            mix = (1.0 - w) * acid + w * base
        # a basic flask holds caustic, and the caustic's carbonate with it: the net base times its carbonate share
        excess_base = max(0.0, float(mix @ self._charge))
        mix[self.carbonate] += self.day.carbonate_per_naoh * excess_base
        return mix

    # ---- one sample ------------------------------------------------------------------------------
    def transition(self, q_in_ml_s: float, dt_s: float) -> Transition:
        """The zone and bulk map over ``dt_s`` with the total inflow ``q_in_ml_s`` held (cached per pair).

        The core's zone equations (:mod:`ph_plant_sim.mixing`) with no feed into the zone:
        dz/dt = k1 (b - z), db/dt = f + k2 z - (k2 + r) b with k1 = Qx/Vz, k2 = Qx/V, r = q/V.
        """
        key = (q_in_ml_s, dt_s)
        hit = self._cache.get(key)
        if hit is not None:
            return hit
        if len(self._cache) > 100_000:  # a PI's continuous commands: keep the cache bounded
            self._cache.clear()
        qx, vz, v = self.zone.exchange_ml_s, self.zone.zone_volume_ml, self.volume_ml
        k1, k2, r = qx / vz, qx / v, q_in_ml_s / v
        m = np.array([[-k1, k1], [k2, -(k2 + r)]])
        half_trace = -0.5 * (k1 + k2 + r)
        det = k1 * r
        root = math.sqrt(half_trace * half_trace - det)  # > 0: a compartment matrix's eigenvalues are distinct
        lam_big = half_trace - root  # the fast one (zone exchange)
        lam_small = det / lam_big if lam_big != 0.0 else 0.0  # the slow one, without cancellation
        e = _sylvester(m, lam_big, lam_small, lambda lam: math.exp(lam * dt_s))
        p = _sylvester(m, lam_big, lam_small, lambda lam: math.expm1(lam * dt_s) / lam if lam != 0.0 else dt_s)
        hit = self._cache[key] = Transition(e, p)
        return hit

    def inflow_per_volume(self, flows_ml_s: np.ndarray) -> np.ndarray:
        """The feeds' inflow of each component per bulk volume (mol/L/s) for flows (acid, base) in mL/s."""
        return (flows_ml_s @ self.feed_conc) / self.volume_ml

    def air_factor(self, dt_s: float) -> float:
        """exp(-kla dt): the carbonate's relaxation toward the air's level over a sample (the core's
        :mod:`ph_plant_sim.exchange` arithmetic, applied after the flow map)."""
        return math.exp(-self.air.kla_per_s * dt_s)


def _sylvester(m: np.ndarray, lam1: float, lam2: float, fn) -> np.ndarray:
    """fn(M) for a 2 x 2 matrix with distinct eigenvalues lam1, lam2 (Sylvester's formula)."""
    eye = np.eye(2)
    return (fn(lam1) * (m - lam2 * eye) - fn(lam2) * (m - lam1 * eye)) / (lam1 - lam2)
