"""The vectorised per-record sample maps agree with the plant's sequential ones."""

from __future__ import annotations

import numpy as np
import pytest

from ph_plant_sim.build import build_plant, load_plant_model
from ph_plant_sim.plant import _sequential_maps, affine_recurrence, record_sample_maps


def _inputs(rng, n, level=34.0):
    q = level + np.repeat(rng.uniform(-6.0, 6.0, n // 50 + 1), 50)[:n]
    op = np.repeat(rng.uniform(0.45, 0.55, n // 50 + 1), 50)[:n]
    return np.maximum(q, 0.5), op


@pytest.mark.parametrize("dt_s", [1.0, 7.0])
def test_gravity_maps_match_sequential(dt_s):
    plant = build_plant(load_plant_model("paper"))
    q, op = _inputs(np.random.default_rng(1), 3000)
    vol, coef = record_sample_maps(plant.tank, 2600.0, q, op, dt_s)
    vol_s, coef_s = _sequential_maps(plant.tank, 2600.0, q, op, dt_s)
    assert np.max(np.abs(vol - vol_s) / vol_s) < 1e-12
    assert np.max(np.abs(coef - coef_s) / np.maximum(np.abs(coef_s), 1e-30)) < 1e-12


def test_gravity_maps_with_a_guess_and_sub_steps():
    plant = build_plant(load_plant_model("paper"))
    q, op = _inputs(np.random.default_rng(2), 400)
    # a sample long enough for several RK4 sub-steps (rate * dt > 0.05)
    vol, coef = record_sample_maps(plant.tank, 2600.0, q, op, 30.0)
    vol_s, coef_s = _sequential_maps(plant.tank, 2600.0, q, op, 30.0)
    assert np.max(np.abs(vol - vol_s) / vol_s) < 1e-12
    guess = vol * 1.01
    vol_g, _ = record_sample_maps(plant.tank, 2600.0, q, op, 30.0, volume_guess_ml=guess)
    assert np.max(np.abs(vol_g - vol_s) / vol_s) < 1e-12


def test_overflow_maps_and_amounts_match_simulate_flows():
    plant = build_plant(load_plant_model("rig_flask"))
    rng = np.random.default_rng(3)
    n = 2000
    flows = np.column_stack([np.repeat(rng.uniform(0, 5, n // 100), 100), np.repeat(rng.uniform(0, 6, n // 100), 100)])
    flows[:100] = 0.0  # no inflow: the state holds
    plant.set_state(plant.mixed_inflow([1.0, 1.0]))
    a0 = list(plant.state.amounts_mmol)
    ref = plant.simulate_flows(flows, 1.0, 0.35)
    vol, coef = record_sample_maps(plant.tank, plant.tank.volume_ml, flows.sum(axis=1), 1.0, 0.35)
    inflow = flows @ np.asarray(plant.feed_conc)
    amounts = affine_recurrence(coef[:, 0], coef[:, 1:2] * inflow, np.asarray(a0))
    amounts_loop = [np.asarray(a0)]
    for k in range(n):  # the recursion of simulate_flows, one sample at a time
        amounts_loop.append(coef[k, 0] * amounts_loop[-1] + coef[k, 1] * inflow[k])
    amounts_loop = np.array(amounts_loop)
    conc = amounts / vol[:, None]
    assert np.max(np.abs(conc - ref["conc_mol_l"]) / np.max(np.abs(ref["conc_mol_l"]))) < 1e-12
    assert np.max(np.abs(amounts - amounts_loop)) < 1e-12 * np.max(np.abs(amounts_loop))


def test_affine_recurrence_small_gains_fall_back_to_steps():
    rng = np.random.default_rng(4)
    g = rng.uniform(0.0, 1e-3, 600)  # products underflow within a chunk
    d = rng.normal(size=600)
    x = affine_recurrence(g, d, 2.0)
    ref = [2.0]
    for gk, dk in zip(g, d):
        ref.append(gk * ref[-1] + dk)
    assert np.allclose(x, ref, rtol=1e-12, atol=1e-14)
