#!/usr/bin/env bash
# Set up (idempotent) and run the main job on the built-in default scenario.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
unset _ROS_WHEELS_BOOTSTRAP_COMPLETE || true
# the demo's own folder (out/demo/) is replaced on each run; a folder given with --out is kept unless --overwrite
# is given too (the rule of every command: an earlier run's output is replaced only with --overwrite)
case " $* " in
    *" --out"*) exec .venv/bin/phfdi demo "$@" ;;
esac
exec .venv/bin/phfdi demo --overwrite "$@"
