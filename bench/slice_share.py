#!/usr/bin/env python3
"""Issue 20: what bricks of 16^3 cost in file size and give in a slice's
share of the bytes, on the three 512^3 phantoms.

    python3 bench/slice_share.py --work DIR [--ivol BINARY] [--phantoms A,B] [--bricks 32,16]

Per phantom: the voxelized truth (`ivol phantom NAME --truth-size 512
--encoding binary16`), plus N(0, 0.002) noise (a tenth of the plastic's
0.02 /mm) rounded to binary16 (seed 1), is the "lossless" volume (every
voxel); its "object" volume keeps the noisy values within 3 voxels of the
part (the truth above half of Otsu's threshold) and one background value
elsewhere (bench/peers_codecs.py's rule, issue 22, on the truth). Each is
converted (`ivol convert`, auto: a bricked grid) once per brick size; the
object files are read back and compared bit for bit. Prints the sizes, then
runs bench/remote_reads.sh over the object files (requests, bytes and share
of a z, y and x slice, a 64^3 box and the 1/8 preview, the open included).
"""
import argparse
import os
import subprocess
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from peers_codecs import dilate, otsu  # noqa: E402

N = 512
# The plastic parts' attenuation is 0.02 /mm in the truth: noise a tenth of it.
NOISE = 0.002


def run(*cmd):
    subprocess.run([str(c) for c in cmd], check=True)


def make_volumes(ivol, work, phantom):
    lossless = os.path.join(work, phantom + "-lossless.raw")
    obj = os.path.join(work, phantom + "-object.raw")
    if os.path.exists(lossless) and os.path.exists(obj):
        return lossless, obj
    truth = os.path.join(work, phantom + "-truth.ivol")
    run(ivol, "-q", "phantom", phantom, "-o", os.path.join(work, "scan.raw"), "--views", 1, "--detector", "8,8",
        "--supersampling", 1, "--truth", truth, "--truth-size", N, "--encoding", "binary16", "-f")
    raw = os.path.join(work, phantom + "-truth.raw")
    run(ivol, "-q", "convert", truth, raw, "--out-type", "f32", "-f")
    f = np.fromfile(raw, dtype=np.float32).reshape(N, N, N)
    os.remove(raw)
    rng = np.random.default_rng(1)
    noisy = (f + rng.normal(0, NOISE, f.shape).astype(np.float32)).astype(np.float16)
    noisy.tofile(lossless)
    # The part from the truth: the noise would move Otsu's threshold.
    keep = dilate(f > 0.5 * otsu(f[::4, ::4, ::4]), 3)
    del f
    rounded = noisy.astype(np.float32)
    background = np.float16(rounded[~keep].mean()) if (~keep).any() else np.float16(0)
    del rounded
    np.where(keep, noisy, background).astype(np.float16).tofile(obj)
    print("%s: %.1f %% of the voxels kept" % (phantom, 100 * keep.mean()), flush=True)
    return lossless, obj


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--work", required=True)
    parser.add_argument("--ivol", default=os.path.join(HERE, "..", "build", "tools", "ivol"))
    parser.add_argument("--phantoms", default="pencil-holder,connector-board,lattice-part")
    parser.add_argument("--bricks", default="32,16")
    parser.add_argument("--latency", default="0")
    args = parser.parse_args()
    os.makedirs(args.work, exist_ok=True)
    bricks = [int(b) for b in args.bricks.split(",")]
    sizes = {}
    object_files = []
    for phantom in args.phantoms.split(","):
        lossless, obj = make_volumes(args.ivol, args.work, phantom)
        for kind, raw in (("lossless", lossless), ("object", obj)):
            for b in bricks:
                out = os.path.join(args.work, "%s-%s-b%d.ivol" % (phantom, kind, b))
                run(args.ivol, "-q", "convert", raw, out, "--dims", "%d,%d,%d" % (N, N, N), "--type", "f16",
                    "--brick", b, "-f")
                sizes[phantom, kind, b] = os.path.getsize(out)
                if kind == "object":
                    back = os.path.join(args.work, "back.raw")
                    run(args.ivol, "-q", "convert", out, back, "--out-type", "f16", "-f")
                    same = np.array_equal(np.fromfile(back, dtype=np.uint16), np.fromfile(raw, dtype=np.uint16))
                    os.remove(back)
                    if not same:
                        sys.exit("%s does not read back bit for bit" % out)
                    object_files.append(out)
    head = " | ".join("bricks of %d^3" % b for b in bricks)
    print("\n| volume | %s | %s |" % (head, " | ".join("%d vs %d" % (b, bricks[0]) for b in bricks[1:])))
    print("|---|" + "---:|" * (2 * len(bricks) - 1))
    for phantom in args.phantoms.split(","):
        for kind in ("lossless", "object"):
            row = [sizes[phantom, kind, b] for b in bricks]
            ratios = ["%+.2f %%" % (100.0 * (s / row[0] - 1)) for s in row[1:]]
            print("| %s %s | %s | %s |" % (phantom, kind, " | ".join("{:,}".format(s) for s in row), " | ".join(ratios)))
    print(flush=True)
    run("bash", os.path.join(HERE, "remote_reads.sh"), "--ivol", args.ivol, "--latency", args.latency, *object_files)


if __name__ == "__main__":
    main()
