#!/usr/bin/env bash
# Builds everything -- library, tools, Python module, benchmarks, tests and the libFuzzer targets (run
# by `scripts/fuzz.sh SECONDS build-asan`) -- with clang + AddressSanitizer + UndefinedBehaviorSanitizer
# (-DLPOE_SANITIZE=ON, RelWithDebInfo at -O1 with line tables only, which is all the sanitizer
# reports need and compiles much faster than -g) in build-asan and runs every test there. Any
# sanitizer report fails the run (-fno-sanitize-recover=undefined, ASan aborts on the first error).
# Ceres, glog, gflags and yaml-cpp are Debian's uninstrumented gcc builds; that is fine for ASan
# (it intercepts malloc/free globally) and UBSan (checks only our code).
# UBSan runs without its vptr, object-size, pointer-overflow, alignment and null checks, which
# quadruple the compile time; why that is a fair trade is written beside LPOE_SANITIZER_FLAGS in CMakeLists.txt.
# It is a unity build (CMAKE_UNITY_BUILD, up to 16 files per translation unit): a third less compile
# time; what that asks of the code is in docs/testing.md.
# The Python tests run in Debian's python3 with the sanitizer runtime preloaded and leak detection off
# (python/CMakeLists.txt); the Install.* tests build their downstream project with this build's
# compiler, and the installed package carries the sanitizer link flags (core/CMakeLists.txt).
#
#   bash scripts/ci_sanitize.sh
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh

build=build-asan
gen=(); [ -f "$build/CMakeCache.txt" ] || gen=(-G Ninja)  # Ninja for a new build directory
CC=clang CXX=clang++ cmake "${gen[@]}" -S . -B "$build" -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -gline-tables-only" -DLPOE_SANITIZE=ON \
  -DCMAKE_EXE_LINKER_FLAGS=-fuse-ld=lld -DCMAKE_SHARED_LINKER_FLAGS=-fuse-ld=lld \
  -DCMAKE_MODULE_LINKER_FLAGS=-fuse-ld=lld \
  -DBUILD_TESTING=ON -DLPOE_BUILD_BENCHMARKS=ON -DLPOE_BUILD_TOOLS=ON -DLPOE_FUZZ=ON \
  -DLPOE_BUILD_PYTHON=ON -DLPOE_PRECOMPILED_HEADERS=OFF -DCMAKE_UNITY_BUILD=ON -DCMAKE_UNITY_BUILD_BATCH_SIZE=16 >/dev/null
cmake --build "$build" -j2

# Without detect_stack_use_after_return: its fake stack frames (one heap frame per call with
# addressable locals) made the suite 1.5-1.8x slower (measured on the Jet-heavy solver and planning
# tests) for one class of bug, a pointer or reference to a local used after its function returned.
# The fuzzers, which drive the readers and parsers (string views into the text), keep it on
# (scripts/fuzz.sh); use-after-scope, heap and stack overflows are still caught here.
# With a 32 MB quarantine instead of ASan's 256 MB: freed memory is held poisoned (an access to it
# is a use-after-free report) until 32 MB more have been freed, then reused. With 256 MB a process
# that frees a few hundred MB keeps taking fresh pages, each a page fault (a quarter of the suite's
# CPU was system time); the suite's longest entries ran about 10% faster (docs/testing.md).
export ASAN_OPTIONS="${ASAN_OPTIONS:-detect_leaks=1:abort_on_error=1:strict_string_checks=1:detect_stack_use_after_return=0:quarantine_size_mb=32}"
export LSAN_OPTIONS="${LSAN_OPTIONS:-suppressions=$PWD/scripts/lsan.supp}"
export UBSAN_OPTIONS="${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}"
ctest --test-dir "$build" --output-on-failure -j2 --timeout 900
