#!/usr/bin/env bash
# Builds the library, tools, tests and the libFuzzer targets (run by `scripts/fuzz.sh SECONDS build-asan`)
# with clang + AddressSanitizer + UndefinedBehaviorSanitizer
# (-DLPOE_SANITIZE=ON, RelWithDebInfo at -O1 with line tables only, which is all the sanitizer
# reports need and compiles much faster than -g) in build-asan and runs the whole test suite there. Any
# sanitizer report fails the run (-fno-sanitize-recover=undefined, ASan aborts on the first error).
# Ceres, glog, gflags and yaml-cpp are Debian's uninstrumented gcc builds; that is fine for ASan
# (it intercepts malloc/free globally) and UBSan (checks only our code).
# UBSan runs without its vptr, object-size and pointer-overflow checks, which double the compile
# time; why that is a fair trade is written beside LPOE_SANITIZER_FLAGS in CMakeLists.txt.
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
  -DBUILD_TESTING=ON -DLPOE_BUILD_BENCHMARKS=OFF -DLPOE_BUILD_TOOLS=ON -DLPOE_FUZZ=ON \
  -DLPOE_BUILD_PYTHON=OFF -DLPOE_PRECOMPILED_HEADERS=ON >/dev/null
cmake --build "$build" -j2

export ASAN_OPTIONS="${ASAN_OPTIONS:-detect_leaks=1:abort_on_error=1:strict_string_checks=1:detect_stack_use_after_return=1}"
export LSAN_OPTIONS="${LSAN_OPTIONS:-suppressions=$PWD/scripts/lsan.supp}"
export UBSAN_OPTIONS="${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}"
# The Python module is not built here: an ASan-instrumented extension cannot be loaded into Debian's
# uninstrumented python3 without preloading the sanitizer runtime into the interpreter, which then
# reports the interpreter's own allocations; the module's C++ code is the library tested here.
# Every test except Install.* (tests/CMakeLists.txt): that one installs the package and builds a
# downstream project against it without sanitizer flags, which cannot link sanitizer-instrumented
# libraries; it checks packaging, not memory safety, and runs in the normal build.
ctest --test-dir "$build" --output-on-failure -j2 --timeout 900 -E '^Install\.'
