#!/usr/bin/env bash
# Builds the libFuzzer targets (tests/fuzz) with clang + ASan + UBSan in build-fuzz/ and runs each
# for a bounded time. Usage:
#   scripts/fuzz.sh [SECONDS_PER_TARGET] [TARGET...]     (default 20 s; targets: obj stl off ply
#                                                          vtk msh scene, default all)
# Each target first replays its saved crashes (tests/fuzz/regressions/<target>/), then fuzzes
# from its seeds (tests/fuzz/corpus/<target>/, read-only) plus a working corpus kept in
# build-fuzz/corpus/<target>/ (it grows from run to run). Limits per input: -timeout (s),
# -rss_limit_mb (also the malloc limit), -max_len (bytes). A crash, sanitizer report, leak,
# timeout or out-of-memory writes a reproducer into build-fuzz/artifacts/<target>/ and makes the
# script exit 1 after all targets ran, printing every reproducer path.
# Environment: FUZZ_JOBS (build parallelism, default nproc), FUZZ_PARALLEL (targets fuzzed side
# by side, default nproc), FUZZ_TIMEOUT (default 10), FUZZ_RSS_MB (default 2048), FUZZ_MAX_LEN
# (default 16384), FUZZ_BUILD_DIR (default build-fuzz), FUZZ_REUSE=1 (FUZZ_BUILD_DIR is a build
# configured elsewhere with the fuzzers, such as scripts/sanitize.sh --ci's build-asan with clang:
# the targets are built there as configured, without a configure step of this script's).
set -euo pipefail
cd "$(dirname "$0")/.."

seconds=${1:-20}
[[ $# -gt 0 ]] && shift
targets=("$@")
[[ ${#targets[@]} -eq 0 ]] && targets=(obj stl off ply vtk msh scene)
build=${FUZZ_BUILD_DIR:-build-fuzz}
jobs=${FUZZ_JOBS:-$(nproc)}
timeout=${FUZZ_TIMEOUT:-10}
rss=${FUZZ_RSS_MB:-2048}
maxlen=${FUZZ_MAX_LEN:-16384}
# Each fuzzer is one process on one core: FUZZ_PARALLEL of them at a time (default nproc).
parallel=${FUZZ_PARALLEL:-$(nproc)}
if [[ ! $parallel =~ ^[1-9][0-9]*$ ]]; then
  echo "fuzz.sh: FUZZ_PARALLEL must be a whole number of at least 1, got '$parallel'" >&2
  exit 2
fi

if ! command -v clang++ >/dev/null; then
  echo "fuzz.sh: clang++ not found (the fuzzers need clang's libFuzzer)" >&2
  exit 2
fi

# The core is built with the sanitizers and coverage too; plugins, tests and benchmarks are off.
plugin_flags=()
for p in PBD MASSSPRING REFERENCE_FEM FEM_HEX METABALLS PARTICLE_BEM HYBRID_FEM_PBD \
  BULLET_SOFTBODY BULLET_DEFORMABLE; do
  plugin_flags+=("-DDEFORM_WITH_${p}=OFF")
done
if [[ ${FUZZ_REUSE:-0} == 1 ]]; then
  if ! grep -q '^DEFORM_BUILD_FUZZERS:BOOL=ON' "$build/CMakeCache.txt" 2>/dev/null; then
    echo "fuzz.sh: FUZZ_REUSE=1 but $build is not a build configured with the fuzzers" >&2
    exit 2
  fi
else
  source scripts/cmake_tools.sh
  cmake_tools "$build"  # generator, launcher
  cmake -S . -B "$build" "${generator[@]}" "${launcher[@]}" -DCMAKE_C_COMPILER=clang \
    -DCMAKE_CXX_COMPILER=clang++ -DCMAKE_BUILD_TYPE=Debug \
    -DCMAKE_CXX_FLAGS_DEBUG="-O1 -gline-tables-only" -DDEFORM_SANITIZE=ON \
    -DDEFORM_BUILD_FUZZERS=ON -DDEFORM_BUILD_TESTS=OFF -DDEFORM_BUILD_BENCHMARKS=OFF \
    "${plugin_flags[@]}" >/dev/null
fi
build_targets=()
for t in "${targets[@]}"; do build_targets+=("fuzz_$t"); done
cmake --build "$build" -j "$jobs" --target "${build_targets[@]}"

export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1:abort_on_error=1:allocator_may_return_null=0}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}

# One target: replay its regressions, then fuzz. What it prints goes to logs/fuzz_<t>.out, a
# failure's line to logs/fuzz_<t>.failed (the targets run side by side, FUZZ_PARALLEL at a time).
fuzz_one() {
  local t=$1
  local bin=$build/fuzz/fuzz_$t seeds=tests/fuzz/corpus/$t regressions=tests/fuzz/regressions/$t
  local work=$build/corpus/$t artifacts=$build/artifacts/$t log=$build/logs/fuzz_$t.log
  local failed_file=$build/logs/fuzz_$t.failed
  rm -f "$failed_file"
  mkdir -p "$work" "$artifacts" "$(dirname "$log")"
  local common=(-timeout="$timeout" -rss_limit_mb="$rss" -max_len="$maxlen"
    -artifact_prefix="$artifacts/")
  if compgen -G "$regressions/*" >/dev/null; then
    echo "== $t: replaying $regressions"
    if ! "$bin" "${common[@]}" "$regressions"/* >"$log.replay" 2>&1; then
      tail -n 40 "$log.replay"
      echo "$t: a saved regression input fails again (see $log.replay)" >"$failed_file"
      return
    fi
  fi
  echo "== $t: fuzzing for ${seconds}s (log $log)"
  local before
  before=$(ls "$artifacts" | wc -l)
  if "$bin" "${common[@]}" -max_total_time="$seconds" -print_final_stats=1 "$work" "$seeds" \
    >"$log" 2>&1; then
    grep -E '^stat::number_of_executed_units|^stat::new_units_added' "$log" | tr '\n' ' '
    echo
  else
    grep -m1 -A25 -E "^==[0-9]+==|^SUMMARY|ERROR:" "$log" || tail -n 40 "$log"
    echo "$t: reproducer $artifacts/$(ls -t "$artifacts" | head -n 1) (log $log)" >"$failed_file"
  fi
  if [[ $(ls "$artifacts" | wc -l) -gt $before && ! -f $failed_file ]]; then
    echo "$t: new files in $artifacts" >"$failed_file"
  fi
}

mkdir -p "$build/logs"
for t in "${targets[@]}"; do
  while [[ $(jobs -rp | wc -l) -ge $parallel ]]; do wait -n || true; done
  rm -f "$build/logs/fuzz_$t.done"
  { fuzz_one "$t" && touch "$build/logs/fuzz_$t.done"; } >"$build/logs/fuzz_$t.out" 2>&1 &
done
wait
failed=()
for t in "${targets[@]}"; do
  cat "$build/logs/fuzz_$t.out"
  if [[ -f $build/logs/fuzz_$t.failed ]]; then
    failed+=("$(cat "$build/logs/fuzz_$t.failed")")
  elif [[ ! -f $build/logs/fuzz_$t.done ]]; then
    failed+=("$t: the script's run of it stopped early (see $build/logs/fuzz_$t.out)")
  fi
done

if [[ ${#failed[@]} -gt 0 ]]; then
  echo
  echo "fuzz.sh: FAILED"
  for f in "${failed[@]}"; do echo "  $f"; done
  echo "Reproduce with: $build/fuzz/fuzz_<target> <reproducer>; once fixed, copy the reproducer" \
    "into tests/fuzz/regressions/<target>/"
  exit 1
fi
echo "fuzz.sh: no crash in ${targets[*]} (${seconds}s each)"
