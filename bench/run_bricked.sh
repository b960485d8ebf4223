#!/usr/bin/env bash
# Issue 22: codec 3 and the bricked regular grid against the octree and the
# usual peers, on one reconstruction, side by side in one run:
#   1. a noise-free scan of the pencil holder, reconstructed by ivol (dense
#      FDK, float32);
#   2. every voxel as binary16 and as uint16 (the volume's range on 0..65535),
#      each written by `ivol convert` as an octree (--structure octree, as
#      before issue 22) and as a bricked grid (the new default), by HDF5
#      (64^3 chunks, shuffle + deflate 9, h5py) and by the zstd CLI (-3, -19);
#   3. codec 3 against codec 2 brick by brick (build/bench/codec_bench),
#      encode and decode MB/s on one core.
#
#   bash bench/run_bricked.sh [--size N] [--build DIR] [--work DIR]
set -euo pipefail
cd "$(dirname "$0")/.."
size=256
build=build
work=$(mktemp -d /tmp/ivol-bricked.XXXXXX)
while [ $# -gt 0 ]; do
  case "$1" in
    --size) size=$2; shift ;;
    --build) build=$2; shift ;;
    --work) work=$2; shift ;;
    *) echo "usage: bash bench/run_bricked.sh [--size N] [--build DIR] [--work DIR]" >&2; exit 1 ;;
  esac
  shift
done
ivol=$build/tools/ivol
[ -x "$ivol" ] || ivol=$build/ivol
mkdir -p "$work"
views=$((size * 3 / 2))
echo "# bench/run_bricked.sh --size $size ($(date -u +%FT%TZ), $(nproc) cores, $(uname -m))"
if [ ! -f "$work/r.raw" ]; then
  pitch=$(/usr/bin/python3 -c "print(round(460.0 / $views, 4))")   # the field of 100 mm radius, magnified 2x, 3 % spare
  "$ivol" -q phantom pencil-holder --views "$views" --detector "$views" --pitch "$pitch" -o "$work/p.h5" -f
  "$ivol" -q recon "$work/p.h5" --geometry "$work/p.xml" --pitch "$pitch" --detector "$views,$views" \
    --views "$views" --size "$size" --voxel $(/usr/bin/python3 -c "print(200.0 / $size)") \
    --encoding float32 -o "$work/r.ivol" -f
  "$ivol" -q convert "$work/r.ivol" "$work/r.raw" --out-type f32
fi
/usr/bin/python3 - "$work" "$size" <<'PY'
import sys, numpy as np
w, n = sys.argv[1], int(sys.argv[2])
f = np.fromfile(w + "/r.raw", dtype="<f4")
f.astype("<f2").tofile(w + "/v-f16.raw")
lo, hi = float(f.min()), float(f.max())
np.round((f - lo) / (hi - lo) * 65535).astype("<u2").tofile(w + "/v-u16.raw")
PY
dims=$size,$size,$size
printf "| values | form | bytes | vs octree | write s |\n|---|---|---:|---:|---:|\n"
for kind in f16 u16; do
  declare -A bytes=()
  for structure in octree bricked; do
    t0=$(date +%s.%N)
    "$ivol" -q convert "$work/v-$kind.raw" "$work/v-$kind-$structure.ivol" --dims "$dims" --type "$kind" \
      --structure "$structure" -f
    t1=$(date +%s.%N)
    bytes[$structure]=$(stat -c %s "$work/v-$kind-$structure.ivol")
    printf "| %s | ivol %s | %d | %s | %.2f |\n" "$kind" "$structure" "${bytes[$structure]}" \
      "$(/usr/bin/python3 -c "print('%+.1f %%' % (100.0 * ${bytes[$structure]} / ${bytes[octree]} - 100))")" \
      "$(echo "$t1 - $t0" | bc)"
  done
  /usr/bin/python3 - "$work" "$size" "$kind" "${bytes[octree]}" <<'PY'
import sys, time, h5py, numpy as np
w, n, kind, octree = sys.argv[1], int(sys.argv[2]), sys.argv[3], int(sys.argv[4])
v = np.fromfile("%s/v-%s.raw" % (w, kind), dtype="<f2" if kind == "f16" else "<u2").reshape(n, n, n)
path = "%s/v-%s.h5" % (w, kind)
t = time.time()
with h5py.File(path, "w") as f:
    f.create_dataset("v", data=v, chunks=(64, 64, 64), shuffle=True, compression="gzip", compression_opts=9)
dt = time.time() - t
import os
b = os.path.getsize(path)
print("| %s | HDF5 64^3 shuffle + deflate 9 | %d | %+.1f %% | %.2f |" % (kind, b, 100.0 * b / octree - 100, dt))
PY
  for level in 3 19; do
    t0=$(date +%s.%N)
    zstd -q -f -"$level" -T2 "$work/v-$kind.raw" -o "$work/v-$kind.raw.zst"
    t1=$(date +%s.%N)
    b=$(stat -c %s "$work/v-$kind.raw.zst")
    printf "| %s | zstd -%s -T2 (whole file) | %d | %s | %.2f |\n" "$kind" "$level" "$b" \
      "$(/usr/bin/python3 -c "print('%+.1f %%' % (100.0 * $b / ${bytes[octree]} - 100))")" "$(echo "$t1 - $t0" | bc)"
  done
done
echo
"$build/bench/codec_bench" "$work/r.raw" "$size" 5
"$build/bench/codec_bench" "$work/r.raw" "$size" 4
