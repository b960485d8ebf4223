"""The reference reader's two checksum paths (format-spec/reference-reader/
ivolref.py): Debian's python3-crc32c and python3-xxhash when present, the
pure-Python code when IVOLREF_PURE_PYTHON=1. Both against published check
values, against each other on random data, and both running the conformance
vectors (which include damaged checksums that must be caught).

Run by ctest (reference_reader_checksums) with IVOLREF=<ivolref.py> and
IVOL_VECTORS=<format-spec/vectors>, under /usr/bin/python3 (the interpreter
that sees the Debian packages).
"""

import importlib.util
import os
import random
import subprocess
import sys
import unittest

IVOLREF = os.environ["IVOLREF"]
VECTORS = os.environ["IVOL_VECTORS"]


def load_reference(pure):
    """A fresh copy of ivolref with the backends chosen at import."""
    old = os.environ.get("IVOLREF_PURE_PYTHON")
    os.environ["IVOLREF_PURE_PYTHON"] = "1" if pure else "0"
    try:
        spec = importlib.util.spec_from_file_location(f"ivolref_{'pure' if pure else 'c'}", IVOLREF)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        return module
    finally:
        if old is None:
            del os.environ["IVOLREF_PURE_PYTHON"]
        else:
            os.environ["IVOLREF_PURE_PYTHON"] = old


PURE = load_reference(pure=True)
FAST = load_reference(pure=False)

# Published check values: CRC-32C from RFC 3720 B.4 and the spec's §2.1 table;
# XXH64 (seed 0) from the xxHash reference implementation's sanity tests.
CRC32C_CHECKS = [
    (b"", 0x00000000),
    (b"123456789", 0xE3069283),
    (bytes(32), 0x8A9136AA),
    (b"\xff" * 32, 0x62A8AB43),
    (bytes(range(32)), 0x46DD794E),
]
XXH64_CHECKS = [
    (b"", 0xEF46DB3751D8E999),
    (b"a", 0xD24EC4F1A98C6E5B),
    (b"abc", 0x44BC2CF5AD770999),
    (b"Nobody inspects the spammish repetition", 0xFBCEA83C8A378BF1),
]


class Backends(unittest.TestCase):
    def test_backends_are_the_ones_asked_for(self):
        self.assertEqual(PURE.checksum_backends(), {"crc32c": "pure-python", "xxh64": "pure-python"})
        # The Debian packages are installed by scripts/install-deps.sh; without
        # them the C path would silently be the pure one and go untested.
        self.assertEqual(FAST.checksum_backends(), {"crc32c": "c", "xxh64": "c"},
                         "python3-crc32c and python3-xxhash are needed (scripts/install-deps.sh)")

    def test_check_values(self):
        for module in (PURE, FAST):
            for data, want in CRC32C_CHECKS:
                with self.subTest(module=module.__name__, crc32c=data[:12]):
                    self.assertEqual(module.crc32c(data), want)
            for data, want in XXH64_CHECKS:
                with self.subTest(module=module.__name__, xxh64=data[:12]):
                    self.assertEqual(module.xxh64(data), want)

    def test_both_agree_on_random_data(self):
        rng = random.Random(19)
        # Every length up to 100 covers XXH64's tails (1, 4, 8 and 32 bytes).
        lengths = list(range(101)) + [255, 1000, 4096, 65536 + 7]
        for n in lengths:
            data = bytes(rng.getrandbits(8) for _ in range(n))
            for kind in (bytes, bytearray, memoryview):
                with self.subTest(n=n, kind=kind.__name__):
                    self.assertEqual(FAST.crc32c(kind(data)), PURE.crc32c(data))
                    self.assertEqual(FAST.xxh64(kind(data)), PURE.xxh64(data))
                    self.assertEqual(FAST.xxh64(kind(data), 7), PURE.xxh64(data, 7))

    def test_conformance_vectors_on_both_paths(self):
        manifest = os.path.join(VECTORS, "manifest.json")
        for pure in ("1", "0"):
            with self.subTest(pure=pure):
                env = dict(os.environ, IVOLREF_PURE_PYTHON=pure)
                r = subprocess.run([sys.executable, "-B", IVOLREF, "conformance", manifest], env=env,
                                   capture_output=True, text=True)
                self.assertEqual(r.returncode, 0, r.stdout[-2000:] + r.stderr[-2000:])
                self.assertRegex(r.stdout, r"\n\d+ passed, 0 failed\n?$")


if __name__ == "__main__":
    unittest.main(verbosity=1)
