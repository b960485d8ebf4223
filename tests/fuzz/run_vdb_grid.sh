#!/usr/bin/env bash
# Builds the libFuzzer harness for ivol's side of the OpenVDB reader
# (fuzz_vdb_grid.cpp: grids built in memory from the input, copied densely
# and checked voxel by voxel against OpenVDB's accessor) with clang, ASan and
# UBSan, and runs it with the limits every harness runs under. Arguments go
# to libFuzzer.
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
out=${IVOL_FUZZ_DIR:-$root/build-fuzz}
mkdir -p "$out/corpus-vdb-grid"
flags="-std=c++17 -O1 -g -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=undefined -fsanitize-ignorelist=$root/tests/fuzz/sanitizer-ignorelist.txt -fsanitize-coverage-ignorelist=$root/tests/fuzz/coverage-ignorelist.txt"
# IVOL_FUZZ_LIBFORMAT=path/libivolformat.a links a built libformat instead of
# compiling it here, as run_vdb.sh does.
libformat=("$root"/libformat/src/*.cpp)
[ -n "${IVOL_FUZZ_LIBFORMAT:-}" ] && libformat=("$IVOL_FUZZ_LIBFORMAT")
clang++ $flags -DIVOL_VERSION_STRING='"fuzz"' -I"$root/libformat/include" -I"$root/libformat/src" \
  -I"$root/tools/convert" "$root"/tools/convert/{vdb_io,dense_volume,volume_metadata,staged_file,exactness,raw_io}.cpp \
  "$root/tests/fuzz/fuzz_vdb_grid.cpp" "${libformat[@]}" -lzstd -lopenvdb -ltbb -lImath-3_1 -o "$out/fuzz_vdb_grid"
cp -n "$root"/tests/fuzz/regressions/vdb-grid/* "$out/corpus-vdb-grid/" 2>/dev/null || true
[ -n "${IVOL_FUZZ_BUILD_ONLY:-}" ] && exit 0
LSAN_OPTIONS="suppressions=$root/tests/fuzz/lsan-suppressions.txt${LSAN_OPTIONS:+:$LSAN_OPTIONS}" \
  "$out/fuzz_vdb_grid" "$out/corpus-vdb-grid" -max_len=65536 -rss_limit_mb=2048 -malloc_limit_mb=1024 -timeout=20 "$@"
