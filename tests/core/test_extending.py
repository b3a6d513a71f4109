"""A user block plugged in through a scenario file (examples/), as docs/extending.md shows."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from phfdi.cli import main
from phfdi.loop import simulate
from phfdi.scenario import load_scenario

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "aging_probe.yaml"


def test_user_sensor_block_from_a_plugin_changes_what_the_controller_sees():
    run = simulate(load_scenario(str(EXAMPLE), overrides=["duration_s=3000",
                                                          "setpoints.ph.changes.0.at_s=2000"]))
    t = run.time_s
    late = (t > 1500) & (t < 2000)
    # the loop holds the *measured* pH at 12 while the ageing probe under-reads the true pH
    assert abs(np.mean(run["ph_measured"][late]) - 12.0) < 0.02
    assert np.mean(run["ph_true"][late]) > 12.03  # 1 % slope loss after half an hour: +0.05 pH


def test_broken_plugin_is_a_one_line_error(tmp_path, capsys):
    (tmp_path / "bad.py").write_text("raise RuntimeError('boom')\n")
    (tmp_path / "s.yaml").write_text("extends: paper\nplugins: [bad.py]\n")
    assert main(["simulate", "--scenario", str(tmp_path / "s.yaml")]) == 2
    err = capsys.readouterr().err
    assert "plugins: cannot load" in err and "boom" in err and len(err.strip().splitlines()) == 1
