#!/usr/bin/env bash
# Set up (idempotent) and run the main job on the built-in default scenario.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
unset _ROS_WHEELS_BOOTSTRAP_COMPLETE || true
exec .venv/bin/phfdi demo "$@"
