#!/usr/bin/env bash
# README command (2), what CI runs (.ci/run): install the dependencies, then
#  1. one build of everything -- library, tools, Python module, benchmarks, the GoogleTest program and the
#     libFuzzer targets -- with clang + AddressSanitizer + UBSan in build-asan (scripts/ci_sanitize.sh),
#     and every test there: the GoogleTest suite, pytest (one ctest entry per file, in an interpreter
#     with the sanitizer runtime preloaded), the installed package (Install.*) and the README's flag list (Docs.*);
#  2. the three file readers, the report text and the two program parsers fuzzed side by side for
#     45 s with that build's libFuzzer targets (scripts/fuzz.sh).
# CI compiles the code once. A Release (gcc -O2) build with every test is the default of any other
# build directory (`cmake -S . -B build && cmake --build build && ctest --test-dir build`): run it
# before a release, and README command (1) builds and runs the main job that way.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
bash scripts/ci_sanitize.sh
bash scripts/fuzz.sh 45 build-asan
