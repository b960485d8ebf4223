#!/usr/bin/env python3
"""Issue 22: ivol's lossless files against the compressors users would pick
instead, on the same voxels, side by side in one run.

    python bench/peers_codecs.py --work DIR [--ivol BINARY] [--phantoms A,B] [--ways W,...]
                                 [--only TEXT,...] [--skip TEXT,...] [--reads] [--reads-only]

DIR holds PHANTOM.f32 (N^3 float32, x fastest: an ivol reconstruction, as
bench/run_peers_codecs.sh makes it). Each volume is kept four ways, every
way stored bit for bit by every method:
  binary16  every voxel as binary16;
  uint16    every voxel as uint16, the volume's range on 0 .. 65535;
  object    binary16 within 3 voxels (Chebyshev) of the part (above half of
            Otsu's threshold), one background value (the mean of the rest)
            elsewhere;
  float32   every voxel as the reconstruction's float32.
Methods: ivol convert (--structure auto: a bricked grid, codec 3 for 16-bit
values, codec 2 for float32, codec 6 for either where noise dominates; with
--entropy-coder zstd, codec 3's residuals
without rANS; with --zstd-level 19, and with --brick 64 --zstd-level 19, its
smallest) and, for "object", ivol's octree that keeps full resolution only
there (--keep);
blosc2 (zstd 9 + byte shuffle, 64^3 chunks); HDF5 64^3 chunks with shuffle +
deflate 9 and with blosc zstd 9 + shuffle (hdf5plugin); the zstd CLI (-3 and
-19, whole file); xz -9 (whole file); JPEG-XL, JPEG-LS and JPEG 2000 lossless per z slice
(imagecodecs, on the 16-bit patterns); pcodec; fpzip (lossless, on the
values as float32). Prints one Markdown table per volume: bytes, against
ivol, encode seconds (wall, the whole volume) and the round trip checked.
With --reads, a second table per volume: the share of the file's bytes that
a z, y and x slice through the centre, a 64^3 box at the centre and the 1/8
preview read, for ivol's default file (`ivol extract`'s count of the bytes
its reader read, the open included) and for the HDF5 blosc file (the stored
sizes of the chunks the read touches, plus the file's bytes outside chunks,
which an HDF5 reader may read to open it: what a reader of that file
fetches at the least; HDF5 keeps no preview, so its 1/8 preview reads every
chunk). --reads-only prints only that table.
Needs numpy, h5py, hdf5plugin, blosc2, imagecodecs, pcodec, fpzip (a venv:
bench/run_peers_codecs.sh makes one).
"""
import argparse
import os
import subprocess
import sys
import tempfile
import time

import numpy as np


def otsu(values, bins=256):
    v = values[np.isfinite(values)]
    hist, edges = np.histogram(v, bins=bins)
    centres = (edges[:-1] + edges[1:]) / 2
    w0 = np.cumsum(hist)
    w1 = w0[-1] - w0
    m0 = np.cumsum(hist * centres)
    mean0 = m0 / np.maximum(w0, 1)
    mean1 = (m0[-1] - m0) / np.maximum(w1, 1)
    between = w0 * w1 * (mean0 - mean1) ** 2
    return float(centres[np.argmax(between)])


def dilate(mask, margin):
    out = mask.copy()
    for axis in range(3):
        grown = out.copy()
        for s in range(1, margin + 1):
            lo = [slice(None)] * 3
            hi = [slice(None)] * 3
            lo[axis], hi[axis] = slice(s, None), slice(None, -s)
            grown[tuple(lo)] |= out[tuple(hi)]
            grown[tuple(hi)] |= out[tuple(lo)]
        out = grown
    return out


def volumes(f):
    """The three ways of keeping the reconstruction f (float32, z, y, x)."""
    half = f.astype(np.float16)
    lo, hi = float(f.min()), float(f.max())
    codes = np.round((f - lo) / (hi - lo) * 65535).astype(np.uint16)
    rounded = half.astype(np.float32)
    keep = dilate(rounded > 0.5 * otsu(rounded), 3)
    background = np.float16(rounded[~keep].mean()) if (~keep).any() else np.float16(0)
    obj = np.where(keep, half, background).astype(np.float16)
    return [("binary16", half, "f16"), ("uint16", codes, "u16"), ("object", obj, "f16"),
            ("float32", np.ascontiguousarray(f, dtype=np.float32), "f32")], keep.mean()


class Timer:
    def __enter__(self):
        self.t = time.perf_counter()
        return self

    def __exit__(self, *a):
        self.seconds = time.perf_counter() - self.t


def bits(v):
    return v.view(np.uint16)


def method_ivol(v, kind, tmp, ivol, keep=None, extra=()):
    raw = os.path.join(tmp, "v.raw")
    v.tofile(raw)
    out = os.path.join(tmp, "v.ivol")
    n = v.shape[0]
    cmd = [ivol, "-q", "convert", raw, out, "--dims", "%d,%d,%d" % (n, n, n), "--type", kind, "-f"]
    if keep is not None:
        cmd += ["--keep", "threshold=%r,margin=3" % keep]
    cmd += list(extra)
    with Timer() as t:
        subprocess.run(cmd, check=True)
    back = os.path.join(tmp, "back.raw")
    subprocess.run([ivol, "-q", "convert", out, back, "--out-type", kind, "-f"], check=True)
    same = np.array_equal(bits(np.fromfile(back, dtype=v.dtype)), bits(v.ravel()))
    return os.path.getsize(out), t.seconds, same


def method_blosc2(v, kind, tmp):
    import blosc2
    path = os.path.join(tmp, "v.b2nd")
    if os.path.exists(path):
        os.remove(path)
    cparams = blosc2.CParams(codec=blosc2.Codec.ZSTD, clevel=9, filters=[blosc2.Filter.SHUFFLE], nthreads=2)
    with Timer() as t:
        blosc2.asarray(v, chunks=(64, 64, 64), urlpath=path, cparams=cparams)
    same = np.array_equal(bits(blosc2.open(path)[:]), bits(v))
    return os.path.getsize(path), t.seconds, same


def method_hdf5(v, kind, tmp, blosc):
    import h5py
    import hdf5plugin
    path = os.path.join(tmp, "v.h5")
    if blosc:
        filters = dict(**hdf5plugin.Blosc(cname="zstd", clevel=9, shuffle=hdf5plugin.Blosc.SHUFFLE))
    else:
        filters = dict(shuffle=True, compression="gzip", compression_opts=9)
    with Timer() as t:
        with h5py.File(path, "w") as f:
            f.create_dataset("v", data=v, chunks=(64, 64, 64), **filters)
    with h5py.File(path, "r") as f:
        same = np.array_equal(bits(f["v"][:]), bits(v))
    return os.path.getsize(path), t.seconds, same


def centre_reads(n):
    """The reads of the --reads table: (label, ivol --box x0,y0,z0,x1,y1,z1 and
    --level, numpy index of the same voxels at full resolution)."""
    c = n // 2
    return [
        ("z slice", (0, 0, c, n, n, c + 1), 0, np.s_[c:c + 1, :, :]),
        ("y slice", (0, c, 0, n, c + 1, n), 0, np.s_[:, c:c + 1, :]),
        ("x slice", (c, 0, 0, c + 1, n, n), 0, np.s_[:, :, c:c + 1]),
        ("64^3 box", (c - 32, c - 32, c - 32, c + 32, c + 32, c + 32), 0, np.s_[c - 32:c + 32, c - 32:c + 32,
                                                                               c - 32:c + 32]),
        ("1/8 preview", (0, 0, 0, (n + 7) // 8, (n + 7) // 8, (n + 7) // 8), 3, np.s_[::8, ::8, ::8]),
    ]


def read_shares(v, kind, tmp, ivol):
    """Per read of centre_reads: the share of ivol's default file and of the
    HDF5 blosc file that it reads (see the module's docstring)."""
    import re
    import h5py
    n = v.shape[0]
    method_ivol(v, kind, tmp, ivol)
    path = os.path.join(tmp, "v.ivol")
    ivol_size = os.path.getsize(path)
    method_hdf5(v, kind, tmp, True)
    h5 = os.path.join(tmp, "v.h5")
    h5_size = os.path.getsize(h5)
    with h5py.File(h5, "r") as f:
        d = f["v"]
        chunks = {}
        d.id.chunk_iter(lambda info: chunks.__setitem__(info.chunk_offset, info.size))
        outside = h5_size - sum(chunks.values())
        cz, cy, cx = d.chunks
    rows = []
    for label, box, level, index in centre_reads(n):
        out = subprocess.run([ivol, "extract", path, "--box", ",".join(map(str, box)), "--level", str(level),
                              "-o", os.path.join(tmp, "part.raw"), "-f"], check=True, capture_output=True, text=True)
        m = re.search(r"read (\d+)", out.stdout + out.stderr)
        ivol_read = int(m.group(1))
        # The chunks the same voxels lie in (the preview: every 8th voxel).
        zs, ys, xs = (np.arange(n)[i] for i in index)
        touched = {(z, y, x) for z in set(zs // cz * cz) for y in set(ys // cy * cy) for x in set(xs // cx * cx)}
        h5_read = outside + sum(chunks[t] for t in touched)
        rows.append((label, ivol_read, h5_read))
    return ivol_size, h5_size, rows


def method_xz(v, kind, tmp):
    raw = os.path.join(tmp, "v.raw")
    v.tofile(raw)
    with Timer() as t:
        with open(raw + ".xz", "wb") as out:
            subprocess.run(["xz", "-9", "-T1", "-c", raw], stdout=out, check=True)
    size = os.path.getsize(raw + ".xz")
    with open(raw + ".back", "wb") as out:
        subprocess.run(["xz", "-d", "-c", raw + ".xz"], stdout=out, check=True)
    same = np.array_equal(np.fromfile(raw + ".back", dtype=np.uint16), bits(v.ravel()))
    return size, t.seconds, same


def method_zstd(v, kind, tmp, level):
    raw = os.path.join(tmp, "v.raw")
    v.tofile(raw)
    with Timer() as t:
        subprocess.run(["zstd", "-q", "-f", "-%d" % level, "-T2", raw, "-o", raw + ".zst"], check=True)
    size = os.path.getsize(raw + ".zst")
    subprocess.run(["zstd", "-q", "-d", "-f", raw + ".zst", "-o", raw + ".back"], check=True)
    same = np.array_equal(np.fromfile(raw + ".back", dtype=np.uint16), bits(v.ravel()))
    return size, t.seconds, same


def method_slices(v, kind, tmp, codec):
    import imagecodecs as ic
    encode, decode = {
        "jpegxl": (lambda s: ic.jpegxl_encode(s, lossless=True, effort=7), ic.jpegxl_decode),
        # JPEG-LS: room for output larger than the input (binary16 bit patterns are noise to it).
        "jpegls": (lambda s: ic.jpegls_encode(s, level=0, out=2 * s.nbytes + 65536), ic.jpegls_decode),
        "jpeg2k": (lambda s: ic.jpeg2k_encode(s, level=0, reversible=True), ic.jpeg2k_decode),
    }[codec]
    u = bits(v)
    with Timer() as t:
        frames = [encode(np.ascontiguousarray(u[z])) for z in range(u.shape[0])]
    same = all(np.array_equal(decode(frames[z]).reshape(u[z].shape), u[z]) for z in range(u.shape[0]))
    return sum(len(b) for b in frames), t.seconds, same


def method_pcodec(v, kind, tmp):
    from pcodec import standalone, ChunkConfig
    data = v.ravel()
    with Timer() as t:
        blob = standalone.simple_compress(data, ChunkConfig())
    back = standalone.simple_decompress(blob)
    return len(blob), t.seconds, np.array_equal(bits(np.asarray(back, dtype=v.dtype)), bits(data))


def method_fpzip(v, kind, tmp):
    import fpzip
    f = v.astype(np.float32)  # every binary16 and uint16 value is a float32 exactly
    with Timer() as t:
        blob = fpzip.compress(f, precision=0, order="C")
    back = fpzip.decompress(blob, order="C").reshape(f.shape).astype(v.dtype)
    return len(blob), t.seconds, np.array_equal(bits(back), bits(v))


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--work", required=True)
    parser.add_argument("--ivol", default="build/tools/ivol")
    parser.add_argument("--phantoms", default="pencil-holder,connector-board,lattice-part")
    parser.add_argument("--ways", default="binary16,uint16,object,float32",
                        help="which ways of keeping each volume (comma-separated)")
    parser.add_argument("--only", default="", help="methods whose label contains one of these (comma-separated)")
    parser.add_argument("--skip", default="", help="methods whose label contains one of these (comma-separated)")
    parser.add_argument("--reads", action="store_true", help="also the share of the file a slice, box, preview reads")
    parser.add_argument("--reads-only", action="store_true", help="only that table")
    args = parser.parse_args()
    only = set(filter(None, args.only.split(",")))
    skip = set(filter(None, args.skip.split(",")))
    methods = [
        ("ivol (convert, --structure auto)", lambda v, k, tmp: method_ivol(v, k, tmp, args.ivol)),
        ("ivol, --entropy-coder zstd (codec 3 without rANS)",
         lambda v, k, tmp: method_ivol(v, k, tmp, args.ivol, extra=["--entropy-coder", "zstd"])),
        ("ivol, --zstd-level 19",
         lambda v, k, tmp: method_ivol(v, k, tmp, args.ivol, extra=["--zstd-level", "19"])),
        ("ivol, --brick 64 --zstd-level 19",
         lambda v, k, tmp: method_ivol(v, k, tmp, args.ivol, extra=["--brick", "64", "--zstd-level", "19"])),
        ("blosc2 64^3, zstd 9 + shuffle", method_blosc2),
        ("HDF5 64^3, blosc zstd 9 + shuffle", lambda v, k, tmp: method_hdf5(v, k, tmp, True)),
        ("HDF5 64^3, shuffle + deflate 9", lambda v, k, tmp: method_hdf5(v, k, tmp, False)),
        ("zstd -3 -T2 (whole file)", lambda v, k, tmp: method_zstd(v, k, tmp, 3)),
        ("zstd -19 -T2 (whole file)", lambda v, k, tmp: method_zstd(v, k, tmp, 19)),
        ("xz -9 (whole file, one thread)", method_xz),
        ("JPEG-XL lossless per slice", lambda v, k, tmp: method_slices(v, k, tmp, "jpegxl")),
        ("JPEG-LS lossless per slice", lambda v, k, tmp: method_slices(v, k, tmp, "jpegls")),
        ("JPEG 2000 reversible per slice", lambda v, k, tmp: method_slices(v, k, tmp, "jpeg2k")),
        ("pcodec", method_pcodec),
        ("fpzip lossless (values as float32)", method_fpzip),
    ]
    import blosc2, h5py, hdf5plugin, imagecodecs, pcodec  # noqa: E401 (versions below)
    versions = "blosc2 %s, h5py %s (HDF5 %s), hdf5plugin %s, imagecodecs %s, pcodec %s" % (
        blosc2.__version__, h5py.__version__, h5py.version.hdf5_version, hdf5plugin.version, imagecodecs.__version__,
        getattr(pcodec, "__version__", "?"))
    zstd_version = subprocess.run(["zstd", "--version"], capture_output=True, text=True).stdout.strip()
    print("# bench/peers_codecs.py --work %s (%s, %d cores, load %s)" % (
        args.work, time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()), os.cpu_count(),
        " ".join(open("/proc/loadavg").read().split()[:3])))
    print("# %s; %s" % (versions, zstd_version))
    with tempfile.TemporaryDirectory(prefix="ivol-peers-codecs.") as tmp:
        for phantom in args.phantoms.split(","):
            f = np.fromfile(os.path.join(args.work, phantom + ".f32"), dtype="<f4")
            n = round(len(f) ** (1 / 3))
            f = f.reshape(n, n, n)
            kept, keep_share = volumes(f)
            for name, v, kind in kept:
                if name not in args.ways.split(","):
                    continue
                print("\n## %s %d^3, %s (raw %d bytes%s)\n" % (
                    phantom, n, name, v.nbytes, ", %.1f %% of the voxels kept" % (100 * keep_share)
                    if name == "object" else ""))
                if args.reads or args.reads_only:
                    ivol_size, h5_size, reads = read_shares(v, kind, tmp, args.ivol)
                    print("| read (share of the file) | ivol (%d bytes) | HDF5 64^3 blosc (%d bytes) |\n|---|---:|---:|"
                          % (ivol_size, h5_size))
                    for label, ivol_read, h5_read in reads:
                        print("| %s | %.2f %% | %.2f %% |" % (label, 100.0 * ivol_read / ivol_size,
                                                            100.0 * h5_read / h5_size))
                    print()
                    sys.stdout.flush()
                    if args.reads_only:
                        continue
                print("| method | bytes | vs ivol | encode s | MB/s | exact |\n|---|---:|---:|---:|---:|---|")
                rows = list(methods)
                if name == "object":
                    threshold = 0.5 * otsu(f.astype(np.float16).astype(np.float32))
                    rows.insert(1, ("ivol octree, --keep threshold=0.5 Otsu,margin=3 (object only)",
                                    lambda v, k, tmp, t=threshold: method_ivol(v, k, tmp, args.ivol, keep=t)))
                ivol_bytes = None
                for label, run in rows:
                    if (only and not any(o in label for o in only)) or any(o in label for o in skip):
                        continue
                    try:
                        size, seconds, same = run(v, kind, tmp)
                    except Exception as e:  # a peer that cannot hold these values says so in the table
                        print("| %s | — | — | — | — | %s |" % (label, str(e).splitlines()[0][:80]))
                        continue
                    if ivol_bytes is None and label.startswith("ivol"):
                        ivol_bytes = size
                    against = "%+.1f %%" % (100.0 * size / ivol_bytes - 100) if ivol_bytes else "—"
                    print("| %s | %d | %s | %.2f | %.0f | %s |" % (
                        label, size, against, seconds, v.nbytes / 1e6 / seconds, "yes" if same else "NO"))
                    sys.stdout.flush()


if __name__ == "__main__":
    main()
