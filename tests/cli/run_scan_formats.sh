#!/usr/bin/env bash
# Scans straight from the scanner's files, reconstructed with no geometry
# option: NeXus NXtomo (files written by ESRF's `nxtomo` package,
# tests/data/nxtomo/make_fixtures.py, and by h5py here) and Nikon XT scans
# (.xtekct + TIFF projections, built here from ivol's phantom). Each is
# compared with the reconstruction of the same projections given as raw
# samples with an explicit geometry. $IVOL is the binary under test.
set -u
cli_dir=$(cd "$(dirname "$0")" && pwd)
: "${IVOL:?set IVOL to the ivol binary}"
data=$(cd "$(dirname "$0")/../data/nxtomo" && pwd)
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cd "$work" || exit 1
source "$cli_dir/cases.sh"
py() { /usr/bin/python3 "$@"; }
# rms A.ivol B.ivol BOUND: the volumes' RMS difference is below BOUND.
rms_below() {
  "$IVOL" -q convert "$1" "$1.raw" --out-type f32 -f && "$IVOL" -q convert "$2" "$2.raw" --out-type f32 -f &&
    py -c "
import numpy as np, sys
a = np.fromfile('$1.raw', '<f4'); b = np.fromfile('$2.raw', '<f4')
rms = float(np.sqrt(((a - b) ** 2).mean()))
print('$1 vs $2: RMS', rms, 'peak', float(abs(b).max()))
sys.exit(0 if rms < $3 else 1)"
}
rms_above() { ! rms_below "$@"; }

# --- NXtomo ------------------------------------------------------------------

# nxtomo's file (uint16 counts, darks, flats before and after, an invalid
# frame, lengths in m and mm) against its line integrals as raw with RTK's
# geometry: RMS 7e-6 on a peak of 0.15 (uint16 rounding and binary16); a
# reader that took only the first flats is at 6e-4, one without the darks
# at 8e-4.
"$IVOL" -q recon "$data/scan.raw" --detector 32,16 --views 20 --pitch 2 --geometry "$data/scan.xml" \
  --size 24 --voxel 1.2 -o raw.ivol
nxtomo_package() {
  "$IVOL" -q recon "$data/shepp_logan.nx" --size 24 --voxel 1.2 -o nx.ivol && rms_below nx.ivol raw.ivol 5e-5 &&
    "$IVOL" info --json nx.ivol >info.json && py -c "
import json
text = open('info.json').read()
for want in ['\"layout\": \"NXtomo\"', '/entry0000/instrument/source/distance (m)', 'x_pixel_size (m)',
             'y_pixel_size (mm)', '\"flat_images\": 4', '\"dark_images\": 2', '\"invalid_images_skipped\": 1',
             '/entry0000/sample/rotation_angle (degree)']:
    assert want in text, want"
}
check "nxtomo-package-file-needs-no-geometry" nxtomo_package

# The same counts written by h5py directly as float32, the angles in
# radians, the source's distance negative (NeXus: upstream), no darks.
py - "$data" <<'PY'
import sys, h5py, numpy as np
d = sys.argv[1]
p = np.fromfile(d + "/scan.raw", "<f4").reshape(20, 16, 32).astype(np.float64)
flat = 30000.0 + 100.0 * np.arange(32)[None, :] * np.ones((16, 1))
frames = np.concatenate([flat[None], flat * np.exp(-p), flat[None]]).astype(np.float32)
with h5py.File("h5py.nx", "w") as f:
    e = f.create_group("scan")
    e.attrs["NX_class"] = "NXentry"
    e["definition"] = "NXtomo"
    det = e.create_group("instrument/detector")
    det["data"] = frames
    det["image_key"] = np.array([1] + [0] * 20 + [1], np.int8)
    for name, value, unit in [("x_pixel_size", 2.0, "mm"), ("y_pixel_size", 2000.0, "um"), ("distance", 30.0, "cm")]:
        det[name] = value
        det[name].attrs["units"] = unit
    e["instrument/source/distance"] = -300.0
    e["instrument/source/distance"].attrs["units"] = "mm"
    e["sample/rotation_angle"] = np.radians(np.concatenate([[0], 18.0 * np.arange(20), [0]]))
    e["sample/rotation_angle"].attrs["units"] = "rad"
PY
check "nxtomo-h5py-file-radians-negative-source" bash -c "
  '$IVOL' -q recon h5py.nx --size 24 --voxel 1.2 -o h5.ivol && $(declare -f rms_below py); rms_below h5.ivol raw.ivol 2e-5"
# A parallel-beam NXtomo file (no source distance) is refused, naming why;
# with --sid and --sdd it is a cone-beam scan again.
check "nxtomo-parallel-beam-refused" bash -c "
  '$IVOL' -q recon '$data/parallel.nx' --size 24 --voxel 1.2 -o par.ivol 2>err; [ \$? -eq 1 ] &&
  grep -q 'parallel-beam scan, and ivol reconstructs cone-beam scans only' err && [ ! -e par.ivol ] &&
  '$IVOL' -q recon '$data/parallel.nx' --sid 300 --sdd 600 --size 24 --voxel 1.2 -o par.ivol &&
  $(declare -f rms_below py); rms_below par.ivol raw.ivol 5e-5"

# --- Any HDF5 dataset ----------------------------------------------------------

# The same line integrals at a path of the user's choosing: --dataset names
# it (the same bits as raw); without it the error says so; on raw input
# --dataset is refused.
py - "$data/scan.raw" <<'PY'
import sys, h5py, numpy as np
p = np.fromfile(sys.argv[1], "<f4").reshape(20, 16, 32)
with h5py.File("moved.h5", "w") as f:
    f["/scan/line_integrals"] = p
PY
check "hdf5-dataset-named" bash -c "
  '$IVOL' -q recon moved.h5 --dataset /scan/line_integrals --geometry '$data/scan.xml' --pitch 2 --size 24 \
    --voxel 1.2 -o moved.ivol && $(declare -f rms_below py); rms_below moved.ivol raw.ivol 1e-12"
check "hdf5-dataset-missing-says-dataset" bash -c "
  '$IVOL' -q recon moved.h5 --geometry '$data/scan.xml' --pitch 2 --size 24 --voxel 1.2 -o x.ivol 2>err;
  [ \$? -eq 2 ] && grep -q 'no dataset /exchange/data; --dataset names another' err && [ ! -e x.ivol ]"
check "hdf5-dataset-on-raw-refused" bash -c "
  '$IVOL' -q recon '$data/scan.raw' --dataset /x --detector 32,16 --views 20 --pitch 2 --geometry '$data/scan.xml' \
    --size 24 --voxel 1.2 -o x.ivol 2>err; [ \$? -eq 1 ] && grep -q 'not HDF5: it has no datasets to name' err"

# --- Nikon XT ----------------------------------------------------------------

# A Nikon scan of ivol's phantom as CIL's NikonDataReader describes one
# (docs/geometry.md): each image turned by 180°, stage angle φ = θ + 180°,
# source and detector shifted by ObjectOffsetX, uint16 counts under
# WhiteLevel. The reference is the same counts unturned as raw uint16 with
# an RTK geometry file of θ and the offsets.
"$IVOL" -q phantom shepp-logan --views 24 --detector 40,20 --sid 250 --sdd 500 --pitch 1.5 --radius 12 -o phantom.raw
py - <<'PY'
import os, numpy as np, tifffile
views, rows, cols, W = 24, 20, 40, 50000.0
p = np.fromfile("phantom.raw", "<f4").reshape(views, rows, cols)
counts = np.rint(W * np.exp(-p * (2.5 / p.max()))).astype("<u2")
counts.tofile("counts.raw")
rng = np.random.default_rng(3)
nominal = 15.0 * np.arange(views)
measured = nominal + rng.uniform(-2, 2, views)

def xml(name, theta, offset):
    with open(name, "w") as f:
        f.write('<?xml version="1.0"?>\n<RTKThreeDCircularGeometry version="3">\n')
        for t in theta:
            f.write(f"<Projection><GantryAngle>{t!r}</GantryAngle><SourceToIsocenterDistance>250"
                    f"</SourceToIsocenterDistance><SourceToDetectorDistance>500</SourceToDetectorDistance>"
                    f"<SourceOffsetX>{offset!r}</SourceOffsetX><ProjectionOffsetX>{offset!r}</ProjectionOffsetX>"
                    "</Projection>\n")
        f.write("</RTKThreeDCircularGeometry>\n")

def scan(folder, keys, angles=None):
    os.makedirs(folder + "/proj")
    for i in range(views):
        tifffile.imwrite(f"{folder}/proj/part_{i + 1:04d}.tif", counts[i, ::-1, ::-1])
    text = {"Name": "part", "InputFolderName": "proj", "Projections": views, "WhiteLevel": W,
            "DetectorPixelsX": cols, "DetectorPixelsY": rows, "DetectorPixelSizeX": 1.5, "DetectorPixelSizeY": 1.5,
            "SrcToObject": 250, "SrcToDetector": 500, "InitialAngle": 180, "AngularStep": 15,
            "VoxelsX": 24, "VoxelsY": 24, "VoxelsZ": 16, "VoxelSizeX": 1.2, "VoxelSizeY": 1.2, "VoxelSizeZ": 1.2}
    text.update(keys)
    with open(f"{folder}/part.xtekct", "w") as f:
        f.write("[XTekCT]\n" + "".join(f"{k}={v}\n" for k, v in text.items()) + "[Xrays]\nXraykV=160\n")
    if angles == "ctdata":
        with open(f"{folder}/_ctdata.txt", "w") as f:
            f.write("Nikon CT data\nFrames per projection\t1\nProjection\tAngle(deg)\tTime\n")
            f.write("".join(f"{i + 1}\t{a:.6f}\t{i * 0.5:.3f}\n" for i, a in enumerate(measured)))
    if angles == "ang":  # listed last projection first
        with open(f"{folder}/part.ang", "w") as f:
            f.write("Projection\tAngle(deg)\n")
            f.write("".join(f"{i + 1:04d}:\t{measured[i]:.6f}\n" for i in reversed(range(views))))

scan("plain", {})
scan("offset", {"ObjectOffsetX": 0.9})
scan("cor", {"CentreOfRotationTop": 1.8, "CentreOfRotationBottom": 1.8})  # 1.8 mm at the detector: 0.9 at the axis
scan("ctdata", {}, "ctdata")
scan("ang", {}, "ang")
scan("aniso", {"VoxelsZ": 12, "VoxelSizeZ": 1.6})
xml("nominal.xml", list(nominal), 0.0)
xml("shifted.xml", list(nominal), 0.9)
xml("measured.xml", [float(round(a, 6)) for a in measured], 0.0)
PY
reference() {  # NAME XML
  "$IVOL" -q recon counts.raw --detector 40,20 --views 24 --sample u16 --incident 50000 --pitch 1.5 \
    --geometry "$2" --size 24,24,16 --voxel 1.2 -o "$1.ivol"
}
reference nominal nominal.xml && reference shifted shifted.xml && reference measured measured.xml
nikon() {  # FOLDER REFERENCE: no option but the output
  "$IVOL" -q recon "$1/part.xtekct" -o "$1.ivol" && rms_below "$1.ivol" "$2.ivol" 1e-5
}
check "xtekct-no-options" nikon plain nominal
check "xtekct-grid-from-voxels-keys" py -c "
import json, subprocess
info = json.loads(subprocess.run(['$IVOL', 'info', '--json', 'plain.ivol'], capture_output=True, check=True).stdout)
assert info['dimensions'] == [24, 24, 16], info['dimensions']"
check "xtekct-anisotropic-grid" bash -c "
  '$IVOL' -q recon aniso/part.xtekct -o aniso.ivol && '$IVOL' info --json aniso.ivol > a.json && /usr/bin/python3 -c \"
import json
info = json.load(open('a.json'))
assert info['dimensions'] == [24, 24, 12], info['dimensions']
text = json.dumps(info)
assert '1.6' in text, 'no voxel size 1.6 in the file'\""
check "xtekct-object-offset" nikon offset shifted
check "xtekct-centre-of-rotation" nikon cor shifted
check "xtekct-ctdata-angles" nikon ctdata measured
check "xtekct-ang-angles" nikon ang measured
# The comparisons can fail: the offset and the measured angles change the
# volume by far more than the bound.
check "xtekct-offset-matters" rms_above offset.ivol nominal.ivol 1e-3
check "xtekct-angles-matter" rms_above ctdata.ivol nominal.ivol 1e-3
check "xtekct-provenance-says-where" bash -c "'$IVOL' info --json ctdata.ivol > j && grep -q '_ctdata.txt + InitialAngle' j &&
  grep -q 'SrcToObject' j && grep -q '\"role\": *\"angles\"' j"

finish
