#!/usr/bin/env bash
# Build the ROS 2 message package interfaces/phfdi_interfaces and install it into
# the venv (C type supports and Python bindings only, PHFDI_PYTHON_ONLY=ON: the graph is Python;
# a ROS workspace build of the package generates C++ as well).
# Idempotent: skipped when its sources are unchanged and it imports.
# Called by scripts/setup.sh; see docs/ros_graph.md for why the graph has its own messages.
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=$(cd "${PHFDI_VENV:-.venv}" && pwd)
PY="$VENV/bin/python"
PKG=interfaces/phfdi_interfaces
unset _ROS_WHEELS_BOOTSTRAP_COMPLETE || true

stamp="$VENV/.phfdi-interfaces-stamp"
want=$( { find "$PKG" -type f -print0 | sort -z | xargs -0 cat; cat scripts/build_interfaces.sh; "$PY" -V; } | sha256sum | cut -d' ' -f1)
if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ] && "$PY" -c 'import phfdi_interfaces.msg' 2>/dev/null; then
  echo "setup: phfdi_interfaces is up to date"
  exit 0
fi
for tool in cmake cc c++; do
  if ! command -v "$tool" >/dev/null; then
    echo "setup: building the message package needs $tool (Debian: apt-get install cmake g++)" >&2
    exit 2
  fi
done
generator=Ninja
command -v ninja >/dev/null || generator="Unix Makefiles"

build=build/phfdi_interfaces
log=build/phfdi_interfaces.log
manifest="$VENV/.phfdi-interfaces-manifest"
rm -rf "$build"
mkdir -p build
echo "setup: building the message package phfdi_interfaces (about a minute; log: $log) ..."
py_include=$("$PY" -c 'import sysconfig; print(sysconfig.get_paths()["include"])')
np_include=$("$PY" -c 'import numpy; print(numpy.get_include())')
if ! {
  AMENT_PREFIX_PATH="$VENV" cmake -S "$PKG" -B "$build" -G "$generator" \
    -DCMAKE_PREFIX_PATH="$VENV" -DCMAKE_INSTALL_PREFIX="$VENV" -DCMAKE_BUILD_TYPE=Release \
    -DPython3_EXECUTABLE="$PY" -DPython3_FIND_VIRTUALENV=ONLY -DBUILD_TESTING=OFF \
    -DPHFDI_PYTHON_ONLY=ON -DPHFDI_PYTHON_INCLUDE="$py_include" -DPHFDI_NUMPY_INCLUDE="$np_include" &&
  AMENT_PREFIX_PATH="$VENV" cmake --build "$build" &&
  { [ ! -f "$manifest" ] || xargs -d '\n' rm -f < "$manifest"; } &&  # files of the previous build
  cmake --install "$build" &&
  cp "$build/install_manifest.txt" "$manifest"
} >"$log" 2>&1; then
  tail -n 30 "$log" >&2
  echo "setup: building phfdi_interfaces failed (full log: $log)" >&2
  exit 1
fi
if ! "$PY" -c 'import phfdi_interfaces.msg' 2>>"$log"; then
  echo "setup: phfdi_interfaces was built but does not import (log: $log)" >&2
  exit 1
fi
echo "$want" > "$stamp"
echo "setup: phfdi_interfaces installed into $VENV"
