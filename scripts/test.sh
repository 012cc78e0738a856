#!/usr/bin/env bash
# The README's second command: install what is missing, build with tests, run every test.
set -euo pipefail
cd "$(dirname "$0")/.."
./scripts/install-deps.sh --tests
# With Ninja for a new build folder (one queue for every target's files), and through ccache when
# it is installed, keyed on paths relative to the checkout, so that a machine that built any
# clone before (a CI runner) recompiles only what changed (scripts/cmake_tools.sh).
source scripts/cmake_tools.sh
cmake_tools build  # generator, launcher
cmake -S . -B build "${generator[@]}" -DCMAKE_BUILD_TYPE=Release -DDEFORM_BUILD_TESTS=ON "${launcher[@]}"
cmake --build build -j "$(nproc)"
ctest --test-dir build --output-on-failure -j "$(nproc)" --timeout 600
