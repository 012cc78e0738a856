#!/usr/bin/env bash
# The README's first command: install what is missing, build (Release), run the default scene on
# the built-in liver phantom, and say where the results are.
set -euo pipefail
cd "$(dirname "$0")/.."
./scripts/install-deps.sh
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release
cmake --build build -j "$(nproc)"
out=results/liver_grasp_lift
./build/bin/deformbench run scenes/liver_grasp_lift.json --out "$out"
echo "setup: results in $out/results.json"
