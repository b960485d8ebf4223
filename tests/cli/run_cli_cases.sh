#!/usr/bin/env bash
# The ivol command line, case by case: each case gives the command, the exit
# code it must return, and a text its output must contain (zstd's
# tests/cli-tests style). $IVOL is the binary under test.
set -u
: "${IVOL:?set IVOL to the ivol binary}"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
passed=0
failed=0

# case NAME EXPECTED_EXIT EXPECTED_TEXT -- COMMAND...
case_() {
  local name=$1 want_exit=$2 want_text=$3
  shift 4
  local out
  out=$("$@" 2>&1)
  local got=$?
  if [ "$got" -ne "$want_exit" ]; then
    echo "FAIL $name: exit $got, expected $want_exit"; echo "$out" | sed 's/^/    /' | head -20
    failed=$((failed + 1)); return
  fi
  if [ -n "$want_text" ] && ! grep -qF -- "$want_text" <<<"$out"; then
    echo "FAIL $name: output lacks '$want_text'"; echo "$out" | sed 's/^/    /' | head -20
    failed=$((failed + 1)); return
  fi
  echo "ok   $name"
  passed=$((passed + 1))
}

case_ help               0 "Subcommands:"            -- "$IVOL" --help
case_ version            0 "ivol 0."                 -- "$IVOL" --version
case_ no-subcommand      1 "subcommand"              -- "$IVOL"
case_ unknown-subcommand 1 "bogus"                   -- "$IVOL" bogus
case_ unknown-option     1 "--frobnicate"            -- "$IVOL" info --frobnicate x.ivol
case_ info-help          0 "--json"                  -- "$IVOL" info --help
case_ verify-help        0 "FILE"                    -- "$IVOL" verify --help
case_ demo-help          0 "--size"                  -- "$IVOL" demo --help
case_ demo-size-range    1 "--size"                  -- "$IVOL" demo --size 4
case_ demo-bad-object    1 "teapot"                  -- "$IVOL" demo --object teapot
case_ info-missing       2 "cannot open"             -- "$IVOL" info "$work/missing.ivol"
case_ demo               0 "octree"                  -- "$IVOL" demo --size 32 --views 48 --object connector-board -o "$work/demo"
case_ demo-quiet         0 ""                        -- "$IVOL" -q demo --size 16 --views 24 -o "$work/quiet"
case_ demo-slice         0 "PNG image data, 32 x 32" -- file "$work/demo/demo-octree-slice.png"
case_ verify-ok          0 "OK"                      -- "$IVOL" verify "$work/demo/demo-octree.ivol" "$work/demo/demo-dense.ivol"
case_ info-text          0 "32 x 32 x 32 voxels"     -- "$IVOL" info "$work/demo/demo-octree.ivol"
case_ info-json          0 '"dimensions": ['         -- "$IVOL" info --json "$work/demo/demo-octree.ivol"
"$IVOL" info --json "$work/demo/demo-octree.ivol" > "$work/info.json"
case_ info-json-parses   0 "32"                      -- /usr/bin/python3 -c "import json,sys; d=json.load(open('$work/info.json')); print(d['dimensions'][0]); sys.exit(0 if d['value_encoding']=='binary16' else 1)"

cp "$work/demo/demo-octree.ivol" "$work/damaged.ivol"
size=$(stat -c %s "$work/damaged.ivol")
printf '\x5a' | dd of="$work/damaged.ivol" bs=1 seek=$((size / 2)) conv=notrunc status=none
case_ verify-damaged     2 "DAMAGED"                 -- "$IVOL" verify "$work/damaged.ivol"
case_ verify-names-block 2 "checksum: "              -- "$IVOL" verify "$work/damaged.ivol"
case_ extract-damaged    2 "checksum"                -- "$IVOL" extract "$work/damaged.ivol" --box 0,0,0,32,32,32 -o "$work/d1.raw"
test ! -e "$work/d1.raw" && case_ damaged-no-output 0 "" -- true
case_ extract-salvage    3 "salvaged"                -- "$IVOL" extract "$work/damaged.ivol" --box 0,0,0,32,32,32 --salvage -o "$work/d2.raw"
case_ salvage-output     0 "131072"                  -- stat -c %s "$work/d2.raw"
head -c $((size - 7)) "$work/demo/demo-octree.ivol" > "$work/truncated.ivol"
case_ verify-truncated   2 "truncated"               -- "$IVOL" verify "$work/truncated.ivol"
# A damaged or cut archive into a sound one: refused without --salvage
# (nothing written), with it exit 3, the regions listed and recorded, the
# file marked not lossless, the same voxels as extract --salvage gives.
case_ reencode-damaged   2 "checksum"                -- "$IVOL" convert "$work/damaged.ivol" "$work/d3.ivol"
test ! -e "$work/d3.ivol" && case_ reencode-damaged-nothing 0 "" -- true
case_ reencode-salvage   3 "salvaged"                -- "$IVOL" convert "$work/damaged.ivol" "$work/d3.ivol" --salvage
case_ reencode-salvage-says 3 "salvaged: see provenance.salvage" -- "$IVOL" convert "$work/damaged.ivol" "$work/d3.ivol" --salvage -f
case_ reencode-salvage-sound 0 "OK"                  -- "$IVOL" verify "$work/d3.ivol"
case_ reencode-salvage-recorded 0 '"regions_filled"' -- "$IVOL" info --json "$work/d3.ivol"
case_ reencode-salvage-info 0 "salvaged       from a damaged input" -- "$IVOL" info "$work/d3.ivol"
case_ reencode-salvage-not-lossless 0 '"lossless": false' -- "$IVOL" info --json "$work/d3.ivol"
"$IVOL" -q convert "$work/d3.ivol" "$work/d3.raw" --out-type f32 -f
case_ reencode-salvage-same 0 ""                     -- cmp "$work/d2.raw" "$work/d3.raw"
# Only the footer cut: every block is found, the copy is whole (exit 0);
# cut in half, the rest comes from coarser levels (exit 3).
case_ reencode-cut-footer 0 "every stored value as it was" -- "$IVOL" convert "$work/truncated.ivol" "$work/t3.ivol" --salvage
head -c $((size / 2)) "$work/demo/demo-octree.ivol" > "$work/half.ivol"
case_ reencode-cut-half  3 "were not found"          -- "$IVOL" convert "$work/half.ivol" "$work/t4.ivol" --salvage
case_ salvage-ivol-only  1 "--salvage"               -- "$IVOL" convert "$work/d2.raw" "$work/t5.ivol" --dims 32,32,32 --salvage
echo "hello" > "$work/text.ivol"
case_ verify-not-ivol    2 "not-ivol"                -- "$IVOL" verify "$work/text.ivol"
case_ info-not-ivol      2 "signature"               -- "$IVOL" info "$work/text.ivol"
case_ verify-mixed       2 "OK"                      -- "$IVOL" verify "$work/demo/demo-octree.ivol" "$work/text.ivol"

# Converters and views.
case_ convert-to-raw     0 "raw f32 32x32x32"        -- "$IVOL" convert "$work/demo/demo-octree.ivol" "$work/v.raw"
case_ convert-no-clobber 1 "exists"                  -- "$IVOL" convert "$work/demo/demo-octree.ivol" "$work/v.raw"
case_ convert-raw-dims   1 "--dims"                  -- "$IVOL" convert "$work/v.raw" "$work/x.ivol"
case_ convert-raw-size   2 "need 126976"             -- "$IVOL" convert "$work/v.raw" "$work/x.ivol" --dims 32,32,31 --type f32
test ! -e "$work/x.ivol" && case_ no-partial-output 0 "" -- true
case_ convert-raw-ivol   0 "lossless"                -- "$IVOL" convert "$work/v.raw" "$work/v.ivol" --dims 32,32,32 --type f32 --voxel-size 0.5
# float32 samples become a bricked grid of float32 (codec 2 bricks, spec
# §8A.4), every bit back; --structure octree still gives the octree.
case_ convert-f32-bricked 0 "bricked, bricks of 32^3" -- "$IVOL" info "$work/v.ivol"
case_ convert-f32-why    0 "as float32 values: bricks of their byte planes" -- "$IVOL" info "$work/v.ivol"
"$IVOL" -q convert "$work/v.ivol" "$work/v-back.raw" -f
case_ convert-f32-exact  0 ""                        -- cmp "$work/v.raw" "$work/v-back.raw"
case_ convert-f32-octree 0 "octree"                  -- "$IVOL" convert "$work/v.raw" "$work/v-octree.ivol" --dims 32,32,32 --type f32 --structure octree
# --brick sets the brick's side both ways from the default 32 (a
# 64 and 128 once came out as 32).
head -c $((128 * 128 * 8 * 2)) /dev/urandom >"$work/b16.raw"
for side in 8 64 128; do
  "$IVOL" -q convert "$work/b16.raw" "$work/b$side.ivol" --dims 128,128,8 --type u16 --structure bricked --brick "$side" -f
  case_ "convert-brick-$side" 0 "\"brick\": $side" -- "$IVOL" info --json "$work/b$side.ivol"
done
# Codec 3's entropy coders (spec §7.2.1, §7.2.2): auto stored tables with
# 32 states at the default level (smaller than byte planes on a smooth
# noisy volume), smaller adaptive contexts in 32³ bricks, zstd only byte
# planes, lanes stored tables and no codec 6; all exact.
/usr/bin/python3 -c "
import random, struct
random.seed(3)
v = [int(20000 + 40 * x + 25 * y + 9 * z + random.gauss(0, 30)) for z in range(16) for y in range(64) for x in range(64)]
open('$work/smooth.raw', 'wb').write(struct.pack('<%dH' % len(v), *v))"
for coder in auto smaller zstd lanes; do
  case_ "convert-entropy-$coder" 0 "lossless" -- "$IVOL" convert "$work/smooth.raw" "$work/e-$coder.ivol" --dims 64,64,16 --type u16 --entropy-coder "$coder"
  "$IVOL" -q convert "$work/e-$coder.ivol" "$work/e-$coder.raw" -f
  case_ "entropy-$coder-exact" 0 "" -- cmp "$work/smooth.raw" "$work/e-$coder.raw"
done
case_ entropy-auto-smaller 0 "" -- test "$(stat -c %s "$work/e-auto.ivol")" -lt "$(stat -c %s "$work/e-zstd.ivol")"
case_ entropy-smaller-smaller 0 "" -- test "$(stat -c %s "$work/e-smaller.ivol")" -lt "$(stat -c %s "$work/e-auto.ivol")"
case_ entropy-bad-coder  1 "--entropy-coder"         -- "$IVOL" convert "$work/smooth.raw" "$work/e-x.ivol" --dims 64,64,16 --type u16 --entropy-coder rans
# A bricked grid's info speaks of bricks and stored levels, not of the
# octree's inner nodes (it once said "2 B (0 inner nodes, 1 values)").
case_ info-bricked       0 "16 x 16 x 1 bricks at full resolution" -- "$IVOL" info "$work/b8.ivol"
case_ info-bricked-no-nodes 1 "" -- bash -c "'$IVOL' info '$work/b8.ivol' | grep -q 'inner nodes'"
/usr/bin/python3 -c "import struct; open('$work/f.raw','wb').write(struct.pack('<4096f', *[i * 0.001 for i in range(4096)]))"
case_ convert-lossy      0 "lossy: f32 rounded to binary16" -- "$IVOL" convert "$work/f.raw" "$work/h.ivol" --dims 16,16,16 --encoding binary16 --allow-lossy
case_ convert-keep       0 "coarsened"               -- "$IVOL" convert "$work/v.raw" "$work/k.ivol" --dims 32,32,32 --keep threshold=otsu,margin=1
# ivol -> ivol re-encodes (a migration): an object-fidelity octree stays an
# octree with the same leaves, a lossless octree becomes a bricked grid;
# every stored value as it was, checked against the input by verify
# --against; a level or an export type is refused before anything is written.
case_ reencode-object    0 "every stored value as it was" -- "$IVOL" convert "$work/k.ivol" "$work/k-again.ivol"
case_ reencode-object-why 0 "may hold coarse leaves" -- "$IVOL" info "$work/k-again.ivol"
case_ reencode-same-leaves 0 "" -- bash -c "diff <('$IVOL' info '$work/k.ivol' | sed -n '/levels/,/metadata/p' | head -n -1) <('$IVOL' info '$work/k-again.ivol' | sed -n '/levels/,/metadata/p' | head -n -1)"
case_ reencode-verify    0 "voxels equal, source digests match" -- "$IVOL" verify "$work/k-again.ivol" --against "$work/k.ivol"
case_ reencode-keeps-keep 0 '"threshold_method": "otsu"' -- "$IVOL" info --json "$work/k-again.ivol"
case_ reencode-to-grid   0 "ivol bricked float32"    -- "$IVOL" convert "$work/v-octree.ivol" "$work/v-again.ivol"
"$IVOL" -q convert "$work/v-again.ivol" "$work/v-again.raw" -f
case_ reencode-grid-exact 0 ""                       -- cmp "$work/v.raw" "$work/v-again.raw"
case_ reencode-no-level  1 "--level"                 -- "$IVOL" convert "$work/v.ivol" "$work/v-l1.ivol" --level 1
case_ reencode-no-out-type 1 "--out-type"            -- "$IVOL" convert "$work/v.ivol" "$work/v-l1.ivol" --out-type f16
/usr/bin/python3 -c "import struct; open('$work/thirds.raw','wb').write(struct.pack('<512f', *[i / 3 for i in range(512)]))"
"$IVOL" -q convert "$work/thirds.raw" "$work/thirds.ivol" --dims 8,8,8
case_ reencode-lossy-refused 2 "--allow-lossy"       -- "$IVOL" convert "$work/thirds.ivol" "$work/v-l1.ivol" --encoding binary16
test ! -e "$work/v-l1.ivol" && case_ reencode-no-partial 0 "" -- true
case_ convert-bad-keep   1 "--keep"                  -- "$IVOL" convert "$work/v.raw" "$work/k2.ivol" --dims 32,32,32 --keep margin=1
case_ convert-to-tiff    0 "tiff f32"                -- "$IVOL" convert "$work/v.ivol" "$work/v.tif"
case_ convert-tiff-ivol  0 "lossless"                -- "$IVOL" convert "$work/v.tif" "$work/t.ivol"
case_ verify-converted   0 "OK"                      -- "$IVOL" verify "$work/v.ivol" "$work/t.ivol" "$work/k.ivol"
case_ info-voxel-size    0 "0.5 x 0.5 x 0.5 mm"      -- "$IVOL" info "$work/v.ivol"
case_ unknown-format     1 "cannot tell the format"  -- "$IVOL" convert "$work/v.ivol" "$work/v.xyz"
case_ extract-tiff       0 "f32 8x4x2"               -- "$IVOL" extract "$work/v.ivol" --box 0,0,0,8,4,2 -o "$work/e.tif"
case_ extract-level      0 "f32 16x16x16"            -- "$IVOL" extract "$work/v.ivol" --box 0,0,0,16,16,16 --level 1 -o "$work/l.raw"
case_ extract-outside    1 "outside the volume"      -- "$IVOL" extract "$work/v.ivol" --box 0,0,0,40,4,2 -o "$work/o.raw"
case_ slice-png          0 "32x32 slice z=5"         -- "$IVOL" slice "$work/k.ivol" --axis z --index 5 --borders -o "$work/s.png"
case_ slice-is-png       0 "PNG 32 x 32"             -- /usr/bin/python3 -c "import struct; b=open('$work/s.png','rb').read(24); assert b[:8]==bytes([137,80,78,71,13,10,26,10]); print('PNG %d x %d' % struct.unpack('>II', b[16:24]))"
case_ slice-bad-index    1 "--index"                 -- "$IVOL" slice "$work/k.ivol" --axis y --index 99 -o "$work/s2.png"
# A slice with no finite value has no range of its own: the summary says so
# (it once said "window inf .. inf"), +inf shows white, -inf and NaN black.
/usr/bin/python3 -c "import struct; inf=float('inf'); open('$work/inf.raw','wb').write(struct.pack('<32f', *([inf] * 16 + [-inf, float('nan')] * 8)))"
case_ convert-infinities 0 "lossless"                -- "$IVOL" convert "$work/inf.raw" "$work/inf.ivol" --dims 4,4,2 --type f32
case_ slice-all-inf      0 "no finite value"         -- "$IVOL" slice "$work/inf.ivol" --index 0 -o "$work/inf0.png"
grey_levels="/usr/bin/python3 $(cd "$(dirname "$0")" && pwd)/png_grey_levels.py"
case_ slice-all-inf-white 0 "levels: 255."           -- bash -c "echo levels: \$($grey_levels '$work/inf0.png')."
case_ slice-nan-minus-inf 0 "window 0 .. 1 (no finite" -- "$IVOL" slice "$work/inf.ivol" --index 1 -o "$work/inf1.png"
case_ slice-nan-black    0 "levels: 0."             -- bash -c "echo levels: \$($grey_levels '$work/inf1.png')."

# HDF5 and OpenVDB through the command line (their libraries are tested in
# test_hdf5_io and test_vdb_io).
case_ convert-to-hdf5    0 "hdf5 f32 32x32x32"       -- "$IVOL" convert "$work/v.ivol" "$work/v.h5"
case_ h5py-reads-ours    0 "(32, 32, 32) float32"    -- /usr/bin/python3 -c "import h5py; d=h5py.File('$work/v.h5')['/exchange/data']; print(d.shape, d.dtype)"
case_ convert-hdf5-ivol  0 "lossless"                -- "$IVOL" convert "$work/v.h5" "$work/h5.ivol"
case_ hdf5-missing-set   2 "/exchange/data"          -- "$IVOL" convert "$work/v.h5" "$work/m.ivol" --dataset /nope
case_ convert-to-vdb     0 "vdb f32 32x32x32"        -- "$IVOL" convert "$work/v.ivol" "$work/v.vdb"
case_ vdb-print-ours     0 "density"                 -- vdb_print "$work/v.vdb"
case_ convert-vdb-ivol   0 "ivol"                    -- "$IVOL" convert "$work/v.vdb" "$work/vdb.ivol"
case_ vdb-not-vdb        2 "VDB"                     -- "$IVOL" convert "$work/v.h5" "$work/x.ivol" --from vdb

# Streaming: a 64 MiB input converts holding far less than 64 MiB.
/usr/bin/python3 -c "import numpy as np; z,y,x=np.mgrid[0:1024,0:128,0:128]; ((x+y+z)%97 * 0.01).astype(np.float32).tofile('$work/big.raw')"
if [ "${IVOL_SANITIZED:-0}" = 1 ]; then
  echo "note bounded-memory: not measured in a sanitizer build (AddressSanitizer's shadow memory inflates RSS); the Release build checks it"
else
case_ bounded-memory     0 "peak"                    -- /usr/bin/python3 -c "
import resource, subprocess, sys
subprocess.run(['$IVOL', '--version'], capture_output=True)
baseline = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
r = subprocess.run(['$IVOL', '-q', 'convert', '$work/big.raw', '$work/big.ivol', '--dims', '128,128,1024', '--memory', '16'])
peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
print('peak %.1f MiB above a baseline of %.1f MiB' % (peak - baseline, baseline))
sys.exit(r.returncode or (0 if peak - baseline < 24 else 1))"
fi
[ -e "$work/big.ivol" ] || "$IVOL" -q convert "$work/big.raw" "$work/big.ivol" --dims 128,128,1024
case_ big-verifies       0 "OK"                      -- "$IVOL" verify "$work/big.ivol"

# Simulated scans of analytic phantoms (recon/phantom.hpp) and the OpenCL devices.
scan=(--views 24 --detector 48 --radius 20)
case_ phantom-help       0 "lattice-part"            -- "$IVOL" phantom --help
case_ phantom-unknown    1 "known phantoms: shepp-logan" -- "$IVOL" phantom teapot -o "$work/p.h5"
case_ phantom-bad-sdd    1 "--sdd"                   -- "$IVOL" phantom thin-pipe "${scan[@]}" --sdd 500 -o "$work/p.h5"
case_ phantom-h5         0 "ivol recon $work/p.h5 --geometry $work/p.xml --pitch" -- "$IVOL" phantom shepp-logan "${scan[@]}" -o "$work/p.h5" --truth "$work/p-truth.ivol"
case_ phantom-no-clobber 1 "p.h5: exists"            -- "$IVOL" phantom shepp-logan "${scan[@]}" -o "$work/p.h5"
case_ phantom-force      0 ""                        -- "$IVOL" -q phantom shepp-logan "${scan[@]}" -o "$work/p.h5" -f
case_ phantom-h5-shape   0 "(24, 48, 48) float32 24" -- /usr/bin/python3 -c "import h5py; f=h5py.File('$work/p.h5'); d=f['/exchange/data']; print(d.shape, d.dtype, len(f['/exchange/theta']))"
case_ phantom-xml        0 "24 projections"          -- /usr/bin/python3 -c "import xml.etree.ElementTree as E; print(len(E.parse('$work/p.xml').getroot().findall('Projection')), 'projections')"
case_ phantom-truth      0 "OK"                      -- "$IVOL" verify "$work/p-truth.ivol"
case_ phantom-provenance 0 '"phantom": "shepp-logan"' -- "$IVOL" info --json "$work/p-truth.ivol"
case_ phantom-raw        0 "--geometry $work/p-raw.xml --pitch 1.835 --detector 48,48 --views 24" -- "$IVOL" phantom thin-pipe "${scan[@]}" --photons 1e5 -o "$work/p.raw" --geometry-out "$work/p-raw.xml"
case_ phantom-raw-size   0 "221184"                  -- stat -c %s "$work/p.raw"
case_ phantom-raw-xml    0 "24 projections"          -- /usr/bin/python3 -c "import xml.etree.ElementTree as E; print(len(E.parse('$work/p-raw.xml').getroot().findall('Projection')), 'projections')"
case_ phantom-no-dir     2 "nodir"                   -- "$IVOL" phantom shepp-logan "${scan[@]}" -o "$work/q.h5" --truth "$work/nodir/q.ivol"
case_ phantom-no-partial 0 ""                        -- bash -c "test ! -e '$work/q.h5' && test ! -e '$work/q.xml' && ! ls -A '$work' | grep -q 'tmp-'"
case_ devices            0 "compute units"           -- "$IVOL" devices
"$IVOL" devices --json > "$work/devices.json"
case_ devices-json       0 "devices:"                -- /usr/bin/python3 -c "import json,sys; d=json.load(open('$work/devices.json'))['devices']; print('devices:', len(d), d[0]['name']); sys.exit(0 if d and d[0]['compute_units'] > 0 else 1)"

# Reconstruction of the simulated scans (the pitch is what `ivol phantom` printed).
recon_args=(--geometry "$work/p.xml" --pitch 1.835 --size 24 --voxel 1.6)
case_ recon-help         0 "--structure"             -- "$IVOL" recon --help
case_ recon-dense        0 "24x24x24 voxels from 24 views" -- "$IVOL" recon "$work/p.h5" "${recon_args[@]}" -o "$work/r.ivol"
case_ recon-verify       0 "OK"                      -- "$IVOL" verify "$work/r.ivol"
case_ recon-provenance   0 '"algorithm": "FDK"'      -- "$IVOL" info --json "$work/r.ivol"
case_ recon-no-clobber   1 "r.ivol: exists"          -- "$IVOL" recon "$work/p.h5" "${recon_args[@]}" -o "$work/r.ivol"
case_ recon-octree       0 '"structure": "octree"'   -- "$IVOL" recon "$work/p.h5" "${recon_args[@]}" -o "$work/r-octree.ivol" --structure octree --json
case_ recon-octree-ok    0 "OK"                      -- "$IVOL" verify "$work/r-octree.ivol"
# Each detector row of each view filtered once, however thin the slabs: at
# most views × detector rows (24 × 48), not that times the 12 slabs.
case_ recon-rows-once    0 "once"                    -- bash -c "rows=\$('$IVOL' recon '$work/p.h5' ${recon_args[*]} -o '$work/r-thin.ivol' --slab-slices 2 --json | sed -n 's/.*\"rows_filtered\": \([0-9]*\).*/\1/p'); test -n \"\$rows\" && test \"\$rows\" -gt 0 && test \"\$rows\" -le 1152 && echo once"
case_ recon-nested       0 ""                        -- "$IVOL" -q recon "$work/p.h5" "${recon_args[@]}" -o "$work/r-nested.ivol" --structure nested --nested-cell 8
case_ recon-aniso        0 "than 20x22x12"         -- "$IVOL" recon "$work/p.h5" --geometry "$work/p.xml" --pitch 1.835 --size 20,22,12 --voxel 1.6,1.4,2.5 --origin -14,-15,-12 -o "$work/r-aniso.ivol" --structure octree
case_ recon-aniso-size   0 "20 x 22 x 12 voxels of 1.6 x 1.4 x 2.5 mm" -- "$IVOL" info "$work/r-aniso.ivol"
case_ recon-aniso-origin 0 "[-14.0, -15.0, -12.0]"  -- bash -c "'$IVOL' info --json '$work/r-aniso.ivol' | python3 -c 'import json,sys; print(json.load(sys.stdin)[\"origin\"])'"
case_ recon-bad-voxel    1 "every voxel size must be a positive" -- "$IVOL" recon "$work/p.h5" "${recon_args[@]}" --voxel 1,0,1 -o "$work/x.ivol"
# A detector shifted sideways (half-fan): weighted, widened and said so; one
# that never sees the axis is refused with the numbers.
case_ phantom-displaced  0 ""                        -- "$IVOL" -q phantom shepp-logan "${scan[@]}" --offset 28,0 -o "$work/off.h5"
case_ recon-displaced    0 "Wang weighting over"     -- "$IVOL" recon "$work/off.h5" --geometry "$work/off.xml" --pitch 1.835 --size 24 --voxel 1.6 -o "$work/r-off.ivol"
case_ recon-displaced-provenance 0 '"weighting": "wang"' -- "$IVOL" info --json "$work/r-off.ivol"
case_ phantom-off-axis   0 ""                        -- "$IVOL" -q phantom shepp-logan "${scan[@]}" --offset 50,0 -o "$work/far.h5"
case_ recon-off-axis     1 "does not see the rotation axis in view 0: the axis projects to column -3.74796 of 0 to 47" -- "$IVOL" recon "$work/far.h5" --geometry "$work/far.xml" --pitch 1.835 --size 24 --voxel 1.6 -o "$work/x.ivol"
case_ recon-raw          0 "24x24x24"                -- "$IVOL" recon "$work/p.raw" --geometry "$work/p-raw.xml" --pitch 1.835 --detector 48,48 --views 24 --size 24 --voxel 1.6 -o "$work/r-raw.ivol" --window hann
case_ recon-no-pitch     1 "--pitch"                 -- "$IVOL" recon "$work/p.h5" --geometry "$work/p.xml" --size 24 --voxel 1.6 -o "$work/x.ivol"
case_ recon-bad-kind     1 "--structure"             -- "$IVOL" recon "$work/p.h5" "${recon_args[@]}" -o "$work/x.ivol" --structure tree
case_ recon-raw-no-dims  1 "--detector C,R"          -- "$IVOL" recon "$work/p.raw" --geometry "$work/p-raw.xml" --pitch 1.835 --size 24 --voxel 1.6 -o "$work/x.ivol"
case_ recon-missing      2 "nothing.h5"              -- "$IVOL" recon "$work/nothing.h5" "${recon_args[@]}" -o "$work/x.ivol"
case_ recon-bad-device   2 "device 99"               -- "$IVOL" recon "$work/p.h5" "${recon_args[@]}" -o "$work/x.ivol" --device 99
case_ recon-no-partial   0 ""                        -- bash -c "test ! -e '$work/x.ivol' && ! ls -A '$work' | grep -q 'tmp-'"

echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]
