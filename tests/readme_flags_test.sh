#!/usr/bin/env bash
# Every flag every tool lists in --help is documented in the README (as `--name`), and every tool
# answers --version with the project version.
# Usage: readme_flags_test.sh <README.md> <version> <tool>...
set -euo pipefail
readme=$1
version=$2
shift 2
status=0
for flag in flagfile version help; do
  grep -q -- "\`--$flag" "$readme" || { echo "README: --$flag is not documented"; status=1; }
done
for tool in "$@"; do
  name=$(basename "$tool")
  out=$("$tool" --version)
  [[ "$out" == *"version $version"* ]] || { echo "$name --version printed '$out'"; status=1; }
  flags=$("$tool" --help | sed -n 's/^  --\([a-z0-9_]*\) (.*/\1/p')
  [ -n "$flags" ] || { echo "$name --help lists no flags"; status=1; }
  for f in $flags; do
    grep -q -- "\`--$f\`" "$readme" || { echo "README: $name --$f is not documented"; status=1; }
  done
done
exit $status
