#!/usr/bin/env bash
# Installs the Debian packages lpoe-calib needs. Idempotent: does nothing (quietly) when they are
# all there. Runs apt-get through sudo when not root.
set -euo pipefail

PACKAGES=(
  cmake g++ make
  libeigen3-dev libceres-dev libgoogle-glog-dev libgflags-dev
  libyaml-cpp-dev          # robot model files (YAML with line numbers in errors)
  libtinyxml2-dev          # URDF robot models
  libsleef-dev             # vectorized sin/cos and exp (SLEEF) behind the AVX2 kernel switch
  libre2-dev               # --targets_only name filters: RE2 matches in linear time, no recursion
  liblbfgspp-dev           # the residual layer's hyperparameters: bounded L-BFGS-B (header-only LBFGSpp, docs/residual_layer.md)
  liburdfdom-dev           # urdf_overlay_test: reads the written URDF independently of our reader
  liburdfdom-tools         # urdf_overlay_test: check_urdf validates the written URDF
  nlohmann-json3-dev       # the JSON calibration report (header-only)
  libgtest-dev libbenchmark-dev
  libpng-dev               # plot_test reads the written PNG images back
  libplplot-dev plplot-driver-cairo pkg-config  # report plots (tools/report/plot.cc): PLplot, PNG via cairo
  chromium                 # report_html_test renders the HTML report headless
  pybind11-dev python3-pybind11 python3-dev python3-numpy python3-pytest  # the Python module lpoe (python/)
  clang libclang-rt-14-dev # scripts/fuzz.sh (libFuzzer) and scripts/ci_sanitize.sh (ASan + UBSan)
  lld                      # the test builds link with lld: the tools, benchmarks and test program each link static Ceres
  ninja-build              # the test builds: keeps both cores busy across targets (make waits per target)
)

missing=()
for p in "${PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
[ ${#missing[@]} -eq 0 ] && exit 0

SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
echo "setup: installing ${missing[*]}" >&2
$SUDO apt-get update -qq
DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
