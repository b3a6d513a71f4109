#!/usr/bin/env bash
# Set up (idempotent) and run the main job on the built-in default scenario.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
unset _ROS_WHEELS_BOOTSTRAP_COMPLETE || true
# the demo's own folder (out/demo/) is replaced on each run; `phfdi demo` itself keeps an earlier run's files
# unless given --overwrite (the rule of every command)
exec .venv/bin/phfdi demo --overwrite "$@"
