"""Detector settings are declared once (wavelet_fdi.config.LearnedSettings, every reference kind's) and everything
else is derived: the CLI options of phfdi calibrate and evaluate, the range checks, the docs table. The physics
reference's design (reference_physics.design_settings) sets some of them otherwise, from the same declaration.

(A new statistic is one registered class: tests/learned/test_learned_statistic_recipe.py.)
"""

from __future__ import annotations

import argparse
from pathlib import Path

import pytest

from phfdi.commands.calibrate import add_detector_args, add_physics_args, given_settings, physics_design
from phfdi_base.errors import UserError
from wavelet_fdi.config import LearnedSettings, setting_specs, settings_table_markdown
from wavelet_fdi.reference_physics import PHYSICS_DESIGN, design_settings

ROOT = Path(__file__).resolve().parents[2]


def test_the_docs_table_is_the_declaration():
    text = (ROOT / "docs" / "detector.md").read_text(encoding="utf-8")
    assert settings_table_markdown() in text, "regenerate the table: wavelet_fdi.config.settings_table_markdown()"


def test_the_learned_detector_checks_its_declared_ranges():
    """A range declared with the learned detector's setting is checked by its check(), with no second copy."""
    ranged = [s for s in setting_specs(of=LearnedSettings) if s.range is not None]
    assert {s.name for s in ranged} >= {"level", "block_samples", "mean_k", "outside_hold_s"}
    for spec in ranged:
        lo, hi = spec.range
        below = lo - 1 if spec.type is int else lo - abs(lo) * 0.5 - 1e-3
        with pytest.raises(UserError, match=f"detector setting {spec.name} must be a number in"):
            LearnedSettings(**{spec.name: below}).check()
        if hi != float("inf"):
            with pytest.raises(UserError, match=spec.name):
                LearnedSettings(**{spec.name: hi + 1}).check()
    with pytest.raises(UserError, match="mean_k"):
        LearnedSettings(mean_k=float("nan")).check()  # was accepted before the declaration checked it


def test_cli_options_are_derived_from_the_declaration():
    parser = argparse.ArgumentParser()
    add_detector_args(parser)
    add_physics_args(parser)
    assert {a.dest for a in parser._actions if a.dest != "help"} == \
        {s.name for s in setting_specs()} | {"channels"}
    level = next(a for a in parser._actions if a.dest == "level")
    assert "default 2; the physics reference's design: 3" in level.help  # both defaults said, from their sources
    # nothing given: the physics design as declared, the pH alone
    options, settings = physics_design(parser.parse_args([]), 1.0)
    assert options == {"watch_level": False} and settings == design_settings(1.0)
    assert (settings.wavelet, settings.level, settings.arl0_samples) == \
        (PHYSICS_DESIGN["wavelet"], PHYSICS_DESIGN["level"], PHYSICS_DESIGN["arl0_samples"])
    # given: set over the design (AJ's k follows the level given: a shift reads 2^(J/2) larger in AJ)
    args = parser.parse_args(["--arl0", "1e6", "--channels", "ph,level", "--level", "4", "--mean-h", "7"])
    assert given_settings(args) == {"arl0_samples": 1e6, "level": 4, "mean_h": 7.0}
    options, got = physics_design(args, 1.0)
    assert options == {"watch_level": True}
    assert (got.arl0_samples, got.level, got.mean_h, got.mean_k) == (1e6, 4, 7.0, pytest.approx(2.0))
    with pytest.raises(UserError, match=r"level must be a number in 1\.\.8"):
        physics_design(parser.parse_args(["--level", "11"]), 1.0)
    with pytest.raises(UserError, match="--channels ph,flow: use ph, or ph,level"):
        physics_design(parser.parse_args(["--channels", "ph,flow"]), 1.0)


def test_the_launcher_refuses_only_parameters_the_detector_node_does_not_take():
    """launcher.RETIRED_NODE_PARAMS (the retired physics detector node's parameters, refused with what does their
    work now) holds none of the detector node's own: no valid parameter is refused."""
    from phfdi.ros.launcher import RETIRED_NODE_PARAMS
    from wavelet_fdi import learned_node

    assert RETIRED_NODE_PARAMS and not set(RETIRED_NODE_PARAMS) & {p.name for p in learned_node.PARAMS}
