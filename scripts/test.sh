#!/usr/bin/env bash
# Set up (idempotent) and run the whole test suite.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
unset _ROS_WHEELS_BOOTSTRAP_COMPLETE || true
exec .venv/bin/python -m pytest -q "$@"
