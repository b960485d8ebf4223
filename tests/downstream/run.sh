#!/usr/bin/env bash
# Installs ivol from the build tree into a temporary prefix, then configures,
# builds and runs tests/downstream against it with find_package(ivol).
set -euo pipefail
source_dir=$1
build_dir=$2
shift 2
# The remaining arguments: the build type and, for sanitizer builds, its flags.
build_type=Release
extra=()
for arg in "$@"; do
  case "$arg" in
    -DCMAKE_BUILD_TYPE=asan) build_type=asan; ;;
    -DCMAKE_BUILD_TYPE=*) ;;
    *) extra+=("$arg") ;;
  esac
done
[ "$build_type" = asan ] || extra=()
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cmake --install "$build_dir" --prefix "$work/prefix" >/dev/null
cmake -S "$source_dir/tests/downstream" -B "$work/build" -G Ninja -DCMAKE_BUILD_TYPE=Release \
  -DCMAKE_PREFIX_PATH="$work/prefix" "${extra[@]}" >/dev/null
cmake --build "$work/build" >/dev/null
"$work/build/downstream" "$work/out.ivol"
