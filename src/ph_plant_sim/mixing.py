"""Imperfect mixing: a small zone around the inlets and the probe that exchanges with the bulk.

A stirred vessel is rarely one perfectly mixed volume: reagent dosed next to
the electrode reaches it before it is diluted in the bulk. The model here is
the classic two-compartment one: a zone of fixed volume ``zone_volume_ml``
that receives the feeds listed in ``feeds`` and exchanges ``exchange_ml_s``
with the bulk both ways; the zone's own inflow passes on to the bulk, the
other feeds enter the bulk directly, the outlet draws from the bulk, and the
probe reads the zone. With concentrations z (zone) and b (bulk), inputs held
over a sample:

    Vz dz/dt = sum_{j in zone} q_j c_j + Qx b - (Qx + q_zone) z
    V  db/dt = sum_{j not in zone} q_j c_j + (Qx + q_zone) z - (Qx + q_in) b

(the bulk's dilution by its own volume change is folded in: V dV/dt terms
cancel to ``q_in``). The system is linear in the concentrations, so each
sample is exact through the matrix exponential of the augmented system
(scipy.linalg.expm), shared by all components; samples with the same flows
and volume share it. A very large exchange flow is the perfectly mixed
vessel (tests check). The bulk's volume follows the vessel's own law
(:class:`~ph_plant_sim.plant.CstrPlant`), the zone's is constant.

:class:`ZonedPlant` composes a :class:`CstrPlant` (the bulk) with the zone,
so the loop, the node graph and the diagnosis run a zoned vessel unchanged.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from .plant import CstrPlant


@dataclass(frozen=True)
class MixingZone:
    """Zone volume (mL), exchange flow with the bulk (mL/s) and the feeds that enter the zone."""

    zone_volume_ml: float
    exchange_ml_s: float
    feeds: tuple[str, ...]

    def __post_init__(self) -> None:
        if not (self.zone_volume_ml > 0 and math.isfinite(self.zone_volume_ml)):
            raise ValueError(f"zone_volume_ml must be positive, got {self.zone_volume_ml}")
        if not (self.exchange_ml_s >= 0 and math.isfinite(self.exchange_ml_s)):
            raise ValueError(f"exchange_ml_s must be non-negative, got {self.exchange_ml_s}")


def zone_transition(zone: MixingZone, in_zone: np.ndarray, flows_ml_s: np.ndarray, bulk_volume_ml: float,
                    dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """One sample's map [z, b]' = A [z, b] + B feed_conc, inputs held: returns A (2, 2) and B (2, n_feeds)."""
    vz, qx = zone.zone_volume_ml, zone.exchange_ml_s
    q = np.asarray(flows_ml_s, dtype=float)
    q_zone = float(q @ in_zone)
    q_in = float(q.sum())
    n_f = len(q)
    m = np.zeros((2 + n_f, 2 + n_f))
    m[0, 0] = -(qx + q_zone) / vz
    m[0, 1] = qx / vz
    m[1, 0] = (qx + q_zone) / bulk_volume_ml
    m[1, 1] = -(qx + q_in) / bulk_volume_ml
    m[0, 2:] = q * in_zone / vz
    m[1, 2:] = q * (1.0 - in_zone) / bulk_volume_ml
    from scipy.linalg import expm  # here: only plants with a mixing zone pay for importing scipy.linalg

    e = expm(m * dt_s)
    return e[:2, :2], e[:2, 2:]


def zone_trajectory(zone: MixingZone, feed_names: Sequence[str], feed_conc: np.ndarray, flows_ml_s: np.ndarray,
                    bulk_volume_ml: np.ndarray, dt_s: float, conc0: np.ndarray,
                    zone_conc0: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Zone and bulk concentrations (N + 1, n_components) over a record of held flows (N, n_feeds).

    ``bulk_volume_ml``: (N + 1,) the bulk's volume (the vessel's law); ``conc0``: the bulk's and, unless
    ``zone_conc0`` is given, the zone's starting composition (mol/L).
    """
    unknown = [f for f in zone.feeds if f not in feed_names]
    if unknown:
        raise ValueError(f"mixing zone: no feed {unknown[0]!r} (feeds: {', '.join(feed_names)})")
    in_zone = np.array([1.0 if f in zone.feeds else 0.0 for f in feed_names])
    flows = np.asarray(flows_ml_s, dtype=float)
    n = len(flows)
    conc_feed = np.asarray(feed_conc, dtype=float)  # (n_feeds, m)
    x = np.vstack([conc0 if zone_conc0 is None else zone_conc0, conc0]).astype(float)  # (2, m)
    zone_c = np.empty((n + 1, x.shape[1]))
    bulk_c = np.empty((n + 1, x.shape[1]))
    zone_c[0], bulk_c[0] = x
    cache: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}
    for k in range(n):
        key = (*flows[k].tolist(), round(float(bulk_volume_ml[k]), 9))
        hit = cache.get(key)
        if hit is None:
            a, b = zone_transition(zone, in_zone, flows[k], float(bulk_volume_ml[k]), dt_s)
            hit = cache[key] = (a, b @ conc_feed)
        x = hit[0] @ x + hit[1]
        zone_c[k + 1], bulk_c[k + 1] = x
    return zone_c, bulk_c


class ZonedPlant:
    """A vessel with a mixing zone: the bulk is a :class:`CstrPlant`, the probe reads the zone.

    Exposes what the loop uses of a plant (``step``, ``ph``, ``level_cm``,
    steady states, ...); everything not about composition is the bulk's.
    """

    def __init__(self, bulk: CstrPlant, zone: MixingZone) -> None:
        self.bulk = bulk
        self.zone = zone
        names = [f.name for f in bulk.feeds]
        unknown = [f for f in zone.feeds if f not in names]
        if unknown:
            raise ValueError(f"mixing zone: no feed {unknown[0]!r} (feeds: {', '.join(names)})")
        self.in_zone = np.array([1.0 if n in zone.feeds else 0.0 for n in names])
        self.zone_conc = list(bulk.concentrations) if bulk.state.amounts_mmol else []
        self.zone_ph = bulk.ph

    def __getattr__(self, name: str):
        return getattr(self.bulk, name)

    @property
    def ph(self) -> float:
        """pH at the probe (the zone)."""
        return self.zone_ph

    def set_state(self, conc_mol_l: Sequence[float], level_cm: float | None = None) -> None:
        self.bulk.set_state(conc_mol_l, level_cm)
        self.zone_conc = list(conc_mol_l)
        self.zone_ph = self.bulk.ph

    def set_steady_state(self, flows_ml_s: Sequence[float], outlet_opening: float = 1.0) -> None:
        self.bulk.set_steady_state(flows_ml_s, outlet_opening)
        self.zone_conc = list(self.bulk.concentrations)
        self.zone_ph = self.bulk.ph

    def step(self, flows_ml_s: Sequence[float], outlet_opening: float, dt_s: float) -> None:
        """Advance the bulk's volume by the vessel's law and both compositions by the zone model.

        The bulk's cumulative out-flow amounts (balance checks) stay those of a perfectly mixed bulk.
        """
        v0 = self.bulk.volume_ml
        x = np.vstack([self.zone_conc, self.bulk.concentrations])
        a, b = zone_transition(self.zone, self.in_zone, np.asarray(flows_ml_s, float), v0, dt_s)
        x = a @ x + b @ np.asarray(self.bulk.feed_conc, dtype=float)
        self.bulk.step(flows_ml_s, outlet_opening, dt_s)
        s = self.bulk.state
        s.amounts_mmol = (x[1] * s.volume_ml).tolist()
        s.ph = self.bulk.balance.ph(x[1].tolist(), guess=s.ph)
        self.zone_conc = x[0].tolist()
        self.zone_ph = self.bulk.balance.ph(self.zone_conc, guess=self.zone_ph)
