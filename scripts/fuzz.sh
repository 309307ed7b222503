#!/usr/bin/env bash
# Builds the libFuzzer targets (fuzz/) with clang in build-fuzz and runs them side by side for the given
# number of seconds (default 60): fuzz_csv (measurements CSV), fuzz_yaml (robot model YAML), fuzz_urdf (robot
# model URDF), fuzz_report_text (names and paths of any bytes through the report writers' text
# functions), fuzz_urscript and fuzz_rapid (robot programs), fuzz_targets_only (the --targets_only
# filter, RE2, on any pattern and name). Each run starts from a copy of the
# committed seed corpus fuzz/corpus/<kind>/ in build-fuzz/corpus/ (the committed corpus is never
# modified). Fails on any crash, sanitizer report, leak, timeout (> 10 s per input) or out-of-memory
# (> 2048 MB); the reproducer is left in build-fuzz/artifacts/<target>/ and its log in
# build-fuzz/logs/. To replay one:
#   build-fuzz/fuzz/fuzz_csv build-fuzz/artifacts/fuzz_csv/crash-...
# Fixed findings go into fuzz/corpus/<kind>/ as regression seeds.
#
# With a second argument, the targets are taken from that build directory instead, which must already
# be configured with -DLPOE_FUZZ=ON and clang: CI (scripts/test.sh) passes the sanitizer build
# (build-asan), whose lpoe_core then carries the coverage instrumentation, so that the core library is
# not compiled a third time.
#
#   bash scripts/fuzz.sh [seconds] [configured build directory]
set -euo pipefail
cd "$(dirname "$0")/.."
seconds="${1:-60}"
if ! [[ "$seconds" =~ ^[0-9]+$ ]] || [ "$seconds" -lt 1 ]; then
  echo "usage: scripts/fuzz.sh [seconds >= 1] [configured build directory]" >&2
  exit 1
fi
bash scripts/setup.sh

if [ $# -ge 2 ]; then
  build=$2
  if ! grep -q '^LPOE_FUZZ:BOOL=ON$' "$build/CMakeCache.txt" 2>/dev/null; then
    echo "fuzz: $build is not a build directory configured with -DLPOE_FUZZ=ON" >&2
    exit 1
  fi
else
  build=build-fuzz
  # Only lpoe_core's sources are compiled (instrumented, as lpoe_core_fuzz) plus the fuzz targets.
  # -O1 with line tables (libFuzzer's recommended level; much faster to compile than -O2 -g), linked
  # with lld.
  gen=(); [ -f "$build/CMakeCache.txt" ] || gen=(-G Ninja)  # Ninja for a new build directory
  CC=clang CXX=clang++ cmake "${gen[@]}" -S . -B "$build" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DLPOE_FUZZ=ON \
    -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -gline-tables-only" -DCMAKE_EXE_LINKER_FLAGS=-fuse-ld=lld \
    -DBUILD_TESTING=OFF -DLPOE_BUILD_BENCHMARKS=OFF -DLPOE_BUILD_TOOLS=OFF -DLPOE_BUILD_PYTHON=OFF >/dev/null
fi
cmake --build "$build" -j2 --target lpoe_fuzz

export ASAN_OPTIONS="${ASAN_OPTIONS:-detect_leaks=1:abort_on_error=1:detect_stack_use_after_return=1}"
export UBSAN_OPTIONS="${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}"
failed=()
# The targets run at the same time (they share the machine's cores; with 2 cores each gets
# about two fifths of one, so `seconds` of wall time is about 2/5 * seconds of fuzzing per target).
declare -A pids
for kind in csv contact_csv yaml urdf report_text urscript rapid targets_only; do
  target="fuzz_$kind"
  exe="$build/fuzz/$target"
  if [ ! -x "$exe" ]; then
    echo "fuzz: $target was not built (see the cmake output), skipped" >&2
    failed+=("$target (not built)")
    continue
  fi
  work="$build/corpus/$kind"
  artifacts="$build/artifacts/$target/"
  log="$build/logs/$target.log"
  mkdir -p "$work" "$artifacts" "$(dirname "$log")"
  cp -f fuzz/corpus/"$kind"/* "$work"/
  echo "fuzz: $target for ${seconds}s (corpus $work, log $log)"
  "$exe" -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 -max_len=8192 \
    -dict="fuzz/$kind.dict" -artifact_prefix="$artifacts" -print_final_stats=1 \
    "$work" >"$log" 2>&1 &
  pids[$kind]=$!
done
for kind in csv contact_csv yaml urdf report_text urscript rapid targets_only; do
  [ -n "${pids[$kind]:-}" ] || continue
  target="fuzz_$kind"
  log="$build/logs/$target.log"
  if wait "${pids[$kind]}"; then
    echo -n "fuzz: $target: "
    grep -E '^stat::number_of_executed_units|^stat::new_units_added|^Done ' "$log" | tr '\n' ' '; echo
  else
    echo "fuzz: $target FAILED; last lines of $log:" >&2
    tail -n 60 "$log" >&2
    failed+=("$target")
  fi
done
if [ ${#failed[@]} -gt 0 ]; then
  echo "fuzz: failures: ${failed[*]} (reproducers in $build/artifacts/)" >&2
  exit 1
fi
echo "fuzz: no findings"
