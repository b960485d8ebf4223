#!/usr/bin/env python3
"""RTK (Reconstruction Toolkit) side of the ivol FDK benchmark.

Runs RTK's CPU FDK (rtk.FDKConeBeamReconstructionFilter) on raw float32
projections, times it, and writes the volume in *our* axis order.  It can also
produce RTK's own Shepp-Logan projections and voxelised reference, to
cross-check our analytic projector and our reconstruction.

Install:  python3 -m pip install itk-rtk==2.7.0.post1   (pulls itk 5.4.7, numpy)

Coordinate systems
------------------
RTK: rotation axis = RTK y.  Gantry angle t (degrees) puts the source at
  (sid*sin t, 0, sid*cos t) (t=0: source on +z, t=90: source on +x); the
  detector plane is at distance sdd-sid on the other side; detector column
  (u) direction = (cos t, 0, -sin t), row (v) direction = +y.
Ours: rotation axis = our Z, and
  our X = RTK x,  our Y = -RTK z,  our Z = RTK y.
  So the source is at sid*(sin t, -cos t, 0) in our frame (t=0: source on -Y,
  t=90: on +X; increasing t turns the source counter-clockwise seen from +Z),
  detector columns run along (cos t, sin t, 0) and detector rows along +Z.

Projections (input and --shepp-logan-projections output): raw little-endian
  float32 line integrals, C order views x rows x columns (column fastest).
  They are handed to RTK unchanged as an image of size (columns, rows, views),
  spacing (pitch, pitch, 1), origin (-(columns-1)/2*pitch, -(rows-1)/2*pitch, 0),
  i.e. detector pixel (c, r) sits at u = (c-(columns-1)/2)*pitch,
  v = (r-(rows-1)/2)*pitch in RTK's projection coordinates.
Geometry (when no --geometry XML): for i in 0..views-1,
  AddProjection(sid, sdd, first + i*arc/views, proj_offset_x, proj_offset_y)
  exactly like rtksimulatedgeometry.  RTK's ProjectionOffsetX/Y *move the
  detector* (not the source) within the rotated detector plane: projection
  coordinate (u,v)=(0,0) lies at (offx, offy) in the rotated frame, so the
  central ray (source->isocentre) hits u=-offx, v=-offy.  (SourceOffsetX/Y,
  XML only here, move the source and leave the detector where it is.)
Volume: RTK image of size (NX, NZ, NY) / spacing (sx, sz, sy) with centred
  origin; the output file is written in OUR order: our x fastest, then our y,
  then our z, i.e. out[z, y, x] = rtk[k = NY-1-y, j = z, i = x]
  (numpy: rtk_arr[::-1, :, :].transpose(1, 0, 2), rtk_arr being ITK's
  [k, j, i] view).  Voxel (x, y, z) of the output is centred at
  ((x-(NX-1)/2)*sx, (y-(NY-1)/2)*sy, (z-(NZ-1)/2)*sz) in our frame.

Ramp filter / --window (RTK's FFTRampImageFilter): the ramp is the discrete
  Kak & Slaney spatial-domain kernel (band-limited "Ram-Lak"), applied via FFT
  after zero-padding each row to >= 2x columns (rounded up to a power of 2 in
  the PyPI wheels, which use ITK's VNL FFT).  Apodisations multiply the
  kernel's DFT over frequencies f in [0, fc) and zero it above fc,
  fc = --cut * Nyquist:
    ram-lak     -> no window (all Set*CutFrequency left at 0)
    hann        -> SetHannCutFrequency(cut):      0.5*(1+cos(pi f/fc))
    cosine      -> SetCosineCutFrequency(cut):    cos(pi/2 f/fc)
    hamming     -> SetHammingFrequency(cut):      0.54+0.46 cos(pi f/fc)
    shepp-logan -> SetSheppLoganCutFrequency(cut): sinc(pi/2 f/fc)
  --truncation-pad maps to SetTruncationCorrection (0 = off, default).

Timing: "read_seconds" = reading the raw file + wrapping it as an ITK image;
  "fdk_seconds" = feldkamp.Update() (displaced-detector weighting if asked,
  Parker weights if --short-scan, cosine/angular weights, ramp, backprojection)
  -- this is the figure to compare against (with --repeat N: the minimum of
  N runs, each preceded by fdk.Modified(); the first run is not slower in
  practice since ITK/RTK modules are loaded before timing starts).  gups = voxels*views/fdk_seconds/1e9.
  The JSON line is printed to stdout.

Examples
  # RTK Shepp-Logan projections + reference volume for a 64-view circular scan
  python3 rtk_fdk.py --columns 96 --rows 96 --views 64 --pitch 2 \
      --sid 500 --sdd 1000 --arc-deg 360 --first-angle-deg 0 \
      --size 64 --spacing 2 --phantom-scale 50 \
      --shepp-logan-projections sl_proj.raw --draw-shepp-logan sl_ref.raw
  # reconstruct them
  python3 rtk_fdk.py --projections sl_proj.raw --columns 96 --rows 96 --views 64 \
      --pitch 2 --sid 500 --sdd 1000 --arc-deg 360 --first-angle-deg 0 \
      --size 64 --spacing 2 --threads 2 --output rtk_vol.raw
"""

import argparse
import importlib.metadata
import json
import sys
import time

import numpy as np


def parse_args(argv=None):
    p = argparse.ArgumentParser(
        description="RTK CPU FDK benchmark / Shepp-Logan reference generator "
        "(see module docstring for axis conventions)",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    g = p.add_argument_group("projections")
    g.add_argument("--projections", help="raw float32 LE line integrals, views x rows x columns")
    g.add_argument("--columns", type=int, required=True)
    g.add_argument("--rows", type=int, required=True)
    g.add_argument("--views", type=int, help="number of views (default: from --geometry)")
    g.add_argument("--pitch", type=float, required=True, help="detector pixel pitch (mm, square)")

    g = p.add_argument_group("geometry (XML, or a uniform circular scan)")
    g.add_argument("--geometry", help="RTK ThreeDCircularProjectionGeometry XML file")
    g.add_argument("--sid", type=float, help="source-isocentre distance (mm)")
    g.add_argument("--sdd", type=float, help="source-detector distance (mm)")
    g.add_argument("--arc-deg", type=float, default=360.0)
    g.add_argument("--first-angle-deg", type=float, default=0.0)
    g.add_argument("--proj-offset-x", type=float, default=0.0,
                   help="RTK ProjectionOffsetX (mm, detector shift along columns)")
    g.add_argument("--proj-offset-y", type=float, default=0.0,
                   help="RTK ProjectionOffsetY (mm, detector shift along rows)")
    g.add_argument("--write-geometry", help="also write the RTK geometry used to this XML file")

    g = p.add_argument_group("volume (our axes)")
    g.add_argument("--size", type=int, nargs="+", default=[256],
                   help="N (cube) or NX NY NZ in our axes")
    g.add_argument("--spacing", type=float, nargs="+", default=[1.0],
                   help="mm, one value or SX SY SZ in our axes")

    g = p.add_argument_group("reconstruction")
    g.add_argument("--threads", type=int, default=2,
                   help="ITK global default number of threads")
    g.add_argument("--window", default="ram-lak",
                   choices=["ram-lak", "hann", "cosine", "hamming", "shepp-logan"])
    g.add_argument("--cut", type=float, default=1.0,
                   help="window cut-off as a fraction of Nyquist, in ]0,1]")
    g.add_argument("--truncation-pad", type=float, default=0.0,
                   help="RTK ramp TruncationCorrection (fraction of width mirrored)")
    g.add_argument("--short-scan", action="store_true",
                   help="apply rtk.ParkerShortScanImageFilter")
    g.add_argument("--displaced-detector", action="store_true",
                   help="apply rtk.DisplacedDetectorForOffsetFieldOfViewImageFilter (as rtkfdk does)")
    g.add_argument("--subset-size", type=int, default=16,
                   help="FDK ProjectionSubsetSize (projections filtered+backprojected per pass)")
    g.add_argument("--repeat", type=int, default=1,
                   help="run the FDK update this many times (Modified() in between); "
                   "fdk_seconds is the minimum, fdk_seconds_all lists all")
    g.add_argument("--output", help="raw float32 volume, our axis order (x fastest)")

    g = p.add_argument_group("Shepp-Logan references")
    g.add_argument("--phantom-scale", type=float, nargs="+", default=[128.0],
                   help="RTK PhantomScale (mm; one value or RTK x y z)")
    g.add_argument("--shepp-logan-projections",
                   help="write RTK SheppLoganPhantomFilter projections here (views x rows x columns)")
    g.add_argument("--draw-shepp-logan",
                   help="write RTK DrawSheppLoganFilter volume here (our axis order)")
    a = p.parse_args(argv)

    if len(a.size) == 1:
        a.size = a.size * 3
    if len(a.spacing) == 1:
        a.spacing = a.spacing * 3
    if len(a.size) != 3 or len(a.spacing) != 3:
        p.error("--size / --spacing take 1 or 3 values")
    if len(a.phantom_scale) == 1:
        a.phantom_scale = a.phantom_scale * 3
    if a.geometry is None and (a.sid is None or a.sdd is None or a.views is None):
        p.error("give --geometry, or --sid, --sdd and --views")
    if not (a.projections or a.shepp_logan_projections or a.draw_shepp_logan):
        p.error("nothing to do: give --projections and/or a Shepp-Logan output")
    if a.projections and not a.output:
        p.error("--projections needs --output")
    if not (0.0 < a.cut <= 1.0):
        p.error("--cut must be in ]0,1]")
    return a


def main(argv=None):
    args = parse_args(argv)

    t0 = time.perf_counter()
    import itk
    from itk import RTK as rtk
    import_seconds = time.perf_counter() - t0

    itk.MultiThreaderBase.SetGlobalDefaultNumberOfThreads(args.threads)
    ImageType = itk.Image[itk.F, 3]

    # ---- geometry --------------------------------------------------------
    if args.geometry:
        geometry = rtk.read_geometry(args.geometry)
        nviews = len(geometry.GetGantryAngles())
        if args.views is not None and args.views != nviews:
            sys.exit(f"--views {args.views} but {args.geometry} has {nviews} projections")
    else:
        nviews = args.views
        geometry = rtk.ThreeDCircularProjectionGeometry.New()
        for i in range(nviews):
            angle = args.first_angle_deg + i * args.arc_deg / nviews
            geometry.AddProjection(args.sid, args.sdd, angle,
                                   args.proj_offset_x, args.proj_offset_y)
    if args.write_geometry:
        rtk.write_geometry(geometry, args.write_geometry)

    ncol, nrow, pitch = args.columns, args.rows, args.pitch
    proj_origin = [-(ncol - 1) / 2.0 * pitch, -(nrow - 1) / 2.0 * pitch, 0.0]
    proj_spacing = [pitch, pitch, 1.0]

    # ---- volume (RTK axes: x = our X, y = our Z, z = -our Y) -------------
    nx, ny, nz = args.size
    sx, sy, sz = args.spacing
    rtk_size = [nx, nz, ny]
    rtk_spacing = [sx, sz, sy]
    rtk_origin = [-(n - 1) / 2.0 * s for n, s in zip(rtk_size, rtk_spacing)]

    def constant(size, spacing, origin):
        src = rtk.ConstantImageSource[ImageType].New()
        src.SetSize(size)
        src.SetSpacing(spacing)
        src.SetOrigin(origin)
        src.SetConstant(0.0)
        return src

    def to_our_order(img):
        a = itk.array_view_from_image(img)          # [k(z_rtk), j(y_rtk), i(x)]
        return np.ascontiguousarray(a[::-1, :, :].transpose(1, 0, 2), dtype="<f4")

    info = {}

    # ---- Shepp-Logan references -------------------------------------------
    if args.shepp_logan_projections:
        t = time.perf_counter()
        src = constant([ncol, nrow, nviews], proj_spacing, proj_origin)
        slp = rtk.SheppLoganPhantomFilter[ImageType, ImageType].New()
        slp.SetInput(src.GetOutput())
        slp.SetGeometry(geometry)
        slp.SetPhantomScale(args.phantom_scale)
        slp.Update()
        itk.array_view_from_image(slp.GetOutput()).astype("<f4").tofile(args.shepp_logan_projections)
        info["shepp_logan_projection_seconds"] = time.perf_counter() - t
    if args.draw_shepp_logan:
        t = time.perf_counter()
        src = constant(rtk_size, rtk_spacing, rtk_origin)
        dsl = rtk.DrawSheppLoganFilter[ImageType, ImageType].New()
        dsl.SetInput(src.GetOutput())
        dsl.SetPhantomScale(args.phantom_scale)
        dsl.Update()
        to_our_order(dsl.GetOutput()).tofile(args.draw_shepp_logan)
        info["draw_shepp_logan_seconds"] = time.perf_counter() - t

    if not args.projections:
        if info:
            print(json.dumps(info))
        return

    # ---- (a) read projections ---------------------------------------------
    t = time.perf_counter()
    proj = np.fromfile(args.projections, dtype="<f4")
    if proj.size != nviews * nrow * ncol:
        sys.exit(f"{args.projections}: {proj.size} floats, expected "
                 f"{nviews}x{nrow}x{ncol} = {nviews * nrow * ncol}")
    proj = proj.reshape(nviews, nrow, ncol).astype(np.float32, copy=False)
    proj_img = itk.image_view_from_array(proj)      # size (ncol, nrow, nviews), no copy
    proj_img.SetSpacing(proj_spacing)
    proj_img.SetOrigin(proj_origin)
    read_seconds = time.perf_counter() - t

    # ---- (b) FDK ------------------------------------------------------------
    pipeline_in = proj_img
    keep = []  # keep filters alive
    if args.displaced_detector:
        ddf = rtk.DisplacedDetectorForOffsetFieldOfViewImageFilter[ImageType].New()
        ddf.SetInput(pipeline_in)
        ddf.SetGeometry(geometry)
        keep.append(ddf)
        pipeline_in = ddf.GetOutput()
    if args.short_scan:
        pssf = rtk.ParkerShortScanImageFilter[ImageType].New()
        pssf.SetInput(pipeline_in)
        pssf.SetGeometry(geometry)
        pssf.InPlaceOff()
        keep.append(pssf)
        pipeline_in = pssf.GetOutput()

    vol_src = constant(rtk_size, rtk_spacing, rtk_origin)
    vol_src.Update()
    fdk = rtk.FDKConeBeamReconstructionFilter[ImageType].New()
    fdk.SetInput(0, vol_src.GetOutput())
    fdk.SetInput(1, pipeline_in)
    fdk.SetGeometry(geometry)
    fdk.SetProjectionSubsetSize(args.subset_size)
    ramp = fdk.GetRampFilter()
    ramp.SetTruncationCorrection(args.truncation_pad)
    setter = {
        "ram-lak": None,
        "hann": ramp.SetHannCutFrequency,
        "cosine": ramp.SetCosineCutFrequency,
        "hamming": ramp.SetHammingFrequency,
        "shepp-logan": ramp.SetSheppLoganCutFrequency,
    }[args.window]
    if setter is not None:
        setter(args.cut)

    fdk_all = []
    for _ in range(max(1, args.repeat)):
        fdk.Modified()
        t = time.perf_counter()
        fdk.Update()
        fdk_all.append(time.perf_counter() - t)
    fdk_seconds = min(fdk_all)

    t = time.perf_counter()
    to_our_order(fdk.GetOutput()).tofile(args.output)
    write_seconds = time.perf_counter() - t

    voxels = nx * ny * nz
    result = {
        "rtk_version": importlib.metadata.version("itk-rtk"),
        "itk_version": itk.Version.GetITKVersion(),
        "threads": args.threads,
        "fdk_seconds": fdk_seconds,
        "voxels": voxels,
        "views": nviews,
        "gups": voxels * nviews / fdk_seconds / 1e9,
        "fdk_seconds_all": fdk_all,
        "read_seconds": read_seconds,
        "write_seconds": write_seconds,
        "import_seconds": import_seconds,
        "size": [nx, ny, nz],
        "spacing": [sx, sy, sz],
        "detector": [ncol, nrow],
        "window": args.window,
        "short_scan": args.short_scan,
    }
    result.update(info)
    print(json.dumps(result))


if __name__ == "__main__":
    main()
