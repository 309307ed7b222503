#!/usr/bin/env bash
# Installs the built project into a temporary prefix and runs a Python script with the module FROM
# THAT PREFIX (PYTHONPATH=<prefix>/lib/python3/dist-packages, not the build tree), from an unrelated
# folder: it calibrates the shipped default data set (under <prefix>/share/lpoe_calib/data) and
# writes a model that must be byte-identical to the installed lpoe_calibrate's on the same data.
# Usage: python_from_prefix.sh <build dir> <python interpreter>
set -euo pipefail
build=$1
python=$2
here=$(cd "$(dirname "$0")" && pwd)
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
cmake --install "$build" --prefix "$tmp/prefix" >/dev/null
prefix=$tmp/prefix
unset LPOE_DATA_DIR PYTHONHOME
mkdir "$tmp/work"
cd "$tmp/work"
fail() { echo "FAIL: $*" >&2; exit 1; }

[ -f "$prefix/lib/python3/dist-packages/lpoe/__init__.py" ] || fail "module not installed"
"$prefix/bin/lpoe_calibrate" --plots_dir= --output=cli.yaml >/dev/null ||
  fail "lpoe_calibrate exited $?"
PYTHONPATH="$prefix/lib/python3/dist-packages" "$python" -s "$here/calibrate_default.py" \
  "$prefix" py.yaml || fail "the Python script failed"
# The tool appends the estimate's covariance block (docs/file_formats.md): the model is what precedes.
sed '/^# covariance of the estimate/,$d' cli.yaml > cli_model.yaml
[ -s cli_model.yaml ] && ! cmp -s cli.yaml cli_model.yaml || fail "lpoe_calibrate wrote no covariance block"
cmp cli_model.yaml py.yaml || fail "the Python model differs from lpoe_calibrate's"
echo "installed module OK: $(wc -c <py.yaml) bytes of YAML identical to lpoe_calibrate's"
