#!/usr/bin/env bash
# A short fuzz run for CI: builds the .ivol reader's libFuzzer harness (clang,
# ASan, UBSan) and runs it for IVOL_FUZZ_SECONDS (default 30) on the
# conformance vectors. Exits 77 (skipped) where clang's libFuzzer is missing.
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
if ! command -v clang++ >/dev/null || ! echo 'extern "C" int LLVMFuzzerTestOneInput(const char*, unsigned long) { return 0; }' |
     clang++ -x c++ -fsanitize=fuzzer - -o /dev/null 2>/dev/null; then
  echo "skipped: clang++ with libFuzzer (clang, libclang-rt-dev) is not installed"
  exit 77
fi
export IVOL_FUZZ_DIR=${IVOL_FUZZ_DIR:-$(mktemp -d)}
# run.sh sets -rss_limit_mb=2048 -malloc_limit_mb=1024 -timeout=20.
bash "$root/tests/fuzz/run.sh" -max_total_time="${IVOL_FUZZ_SECONDS:-30}" -print_final_stats=1 2>&1 | tail -15
