#!/usr/bin/env bash
# The README's first command: install what is missing, build (Release), run the default scene on
# the built-in liver phantom, and say where the results are.
set -euo pipefail
cd "$(dirname "$0")/.."
./scripts/install-deps.sh
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release
cmake --build build -j "$(nproc)"
out=results/liver_grasp_lift
# Each model beside its twin calibrated on the liver's training scenes (calibrations/liver,
# scripts/ship_calibrations.sh), when the checkout ships them.
twins=()
compgen -G "calibrations/liver/*.json" >/dev/null && twins=(--calibration shipped --calibrated-twins)
./build/bin/deformbench run scenes/liver_grasp_lift.json --out "$out" "${twins[@]}"
echo "setup: results in $out/results.json"
