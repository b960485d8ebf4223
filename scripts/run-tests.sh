#!/usr/bin/env bash
# Set up, build, and run the whole test suite through ctest.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/build.sh
ctest --test-dir build --output-on-failure --parallel "$(nproc)" --timeout 900

# The same suite once more under AddressSanitizer and UndefinedBehaviorSanitizer
# (skip with IVOL_SKIP_SANITIZERS=1 for a quick local run).
if [ "${IVOL_SKIP_SANITIZERS:-0}" != 1 ]; then
  cmake -S . -B build-asan -G Ninja -DCMAKE_BUILD_TYPE=asan -DIVOL_BUILD_BENCH=OFF >/dev/null
  cmake --build build-asan --parallel "$(nproc)"
  ctest --test-dir build-asan --output-on-failure --parallel "$(nproc)" --timeout 900
fi
