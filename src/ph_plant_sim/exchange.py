"""Exchange of one dissolved component with the air above an open vessel: CO2 absorbed or stripped.

An open, stirred vessel takes up CO2 from the air (or loses it) through its surface. As a first-order
mass-transfer term on the component's total concentration C (mol/L) toward an equilibrium level C_eq:

    dn/dt = (flow terms of the vessel) + kla V (C_eq - n / V)

with ``kla_per_s`` the volumetric mass-transfer coefficient (1/s) and ``equilibrium_mol_l`` the level the
vessel's liquid would reach without flow. (A simplification: the true driving force is the dissolved CO2
itself, a pH-dependent fraction of the total; the first-order form is the one a fit to pH data can carry.)

Per sample, after the vessel's own exact flow map, the component relaxes toward the equilibrium over the sample:
n' = V C_eq + (n - V C_eq) exp(-kla dt) (operator splitting; its error is of order kla (q / V) dt^2, below 1e-4
of the exchanged amount at the rig's rates and 1 s samples). The diagnosis (phfdi.diagnosis.model) runs the
same arithmetic over a whole record as one affine recurrence.

:class:`ExchangePlant` composes a :class:`CstrPlant` with the exchange, so the loop runs it unchanged.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from .plant import CstrPlant
from .series import stepped_simulate_flows


@dataclass(frozen=True)
class AirExchange:
    """Which component exchanges with the air, how fast (1/s) and toward which level (mol/L)."""

    component: str
    kla_per_s: float
    equilibrium_mol_l: float

    def __post_init__(self) -> None:
        for name in ("kla_per_s", "equilibrium_mol_l"):
            v = getattr(self, name)
            if not (v >= 0.0 and math.isfinite(v)):
                raise ValueError(f"air exchange: {name} must be non-negative and finite, got {v}")

    def steady_conc(self, feed_rate_mmol_s: float, q_in_ml_s: float, volume_ml: float) -> float:
        """The component's steady concentration (mol/L) under constant flows: inflow and air against outflow."""
        k_v = self.kla_per_s * volume_ml
        denom = q_in_ml_s + k_v
        return (feed_rate_mmol_s + k_v * self.equilibrium_mol_l) / denom if denom > 0 else self.equilibrium_mol_l


def exchange_recurrence(exchange: AirExchange, coef: np.ndarray, inflow_mmol_s: np.ndarray, volume_ml: np.ndarray,
                        dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """The exchanging component's per-sample map n_k+1 = gain_k n_k + drive_k over a record: the vessel's flow
    map (``coef`` (N, 4) = (a, b, oa, ob) of :meth:`CstrPlant.sample_map`), then the relaxation."""
    e = math.exp(-exchange.kla_per_s * dt_s)
    gain = e * coef[:, 0]
    drive = e * coef[:, 1] * inflow_mmol_s + (1.0 - e) * np.asarray(volume_ml)[1:] * exchange.equilibrium_mol_l
    return gain, drive


class ExchangePlant:
    """A vessel one of whose components exchanges with the air (:class:`AirExchange`)."""

    def __init__(self, vessel: CstrPlant, exchange: AirExchange) -> None:
        names = [c.name for c in vessel.chemistry.components]
        if exchange.component not in names:
            raise ValueError(f"air exchange: no component {exchange.component!r} (components: {', '.join(names)})")
        self.bulk = vessel
        self.exchange = exchange
        self.index = names.index(exchange.component)

    def __getattr__(self, name: str):
        return getattr(self.bulk, name)

    def steady_component(self, flows_ml_s: Sequence[float], volume_ml: float) -> float:
        rate = sum(q * c[self.index] for q, c in zip(flows_ml_s, self.bulk.feed_conc))
        return self.exchange.steady_conc(rate, float(sum(flows_ml_s)), volume_ml)

    def set_steady_state(self, flows_ml_s: Sequence[float], outlet_opening: float = 1.0) -> None:
        """The vessel's steady state, the exchanging component at its own steady level (inflow and air)."""
        self.bulk.set_steady_state(flows_ml_s, outlet_opening)
        s = self.bulk.state
        s.amounts_mmol[self.index] = self.steady_component(flows_ml_s, s.volume_ml) * s.volume_ml
        s.ph = self.bulk.balance.ph(self.bulk.concentrations, guess=s.ph)

    def simulate_flows(self, flows_ml_s: np.ndarray, openings: np.ndarray | float, dt_s: float) -> dict:
        return stepped_simulate_flows(self, flows_ml_s, openings, dt_s)

    def step(self, flows_ml_s: Sequence[float], outlet_opening: float, dt_s: float) -> None:
        self.bulk.step(flows_ml_s, outlet_opening, dt_s)
        s = self.bulk.state
        target = s.volume_ml * self.exchange.equilibrium_mol_l
        e = math.exp(-self.exchange.kla_per_s * dt_s)
        s.amounts_mmol[self.index] = target + (s.amounts_mmol[self.index] - target) * e
        s.ph = self.bulk.balance.ph(self.bulk.concentrations, guess=s.ph)
