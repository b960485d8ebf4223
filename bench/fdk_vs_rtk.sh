#!/usr/bin/env bash
# ivol's OpenCL FDK and RTK's CPU FDK on the same projections and geometry,
# one after the other in one run, and how far apart their volumes are.
#
#   bash bench/fdk_vs_rtk.sh [SIZE] [VIEWS] [DETECTOR] [PHANTOM]
#
# Default: 256³ voxels of 1 mm from 360 views of 384² pixels (the issue's
# case), Shepp-Logan. Needs build/bench/fdk_bench and RTK (bench/rtk/README.md:
# python3 -m pip install itk-rtk==2.7.0.post1).
set -euo pipefail
cd "$(dirname "$0")/.."
size=${1:-256}
views=${2:-360}
detector=${3:-384}
phantom=${4:-shepp-logan}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

echo "# ivol (fdk_bench), $(nproc) cores"
ours=$(build/bench/fdk_bench --size "$size" --views "$views" --detector "$detector" --phantom "$phantom" --export "$work")
echo "$ours"
pitch=$(echo "$ours" | sed -n 's/.*pitch \([0-9.]*\) mm.*/\1/p')
echo "# RTK (rtk_fdk.py), same projections and geometry XML"
python3 bench/rtk/rtk_fdk.py --geometry "$work/geometry.xml" --columns "$detector" --rows "$detector" \
  --pitch "$pitch" --size "$size" --spacing 1 --projections "$work/projections.raw" --threads "$(nproc)" \
  --output "$work/rtk_volume.raw"
echo "# difference between the two volumes (central cylinder, radius 0.45·size, |z| < 0.3·size)"
/usr/bin/python3 - "$work" "$size" <<'PY'
import sys, numpy as np
work, n = sys.argv[1], int(sys.argv[2])
a = np.fromfile(f"{work}/ivol_volume.raw", np.float32).reshape(n, n, n)
b = np.fromfile(f"{work}/rtk_volume.raw", np.float32).reshape(n, n, n)
c = (np.arange(n) - (n - 1) / 2)
z, y, x = np.meshgrid(c, c, c, indexing="ij")
m = (x**2 + y**2 < (0.45 * n) ** 2) & (abs(z) < 0.3 * n)
d = a[m] - b[m]
print(f'{{"rms_difference": {np.sqrt(np.mean(d**2)):.4g}, "max_abs_difference": {np.abs(d).max():.4g}, '
      f'"rms_value": {np.sqrt(np.mean(b[m]**2)):.4g}}}')
PY
