"""The classifier's loop generator by class: historian compression, load ramps, labels by class."""

from __future__ import annotations

import numpy as np

from phfdi.loopdiag.synthetic import SyntheticLoop, compress, simulate_loop
from phfdi.loopdiag.training import LOOP_CLASSES, class_round_robin, draw_class_loops


def test_compression_holds_until_the_signal_moves_past_the_dead_band():
    x = np.array([0.0, 0.05, 0.09, 0.2, 0.25, 0.11, 0.12, -0.5])
    y = compress(x, 0.1)
    assert y.tolist() == [0.0, 0.0, 0.0, 0.2, 0.2, 0.2, 0.2, -0.5]


def test_a_load_ramp_enters_at_the_valve_and_the_controller_takes_it_back():
    base = dict(dt_s=4.0, duration_s=2000.0, noise_std=0.01, seed=3)
    plain = simulate_loop(SyntheticLoop(**base))
    ramp = simulate_loop(SyntheticLoop(load_ramps=[(400.0, 400.0, 3.0)], **base))
    # a load of +3 % at the valve: at the end the controller has closed OP by 3 % and PV is back
    assert abs(np.mean(ramp["op_pct"][-50:]) - np.mean(plain["op_pct"][-50:]) + 3.0) < 0.2
    assert abs(np.mean(ramp["pv"][-50:]) - np.mean(plain["pv"][-50:])) < 0.05
    # while the ramp runs PV is pushed off the setpoint
    assert np.max(ramp["pv"][100:250]) - 50.0 > 0.1


def test_each_class_drawn_in_order_and_only_sticky_valves_labelled_stiction():
    loops = draw_class_loops(class_round_robin(1), seed=5, prefix="T")
    assert [d.loop_class for d, _ in loops] == list(LOOP_CLASSES)
    for d, run in loops:
        assert d.stiction == (d.loop_class == "stiction")
        valve = d.spec.valve[0] if d.spec.valve else None
        if d.loop_class.startswith("healthy"):
            assert valve is None
        elif d.loop_class == "stiction":
            assert valve in ("stiction", "stiction_he")
        elif d.loop_class == "other_nonlinearity":
            assert valve in ("deadzone", "quantization", "saturation")
        else:
            assert valve == "backlash"
        assert np.all(np.isfinite(run["pv"])) and len(run["pv"]) == 751
    assert "load_steps" in loops[0][0].conditions  # healthy_load_steps
