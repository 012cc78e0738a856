#!/usr/bin/env bash
# slurm_e2e.sh DEFORMBENCH PLUGIN_DIR WORK: a quick table through a real single-node Slurm.
# Starts munged (key in /etc/munge), slurmctld and slurmd (slurm.conf in WORK naming this host
# as controller and node, auth/munge, proctrack/linuxproc, state and spool under WORK), runs
# `tables hybrid-timing --quick --slurm`, submits the array and the collect step, waits, and
# compares the rows with a serial run. Stops what it started. Needs root, slurm-wlm and munge
# (not installed by setup.sh: run `apt-get install slurm-wlm munge` first). ctest runs it as
# dispatch_slurm_e2e when slurmctld, slurmd, munged and sbatch are found.
set -euo pipefail
exe=$(readlink -f "$1") plugins=$2 work=$3
# Optional: the toy fixture's folder; then a sweep (two arrays, the second after the first) goes
# through the same Slurm too (sweep_converge_test.sh's scene, a few seconds).
toy=${4:-}
for tool in slurmctld slurmd munged sbatch squeue; do
  command -v "$tool" > /dev/null || { echo "slurm_e2e: $tool not installed: skipped"; exit 77; }
done
[ "$(id -u)" -eq 0 ] || { echo "slurm_e2e: needs root: skipped"; exit 77; }
[ -r /etc/munge/munge.key ] || { echo "slurm_e2e: no /etc/munge/munge.key: skipped"; exit 77; }
rm -rf "$work"
mkdir -p "$work/plugins" "$work/state" "$work/spool" "$work/munge"
for p in pbd massspring; do ln -s "$plugins/deform_$p.so" "$work/plugins/"; done
[ -n "$toy" ] && ln -s "$(readlink -f "$toy")/deform_toy.so" "$work/plugins/"
host=$(hostname -s)
cpus=$(nproc)
pids=()
cleanup() {
  for pid in "${pids[@]}"; do kill "$pid" 2> /dev/null || true; done
  for pid in "${pids[@]}"; do
    for _ in $(seq 50); do kill -0 "$pid" 2> /dev/null || break; sleep 0.1; done
  done
}
trap cleanup EXIT

# munge: our own socket, so a munged already running elsewhere is left alone.
sock="$work/munge/munge.socket"
munged --force --socket="$sock" --pid-file="$work/munge/munged.pid" \
  --log-file="$work/munge/munged.log" --seed-file="$work/munge/seed"
for _ in $(seq 50); do [ -s "$work/munge/munged.pid" ] && break; sleep 0.1; done
pids+=("$(cat "$work/munge/munged.pid")")

port=$((17000 + RANDOM % 2000))
cat > "$work/slurm.conf" <<CONF
ClusterName=deformtest
SlurmctldHost=$host
SlurmctldPort=$port
SlurmdPort=$((port + 1))
AuthType=auth/munge
AuthInfo=socket=$sock
CredType=cred/munge
SlurmUser=root
SlurmdUser=root
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
SchedulerType=sched/builtin
ReturnToService=2
MpiDefault=none
JobCompType=jobcomp/none
AccountingStorageType=accounting_storage/none
JobAcctGatherType=jobacct_gather/none
StateSaveLocation=$work/state
SlurmdSpoolDir=$work/spool
SlurmctldPidFile=$work/slurmctld.pid
SlurmdPidFile=$work/slurmd.pid
SlurmctldLogFile=$work/slurmctld.log
SlurmdLogFile=$work/slurmd.log
NodeName=$host CPUs=$cpus State=UNKNOWN
PartitionName=test Nodes=$host Default=YES MaxTime=INFINITE State=UP
CONF
export SLURM_CONF=$work/slurm.conf
slurmctld -f "$SLURM_CONF" -i
for _ in $(seq 50); do [ -s "$work/slurmctld.pid" ] && break; sleep 0.1; done
pids+=("$(cat "$work/slurmctld.pid")")
slurmd -f "$SLURM_CONF"
for _ in $(seq 50); do [ -s "$work/slurmd.pid" ] && break; sleep 0.1; done
pids+=("$(cat "$work/slurmd.pid")")
for _ in $(seq 100); do
  sinfo -h -o %t 2> /dev/null | grep -q idle && break
  sleep 0.2
done
sinfo -h -o %t | grep -q idle || { echo "slurm node not idle"; sinfo; cat "$work/slurmctld.log"; exit 1; }

# Until the queue is empty, 5 minutes at most.
wait_for_queue() {
  for _ in $(seq 600); do
    [ -z "$(squeue -h -o %i)" ] && break
    sleep 0.5
  done
}

# The build's plugin folder is searched after --plugin-dir, so hybrid_fem_pbd and reference_fem
# run too; 100 target tets keep the reference on the cube's coarsest quadratic mesh (~2,700 tets).
common=(--plugin-dir "$work/plugins" tables hybrid-timing --quick --no-cache --no-reference-check
  --reference-elements 100)
"$exe" "${common[@]}" --out "$work/serial" > "$work/serial.log" 2>&1
"$exe" "${common[@]}" --out "$work/cluster" --slurm "$work/plan" > "$work/plan.log" 2>&1
"$work/plan/submit.sh" > "$work/submit.log"
wait_for_queue
[ -z "$(squeue -h -o %i)" ] || { echo "jobs still queued"; squeue; exit 1; }
[ -s "$work/cluster/hybrid-timing.json" ] || {
  echo "no table"; cat "$work/plan/logs/"* "$work/slurmctld.log"; exit 1
}
strip() {
  python3 -c 'import json,sys
for r in json.load(open(sys.argv[1]))["rows"]:
    print({k: v for k, v in r.items() if not (k.endswith("_ms") or k.endswith("_s"))})' "$1"
}
diff <(strip "$work/serial/hybrid-timing.json") <(strip "$work/cluster/hybrid-timing.json")
grep -c "(resumed)" "$work/plan/logs/collect.out"
echo "slurm_e2e: the table through Slurm equals the serial one"

[ -n "$toy" ] || exit 0
here=$(cd "$(dirname "$0")" && pwd)
sweep=(--plugin-dir "$work/plugins" sweep "$here/sweep_toy.json" --quick --no-cache --no-plot)
"$exe" "${sweep[@]}" --out "$work/sweep_serial" > "$work/sweep_serial.log" 2>&1
"$exe" "${sweep[@]}" --out "$work/sweep_cluster" --slurm "$work/sweep_plan" > "$work/sweep_plan.log" 2>&1
"$work/sweep_plan/submit.sh" > "$work/sweep_submit.log"
wait_for_queue
[ -s "$work/sweep_cluster/sweep.json" ] || {
  echo "no sweep"; cat "$work/sweep_plan/logs/"* "$work/slurmctld.log"; exit 1
}
points() {
  python3 -c 'import json,sys
s = json.load(open(sys.argv[1]))
print(s["reference_status"])
for p in s["points"]:
    print({k: v for k, v in p.items() if k not in ("ms_median", "ms_p95", "pareto", "pareto_overall", "results")})' "$1"
}
diff <(points "$work/sweep_serial/sweep.json") <(points "$work/sweep_cluster/sweep.json")
echo "slurm_e2e: the sweep through Slurm (two arrays) equals the serial one"
