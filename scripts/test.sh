#!/usr/bin/env bash
# README command (2), what CI runs (.ci/run): install the dependencies, then
#  1. a Release build (gcc, -O2) of the library, tools, Python module and benchmarks in build-test, and
#     the tests that need a normal, uninstrumented build there: the Python suite (pytest), the
#     installed package (Install.*) and the README's flag list (Docs.*);
#  2. one build of everything with clang + AddressSanitizer + UBSan in build-asan (scripts/ci_sanitize.sh)
#     and the whole GoogleTest suite there;
#  3. the three file readers fuzzed side by side for 45 s with that build's libFuzzer targets
#     (scripts/fuzz.sh).
# The GoogleTest programs are compiled once, in the sanitizer build, not a second time in Release: that
# second compile was a quarter of the run. A Release build with every test is the default of any other
# build directory (`cmake -S . -B build && cmake --build build && ctest --test-dir build`).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
# lld links the test and benchmark programs (each with static Ceres) several times faster than ld.
# Ninja for a new build directory (an existing one keeps the generator it was made with).
gen=(); [ -f build-test/CMakeCache.txt ] || gen=(-G Ninja)
cmake "${gen[@]}" -S . -B build-test -DCMAKE_BUILD_TYPE=Release -DBUILD_TESTING=ON -DLPOE_BUILD_TEST_PROGRAMS=OFF \
  -DLPOE_BUILD_BENCHMARKS=ON -DCMAKE_EXE_LINKER_FLAGS=-fuse-ld=lld -DCMAKE_SHARED_LINKER_FLAGS=-fuse-ld=lld \
  -DCMAKE_MODULE_LINKER_FLAGS=-fuse-ld=lld -DLPOE_PRECOMPILED_HEADERS=ON >/dev/null
cmake --build build-test -j2
ctest --test-dir build-test --output-on-failure -j2 --timeout 600
bash scripts/ci_sanitize.sh
bash scripts/fuzz.sh 45 build-asan
