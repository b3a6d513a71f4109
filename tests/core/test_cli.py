"""The command line: simulate, scenarios, paper-runs; bad scenarios get one clear line and exit 2."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from phfdi.cli import main
from phfdi.records import read_run

SHORT = ["--set", "duration_s=1200", "--set", "setpoints.ph.changes.0.at_s=600"]


def run_cli(args, capsys):
    code = main(args)
    out = capsys.readouterr()
    return code, out.out, out.err


def write(tmp_path: Path, text: str) -> str:
    p = tmp_path / "scenario.yaml"
    p.write_text(text)
    return str(p)


BAD_SCENARIOS = [
    ("unknown key", "extends: paper\nnoise_level: 3\n", "noise_level: unknown key"),
    ("negative width", "extends: paper\nfaults: [{type: backlash, params: {width_pct: -0.5}, onset_s: 7000}]\n",
     "faults.0: backlash: width_pct must be non-negative"),
    ("unreachable setpoint", "extends: paper\nsetpoints: {ph: {initial: 12.0, changes: [{at_s: 5000, value: 2.0}]}}\n",
     "setpoints.ph: pH 2.0 is not reachable"),
    ("setpoint inside the valve's range but outside the 20 % margin",
     "extends: paper\nsetpoints: {ph: {initial: 12.5}}\n",
     "pH 12.5 needs the valve at 7.2 %, outside the reachable range 20..80 %"),
    ("onset after the end", "extends: paper\nfaults: [{type: backlash, params: {width_pct: 0.7}, onset_s: 20000}]\n",
     "onset_s = 20000.0 s is not before the end of the run"),
    ("negative noise", "extends: paper\nsensors: {ph: {noise_std: -1}}\n", "sensors.ph.noise_std"),
    ("unknown block", "extends: paper\nfaults: [{type: rust, onset_s: 10}]\n", "unknown block type 'rust'"),
    ("not yaml", "extends: paper\n  : [\n", "not valid YAML"),
]


@pytest.mark.parametrize("name,text,message", BAD_SCENARIOS, ids=[b[0] for b in BAD_SCENARIOS])
def test_bad_scenario_one_line_exit_2(tmp_path, capsys, name, text, message):
    code, out, err = run_cli(["simulate", "--scenario", write(tmp_path, text)], capsys)
    assert code == 2
    assert message in err
    assert len(err.strip().splitlines()) == 1
    assert "Traceback" not in err


def test_bad_input_through_the_real_entry_point_has_no_traceback(tmp_path):
    exe = Path(sys.executable).parent / "phfdi"
    proc = subprocess.run([str(exe), "simulate", "--fault", "rusty_valve"], capture_output=True, text=True)
    assert proc.returncode == 2
    assert "unknown fault 'rusty_valve'" in proc.stderr and "Traceback" not in proc.stderr
    proc = subprocess.run([str(exe), "simulate", "--set", "duration_s=-5"], capture_output=True, text=True)
    assert proc.returncode == 2 and "duration_s" in proc.stderr and "Traceback" not in proc.stderr


def test_simulate_writes_csv_and_parquet_with_the_same_signals(tmp_path, capsys):
    csv, pq = tmp_path / "r.csv", tmp_path / "r.parquet"
    code, out, _ = run_cli(["simulate", "--fault", "backlash", "--onset", "800", *SHORT, "--out", str(csv)], capsys)
    assert code == 0 and "fault: backlash" in out
    run_cli(["simulate", "--fault", "backlash", "--onset", "800", *SHORT, "--out", str(pq)], capsys)
    a, b = read_run(csv), read_run(pq)
    assert a.names == b.names
    for n in a.names:
        assert np.allclose(a[n], b[n], equal_nan=True, rtol=0, atol=0), n
    assert b.metadata["scenario"] == "paper-backlash"
    assert len(a) == 1201 and a.dt_s == 1.0


def test_simulate_json_summary(capsys):
    code, out, _ = run_cli(["simulate", "--fault", "saturation", "--onset", "700", *SHORT, "--json"], capsys)
    s = json.loads(out)
    assert code == 0 and s["faults"][0]["type"] == "saturation"
    assert [seg["setpoint_ph"] for seg in s["segments"]] == [12.0, 8.0]


def test_scenarios_lists_presets(capsys):
    code, out, _ = run_cli(["scenarios"], capsys)
    assert code == 0
    for word in ("paper", "henson_seborg", "rig_flask", "backlash", "probe_delay"):
        assert word in out


def test_every_subcommand_help_has_an_example(capsys):
    from phfdi.cli import COMMANDS

    for name in COMMANDS:
        cmd = name.replace("_", "-")
        with pytest.raises(SystemExit) as exc:
            main([cmd, "--help"])
        assert exc.value.code == 0
        assert "example" in capsys.readouterr().out.lower(), cmd


def test_paper_runs_writes_runs_and_labelled_figures(tmp_path, capsys):
    # a shortened paper-runs: same command on a scenario file with a shorter horizon
    scen = write(tmp_path, "extends: paper\nduration_s: 1500\nsetpoints: {ph: {initial: 12.0, changes: "
                           "[{at_s: 600, value: 8.0}]}, level_cm: {initial: 14.0}}\n")
    code, out, _ = run_cli(["paper-runs", "--scenario", scen, "--out", str(tmp_path / "pr")], capsys)
    assert code == 0
    for f in ("healthy", "backlash", "friction", "deadzone", "saturation", "stiction", "probe_delay"):
        assert (tmp_path / "pr" / f"{f}.csv").exists() and (tmp_path / "pr" / f"{f}.png").stat().st_size > 10000
    assert (tmp_path / "pr" / "overview.png").exists() and (tmp_path / "pr" / "overview_map.png").exists()
    summary = json.loads((tmp_path / "pr" / "summary.json").read_text())
    assert set(summary) >= {"healthy", "saturation"}


def test_simulate_open_loop_from_recorded_inputs(tmp_path, capsys):
    closed, opened = tmp_path / "closed.csv", tmp_path / "open.csv"
    run_cli(["simulate", *SHORT, "--out", str(closed)], capsys)
    code, _, _ = run_cli(["simulate", *SHORT, "--inputs", str(closed), "--out", str(opened)], capsys)
    assert code == 0
    a, b = read_run(closed), read_run(opened)
    # the same valve commands drive the same plant; it starts at the first inputs' steady state, not the
    # closed loop's, and that small difference fades (compare away from the steep setpoint transition)
    t = a.time_s
    steady = ((t > 300) & (t < 600)) | (t > 1100)
    assert np.max(np.abs(a["ph_true"][steady] - b["ph_true"][steady])) < 1e-3
    assert np.all(np.isnan(b["ph_setpoint"]))


@pytest.mark.parametrize("argv, words", [
    (["simulate", "--set", "duration_s=inf"], "duration_s: Input should be a finite number"),
    (["simulate", "--set", "sensors.ph.noise_std=nan"], "sensors.ph.noise_std: Input should be a finite number"),
    (["simulate", "--set", "duration_s=1e12"], "at most 1e+07 per run"),
    (["simulate", "--set", "valves.ph.max_flow_ml_s=1e308"], "valves.ph.max_flow_ml_s: Input should be less than"),
    (["diagnose", "--data", "x.csv", "--dt", "nan"], "--dt: must be a finite number, got nan"),
    (["replay", "x.csv", "--arl0", "inf"], "--arl0: must be a finite number, got inf"),
])
def test_non_finite_and_unbounded_values_are_one_line_before_any_work(argv, words, capsys):
    """inf, NaN, a run of 1e12 samples and a flow of 1e308 (tracebacks or a run without end before): refused
    by the scenario's schema or the option check, one line, exit 2, nothing run."""
    code, out, err = run_cli(argv, capsys)
    assert code == 2 and out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and words in lines[0], err


@pytest.mark.parametrize("link", ["__cause__", "__context__"])
def test_ctrl_c_that_surfaces_as_another_error_is_still_a_ctrl_c(monkeypatch, capsys, link):
    """A Ctrl-C inside an extension module's import can come out as ``ImportError: initialization failed`` (a pybind11
    module of scipy did, in a launch at 0.6 s): one line and status 130, as for the KeyboardInterrupt itself."""
    import phfdi.commands.scenarios as scenarios_command

    def interrupted_import(_args):
        error = ImportError("initialization failed")
        setattr(error, link, KeyboardInterrupt())
        raise error

    monkeypatch.setattr(scenarios_command, "run", interrupted_import)
    assert main(["scenarios"]) == 130
    assert capsys.readouterr().err.strip() == "phfdi scenarios: interrupted"


def test_an_error_with_no_ctrl_c_behind_it_is_not_taken_for_one(monkeypatch):
    import phfdi.commands.scenarios as scenarios_command

    def broken(_args):
        raise ImportError("initialization failed")

    monkeypatch.setattr(scenarios_command, "run", broken)
    with pytest.raises(ImportError):
        main(["scenarios"])
