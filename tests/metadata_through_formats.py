#!/usr/bin/python3
"""Geometry and metadata through every format (README "Geometry through the
formats"), checked against the libraries on the other side: files written by
tifffile (ImageJ and OME modes), h5py (attributes, DXchange) and pyopenvdb
are read by `ivol convert` with the right voxel size, origin and unit; ivol's
TIFF, HDF5 and OpenVDB outputs are read back by those libraries with the
right values; .ivol -> X -> .ivol keeps voxel size, origin, unit, quantity,
value unit and provenance; explicit options win over the file.

$IVOL is the binary under test. Exit status 0 when every check holds."""

import json
import os
import subprocess
import sys
import tempfile

import h5py
import numpy as np
import pyopenvdb as vdb
import tifffile

IVOL = os.environ["IVOL"]
work = tempfile.mkdtemp(prefix="ivol_meta_")
failures = []


def check(name, condition, detail=""):
    print(("ok   " if condition else "FAIL ") + name + ("" if condition else ": " + str(detail)))
    if not condition:
        failures.append(name)


def close(a, b, rel=1e-9):
    return len(a) == len(b) and all(abs(x - y) <= rel * max(1.0, abs(x), abs(y)) for x, y in zip(a, b))


def path(name):
    return os.path.join(work, name)


def ivol(*args):
    run = subprocess.run([IVOL, *args], capture_output=True, text=True)
    if run.returncode != 0:
        raise SystemExit("ivol %s failed (%d): %s%s" % (" ".join(args), run.returncode, run.stdout, run.stderr))
    return run.stdout, run.stderr


def convert(src, dst, *options):
    if os.path.exists(dst):
        os.remove(dst)
    return ivol("convert", src, dst, *options)


def metadata(ivol_file):
    return json.loads(ivol("info", "--json", ivol_file)[0])["metadata"]


def geometry_of(ivol_file):
    m = metadata(ivol_file)
    return m["voxel_size"], m["origin"], m["unit"], m


volume = (np.arange(5 * 6 * 7, dtype=np.uint16).reshape(5, 6, 7) + 1)  # (z, y, x)

# --- Files written by others, read by ivol ---------------------------------

tifffile.imwrite(path("imagej.tif"), volume, imagej=True, resolution=(1 / 0.05, 1 / 0.04),
                 metadata={"spacing": 0.1, "unit": "um", "axes": "ZYX"})
out, err = convert(path("imagej.tif"), path("imagej.ivol"))
size, origin, unit, _ = geometry_of(path("imagej.ivol"))
check("tifffile ImageJ: voxel size from resolution and spacing", close(size, [0.05, 0.04, 0.1]), size)
check("tifffile ImageJ: unit", unit == "um", unit)
check("tifffile ImageJ: summary says where", "(from ImageJ XResolution/YResolution and spacing=)" in out, out)

tifffile.imwrite(path("imagej_micron.tif"), volume, imagej=True, resolution=(2.0, 2.0),
                 metadata={"spacing": 0.5, "unit": "micron", "axes": "ZYX"})
convert(path("imagej_micron.tif"), path("imagej_micron.ivol"))
size, _, unit, _ = geometry_of(path("imagej_micron.ivol"))
check("tifffile ImageJ micron", close(size, [0.5, 0.5, 0.5]) and unit == "um", (size, unit))

tifffile.imwrite(path("ome.tif"), volume, ome=True, metadata={
    "axes": "ZYX", "PhysicalSizeX": 0.05, "PhysicalSizeXUnit": "mm", "PhysicalSizeY": 0.06,
    "PhysicalSizeYUnit": "mm", "PhysicalSizeZ": 70.0, "PhysicalSizeZUnit": "\u00b5m"})
out, err = convert(path("ome.tif"), path("ome.ivol"))
size, origin, unit, _ = geometry_of(path("ome.ivol"))
check("tifffile OME: PhysicalSize, Z in um converted to mm", close(size, [0.05, 0.06, 0.07]), size)
check("tifffile OME: unit", unit == "mm", unit)
check("tifffile OME: summary", "voxel size 0.05 x 0.06 x 0.07 mm (from OME-TIFF PhysicalSize)" in out, out)
check("tifffile OME: origin not in the file", "origin 0, 0, 0 mm (default: none in the file)" in out, out)

tifffile.imwrite(path("ome_default_unit.tif"), volume, ome=True,
                 metadata={"axes": "ZYX", "PhysicalSizeX": 2.5, "PhysicalSizeY": 2.5, "PhysicalSizeZ": 3.0})
convert(path("ome_default_unit.tif"), path("ome_default_unit.ivol"))
size, _, unit, _ = geometry_of(path("ome_default_unit.ivol"))
check("tifffile OME: no unit means micrometres", close(size, [2.5, 2.5, 3.0]) and unit == "um", (size, unit))

# A hyperstack's pages are not the slices of one grey volume: refused.
for mode, name in (("imagej", "hyperstack.tif"), ("ome", "ome_channels.tif")):
    stack = np.zeros((3, 2, 6, 7), np.uint16)  # (z, c, y, x)
    if mode == "imagej":
        tifffile.imwrite(path(name), stack, imagej=True, metadata={"axes": "ZCYX"})
    else:
        tifffile.imwrite(path(name), stack, ome=True, metadata={"axes": "ZCYX"})
    run = subprocess.run([IVOL, "convert", path(name), path(name + ".ivol")], capture_output=True, text=True)
    check("%s with 2 channels refused" % mode, run.returncode == 2 and "2 channels" in run.stderr and
          name in run.stderr and not os.path.exists(path(name + ".ivol")), (run.returncode, run.stderr))

tifffile.imwrite(path("plain.tif"), volume)
out, err = convert(path("plain.tif"), path("plain.ivol"))
size, _, unit, m = geometry_of(path("plain.ivol"))
check("plain TIFF: no voxel size invented", unit == "pixel" and m["provenance"].get("voxel_size_known") is False,
      (unit, m["provenance"]))
check("plain TIFF: warning", "gives no voxel size" in err, err)

with h5py.File(path("attrs.h5"), "w") as f:
    d = f.create_dataset("/exchange/data", data=volume.astype(np.float32))
    d.attrs["voxel_size"] = [0.3, 0.2, 0.1]  # (z, y, x)
    d.attrs["origin"] = [-3.0, -2.0, -1.0]
    d.attrs["unit"] = "mm"
    d.attrs["quantity"] = "linear_attenuation"
    d.attrs["value_unit"] = "1/mm"
    d.attrs["provenance"] = json.dumps({"created": "2026-01-02T03:04:05Z", "scanner": "h5py test"})
out, _ = convert(path("attrs.h5"), path("attrs.ivol"))
size, origin, unit, m = geometry_of(path("attrs.ivol"))
check("h5py attributes: voxel size (z, y, x) -> (x, y, z)", close(size, [0.1, 0.2, 0.3]), size)
check("h5py attributes: origin", close(origin, [-1.0, -2.0, -3.0]), origin)
check("h5py attributes: quantity and value unit",
      m["value"].get("quantity") == "linear_attenuation" and m["value"].get("unit") == "1/mm", m["value"])
check("h5py attributes: provenance kept", m["provenance"].get("derived_from") ==
      {"created": "2026-01-02T03:04:05Z", "scanner": "h5py test"}, m["provenance"])
check("h5py attributes: summary", "(from HDF5 attribute voxel_size)" in out and
      "values: linear_attenuation in 1/mm (from HDF5 attributes quantity, value_unit)" in out, out)

with h5py.File(path("dxchange.h5"), "w") as f:
    f.create_dataset("/exchange/data", data=volume)
    x = f.create_dataset("/measurement/instrument/detector/actual_pixel_size_x", data=1.3)
    x.attrs["units"] = "microns"
    y = f.create_dataset("/measurement/instrument/detector/actual_pixel_size_y", data=1.5)
    y.attrs["units"] = "microns"
out, _ = convert(path("dxchange.h5"), path("dxchange.ivol"))
size, _, unit, _ = geometry_of(path("dxchange.ivol"))
check("DXchange actual_pixel_size_x/_y in microns", close(size, [0.0013, 0.0013, 0.0015]) and unit == "mm",
      (size, unit))
check("DXchange summary", "(from DXchange /measurement/instrument/detector/actual_pixel_size_x" in out, out)

with h5py.File(path("dxchange_m.h5"), "w") as f:
    f.create_dataset("/exchange/data", data=volume)
    f.create_dataset("/measurement/instrument/detector/actual_pixel_size_x", data=2e-6)
convert(path("dxchange_m.h5"), path("dxchange_m.ivol"))
size, _, unit, _ = geometry_of(path("dxchange_m.ivol"))
check("DXchange without units: metres", close(size, [0.002, 0.002, 0.002]) and unit == "mm", (size, unit))

grid = vdb.FloatGrid(0.0)
grid.copyFromArray(volume.astype(np.float32).transpose(2, 1, 0).copy())  # pyopenvdb indexes [x][y][z]
grid.transform = vdb.createLinearTransform([[0.5, 0, 0, 0], [0, 0.25, 0, 0], [0, 0, 2, 0], [1, 2, 3, 1]])
grid.name = "density"
grid["unit"] = "um"
grid["quantity"] = "density"
grid["value_unit"] = "g/cm3"
vdb.write(path("pyopenvdb.vdb"), grids=[grid])
out, _ = convert(path("pyopenvdb.vdb"), path("pyopenvdb.ivol"))
size, origin, unit, m = geometry_of(path("pyopenvdb.ivol"))
check("pyopenvdb: transform scale", close(size, [0.5, 0.25, 2.0]), size)
check("pyopenvdb: transform translation", close(origin, [1.0, 2.0, 3.0]), origin)
check("pyopenvdb: unit, quantity, value unit metadata",
      unit == "um" and m["value"].get("quantity") == "density" and m["value"].get("unit") == "g/cm3", m)

# --- ivol's outputs, read by others -----------------------------------------

volume.astype(np.float32).tofile(path("base.raw"))
convert(path("base.raw"), path("base.ivol"), "--dims", "7,6,5", "--type", "f32", "--voxel-size", "0.05,0.06,0.07",
        "--origin", "1,2,3", "--unit", "mm", "--quantity", "linear_attenuation", "--value-unit", "1/mm")
base_size, base_origin, base_unit, base = geometry_of(path("base.ivol"))
check("base: options recorded", close(base_size, [0.05, 0.06, 0.07]) and close(base_origin, [1, 2, 3]), base)

convert(path("base.ivol"), path("out.tif"))
with tifffile.TiffFile(path("out.tif")) as t:
    ij = t.imagej_metadata or {}
    page = t.pages[0]
    xres = page.tags["XResolution"].value if "XResolution" in page.tags else (1, 0)
    yres = page.tags["YResolution"].value if "YResolution" in page.tags else (1, 0)
    tag = page.tags[65369].value if 65369 in page.tags else "{}"
    ours = json.loads(tag) if isinstance(tag, str) else {"not ASCII text": str(tag)}
    data = t.asarray()
check("tifffile reads ivol TIFF: ImageJ spacing and unit", ij.get("spacing") == 0.07 and ij.get("unit") == "mm", ij)
check("tifffile reads ivol TIFF: resolution is pixels per unit",
      abs(xres[1] / xres[0] - 0.05) < 1e-7 and abs(yres[1] / yres[0] - 0.06) < 1e-7, (xres, yres))
check("tifffile reads ivol TIFF: tag 65369 holds the metadata",
      close(ours.get("voxel_size", []), [0.05, 0.06, 0.07]) and close(ours.get("origin", []), [1, 2, 3]) and
      ours.get("value") == {"quantity": "linear_attenuation", "unit": "1/mm"}, ours)
check("tifffile reads ivol TIFF: samples", data.shape == (5, 6, 7) and np.array_equal(data, volume), data.shape)

# Without tag 65369 (tiffcp drops tags it does not know), the ImageJ
# description and resolution tags alone give the geometry back.
subprocess.run(["tiffcp", path("out.tif"), path("imagej_only.tif")], check=True, capture_output=True)
out, _ = convert(path("imagej_only.tif"), path("imagej_only.ivol"))
size, origin, unit, _ = geometry_of(path("imagej_only.ivol"))
check("ivol TIFF without tag 65369: ImageJ geometry", close(size, base_size, 1e-6) and
      close(origin, base_origin, 1e-6) and unit == base_unit and "(from ImageJ xorigin/yorigin/zorigin)" in out,
      (size, origin, unit, out))

convert(path("base.ivol"), path("out.h5"))
with h5py.File(path("out.h5"), "r") as f:
    d = f["/exchange/data"]
    attrs = {k: d.attrs[k] for k in d.attrs}
check("h5py reads ivol HDF5: voxel_size (z, y, x)", close(list(attrs.get("voxel_size", [])), [0.07, 0.06, 0.05]), attrs)
check("h5py reads ivol HDF5: origin (z, y, x)", close(list(attrs.get("origin", [])), [3, 2, 1]), attrs)
check("h5py reads ivol HDF5: unit, quantity, value_unit",
      attrs.get("unit") == "mm" and attrs.get("quantity") == "linear_attenuation" and
      attrs.get("value_unit") == "1/mm", attrs)
check("h5py reads ivol HDF5: provenance JSON",
      json.loads(attrs.get("provenance", "{}")).get("derived_from") == base["provenance"], attrs.get("provenance"))

convert(path("base.ivol"), path("out.vdb"))
grids, _ = vdb.readAll(path("out.vdb"))
g = grids[0]
check("pyopenvdb reads ivol VDB: voxel size", close(list(g.transform.voxelSize()), [0.05, 0.06, 0.07]),
      g.transform.voxelSize())
check("pyopenvdb reads ivol VDB: origin", close(list(g.transform.indexToWorld((0, 0, 0))), [1, 2, 3]),
      g.transform.indexToWorld((0, 0, 0)))
check("pyopenvdb reads ivol VDB: metadata",
      g.metadata.get("unit") == "mm" and g.metadata.get("quantity") == "linear_attenuation" and
      g.metadata.get("value_unit") == "1/mm" and
      json.loads(g.metadata.get("provenance", "{}")).get("derived_from") == base["provenance"], g.metadata)

# --- Round trips -------------------------------------------------------------

for ext in ("h5", "tif", "vdb"):
    convert(path("out." + ext), path("back_%s.ivol" % ext))
    size, origin, unit, m = geometry_of(path("back_%s.ivol" % ext))
    name = ".ivol -> .%s -> .ivol" % ext
    check(name + ": voxel size, origin, unit",
          close(size, base_size) and close(origin, base_origin) and unit == base_unit, (size, origin, unit))
    check(name + ": quantity and value unit", m["value"] == base["value"], m["value"])
    p = m["provenance"]
    check(name + ": provenance kept", p.get("derived_from", {}).get("derived_from") == base["provenance"], p)
    check(name + ": both conversions recorded", p["sources"][0]["format"] in ("hdf5", "tiff", "vdb") and
          p["derived_from"]["sources"][0]["format"] == "ivol", p)

# An unknown voxel size stays unknown through a round trip.
convert(path("base.raw"), path("unknown.ivol"), "--dims", "7,6,5", "--type", "f32")
convert(path("unknown.ivol"), path("unknown.tif"))
with tifffile.TiffFile(path("unknown.tif")) as t:
    ij = t.imagej_metadata or {}
    has_resolution = "XResolution" in t.pages[0].tags
check("unknown voxel size: the TIFF claims none", "spacing" not in ij and "unit" not in ij and not has_resolution,
      ij)
out, err = convert(path("unknown.tif"), path("unknown_back.ivol"))
_, _, unit, m = geometry_of(path("unknown_back.ivol"))
check("unknown voxel size: still unknown after .tif",
      unit == "pixel" and m["provenance"].get("voxel_size_known") is False and "gives no voxel size" in err, m)
convert(path("unknown.ivol"), path("unknown.vdb"))
convert(path("unknown.vdb"), path("unknown_vdb.ivol"))
_, _, unit, m = geometry_of(path("unknown_vdb.ivol"))
check("unknown voxel size: still unknown after .vdb",
      unit == "pixel" and m["provenance"].get("voxel_size_known") is False, m)

# --- Explicit options win ----------------------------------------------------

out, _ = convert(path("attrs.h5"), path("override.ivol"), "--voxel-size", "0.25", "--origin", "9,8,7", "--unit", "um",
                 "--quantity", "density", "--value-unit", "g/cm3")
size, origin, unit, m = geometry_of(path("override.ivol"))
check("override HDF5 attributes", close(size, [0.25] * 3) and close(origin, [9, 8, 7]) and unit == "um" and
      m["value"] == {"quantity": "density", "unit": "g/cm3"}, m)
check("override summary", "(from --voxel-size)" in out and "(from --origin)" in out and "(from --unit)" in out and
      "values: density in g/cm3 (from --quantity, --value-unit)" in out, out)
convert(path("pyopenvdb.vdb"), path("override_vdb.ivol"), "--voxel-size", "0.125,0.25,0.5", "--origin", "0,0,0")
size, origin, _, _ = geometry_of(path("override_vdb.ivol"))
check("override OpenVDB transform", close(size, [0.125, 0.25, 0.5]) and close(origin, [0, 0, 0]), (size, origin))
convert(path("ome.tif"), path("override_ome.ivol"), "--voxel-size", "1,2,3")
size, _, _, _ = geometry_of(path("override_ome.ivol"))
check("override OME PhysicalSize", close(size, [1, 2, 3]), size)
convert(path("base.ivol"), path("override.h5"), "--voxel-size", "0.5", "--unit", "um")
with h5py.File(path("override.h5"), "r") as f:
    attrs = dict(f["/exchange/data"].attrs)
check("override on export to HDF5", close(list(attrs["voxel_size"]), [0.5] * 3) and attrs["unit"] == "um", attrs)

print("%d failed" % len(failures))
sys.exit(1 if failures else 0)
