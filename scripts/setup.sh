#!/usr/bin/env bash
# Set up the project venv (.venv): ROS 2 Jazzy wheels, the project (editable)
# with its test and peer extras. Idempotent: a stamp of the inputs skips the
# install when nothing changed (about a second when already set up).
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=${PHFDI_VENV:-.venv}
PY=${PYTHON:-python3}
# A Python started from another ROS-wheels venv must not inherit this marker
# (../shared/notes/ros2-on-this-machine.md).
unset _ROS_WHEELS_BOOTSTRAP_COMPLETE || true

if ! "$PY" -c 'import sys; sys.exit(sys.version_info < (3, 11))'; then
  echo "setup: needs Python 3.11 or newer ($PY is $("$PY" --version 2>&1))" >&2
  exit 2
fi
[ -x "$VENV/bin/python" ] || "$PY" -m venv "$VENV"

stamp="$VENV/.phfdi-setup-stamp"
want=$(cat pyproject.toml scripts/setup.sh | sha256sum | cut -d' ' -f1)
if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ] && "$VENV/bin/python" -c 'import phfdi, rclpy' 2>/dev/null; then
  echo "setup: $VENV is up to date"
else
  echo "setup: installing into $VENV (ROS 2 Jazzy wheels, numpy/scipy/PyWavelets, mcap, test tools) ..."
  "$VENV/bin/python" -m pip install --quiet --upgrade pip 2>&1 | { grep -v "is ignored: it is neither a file nor a directory" || true; }
  "$VENV/bin/python" -m pip install --quiet -e ".[ros,interfaces,peers,test]" 2>&1 | { grep -v -e "is ignored: it is neither a file nor a directory" -e "BuildBackendWarning" || true; }
  echo "$want" > "$stamp"
fi
# The estimator's compiled filter (Numba, wavelet_fdi.estimator_kernel): compiled once into its cache (about
# 10 s; it says so), so that the first replay or detector node does not wait for it; skipped when the cache is there.
if ! ls src/wavelet_fdi/__pycache__/estimator_kernel._run-*.nbi >/dev/null 2>&1; then
  "$VENV/bin/python" -c "from wavelet_fdi.reference_estimator import compile_filter; compile_filter()"
fi
# The graph's message package (ROS 2 .msg -> C type support + Python); skipped when up to date.
PHFDI_VENV="$VENV" bash scripts/build_interfaces.sh
echo "setup: done"
