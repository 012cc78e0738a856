#!/usr/bin/env bash
# dispatch_test.sh MODE DEFORMBENCH PLUGIN_DIR WORK: one dispatch test (see CMakeLists.txt).
#   jobs             --jobs 2 gives the --jobs 1 rows
#   mpi              mpirun -n 3 ... --mpi gives the serial rows
#   mpi_lost_worker  worker rank 1 is killed (SIGKILL) while it runs a case: rank 0 gives the
#                    case to rank 2 and the rows are the serial ones
#   slurm_plan       --slurm DIR writes the array, the tasks and the collect step; running them
#                    by hand (as the array would) then the collect step gives the serial rows
#   serial           the serial run whose rows the others compare with (a CTest fixture run
#                    once, in WORK/../serial)
set -euo pipefail
mode=$1 exe=$(readlink -f "$2") plugins=$3 work=$4
serial=$(dirname "$work")/serial
rm -rf "$work"
mkdir -p "$work/plugins"
for p in pbd massspring; do ln -s "$plugins/deform_$p.so" "$work/plugins/"; done
# The build's plugin folder is searched after --plugin-dir, so hybrid_fem_pbd and reference_fem
# run too; 100 target tets keep the reference on the cube's coarsest quadratic mesh (~2,700 tets).
common=(--plugin-dir "$work/plugins" tables hybrid-timing --quick --no-cache --no-reference-check
  --reference-elements 100)
mpirun=(mpirun --oversubscribe --allow-run-as-root --mca btl self,vader,tcp)

# The rows without their timings (keys ending _ms or _s) plus every case's run statuses.
rows() {
  python3 - "$1" <<'PY'
import json, sys, glob, os
d = sys.argv[1]
t = json.load(open(os.path.join(d, "hybrid-timing.json")))
for r in t["rows"]:
    print({k: v for k, v in r.items() if not (k.endswith("_ms") or k.endswith("_s"))})
for f in sorted(glob.glob(os.path.join(d, "runs", "*", "*", "results.json")) +
                glob.glob(os.path.join(d, "runs", "*", "results.json"))):
    runs = json.load(open(f))["runs"]
    print(os.path.relpath(f, d), [(r["label"], r["status"], r.get("steps")) for r in runs])
PY
}

if [[ $mode == serial ]]; then
  "$exe" "${common[@]}" --out "$work/serial" > "$work/serial.log" 2>&1
  rows "$work/serial" > "$work/serial.rows"
  test "$(grep -c "'status'" "$work/serial.rows")" -eq 4 || { cat "$work/serial.rows"; exit 1; }
  exit 0
fi
test -f "$serial/serial.rows" || { echo "no serial rows in $serial (run dispatch_serial)"; exit 1; }

case $mode in
  jobs)
    "$exe" "${common[@]}" --out "$work/other" --jobs 2 > "$work/other.log" 2>&1
    ;;
  mpi)
    "${mpirun[@]}" -n 3 "$exe" "${common[@]}" --out "$work/other" --mpi > "$work/other.log" 2>&1
    ;;
  mpi_lost_worker)
    export DEFORM_MPI_LOST_AFTER=3
    "${mpirun[@]}" --enable-recovery -n 3 "$exe" "${common[@]}" --out "$work/other" --mpi \
      > "$work/other.log" 2>&1 &
    launcher=$!
    # The first `deformbench run` child of this test (its --out is under $work: ctest runs the
    # other dispatch tests at the same time, with the same executable) whose parent is rank 1:
    # kill that parent.
    own_runs=$(printf '%s' "$work/other/runs/" | sed 's/[][\\.*^$+?(){}|]/\\&/g')
    killed=""
    for _ in $(seq 1 1500); do
      for child in $(pgrep -f "^$exe.* run .*$own_runs" || true); do
        parent=$(ps -o ppid= -p "$child" | tr -d ' ') || continue
        if tr '\0' '\n' < "/proc/$parent/environ" 2>/dev/null | grep -qx OMPI_COMM_WORLD_RANK=1; then
          kill -9 "$parent" && killed=$parent
          break 2
        fi
      done
      sleep 0.02
    done
    test -n "$killed" || { echo "never saw rank 1 run a case"; kill "$launcher"; exit 1; }
    wait "$launcher" || { echo "mpirun failed"; cat "$work/other.log"; exit 1; }
    grep -q "worker rank 1 lost" "$work/other.log" || { cat "$work/other.log"; exit 1; }
    ;;
  slurm_plan)
    "$exe" "${common[@]}" --out "$work/other" --slurm "$work/slurm" > "$work/plan.log" 2>&1
    grep -q "submit with" "$work/plan.log" || { cat "$work/plan.log"; exit 1; }
    test ! -e "$work/other/hybrid-timing.json"
    grep -q -- "--array=0-3" "$work/slurm/job.sbatch"
    for i in 0 1 2 3; do
      (export SLURM_ARRAY_TASK_ID=$i; bash "$work/slurm/job.sbatch")
    done
    bash "$work/slurm/collect.sbatch" > "$work/other.log" 2>&1
    test "$(grep -c "(resumed)" "$work/other.log")" -eq 4 || { cat "$work/other.log"; exit 1; }
    ;;
  *) echo "unknown mode $mode"; exit 2 ;;
esac
rows "$work/other" > "$work/other.rows"
diff "$serial/serial.rows" "$work/other.rows"
echo "dispatch $mode: the rows equal the serial run's"
