# Salvage of a cut file (format 1.3 framed blocks, spec §18): extract
# --salvage writes what survived, fills the rest from coarser levels and
# lists it (exit 3); plain extract refuses the cut file as truncated; info and
# verify say what could be salvaged and still fail; a cut 1.2 file (no
# framing) cannot be salvaged, and extract says why.
# (an octree of small blocks: what is lost is filled from its stored averages)
"$IVOL" -q convert "$work/v.raw" "$work/salvage-whole.ivol" --dims 16,16,16 --block-size 512 --structure octree
whole=$(stat -c %s "$work/salvage-whole.ivol")
head -c $((whole * 2 / 3)) "$work/salvage-whole.ivol" > "$work/salvage-cut.ivol"
"$IVOL" -q convert "$work/v.raw" "$work/salvage-v12.ivol" --dims 16,16,16 --format-version 1.2
head -c 2000 "$work/salvage-v12.ivol" > "$work/salvage-v12-cut.ivol"
bad salvage-extract-cut     3 "were not found"         -- "$IVOL" extract "$work/salvage-cut.ivol" --salvage --box 0,0,0,16,16,16 -o "$work/salvaged.raw"
bad salvage-extract-size    0 ""                       -- test "$(stat -c %s "$work/salvaged.raw")" -eq 16384
bad salvage-extract-plain   2 "truncated"              -- "$IVOL" extract "$work/salvage-cut.ivol" --box 0,0,0,16,16,16 -o "$out/x.raw"
bad salvage-verify-cut      2 "complete down to level of detail" -- "$IVOL" verify "$work/salvage-cut.ivol"
bad salvage-info-cut        2 "salvaged from its blocks" -- "$IVOL" info "$work/salvage-cut.ivol"
bad salvage-unframed        2 "not framed"             -- "$IVOL" extract "$work/salvage-v12-cut.ivol" --salvage --box 0,0,0,16,16,16 -o "$out/x.raw"
bad salvage-format-version  1 "--format-version"       -- "$IVOL" convert "$work/v.raw" "$out/x.ivol" --dims 16,16,16 --format-version 1.1

# A bricked grid cut in half keeps its voxel size: the bricked writer
# writes its metadata block last, and an early metadata block (stream 6)
# first (spec §15). Before, the salvaged TIFF said 1 mm a voxel. With no
# metadata left at all (the early block damaged too), the export states no
# voxel size rather than the defaults' 1.
/usr/bin/python3 -c "
import numpy as np
np.random.default_rng(5).standard_normal(96 * 80 * 70).astype('<f4').tofile('$work/salvage-f32.raw')"
"$IVOL" -q convert "$work/salvage-f32.raw" "$work/salvage-bricked.ivol" --dims 96,80,70 --type f32 --voxel-size 0.05 --unit mm
bricked_size=$(stat -c %s "$work/salvage-bricked.ivol")
head -c $((bricked_size / 2)) "$work/salvage-bricked.ivol" > "$work/salvage-bricked-cut.ivol"
bad salvage-bricked-early   2 "early metadata only" -- "$IVOL" verify "$work/salvage-bricked-cut.ivol"
bad salvage-bricked-extract 3 "were not found" -- "$IVOL" extract "$work/salvage-bricked-cut.ivol" --salvage --box 0,0,0,96,80,70 -o "$work/salvage-bricked.tif"
bands_check salvage-bricked-spacing "
import tifffile
t = tifffile.TiffFile('$work/salvage-bricked.tif')
print('same' if t.imagej_metadata.get('spacing') == 0.05 and t.imagej_metadata.get('unit') == 'mm'
      and t.pages[0].tags['XResolution'].value == (20, 1) else t.imagej_metadata)"
/usr/bin/python3 - "$work/salvage-bricked-cut.ivol" "$work/salvage-bricked-nometa.ivol" <<'PY'
import sys
d = bytearray(open(sys.argv[1], "rb").read())
first = d.find(b"IVBK")  # the first block: the early metadata
d[first + 40] ^= 0xFF
open(sys.argv[2], "wb").write(d)
PY
bad salvage-bricked-nometa 3 "were not found" -- "$IVOL" extract "$work/salvage-bricked-nometa.ivol" --salvage --box 0,0,0,96,80,70 -o "$work/salvage-nometa.tif"
bands_check salvage-bricked-no-spacing "
import tifffile
t = tifffile.TiffFile('$work/salvage-nometa.tif')
m = t.imagej_metadata or {}
print('same' if 'spacing' not in m and 'XResolution' not in t.pages[0].tags else (m, t.pages[0].tags.get('XResolution')))"
