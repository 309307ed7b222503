#!/usr/bin/env bash
# README command (1): install dependencies, build the tools, calibrate the shipped default data
# (the paper's section-4 simulation) and print the iteration table and before/after errors.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release -DBUILD_TESTING=OFF -DLPOE_BUILD_BENCHMARKS=OFF >/dev/null
cmake --build build -j2 --target lpoe_calibrate lpoe_compare lpoe_simulate lpoe_plan lpoe_predict \
  lpoe_compensate >/dev/null
./build/tools/lpoe_calibrate "$@"
