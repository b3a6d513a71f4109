"""Fixtures of the diagnosis tests: hidden-effect cases and a CLI runner."""

from __future__ import annotations

import json
import os
import secrets
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))


@pytest.fixture
def hidden_rng(request):
    """A fresh random generator per test (PHFDI_HIDDEN_SEED reproduces a run); the seed is printed on failure."""
    seed = int(os.environ.get("PHFDI_HIDDEN_SEED", secrets.randbits(32)))
    request.node.user_properties.append(("hidden_seed", seed))
    print(f"hidden-effect seed {seed} (rerun with PHFDI_HIDDEN_SEED={seed})")
    return np.random.default_rng(seed)


@pytest.fixture
def diagnose_json(run_cli):
    def run(*argv: str):
        status, out, err = run_cli("diagnose", *argv, "--json", "--quiet")
        assert status == 0, err
        return json.loads(out)

    return run

