#!/usr/bin/env bash
# README command (2): install dependencies, build everything (library, tools, tests, benchmarks)
# and run the whole test suite; then fuzz the file readers for 30 s each (scripts/fuzz.sh) and run the
# suite again under AddressSanitizer + UBSan (scripts/ci_sanitize.sh).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
cmake -S . -B build-test -DCMAKE_BUILD_TYPE=Release -DBUILD_TESTING=ON -DLPOE_BUILD_BENCHMARKS=ON >/dev/null
cmake --build build-test -j2
ctest --test-dir build-test --output-on-failure -j2 --timeout 600
bash scripts/fuzz.sh 30
bash scripts/ci_sanitize.sh
