#!/usr/bin/env bash
# The main job on its built-in default: set up, build, and run `ivol demo`
# (a simulated CT scan reconstructed dense and as an octree, both written as .ivol). Arguments go to
# `ivol demo` (see `build/tools/ivol demo --help`).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/build.sh
build/tools/ivol demo "$@"
build/tools/ivol verify ivol-demo/demo-dense.ivol ivol-demo/demo-octree.ivol
