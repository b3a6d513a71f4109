"""Plant dynamics: accuracy against scipy, conservation, batch = step."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from ph_plant_sim.build import build_plant, load_plant_model


def _flows_profile(n, seed=0):
    rng = np.random.default_rng(seed)
    acid = np.clip(16.6 + np.cumsum(rng.normal(0, 0.3, n)), 5, 30)
    return np.column_stack([acid, np.full(n, 0.55), np.full(n, 15.6)])


def test_gravity_tank_matches_reference_integrator():
    """Held-input RK4 steps vs scipy's DOP853 at rtol 1e-12 over 2000 s of stepped inflow."""
    plant = build_plant(load_plant_model("henson_seborg"))
    plant.set_steady_state([16.6, 0.55, 15.6])
    hold = 50  # inputs change every 50 samples, so the reference integrates 50 s at a time
    flows = np.repeat(_flows_profile(40), hold, axis=0)
    y = np.array([plant.volume_ml] + list(plant.state.amounts_mmol), dtype=float)
    out = plant.simulate_flows(flows, 1.0, 1.0)
    outlet, area, fc = plant.tank.outlet, plant.tank.area_cm2, np.asarray(plant.feed_conc)

    for seg in range(40):
        q = flows[seg * hold]

        def rhs(t, y, q=q):
            qo = outlet.flow(y[0] / area, 1.0)
            return np.concatenate([[q.sum() - qo], q @ fc - qo * y[1:] / y[0]])

        y = solve_ivp(rhs, (0.0, float(hold)), y, method="DOP853", rtol=1e-12, atol=1e-15).y[:, -1]
        k = (seg + 1) * hold
        assert out["volume_ml"][k] == pytest.approx(y[0], rel=1e-9)
        assert out["conc_mol_l"][k] == pytest.approx(y[1:] / y[0], rel=1e-8, abs=1e-14)


@pytest.mark.parametrize("preset", ["henson_seborg", "rig_flask"])
def test_volume_and_invariants_balance_in_minus_out(preset):
    """Liquid volume and every component: change = in-flow - out-flow, to 1e-9 relative."""
    plant = build_plant(load_plant_model(preset))
    n_feeds = len(plant.feeds)
    flows = np.abs(_flows_profile(3000, seed=1)[:, :n_feeds]) * (0.1 if preset == "rig_flask" else 1.0)
    plant.set_steady_state(list(flows[0]))
    v0, n0 = plant.volume_ml, np.array(plant.state.amounts_mmol)
    for q in flows:
        plant.step(list(q), 1.0, 1.0)
    s = plant.state
    dv = s.volume_ml - v0
    assert dv == pytest.approx(s.volume_in_ml - s.volume_out_ml, rel=1e-9, abs=1e-9 * s.volume_in_ml)
    dn = np.array(s.amounts_mmol) - n0
    bal = np.array(s.amounts_in_mmol) - np.array(s.amounts_out_mmol)
    scale = np.array(s.amounts_in_mmol) + 1e-30
    assert np.all(np.abs(dn - bal) <= 1e-9 * scale)
    # the in-flows are an independent account of what went in
    assert s.volume_in_ml == pytest.approx(flows.sum(), rel=1e-12)


def test_batch_equals_step():
    plant_a = build_plant(load_plant_model("paper"))
    plant_b = build_plant(load_plant_model("paper"))
    flows = np.column_stack([np.linspace(8, 30, 1500), np.full(1500, 2.0), np.full(1500, 15.6)])
    opening = np.linspace(0.4, 0.7, 1500)
    for p in (plant_a, plant_b):
        p.set_steady_state(list(flows[0]), 0.4)
    out = plant_a.simulate_flows(flows, opening, 1.0)
    phs = [plant_b.ph]
    for q, o in zip(flows, opening):
        plant_b.step(list(q), o, 1.0)
        phs.append(plant_b.ph)
    assert np.max(np.abs(out["ph"] - np.array(phs))) < 1e-9
    assert plant_a.volume_ml == pytest.approx(plant_b.volume_ml, rel=1e-14)


def test_overflow_vessel_keeps_its_volume():
    model = load_plant_model("rig_flask")
    plant = build_plant(model)
    plant.set_steady_state([0.5, 0.4])
    ph_start = plant.ph
    for _ in range(400):
        plant.step([2.0, 0.02], 1.0, 5.0)  # acid-rich inflow
    assert plant.volume_ml == model.tank.volume_ml  # exactly: the overflow takes all the inflow
    assert plant.ph < ph_start - 1.0
