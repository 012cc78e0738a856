# Sourced by the scripts that configure a build folder of their own (fuzz.sh, sanitize.sh): sets
# the arrays `generator` (Ninja when it is installed and the folder $1 is not configured yet) and
# `launcher` (ccache when it is installed, keyed on paths relative to the checkout and not on the
# build folder, which -g would hash, so that any clone built before on this machine is a cache
# hit).
cmake_tools() {
  generator=()
  command -v ninja >/dev/null && [[ ! -f $1/CMakeCache.txt ]] && generator=(-G Ninja)
  launcher=()
  if command -v ccache >/dev/null; then
    export CCACHE_BASEDIR=${CCACHE_BASEDIR:-$PWD} CCACHE_NOHASHDIR=${CCACHE_NOHASHDIR:-1}
    launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_C_COMPILER_LAUNCHER=ccache)
  fi
}
