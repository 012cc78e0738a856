#!/usr/bin/env bash
# Regenerates the shipped calibrations, calibrations/<organ>/<model>.json (issue H4): for each
# built-in phantom with a training set, scripts/calibration_study.sh fits every calibratable model
# on it, and each model's calibration.json is copied in with its scene paths made relative to
# the checkout. `deformbench run --calibration shipped --calibrated-twins` (scripts/setup.sh)
# then shows each model beside its calibrated twin.
#
#   scripts/ship_calibrations.sh [--budget N] [--jobs N] [--work DIR] [--organ NAME]...
#                                [--model M]... [--deformbench PATH]
#
# Training sets: liver scenes/calibration, gallbladder scenes/calibration/gallbladder, cube
# scenes/calibration/cube (train_*.json; validate_*.json held out). An organ whose folder has no
# training scene is skipped with a line saying so.
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
budget=30 jobs=1 work=$here/out/ship_calibrations organs=() models=() exe=()
while [[ $# -gt 0 ]]; do
  case $1 in
    --budget) budget=$2; shift 2 ;;
    --jobs) jobs=$2; shift 2 ;;
    --work) work=$2; shift 2 ;;
    --organ) organs+=("$2"); shift 2 ;;
    --model) models+=(--model "$2"); shift 2 ;;
    --deformbench) exe=(--deformbench "$2"); shift 2 ;;
    *) echo "ship_calibrations.sh: unknown argument '$1'" >&2; exit 2 ;;
  esac
done
[[ ${#organs[@]} -gt 0 ]] || organs=(liver gallbladder cube)
for organ in "${organs[@]}"; do
  case $organ in
    liver) scenes=$here/scenes/calibration ;;
    *) scenes=$here/scenes/calibration/$organ ;;
  esac
  if ! compgen -G "$scenes/train_*.json" >/dev/null; then
    echo "$organ: no training scene in $scenes: skipped"
    continue
  fi
  "$here/scripts/calibration_study.sh" --scenes "$scenes" --out "$work/$organ" --budget "$budget" \
    --jobs "$jobs" "${models[@]}" "${exe[@]}"
  mkdir -p "$here/calibrations/$organ"
  for f in "$work/$organ"/*/calibration.json; do
    [[ -f $f ]] || continue
    m=$(basename "$(dirname "$f")")
    python3 - "$f" "$here/calibrations/$organ/$m.json" "$here/" <<'PY'
import json, sys
src, dst, root = sys.argv[1:]
text = open(src).read().replace(root, "")  # the checkout's paths, relative
json.dump(json.loads(text), open(dst, "w"), indent=2)
open(dst, "a").write("\n")
print("shipped " + dst.replace(root, ""))
PY
  done
done
