#!/usr/bin/env python3
"""Writes the ITK-image fixtures of tests/test_itk_images.cpp and
tests/cli/run_itk_cases.sh with ITK's and NRRD's own libraries, so that ivol's
readers are checked against files it did not write.

    python3 -m venv /tmp/itk && /tmp/itk/bin/pip install SimpleITK pynrrd itk-rtk==2.7.0.post1
    /tmp/itk/bin/python tests/data/itk/make_fixtures.py tests/data/itk

Volumes (SimpleITK / pynrrd), each with the numpy array it holds as NAME.npy
(C order [z][y][x]), anisotropic spacing and an origin:
  u16.mha        MetaImage, uint16, uncompressed
  i16_z.mha      MetaImage, int16, zlib-compressed
  f32.mhd        MetaImage header + f32.raw
  u8.nrrd        NRRD (pynrrd), uint8, gzip
  i8.nrrd        NRRD (pynrrd), int8, raw
  f32_be.nhdr    NRRD detached header + f32_be.raw, big-endian float32
  u16_itk.h5     ITK's HDF5 image layout, the values of u16.npy
  rotated_itk.h5 the same with a direction that is not the identity
  rotated.mha    a direction that is not the identity (must be refused)
RTK (itk-rtk 2.7): rtk/proj.mha, Shepp-Logan line integrals of 24 views of
40x30 pixels, pitch 1.5 x 1.25 mm, projection origin off centre by (+3, -2)
mm, zlib-compressed; rtk/geometry.xml; rtk/fdk.npy, RTK's FDK of them
(ramp filter, 24^3 voxels of 1.6 mm) in ivol's axis order [z][y][x]
(bench/rtk/rtk_fdk.py explains the axes).
"""
import os
import sys

import numpy as np
import nrrd
import SimpleITK as sitk

out = sys.argv[1]
os.makedirs(os.path.join(out, "rtk"), exist_ok=True)
rng = np.random.default_rng(20261202)
spacing = (0.5, 0.25, 2.0)
origin = (-3.5, 1.25, 10.0)
shape = (7, 10, 12)  # z, y, x


def save(name, array):
    np.save(os.path.join(out, name + ".npy"), array)


def sitk_image(array):
    image = sitk.GetImageFromArray(array)
    image.SetSpacing(spacing)
    image.SetOrigin(origin)
    return image


u16 = rng.integers(0, 65536, shape, dtype=np.uint16)
sitk.WriteImage(sitk_image(u16), os.path.join(out, "u16.mha"), useCompression=False)
save("u16", u16)
i16 = rng.integers(-32768, 32768, shape, dtype=np.int16)
i16[0, 0, :4] = [-32768, 32767, 0, -1]
sitk.WriteImage(sitk_image(i16), os.path.join(out, "i16_z.mha"), useCompression=True)
save("i16_z", i16)
f32 = rng.normal(0, 100, shape).astype(np.float32)
f32[0, 0, :3] = [np.float32(-0.0), np.inf, 1e-42]
sitk.WriteImage(sitk_image(f32), os.path.join(out, "f32.mhd"), useCompression=False)
save("f32", f32)

directions = np.diag(spacing)
header = {"space dimension": 3, "space directions": directions, "space origin": np.array(origin),
          "space units": ["mm", "mm", "mm"], "kinds": ["domain"] * 3}
u8 = rng.integers(0, 256, shape, dtype=np.uint8)
nrrd.write(os.path.join(out, "u8.nrrd"), u8, dict(header, encoding="gzip"), index_order="C")
save("u8", u8)
i8 = rng.integers(-128, 128, shape, dtype=np.int8)
nrrd.write(os.path.join(out, "i8.nrrd"), i8, dict(header, encoding="raw"), index_order="C")
save("i8", i8)
f32be = rng.normal(0, 1, shape).astype(">f4")
nrrd.write(os.path.join(out, "f32_be.nhdr"), f32be, dict(header, encoding="raw", endian="big"),
           detached_header=True, index_order="C")
save("f32_be", f32be.astype("<f4"))

rotated = sitk_image(u16)
rotated.SetDirection((0, 1, 0, 1, 0, 0, 0, 0, 1))
sitk.WriteImage(rotated, os.path.join(out, "rotated.mha"))
# ITK's own HDF5 layout (HDF5ImageIO): /ITKImage/0/VoxelData with Spacing,
# Origin and Directions beside it.
sitk.WriteImage(sitk_image(u16), os.path.join(out, "u16_itk.h5"))
sitk.WriteImage(rotated, os.path.join(out, "rotated_itk.h5"))

# ---- RTK ------------------------------------------------------------------
import itk
from itk import RTK as rtk

itk.MultiThreaderBase.SetGlobalDefaultNumberOfThreads(2)
Image = itk.Image[itk.F, 3]
views, columns, rows = 24, 40, 30
pitch = (1.5, 1.25)
proj_origin = [-(columns - 1) / 2 * pitch[0] + 3.0, -(rows - 1) / 2 * pitch[1] - 2.0, 0.0]
geometry = rtk.ThreeDCircularProjectionGeometry.New()
for i in range(views):
    geometry.AddProjection(100.0, 180.0, i * 360.0 / views, 0.0, 0.0)
rtk.write_geometry(geometry, os.path.join(out, "rtk", "geometry.xml"))


def constant(size, spacing_, origin_):
    source = rtk.ConstantImageSource[Image].New()
    source.SetSize(size)
    source.SetSpacing(spacing_)
    source.SetOrigin(origin_)
    source.SetConstant(0.0)
    return source


projections_source = constant([columns, rows, views], [pitch[0], pitch[1], 1.0], proj_origin)
phantom = rtk.SheppLoganPhantomFilter[Image, Image].New()
phantom.SetInput(projections_source.GetOutput())
phantom.SetGeometry(geometry)
phantom.SetPhantomScale(16.0)
phantom.Update()
writer = itk.ImageFileWriter[Image].New()
writer.SetFileName(os.path.join(out, "rtk", "proj.mha"))
writer.SetInput(phantom.GetOutput())
writer.SetUseCompression(True)
writer.Update()

n, voxel = 24, 1.6
volume_origin = [-(n - 1) / 2 * voxel] * 3
volume = constant([n, n, n], [voxel] * 3, volume_origin)
# As rtkfdk does: behind the displaced-detector weighting, which acts here
# (the origin moves the detector 3 mm, over 10 % of its width between edges).
weighting = rtk.DisplacedDetectorImageFilter[Image].New()
weighting.SetInput(phantom.GetOutput())
weighting.SetGeometry(geometry)
fdk = rtk.FDKConeBeamReconstructionFilter[Image].New()
fdk.SetInput(0, volume.GetOutput())
fdk.SetInput(1, weighting.GetOutput())
fdk.SetGeometry(geometry)
fdk.Update()
rtk_array = itk.array_view_from_image(fdk.GetOutput())  # [k = -our y, j = our z, i = our x]
np.save(os.path.join(out, "rtk", "fdk.npy"), np.ascontiguousarray(rtk_array[::-1, :, :].transpose(1, 0, 2)))
print("fixtures written to", out)

# ---- RTK, displaced detector -------------------------------------------------
# rtk/displaced_*: the detector shifted 18 mm sideways (its near edge 11 mm
# from the axis at the detector, a half-fan scan), 60 views over 360°; RTK's
# FDK behind its DisplacedDetectorImageFilter, and the phantom drawn by RTK.
views = 60
geometry = rtk.ThreeDCircularProjectionGeometry.New()
for i in range(views):
    geometry.AddProjection(100.0, 180.0, i * 360.0 / views, 18.0, 0.0)
rtk.write_geometry(geometry, os.path.join(out, "rtk", "displaced_geometry.xml"))
centred_origin = [-(columns - 1) / 2 * pitch[0], -(rows - 1) / 2 * pitch[1], 0.0]
projections_source = constant([columns, rows, views], [pitch[0], pitch[1], 1.0], centred_origin)
phantom = rtk.SheppLoganPhantomFilter[Image, Image].New()
phantom.SetInput(projections_source.GetOutput())
phantom.SetGeometry(geometry)
phantom.SetPhantomScale(16.0)
phantom.Update()
writer = itk.ImageFileWriter[Image].New()
writer.SetFileName(os.path.join(out, "rtk", "displaced_proj.mha"))
writer.SetInput(phantom.GetOutput())
writer.SetUseCompression(True)
writer.Update()
weighting = rtk.DisplacedDetectorImageFilter[Image].New()
weighting.SetInput(phantom.GetOutput())
weighting.SetGeometry(geometry)
fdk = rtk.FDKConeBeamReconstructionFilter[Image].New()
fdk.SetInput(0, volume.GetOutput())
fdk.SetInput(1, weighting.GetOutput())
fdk.SetGeometry(geometry)
fdk.Update()
rtk_array = itk.array_view_from_image(fdk.GetOutput())
np.save(os.path.join(out, "rtk", "displaced_fdk.npy"), np.ascontiguousarray(rtk_array[::-1, :, :].transpose(1, 0, 2)))
draw = rtk.DrawSheppLoganFilter[Image, Image].New()
draw.SetInput(volume.GetOutput())
draw.SetPhantomScale(16.0)
draw.Update()
truth = itk.array_view_from_image(draw.GetOutput())
np.save(os.path.join(out, "rtk", "displaced_truth.npy"), np.ascontiguousarray(truth[::-1, :, :].transpose(1, 0, 2)))
print("displaced-detector fixtures written")
