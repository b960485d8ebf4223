# TIFF folders checked before they are trusted (README "TIFF folders"): a
# missing slice number, two files with one number, a page of another size or
# sample type, a file of several pages among single slices are refused (exit
# 2) naming the file; hidden files (macOS
# AppleDouble ._*) are skipped with a note. Sourced by ../run_bad_input.sh.

/usr/bin/python3 - "$work" <<'PY'
import os, sys, numpy as np, tifffile
d = sys.argv[1]
def folder(name, slices):
    path = os.path.join(d, name)
    os.makedirs(path)
    for file, array in slices:
        tifffile.imwrite(os.path.join(path, file), array)
u16 = lambda v, shape=(8, 8): np.full(shape, v, dtype=np.uint16)
folder("gap", [("s%d.tif" % i, u16(i)) for i in (54, 55, 56, 58, 59)])
folder("duplicate", [("s1.tif", u16(1)), ("s01.tif", u16(1)), ("s2.tif", u16(2))])
folder("size", [("s1.tif", u16(1)), ("s2.tif", u16(2)), ("s3.tif", u16(3, (8, 9))), ("s4.tif", u16(4))])
folder("type", [("s1.tif", u16(1)), ("s2.tif", u16(2)), ("s3.tif", np.full((8, 8), 3, np.float32))])
folder("unnumbered", [("s1.tif", u16(1)), ("s2.tif", u16(2)), ("preview.tif", u16(0))])
folder("every_other", [("s%d.tif" % i, u16(i)) for i in (0, 2, 4, 6)])
folder("appledouble", [("s1.tif", u16(1)), ("s2.tif", u16(2))])
# One file of four pages among files of one: s3's other pages would move
# every later slice by three.
folder("multipage", [("s%d.tif" % i, u16(i)) for i in (1, 2, 4, 5)])
tifffile.imwrite(os.path.join(d, "multipage", "s3.tif"), np.stack([u16(3)] * 4), photometric="minisblack")
# What macOS leaves on a non-Apple disk: a resource fork that is no TIFF.
open(os.path.join(d, "appledouble", "._s1.tif"), "wb").write(b"\x00\x05\x16\x07" + bytes(60))
PY

bad tiff-folder-gap        2 "gap/s58.tif follows s56.tif: s57.tif is missing; use --allow-gaps" -- "$IVOL" convert "$work/gap" "$out/x.ivol"
bad tiff-folder-duplicate  2 "s1.tif and s01.tif have the same slice number 1" -- "$IVOL" convert "$work/duplicate" "$out/x.ivol"
bad tiff-folder-size       2 "size/s3.tif: 9x8 u16 differs from $work/size/s1.tif: 8x8 u16" -- "$IVOL" convert "$work/size" "$out/x.ivol"
bad tiff-folder-type       2 "type/s3.tif: 8x8 f32 differs from $work/type/s1.tif: 8x8 u16" -- "$IVOL" convert "$work/type" "$out/x.tif"
bad tiff-folder-unnumbered 2 "unnumbered/preview.tif: no slice number in the name" -- "$IVOL" convert "$work/unnumbered" "$out/x.ivol"
# --allow-gaps converts what is there and says so; the output goes outside
# $out, which must stay empty.
bad tiff-folder-allow-gaps 0 "s57.tif is missing: converted without it (--allow-gaps)" -- "$IVOL" convert "$work/gap" "$work/gap.ivol" --allow-gaps
bad tiff-folder-appledouble 0 "skipped hidden file ._s1.tif" -- "$IVOL" convert "$work/appledouble" "$work/appledouble.ivol"
bad tiff-folder-multipage  2 "multipage/s3.tif: holds more than one page, but among several TIFF files each must be one slice" -- "$IVOL" convert "$work/multipage" "$out/x.ivol"
# A folder of every other slice has a step of 2, not gaps.
bad tiff-folder-step-two   0 "every_other (tiff u16 8x8x4" -- "$IVOL" convert "$work/every_other" "$work/every_other.ivol"
# Projections in a folder are checked the same way: a missing view would
# shift every later angle.
bad recon-tiff-folder-gap  2 "gap/s58.tif follows s56.tif: s57.tif is missing; every view needs its projection" -- "$IVOL" recon "$work/gap" --sid 600 --sdd 1200 --pitch 1.5 --size 16 --voxel 1.5 -o "$out/x.ivol"
bad recon-tiff-folder-multipage 2 "multipage/s3.tif: holds more than one page, but among several TIFF files each must be one projection" -- "$IVOL" recon "$work/multipage" --sid 600 --sdd 1200 --pitch 1.5 --size 16 --voxel 1.5 -o "$out/x.ivol"

# A volumetric TIFF (SGI's ImageDepth, as tifffile writes with
# volumetric=True): one page that is a whole 3-D block. It was read as its
# first plane only, exit 0 and "lossless"; now refused, naming the tag.
/usr/bin/python3 - "$work" <<'PY'
import os, sys, numpy as np, tifffile
d = sys.argv[1]
v = np.random.default_rng(3).random((9, 7, 33)).astype(np.float32)
tifffile.imwrite(os.path.join(d, "volumetric-tiled.tif"), v, tile=(8, 16, 16), volumetric=True)
tifffile.imwrite(os.path.join(d, "volumetric.tif"), v, volumetric=True)
PY
bad tiff-volumetric-tiled 2 "volumetric-tiled.tif: a volumetric page (ImageDepth 9) is not supported" -- "$IVOL" convert "$work/volumetric-tiled.tif" "$out/x.ivol"
bad tiff-volumetric       2 "volumetric.tif: a volumetric page (ImageDepth 9) is not supported" -- "$IVOL" convert "$work/volumetric.tif" "$out/x.raw"
