#!/usr/bin/env bash
# crease's test command: the same set-up as quickstart.sh (installs what is
# missing, builds Release), then runs the whole GoogleTest suite with ctest on
# all cores and prints its summary. Extra arguments go to ctest (e.g. -R Rig).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
"$root/scripts/setup.sh"
build="${CREASE_BUILD_DIR:-$root/build}"
printf '[crease test] running ctest in %s\n' "$build"
ctest --test-dir "$build" --output-on-failure -j "$(nproc)" "$@"
