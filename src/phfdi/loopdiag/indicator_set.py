"""Every stiction indicator of one loop, by name (what :mod:`.classifier` combines)."""

from __future__ import annotations

import numpy as np

from .baselines import he_curve_fit, horch_ccf
from .bicoherence import apparent_stiction, ngi_nli
from .deadband import deadband_evidence
from .indicators import Indicator, area_peak_ratio, kano_stuck_index, not_applicable, relay_shape
from .stickslip import stick_slip_index

HORCH_CCF_REF = "Horch (1999), Control Eng. Practice 7, 1221-1231: OP-PV cross-correlation odd = stiction"
HE_REF = "He, Wang, Pottmann & Qin (2007), Ind. Eng. Chem. Res. 46, 4549-4560: triangle vs sinusoid fit"


def compute_indicators(op: np.ndarray, pv: np.ndarray, sp: np.ndarray | None, dt_s: float,
                       process_type: str) -> dict[str, Indicator]:
    """The published indicators and this project's dead-band screen (:mod:`.deadband`); the full valve-model
    fit with Kano's S and J comes from :mod:`.hammerstein` separately, for the loops the screen flags.

    Horch's derivative histogram (:func:`.indicators.horch_histogram`) is left out: on the simulated training
    loops the classifier does as well without it (cross-validated log-loss 0.5763 both ways, recall at the
    operating point 0.336 against 0.340), and it took a third of the screen's time."""
    out: dict[str, Indicator] = {}
    h = horch_ccf(op, pv, sp, dt_s, process_type)
    out["horch_ccf"] = (Indicator("horch_ccf", h.index, h.decision, dict(h.detail), HORCH_CCF_REF)
                        if h.index is not None else
                        not_applicable("horch_ccf", str(h.detail.get("reason", h.decision)), HORCH_CCF_REF))
    he = he_curve_fit(op, pv, sp, dt_s, process_type)
    out["he_curve_fit"] = (Indicator("he_curve_fit", he.index, he.decision, dict(he.detail), HE_REF)
                           if he.index is not None else
                           not_applicable("he_curve_fit", str(he.detail.get("reason", he.decision)), HE_REF))
    out["kano_stuck"] = kano_stuck_index(op, pv, dt_s, process_type)
    out["stick_slip"] = stick_slip_index(op, pv, dt_s, process_type)
    out["area_peak_ratio"] = area_peak_ratio(pv, sp, dt_s, process_type)
    out["relay_shape"] = relay_shape(pv, sp, dt_s, process_type)
    ngi, nli = ngi_nli(pv, sp, dt_s)
    out["bicoherence_ngi"] = ngi
    out["bicoherence_nli"] = nli
    out["ellipse_apparent_stiction"] = apparent_stiction(op, pv, sp, dt_s)
    out["deadband_evidence"] = deadband_evidence(op, pv, process_type)
    return out
