#!/usr/bin/env bash
# README command (1): install dependencies, build every tool and the Python module, calibrate the
# shipped default data (the paper's section-4 simulation) and print the iteration table and
# before/after errors. The build prints its progress ([n/N] per compiled file); on two cores it
# takes 10 to 20 minutes the first time, seconds after.
set -euo pipefail
cd "$(dirname "$0")/.."
echo "quickstart: [1/4] system packages (scripts/setup.sh)"
bash scripts/setup.sh
echo "quickstart: [2/4] configuring build/ (Release, no tests or benchmarks)"
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release -DBUILD_TESTING=OFF -DLPOE_BUILD_BENCHMARKS=OFF >/dev/null
targets=(lpoe_calibrate lpoe_compare lpoe_simulate lpoe_plan lpoe_predict lpoe_compensate lpoe_prior)
# The Python module, when pybind11 was found (python/CMakeLists.txt): `_lpoe`.
if cmake --build build --target help 2>/dev/null | grep -q '_lpoe'; then targets+=(_lpoe); fi
echo "quickstart: [3/4] building ${targets[*]} (10-20 minutes on two cores the first time)"
start=$(date +%s)
# Ninja's and Make's own progress lines, one per compiled file, without the compiler's output.
set +e
cmake --build build -j2 --target "${targets[@]}" 2>&1 | grep --line-buffered -E '^\[ *[0-9]+(/[0-9]+\]|%\])'
status=${PIPESTATUS[0]}
set -e
if [ "$status" -ne 0 ]; then
  echo "quickstart: the build failed; run cmake --build build to see why" >&2
  exit 1
fi
echo "quickstart: built in $(( $(date +%s) - start )) s; tools in build/tools/, Python module in build/python (PYTHONPATH=build/python)"
echo "quickstart: [4/4] lpoe_calibrate $*"
./build/tools/lpoe_calibrate "$@"
