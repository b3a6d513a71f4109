"""Chemistry: Henson-Seborg steady state, pH solver, titration curves."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import brentq

from ph_plant_sim.build import build_plant, load_plant_model
from ph_plant_sim.chemistry import COMPONENTS, ChargeBalance, Chemistry

HS_FLOWS = [16.6, 0.55, 15.6]  # acid, buffer, base (mL/s)


def test_henson_seborg_steady_state():
    """Henson & Seborg (1994): q1=16.6, q2=0.55, q3=15.6 mL/s -> h = 14.0 cm, pH 7.03."""
    plant = build_plant(load_plant_model("henson_seborg"))
    plant.set_steady_state(HS_FLOWS, outlet_opening=1.0)
    assert plant.level_cm == pytest.approx(14.0, abs=0.05)
    assert plant.ph == pytest.approx(7.03, abs=0.005)
    conc = dict(zip(plant.chemistry.names, plant.concentrations))
    wa4 = conc["nitrate"] - conc["sodium"]
    wb4 = conc["carbonate"]
    assert wa4 == pytest.approx(-4.36e-4, rel=2e-3)
    assert wb4 == pytest.approx(5.28e-4, rel=2e-3)


def test_henson_seborg_charge_balance_matches_their_equation():
    """Our general residual equals HS's own charge balance written with Wa, Wb."""
    chem = Chemistry.for_streams([{"HNO3": 1.0}, {"NaHCO3": 1.0}])
    cb = chem.charge_balance()
    wa, wb = -4.36e-4, 5.28e-4
    conc = {"nitrate": 0.0, "sodium": -wa, "carbonate": wb}
    vec = [conc[n] for n in chem.names]
    for ph in (3.0, 6.35, 7.03, 9.0, 11.0):
        hs = (wa + 10 ** (ph - 14) - 10 ** (-ph)
              + wb * (1 + 2 * 10 ** (ph - 10.25)) / (1 + 10 ** (6.35 - ph) + 10 ** (ph - 10.25)))
        ours, _ = cb.residual(ph, vec)
        assert ours == pytest.approx(-hs, abs=1e-15)


def _random_chemistry():
    comps = [COMPONENTS[n] for n in ("sodium", "nitrate", "carbonate", "sulfate", "phosphate", "ammonium", "acetate")]
    return ChargeBalance(comps), comps


@settings(max_examples=3000, deadline=None)
@given(conc=st.lists(st.floats(0.0, 0.2), min_size=7, max_size=7),
       guess=st.floats(0.0, 14.0))
def test_ph_solver_agrees_with_brentq_on_random_invariants(conc, guess):
    """Thousands of random physically valid invariants: finite, in range, equal to scipy's brentq."""
    cb, _ = _random_chemistry()
    ph = cb.ph(conc, guess=guess)
    assert math.isfinite(ph) and 0.0 <= ph <= 14.0
    f0, _ = cb.residual(0.0, conc)
    f14, _ = cb.residual(14.0, conc)
    if f0 > 0 > f14:
        ref = brentq(lambda x: cb.residual(x, conc)[0], 0.0, 14.0, xtol=1e-13)
        assert ph == pytest.approx(ref, abs=1e-8)
    elif f0 <= 0:
        assert ph == 0.0  # root below pH 0: clamped
    else:
        assert ph == 14.0


def test_vectorised_solver_equals_scalar():
    rng = np.random.default_rng(3)
    cb, _ = _random_chemistry()
    conc = rng.uniform(0, 0.1, size=(500, 7))
    vec = cb.ph_array(conc)
    scal = np.array([cb.ph(list(c)) for c in conc])
    assert np.max(np.abs(vec - scal)) < 1e-8


@pytest.mark.parametrize("acid", ["HNO3", "H2SO4"])
def test_titration_curve_is_monotone(acid):
    """Adding base to an acid never lowers the pH."""
    chem = Chemistry.for_streams([{acid: 0.01}, {"NaOH": 0.01}, {"NaHCO3": 0.001}])
    cb = chem.charge_balance()
    acid_c = chem.concentrations({acid: 0.01})
    base_c = chem.concentrations({"NaOH": 0.01})
    buf_c = chem.concentrations({"NaHCO3": 0.001})
    ratios = np.linspace(0, 1, 2001)
    phs = []
    for r in ratios:
        mix = [(1 - r) * a + r * b + 0.05 * c for a, b, c in zip(acid_c, base_c, buf_c)]
        phs.append(cb.ph(mix))
    assert np.all(np.diff(phs) >= -1e-12)
    assert phs[0] < 3.0 and phs[-1] > 11.0


def test_sulfuric_acid_is_diprotic():
    """0.01 M H2SO4: pH about 1.84 (second dissociation pKa 1.99), not 1.70 (fully) nor 2.0 (monoprotic)."""
    chem = Chemistry.for_streams([{"H2SO4": 0.01}])
    ph = chem.charge_balance().ph(chem.concentrations({"H2SO4": 0.01}))
    assert 1.78 < ph < 1.90


def test_unknown_compound_is_named():
    with pytest.raises(ValueError, match="unknown compound 'HF'"):
        Chemistry.for_streams([{"HF": 0.1}])
