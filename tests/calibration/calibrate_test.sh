#!/usr/bin/env bash
# calibrate_test.sh MODE DEFORMBENCH FIXTURE_PLUGIN_DIR WORK: one `deformbench calibrate` test on
# the toy fixture plugin (tests/plugin_fixtures), whose runs take milliseconds.
#   recover     the reference is the toy at gain 0.4: calibration from the default gain 1 finds
#               it within 0.02, although trials below gain 0.2 diverge (scored, not fatal);
#               then `run --calibration` uses it and --explain says where gain came from, and
#               `sweep --calibration` shows the default and the calibrated point; the file
#               names the organ it was fitted on, and applies to scenes of that organ only (a
#               scene of another organ is refused in one line; one file per model and organ);
#               it records the other parameters the training ran with, and a run or sweep
#               point of the calibrated model with another value of one gets a note; `sweep
#               --calibrate` fits the point itself (and refuses --calibration beside it); `run
#               --calibration shipped --calibrated-twins` runs the model and its twin; a
#               validation scene with an invalid reference scores nothing and says why, and
#               neither does a trial whose own run is invalid
#   bad_input   unknown model, no calibratable parameter, a scene without a reference, budget 0,
#               a reference that crashes in every trial (CRASHING_PLUGIN_DIR, the optional fifth
#               argument: no trial can be scored, so nothing is fitted): one stderr line each and
#               exit 2
#   measured    (PLUGINS also holds reference_fem) against measured markers, no reference:
#               markers "measured" from reference_fem at nu 0.45 and shifted 1 mm (a scan not
#               registered to the model), calibrate --metric marker_rms --material poisson from
#               nu 0.3 finds 0.45 and the registered error vanishes; --material without
#               marker_rms, marker_rms without measured positions and a Truth Cube level the
#               data do not hold are refused in one line
set -euo pipefail
mode=$1 exe=$(readlink -f "$2") plugins=$3 work=$4
here=$(cd "$(dirname "$0")" && pwd)
rm -rf "$work"
mkdir -p "$work"
db=("$exe" --plugin-dir "$plugins")
fail() { echo "FAIL: $*" >&2; exit 1; }
# check NAME EXPECTED_TEXT ARGS...: `calibrate ARGS` exits 2 with one stderr line holding the text.
check() {
  local name=$1 text=$2
  shift 2
  set +e
  "${db[@]}" calibrate "$@" >"$work/$name.out" 2>"$work/$name.err"
  local code=$?
  set -e
  [[ $code == 2 ]] || fail "$name: exit $code, expected 2"
  [[ $(wc -l <"$work/$name.err") == 1 ]] || { cat "$work/$name.err"; fail "$name: not one line"; }
  grep -qF -- "$text" "$work/$name.err" || { cat "$work/$name.err"; fail "$name: no '$text'"; }
}

case $mode in
recover)
  "${db[@]}" calibrate "$here/toy_reference.json" --model toy --out "$work/cal" --budget 16 \
    --validate "$here/toy_reference.json" --cache-dir "$work/cache" --jobs 2 >"$work/out.txt" 2>"$work/err.txt" \
    || { cat "$work/out.txt" "$work/err.txt"; fail "calibrate exited $?"; }
  python3 - "$work/cal" <<'PY'
import json, sys, csv, os
d = sys.argv[1]
c = json.load(open(os.path.join(d, "calibration.json")))
assert c["format"] == "deformbench-calibration/1", c["format"]
assert c["plugin"] == "toy" and c["model"] == "toy" and c["metric"] == "rmse_all"
gain = c["params"]["gain"]
assert abs(gain - 0.4) < 0.02, f"gain {gain}, expected 0.4"
assert c["train"]["before"] > 1e-4, c["train"]  # gain 1 is far from 0.4
assert c["train"]["after"] < 0.05 * c["train"]["before"], c["train"]
assert c["validation"]["after"] < 0.05 * c["validation"]["before"], c["validation"]
assert 1 <= c["evaluations"] <= 16 and c["wall_s"] > 0
assert c["organs"] == ["phantom:gallbladder, resolution 0.3"], c["organs"]
assert c["held"] == {"iterations": 20, "mode": "rigid", "diverge_below": 0.2,
                     "unconverged_below": 0.0}, c["held"]
rows = list(csv.DictReader(open(os.path.join(d, "trials.csv"))))
assert len(rows) == c["evaluations"], (len(rows), c["evaluations"])
diverged = [r for r in rows if "diverged" in r["status"]]
assert diverged, "no trial diverged (expected some below gain 0.2)"
assert c["failed_runs"] == len(diverged)
worst = max(float(r["objective"]) for r in rows)
assert all(float(r["objective"]) == worst for r in diverged), "a diverged trial not scored worst"
print("gain", gain, "trials", len(rows), "diverged", len(diverged))
PY
  # A validation scene whose reference is invalid (the toy at gain 0 does not follow the grasp)
  # fits nothing: its status says so and the validation mean is null, not a number against it.
  sed 's/"gain": 0.4/"gain": 0.0/' "$here/toy_reference.json" >"$work/toy_invalid_reference.json"
  "${db[@]}" calibrate "$here/toy_reference.json" --model toy --out "$work/cal_invalid" \
    --budget 2 --validate "$work/toy_invalid_reference.json" --no-cache >"$work/invalid.txt" 2>&1 \
    || { cat "$work/invalid.txt"; fail "calibrate with an invalid validation reference"; }
  python3 - "$work/cal_invalid/calibration.json" <<'PY'
import json, sys
v = json.load(open(sys.argv[1]))["validation"]
assert v["after"] is None, v
status = v["per_scene"][0]["status_after"]
assert status.startswith("against an invalid reference: the reference toy(gain=0) is invalid: "), status
PY
  # A trial whose own run is invalid (a solve that gave up, here below gain 0.5) fits nothing,
  # however small its error: the best gain is the smallest valid one, not the reference's 0.4.
  sed 's/"diverge_below": 0.2/"diverge_below": 0.2, "unconverged_below": 0.5/' \
    "$here/toy_reference.json" >"$work/toy_unconverged.json"
  "${db[@]}" calibrate "$work/toy_unconverged.json" --model toy --out "$work/cal_unconverged" \
    --budget 12 --no-cache >"$work/unconverged.txt" 2>&1 \
    || { cat "$work/unconverged.txt"; fail "calibrate with invalid trial runs"; }
  python3 - "$work/cal_unconverged" <<'PY'
import csv, json, sys
c = json.load(open(sys.argv[1] + "/calibration.json"))
rows = list(csv.DictReader(open(sys.argv[1] + "/trials.csv")))
invalid = [r for r in rows if "invalid: 1 solve did not converge" in r["status"]]
assert invalid, [r["status"] for r in rows]
assert all(float(r["gain"]) < 0.5 for r in invalid), invalid
assert c["params"]["gain"] >= 0.5, c["params"]
PY
  "${db[@]}" run "$here/toy_reference.json" --out "$work/run" --no-cache --explain \
    --calibration "$work/cal/calibration.json" >"$work/run.txt" 2>&1 || { cat "$work/run.txt"; fail run; }
  grep -q "gain from calibration $work/cal/calibration.json" "$work/run.txt" \
    || { cat "$work/run.txt"; fail "--explain does not say gain came from the calibration"; }
  grep -q "diverge_below from scene" "$work/run.txt" || fail "--explain: diverge_below not from scene"
  python3 - "$work/run/results.json" <<'PY'
import json, sys
run = json.load(open(sys.argv[1]))["runs"][0]
assert not any("fitted with other parameters" in n for n in run.get("notes", [])), run["notes"]
PY
  # Another value of a parameter the training held: the run and the sweep's calibrated point
  # say so (the calibration still applies).
  python3 - "$here/toy_reference.json" "$work/other_iterations.json" <<'PY'
import json, sys
scene = json.load(open(sys.argv[1]))
scene["models"][0]["params"]["iterations"] = 30
json.dump(scene, open(sys.argv[2], "w"))
PY
  "${db[@]}" run "$work/other_iterations.json" --out "$work/run_iter" --no-cache \
    --calibration "$work/cal/calibration.json" >"$work/run_iter.txt" 2>&1 || { cat "$work/run_iter.txt"; fail run_iter; }
  note="calibration $work/cal/calibration.json was fitted with other parameters: iterations = 30 (fitted with 20)"
  python3 - "$work/run_iter/results.json" "$note" <<'PY'
import json, sys
run = json.load(open(sys.argv[1]))["runs"][0]
assert sys.argv[2] in run.get("notes", []), run.get("notes")
assert abs(run["params"]["gain"] - json.load(open(sys.argv[1].replace("run_iter/results.json", "cal/calibration.json")))["params"]["gain"]) < 1e-12
PY
  # A fit at a bound of its search: every calibrated run and sweep point says so in its notes.
  python3 - "$work/cal/calibration.json" "$work/bound.json" <<'PY'
import json, sys
c = json.load(open(sys.argv[1]))
c["at_bound"] = {"gain": "max"}
json.dump(c, open(sys.argv[2], "w"))
PY
  "${db[@]}" run "$here/toy_reference.json" --out "$work/run_bound" --no-cache \
    --calibration "$work/bound.json" >"$work/run_bound.txt" 2>&1 || { cat "$work/run_bound.txt"; fail run_bound; }
  "${db[@]}" sweep "$here/toy_reference.json" --out "$work/sweep_bound" --no-cache --no-plot \
    --calibration "$work/bound.json" >"$work/sweep_bound.txt" 2>&1 || { cat "$work/sweep_bound.txt"; fail sweep_bound; }
  python3 - "$work/run_bound/results.json" "$work/sweep_bound/sweep.json" \
    "calibration $work/bound.json: gain fitted at its upper bound" <<'PY'
import json, sys
run = json.load(open(sys.argv[1]))["runs"][0]
assert any(n.startswith(sys.argv[3]) for n in run.get("notes", [])), run.get("notes")
p = {q["label"]: q for q in json.load(open(sys.argv[2]))["points"]}
assert p["toy+cal"]["note"].startswith(sys.argv[3]) and p["toy"]["note"] == "", p
PY
  "${db[@]}" sweep "$work/other_iterations.json" --out "$work/sweep_iter" --no-cache --no-plot \
    --calibration "$work/cal/calibration.json" >"$work/sweep_iter.txt" 2>&1 || { cat "$work/sweep_iter.txt"; fail sweep_iter; }
  grep -qF "note: $note" "$work/sweep_iter.txt" || { cat "$work/sweep_iter.txt"; fail "sweep: no note"; }
  python3 - "$work/sweep_iter/sweep.json" "$note" <<'PY'
import json, sys
p = {q["label"]: q for q in json.load(open(sys.argv[1]))["points"]}
assert p["toy+cal"]["note"] == sys.argv[2] and p["toy"]["note"] == "", p
PY
  # sweep --calibration: the model at its defaults and calibrated, the latter far closer.
  "${db[@]}" sweep "$here/toy_reference.json" --out "$work/sweep" --no-cache --no-plot \
    --calibration "$work/cal/calibration.json" >"$work/sweep.txt" 2>&1 || { cat "$work/sweep.txt"; fail sweep; }
  python3 - "$work/sweep/sweep.json" <<'PY'
import json, sys
p = {q["label"]: q for q in json.load(open(sys.argv[1]))["points"]}
assert set(p) == {"toy", "toy+cal"}, list(p)
assert p["toy+cal"]["calibrated"] and not p["toy"]["calibrated"]
assert p["toy+cal"]["rmse_all"] < 0.05 * p["toy"]["rmse_all"], p
PY
  # sweep --calibrate: the point fitted on the scene itself (its own calibration.json), run
  # again at its fit; the fitted curve is summarised apart.
  "${db[@]}" sweep "$here/toy_reference.json" --out "$work/sweep_fit" --no-cache --no-plot \
    --calibrate --calibrate-budget 8 --calibrate-metric rmse_all >"$work/sweep_fit.txt" 2>&1 \
    || { cat "$work/sweep_fit.txt"; fail "sweep --calibrate"; }
  python3 - "$work/sweep_fit" <<'PY'
import json, sys, os
s = json.load(open(os.path.join(sys.argv[1], "sweep.json")))
p = {q["label"]: q for q in s["points"]}
assert set(p) == {"toy", "toy+cal"}, list(p)
assert p["toy+cal"]["rmse_all"] < 0.05 * p["toy"]["rmse_all"], p
assert [m["calibrated"] for m in s["models"]] == [False, True], s["models"]
fit = json.load(open(os.path.join(sys.argv[1], "calibrate", "point_0", "calibration.json")))
assert abs(fit["params"]["gain"] - 0.4) < 0.05, fit["params"]
PY
  # run --calibration shipped --calibrated-twins: the shipped folder's file for this organ gives
  # a twin beside the model; a shipped file of another organ is passed over in silence.
  mkdir -p "$work/shipped/a" "$work/shipped/b"
  cp "$work/cal/calibration.json" "$work/shipped/a/toy.json"
  python3 - "$work/cal/calibration.json" "$work/shipped/b/toy.json" <<'PY'
import json, sys
c = json.load(open(sys.argv[1]))
c["organs"] = ["phantom:cube, resolution 1"]
json.dump(c, open(sys.argv[2], "w"))
PY
  DEFORM_CALIBRATIONS_DIR=$work/shipped "${db[@]}" run "$here/toy_reference.json" --out "$work/twins" \
    --no-cache --calibration shipped --calibrated-twins >"$work/twins.txt" 2>&1 \
    || { cat "$work/twins.txt"; fail "run --calibrated-twins"; }
  python3 - "$work/twins/results.json" "$work/shipped/a/toy.json" <<'PY'
import json, sys
runs = {r["label"]: r for r in json.load(open(sys.argv[1]))["runs"] if r["role"] == "model"}
plain, twin = "toy(diverge_below=0.2)", "toy(diverge_below=0.2)+cal"
assert set(runs) == {plain, twin}, list(runs)
assert runs[twin]["calibration"] == sys.argv[2] and "calibration" not in runs[plain], runs
assert runs[twin]["error"]["rmse_all"] < 0.05 * runs[plain]["error"]["rmse_all"]
PY
  set +e
  "${db[@]}" sweep "$here/toy_reference.json" --out "$work/sweep_both_ways" --calibrate \
    --calibration "$work/cal/calibration.json" >/dev/null 2>"$work/both_ways.err"
  code=$?
  set -e
  [[ $code == 2 && $(wc -l <"$work/both_ways.err") == 1 ]] || { cat "$work/both_ways.err"; fail "--calibrate with --calibration: exit $code"; }
  # Per organ: the same model on a coarser gallbladder is another organ.
  python3 - "$here/toy_reference.json" "$work/cal/calibration.json" "$work" <<'PY'
import json, sys
scene, cal, work = json.load(open(sys.argv[1])), json.load(open(sys.argv[2])), sys.argv[3]
scene["organ"]["resolution"] = 0.25
json.dump(scene, open(work + "/other_organ.json", "w"))
cal["organs"] = ["phantom:gallbladder, resolution 0.25"]
cal["params"]["gain"] = 0.5
json.dump(cal, open(work + "/other_cal.json", "w"))
PY
  set +e
  "${db[@]}" run "$work/other_organ.json" --out "$work/run_other" --no-cache \
    --calibration "$work/cal/calibration.json" >"$work/other.out" 2>"$work/other.err"
  code=$?
  set -e
  [[ $code == 2 && $(wc -l <"$work/other.err") == 1 ]] || { cat "$work/other.err"; fail "other organ: exit $code"; }
  grep -qF "not on this scene's organ (phantom:gallbladder, resolution 0.25)" "$work/other.err" \
    || { cat "$work/other.err"; fail "other organ: message"; }
  # Both files: each applies to its own organ.
  "${db[@]}" run "$work/other_organ.json" --out "$work/run_both" --no-cache --explain \
    --calibration "$work/cal/calibration.json" --calibration "$work/other_cal.json" \
    >"$work/both.txt" 2>&1 || { cat "$work/both.txt"; fail "two organs' calibrations"; }
  grep -q "gain from calibration $work/other_cal.json" "$work/both.txt" \
    || { cat "$work/both.txt"; fail "the other organ's calibration was not the one applied"; }
  # sweep takes the same pair: the file of this scene's organ, whichever comes first.
  "${db[@]}" sweep "$work/other_organ.json" --out "$work/sweep_both" --no-cache --no-plot \
    --calibration "$work/cal/calibration.json" --calibration "$work/other_cal.json" \
    >"$work/sweep_both.txt" 2>&1 || { cat "$work/sweep_both.txt"; fail "sweep with two organs' calibrations"; }
  python3 - "$work/sweep_both/sweep.json" <<'PY'
import json, sys
p = {q["label"]: q for q in json.load(open(sys.argv[1]))["points"]}
assert set(p) == {"toy", "toy+cal"}, list(p)
PY
  set +e
  "${db[@]}" run "$work/other_organ.json" --out "$work/run_twice" --no-cache \
    --calibration "$work/other_cal.json" --calibration "$work/other_cal.json" >/dev/null 2>"$work/twice.err"
  code=$?
  set -e
  [[ $code == 2 ]] && grep -qF "a second calibration of toy/toy" "$work/twice.err" \
    || { cat "$work/twice.err"; fail "two calibrations of one model and organ accepted"; }
  ;;
bad_input)
  check unknown_model "no_such_plugin" "$here/toy_reference.json" --model no_such_plugin --out "$work/x"
  check no_calibratable "declares no calibratable parameter" "$here/toy_reference.json" \
    --model prefixed --out "$work/x"
  check no_reference "needs a reference" "$here/toy_no_reference.json" --model toy --out "$work/x"
  check budget "--budget" "$here/toy_reference.json" --model toy --out "$work/x" --budget 0
  check metric "unknown metric" "$here/toy_reference.json" --model toy --out "$work/x" --metric max
  if [[ -n ${5:-} ]]; then
    python3 - "$here/toy_reference.json" "$work/segv_reference.json" <<'PY'
import json, sys
scene = json.load(open(sys.argv[1]))
scene["reference"] = {"plugin": "segv", "params": {"at": "step"}}
json.dump(scene, open(sys.argv[2], "w"))
PY
    db+=(--plugin-dir "$5")
    # The trials' progress lines come first on stderr; the error is the last line.
    set +e
    "${db[@]}" calibrate "$work/segv_reference.json" --model toy --out "$work/segv" --budget 2 \
      --no-cache >"$work/segv.out" 2>"$work/segv.err"
    code=$?
    set -e
    [[ $code == 2 ]] || fail "reference_crashes: exit $code, expected 2"
    tail -n 1 "$work/segv.err" | grep -qF "no trial run could be scored (no error: the reference segv" \
      || { cat "$work/segv.err"; fail "reference_crashes: no reason"; }
    [[ ! -e $work/segv/calibration.json ]] || fail "reference_crashes: calibration.json written"
  fi
  ;;
measured)
  # A cube pressed 3 mm by a bonded plate; five interior markers; P1 tets, a second a run.
  python3 - "$work" 0.45 <<'PY'
import json, sys
work, nu = sys.argv[1], float(sys.argv[2])
scene = {
  "organ": {"mesh": "phantom:cube", "resolution": 0.3,
            "material": {"young": 5500, "poisson": nu, "density": 1000},
            "fixed": {"box": [[-0.06, -0.06, -0.06], [0.06, 0.06, -0.049999]]}},
  "gravity": [0, 0, 0], "dt": 1.0, "duration": 1.0,
  "plates": [{"region": {"box": [[-0.06, -0.06, 0.049999], [0.06, 0.06, 0.06]]},
              "trajectory": [{"t": 0, "offset": [0, 0, 0]}, {"t": 1, "offset": [0, 0, -0.006]}]}],
  "markers": {"points": [[0.04, 0, 0], [-0.04, 0.02, 0.01], [0, 0.04, -0.02], [0.03, -0.035, 0.02],
                         [0, 0, 0.03]]},
  "models": [{"plugin": "reference_fem",
              "params": {"elements": 300, "element_order": 1}}],
  "output": {"surfaces": "none"}}
json.dump(scene, open(work + "/truth.json", "w"))
PY
  "${db[@]}" run "$work/truth.json" --out "$work/truth" --no-cache >"$work/truth.txt" 2>&1 \
    || { cat "$work/truth.txt"; fail "run of the truth"; }
  python3 - "$work" <<'PY'
import json, sys
work = sys.argv[1]
run = json.load(open(work + "/truth/results.json"))["runs"][0]
assert run["markers"]["status"] == "ok", run["markers"]
x = run["markers"]["at"][0]["positions_m"]
scene = json.load(open(work + "/truth.json"))
scene["organ"]["material"]["poisson"] = 0.3
scene["markers"]["measured"] = [{"t": 1.0, "points": [[p[0] + 0.001, p[1], p[2]] for p in x]}]
json.dump(scene, open(work + "/measured.json", "w"))
del scene["markers"]["measured"]
json.dump(scene, open(work + "/unmeasured.json", "w"))
PY
  "${db[@]}" calibrate "$work/measured.json" --model reference_fem --metric marker_rms \
    --material poisson --budget 12 --out "$work/cal" --no-cache --jobs 2 >"$work/out.txt" 2>&1 \
    || { cat "$work/out.txt"; fail "calibrate exited $?"; }
  python3 - "$work/cal/calibration.json" <<'PY'
import json, sys
c = json.load(open(sys.argv[1]))
assert c["metric"] == "marker_rms" and c["params"] == {}, c
nu = c["material"]["poisson"]
assert abs(nu - 0.45) < 0.01, f"nu {nu}, expected 0.45"
assert c["defaults"] == {"material.poisson": 0.3}, c["defaults"]
before, after = c["train"]["before"], c["train"]["after"]
assert before > 5e-5 and after < 0.1 * before, c["train"]  # the 1 mm shift registered away
print("nu", nu, "marker rms", before, "->", after)
PY
  grep -q "organ poisson = " "$work/out.txt" || { cat "$work/out.txt"; fail "no fitted nu printed"; }
  check circular "fitted to measurements only" "$work/measured.json" --model reference_fem \
    --material poisson --out "$work/x"
  check unmeasured "needs measured marker positions" "$work/unmeasured.json" \
    --model reference_fem --metric marker_rms --material poisson --out "$work/x"
  check level "the data hold levels 1 to 2" --truth-cube 3 --model reference_fem \
    --material poisson --out "$work/x"
  # A fit of the material is the scene's: `run --calibration` refuses it in one line.
  set +e
  "${db[@]}" run "$work/measured.json" --out "$work/run" --no-cache \
    --calibration "$work/cal/calibration.json" >/dev/null 2>"$work/material.err"
  code=$?
  set -e
  [[ $code == 2 ]] && grep -qF "/material: fits the organ's material" "$work/material.err" \
    || { cat "$work/material.err"; fail "a material fit given to run --calibration"; }
  ;;
*) fail "unknown mode $mode" ;;
esac
echo "ok: $mode"
