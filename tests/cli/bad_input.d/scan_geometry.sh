# Geometry mistakes made loud (issue 21, item 6), and the scanner files whose
# geometry recon reads (NeXus NXtomo, Nikon .xtekct) refused when they say
# something ivol cannot reconstruct or an option contradicts them. A doubtful
# but usable input is a warning naming the numbers (exit 0, written to $work
# so that $out stays empty). Sourced by ../run_bad_input.sh.

nx="$(dirname "$0")/../data/nxtomo"
/usr/bin/python3 - "$work" "$nx" <<'PY'
import os, shutil, sys, h5py, numpy as np, tifffile
d, nx = sys.argv[1:]
# Two NXtomo entries; an image key 5; a length in furlongs.
shutil.copy(nx + "/shepp_logan.nx", d + "/two.nx")
with h5py.File(d + "/two.nx", "a") as f:
    f.copy("entry0000", "entry0001")
for name, change in [("key5.nx", lambda f: f["entry0000/instrument/detector/image_key"].__setitem__(5, 5)),
                     ("furlong.nx", lambda f: f["entry0000/instrument/detector/x_pixel_size"].attrs.__setitem__("units", "furlong")),
                     ("noflat.nx", lambda f: f["entry0000/instrument/detector/image_key"].__setitem__(
                         np.s_[:], np.where(f["entry0000/instrument/detector/image_key"][()] == 1, 0, f["entry0000/instrument/detector/image_key"][()])))]:
    shutil.copy(nx + "/shepp_logan.nx", d + "/" + name)
    with h5py.File(d + "/" + name, "a") as f:
        change(f)
# Nikon scans: a good one, then one key changed each.
good = {"Name": "part", "Projections": 4, "WhiteLevel": 60000, "DetectorPixelsX": 16, "DetectorPixelsY": 8,
        "DetectorPixelSizeX": 0.5, "DetectorPixelSizeY": 0.5, "SrcToObject": 100, "SrcToDetector": 400,
        "InitialAngle": 0, "AngularStep": 90}
def nikon(name, changes={}, drop=(), views=4, ctdata=None):
    folder = os.path.join(d, name)
    os.makedirs(folder)
    for i in range(views):
        tifffile.imwrite(f"{folder}/part_{i + 1:04d}.tif", np.full((8, 16), 30000, np.uint16))
    keys = {k: v for k, v in {**good, **changes}.items() if k not in drop}
    open(folder + "/part.xtekct", "w").write("[XTekCT]\n" + "".join(f"{k}={v}\n" for k, v in keys.items()))
    if ctdata is not None:
        open(folder + "/_ctdata.txt", "w").write("h\nh\nh\n" + ctdata)
nikon("nikon_good")
nikon("nikon_no_sod", drop=("SrcToObject",))
nikon("nikon_text", {"WhiteLevel": "bright"})
nikon("nikon_count", views=3)
nikon("nikon_tilt", {"ObjectTilt": 0.5})
nikon("nikon_roll", {"CentreOfRotationTop": 0.4, "CentreOfRotationBottom": -0.4})
nikon("nikon_detoffset", {"DetectorOffsetX": 2})
nikon("nikon_beside", {"ObjectOffsetX": 5})
nikon("nikon_ctdata", ctdata="1\t0\t0\n2\t90\t1\n3\t180\t2\n")
nikon("nikon_nogrid")
# An uncompressed MetaImage stack, whose header a raw read skips.
open(d + "/stack.mha", "wb").write(b"ObjectType = Image\nNDims = 3\nDimSize = 8 4 2\nElementSpacing = 1 1 1\n"
                                   b"Offset = -3.5 -1.5 0\nElementType = MET_FLOAT\nElementDataFile = LOCAL\n" +
                                   np.zeros(64, "<f4").tobytes())
PY
"$IVOL" -q recon "$work/p.raw" "${scan[@]}" "${grid[@]}" -o "$work/p.ivol"
cp "$work/p.xml" "$work/p_copy.xml"

# A Nikon scan whose ObjectOffsetX puts the axis beside the detector.
bad geometry-nikon-axis-beside     1 "part.xtekct: the detector does not see the rotation axis in view 0" -- "$IVOL" recon "$work/nikon_beside/part.xtekct" --size 8 --voxel 0.1 -o "$out/x.ivol"
# Options that contradict each other or the file.
bad geometry-xml-and-sid           1 "--geometry gives the distances and offsets of every view; leave --sid, --sdd and --offset out" -- "$IVOL" recon "$work/p.raw" "${scan[@]}" --sid 500 --sdd 1000 "${grid[@]}" -o "$out/x.ivol"
bad geometry-itk-read-as-raw-warns 0 "is an ITK image read as raw samples: its header's spacing and origin are not used" -- bash -c "'$IVOL' recon '$work/stack.mha' --format raw --detector 8,4 --views 2 --header-bytes \$(( \$(stat -c %s '$work/stack.mha') - 256 )) --pitch 1 --sid 100 --sdd 150 --size 4 --voxel 0.5 -o '$work/asraw.ivol'"
bad nxtomo-pitch-disagrees         1 "--pitch 1.5 disagrees with $nx/shepp_logan.nx's /entry0000/instrument/detector/x_pixel_size (m)" -- "$IVOL" recon "$nx/shepp_logan.nx" --pitch 1.5 "${grid[@]}" -o "$out/x.ivol"
bad nxtomo-sid-disagrees           1 "--sid 250 disagrees with $nx/shepp_logan.nx's /entry0000/instrument/source/distance (m) (300 mm)" -- "$IVOL" recon "$nx/shepp_logan.nx" --sid 250 "${grid[@]}" -o "$out/x.ivol"
bad nxtomo-parallel-beam           1 "parallel-beam scan, and ivol reconstructs cone-beam scans only (FDK)" -- "$IVOL" recon "$nx/parallel.nx" "${grid[@]}" -o "$out/x.ivol"
bad nxtomo-two-entries             2 "two.nx: holds 2 NXtomo entries (/entry0000, /entry0001)" -- "$IVOL" recon "$work/two.nx" "${grid[@]}" -o "$out/x.ivol"
bad nxtomo-image-key-5             2 "image_key value 5 is 5.000000; image keys are 0 (projection), 1 (flat), 2 (dark), 3 (invalid)" -- "$IVOL" recon "$work/key5.nx" "${grid[@]}" -o "$out/x.ivol"
bad nxtomo-unknown-unit            2 "x_pixel_size has units 'furlong', not a length ivol knows" -- "$IVOL" recon "$work/furlong.nx" "${grid[@]}" -o "$out/x.ivol"
bad nxtomo-no-flat                 2 "marks no flat field (1): the data cannot be turned into line integrals" -- "$IVOL" recon "$work/noflat.nx" --intensities "${grid[@]}" -o "$out/x.ivol"
# Nikon scans whose keys are missing, wrong or beyond ivol's geometry.
bad nikon-missing-key              2 "part.xtekct: key SrcToObject is missing" -- "$IVOL" recon "$work/nikon_no_sod/part.xtekct" "${grid[@]}" -o "$out/x.ivol"
bad nikon-key-not-a-number         2 "key WhiteLevel is 'bright', not a number" -- "$IVOL" recon "$work/nikon_text/part.xtekct" "${grid[@]}" -o "$out/x.ivol"
bad nikon-projection-count         2 "Projections=4 but $work/nikon_count/part_*.tif holds 3 TIFF files" -- "$IVOL" recon "$work/nikon_count/part.xtekct" "${grid[@]}" -o "$out/x.ivol"
bad nikon-object-tilt              2 "ObjectTilt = 0.5 degrees: ivol's geometry has a rotation axis perpendicular to the central ray" -- "$IVOL" recon "$work/nikon_tilt/part.xtekct" "${grid[@]}" -o "$out/x.ivol"
bad nikon-leaning-axis             2 "CentreOfRotationTop − CentreOfRotationBottom = 0.8 mm: the rotation axis leans by 0.8 mm over the detector's 4 mm" -- "$IVOL" recon "$work/nikon_roll/part.xtekct" "${grid[@]}" -o "$out/x.ivol"
bad nikon-detector-offset          2 "DetectorOffsetX/Y = 2, 0: a shifted detector is not mapped" -- "$IVOL" recon "$work/nikon_detoffset/part.xtekct" "${grid[@]}" -o "$out/x.ivol"
bad nikon-ctdata-count             2 "_ctdata.txt: lists 3 angles for 4 projections" -- "$IVOL" recon "$work/nikon_ctdata/part.xtekct" "${grid[@]}" -o "$out/x.ivol"
bad nikon-and-geometry-option      1 "part.xtekct gives the scan's geometry, detector and white level (a Nikon XT .xtekct file); leave --sid out" -- "$IVOL" recon "$work/nikon_good/part.xtekct" --sid 100 "${grid[@]}" -o "$out/x.ivol"
bad nikon-no-grid                  1 "--size and --voxel are required (the scan's files do not propose a grid)" -- "$IVOL" recon "$work/nikon_nogrid/part.xtekct" -o "$out/x.ivol"
bad recon-size-without-voxel       1 "--size and --voxel go together" -- "$IVOL" recon "$work/p.raw" "${scan[@]}" --size 16 -o "$out/x.ivol"
bad geometry-offset-and-origin-warns 0 "--offset 1,0 and $(dirname "$0")/../data/itk/rtk/proj.mha MetaImage Offset (which shifts the detector by 3, -2 mm) both apply: the detector is offset by 4, -2 mm in all" -- "$IVOL" recon "$(dirname "$0")/../data/itk/rtk/proj.mha" --sid 1000 --sdd 1500 --offset 1,0 "${grid[@]}" -o "$work/both.ivol"
