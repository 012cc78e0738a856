#!/usr/bin/env bash
# sweep_converge_test.sh MODE DEFORMBENCH PLUGIN_DIR TOY_DIR WORK: the dispatch of `sweep` and
# `converge` (see CMakeLists.txt). The sweep is pbd (3 quick points) and the rigid toy against the
# toy fixture as reference (sweep_toy.json: milliseconds a run); converge is reference_fem on a
# coarse cube (converge_cube.json: three levels of ~1000-3000 tets, about a second each).
#   sweep_jobs        in this process, --jobs 1 and --jobs 2 give the same points (timings and
#                     the Pareto flag apart); the later points read the reference from the cache;
#                     --resume reruns nothing
#   sweep_mpi         mpirun -n 3 ... --mpi gives the serial points
#   sweep_slurm_plan  --slurm DIR writes two arrays (the reference's point, then the others) and
#                     the collect step; running them by hand then the collect step gives the
#                     serial points
#   converge_jobs     --jobs 2 and a --slurm plan run by hand give the in-process study (levels
#                     without their wall times); a sweep prints and writes the reference's check
#                     once `converge --of-reference` has cached it
set -euo pipefail
mode=$1 exe=$(readlink -f "$2") plugins=$(readlink -f "$3") toy=$(readlink -f "$4") work=$5
here=$(cd "$(dirname "$0")" && pwd)
rm -rf "$work"
mkdir -p "$work/plugins"
for p in deform_pbd deform_reference_fem deform_toy; do
  for d in "$plugins" "$toy"; do [ -e "$d/$p.so" ] && ln -sf "$d/$p.so" "$work/plugins/"; done
done
db=("$exe" --plugin-dir "$work/plugins")
mpirun=(mpirun --oversubscribe --allow-run-as-root --mca btl self,vader,tcp)
fail() { echo "FAIL: $*" >&2; exit 1; }

# The sweep's points without timings, Pareto flag and results path; the reference's status.
points() {
  python3 - "$1/sweep.json" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))
print("reference", s["reference_status"])
for p in s["points"]:
    print({k: v for k, v in p.items() if k not in ("ms_median", "ms_p95", "pareto", "pareto_overall", "results")})
PY
}
# The convergence study without the levels' wall times and the cached flag.
study() {
  python3 - "$1/convergence.json" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))
for l in s["levels"]:
    l.pop("wall_s")
s.pop("cached")
print(json.dumps(s, indent=1))
PY
}
sweep() { "${db[@]}" sweep "$here/sweep_toy.json" --quick --no-cache --no-plot "$@"; }

case $mode in
sweep_jobs | sweep_mpi | sweep_slurm_plan)
  sweep --out "$work/serial" > "$work/serial.log" 2>&1 || { cat "$work/serial.log"; fail serial; }
  points "$work/serial" > "$work/serial.points"
  test "$(grep -c "'status': 'ok'" "$work/serial.points")" -eq 4 || { cat "$work/serial.points"; fail "not 4 ok points"; }
  grep -qx "reference ok" "$work/serial.points" || fail "reference not ok"
  ;;&
sweep_jobs)
  for j in 1 2; do
    sweep --out "$work/jobs$j" --jobs "$j" > "$work/jobs$j.log" 2>&1 || { cat "$work/jobs$j.log"; fail "--jobs $j"; }
    points "$work/jobs$j" | diff "$work/serial.points" - || fail "--jobs $j: other points"
  done
  # One case per point; the first solved the reference, the other three read it back.
  test "$(ls -d "$work"/jobs2/runs/point_* | wc -l)" -eq 4 || fail "not 4 point cases"
  test "$(grep -l "reference read from the cache" "$work"/jobs2/runs/point_*/log.txt | wc -l)" -eq 3 \
    || fail "the reference was not solved once"
  stamp() { stat -c %y "$work"/jobs2/runs/point_*/case.json; }
  before=$(stamp)
  sweep --out "$work/jobs2" --jobs 2 --resume > "$work/resume.log" 2>&1 || { cat "$work/resume.log"; fail resume; }
  test "$before" = "$(stamp)" || fail "--resume ran finished points again"
  points "$work/jobs2" | diff "$work/serial.points" - || fail "--resume: other points"
  ;;
sweep_mpi)
  "${mpirun[@]}" -n 3 "${db[@]}" sweep "$here/sweep_toy.json" --quick --no-cache --no-plot \
    --out "$work/mpi" --mpi > "$work/mpi.log" 2>&1 || { cat "$work/mpi.log"; fail mpirun; }
  points "$work/mpi" | diff "$work/serial.points" - || fail "--mpi: other points"
  ;;
sweep_slurm_plan)
  sweep --out "$work/slurm_out" --slurm "$work/slurm" > "$work/plan.log" 2>&1 || { cat "$work/plan.log"; fail plan; }
  grep -q "submit with" "$work/plan.log" || { cat "$work/plan.log"; fail "no plan summary"; }
  test ! -e "$work/slurm_out/sweep.json" || fail "the plan wrote sweep.json"
  grep -q -- "--array=0-0" "$work/slurm/job.sbatch" || fail "stage 0 array"
  grep -q -- "--array=1-3" "$work/slurm/job_1.sbatch" || fail "stage 1 array"
  grep -q "dependency=afterany.*job_1.sbatch" "$work/slurm/submit.sh" || fail "submit.sh order"
  for i in 0 1 2 3; do
    test -s "$work/slurm/tasks/$i.json" || fail "task $i"
    test -s "$work/slurm_out/scenes/point_$i.json" || fail "scene of point $i"
  done
  grep -q -- "--resume" "$work/slurm/collect.sbatch" || fail "collect without --resume"
  for i in 0 1 2 3; do
    (export SLURM_ARRAY_TASK_ID=$i; bash "$work/slurm/$([ $i -eq 0 ] && echo job || echo job_1).sbatch")
  done
  bash "$work/slurm/collect.sbatch" > "$work/collect.log" 2>&1 || { cat "$work/collect.log"; fail collect; }
  points "$work/slurm_out" | diff "$work/serial.points" - || fail "--slurm: other points"
  ;;
converge_jobs)
  conv() { "${db[@]}" converge "$here/converge_cube.json" --no-cache "$@"; }
  conv --out "$work/serial" > "$work/serial.log" 2>&1 || { cat "$work/serial.log"; fail serial; }
  study "$work/serial" > "$work/serial.study"
  test "$(grep -c '"status": "ok"' "$work/serial.study")" -eq 3 || { cat "$work/serial.study"; fail "not 3 ok levels"; }
  conv --out "$work/jobs2" --jobs 2 > "$work/jobs2.log" 2>&1 || { cat "$work/jobs2.log"; fail "--jobs 2"; }
  study "$work/jobs2" | diff "$work/serial.study" - || fail "--jobs 2: another study"
  conv --out "$work/slurm_out" --slurm "$work/slurm" > "$work/plan.log" 2>&1 || { cat "$work/plan.log"; fail plan; }
  grep -q -- "--array=0-2" "$work/slurm/job.sbatch" || fail "array of 3 levels"
  for i in 0 1 2; do (export SLURM_ARRAY_TASK_ID=$i; bash "$work/slurm/job.sbatch"); done
  bash "$work/slurm/collect.sbatch" > "$work/collect.log" 2>&1 || { cat "$work/collect.log"; fail collect; }
  study "$work/slurm_out" | diff "$work/serial.study" - || fail "--slurm: another study"
  # sweep shows the reference's own check once one is cached, and says how to get one before.
  swc() { "${db[@]}" sweep "$here/converge_cube.json" --quick --no-plot --cache-dir "$work/cache" "$@"; }
  swc --out "$work/sw0" > "$work/sw0.log" 2>&1 || { cat "$work/sw0.log"; fail "sweep before"; }
  grep -q "^reference: discretisation error not estimated" "$work/sw0.log" || { cat "$work/sw0.log"; fail "no hint"; }
  python3 -c 'import json,sys; assert json.load(open(sys.argv[1]))["reference_check"] is None' \
    "$work/sw0/sweep.json" || fail "a reference_check without a study"
  "${db[@]}" converge "$here/converge_cube.json" --of-reference --cache-dir "$work/cache" \
    --out "$work/check" > "$work/check.log" 2>&1 || { cat "$work/check.log"; fail "the check"; }
  swc --out "$work/sw1" > "$work/sw1.log" 2>&1 || { cat "$work/sw1.log"; fail "sweep after"; }
  grep -q "^reference: .*(cached study)$" "$work/sw1.log" || { cat "$work/sw1.log"; fail "no check line"; }
  python3 - "$work/sw1/sweep.json" "$work/check/convergence.json" <<'PY' || fail "reference_check"
import json, sys
s, c = (json.load(open(f)) for f in sys.argv[1:])
r = s["reference_check"]
assert [l["elements"] for l in r["levels"]] == [l["elements"] for l in c["levels"]], r
assert r["converged"] == c["converged"] and r["reason"] == c["reason"], (r, c)
assert (r["relative_error"] is None) == (c["relative_error"] is None), (r, c)
PY
  ;;
*) echo "unknown mode $mode"; exit 2 ;;
esac
echo "dispatch $mode: equal to the serial run"
