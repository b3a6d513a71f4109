"""One fault catalogue (issue 14): each fault is declared once, with its block, and everything reads it there.

A block of the test's own, registered with a fault, must show up in the presets, the command line's help,
the evaluation, the paper set, the isolation and the diagnosis with no other edit.
"""

from __future__ import annotations

import json
import sys
from dataclasses import dataclass

import numpy as np
import pytest

from phfdi.cli import main
from phfdi.faults import catalogue, fault_library
from phfdi.loop import simulate
from phfdi.records.record import Record
from phfdi.scenario import load_scenario, raw_scenario
from phfdi_base.blocks import BLOCKS, make_block, register_block
from phfdi_base.faults import FAULTS, Fault, FaultParam, Range
from phfdi_base.spec import validate_scenario
from wavelet_fdi.isolation import classes

from ..detector.detector_helpers import short_spec
from ..diagnosis.hidden_cases import COLUMNS, WARMUP_S, _setpoints


@pytest.fixture
def stem_offset():
    """A user's valve block: the stem sits ``offset_pct`` below the command (a slipped linkage)."""

    @register_block("test_stem_offset", fault=Fault(
        "stem_offset", site="valve", description="stem 3 % of span below the command (test)",
        params=(FaultParam("offset_pct", "% of span", (0.0, 50.0), paper=3.0, search=Range(0.5, 20.0, log=True)),),
        severities=(1.5, 3.0, 6.0)))
    @dataclass
    class StemOffset:
        offset_pct: float
        severity: float = 1.0

        def reset(self, x0: float) -> None:
            pass

        def step(self, x: float, t_s: float) -> float:
            return max(0.0, x - self.severity * self.offset_pct)

    yield "stem_offset"
    BLOCKS.pop("test_stem_offset")
    FAULTS.pop("stem_offset")


def test_a_users_fault_is_a_preset_that_simulates(stem_offset):
    entry = fault_library()[stem_offset]
    assert entry["type"] == "test_stem_offset" and entry["params"] == {"offset_pct": 3.0}
    spec = load_scenario("paper", fault=stem_offset, onset_s=200.0,
                         overrides=["duration_s=400", "setpoints.ph.changes=[{at_s: 100, value: 8.0}]"])
    run = simulate(spec)
    gap = run["valve_command_pct"] - run["valve_position_pct"]
    t = run.time_s
    assert np.allclose(gap[t < 200.0], 0.0) and np.allclose(gap[(t >= 200.0) & (run["valve_command_pct"] > 3.0)], 3.0)


def test_a_users_fault_is_listed_by_the_command_line(stem_offset, capsys):
    with pytest.raises(SystemExit):
        main(["simulate", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    listed = text[text.index("--fault FAULT fault from the library"):text.index("--onset S fault onset")]
    assert f"{stem_offset}," in listed and "backlash," in listed
    assert main(["scenarios"]) == 0
    assert "stem 3 % of span below the command (test)" in capsys.readouterr().out


def test_a_users_fault_is_evaluated_at_its_severities(stem_offset):
    from phfdi.study.evaluation import EvalConfig, severities
    from phfdi.study.paperset import severity_overrides

    assert severities()[stem_offset] == ("offset_pct", [{"offset_pct": 1.5}, {"offset_pct": 3.0},
                                                        {"offset_pct": 6.0}])
    assert stem_offset in EvalConfig().faults
    assert severity_overrides(stem_offset, 1.2) == ["faults.0.params.offset_pct=3.6"]


def test_a_users_fault_is_isolated_and_sized_online(stem_offset):
    """Through the default detector, as phfdi replay runs a paper record: the shipped physics reference of the run's
    scenario names the user's fault (its isolation reads the catalogue) and sizes it, 150 s after the detection (as
    this test has named it since the physics detector's days: over 300 s the fit's window holds more of the loop's
    own moves, and the stem offset is not told from friction and backlash there)."""
    from dataclasses import replace

    from phfdi.replay import scenario_of, shipped_physics_model
    from wavelet_fdi.learned_detector import run_record

    assert stem_offset in classes()
    run = simulate(short_spec(stem_offset, onset_s=1000.0, duration_s=1600.0))
    model, _ = shipped_physics_model(scenario_of(run))
    model = replace(model, reference=replace(model.reference, naming_after_s=150.0))
    x = np.column_stack([np.asarray(run[c], dtype=float) for c in model.channels])
    _, _, detector = run_record(model, np.asarray(run.time_s, dtype=float), x)
    first = detector.alarms[0]
    iso = first["isolation"]
    assert first["detection_time"] >= 1000.0 and iso["fault_class"] == stem_offset, iso
    assert iso["parameter"]["name"] == "offset_pct" and iso["parameter"]["value"] == pytest.approx(3.0, rel=0.05)


def test_a_users_fault_is_a_diagnosis_candidate_found_in_measured_data(stem_offset, tmp_path, capsys):
    """Historian columns only (no name, no metadata) reach the diagnosis; it names the block and sizes it."""
    raw = raw_scenario("paper")
    raw.update(faults=[{"type": "test_stem_offset", "params": {"offset_pct": 2.2}}], seed=5,
               duration_s=WARMUP_S + 1700.0)
    raw["setpoints"]["ph"] = _setpoints(np.random.default_rng(7), 1700.0)
    run = simulate(validate_scenario(raw))
    keep = run.time_s >= WARMUP_S
    data = {c: np.asarray(run[c])[keep] for c in COLUMNS}
    data["time_s"] = data["time_s"] - data["time_s"][0]
    path = Record.of(data, {}).to_csv(tmp_path / "record.csv")
    with pytest.raises(SystemExit):
        main(["diagnose", "--help"])
    assert "test_stem_offset (actuator)" in capsys.readouterr().out
    assert main(["diagnose", "--data", str(path), "--model", "paper", "--out", str(tmp_path / "rep"), "--json",
                 "--quiet", "--candidates", "test_stem_offset", "deadzone", "saturation", "--no-pairs"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["verdict"] == "explained" and rep["cause"] == "test_stem_offset" and rep["family"] == "actuator", rep
    assert rep["parameters"]["offset_pct"] == pytest.approx(2.2, rel=0.05)


# ---- the built-in catalogue ------------------------------------------------------------------------------------
def test_every_preset_builds_its_block_with_the_preset_values():
    for name, f in catalogue().items():
        for p in f.params:
            assert p.fit_range("isolation").low >= p.bounds[0] and p.fit_range("diagnosis").high <= p.bounds[1]
        if not f.preset:  # a diagnosis-only fault (sensor lag, bias, drift, gain)
            assert name not in fault_library()
            continue
        assert f.preset_entry() == fault_library()[name]
        block = make_block(f.block, f.preset_params(), dt_s=1.0)
        for p in f.params:
            if p.paper is not None:
                assert getattr(block, p.name) == p.paper


def test_severities_bracket_the_preset_and_scale_the_others_along():
    stiction = catalogue()["stiction"]
    mild, paper, strong = stiction.severity_params()
    assert paper == stiction.preset_params()
    assert mild == {"s_pct": 0.75, "j_pct": 0.25} and strong == {"s_pct": 3.0, "j_pct": 1.0}


def test_a_fault_outside_its_bounds_or_at_an_unknown_site_is_refused():
    with pytest.raises(ValueError, match="outside its bounds"):
        FaultParam("width_pct", "% of span", (0.0, 100.0), paper=120.0)
    with pytest.raises(ValueError, match="outside its bounds"):
        FaultParam("width_pct", "% of span", (0.0, 100.0), search=Range(0.05, 200.0, log=True))
    with pytest.raises(ValueError, match="site"):
        Fault("x", site="valve_stem", description="")


def test_a_loop_only_valve_is_catalogued_with_its_draws_and_kept_out_of_the_ph_loops_answers():
    """He's stiction and quantization are faults of the catalogue (issue 37): their entries carry the loop
    diagnosis's draws; candidate=False keeps them out of phfdi diagnose's causes, as isolate and preset keep them
    out of the isolation and --fault."""
    from phfdi.diagnosis.catalogue import _others
    from phfdi.diagnosis.report import causes
    from phfdi.loopdiag.vocabulary import DOMAIN_DRAWS, TRAINING_DRAWS

    for name, main_param in (("stiction_he", "fs_pct"), ("quantization", "step_pct")):
        f = catalogue()[name]
        assert f.block == name and f.main.name == main_param and f.loop is not None
        assert TRAINING_DRAWS[name] is f.loop.training and DOMAIN_DRAWS[name] is f.loop.domain
        assert name not in causes() and name not in _others(("valve", "valve_flow", "ph_sensor"))
        assert name not in classes() and name not in fault_library()
    assert "stiction" in causes() and catalogue()["stiction"].loop.domain["s_pct"] == (0.3, 8.0)


def test_a_fault_answers_to_its_preset_name_and_its_blocks():
    from phfdi.diagnosis.catalogue import Context
    from phfdi.diagnosis.catalogue import catalogue as candidates

    by_block = load_scenario("paper", fault="coulomb_viscous_friction")
    assert by_block.faults == load_scenario("paper", fault="friction").faults
    ctx = Context(feeds=["acid", "base"], valve_feed="acid", valve_max_flow_ml_s=40.0, overflow=False,
                  has_command=True, command_pct=np.linspace(30.0, 60.0, 50), ph_range=(8.0, 11.0),
                  duration_s=1000.0, dt_s=1.0, total_inflow_ml_s=30.0, feed_strength_mol_l={"acid": 0.1, "base": 0.1},
                  outputs={"ph_measured"})
    cands, _ = candidates(ctx, only=["friction", "probe_delay", "probe_bias"])  # the name phfdi inject uses too
    assert sorted(c.cause for c in cands) == ["coulomb_viscous_friction", "sensor_bias", "sensor_delay"]
    delay = next(c for c in cands if c.cause == "sensor_delay").params[0]
    # the catalogue's diagnosis range, narrowed by the record (a fifth of 1000 s)
    assert (delay.low, delay.high) == (0.0, 200.0)


def test_a_plugins_fault_is_a_preset_of_the_scenario_naming_it(tmp_path):
    (tmp_path / "slip.py").write_text(
        "from dataclasses import dataclass\n"
        "from phfdi_base import Fault, FaultParam, register_block\n\n"
        "@register_block('test_plugin_slip', fault=Fault('plugin_slip', site='valve', description='slipped stem',\n"
        "    params=(FaultParam('slip_pct', '% of span', (0.0, 50.0), paper=2.0),)))\n"
        "@dataclass\n"
        "class Slip:\n"
        "    slip_pct: float\n"
        "    severity: float = 1.0\n"
        "    def reset(self, x0): pass\n"
        "    def step(self, x, t_s): return x - self.severity * self.slip_pct\n")
    (tmp_path / "s.yaml").write_text("extends: paper\nplugins: [slip.py]\n")
    try:
        spec = load_scenario(str(tmp_path / "s.yaml"), fault="plugin_slip")
        assert spec.faults[0].type == "test_plugin_slip" and spec.faults[0].params == {"slip_pct": 2.0}
    finally:
        BLOCKS.pop("test_plugin_slip", None)
        FAULTS.pop("plugin_slip", None)
        sys.modules.pop("phfdi_plugin_slip", None)


def test_the_base_scenario_is_decided_from_the_catalogues_names():
    """One rule for the scenario a resolved name comes from (shipped references, a recording's base): a name
    holding '-' of its own keeps it (replay used to split on the first '-': 'my-plant' gave 'my')."""
    from phfdi.faults import base_scenario
    from phfdi.replay import shipped_physics_name
    from phfdi.ros.parts import recorded_part
    from phfdi_base.spec import resolve_scenario

    spec = resolve_scenario(dict(raw_scenario("paper"), name="my-plant"), "backlash", fault_library(), [], None)
    assert base_scenario(spec.name) == "my-plant"
    assert base_scenario("my-plant") == "my-plant" and base_scenario("paper-probe_delay") == "paper"
    assert base_scenario("paper-coulomb_viscous_friction") == "paper" and base_scenario("-backlash") == "-backlash"
    assert base_scenario("paper-extended-valve_gain") == "paper"  # the model phfdi diagnose writes (extends paper)
    assert base_scenario("my-plant-extended-stiction-backlash") == "my-plant"
    assert base_scenario("paper-extendedness") == "paper-extendedness"
    assert recorded_part(spec).base_scenario == "my-plant"
    with pytest.raises(Exception, match="no physics reference ships for scenario 'my-plant'"):
        shipped_physics_name(spec)  # asks for the base scenario's reference
