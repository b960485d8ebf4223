#!/usr/bin/env bash
# Issue 22: ivol's lossless files against blosc2, HDF5 (shuffle + deflate,
# blosc zstd), zstd, JPEG-XL / JPEG-LS / JPEG 2000 per slice, pcodec and
# fpzip on the same voxels, side by side in one run (bench/peers_codecs.py).
#
#   bash bench/run_peers_codecs.sh [--size N] [--photons P] [--build DIR] [--work DIR] [--venv DIR]
#
# 1. Scans of the pencil holder, the connector board and the lattice part,
#    noise-free or with Poisson noise of P incident photons a pixel
#    (--photons), reconstructed by ivol (dense FDK, float32) at N^3
#    (default 256), cached in the work folder (default /tmp/ivol-peers-codecs;
#    give another one for each --photons);
# 2. a venv (default /tmp/ivol-peers-venv) with the peers from PyPI:
#    numpy, h5py, hdf5plugin, blosc2, imagecodecs, pcodec, fpzip (the
#    benchmark's own; ivol does not use them);
# 3. the tables, printed (bench/RESULTS.md keeps one run's).
set -euo pipefail
cd "$(dirname "$0")/.."
size=256
photons=
build=build
work=/tmp/ivol-peers-codecs
venv=/tmp/ivol-peers-venv
while [ $# -gt 0 ]; do
  case "$1" in
    --size) size=$2; shift ;;
    --photons) photons=$2; shift ;;
    --build) build=$2; shift ;;
    --work) work=$2; shift ;;
    --venv) venv=$2; shift ;;
    *) echo "usage: bash bench/run_peers_codecs.sh [--size N] [--photons P] [--build DIR] [--work DIR] [--venv DIR]" >&2; exit 1 ;;
  esac
  shift
done
ivol=$build/tools/ivol
mkdir -p "$work"
views=$((size * 3 / 2))
pitch=$(/usr/bin/python3 -c "print(round(460.0 / $views, 4))")   # the field of 100 mm radius, magnified 2x, 3 % spare
for phantom in pencil-holder connector-board lattice-part; do
  [ -f "$work/$phantom.f32" ] && continue
  "$ivol" -q phantom "$phantom" --views "$views" --detector "$views" --pitch "$pitch" \
    ${photons:+--photons "$photons"} -o "$work/$phantom.h5" -f
  "$ivol" -q recon "$work/$phantom.h5" --geometry "$work/$phantom.xml" --pitch "$pitch" --detector "$views,$views" \
    --views "$views" --size "$size" --voxel "$(/usr/bin/python3 -c "print(200.0 / $size)")" \
    --encoding float32 -o "$work/$phantom.ivol" -f
  "$ivol" -q convert "$work/$phantom.ivol" "$work/$phantom.f32.part" --to raw --out-type f32 -f
  mv "$work/$phantom.f32.part" "$work/$phantom.f32"
  rm -f "$work/$phantom.h5" "$work/$phantom.ivol"
done
if [ ! -x "$venv/bin/python" ]; then
  /usr/bin/python3 -m venv "$venv"
  "$venv/bin/pip" install -q numpy h5py hdf5plugin blosc2 imagecodecs pcodec fpzip
fi
"$venv/bin/python" bench/peers_codecs.py --work "$work" --ivol "$ivol"
