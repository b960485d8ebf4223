#!/usr/bin/env bash
# Builds the libFuzzer harness for the .ivol reader with clang, ASan and
# UBSan, and runs it on a corpus seeded with the conformance vectors.
# Arguments go to libFuzzer (e.g. -max_total_time=60 or -runs=10000000).
# The converters' harness: tests/fuzz/run_converters.sh.
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
out=${IVOL_FUZZ_DIR:-$root/build-fuzz}
mkdir -p "$out/corpus"
flags="-std=c++17 -O1 -g -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=undefined -ffp-contract=off"
clang++ $flags -DIVOL_VERSION_STRING='"fuzz"' -I"$root/libformat/include" -I"$root/libformat/src" \
  "$root"/libformat/src/*.cpp "$root/tests/fuzz/fuzz_check_file.cpp" "$root/tests/fuzz/ivol_mutator.cpp" -lzstd -lcurl -o "$out/fuzz_check_file"
cp -n "$root"/format-spec/vectors/valid/*.ivol "$root"/format-spec/vectors/invalid/*.ivol \
  "$root"/tests/fuzz/regressions/ivol/*.ivol "$out/corpus/" 2>/dev/null || true
# Not a seed: 16 MiB of metadata (the spec's limit) takes 10 s of CPU under
# ASan and UBSan, past -timeout on a loaded machine; fuzz_replay_check_file
# reads it in the normal and sanitizer builds.
rm -f "$out/corpus/metadata_16mib.ivol"
# A reader must stay within these whatever the file (spec §13, Resources):
# exceeding one is a finding, as a crash is.
"$out/fuzz_check_file" "$out/corpus" -max_len=65536 -rss_limit_mb=2048 -malloc_limit_mb=1024 -timeout=20 "$@"
