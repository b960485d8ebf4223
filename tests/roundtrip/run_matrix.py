#!/usr/bin/python3
"""The exactness contract of `ivol convert` and `ivol extract`, as a matrix.

Every input format (raw, TIFF, HDF5, OpenVDB) x every sample type it has (u8,
u16, i16, f16, f32; OpenVDB: float and half-float grids) is written by its
own library (numpy, tifffile, h5py, pyopenvdb) from a numpy array holding the
type's awkward values (extremes, -0, NaNs with payloads, infinities,
subnormals), converted by ivol into .ivol and straight into every other
format, and from .ivol into every format; each output is read back by those
libraries (the .ivol by the reference reader, format-spec/reference-reader)
and compared bit for bit with the array: same dtype and same bytes, or, where
the target type is wider (an integer or binary16 into an OpenVDB float32
grid), the same values. Then the lossy conversions the contract refuses:
exit 2, a message naming the loss and --allow-lossy, nothing left behind;
and with --allow-lossy, the output and the loss in the summary.

Usage: run_matrix.py IVOL [REFERENCE_READER]. Prints the matrix; exits 1 on
any failed cell.
"""
import json
import os
import subprocess
import sys
import tempfile

import h5py
import numpy as np
import pyopenvdb as vdb
import tifffile

IVOL = sys.argv[1]
REFERENCE = sys.argv[2] if len(sys.argv) > 2 else os.path.join(
    os.path.dirname(__file__), "..", "..", "format-spec", "reference-reader", "ivolref.py")
SHAPE = (6, 5, 7)  # z, y, x: odd sizes, so that the octree has padding
EXT = {"raw": ".raw", "tiff": ".tif", "hdf5": ".h5", "vdb": ".vdb"}
TYPES = {"u8": np.uint8, "u16": np.uint16, "i16": np.int16, "f16": np.float16, "f32": np.float32}
failures = []


def bits(a):
    """The array's bytes as unsigned integers of its width, for comparing NaNs."""
    return a.view({1: np.uint8, 2: np.uint16, 4: np.uint32}[a.dtype.itemsize])


def sample(type_name, seed):
    """An array of the type with its awkward values among random ones."""
    rng = np.random.default_rng(seed)
    dtype = np.dtype(TYPES[type_name])
    n = int(np.prod(SHAPE))
    if dtype.kind in "ui":
        info = np.iinfo(dtype)
        a = rng.integers(info.min, int(info.max) + 1, n).astype(dtype)
        a[:4] = [info.min, info.max, 0, 1]
    elif dtype == np.float16:
        a = rng.normal(0, 300, n).astype(np.float16)
        a.view(np.uint16)[:8] = [0x8000, 0x7D01, 0xFE05, 0x7C00, 0xFC00, 0x0001, 0x7BFF, 0x8000]
    else:
        a = (rng.normal(0, 1, n) * 1e5).astype(np.float32)
        a.view(np.uint32)[:8] = [0x80000000, 0x7FC00123, 0xFF800001, 0x7F800000, 0x00000001, 0x7F7FFFFF,
                                 0xC2F6E979, 0x80000000]
    a = a.reshape(SHAPE)
    # Not the OpenVDB background (0) at the corners: its active bounding box
    # is the whole volume, as ivol reads it.
    a.flat[-1] = 1
    return a


# Writers and readers of the foreign formats, by their own libraries.
def write_foreign(fmt, a, path, half=False):
    if fmt == "raw":
        a.tofile(path)
    elif fmt == "tiff":
        tifffile.imwrite(path, a)
    elif fmt == "hdf5":
        with h5py.File(path, "w") as f:
            f.create_dataset("/exchange/data", data=a, chunks=(2, 5, 7), compression="gzip")
    else:
        grid = vdb.FloatGrid()
        grid.name = "density"
        acc = grid.getAccessor()
        for (z, y, x), v in np.ndenumerate(a.astype(np.float32)):
            acc.setValueOn((x, y, z), float(v))
        grid.saveFloatAsHalf = half
        vdb.write(path, grids=[grid])


def read_foreign(fmt, path, dtype=None):
    if fmt == "raw":
        return np.fromfile(path, dtype=dtype).reshape(SHAPE)
    if fmt == "tiff":
        return tifffile.imread(path).reshape(SHAPE)
    if fmt == "hdf5":
        with h5py.File(path, "r") as f:
            return f["/exchange/data"][...]
    grid = vdb.read(path, "density")
    out = np.zeros(SHAPE[::-1], dtype=np.float32)  # x, y, z: pyopenvdb's array axes are the index axes
    grid.copyToArray(out, ijk=(0, 0, 0))
    return np.ascontiguousarray(out.transpose(2, 1, 0)), grid.saveFloatAsHalf


def read_ivol(path):
    """The physical values by the reference reader: its dense export (stored
    bits) and its header's encoding, scale and offset. uint16 codes come back
    as int64 values (exact for the integer scales and offsets ivol writes)."""
    dense = path + ".dense"
    subprocess.run(["/usr/bin/python3", REFERENCE, "dense", path, "-o", dense], check=True, capture_output=True)
    info = json.loads(subprocess.run(["/usr/bin/python3", REFERENCE, "info", path], check=True,
                                     capture_output=True, text=True).stdout)
    dtype = {"binary16": "<f2", "uint16": "<u2", "float32": "<f4"}[info["encoding"]]
    values = np.fromfile(dense, dtype=dtype).reshape(SHAPE)
    if info["encoding"] == "uint16":
        assert info["scale"] == int(info["scale"]) and info["offset"] == int(info["offset"])
        return values.astype(np.int64) * int(info["scale"]) + int(info["offset"])
    assert info["scale"] == 1 and info["offset"] == 0
    return values.astype(values.dtype.newbyteorder("="))


def same(want, got):
    """'exact' when `got` holds `want` bit for bit (a wider float: value for
    value: binary16 NaNs keep their payload, signalling ones included, through
    OpenVDB's half-float grids and numpy's float16 -> float32), else why not."""
    if got.shape != want.shape:
        return "shape %s, expected %s" % (got.shape, want.shape)
    if got.dtype != want.dtype:
        if got.dtype == np.float32 and want.dtype.kind in "uif":
            widened = want.astype(np.float32)  # exact: u8, u16, i16 and binary16 are all float32 numbers
            if np.array_equal(bits(got), bits(widened)):
                return "exact"
        return "dtype %s, expected %s" % (got.dtype, want.dtype)
    if not np.array_equal(bits(got), bits(want)):
        diff = np.flatnonzero(bits(got) != bits(want))
        return "%d voxels differ, first at %d: %r for %r" % (len(diff), diff[0], got.flat[diff[0]], want.flat[diff[0]])
    return "exact"


def ivol(*args):
    return subprocess.run([IVOL, *args], capture_output=True, text=True)


def cell(label, result, ok=None):
    print("  %-34s %s" % (label, result))
    if ok is None:
        ok = result.startswith("exact")
    if not ok:
        failures.append("%s: %s" % (label, result))


def convert_and_compare(src, dst, fmt, want, label, extra=()):
    r = ivol("-q", "convert", src, dst, *extra)
    if r.returncode != 0:
        cell(label, "exit %d: %s" % (r.returncode, r.stderr.strip()))
        return
    got = read_foreign(fmt, dst, want.dtype)
    if fmt == "vdb":
        got, was_half = got
        result = same(want, got)
        kind = "half" if was_half else "float32"
        cell(label, result + " (%s grid)" % kind if result == "exact" else result)
    else:
        cell(label, same(want, got))


def refused(label, args, needles, work):
    """A lossy conversion: exit 2, every needle in the message, nothing left in `work`/out."""
    out = os.path.join(work, "out")
    os.makedirs(out, exist_ok=True)
    r = ivol(*args)
    left = os.listdir(out)
    message = r.stderr.strip()
    missing = [n for n in needles if n not in message]
    if r.returncode != 2 or missing or left:
        cell(label, "exit %d, missing %r, left %r: %s" % (r.returncode, missing, left, message))
    else:
        cell(label, "refused: " + message.split("): ", 1)[-1].replace(work + "/", ""), ok=True)


def main():
    with tempfile.TemporaryDirectory(prefix="ivol-matrix-") as work:
        return matrix(work)


def matrix(work):
    inputs = [(fmt, t) for fmt in ("raw", "tiff", "hdf5") for t in TYPES] + [("vdb", "f32"), ("vdb", "f16")]
    print("input -> output: exact (bit for bit; into an OpenVDB float32 grid, value for value) or refused: reason")
    for seed, (fmt, t) in enumerate(inputs):
        a = sample(t, seed)
        if fmt == "vdb":
            # A grid holds float32 values; a half-float grid binary16 ones,
            # which OpenVDB reads back as float32.
            a = a.astype(np.float32) if t == "f32" else a.astype(np.float16).astype(np.float32)
        name = "%s-%s" % (fmt, t)
        src = os.path.join(work, name + EXT[fmt])
        write_foreign(fmt, a, src, half=(t == "f16"))
        if fmt == "vdb":
            a, _ = read_foreign("vdb", src)  # what OpenVDB itself reads back from the file it wrote
        print("%s %s %s" % (fmt, t, "x".join(map(str, SHAPE[::-1]))))
        raw_args = ("--dims", "%d,%d,%d" % SHAPE[::-1], "--type", t) if fmt == "raw" else ()
        stored = os.path.join(work, name + ".ivol")
        r = ivol("-q", "convert", src, stored, *raw_args)
        if r.returncode != 0:
            cell("-> ivol", "exit %d: %s" % (r.returncode, r.stderr.strip()))
            continue
        back = read_ivol(stored)
        if a.dtype.kind in "ui":
            cell("-> ivol", "exact (uint16 codes)" if np.array_equal(back, a.astype(np.int64)) else "values differ")
        else:
            cell("-> ivol", same(a, back))
        for out_fmt in EXT:
            dst = os.path.join(work, "%s-via-ivol%s" % (name, EXT[out_fmt]))
            convert_and_compare(stored, dst, out_fmt, a, "-> ivol -> " + out_fmt)
            if out_fmt != fmt:
                dst = os.path.join(work, "%s-direct%s" % (name, EXT[out_fmt]))
                convert_and_compare(src, dst, out_fmt, a, "-> " + out_fmt, raw_args)
        box = "0,0,0,%d,%d,%d" % SHAPE[::-1]
        dst = os.path.join(work, name + "-extract.tif")
        r = ivol("-q", "extract", stored, "--box", box, "-o", dst)
        cell("ivol extract -> tiff", same(a, read_foreign("tiff", dst)) if r.returncode == 0 else r.stderr.strip())
        # Re-encoded into each structure (ivol convert IN.ivol OUT.ivol): the
        # reference reader's stored values of both files, bit for bit.
        for structure in ("octree", "bricked"):
            again = os.path.join(work, "%s-again-%s.ivol" % (name, structure))
            r = ivol("-q", "convert", stored, again, "--structure", structure)
            label = "-> ivol -> ivol %s" % structure
            if r.returncode != 0:
                cell(label, "exit %d: %s" % (r.returncode, r.stderr.strip()))
                continue
            got = read_ivol(again)
            if back.dtype.kind in "ui":
                cell(label, "exact (uint16 codes)" if got.dtype == back.dtype and np.array_equal(got, back)
                     else "values differ")
            else:
                cell(label, same(back, got))

    print("lossy conversions")
    out = os.path.join(work, "out")
    f32, i16 = os.path.join(work, "raw-f32.ivol"), os.path.join(work, "raw-i16.ivol")
    refused("f32 -> u8", ["convert", f32, out + "/x.raw", "--out-type", "u8"],
            ["do not fit in u8", "--out-type f32 is exact", "--allow-lossy", "of 210 voxels"], work)
    refused("i16 -> u16 (negatives)", ["convert", i16, out + "/x.raw", "--out-type", "u16"],
            ["-32768", "do not fit in u16", "--out-type i16 is exact", "--allow-lossy"], work)
    refused("f32 -> vdb half", ["convert", f32, out + "/x.vdb", "--out-type", "f16"],
            ["do not fit in f16", "NaN lose their payload", "--allow-lossy"], work)
    refused("extract f32 -> u16", ["extract", f32, "--box", "0,0,0,7,5,6", "-o", out + "/x.h5", "--type", "u16"],
            ["--type f32 is exact", "--allow-lossy"], work)
    refused("f32 raw -> binary16 ivol", ["convert", os.path.join(work, "raw-f32.raw"), out + "/x.ivol", "--dims",
                                         "7,5,6", "--encoding", "binary16"],
            ["as binary16 is not exact", "--encoding float32 is exact", "--allow-lossy"], work)
    # Exact from the values: integers 0..255 held as float32 go to u8.
    ints = np.arange(np.prod(SHAPE), dtype=np.float32).reshape(SHAPE) % 256
    ints.tofile(os.path.join(work, "ints.raw"))
    ivol("-q", "convert", os.path.join(work, "ints.raw"), os.path.join(work, "ints.ivol"), "--dims", "7,5,6")
    convert_and_compare(os.path.join(work, "ints.ivol"), os.path.join(work, "ints-u8.raw"), "raw",
                        ints.astype(np.uint8), "f32 integers 0..255 -> u8", ("--out-type", "u8"))
    # Accepted with --allow-lossy: the output is what rounding gives, the loss is in the summary.
    r = ivol("convert", f32, os.path.join(work, "lossy.raw"), "--out-type", "u8", "--allow-lossy")
    with np.errstate(invalid="ignore"):
        want = np.clip(np.nan_to_num(np.rint(read_ivol(f32).astype(np.float64)), nan=0, posinf=255, neginf=0), 0, 255)
    want = want.astype(np.uint8)  # NaN written as 0, the rest rounded to nearest and clamped
    got = np.fromfile(os.path.join(work, "lossy.raw"), np.uint8).reshape(SHAPE)
    ok = r.returncode == 0 and "lossy" in r.stderr and "largest error" in r.stderr and np.array_equal(got, want)
    cell("f32 -> u8 --allow-lossy", "written, rounded and clamped as reported: " +
         r.stderr.strip().replace(work + "/", "") if ok else "exit %d, %s" % (r.returncode, r.stderr.strip()), ok)

    print("%d failed" % len(failures))
    for f in failures:
        print("FAIL " + f)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
