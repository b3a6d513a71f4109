#!/usr/bin/env bash
# Set up (idempotent) and run the whole test suite.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
unset _ROS_WHEELS_BOOTSTRAP_COMPLETE || true
# Lint (ruff: rules in pyproject.toml) and type-check the base, the four cores, phfdi.records, the loop
# diagnosis (phfdi.loopdiag) and the paper's offline analysis (checked in wavelet_fdi before it moved to
# phfdi.study) with mypy, before the tests.
.venv/bin/ruff check src tests benchmarks examples
.venv/bin/mypy src/phfdi_base src/ph_plant_sim src/valve_actuator src/pi_controllers src/wavelet_fdi src/phfdi/records \
  src/phfdi/loopdiag \
  src/phfdi/study/__init__.py src/phfdi/study/{analysis,changepoint,cluster,compress,denoise,figures,multisignal,report,residuals}.py
# Two workers (the machine has 2 cores): the tests that start ROS 2 graphs run one after another on one of
# them (tests/conftest.py groups them), everything else on both. Pass -n 0 to run in one process, or pytest
# arguments to pick tests: bash scripts/test.sh tests/core -n 0
exec .venv/bin/python -m pytest -q -n 2 --dist loadgroup "$@"
