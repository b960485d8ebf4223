#!/usr/bin/env python3
"""Issue 18, item 2: where the time of `ivol recon` goes, dense against
--structure octree, for one or more ivol binaries side by side on the same
scans (each scan written by `ivol phantom` as HDF5, read back through the
CLI's own path: libhdf5 in its child process).

    python3 bench/recon_stages.py --ivol NAME=PATH [--ivol NAME=PATH ...]
        --work DIR [--phantom NAME ...] [--size 256] [--views 360]
        [--detector 384] [--repeat 1]

Prints, per phantom and binary, the stages of `recon --json` (seconds) and
the speedup of the octree over the dense run of the same binary against
the voxel reduction. Runs alternate between the binaries so that load
drifts hit them alike.
"""

import argparse
import json
import os
import subprocess

STAGES = ("preview", "generation", "reading", "filtering", "backprojection", "writing", "total")


def recon(ivol, scan, out, size, structure):
    args = [ivol, "recon", scan + ".h5", "--geometry", scan + ".xml", "--pitch", str(PITCH), "--size", str(size),
            "--voxel", str(FOV / size), "--json", "-o", out, "-f"]
    if structure:
        args += ["--structure", "octree"]
    done = subprocess.run(args, capture_output=True, text=True, check=True)
    return json.loads(done.stdout)


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--ivol", action="append", required=True, help="NAME=PATH of an ivol binary")
    p.add_argument("--work", required=True)
    p.add_argument("--phantom", action="append")
    p.add_argument("--size", type=int, default=256)
    p.add_argument("--views", type=int, default=360)
    p.add_argument("--detector", type=int, default=384)
    p.add_argument("--repeat", type=int, default=1)
    a = p.parse_args()
    binaries = [tuple(x.split("=", 1)) for x in a.ivol]
    phantoms = a.phantom or ["pencil-holder", "connector-board", "computer-board", "thin-pipe", "lattice-part",
                             "fine-wires"]
    os.makedirs(a.work, exist_ok=True)
    global PITCH, FOV
    # The field ivol phantom sizes its objects to (radius 100 mm) on the
    # grid, and a pitch that shows it whole (as in "Lossless peers").
    FOV = 200.0
    PITCH = 1.1979 * 384 / a.detector
    print(f"{'phantom':<16} {'binary':<8} {'run':<7}" + "".join(f"{s:>15}" for s in STAGES) +
          f"{'reduction':>11}{'speedup':>9}{'ratio':>7}")
    for phantom in phantoms:
        scan = os.path.join(a.work, phantom)
        if not os.path.exists(scan + ".h5"):
            subprocess.run([binaries[0][1], "-q", "phantom", phantom, "-o", scan + ".h5", "--views", str(a.views),
                            "--detector", str(a.detector), "--pitch", str(PITCH)], check=True)
        results = {}
        for _ in range(a.repeat):
            for name, ivol in binaries:
                for structure in (False, True):
                    r = recon(ivol, scan, os.path.join(a.work, "out.ivol"), a.size, structure)
                    key = (name, structure)
                    best = results.get(key)
                    if best is None or r["seconds"]["total"] < best["seconds"]["total"]:
                        results[key] = r
        for name, _ in binaries:
            dense, octree = results[(name, False)], results[(name, True)]
            for label, r in (("dense", dense), ("octree", octree)):
                line = f"{phantom:<16} {name:<8} {label:<7}" + "".join(
                    f"{r['seconds'].get(s, 0.0):15.2f}" for s in STAGES)
                if label == "octree":
                    reduction = r["voxel_reduction"]
                    speedup = dense["seconds"]["total"] / r["seconds"]["total"]
                    line += f"{reduction:11.1f}{speedup:9.2f}{speedup / reduction:7.3f}"
                print(line, flush=True)


if __name__ == "__main__":
    main()
