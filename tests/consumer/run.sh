#!/usr/bin/env bash
# Installs the built project into a temporary prefix and builds and runs tests/consumer against it,
# linked once with the static and once with the shared libraries, with the C++ compiler the project
# was built with (a sanitizer build's libraries need that compiler's sanitizer runtime).
# Usage: run.sh <build dir> <source dir of the consumer> [<C++ compiler>]
set -euo pipefail
build=$1
src=$2
compiler=(); [ -n "${3:-}" ] && compiler=(-DCMAKE_CXX_COMPILER="$3")
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
cmake --install "$build" --prefix "$tmp/prefix" >/dev/null
cmake -S "$src" -B "$tmp/build" "${compiler[@]}" -DCMAKE_PREFIX_PATH="$tmp/prefix" -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build "$tmp/build" -j2 >/dev/null
"$tmp/build/consumer"
# The shared build really loads the installed shared libraries, and the static one does not.
# ldd's output is captured first: `ldd | grep -q` under pipefail fails when grep stops reading
# before ldd has written everything (SIGPIPE), which happened under a loaded parallel ctest.
shared_deps=$(ldd "$tmp/build/consumer_shared")
static_deps=$(ldd "$tmp/build/consumer")
grep -q "liblpoe_solvers.so.* => $tmp/prefix/" <<<"$shared_deps" ||
  { echo "FAIL: consumer_shared does not load the installed liblpoe_solvers.so" >&2; exit 1; }
if grep -q liblpoe_ <<<"$static_deps"; then
  echo "FAIL: the static consumer loads a shared lpoe library" >&2; exit 1
fi
"$tmp/build/consumer_shared"
