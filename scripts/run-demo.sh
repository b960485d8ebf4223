#!/usr/bin/env bash
# The main job on its built-in default: set up, build, and run `ivol demo`
# (a synthetic CT volume written as .ivol and read back). Arguments go to
# `ivol demo` (see `build/tools/ivol demo --help`).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/build.sh
build/tools/ivol demo "$@"
build/tools/ivol verify ivol-demo/demo-lossless.ivol ivol-demo/demo-octree.ivol
