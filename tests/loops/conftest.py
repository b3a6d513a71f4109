"""Fixtures of the loop-diagnosis tests: the synthetic acceptance loops, diagnosed once per session."""

from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor

import pytest

from phfdi.loopdiag.diagnose import Settings, diagnose_run
from phfdi.loopdiag.synthetic import acceptance_cases, simulate_loop


def _diagnose_case(name: str) -> tuple[str, dict]:
    case = acceptance_cases()[name]
    return name, diagnose_run(simulate_loop(case.loop), Settings(baselines=False))


@pytest.fixture(scope="session")
def synthetic_reports() -> dict[str, dict]:
    """Report of every acceptance case (both cores: the cases are independent)."""
    names = list(acceptance_cases())
    with ProcessPoolExecutor(max_workers=2) as pool:
        return dict(pool.map(_diagnose_case, names))
