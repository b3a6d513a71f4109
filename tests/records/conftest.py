"""Fixtures of the reader tests: a short simulated run (once per session) and the CLI in process."""

from __future__ import annotations

import pytest

_RUN: dict = {}


@pytest.fixture(scope="session")
def short_run():
    """The paper loop, 900 s, pH 8 from 200 s, healthy (a phfdi.records.Record)."""
    if "run" not in _RUN:
        from phfdi.loop import simulate
        from phfdi.scenario import load_scenario

        _RUN["run"] = simulate(load_scenario("paper", fault="healthy", overrides=[
            "duration_s=900", "setpoints.ph.changes=[{at_s: 200, value: 8.0}]"]))
    return _RUN["run"]
