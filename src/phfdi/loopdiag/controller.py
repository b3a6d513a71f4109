"""The loop's PI controller, estimated from SP, PV and OP (its action decides the process gain sign).

Velocity form of a PI controller sampled at the historian's interval
(trapezoidal integral, since the controller runs faster than the historian):

    OP(k) - OP(k-1) = Kc (e(k) - e(k-1)) + Kc dt / Ti (e(k) + e(k-1)) / 2,   e = SP - PV

Least squares on the differences. A reverse-acting controller (OP rises when PV
falls below SP) has Kc > 0 here and needs a process gain > 0 for negative
feedback; a direct-acting one the opposite. When the fit explains little of
OP's movement (R^2 below :data:`MIN_R2`: a cascade master, a controller with
filters or feed-forward, manual operation), the action is left undecided.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

#: share of OP's sample-to-sample movement the PI law must explain to be trusted
MIN_R2 = 0.3


@dataclass
class ControllerEstimate:
    kc: float
    ti_s: float
    r2: float
    action: str  # "reverse" (Kc > 0), "direct" (Kc < 0) or "unknown"

    @property
    def gain_sign(self) -> int:
        """Sign the process gain must have for negative feedback (0 when unknown)."""
        return {"reverse": 1, "direct": -1}.get(self.action, 0)

    def to_dict(self) -> dict:
        d = asdict(self)
        for k in ("kc", "ti_s", "r2"):
            v = d[k]
            d[k] = float(f"{v:.4g}") if math.isfinite(v) else None
        return d


def estimate_pi(op: np.ndarray, pv: np.ndarray, sp: np.ndarray | None, dt_s: float) -> ControllerEstimate:
    """Least-squares PI law from the data (see module docstring)."""
    e = (np.asarray(sp, float) if sp is not None else np.full(len(pv), float(np.mean(pv)))) - np.asarray(pv, float)
    du = np.diff(op)
    de = np.diff(e)
    ei = 0.5 * (e[1:] + e[:-1]) * dt_s
    design = np.column_stack([de, ei])
    den = float(du @ du)
    if den <= 0 or not np.any(design):
        return ControllerEstimate(math.nan, math.nan, 0.0, "unknown")
    (kc, ki), *_ = np.linalg.lstsq(design, du, rcond=None)
    r2 = 1.0 - float(np.sum((du - design @ np.array([kc, ki])) ** 2)) / den
    ti_s = kc / ki if ki != 0 and kc * ki > 0 else math.inf
    # the integral action sets the loop's direction; the proportional sign only when it agrees
    sign = np.sign(ki) if ki != 0 else np.sign(kc)
    action = "unknown"
    if r2 >= MIN_R2 and sign != 0:
        action = "reverse" if sign > 0 else "direct"
    return ControllerEstimate(float(kc), float(ti_s), float(r2), action)
