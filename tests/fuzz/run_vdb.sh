#!/usr/bin/env bash
# Builds the libFuzzer harness for the OpenVDB reader with clang, ASan and
# UBSan, and runs it on the grids of tests/fuzz/regressions/vdb/ with the
# limits every harness runs under. Arguments go to libFuzzer.
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
out=${IVOL_FUZZ_DIR:-$root/build-fuzz}
mkdir -p "$out/corpus-vdb"
flags="-std=c++17 -O1 -g -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=undefined"
# read_vdb and what it uses: the converters' shared pieces and libformat.
# IVOL_FUZZ_LIBFORMAT=path/libivolformat.a links a built libformat instead of
# compiling it here (faster; libformat is then not instrumented, and the
# OpenVDB reader is what this harness is for).
libformat=("$root"/libformat/src/*.cpp)
[ -n "${IVOL_FUZZ_LIBFORMAT:-}" ] && libformat=("$IVOL_FUZZ_LIBFORMAT")
clang++ $flags -DIVOL_VERSION_STRING='"fuzz"' -I"$root/libformat/include" -I"$root/libformat/src" \
  -I"$root/tools/convert" "$root"/tools/convert/{vdb_io,dense_volume,volume_metadata,staged_file,exactness,raw_io}.cpp \
  "$root/tests/fuzz/fuzz_vdb.cpp" "${libformat[@]}" -lzstd -lopenvdb -ltbb -lImath-3_1 -o "$out/fuzz_vdb"
cp -n "$root"/tests/fuzz/regressions/vdb/* "$out/corpus-vdb/"
[ -n "${IVOL_FUZZ_BUILD_ONLY:-}" ] && exit 0
LSAN_OPTIONS="suppressions=$root/tests/fuzz/lsan-suppressions.txt${LSAN_OPTIONS:+:$LSAN_OPTIONS}" \
  "$out/fuzz_vdb" "$out/corpus-vdb" -max_len=65536 -rss_limit_mb=2048 -malloc_limit_mb=1024 -timeout=20 "$@"
