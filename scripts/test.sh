#!/usr/bin/env bash
# The README's second command: install what is missing, build with tests, run every test.
set -euo pipefail
cd "$(dirname "$0")/.."
./scripts/install-deps.sh --tests
# Through ccache when it is installed, keyed on paths relative to the checkout, so that a machine
# that built any clone before (a CI runner) recompiles only what changed.
launcher=()
if command -v ccache >/dev/null; then
  export CCACHE_BASEDIR=${CCACHE_BASEDIR:-$PWD} CCACHE_NOHASHDIR=${CCACHE_NOHASHDIR:-1}
  launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_C_COMPILER_LAUNCHER=ccache)
fi
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release -DDEFORM_BUILD_TESTS=ON "${launcher[@]}"
cmake --build build -j "$(nproc)"
ctest --test-dir build --output-on-failure -j "$(nproc)" --timeout 600
