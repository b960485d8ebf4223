#!/usr/bin/env python3
"""End-to-end self-check of rtk_fdk.py at small size (~20 s on 2 cores).

1. RTK Shepp-Logan projections + drawn reference (rtk_fdk.py).
2. Independent numpy check of the conventions documented in rtk_fdk.py:
   the phantom voxelised in OUR frame must equal RTK's drawn volume, and
   analytic line integrals computed with OUR-frame source/detector formulas
   must equal RTK's projections (also with a projection offset).
3. RTK FDK of those projections; MAE against the reference.

Usage: python3 check_rtk.py [WORKDIR]   (default: a temporary directory)
Exit status 0 when every check passes.
"""

import json
import os
import subprocess
import sys
import tempfile

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
N, SP, SCALE = 64, 1.25, 40.0
SID, SDD, PITCH, NC, NR, NV = 500.0, 1000.0, 2.0, 96, 96, 64
FIRST, OFFX, OFFY = 30.0, 10.0, -6.0

# RTK's 3D Shepp-Logan (rtkSheppLoganPhantom.cxx), RTK coordinates, before
# PhantomScale: semi-axes (ax, ay, az), centre (cx, cy, cz), angle (deg,
# rotation about RTK y taking the shape's x axis towards +z), density (added).
RTK_SL = [
    (0.69, 0.90, 0.92, 0, 0, 0, 0, 2.0),
    (0.6624, 0.880, 0.874, 0, 0, 0, 0, -0.98),
    (0.41, 0.21, 0.16, -0.22, -0.25, 0, 108, -0.02),
    (0.31, 0.22, 0.11, 0.22, -0.25, 0, 72, -0.02),
    (0.21, 0.50, 0.25, 0, -0.25, 0.35, 0, 0.02),
    (0.046, 0.046, 0.046, 0, -0.25, 0.10, 0, 0.02),
    (0.046, 0.02, 0.023, -0.08, -0.25, -0.65, 0, 0.01),
    (0.046, 0.02, 0.023, 0.06, -0.25, -0.65, 90, 0.01),
    (0.056, 0.1, 0.04, 0.06, 0.625, -0.105, 90, 0.02),
    (0.056, 0.1, 0.056, 0, 0.625, 0.1, 0, -0.02),
]


def sl_in_our_frame(scale):
    """Ellipsoids as (centre, unit axes as rows, semi-axes, density) in OUR frame
    (X = RTK x, Y = -RTK z, Z = RTK y)."""
    out = []
    for ax, ay, az, cx, cy, cz, ang, d in RTK_SL:
        a = np.deg2rad(ang)
        centre = np.array([cx, -cz, cy]) * scale
        axes = np.array([[np.cos(a), -np.sin(a), 0.0],
                         [-np.sin(a), -np.cos(a), 0.0],
                         [0.0, 0.0, 1.0]])
        out.append((centre, axes, np.array([ax, az, ay]) * scale, d))
    return out


def analytic_projection(ell, angle_deg, offx, offy):
    t = np.deg2rad(angle_deg)
    radial = np.array([np.sin(t), -np.cos(t), 0.0])
    src = SID * radial
    eu, ev = np.array([np.cos(t), np.sin(t), 0.0]), np.array([0.0, 0.0, 1.0])
    u = (np.arange(NC) - (NC - 1) / 2) * PITCH + offx
    v = (np.arange(NR) - (NR - 1) / 2) * PITCH + offy
    V, U = np.meshgrid(v, u, indexing="ij")
    det = -(SDD - SID) * radial + U[..., None] * eu + V[..., None] * ev
    r = det - src
    r /= np.linalg.norm(r, axis=-1, keepdims=True)
    p = np.zeros((NR, NC))
    for c, axes, semi, d in ell:
        o = ((src - c) @ axes.T) / semi
        w = (r @ axes.T) / semi
        qa, qb, qc = (w * w).sum(-1), 2 * (o * w).sum(-1), (o * o).sum() - 1
        p += d * np.sqrt(np.maximum(qb * qb - 4 * qa * qc, 0)) / qa
    return p


def run(args):
    out = subprocess.run([sys.executable, os.path.join(HERE, "rtk_fdk.py")] + args,
                         check=True, capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def main():
    wd = sys.argv[1] if len(sys.argv) > 1 else tempfile.mkdtemp(prefix="rtkcheck")
    os.makedirs(wd, exist_ok=True)
    f = lambda n: os.path.join(wd, n)
    geo = ["--columns", str(NC), "--rows", str(NR), "--views", str(NV), "--pitch", str(PITCH),
           "--sid", str(SID), "--sdd", str(SDD), "--arc-deg", "360",
           "--first-angle-deg", str(FIRST), "--proj-offset-x", str(OFFX),
           "--proj-offset-y", str(OFFY), "--size", str(N), "--spacing", str(SP)]
    ok = True

    run(geo + ["--phantom-scale", str(SCALE), "--shepp-logan-projections", f("sl_proj.raw"),
               "--draw-shepp-logan", f("sl_ref.raw")])
    ref = np.fromfile(f("sl_ref.raw"), "<f4").reshape(N, N, N)
    proj = np.fromfile(f("sl_proj.raw"), "<f4").reshape(NV, NR, NC)

    ell = sl_in_our_frame(SCALE)
    g = (np.arange(N) - (N - 1) / 2) * SP
    Z, Y, X = np.meshgrid(g, g, g, indexing="ij")
    P = np.stack([X, Y, Z], -1)
    vox = np.zeros((N, N, N))
    for c, axes, semi, d in ell:
        vox += d * (((((P - c) @ axes.T) / semi) ** 2).sum(-1) <= 1)
    bad = int((np.abs(vox - ref) > 1e-4).sum())
    print(f"drawn phantom vs our-frame voxelisation: {bad} mismatching voxels")
    ok &= bad == 0

    err = max(np.abs(analytic_projection(ell, FIRST + i * 360.0 / NV, OFFX, OFFY) - proj[i]).max()
              for i in (0, 5, 16, 37))
    print(f"RTK projections vs our-frame analytic line integrals: max |diff| {err:.2e} "
          f"(max value {proj.max():.1f})")
    ok &= err < 1e-3

    res = run(["--projections", f("sl_proj.raw")] + geo + ["--output", f("rtk_vol.raw")])
    rec = np.fromfile(f("rtk_vol.raw"), "<f4").reshape(N, N, N)
    c = slice(N // 4, 3 * N // 4)
    mae = float(np.abs(rec[c, c, c] - ref[c, c, c]).mean())
    print(f"FDK central half-cube MAE {mae:.4f} (phantom brain density 1.02); "
          f"fdk {res['fdk_seconds']:.3f} s, {res['gups']:.3f} GUPS, {res['threads']} threads")
    ok &= mae < 0.01
    print("PASS" if ok else "FAIL")
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
