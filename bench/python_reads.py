"""Reads of one volume from Python: the ivol package against h5py on ivol's
own HDF5 export and tifffile on its TIFF export (the files `ivol convert`
writes), and the reference reader (format-spec/reference-reader) for the
whole volume.

    PYTHONPATH=build/python /usr/bin/python3 bench/python_reads.py FILE.ivol \\
        --ivol build/tools/ivol --work DIR [--repeat 3] [--reference]

Makes DIR/NAME.h5 and DIR/NAME.tif with `ivol convert` (unless they exist),
then times, per library, each read opening the file anew (the operating
system's page cache warm: every file was read once before): one z-slice, one
x-slice, a 64^3 box at the centre, the 1/8 level (each voxel the mean of an
8^3 cube: ivol reads its level 3; h5py and tifffile read the volume and
average in numpy, the only way they have) and the whole volume. Prints the
median of --repeat runs per read and checks that every library returned the
same values (the exports are float32; ivol's values are float32 too).
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import time

import h5py
import numpy as np
import tifffile

import ivol


def mean_level(a, k):
    """Level k of spec §12.3 from the dense array: means of 2^k cubes (the
    volume's dims here are multiples of 2^k), in float64 then float32."""
    s = 1 << k
    z, y, x = (n // s for n in a.shape)
    return a.reshape(z, s, y, s, x, s).mean(axis=(1, 3, 5), dtype=np.float64).astype(np.float32)


def tiff_pages(path, first, stop):
    with tifffile.TiffFile(path) as t:
        return np.stack([t.pages[i].asarray() for i in range(first, stop)])


def reads(shape):
    z, y, x = shape
    c = [n // 2 for n in shape]
    box = tuple(slice(n - 32, n + 32) for n in c)
    return {
        "z-slice": (np.s_[c[0]], lambda t: tiff_pages(t, c[0], c[0] + 1)[0]),
        "x-slice": (np.s_[:, :, c[2]], lambda t: tifffile.imread(t)[:, :, c[2]]),
        "64^3 box": (box, lambda t: tiff_pages(t, box[0].start, box[0].stop)[:, box[1], box[2]]),
        "1/8 level": (None, lambda t: mean_level(tifffile.imread(t), 3)),
        "whole": (np.s_[...], lambda t: tifffile.imread(t)),
    }


def timed(fn, repeat):
    times, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out


def main():
    p = argparse.ArgumentParser()
    p.add_argument("file")
    p.add_argument("--ivol", required=True, help="the ivol command (for the exports)")
    p.add_argument("--work", required=True)
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--reference", action="store_true", help="also time the reference reader's whole read")
    a = p.parse_args()
    name = os.path.splitext(os.path.basename(a.file))[0]
    h5_path = os.path.join(a.work, name + ".h5")
    tif_path = os.path.join(a.work, name + ".tif")
    for out in (h5_path, tif_path):
        if not os.path.exists(out):
            subprocess.run([a.ivol, "--quiet", "convert", a.file, out], check=True)
    f = ivol.open(a.file)
    print(f"{a.file}: {f.structure} {f.shape} {f.encoding}, {os.path.getsize(a.file)} bytes; "
          f"{h5_path}: {os.path.getsize(h5_path)} bytes; {tif_path}: {os.path.getsize(tif_path)} bytes")
    with h5py.File(h5_path, "r") as h:
        d = h["exchange/data"]
        print(f"  HDF5: chunks {d.chunks}, {d.compression} {d.compression_opts}; "
              f"h5py {h5py.__version__}, tifffile {tifffile.__version__}, numpy {np.__version__}, "
              f"ivol {ivol.library_version()}")
    for path in (a.file, h5_path, tif_path):  # the page cache warm for all
        with open(path, "rb") as fh:
            while fh.read(1 << 24):
                pass

    def by_ivol(key):
        g = ivol.open(a.file)
        return g.level(3)[...] if key is None else g[key]

    def by_h5py(key):
        with h5py.File(h5_path, "r") as h:
            d = h["exchange/data"]
            return mean_level(d[...], 3) if key is None else d[key]

    results = {}
    print(f"{'read':<10} {'ivol s':>9} {'h5py s':>9} {'tifffile s':>11} {'h5py/ivol':>10} {'tiff/ivol':>10}")
    for label, (key, tiff_read) in reads(f.shape).items():
        t_ivol, v_ivol = timed(lambda: by_ivol(key), a.repeat)
        t_h5, v_h5 = timed(lambda: by_h5py(key), a.repeat)
        t_tif, v_tif = timed(lambda: tiff_read(tif_path), a.repeat)
        same = np.array_equal(v_ivol, v_h5) and np.array_equal(v_ivol, v_tif)
        if key is None:
            # The file stores its level averages in its encoding (binary16
            # rounds to 11 bits); numpy averages in float64: equal to that
            # rounding.
            tol = {"binary16": 2.0**-11, "uint16": 0.0, "float32": 2.0**-23}[f.encoding]
            scale = f.value_scale if f.encoding == "uint16" else 0.0
            same = all(np.all(np.abs(v_ivol - v) <= tol * np.abs(v) + scale / 2 + 2.0**-24) for v in (v_h5, v_tif))
        results[label] = {"ivol_s": t_ivol, "h5py_s": t_h5, "tifffile_s": t_tif, "same_values": bool(same)}
        print(f"{label:<10} {t_ivol:9.4f} {t_h5:9.4f} {t_tif:11.4f} {t_h5 / t_ivol:9.1f}x {t_tif / t_ivol:9.1f}x"
              f"{'' if same else '  VALUES DIFFER'}")
    if a.reference:
        ref = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "format-spec", "reference-reader",
                           "ivolref.py")
        out = os.path.join(a.work, name + ".ref.raw")
        for pure in ("0", "1"):
            t0 = time.perf_counter()
            subprocess.run([sys.executable, "-B", ref, "dense", a.file, "-o", out], check=True,
                           env=dict(os.environ, IVOLREF_PURE_PYTHON=pure), stdout=subprocess.DEVNULL)
            t = time.perf_counter() - t0
            label = "reference reader, " + ("pure-Python checksums" if pure == "1" else "C checksums")
            width = {"binary16": "<u2", "uint16": "<u2", "float32": "<u4"}[f.encoding]
            same = np.fromfile(out, dtype=width).tobytes() == f.stored[...].tobytes()
            os.remove(out)
            results[label] = {"whole_s": t, "same_bits": same}
            print(f"whole, {label}: {t:.2f} s ({t / results['whole']['ivol_s']:.0f}x ivol's whole read)"
                  f"{'' if same else '  BITS DIFFER'}")
    print(json.dumps(results))


if __name__ == "__main__":
    main()
