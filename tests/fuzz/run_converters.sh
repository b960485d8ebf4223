#!/usr/bin/env bash
# Builds the libFuzzer harness for the converters' input parsers (raw, TIFF,
# HDF5, ITK images, scans; OpenVDB on request) with clang, ASan and UBSan, and runs it on a corpus seeded
# with small files of each format. Arguments go to libFuzzer.
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
out=${IVOL_FUZZ_DIR:-$root/build-fuzz}
mkdir -p "$out/corpus-converters"
flags="-std=c++17 -O1 -g -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=undefined"
hdf5_flags=$(pkg-config --cflags --libs hdf5-serial 2>/dev/null || echo "-I/usr/include/hdf5/serial -lhdf5_serial")
# Every converter, projection reader and the HDF5 child; not recon_io/,
# which needs the OpenCL FDK.
converters=$(ls "$root"/tools/{convert,scan,isolated}/*.cpp)
clang++ $flags -DIVOL_VERSION_STRING='"fuzz"' -I"$root/libformat/include" -I"$root/libformat/src" \
  -I"$root/tools/convert" -I"$root/tools/scan" -I"$root/tools/isolated" -I"$root/recon/include" "$root"/libformat/src/*.cpp $converters \
  "$root"/recon/src/{geometry,projections,rtk_geometry_xml}.cpp \
  "$root/tests/fuzz/fuzz_converters.cpp" -lzstd -lz -lcurl -ltiff -lopenvdb -ltbb -lImath-3_1 -lpugixml $hdf5_flags \
  -o "$out/fuzz_converters"
# Seeds: a tiny file of each format, prefixed with the byte that selects it.
seed() { { printf "\\x$(printf %02x "$1")"; cat "$2"; } > "$out/corpus-converters/$(basename "$2").$1"; }
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
/usr/bin/python3 - "$work" <<'PY'
import sys, numpy as np, tifffile, h5py
d = sys.argv[1]
v = (np.arange(60, dtype=np.uint16).reshape(3, 4, 5) * 7)
v.tofile(d + "/v.raw")
tifffile.imwrite(d + "/v.tif", v, compression="zlib")
with h5py.File(d + "/v.h5", "w") as f:
    f.create_dataset("/exchange/data", data=v.astype(np.float32), chunks=(2, 2, 5), compression="gzip")
p = np.linspace(0, 2, 2 * 2 * 3, dtype=np.float32).reshape(2, 2, 3)
p.tofile(d + "/p.raw")
tifffile.imwrite(d + "/p.tif", p)
with h5py.File(d + "/p.h5", "w") as f:
    f.create_dataset("/exchange/data", data=p, chunks=(1, 2, 3), compression="gzip")
    f.create_dataset("/exchange/theta", data=np.array([0.0, 90.0]))
open(d + "/g.xml", "w").write(
    '<?xml version="1.0"?>\n<!DOCTYPE RTKGEOMETRY>\n<RTKThreeDCircularGeometry version="3">\n'
    '  <SourceToIsocenterDistance>600</SourceToIsocenterDistance>\n'
    '  <SourceToDetectorDistance>1200</SourceToDetectorDistance>\n'
    '  <Projection>\n    <GantryAngle>0</GantryAngle>\n  </Projection>\n'
    '  <Projection>\n    <GantryAngle>90</GantryAngle>\n    <ProjectionOffsetX>2</ProjectionOffsetX>\n  </Projection>\n'
    '</RTKThreeDCircularGeometry>\n')
PY
seed 0 "$work/v.raw"
seed 1 "$work/v.tif"
seed 2 "$work/v.h5"
seed 4 "$work/p.raw"
seed 5 "$work/p.tif"
seed 6 "$work/p.h5"
seed 7 "$work/g.xml"
# ITK images written by SimpleITK, pynrrd and RTK (tests/data/itk).
seed 234 "$root/tests/data/itk/i16_z.mha"
seed 234 "$root/tests/data/itk/u16.mha"
seed 235 "$root/tests/data/itk/u8.nrrd"
seed 235 "$root/tests/data/itk/i8.nrrd"
seed 236 "$root/tests/data/itk/rtk/proj.mha"
# NXtomo written by the nxtomo package (tests/data/nxtomo); a Nikon .xtekct.
seed 238 "$root/tests/data/nxtomo/shepp_logan.nx"
seed 237 "$root/tests/data/nikon/part.xtekct"
# OpenVDB grids (selector 3) are read only with IVOL_FUZZ_VDB_IN_PROCESS=1:
# libopenvdb has its own harness, run_vdb.sh.
if [ -n "${IVOL_FUZZ_VDB_IN_PROCESS:-}" ]; then
  for g in "$root"/tests/fuzz/regressions/vdb/*.vdb; do seed 3 "$g"; done
fi
# libhdf5 asks malloc for absurd sizes on hostile files and handles the
# failure; under ASan that must return null as it does in a normal build.
ASAN_OPTIONS="allocator_may_return_null=1${ASAN_OPTIONS:+:$ASAN_OPTIONS}" \
LSAN_OPTIONS="suppressions=$root/tests/fuzz/lsan-suppressions.txt${LSAN_OPTIONS:+:$LSAN_OPTIONS}" \
  "$out/fuzz_converters" "$out/corpus-converters" -max_len=65536 -rss_limit_mb=2048 -malloc_limit_mb=1024 -timeout=20 "$@"
