"""Tanks in series: a vessel whose contents move from inlet to outlet more like plug flow than one stirred volume.

The classic residence-time model of a poorly back-mixed vessel (Levenspiel, ch. 14): the vessel's volume V split
into ``n_tanks`` equal, perfectly mixed compartments in series. Every feed enters the first, the flow passes from
each to the next, and the outlet and the probe are at the last. One compartment is the stirred tank; many
approach plug flow (a dead time V / q). With concentrations c_i and total inflow q held over a sample:

    (V / n) dc_1/dt = sum_j q_j c_feed_j - q c_1
    (V / n) dc_i/dt = q (c_i-1 - c_i),  i = 2..n

Linear in the concentrations, so each sample is exact through the matrix exponential of the augmented system
(scipy.linalg.expm), shared by all components; samples with the same flows share it. An overflow vessel only
(constant volume): a gravity tank's changing volume would change every compartment's.

:class:`SeriesPlant` composes a :class:`CstrPlant` (the vessel's volume, outlet and balances) with the
compartments, so the loop, the node graph and the diagnosis run it unchanged.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from .plant import CstrPlant


@dataclass(frozen=True)
class TanksInSeries:
    """Number of equal, perfectly mixed compartments the vessel's volume is split into (1: a stirred tank)."""

    n_tanks: int

    def __post_init__(self) -> None:
        if not (isinstance(self.n_tanks, int) and 1 <= self.n_tanks <= 50):
            raise ValueError(f"n_tanks must be an integer from 1 to 50, got {self.n_tanks!r}")


def series_transition(n_tanks: int, flows_ml_s: np.ndarray, volume_ml: float,
                      dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """One sample's map c' = A c + B c_feed (inputs held): A (n, n), B (n, n_feeds)."""
    q = np.asarray(flows_ml_s, dtype=float)
    n_f = len(q)
    rate = float(q.sum()) * n_tanks / volume_ml
    m = np.zeros((n_tanks + n_f, n_tanks + n_f))
    for i in range(n_tanks):
        m[i, i] = -rate
        if i > 0:
            m[i, i - 1] = rate
    m[0, n_tanks:] = q * n_tanks / volume_ml
    from scipy.linalg import expm  # here: only plants with compartments pay for importing scipy.linalg

    e = expm(m * dt_s)
    return e[:n_tanks, :n_tanks], e[:n_tanks, n_tanks:]


#: per-sample maps already computed (a fit re-simulates the same record many times)
_TRANSITIONS: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}


def series_trajectory(series: TanksInSeries, feed_conc: np.ndarray, flows_ml_s: np.ndarray, volume_ml: float,
                      dt_s: float, conc0: np.ndarray) -> np.ndarray:
    """Concentrations of the last compartment (the outlet, where the probe is), (N + 1, n_components), over a
    record of held flows (N, n_feeds), every compartment starting at ``conc0`` (mol/L)."""
    flows = np.asarray(flows_ml_s, dtype=float)
    n = len(flows)
    conc_feed = np.asarray(feed_conc, dtype=float)
    x = np.tile(np.asarray(conc0, dtype=float), (series.n_tanks, 1))  # (n_tanks, m)
    out = np.empty((n + 1, x.shape[1]))
    out[0] = x[-1]
    if len(_TRANSITIONS) > 20000:
        _TRANSITIONS.clear()
    tag = (series.n_tanks, float(volume_ml), dt_s, conc_feed.tobytes())
    change = np.flatnonzero(np.any(flows[1:] != flows[:-1], axis=1)) + 1
    bounds = np.r_[0, change, n]
    for k0, k1 in zip(bounds[:-1].tolist(), bounds[1:].tolist()):
        key = (tag, *flows[k0].tolist())
        hit = _TRANSITIONS.get(key)
        if hit is None:
            a, b = series_transition(series.n_tanks, flows[k0], volume_ml, dt_s)
            hit = _TRANSITIONS[key] = (a, b @ conc_feed)
        a, c = hit
        for k in range(k0, k1):
            x = a @ x + c
            out[k + 1] = x[-1]
    return out


def stepped_simulate_flows(plant, flows_ml_s: np.ndarray, openings: np.ndarray | float,
                           dt_s: float) -> dict[str, np.ndarray]:
    """:meth:`CstrPlant.simulate_flows` of a composed plant (compartments, air exchange) by stepping it sample by
    sample: the same outputs (``volume_ml``, ``level_cm``, ``conc_mol_l`` of the vessel, ``ph`` at the probe)."""
    flows = np.asarray(flows_ml_s, dtype=float)
    n = len(flows)
    open_arr = np.broadcast_to(np.asarray(openings, dtype=float), (n,))
    vol, conc, ph = np.empty(n + 1), np.empty((n + 1, plant.bulk.n_comp)), np.empty(n + 1)
    vol[0], conc[0], ph[0] = plant.volume_ml, plant.bulk.concentrations, plant.ph
    for k in range(n):
        plant.step(flows[k].tolist(), float(open_arr[k]), dt_s)
        vol[k + 1], conc[k + 1], ph[k + 1] = plant.volume_ml, plant.bulk.concentrations, plant.ph
    return {"volume_ml": vol, "level_cm": vol / plant.bulk.tank.area_cm2, "conc_mol_l": conc, "ph": ph}


class SeriesPlant:
    """An overflow vessel as compartments in series: the probe reads the last one.

    Exposes what the loop uses of a plant (``step``, ``ph``, ``level_cm``, steady states, ...); everything not
    about composition is the vessel's (:class:`CstrPlant`), whose amounts are kept as the compartments' total.
    """

    def __init__(self, vessel: CstrPlant, series: TanksInSeries) -> None:
        if not vessel.tank.overflow or vessel.tank.volume_ml is None:
            raise ValueError("tanks in series: modelled for an overflow vessel (constant volume) only")
        self.bulk = vessel
        self.series = series
        self.tanks = np.zeros((series.n_tanks, vessel.n_comp))
        self.outlet_ph = vessel.ph

    def __getattr__(self, name: str):
        return getattr(self.bulk, name)

    @property
    def ph(self) -> float:
        """pH at the probe (the last compartment)."""
        return self.outlet_ph

    def _sync(self) -> None:
        s = self.bulk.state
        s.amounts_mmol = (self.tanks.mean(axis=0) * s.volume_ml).tolist()
        s.ph = self.bulk.balance.ph(self.tanks.mean(axis=0).tolist(), guess=s.ph)
        self.outlet_ph = self.bulk.balance.ph(self.tanks[-1].tolist(), guess=self.outlet_ph)

    def set_state(self, conc_mol_l: Sequence[float], level_cm: float | None = None) -> None:
        self.bulk.set_state(conc_mol_l, level_cm)
        self.tanks = np.tile(np.asarray(conc_mol_l, dtype=float), (self.series.n_tanks, 1))
        self.outlet_ph = self.bulk.ph

    def set_steady_state(self, flows_ml_s: Sequence[float], outlet_opening: float = 1.0) -> None:
        self.bulk.set_steady_state(flows_ml_s, outlet_opening)
        self.tanks = np.tile(np.asarray(self.bulk.concentrations, dtype=float), (self.series.n_tanks, 1))
        self.outlet_ph = self.bulk.ph

    def simulate_flows(self, flows_ml_s: np.ndarray, openings: np.ndarray | float, dt_s: float) -> dict:
        return stepped_simulate_flows(self, flows_ml_s, openings, dt_s)

    def step(self, flows_ml_s: Sequence[float], outlet_opening: float, dt_s: float) -> None:
        """Advance the vessel (volume, in- and out-flow totals) and the compartments (exact per sample)."""
        a, b = series_transition(self.series.n_tanks, np.asarray(flows_ml_s, float), self.bulk.state.volume_ml,
                                 dt_s)
        self.tanks = a @ self.tanks + b @ np.asarray(self.bulk.feed_conc, dtype=float)
        self.bulk.step(flows_ml_s, outlet_opening, dt_s)
        self._sync()
