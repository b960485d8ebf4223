"""Read and write .ivol volumes (industrial CT, format-spec/ivol.md) as numpy arrays.

    f = ivol.open("part.ivol")
    f.shape            # (z, y, x): numpy order
    f[10]              # slice z = 10, physical values, float32
    f[:, 100:200, ::2] # any basic index; reads only the blocks it touches
    f.stored[...]      # the stored bits (uint16, float16 or float32), bit-exact
    pyramid = [f.level(k) for k in range(f.levels)]

Axes, voxel sizes and origins are all in numpy order (z, y, x), unlike the
command line and the file, which give x, y, z.
"""

import builtins
import hashlib
import json
import os
import stat
import threading

import numpy as np

from . import _ivol
from ._errors import (  # noqa: F401 (the package's exceptions)
    ChecksumError,
    InvalidArgumentError,
    IvolError,
    IvolIOError,
    LimitExceededError,
    MalformedError,
    NotIvolError,
    TruncatedError,
    UnsupportedFeatureError,
    UnsupportedVersionError,
)
from ._indexing import plan as _plan

__all__ = ["open", "verify", "write", "File", "Level", "IvolError", "library_version"]

_STORED_DTYPES = {"uint16": np.dtype("<u2"), "binary16": np.dtype("<f2"), "float32": np.dtype("<f4")}


def library_version():
    return _ivol.library_version()


class Level:
    """Level of detail `k` of a file (spec §12.3): an array-like of
    ceil(size / 2^k) voxels per axis, each the mean of the 2^k-voxel cube it
    covers. Level 0 is the full volume. Indexing is numpy basic indexing."""

    def __init__(self, file, lod, stored=False):
        self._file = file
        self.lod = lod
        self._stored = stored
        x, y, z = file._dims
        self.shape = tuple(-(-n // (1 << lod)) for n in (z, y, x))
        self.dtype = _STORED_DTYPES[file.encoding] if stored else np.dtype(np.float32)
        self.ndim = 3

    @property
    def size(self):
        return int(np.prod(self.shape))

    def __len__(self):
        return self.shape[0]

    def __getitem__(self, key):
        lo, hi, local, empty_shape = _plan(key, self.shape)
        if empty_shape is not None:
            return np.empty(empty_shape, dtype=self.dtype)
        z_at = next(i for i, k in enumerate(local) if k is not None)
        z_key = local[z_at]
        if isinstance(z_key, slice) and abs(z_key.step) > 1:
            # Slices of z one by one: a box spanning the skipped ones would
            # read and decode their blocks too.
            planes = range(lo[0], hi[0])[z_key]
            block = np.concatenate([self._read([z, lo[1], lo[2]], [z + 1, hi[1], hi[2]]) for z in planes])
            local = local[:z_at] + (slice(None),) + local[z_at + 1 :]
        else:
            block = self._read(lo, hi)
        out = block[local]
        # A view of a larger box would keep the whole box alive.
        return out.copy() if isinstance(out, np.ndarray) and out.size < block.size else out

    def _read(self, lo, hi):
        """The box [lo, hi) (z, y, x) of this level, as an array."""
        # libformat takes boxes as (x, y, z).
        box_lo, box_hi = lo[::-1], hi[::-1]
        reader = self._file._reader()
        if self._stored:
            bits = reader.read_bits(box_lo, box_hi, self.lod)
            return bits.view(self.dtype).reshape([h - l for l, h in zip(lo, hi)])
        return reader.read(box_lo, box_hi, self.lod)

    @property
    def stored(self):
        """The same level's stored bits: uint16, float16 (binary16) or float32."""
        return Level(self._file, self.lod, stored=True)

    def __array__(self, dtype=None, copy=None):
        a = self[...]
        return a if dtype is None else a.astype(dtype, copy=False)

    def __repr__(self):
        kind = "stored bits" if self._stored else "values"
        return f"<ivol level {self.lod} of {self._file.path!r}: {kind} {self.shape} {self.dtype}>"


class File(Level):
    """An open .ivol file; indexing it reads physical values of level 0."""

    def __init__(self, path, cache_bytes=256 << 20):
        self.path = os.fspath(path)
        self._cache_bytes = cache_bytes
        self._local = threading.local()
        self._lock = threading.Lock()
        self._readers = []
        info = self._reader().info()
        self._dims = info["dims"]
        self.encoding = info["encoding"]
        self.structure = info["structure"]
        self.levels = info["depth"] + 1
        self.value_scale = info["value_scale"]
        self.value_offset = info["value_offset"]
        self.version = info["version"]
        self.file_size = info["file_size"]
        self.metadata = json.loads(info["metadata_json"])
        m = self.metadata
        self.voxel_size = tuple(float(v) for v in m["voxel_size"][::-1])
        self.origin = tuple(float(v) for v in m["origin"][::-1])
        self.unit = m["unit"]
        super().__init__(self, 0)

    def _reader(self):
        # libformat's Reader is not thread-safe: one per thread.
        reader = getattr(self._local, "reader", None)
        if reader is None:
            reader = _ivol.Reader(self.path, self._cache_bytes)
            self._local.reader = reader
            with self._lock:
                self._readers.append(reader)
        return reader

    def level(self, k, stored=False):
        """Level of detail k (0 <= k < levels) as an array-like."""
        k = int(k)
        if not 0 <= k < self.levels:
            raise InvalidArgumentError(
                f"{self.path}: level of detail {k} does not exist (this file has levels 0 .. {self.levels - 1})",
                "invalid-argument",
            )
        return Level(self, k, stored)

    @property
    def io_stats(self):
        """Bytes read from the file, blocks decoded and cache hits, summed
        over the readers of every thread that read this file."""
        total = {"bytes_read": 0, "blocks_decoded": 0, "cache_hits": 0}
        with self._lock:
            readers = list(self._readers)
        for r in readers:
            for k, v in r.io_stats().items():
                total[k] += v
        return total

    def reset_io_stats(self):
        with self._lock:
            readers = list(self._readers)
        for r in readers:
            r.reset_io_stats()

    # Pickled by path (dask's process and distributed schedulers send the
    # array-likes to other processes): the copy opens the file anew.
    def __getstate__(self):
        return {"path": self.path, "cache_bytes": self._cache_bytes}

    def __setstate__(self, state):
        self.__init__(state["path"], state["cache_bytes"])

    def close(self):
        with self._lock:
            self._readers.clear()
        self._local = threading.local()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __repr__(self):
        return (
            f"<ivol file {self.path!r}: {self.structure} {self.shape} (z, y, x), "
            f"{self.encoding}, {self.levels} levels>"
        )


def open(path, cache_bytes=256 << 20):  # noqa: A001 (the package's entry point)
    """Opens an .ivol file; raises IvolError (by class) for a bad file."""
    return File(path, cache_bytes)


def verify(path):
    """Every checksum and structural rule of the file, as a dict with the
    facts of `ivol verify --json`: path, status (ok, damaged, not-ivol,
    unsupported, missing, unreadable), error_class (None when ok), problems,
    blocks_checked, blocks_damaged, tree_checked, bytes and sha256. Never
    raises for a bad file."""
    path = os.fspath(path)
    r = {"path": path, "status": None, "error_class": None}
    try:
        st = os.stat(path)
    except OSError as e:
        r["status"] = "missing" if isinstance(e, (FileNotFoundError, NotADirectoryError)) else "unreadable"
        r["error_class"] = "io"
        r["message"] = os.strerror(e.errno)
        return r
    if not stat.S_ISREG(st.st_mode):
        r["status"] = "unreadable"
        r["error_class"] = "io"
        r["message"] = "a directory, not a file" if stat.S_ISDIR(st.st_mode) else "not a regular file"
        return r
    report = _ivol.check(path)
    if report["problems"]:
        first = report["problems"][0]["error_class"]
        r["error_class"] = first
        r["status"] = {
            "not-ivol": "not-ivol",
            "io": "unreadable",
            "unsupported-version": "unsupported",
            "unsupported-feature": "unsupported",
        }.get(first, "damaged")
    else:
        r["status"] = "ok"
    try:
        digest = hashlib.sha256()
        size = 0
        with builtins.open(path, "rb") as f:
            for chunk in iter(lambda: f.read(1 << 20), b""):
                digest.update(chunk)
                size += len(chunk)
        r["bytes"] = size
        r["sha256"] = digest.hexdigest()
    except OSError as e:
        r["status"] = "unreadable"
        r["error_class"] = "io"
        r["message"] = f"{path}: {e.strerror}"
    r.update(report)
    return r


_SAMPLE_NAMES = {
    np.dtype(np.uint8): "u8",
    np.dtype(np.uint16): "u16",
    np.dtype(np.int16): "i16",
    np.dtype(np.float16): "f16",
    np.dtype(np.float32): "f32",
}


def write(
    path,
    array,
    voxel_size=(1.0, 1.0, 1.0),
    origin=(0.0, 0.0, 0.0),
    unit="mm",
    encoding=None,
    quantity=None,
    value_unit=None,
    provenance=None,
    block_bytes=0,
    byte_planes=True,
):
    """Writes a 3-D array (z, y, x) as a lossless octree .ivol file, as
    `ivol convert` writes the same samples from a raw file: the same file,
    byte for byte, given the same provenance. voxel_size and origin are in
    (z, y, x) order. encoding: None (lossless: uint16 for integer arrays,
    binary16 for float16, float32 for float32), "uint16", "binary16" or
    "float32". provenance: a dict merged into the default provenance.
    The file appears at `path` only when complete."""
    a = np.asarray(array)
    if a.ndim != 3:
        raise InvalidArgumentError(f"{path}: a volume needs 3 dimensions (z, y, x), not {a.ndim}", "invalid-argument")
    name = _SAMPLE_NAMES.get(a.dtype.newbyteorder("="))
    if name is None:
        raise InvalidArgumentError(
            f"{path}: samples of type {a.dtype} cannot be written; use uint8, uint16, int16, float16 or float32 "
            "(e.g. array.astype(numpy.float32))",
            "invalid-argument",
        )
    a = np.ascontiguousarray(a, dtype=a.dtype.newbyteorder("<"))
    if 0 in a.shape:
        raise InvalidArgumentError(f"{path}: the volume is empty {a.shape}", "invalid-argument")
    vz, vy, vx = (float(v) for v in voxel_size)
    oz, oy, ox = (float(v) for v in origin)
    return _ivol.write(
        os.fspath(path),
        a,
        name,
        (a.shape[2], a.shape[1], a.shape[0]),
        encoding or "",
        (vx, vy, vz),
        (ox, oy, oz),
        unit,
        quantity or "",
        value_unit or "",
        json.dumps(provenance) if provenance else "",
        int(block_bytes),
        bool(byte_planes),
    )

