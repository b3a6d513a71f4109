"""valve_effect_on_pv: how far a valve moves PV, against the same loop with a linear valve, in noise levels."""

import math
from dataclasses import replace

import pytest

import valve_actuator.blocks  # noqa: F401  (registers the valve blocks)
from phfdi.loopdiag.domain import valve_effect_on_pv
from phfdi.loopdiag.synthetic import SyntheticLoop, simulate_loop

#: a loop whose random-walk load makes OP travel, so that a sticky valve breaks away
LOOP = SyntheticLoop(load_walk_std=0.3, duration_s=3000.0, seed=3)


def sticky(s_pct: float) -> SyntheticLoop:
    return replace(LOOP, valve=("stiction", {"s_pct": s_pct, "j_pct": s_pct}))


def test_a_vanishing_dead_band_moves_pv_by_nothing():
    # the difference is the valve's alone: the loads and noise draws are the same in both loops
    assert valve_effect_on_pv(sticky(1e-9)) == pytest.approx(0.0, abs=1e-9)


def test_a_larger_sticky_valve_moves_pv_further():
    effects = [valve_effect_on_pv(sticky(s)) for s in (0.2, 1.0, 4.0)]
    assert effects[0] < effects[1] < effects[2]
    assert effects[0] > 0.0
    assert effects[2] > 5.0  # a 4 % dead-band on this loop: far above the noise


def test_the_run_at_hand_gives_the_same_effect():
    spec = sticky(1.0)
    assert valve_effect_on_pv(spec, simulate_loop(spec)) == valve_effect_on_pv(spec)


def test_in_units_of_the_noise():
    spec = sticky(1.0)
    quiet = replace(spec, noise_std=spec.noise_std / 2)
    # half the noise: the valve's effect is the same in PV units, twice as many noise levels
    # (the noise draws scale, the loop's response to them too, so equal only to a tolerance)
    assert valve_effect_on_pv(quiet) == pytest.approx(2 * valve_effect_on_pv(spec), rel=0.25)
    assert math.isinf(valve_effect_on_pv(replace(spec, noise_std=0.0)))
