#!/usr/bin/env python3
"""recon --structure octree with 1 and N MPI ranks, for one or more ivol
binaries side by side (issue 18, item 4: each rank builds its slabs).

For every round, every binary and every rank count: one run of
`[mpirun -np N] IVOL -q recon SCAN ... --structure octree --json`, alternating,
with SOURCE_DATE_EPOCH fixed, so that the files of one binary compare with
`cmp`. Prints wall time and peak RSS (from /usr/bin/time), rank 0's seconds in
writing and building, the slab bytes it received, and each rank's voxel
updates and slabs built; then whether every file of a size is the same.

  python3 bench/distributed_structure.py --scan ph.h5 --geometry ph.xml \
      --pitch 1.163 --size 256 --voxel 0.782 --ranks 2 --rounds 2 \
      before=/tmp/before/ivol after=/tmp/after/ivol  (binaries named alike: the file records the command)
"""
import argparse
import filecmp
import json
import os
import subprocess
import sys
import tempfile


def run(binary, ranks, args, out, work):
    command = [binary, "-q", "recon", args.scan, "--geometry", args.geometry, "--pitch", str(args.pitch),
               "--size", str(args.size), "--voxel", str(args.voxel), "--structure", "octree", "--json", "-f",
               "-o", out]
    if ranks > 1:
        command = ["mpirun", "--oversubscribe", "-np", str(ranks)] + command
    timing = os.path.join(work, "time.txt")  # beside the output
    env = dict(os.environ, SOURCE_DATE_EPOCH="1700000000", OMPI_ALLOW_RUN_AS_ROOT="1",
               OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1", OMPI_MCA_btl="self,vader")
    result = subprocess.run(["/usr/bin/time", "-f", "%e %M", "-o", timing] + command, capture_output=True,
                            text=True, env=env, cwd=work, check=True)
    wall, rss = open(timing).read().split()[-2:]
    return json.loads(result.stdout), float(wall), int(rss) / 1024


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scan", required=True)
    p.add_argument("--geometry", required=True)
    p.add_argument("--pitch", type=float, required=True)
    p.add_argument("--size", type=int, required=True)
    p.add_argument("--voxel", type=float, required=True)
    p.add_argument("--ranks", type=int, default=2)
    p.add_argument("--rounds", type=int, default=1)
    p.add_argument("binaries", nargs="+", help="NAME=PATH")
    args = p.parse_args()
    args.scan, args.geometry = os.path.abspath(args.scan), os.path.abspath(args.geometry)
    binaries = [b.split("=", 1) for b in args.binaries]
    work = tempfile.mkdtemp(prefix="dist-structure-")
    files = []
    print("| binary | ranks | wall s | peak RSS MiB | rank 0 writing s | rank 0 building s | rank 0 slab bytes in "
          "| voxel updates per rank | slabs built per rank |")
    print("|---|---:|---:|---:|---:|---:|---:|---|---|")
    for _ in range(args.rounds):
        for name, binary in binaries:
            for ranks in (1, args.ranks):
                # The same command in a folder of its own: the file records it.
                folder = os.path.join(work, str(len(files)))
                os.mkdir(folder)
                report, wall, rss = run(os.path.abspath(binary), ranks, args, "out.ivol", folder)
                files.append(os.path.join(folder, "out.ivol"))
                r = report.get("ranks", [])
                seconds = report["seconds"]
                print("| %s | %d | %.2f | %.0f | %.2f | %s | %s | %s | %s |" % (
                    name, ranks, wall, rss, seconds["writing"],
                    "%.2f" % seconds["building"] if "building" in seconds else "–",
                    "{:,}".format(r[0]["slab_bytes_received"]) if r else "–",
                    ", ".join("{:,}".format(k["voxel_updates"]) for k in r) or "{:,}".format(report["voxel_updates"]),
                    ", ".join(str(k["slabs_built"]) for k in r) or "–"))
                sys.stdout.flush()
    same = all(filecmp.cmp(files[0], f, shallow=False) for f in files[1:])
    print("\nevery file the same bytes:", "yes" if same else "NO")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
