# Sourced by setup.sh and asan_build.sh (one copy of the compiler-cache setup):
# paths relative to the checkout `root`, so a fresh clone elsewhere still hits the
# cache; `launcher` holds the CMake arguments that route compiles through ccache
# (empty when ccache is not installed).
export CCACHE_BASEDIR="$root" CCACHE_NOHASHDIR=1
launcher=()
if command -v ccache >/dev/null 2>&1; then
  launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_C_COMPILER_LAUNCHER=ccache)
fi
