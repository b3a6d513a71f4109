"""Fixtures of the injection tests: a real rig record (or a rig-like synthetic one), the CLI in process."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from tests.conftest import SHARED_DATA

HEADER = 'Time, ElapsedTime (s),"%, Acid","%, Base","Acid Flow, mL/s","Base Flow, mL/s","pH","T_Room",,,,\n'
#: the real closed-loop record: acid pump always on, base pump switching (both pump kinds have cells to change)
RIG_CONTROL = "ph_rig/2025.02.24-005_control_pH7_from_basic.csv"


def rig_like_csv(path: Path, n: int = 1200, dt_s: float = 0.35, ph=None) -> Path:
    """A CSV in the rig's format: acid 60 % (4.31 mL/s), base 100 % (6.45 mL/s) in blocks of 40 rows."""
    rows = []
    for k in range(n):
        t = 1.004 + k * dt_s
        base_on = (k // 40) % 2 == 0
        value = ph(t) if ph else 7.0 + 3.0 * math.sin(t / 40.0)
        rows.append(f"2/24/2025 2:00:{k % 60:02d} PM , {t:.12g} ,60.00,{100 if base_on else 0:.2f},4.31,"
                    f"{6.45 if base_on else 0:.2f},{value:.2f},22.{k % 90 + 10},,,,\n")
    path.write_text(HEADER + "".join(rows))
    return path


@pytest.fixture
def rig_file(tmp_path) -> Path:
    """The real control record when ../shared/data is there (PHFDI_SHARED_DATA), else a rig-like CSV."""
    real = SHARED_DATA / RIG_CONTROL
    return real if real.is_file() else rig_like_csv(tmp_path / "rig.csv")
