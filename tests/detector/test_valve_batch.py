"""Valve.step_many (core addition for the replaying reference) gives what step gives per sample."""

from __future__ import annotations

import numpy as np
import pytest

import valve_actuator.blocks  # noqa: F401  (registers blocks)
from phfdi_base.blocks import Chain, Injected, make_block
from valve_actuator.valve import Valve


def make(char: str, block: str | None, leak: bool) -> Valve:
    params = {"backlash": {"width_pct": 2.0}, "stiction": {"s_pct": 1.5, "j_pct": 0.5}}
    pb = Chain([Injected(make_block(block, params[block], dt_s=1.0), 50.0)] if block else [])
    fb = Chain([Injected(make_block("leakage", {"flow_ml_s": 2.0}, max_flow_ml_s=40.0), 20.0)] if leak else [])
    v = Valve(40.0, char, 50.0, pb, fb)
    v.reset(60.0)
    return v


@pytest.mark.parametrize("char", ["linear", "equal_percentage"])
@pytest.mark.parametrize("block", [None, "backlash", "stiction"])
@pytest.mark.parametrize("leak", [False, True])
def test_step_many_equals_step(char, block, leak):
    rng = np.random.default_rng(4)
    cmd = 60 + np.cumsum(rng.standard_normal(300)) * 2
    cmd[[0, 5, 6, 7, 100, 299]] = [60.0, np.nan, np.inf, -np.inf, np.nan, np.nan]
    cmd[10], cmd[11] = 150.0, -20.0
    t = np.arange(300.0)
    a = make(char, block, leak)
    ref = [a.step(float(c), float(tt)) for c, tt in zip(cmd, t)]
    b = make(char, block, leak)
    outs = [b.step_many(cmd[s], t[s]) for s in (slice(0, 1), slice(1, 8), slice(8, 120), slice(120, 300))]
    pos = np.concatenate([o.position_pct for o in outs])
    flow = np.concatenate([o.flow_ml_s for o in outs])
    sev = np.concatenate([o.fault_severity for o in outs])
    assert np.array_equal(pos, [r.position_pct for r in ref])
    assert np.array_equal(sev, [r.fault_severity for r in ref])
    if char == "linear":
        assert np.array_equal(flow, [r.flow_ml_s for r in ref])
    else:  # numpy's power may differ from libm's in the last bit
        np.testing.assert_allclose(flow, [r.flow_ml_s for r in ref], rtol=1e-14)
    assert a.rejected_commands == b.rejected_commands == 5
