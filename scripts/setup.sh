#!/usr/bin/env bash
# Shared set-up for scripts/quickstart.sh and scripts/test.sh:
#   1. installs the Debian packages of scripts/deps.txt that are missing (apt-get),
#   2. configures a Release build with CMake + Ninja in ${CREASE_BUILD_DIR:-build},
#   3. builds it.
# Idempotent: installed packages are skipped, an existing build is reused.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="${CREASE_BUILD_DIR:-$root/build}"

say() { printf '[crease setup] %s\n' "$*"; }

missing=()
while read -r pkg; do
  pkg="${pkg%%#*}"; pkg="${pkg//[[:space:]]/}"
  [ -z "$pkg" ] && continue
  if ! dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$pkg")
  fi
done < "$root/scripts/deps.txt"

if [ ${#missing[@]} -gt 0 ]; then
  say "installing ${#missing[@]} missing Debian packages: ${missing[*]}"
  sudo_cmd=()
  if [ "$(id -u)" -ne 0 ]; then sudo_cmd=(sudo); fi
  "${sudo_cmd[@]}" apt-get update -qq
  DEBIAN_FRONTEND=noninteractive "${sudo_cmd[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}"
else
  say "all Debian packages of scripts/deps.txt are installed"
fi

source "$root/scripts/ccache_launcher.sh"
if [ ! -f "$build/build.ninja" ]; then
  say "configuring Release build in $build"
  cmake -S "$root" -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=Release "${launcher[@]}"
else
  say "reusing configured build in $build"
fi
jobs="${CREASE_JOBS:-$(nproc)}"
say "building with $jobs jobs"
cmake --build "$build" -j "$jobs"
