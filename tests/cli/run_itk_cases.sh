#!/usr/bin/env bash
# ITK's image files through the command line: RTK's own projections (.mha
# with the pitch and the projection origin in its header) reconstruct with
# --geometry and nothing else, as RTK reconstructs them; MetaImage and NRRD
# volumes written by SimpleITK and pynrrd convert both ways with spacing and
# origin; what cannot be kept is refused. Fixtures: tests/data/itk
# (make_fixtures.py). $IVOL is the binary under test.
set -u
cli_dir=$(cd "$(dirname "$0")" && pwd)
: "${IVOL:?set IVOL to the ivol binary}"
data=$(cd "$(dirname "$0")/../data/itk" && pwd)
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cd "$work" || exit 1
source "$cli_dir/cases.sh"
py() { /usr/bin/python3 -c "$@"; }

# RTK's projections, nothing but the geometry and the grid: the pitch and the
# origin come from the header, and the result is RTK's FDK of them (RMS
# within 0.1 of a peak of 1.8: RTK's ramp pads differently at the truncated
# edges), as close as with the values typed by hand, and far closer than
# with the centred origin the header corrects (RMS 0.29).
recon_rtk() {
  "$IVOL" -q recon "$data/rtk/proj.mha" --geometry "$data/rtk/geometry.xml" --size 24 --voxel 1.6 -o rtk.ivol &&
    "$IVOL" -q convert rtk.ivol rtk.raw --out-type f32 &&
    "$IVOL" info --json rtk.ivol | grep -q '"pitch_from": *".*MetaImage ElementSpacing"' &&
    "$IVOL" info --json rtk.ivol | grep -q '"projection_origin_from": *".*MetaImage Offset"' &&
    py "
import numpy as np, zlib
a = np.fromfile('rtk.raw', '<f4').reshape(24, 24, 24)
r = np.load('$data/rtk/fdk.npy')
rms = float(np.sqrt(((a - r) ** 2).mean()))
print('RMS against RTK', rms)
assert rms < 0.1, rms
b = open('$data/rtk/proj.mha', 'rb').read()
np.frombuffer(zlib.decompress(b[b.index(b'ElementDataFile = LOCAL\n') + 24:]), '<f4').tofile('p.raw')
" &&
    "$IVOL" -q recon p.raw --detector 40,30 --views 24 --pitch 1.5,1.25 --projection-origin=-26.25,-20.125 \
      --geometry "$data/rtk/geometry.xml" --size 24 --voxel 1.6 -o typed.ivol &&
    "$IVOL" -q convert typed.ivol typed.raw --out-type f32 && cmp rtk.raw typed.raw &&
    "$IVOL" -q recon p.raw --detector 40,30 --views 24 --pitch 1.5,1.25 \
      --geometry "$data/rtk/geometry.xml" --size 24 --voxel 1.6 -o centred.ivol &&
    "$IVOL" -q convert centred.ivol centred.raw --out-type f32 &&
    py "
import numpy as np
a = np.fromfile('centred.raw', '<f4').reshape(24, 24, 24)
rms = float(np.sqrt(((a - np.load('$data/rtk/fdk.npy')) ** 2).mean()))
print('RMS with the centred origin', rms)
assert rms > 0.2, rms"
}
check "rtk-projections-need-no-pitch-or-origin" recon_rtk

# RTK's own half-fan scan (the detector shifted 18 mm, make_fixtures.py):
# ivol applies Wang's weighting by itself and lands as close to RTK's FDK
# behind its DisplacedDetectorImageFilter as on the centred scan, and as close
# to the phantom RTK draws (MAE 0.086 against RTK's 0.090 when written).
recon_rtk_displaced() {
  "$IVOL" recon "$data/rtk/displaced_proj.mha" --geometry "$data/rtk/displaced_geometry.xml" --size 24 --voxel 1.6 \
    -o displaced.ivol 2>displaced.log && grep -q "Wang weighting over +-11.25 mm" displaced.log &&
    "$IVOL" -q convert displaced.ivol displaced.raw --out-type f32 &&
    py "
import numpy as np
a = np.fromfile('displaced.raw', '<f4').reshape(24, 24, 24)
r = np.load('$data/rtk/displaced_fdk.npy')
t = np.load('$data/rtk/displaced_truth.npy')
rms = float(np.sqrt(((a - r) ** 2).mean()))
ours, theirs = float(np.abs(a - t).mean()), float(np.abs(r - t).mean())
print('RMS against RTK', rms, 'MAE ivol', ours, 'MAE RTK', theirs)
assert rms < 0.1, rms
assert ours <= 1.05 * theirs, (ours, theirs)"
}
check "rtk-displaced-detector-matches-rtk" recon_rtk_displaced

# A --pitch or --projection-origin that contradicts the header is a usage
# error naming both, with nothing written.
contradiction() {
  "$IVOL" -q recon "$data/rtk/proj.mha" --geometry "$data/rtk/geometry.xml" --size 24 --voxel 1.6 "$@" -o x.ivol
  local status=$?
  [ "$status" -eq 1 ] && [ ! -e x.ivol ]
}
check "pitch-contradicting-the-header" contradiction --pitch 1.5
check "origin-contradicting-the-header" contradiction --projection-origin=-29.25,-18.125
check "pitch-still-required-without-a-header" bash -c "
  '$IVOL' -q recon p.raw --detector 40,30 --views 24 --geometry '$data/rtk/geometry.xml' --size 24 --voxel 1.6 \
    -o y.ivol 2>err; [ \$? -eq 1 ] && grep -q -- '--pitch is required' err && [ ! -e y.ivol ]"

# Volumes written by SimpleITK and pynrrd: into .ivol and out again as .mha
# and .nrrd, the samples those libraries wrote (their numpy arrays), the
# spacing and origin in the .ivol metadata and in the files written.
volume_round_trip() {
  local file=$1 stem=$2 type=$3
  "$IVOL" -q convert "$data/$file" "$stem.ivol" &&
    "$IVOL" info --json "$stem.ivol" | py "
import json, sys
m = json.load(sys.stdin)['metadata']
assert m['voxel_size'] == [0.5, 0.25, 2.0], m['voxel_size']
assert m['origin'] == [-3.5, 1.25, 10.0], m['origin']
assert m['unit'] == 'mm'" &&
    "$IVOL" -q convert "$stem.ivol" "$stem.mha" && "$IVOL" -q convert "$stem.mha" "$stem.nrrd" &&
    "$IVOL" -q convert "$stem.nrrd" "$stem.raw" --type "$type" &&
    py "
import numpy as np
want = np.load('$data/$stem.npy')
if want.dtype == np.int8: want = want.astype('<i2')
got = np.fromfile('$stem.raw', want.dtype.newbyteorder('<')).reshape(want.shape)
assert got.tobytes() == want.astype(want.dtype.newbyteorder('<')).tobytes()
head = open('$stem.mha', 'rb').read(400)
assert b'ElementSpacing = 0.5 0.25 2\n' in head and b'Offset = -3.5 1.25 10\n' in head, head"
}
check "mha-uint16" volume_round_trip u16.mha u16 u16
check "mha-int16-compressed" volume_round_trip i16_z.mha i16_z i16
check "mhd-float32" volume_round_trip f32.mhd f32 f32
check "nrrd-uint8-gzip" volume_round_trip u8.nrrd u8 u8
check "nrrd-int8-widened" volume_round_trip i8.nrrd i8 i16
check "nhdr-float32-big-endian" volume_round_trip f32_be.nhdr f32_be f32

refused() {
  local status=$1 text=$2 out=$3
  shift 3
  "$IVOL" -q "$@" >out.txt 2>&1
  local got=$?
  [ "$got" -eq "$status" ] && grep -qF -- "$text" out.txt && [ ! -e "$out" ] ||
    { echo "exit $got"; cat out.txt; false; }
}
check "rotated-direction-refused" refused 2 "not the identity" r.ivol convert "$data/rotated.mha" r.ivol
check "mhd-output-refused" refused 2 "written as .mha or .nrrd" u.mhd convert u16.ivol u.mhd
check "binary16-into-metaimage-refused" bash -c "
  '$IVOL' -q convert '$data/f32.mhd' h.ivol --type f16 --allow-lossy 2>/dev/null &&
  '$IVOL' -q convert h.ivol h.mha && grep -q 'MET_FLOAT' h.mha &&
  '$IVOL' -q convert h.ivol h2.mha --out-type f16 2>err; [ \$? -eq 1 ] && grep -q 'no binary16 type' err && [ ! -e h2.mha ]"

finish
