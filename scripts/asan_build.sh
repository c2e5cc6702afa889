#!/usr/bin/env bash
# Configures (once) and builds the clang ASan+UBSan build used by scripts/test_sanitize.sh
# and scripts/fuzz.sh: ${CREASE_ASAN_BUILD_DIR:-build-asan}, CREASE_SANITIZE=ON and
# CREASE_FUZZ=ON (library code with -fsanitize=fuzzer-no-link, so the tests and the
# fuzz targets share one set of objects), -O1 with line tables for readable reports,
# benchmarks off, the tests' time limits ×20 (tests/CMakeLists.txt). Builds only the
# targets given as arguments, with ${CREASE_JOBS:-nproc} jobs, through ccache when
# present (paths relative to the checkout, like setup.sh).
# Needs the Debian packages of scripts/deps.txt (clang, libclang-rt-14-dev); run
# scripts/setup.sh first on a fresh machine.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="${CREASE_ASAN_BUILD_DIR:-$root/build-asan}"
say() { printf '[crease asan] %s\n' "$*"; }

source "$root/scripts/ccache_launcher.sh"
if [ ! -f "$build/build.ninja" ]; then
  say "configuring the clang ASan+UBSan build in $build"
  cmake -S "$root" -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
    -DCMAKE_C_COMPILER=clang -DCMAKE_CXX_COMPILER=clang++ \
    "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O1 -gline-tables-only -DNDEBUG" \
    "-DCMAKE_C_FLAGS_RELWITHDEBINFO=-O1 -gline-tables-only -DNDEBUG" \
    -DCREASE_SANITIZE=ON -DCREASE_FUZZ=ON -DCREASE_BUILD_BENCH=OFF -DCREASE_TEST_TIMEOUT_FACTOR=20 "${launcher[@]}"
elif ! grep -q '^CREASE_TEST_TIMEOUT_FACTOR:STRING=20$' "$build/CMakeCache.txt"; then
  cmake "$build" -DCREASE_TEST_TIMEOUT_FACTOR=20 >/dev/null  # a build dir configured before the factor
fi
jobs="${CREASE_JOBS:-$(nproc)}"
say "building $# targets with $jobs jobs"
cmake --build "$build" -j "$jobs" --target "$@"
