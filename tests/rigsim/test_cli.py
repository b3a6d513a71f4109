"""phfdi rig-sim on the command line: the list, a run with its sidecars, a replayed record, bad input as one line."""

from __future__ import annotations

import json

import numpy as np

from phfdi.commands.common import shipped_map
from phfdi.learned import read_measured
from phfdi.rigsim import operation_names


def test_list_names_every_operation_by_group(run_cli):
    status, out, err = run_cli("rig-sim", "--list")
    assert status == 0 and err == ""
    assert out.index("shared:") < out.index("unseen:")
    assert all(f"  {name} " in out for name in operation_names())


def test_a_run_with_a_probe_fault(run_cli, tmp_path):
    out_csv = tmp_path / "run.csv"
    status, out, err = run_cli("rig-sim", "--operation", "on_off_both", "--seed", "5", "--duration-s", "400",
                               "--probe-fault", "probe_lag", "--size", "15", "--onset", "200", "--out", out_csv)
    assert status == 0, err
    assert "probe_lag of 15 s" in out and "wrote" in out
    truth = json.loads((tmp_path / "run.csv.fault.json").read_text())
    meta = json.loads((tmp_path / "run.csv.rigsim.json").read_text())
    assert truth["kind"] == "probe_lag" and truth["onset_s"] == 200.0 and meta["seed"] == 5
    rec = read_measured(out_csv, shipped_map("ph_rig"), channels=["ph_measured"])
    assert 1100 < len(rec.time_s) < 1250 and rec.time_s[-1] - rec.time_s[0] <= 400.0


def test_replay_of_a_record(run_cli, tmp_path, shared_data):
    source = next((shared_data / "ph_rig").glob("2025.02.24-001*.csv"))
    status, out, err = run_cli("rig-sim", "--replay", source, "--seed", "1", "--out", tmp_path / "r.csv")
    assert status == 0, err
    real = read_measured(source, shipped_map("ph_rig"), channels=["base_flow_ml_s"])
    sim = read_measured(tmp_path / "r.csv", shipped_map("ph_rig"), channels=["base_flow_ml_s"])
    assert np.all(sim.x == 3.87) and np.all(real.x == 3.87)


def test_bad_input_is_one_line_and_writes_nothing(run_cli, tmp_path):
    out_csv = tmp_path / "x.csv"
    cases = [
        (["--operation", "nope"], "no operation 'nope'"),
        (["--operation", "pi_base", "--size", "1"], "--size goes with --probe-fault"),
        (["--operation", "pi_base", "--probe-fault", "probe_bias", "--size", "1"], "needs --onset"),
        (["--operation", "pi_base", "--probe-fault", "probe_bias", "--size", "1", "--onset", "1e6"], "outside the run"),
        (["--operation", "pi_base", "--probe-fault", "probe_gain", "--size", "-2", "--onset", "50"], "above -1"),
        (["--operation", "pi_base", "--duration-s", "1"], "--duration-s 1: must lie within"),
        (["--operation", "pi_base", "--seed", "-3"], "non-negative"),
        (["--operation", "pi_base", "--catalogue", tmp_path / "none.yaml"], "none.yaml"),
    ]
    for args, message in cases:
        status, out, err = run_cli("rig-sim", *args, "--out", out_csv)
        assert status == 2 and message in err and err.count("\n") == 1, (args, err)
    assert list(tmp_path.iterdir()) == []
    (tmp_path / "x.csv").write_text("keep")
    status, _, err = run_cli("rig-sim", "--operation", "pi_base", "--out", out_csv)
    assert status == 2 and "exists; give --overwrite" in err and out_csv.read_text() == "keep"
