#!/usr/bin/env bash
# The shipped calibration study (issue G2): calibrates each model on the liver phantom's three
# training scenes (grasp-lift, 1 N up, 1 N down; scenes/calibration/train_*.json), validates on
# the held-out ones (a grasp on the left lobe, 5 N down, the gallbladder; validate_*.json) and
# prints the before/after table (also written as OUT/study.md).
#
#   scripts/calibration_study.sh [--out DIR] [--budget N] [--jobs N] [--deformbench PATH]
#                                [--scenes DIR]    (train_*.json and validate_*.json; default
#                                                   scenes/calibration)
#                                [--model M]...    (default: pbd massspring metaballs
#                                                   particle_bem hybrid_fem_pbd)
#                                [--param M:KEY]... (calibrate only these parameters of model M;
#                                                   default: all its calibratable ones)
# Each model's folder OUT/<model>/ holds calibration.json and trials.csv; a model already
# calibrated there (calibration.json present) is not run again.
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
out=out/calibration budget=30 jobs=1 exe="$here/build/bin/deformbench" models=() params=()
scenes=$here/scenes/calibration
while [[ $# -gt 0 ]]; do
  case $1 in
    --out) out=$2; shift 2 ;;
    --budget) budget=$2; shift 2 ;;
    --jobs) jobs=$2; shift 2 ;;
    --deformbench) exe=$2; shift 2 ;;
    --model) models+=("$2"); shift 2 ;;
    --param) params+=("$2"); shift 2 ;;
    --scenes) scenes=$(cd "$2" && pwd); shift 2 ;;
    *) echo "calibration_study.sh: unknown argument '$1'" >&2; exit 2 ;;
  esac
done
[[ ${#models[@]} -gt 0 ]] || models=(pbd massspring metaballs particle_bem hybrid_fem_pbd)
mkdir -p "$out"
for m in "${models[@]}"; do
  if [[ -f $out/$m/calibration.json ]]; then
    echo "$m: already calibrated in $out/$m"
    continue
  fi
  only=()
  for p in "${params[@]}"; do [[ ${p%%:*} == "$m" ]] && only+=(--param "${p#*:}"); done
  validate=()
  for v in "$scenes"/validate_*.json; do [[ -f $v ]] && validate+=(--validate "$v"); done
  "$exe" calibrate "$scenes"/train_*.json --model "$m" --out "$out/$m" "${validate[@]}" \
    --budget "$budget" --jobs "$jobs" --label "calibration study" "${only[@]}" \
    || echo "$m: calibrate failed (exit $?)" >&2
done
python3 - "$out" "${models[@]}" <<'PY'
import json, os, sys
out, models = sys.argv[1], sys.argv[2:]
def mm(v):
    return "-" if v is None else "%.3g" % (1e3 * v)
lines = ["| model | params (calibrated) | train before (mm) | train after (mm) | "
         "validation before (mm) | validation after (mm) | per validation scene before -> after (mm) | "
         "trials | wall s |",
         "|---|---|---|---|---|---|---|---|---|"]
for m in models:
    f = os.path.join(out, m, "calibration.json")
    if not os.path.exists(f):
        lines.append("| %s | not calibrated | | | | | | | |" % m)
        continue
    c = json.load(open(f))
    params = ", ".join("%s %.3g (%.3g)" % (k, v, c["defaults"][k]) for k, v in c["params"].items())
    per = "; ".join("%s %s -> %s" % (os.path.basename(p["scene"]).replace(".json", ""),
                                     mm(p["before"]), mm(p["after"]))
                    for p in c["validation"]["per_scene"])
    lines.append("| %s | %s | %s | %s | %s | %s | %s | %d | %.0f |" % (
        m, params, mm(c["train"]["before"]), mm(c["train"]["after"]),
        mm(c["validation"]["before"]), mm(c["validation"]["after"]), per, c["evaluations"],
        c["wall_s"]))
text = "\n".join(lines) + "\n"
metric = "rmse_all"
print("\nCalibration study (metric %s, mean over scenes; calibrated values with defaults in "
      "parentheses)\n" % metric)
print(text)
open(os.path.join(out, "study.md"), "w").write(text)
PY
