"""The Python package, the rest of issue 19: steps along y and x against
numpy on the dense array, salvage reads of cut files against the reference
reader's salvage (format-spec/reference-reader, an implementation of spec §18
apart from libformat), and write_structure for the four structure kinds
against the array written and the reference reader's dense export.

Run by ctest (python_package_more) with PYTHONPATH=<build>/python,
IVOL=<ivol> and IVOLREF=<ivolref.py>.
"""

import json
import os
import subprocess
import sys
import tempfile
import unittest

import numpy as np

import ivol

IVOL = os.environ["IVOL"]
IVOLREF = os.environ["IVOLREF"]


def same_bits(a, b):
    a = np.ascontiguousarray(a, dtype=np.float32)
    b = np.ascontiguousarray(b, dtype=np.float32)
    return a.shape == b.shape and np.array_equal(a.view(np.uint32), b.view(np.uint32))


def reference(*args):
    r = subprocess.run([sys.executable, "-B", IVOLREF, *args], capture_output=True, text=True)
    if r.returncode != 0:
        raise AssertionError(f"ivolref.py {' '.join(args)}: {r.stdout}{r.stderr}")
    return r.stdout


def smooth_noisy(shape, seed):
    rng = np.random.default_rng(seed)
    z, y, x = np.indices(shape)
    return (0.01 * (x + 2 * y + 3 * z) + rng.normal(size=shape)).astype(np.float32)


class Steps(unittest.TestCase):
    """Steps along y and x (and z) on a volume of many blocks, each against
    numpy's result on the full array."""

    KEYS = [
        np.s_[:, ::2, ::3],
        np.s_[::2, :, ::3],
        np.s_[5, ::7, ::5],
        np.s_[:, 3, ::-4],
        np.s_[::-3, ::-5, 1],
        np.s_[::9, 60::-33, ::40],
        np.s_[:, ::40, ::40],
        np.s_[1:70:13, ::-64, 2::17],
        np.s_[..., ::33],
        np.s_[None, ::50, 7, ::-35],
    ]

    def test_steps_against_numpy(self):
        a = smooth_noisy((72, 66, 80), 1)
        with tempfile.TemporaryDirectory() as tmp:
            for encoding in (None, "binary16"):
                path = os.path.join(tmp, f"{encoding}.ivol")
                ivol.write(path, a, encoding=encoding, block_bytes=4096)
                f = ivol.open(path)
                full = f[...]
                if encoding is None:
                    self.assertTrue(same_bits(full, a))
                stored = f.stored[...]
                for key in self.KEYS:
                    with self.subTest(encoding=encoding, key=key):
                        got = f[key]
                        self.assertEqual(got.shape, full[key].shape)
                        self.assertTrue(same_bits(got, full[key]))
                        self.assertEqual(f.stored[key].tobytes(), stored[key].tobytes())
                        k1 = f.level(1)
                        self.assertTrue(same_bits(k1[key], k1[...][key]))

    def test_wide_steps_read_fewer_bytes(self):
        a = smooth_noisy((64, 128, 128), 2)
        with tempfile.TemporaryDirectory() as tmp:
            path = os.path.join(tmp, "v.ivol")
            ivol.write(path, a, block_bytes=4096)
            bytes_for = {}
            for name, key in [("box", np.s_[:, 0:128, 0:128]), ("steps", np.s_[:, ::64, ::64])]:
                f = ivol.open(path)
                f.reset_io_stats()
                self.assertTrue(same_bits(f[key], a[key]))
                bytes_for[name] = f.io_stats["bytes_read"]
            # 2 x 2 columns of a 128 x 128 plane: a small share of the blocks.
            self.assertLess(bytes_for["steps"], 0.25 * bytes_for["box"])


class Salvage(unittest.TestCase):
    def test_cut_files(self):
        a = smooth_noisy((40, 50, 60), 3)
        with tempfile.TemporaryDirectory() as tmp:
            path = os.path.join(tmp, "whole.ivol")
            ivol.write(path, a, block_bytes=4096)
            with open(path, "rb") as f:
                data = f.read()
            intact = ivol.open(path, salvage=True)
            self.assertIsNone(intact.salvage)
            values, damaged = intact.read_salvaged()
            self.assertEqual(damaged, [])
            self.assertTrue(same_bits(values, a))
            cut_path = os.path.join(tmp, "cut.ivol")
            for fraction in (0.15, 0.35, 0.5, 0.7, 0.9, 0.99):
                cut = int(len(data) * fraction)
                with self.subTest(cut=cut):
                    with open(cut_path, "wb") as f:
                        f.write(data[:cut])
                    with self.assertRaises(ivol.TruncatedError):
                        ivol.open(cut_path)
                    f = ivol.open(cut_path, salvage=True)
                    self.assertIn("IVOL_END", f.salvage["reason"])
                    self.assertLessEqual(f.salvage["values_found"], f.salvage["values_total"])
                    values, damaged = f.read_salvaged()
                    # A cut in the index or footer loses no value.
                    self.assertEqual(len(damaged) > 0, f.salvage["values_found"] < f.salvage["values_total"])
                    # The reference reader's salvage: stored bits and the
                    # number of voxels it filled from coarser levels.
                    ref_raw = os.path.join(tmp, "ref.raw")
                    summary = json.loads(reference("salvage", cut_path, "-o", ref_raw))
                    ref_bits = np.fromfile(ref_raw, dtype="<u4").reshape(a.shape)
                    self.assertTrue(np.array_equal(f.stored[...].view("<u4"), ref_bits))
                    stored, damaged_stored = f.stored.read_salvaged()
                    self.assertTrue(np.array_equal(stored.view("<u4"), ref_bits))
                    self.assertEqual(damaged_stored, damaged)
                    missing = np.zeros(a.shape, bool)
                    for r in damaged:
                        self.assertEqual(len(r["lo"]), 3)
                        self.assertIn("not found", r["message"])
                        missing[tuple(slice(lo, hi) for lo, hi in zip(r["lo"], r["hi"]))] = True
                    self.assertEqual(int(missing.sum()), summary["filled_voxels"])
                    # What survived is exact; plain indexing salvages too.
                    self.assertTrue(same_bits(values[~missing], a[~missing]))
                    self.assertTrue(same_bits(f[...], values))
                    # A part: its regions are the whole read's, clipped to
                    # the boxes the part reads (plane by plane along z here).
                    part, part_damaged = f.read_salvaged(np.s_[::3, 10:40, ::-7])
                    self.assertTrue(same_bits(part, values[::3, 10:40, ::-7]))
                    part_missing = np.zeros(a.shape, bool)
                    for r in part_damaged:
                        box = tuple(slice(lo, hi) for lo, hi in zip(r["lo"], r["hi"]))
                        self.assertTrue(missing[box].all(), r)
                        part_missing[box] = True
                    self.assertTrue(np.array_equal(part_missing[::3, 10:40, 3::7], missing[::3, 10:40, 3::7]))
            # A cut inside the header: nothing to salvage, an IvolError.
            with open(cut_path, "wb") as f:
                f.write(data[:20])
            with self.assertRaises(ivol.IvolError):
                ivol.open(cut_path, salvage=True)


    def test_unreadable_metadata_is_named_not_defaulted(self):
        """A damaged metadata block: refused as it is; salvaged, the values
        are read but the voxel size is unknown (not the defaults' 1s) and
        f.metadata_problem says why."""
        a = smooth_noisy((20, 24, 28), 5)
        with tempfile.TemporaryDirectory() as tmp:
            path = os.path.join(tmp, "v.ivol")
            ivol.write(path, a, voxel_size=(0.5, 0.25, 0.125))
            self.assertEqual(ivol.open(path).voxel_size, (0.5, 0.25, 0.125))
            self.assertIsNone(ivol.open(path, salvage=True).metadata_problem)
            blocks = json.loads(reference("info", path))["blocks"]
            meta = next(b for b in blocks if b["stream_name"] == "metadata")
            with open(path, "r+b") as f:
                f.seek(meta["file_offset"] + meta["stored_size"] // 2)
                byte = f.read(1)
                f.seek(-1, os.SEEK_CUR)
                f.write(bytes([byte[0] ^ 0x5A]))
            with self.assertRaises(ivol.IvolError):
                ivol.open(path)
            f = ivol.open(path, salvage=True)
            self.assertIn("metadata", f.metadata_problem)
            self.assertIsNone(f.voxel_size)
            self.assertTrue(same_bits(f[...], a))


class WriteStructure(unittest.TestCase):
    def test_four_kinds(self):
        shape = (40, 48, 56)
        factor = 8
        cells = tuple(-(-n // factor) for n in shape)
        need = np.zeros(cells, bool)
        need[1:3, 2:4, 1:5] = True
        need[4, 0, 6] = True
        # Detail where full resolution is kept, a constant elsewhere: every
        # coarse voxel averages the constant, so the file holds the array.
        a = np.full(shape, 0.25, np.float32)
        fine = np.kron(need, np.ones((factor,) * 3, bool))[: shape[0], : shape[1], : shape[2]]
        a[fine] = smooth_noisy(shape, 4)[fine]
        with tempfile.TemporaryDirectory() as tmp:
            for kind in ("octree", "regular", "rectilinear", "nested"):
                for encoding in ("float32", "binary16"):
                    with self.subTest(kind=kind, encoding=encoding):
                        path = os.path.join(tmp, f"{kind}_{encoding}.ivol")
                        r = ivol.write_structure(path, a, need, factor=factor, structure=kind, encoding=encoding,
                                                 voxel_size=(0.5, 0.25, 0.125), origin=(3, 2, 1), nested_cell=8)
                        f = ivol.open(path)
                        self.assertEqual(f.structure, kind)
                        self.assertEqual(f.shape, shape)
                        self.assertEqual(f.encoding, encoding)
                        self.assertEqual(f.voxel_size, (0.5, 0.25, 0.125))
                        self.assertEqual(f.origin, (3.0, 2.0, 1.0))
                        self.assertEqual(ivol.verify(path)["status"], "ok")
                        self.assertEqual(r["file_bytes"], os.path.getsize(path))
                        self.assertGreaterEqual(r["structure_voxels"], int(fine.sum()))
                        want = a if encoding == "float32" else a.astype(np.float16).astype(np.float32)
                        self.assertTrue(same_bits(f[...], want))
                        # The reference reader's dense export of the file.
                        raw = os.path.join(tmp, "ref.raw")
                        reference("dense", path, "-o", raw)
                        bits = np.fromfile(raw, dtype="<u4" if encoding == "float32" else "<u2")
                        self.assertEqual(bits.tobytes(), f.stored[...].tobytes())
                        if kind != "regular":
                            self.assertLess(r["structure_voxels"], a.size)

    def test_coarse_voxels_are_means(self):
        # Random values everywhere: a coarse voxel holds the mean of the
        # voxels it covers, so the mean over each region of equal read
        # values equals the written array's mean there (float64 reference).
        shape = (32, 32, 32)
        need = np.zeros((4, 4, 4), bool)
        need[0, 0, 0] = True
        a = smooth_noisy(shape, 5)
        with tempfile.TemporaryDirectory() as tmp:
            for kind in ("octree", "rectilinear", "nested"):
                with self.subTest(kind=kind):
                    path = os.path.join(tmp, f"{kind}.ivol")
                    ivol.write_structure(path, a, need, factor=8, structure=kind, nested_cell=8)
                    got = ivol.open(path)[...]
                    self.assertTrue(same_bits(got[:8, :8, :8], a[:8, :8, :8]))
                    values, inverse = np.unique(got, return_inverse=True)
                    self.assertLess(len(values), a.size / 4)
                    sums = np.bincount(inverse.ravel(), weights=a.astype(np.float64).ravel())
                    counts = np.bincount(inverse.ravel())
                    np.testing.assert_allclose(values, sums / counts, rtol=0, atol=1e-5)

    def test_refusals_leave_nothing(self):
        a = np.zeros((16, 16, 16), np.float32)
        with tempfile.TemporaryDirectory() as tmp:
            out = os.path.join(tmp, "x.ivol")
            for kw in [dict(need=np.ones((3, 2, 2), bool), factor=8),
                       dict(need=np.ones((2, 2, 2), bool), factor=6),
                       dict(need=np.ones((2, 2, 2), bool), factor=8, structure="sparse"),
                       dict(need=np.ones((2, 2, 2), bool), factor=8, encoding="uint16"),
                       dict(need=np.ones((2, 2), bool), factor=8)]:
                with self.subTest(**{k: v for k, v in kw.items() if k != "need"}):
                    with self.assertRaises(ivol.InvalidArgumentError):
                        ivol.write_structure(out, a, **kw)
                    self.assertEqual(os.listdir(tmp), [])
            with self.assertRaises(ivol.InvalidArgumentError):
                ivol.write_structure(out, a.astype(np.float64), np.ones((2, 2, 2), bool), factor=8)


class WholeReads(unittest.TestCase):
    """The whole volume, read on several threads with vector conversions
    (libformat's whole_level.hpp, cube_writers.hpp), and f.stored read into
    numpy's own array."""

    def test_every_binary16_code(self):
        rng = np.random.default_rng(5)
        codes = rng.permutation(np.arange(65536, dtype=np.uint32)).astype(np.uint16)
        a = codes.view(np.float16).reshape(32, 32, 64)
        # binary16 to float32 exactly; a NaN keeps its payload and is quieted.
        h = codes.astype(np.uint32)
        sign, exponent, mantissa = (h & 0x8000) << 16, (h >> 10) & 0x1F, h & 0x3FF
        expected = a.astype(np.float32).view(np.uint32).reshape(-1).copy()
        nan = (exponent == 31) & (mantissa != 0)
        expected[nan] = sign[nan] | 0x7F800000 | 0x400000 | (mantissa[nan] << 13)
        with tempfile.TemporaryDirectory() as d:
            path = os.path.join(d, "codes.ivol")
            ivol.write(path, a)
            f = ivol.open(path)
            self.assertEqual(f.encoding, "binary16")
            whole = f[:]
            self.assertTrue(np.array_equal(whole.view(np.uint32).reshape(-1), expected))
            walked, damaged = f.read_salvaged()
            self.assertEqual(damaged, [])
            self.assertTrue(same_bits(whole, walked))
            # ivol.write keeps every bit, signalling NaNs included.
            written = codes.reshape(a.shape)
            stored = f.stored[...]
            self.assertEqual(stored.dtype, np.float16)
            self.assertTrue(np.array_equal(stored.view(np.uint16), written))
            part = f.stored[3:29, 1:, 5:60]
            self.assertTrue(np.array_equal(part.view(np.uint16), written[3:29, 1:, 5:60]))

    def test_damaged_block_raises(self):
        rng = np.random.default_rng(6)
        a = rng.integers(0, 4000, size=(64, 64, 64)).astype(np.uint16)
        with tempfile.TemporaryDirectory() as d:
            path = os.path.join(d, "noise.ivol")
            ivol.write(path, a)
            self.assertTrue(np.array_equal(ivol.open(path)[:], a.astype(np.float32)))
            with open(path, "r+b") as out:  # a byte in the middle: inside the deepest level's values
                size = os.path.getsize(path)
                out.seek(size // 2)
                byte = out.read(1)
                out.seek(size // 2)
                out.write(bytes([byte[0] ^ 0x55]))
            f = ivol.open(path)
            for read in (lambda: f[:], lambda: f.stored[...], lambda: f[:]):
                with self.assertRaises(ivol.ChecksumError) as caught:
                    read()
                self.assertIn("block ", str(caught.exception))
            salvaged, damaged = f.read_salvaged()
            self.assertGreater(len(damaged), 0)
            self.assertEqual(salvaged.shape, a.shape)

    def test_large_output_memory(self):
        # Reads of 32 MiB or more land in memory the package maps and faults
        # in itself (python/src/output_memory.hpp), not numpy's.
        z, y, x = np.indices((288, 256, 256), dtype=np.uint32)
        a = ((x * 7 + y * 3 + z * 5) % 4001).astype(np.uint16)
        with tempfile.TemporaryDirectory() as d:
            path = os.path.join(d, "large.ivol")
            ivol.write(path, a)
            f = ivol.open(path)
            whole = f[:]
            self.assertEqual(whole.nbytes, 288 * 256 * 256 * 4)
            self.assertTrue(np.array_equal(whole, a.astype(np.float32)))
            stored = f.stored[...]
            self.assertEqual(stored.nbytes, 288 * 256 * 256 * 2)
            self.assertTrue(np.array_equal(stored, a))
            # The arrays own their memory: they outlive the file, are
            # writable, and a view keeps it alive after the array is gone.
            part = whole[100:110, 5, :]
            del f, whole, stored
            part += 1
            self.assertTrue(np.array_equal(part, a[100:110, 5, :].astype(np.float32) + 1))
            self.assertTrue(np.array_equal(ivol.open(path)[-3:], a[-3:].astype(np.float32)))

            # A read that fails leaves no memory behind.
            with open(path, "r+b") as out:
                size = os.path.getsize(path)
                out.seek(size // 2)
                byte = out.read(1)
                out.seek(size // 2)
                out.write(bytes([byte[0] ^ 0x55]))
            f = ivol.open(path)

            def resident():
                with open("/proc/self/statm") as s:
                    return int(s.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")

            with self.assertRaises(ivol.ChecksumError):
                f[:]
            before = resident()
            for _ in range(8):
                with self.assertRaises(ivol.ChecksumError):
                    f[:]
            self.assertLess(resident() - before, 32 << 20)

            # Memory that cannot be had is a MemoryError, not a crash.
            script = (
                "import resource, sys, ivol\n"
                "f = ivol.open(sys.argv[1])\n"
                "soft, hard = resource.getrlimit(resource.RLIMIT_AS)\n"
                "with open('/proc/self/statm') as s: used = int(s.read().split()[0]) * 4096\n"
                "resource.setrlimit(resource.RLIMIT_AS, (used + (48 << 20), hard))\n"
                "try:\n"
                "    f[:]\n"
                "except MemoryError:\n"
                "    print('MemoryError')\n"
            )
            ivol.write(path, a)
            r = subprocess.run([sys.executable, "-B", "-c", script, path], capture_output=True, text=True,
                               env=os.environ)
            self.assertEqual((r.returncode, r.stdout.strip()), (0, "MemoryError"), r.stderr)


if __name__ == "__main__":
    unittest.main(verbosity=1)
