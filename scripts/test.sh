#!/usr/bin/env bash
# README command (2): install dependencies, build everything (library, tools, tests, benchmarks)
# and run the whole test suite; then fuzz the three file readers side by side for 45 s (scripts/fuzz.sh) and run the
# suite again under AddressSanitizer + UBSan (scripts/ci_sanitize.sh).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
# lld links the ~40 test and benchmark programs (each with static Ceres) several times faster than ld.
# Ninja for a new build directory (an existing one keeps the generator it was made with).
gen=(); [ -f build-test/CMakeCache.txt ] || gen=(-G Ninja)
cmake "${gen[@]}" -S . -B build-test -DCMAKE_BUILD_TYPE=Release -DBUILD_TESTING=ON -DLPOE_BUILD_BENCHMARKS=ON \
  -DCMAKE_EXE_LINKER_FLAGS=-fuse-ld=lld -DCMAKE_SHARED_LINKER_FLAGS=-fuse-ld=lld \
  -DCMAKE_MODULE_LINKER_FLAGS=-fuse-ld=lld -DLPOE_PRECOMPILED_HEADERS=ON >/dev/null
cmake --build build-test -j2
ctest --test-dir build-test --output-on-failure -j2 --timeout 600
bash scripts/fuzz.sh 45
bash scripts/ci_sanitize.sh
