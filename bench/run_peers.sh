#!/usr/bin/env bash
# ivol against what users would pick instead, in one run (issue 9):
#   storage   ivol (octree, regular) vs OpenVDB, HDF5, a TIFF stack and raw
#             (build-bench/bench/peers_bench storage)
#   recon     ivol's dense and octree FDK vs RTK's CPU FDK on the same noisy
#             scan, with the error against the analytic phantom
#   convert   `ivol convert` TIFF stack -> .ivol -> TIFF vs the zstd CLI on
#             the same raw bytes
# and writes bench/results/peers.md with PNG plots.
#
#   bash bench/run_peers.sh [--quick] [--out DIR] [--build DIR] [--work DIR]
#
# --quick: 256^3 for two phantoms, the RTK comparison at 128^3, conversion at
# 256^3 (a few minutes). Full: 256^3 for the five industrial phantoms, 512^3
# for the pencil holder and the connector board, RTK at 256^3, conversion at
# 512^3 (about 25 minutes on the 2-core machine). Reconstructed volumes are
# cached under the work folder (default /tmp/ivol-peers), so a rerun skips
# the scans. Needs RTK for python3 (bench/rtk/README.md) and Debian's
# python3-matplotlib for /usr/bin/python3 (scripts/install-deps.sh).
set -euo pipefail
cd "$(dirname "$0")/.."
command_line="bash bench/run_peers.sh $*"
quick=0
out=bench/results
build=build-bench
work=/tmp/ivol-peers
while [ $# -gt 0 ]; do
  case "$1" in
    --quick) quick=1 ;;
    --out) out=$2; shift ;;
    --build) build=$2; shift ;;
    --work) work=$2; shift ;;
    *) echo "usage: bash bench/run_peers.sh [--quick] [--out DIR] [--build DIR] [--work DIR]" >&2; exit 1 ;;
  esac
  shift
done
threads=$(nproc)
if [ $quick -eq 1 ]; then
  storage_runs=("256:pencil-holder connector-board")
  recon_size=128
  convert_size=256
else
  storage_runs=("256:pencil-holder connector-board computer-board thin-pipe lattice-part"
                "512:pencil-holder connector-board")
  recon_size=256
  convert_size=512
fi

# Configured once; rebuilt incrementally so that the figures are of the sources.
[ -f "$build/build.ninja" ] || cmake -S . -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=Release -DIVOL_BUILD_TESTS=OFF >/dev/null
cmake --build "$build" -j"$threads" --target peers_bench ivol >&2
raw="$out/raw"
rm -rf "$raw"
mkdir -p "$raw" "$work"
# blosc (OpenVDB's and HDF5's filter) compresses on as many threads as ivol.
export BLOSC_NTHREADS=$threads
started=$(date +%s)
log() { echo "run_peers: $* ($(( $(date +%s) - started )) s)" >&2; }
now() { date +%s.%N; }

# ---- storage -----------------------------------------------------------------
for run in "${storage_runs[@]}"; do
  size=${run%%:*}
  for phantom in ${run#*:}; do
    log "storage $size^3 $phantom"
    "$build/bench/peers_bench" storage --size "$size" --phantom "$phantom" --work "$work/storage" \
      >>"$raw/storage.jsonl"
  done
done

# ---- reconstruction against RTK --------------------------------------------------
log "reconstruction $recon_size^3 (ivol dense, ivol octree)"
recon_dir="$work/recon"
rm -rf "$recon_dir"
"$build/bench/peers_bench" recon --size "$recon_size" --phantom pencil-holder --export "$recon_dir" >"$raw/recon.json"
detector=$(( recon_size * 3 / 2 ))
pitch=$(/usr/bin/python3 -c "import json; print(json.load(open('$raw/recon.json'))['pitch'])")
log "reconstruction $recon_size^3 (RTK)"
python3 bench/rtk/rtk_fdk.py --geometry "$recon_dir/geometry.xml" --columns "$detector" --rows "$detector" \
  --pitch "$pitch" --size "$recon_size" --spacing 1 --projections "$recon_dir/projections.raw" \
  --threads "$threads" --output "$recon_dir/rtk_volume.raw" >"$raw/rtk.json"
/usr/bin/python3 - "$recon_dir" "$recon_size" >"$raw/accuracy.json" <<'PY'
# Mean absolute error against the voxelised analytic phantom, in the central
# cylinder (radius 0.45 n, |z| < 0.3 n, away from the cone's truncated ends),
# over all its voxels and over the object's (phantom density > 0).
import json, sys
import numpy as np
work, n = sys.argv[1], int(sys.argv[2])
load = lambda name: np.fromfile(f"{work}/{name}", np.float32).reshape(n, n, n)
truth = load("phantom.raw")
c = np.arange(n) - (n - 1) / 2
z, y, x = np.meshgrid(c, c, c, indexing="ij")
cylinder = (x**2 + y**2 < (0.45 * n) ** 2) & (abs(z) < 0.3 * n)
obj = cylinder & (truth > 0)
result = {}
for label, name in (("ivol dense", "ivol_dense.raw"), ("ivol octree", "ivol_octree.raw"), ("RTK", "rtk_volume.raw")):
    v = load(name)
    result[label] = {"mae_cylinder": float(np.abs(v - truth)[cylinder].mean()),
                     "mae_object": float(np.abs(v - truth)[obj].mean())}
d = load("ivol_dense.raw")[cylinder] - load("rtk_volume.raw")[cylinder]
result["dense_vs_rtk"] = {"rms_difference": float(np.sqrt(np.mean(d**2))), "max_abs_difference": float(np.abs(d).max())}
print(json.dumps(result))
PY
rm -rf "$recon_dir"

# ---- conversion throughput --------------------------------------------------------
log "conversion $convert_size^3"
conv="$work/convert"
"$build/bench/peers_bench" stack --size "$convert_size" --phantom pencil-holder --work "$work/storage" --out "$conv" \
  >"$raw/stack.json"
timed() {  # label, command...: one JSON line with the wall-clock seconds
  local label=$1; shift
  local t0; t0=$(now)
  "$@" >/dev/null 2>&1
  local t1; t1=$(now)
  echo "{\"step\": \"$label\", \"seconds\": $(awk -v a="$t0" -v b="$t1" 'BEGIN { printf "%.3f", b - a }'), \"command\": \"$*\"}" >>"$raw/convert.jsonl"
}
ivol="$build/tools/ivol"
sync
timed "TIFF stack -> .ivol (lossless uint16)" "$ivol" convert "$conv/stack" "$conv/volume.ivol" -f -q
timed "TIFF stack -> .ivol (--keep threshold=otsu,margin=3)" "$ivol" convert "$conv/stack" "$conv/keep.ivol" \
  --keep threshold=otsu,margin=3 -f -q
timed ".ivol -> TIFF (deflate multi-page)" "$ivol" convert "$conv/volume.ivol" "$conv/back.tif" -f -q
timed "zstd -3 -T$threads (raw uint16)" zstd -3 -T"$threads" -q -f "$conv/volume.u16" -o "$conv/volume.u16.zst"
timed "zstd -d (raw uint16)" zstd -d -q -f "$conv/volume.u16.zst" -o "$conv/volume.back.u16"
for f in volume.ivol keep.ivol back.tif volume.u16.zst; do
  echo "{\"file\": \"$f\", \"bytes\": $(stat -c %s "$conv/$f")}" >>"$raw/convert_sizes.jsonl"
done
rm -rf "$conv"

# ---- the report ---------------------------------------------------------------
log "report"
{
  echo "{\"command\": \"$command_line\","
  echo " \"commit\": \"$(git rev-parse --short HEAD)$(git diff --quiet HEAD -- . 2>/dev/null || echo ' (with uncommitted changes)')\","
  echo " \"date\": \"$(date -u +%Y-%m-%d)\","
  echo " \"cpu\": \"$(lscpu | sed -n 's/^Model name: *//p' | head -1)\","
  echo " \"cores\": $threads,"
  echo " \"memory\": \"$(free -g | awk '/Mem:/ {print $2}') GiB\","
  echo " \"debian\": \"$(cat /etc/debian_version)\","
  echo " \"compiler\": \"$(c++ --version | head -1)\","
  echo " \"packages\": \"$(dpkg-query -W -f='${Package} ${Version}, ' libopenvdb10.0 libhdf5-103-1 libtiff6 libzstd1 zstd \
       libblosc1 hdf5-filter-plugin-blosc-serial pocl-opencl-icd python3-matplotlib 2>/dev/null | sed 's/, $//')\","
  echo " \"rtk\": \"itk-rtk $(python3 -c 'import importlib.metadata as m; print(m.version("itk-rtk"))'), itk $(python3 -c 'import importlib.metadata as m; print(m.version("itk"))')\","
  echo " \"blosc_threads\": $threads, \"seconds\": $(( $(date +%s) - started ))}"
} >"$raw/machine.json"
/usr/bin/python3 bench/peers_report.py "$raw" "$out"
log "wrote $out/peers.md"
