"""Shared fixtures: where ../shared/data is, and marks."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: the real measured data; override with PHFDI_SHARED_DATA
SHARED_DATA = Path(os.environ.get("PHFDI_SHARED_DATA", ROOT.parent / "shared" / "data"))


@pytest.fixture
def shared_data() -> Path:
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real data folder not found at {SHARED_DATA} (set PHFDI_SHARED_DATA)")
    return SHARED_DATA
