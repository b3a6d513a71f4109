"""The operations catalogue: the shipped file validates, the schema refuses what it should (one line naming the
operation and the key), the unseen operations are unseen, the shared ones are the recorded runs' commands."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest
import yaml

from phfdi.rigsim import command_profile, draw_operation, load_catalogue, operation_names
from phfdi.rigsim.operations import catalogue_path
from phfdi_base.errors import UserError

#: the recorded runs' settings (%): acid 50 and 60, base 20, 50 (ramped through 33.6-49.9), 60, 100 (switched)
RECORDED_ACID = {50.0, 60.0}
RECORDED_BASE = {20.0, 50.0, 60.0, 100.0}


def _shipped() -> dict:
    return yaml.safe_load(catalogue_path().read_text())


def _write(tmp_path: Path, data: dict) -> Path:
    path = tmp_path / "ops.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_shipped_catalogue_has_both_groups_and_every_kind():
    ops = load_catalogue()
    assert len(operation_names("shared")) >= 5 and len(operation_names("unseen")) >= 8
    assert {op.kind for op in ops.values()} == {"profile", "open_loop", "on_off", "pi"}
    # the brief's operations are there
    for name in ("slow_rise", "add_base_new_setting", "add_acid_new_setting", "on_off_base", "on_off_both",
                 "chatter_setpoint_change", "pi_base", "pi_acid", "titration_base_to_acid_new_rate"):
        assert ops[name].group == "unseen"


def test_unseen_open_loop_settings_are_not_the_recorded_ones():
    ops = load_catalogue()
    for name in ("add_base_new_setting", "add_acid_new_setting", "titration_base_to_acid_new_rate"):
        op = ops[name]
        acid = set(getattr(op.acid_pct, "choices", [op.acid_pct]))
        base = set(getattr(op.base_pct, "choices", [op.base_pct]))
        assert not ({a for a in acid if a} & RECORDED_ACID) and not ({b for b in base if b} & RECORDED_BASE), name


def test_long_runs_and_many_distinct_draws():
    ops = load_catalogue()
    longest = max(op.duration_s.max for op in ops.values() if hasattr(op.duration_s, "max"))
    assert longest >= 3600.0
    draws = {tuple(sorted((k, str(v)) for k, v in draw_operation(ops["on_off_base"], np.random.default_rng(s))
                          .values.items())) for s in range(50)}
    assert len(draws) == 50


@pytest.mark.parametrize(("edit", "message"), [
    (lambda d: d["operations"][6].update(colour="red"), "operations.6 (slow_rise).colour: unknown key"),
    (lambda d: d["operations"][6].pop("base_pct"), "needs base_pct"),
    (lambda d: d["operations"][6].update(base_pct={"min": 5, "max": 150}), "base_pct must lie within [0, 100]"),
    (lambda d: d["operations"][6].update(duration_s={"min": 600, "max": 300}), "min 600 is above max 300"),
    (lambda d: d["operations"][12].update(kp_pct_per_ph=3.0), "a on_off operation takes no kp_pct_per_ph"),
    (lambda d: d["operations"][12].update(switched="sideways"), "switched must be one of"),
    (lambda d: d["operations"].append(copy.deepcopy(d["operations"][6])), "operation 'slow_rise' is listed twice"),
    (lambda d: d.update(format="v2"), "format"),
    (lambda d: d["operations"][0].update(profile=[[5.0, 0.0, 60.0]]), "a profile starts with a change point at 0 s"),
])
def test_schema_refuses_with_one_line(tmp_path, edit, message):
    data = _shipped()
    assert data["operations"][6]["name"] == "slow_rise" and data["operations"][12]["name"] == "on_off_base"
    edit(data)
    with pytest.raises(UserError) as err:
        load_catalogue(_write(tmp_path, data))
    assert message in str(err.value) and "\n" not in str(err.value)


def test_an_operation_some_day_cannot_perform_is_refused(tmp_path):
    data = _shipped()
    on_off_acid = next(op for op in data["operations"] if op["name"] == "on_off_acid")
    on_off_acid["other_pct"] = {"min": 5.0, "max": 10.0}  # a steady base the acid pump cannot overpower on a weak-acid day
    with pytest.raises(UserError, match="on_off_acid.*acid switched"):
        load_catalogue(_write(tmp_path, data))


def test_shared_operations_are_the_recorded_commands(shared_data):
    ops = load_catalogue()
    files = {"shared_add_base": "2025.02.24-001", "shared_control_ph7": "2025.02.24-005",
             "shared_add_acid": "2025.02.24-add", "shared_acid_to_base": "2025.03.03",
             "shared_base_to_acid": "2025.04.07"}
    for name, prefix in files.items():
        path = next((shared_data / "ph_rig").glob(f"{prefix}*.csv"))
        recorded = command_profile(path)
        op = ops[name]
        assert [list(p) for p in op.profile] == recorded["profile"], name
        assert (op.start_ph, op.duration_s, op.start_elapsed_s) == \
            (recorded["start_ph"], recorded["duration_s"], recorded["start_elapsed_s"]), name
