"""Fixtures of the detector tests: simulated paper runs (cached per session)."""

from __future__ import annotations

import pytest

from phfdi.loop import simulate
from phfdi.scenario import load_scenario

_RUNS: dict = {}


@pytest.fixture(scope="session")
def paper_run():
    """paper_run(fault) -> the paper scenario's run (seed 1, fault at 7000 s), simulated once per session."""

    def get(fault: str):
        if fault not in _RUNS:
            _RUNS[fault] = simulate(load_scenario("paper", fault=fault))
        return _RUNS[fault]

    return get
