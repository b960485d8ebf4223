#!/usr/bin/env python3
"""Issue 22: ivol's object-fidelity files against HDF5 with blosc zstd 9 +
shuffle (64^3 chunks), the smallest peer there, side by side in one run,
and where ivol's bytes go.

    python bench/object_fidelity.py --work DIR [--ivol BINARY] [--before BINARY] [--phantoms A,B]

DIR holds PHANTOM.f32 (bench/run_peers_codecs.sh makes them). The "object"
volume is bench/peers_codecs.py's: binary16 within 3 voxels of the part, one
background value elsewhere. Rows: ivol convert (auto: a bricked grid) at
zstd 3 (the default) and 9, with --before's binary too when given (the same
rows of an older ivol), and HDF5 64^3 chunks with blosc zstd 9 + shuffle
(hdf5plugin). Every file is read back and compared bit for bit. Then ivol's
file at zstd 3 broken down by brick kind (only the background, mixed,
none of it) and codec, from the index read by the reference reader.
Needs numpy, h5py, hdf5plugin (a venv: bench/run_peers_codecs.sh makes one)
and zstandard (the reference reader's).
"""
import argparse
import collections
import os
import subprocess
import sys
import tempfile

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
sys.path.insert(0, os.path.join(HERE, "..", "format-spec", "reference-reader"))
from peers_codecs import method_hdf5, volumes  # noqa: E402


def write_ivol(ivol, v, tmp, level):
    raw, out, back = (os.path.join(tmp, name) for name in ("v.raw", "v.ivol", "back.raw"))
    v.tofile(raw)
    n = v.shape[0]
    subprocess.run([ivol, "-q", "convert", raw, out, "--dims", "%d,%d,%d" % (n, n, n), "--type", "f16",
                    "--zstd-level", str(level), "-f"], check=True)
    subprocess.run([ivol, "-q", "convert", out, back, "--out-type", "f16", "-f"], check=True)
    same = np.array_equal(np.fromfile(back, dtype=np.uint16), v.view(np.uint16).ravel())
    return out, os.path.getsize(out), same


def breakdown(path, v):
    """Bytes by brick kind (of a block's first brick) and codec: (blocks,
    bricks, stored bytes) per row."""
    import ivolref
    r, ix, _ = ivolref.open_ivol(path)
    r.close()
    u = v.view(np.uint16)
    background = np.bincount(u.ravel()).argmax()
    n = u.shape[0]
    B = 1 << ix.cell_log2 if hasattr(ix, "cell_log2") else 32
    where = {}
    for first, ext, origin in ivolref_bricks(n, B):
        where[first] = origin
    rows = collections.defaultdict(lambda: [0, 0, 0])
    for e in ix.blocks:
        if e.stream != 3:
            key = "metadata" if e.stream == 1 else "stream %d" % e.stream
        else:
            x, y, z = where[e.first_element]
            b = u[z:z + B, y:y + B, x:x + B]
            k = int((b == background).sum())
            kind = "background only" if k == b.size else "no background" if k == 0 else "mixed"
            key = "%s, codec %d" % (kind, e.codec)
        rows[key][0] += 1
        rows[key][1] += e.element_count // B ** 3 if e.stream == 3 else 0
        rows[key][2] += e.stored_size
    rows["header, index, footer"] = [0, 0, os.path.getsize(path) - sum(s for _, _, s in rows.values())]
    return rows


def ivolref_bricks(n, B):
    """§8A.4 for a cube of side n: (first value, extent, origin) per brick."""
    first = 0
    for z in range(0, n, B):
        for y in range(0, n, B):
            for x in range(0, n, B):
                e = (min(B, n - x), min(B, n - y), min(B, n - z))
                yield first, e, (x, y, z)
                first += e[0] * e[1] * e[2]


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--work", required=True)
    parser.add_argument("--ivol", default="build/tools/ivol")
    parser.add_argument("--before", help="an older ivol binary for the 'before' rows")
    parser.add_argument("--phantoms", default="pencil-holder,connector-board,lattice-part")
    args = parser.parse_args()
    print("| volume | ivol before, zstd 3 | ivol before, zstd 9 | ivol, zstd 3 | ivol, zstd 9 | "
          "HDF5 64^3 blosc zstd 9 + shuffle | ivol zstd 3 vs HDF5 | ivol zstd 9 vs HDF5 | exact |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---|")
    details = []
    with tempfile.TemporaryDirectory(prefix="ivol-object.") as tmp:
        for phantom in args.phantoms.split(","):
            f = np.fromfile(os.path.join(args.work, phantom + ".f32"), dtype=np.float32)
            n = round(len(f) ** (1 / 3))
            kinds, share = volumes(f.reshape(n, n, n))
            v = [vol for name, vol, _ in kinds if name == "object"][0]
            sizes, exact = {}, True
            for label, binary in (("before", args.before), ("after", args.ivol)):
                for level in (3, 9):
                    if binary is None:
                        sizes[label, level] = None
                        continue
                    path, size, same = write_ivol(binary, v, tmp, level)
                    sizes[label, level] = size
                    exact &= same
                    if label == "after" and level == 3:
                        details.append((phantom, size, breakdown(path, v)))
            h5, _, same = method_hdf5(v, "f16", tmp, True)
            exact &= same
            cell = lambda s: "—" if s is None else "{:,}".format(s)
            print("| %s object (%.1f %% kept) | %s | %s | %s | %s | %s | %+.1f %% | %+.1f %% | %s |" % (
                phantom, 100 * share, cell(sizes["before", 3]), cell(sizes["before", 9]), cell(sizes["after", 3]),
                cell(sizes["after", 9]), cell(h5), 100.0 * sizes["after", 3] / h5 - 100,
                100.0 * sizes["after", 9] / h5 - 100, "yes" if exact else "NO"))
            sys.stdout.flush()
    for phantom, total, rows in details:
        print("\n%s object, ivol at zstd 3 (%s bytes):\n\n| blocks of | blocks | bricks | bytes | share |\n"
              "|---|---:|---:|---:|---:|" % (phantom, "{:,}".format(total)))
        for key in sorted(rows):
            blocks, bricks, size = rows[key]
            print("| %s | %d | %d | %s | %.1f %% |" % (key, blocks, bricks, "{:,}".format(size), 100.0 * size / total))


if __name__ == "__main__":
    main()
