#!/usr/bin/env bash
# Installs the built project into a temporary prefix, moves the prefix elsewhere (so that nothing may
# depend on the install path), and runs the installed tools from an unrelated directory with no
# LPOE_DATA_DIR: they must find their data under <prefix>/share/lpoe_calib, not in the source tree.
# Usage: run_tools.sh <build dir> <expected version>
set -euo pipefail
build=$1
version=$2
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
cmake --install "$build" --prefix "$tmp/stage" >/dev/null
mv "$tmp/stage" "$tmp/moved"
prefix=$tmp/moved
share=$prefix/share/lpoe_calib
unset LPOE_DATA_DIR
mkdir "$tmp/work"
cd "$tmp/work"

fail() { echo "FAIL: $*" >&2; exit 1; }

for f in data/cobot6.yaml data/section4/identification.csv docs/urdf.md README.md LICENSE \
         CHANGELOG.md; do
  [ -f "$share/$f" ] || fail "$share/$f is not installed"
done
for tool in "$prefix"/bin/lpoe_*; do
  out=$("$tool" --version) || fail "$tool --version exited $?"
  [[ "$out" == *"version $version"* ]] || fail "$tool --version printed '$out'"
done

# The default run: the shipped section-4 data, found under the moved prefix.
out=$("$prefix/bin/lpoe_calibrate" --plots_dir= --output=cal.yaml) || fail "lpoe_calibrate exited $?"
grep -q "model: *$share/data/cobot6.yaml" <<<"$out" || fail "model not from the prefix: $out"
grep -q "identification: *$share/data/section4/identification.csv" <<<"$out" ||
  fail "measurements not from the prefix: $out"
[ -s cal.yaml ] || fail "no calibrated model written"

# LPOE_DATA_DIR still overrides (documented): an empty directory makes the default run fail.
mkdir empty
if LPOE_DATA_DIR=$tmp/work/empty "$prefix/bin/lpoe_calibrate" --plots_dir= >/dev/null 2>&1; then
  fail "LPOE_DATA_DIR was not used"
fi

# Simulation and comparison from the installed data.
"$prefix/bin/lpoe_simulate" --model="$share/data/cobot6.yaml" --count=40 --output=sim.csv >/dev/null ||
  fail "lpoe_simulate exited $?"
"$prefix/bin/lpoe_compare" --model="$share/data/cobot6.yaml" --measurements=sim.csv \
  >/dev/null || fail "lpoe_compare exited $?"
echo "installed tools OK from $prefix"
