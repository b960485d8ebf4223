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
from ._indexing import pieces as _pieces
from ._indexing import plan as _plan
from ._writing import write, write_structure  # noqa: F401 (the package's writers)

__all__ = ["open", "verify", "write", "write_structure", "File", "Level", "IvolError", "library_version"]

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
        return self._get(key, self._file._salvage, None)

    def read_salvaged(self, key=Ellipsis):
        """(array, damaged) for `key`: blocks that are damaged or missing do
        not stop the read; their voxels take the value of the nearest
        coarser level that survived (spec §18; a grid, which has none, reads
        stored code 0 there), and `damaged` lists those regions as dicts:
        lo and hi (z, y, x, half-open, in this level's voxels), level (the
        octree level where the damage was met) and message (which block)."""
        damaged = []
        out = self._get(key, True, damaged)
        unique = {(d["lo"], d["hi"], d["level"], d["message"]): d for d in damaged}
        return out, list(unique.values())

    def _get(self, key, salvage, damaged):
        _, _, _, empty_shape = _plan(key, self.shape)
        if empty_shape is not None:
            return np.empty(empty_shape, dtype=self.dtype)
        out_shape, squeeze, boxes = _pieces(key, self.shape)
        if len(boxes) == 1:
            lo, hi, _, box_slices = boxes[0]
            block = self._read(lo, hi, salvage, damaged)
            out = block[box_slices][squeeze]
            # A view of a larger box would keep the whole box alive.
            return out.copy() if isinstance(out, np.ndarray) and out.size < block.size else out
        # Several boxes (a step along z, or a wide one along y or x): each
        # reads only the blocks its voxels lie in.
        out = np.empty(out_shape, dtype=self.dtype)
        for lo, hi, out_slices, box_slices in boxes:
            out[out_slices] = self._read(lo, hi, salvage, damaged)[box_slices]
        return out[squeeze]

    def _read(self, lo, hi, salvage, damaged):
        """The box [lo, hi) (z, y, x) of this level, as an array; with
        salvage, the regions filled from coarser levels go into `damaged`."""
        # libformat takes boxes as (x, y, z).
        box_lo, box_hi = lo[::-1], hi[::-1]
        reader = self._file._reader()
        read = reader.read_bits if self._stored else reader.read
        out = read(box_lo, box_hi, self.lod, salvage)
        if salvage:
            out, regions = out
            if damaged is not None:
                damaged.extend(
                    {"lo": r["lo"][::-1], "hi": r["hi"][::-1], "level": r["level"], "message": r["message"]}
                    for r in regions
                )
        if self._stored:
            return out.view(self.dtype).reshape([h - l for l, h in zip(lo, hi)])
        return out

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

    def __init__(self, path, cache_bytes=256 << 20, salvage=False):
        self.path = os.fspath(path)
        self._cache_bytes = cache_bytes
        self._salvage = bool(salvage)
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
        # What a salvaging open found when the index could not be used
        # (None when the file opened as it is).
        self.salvage = info["salvage"]
        # Why a salvaging open read the file without its metadata block (the
        # defaults stand in for it); None when it was read.
        self.metadata_problem = info["metadata_problem"] or None
        m = self.metadata
        # None where the file says nobody knew it (ivol convert of a raw file
        # without --voxel-size): the stored 1s are no measurement; nor are
        # the defaults a salvaging open puts in place of lost metadata.
        provenance = m.get("provenance")
        marked_unknown = isinstance(provenance, dict) and provenance.get("voxel_size_known") is False
        known = self.metadata_problem is None and not marked_unknown
        self.voxel_size = tuple(float(v) for v in m["voxel_size"][::-1]) if known else None
        self.origin = tuple(float(v) for v in m["origin"][::-1])
        self.unit = m["unit"]
        super().__init__(self, 0)

    def _reader(self):
        # libformat's Reader is not thread-safe: one per thread.
        reader = getattr(self._local, "reader", None)
        if reader is None:
            reader = _ivol.Reader(self.path, self._cache_bytes, self._salvage)
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
        return {"path": self.path, "cache_bytes": self._cache_bytes, "salvage": self._salvage}

    def __setstate__(self, state):
        self.__init__(state["path"], state["cache_bytes"], state.get("salvage", False))

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


def open(path, cache_bytes=256 << 20, salvage=False):  # noqa: A001 (the package's entry point)
    """Opens an .ivol file; raises IvolError (by class) for a bad file.

    salvage=True opens a cut or damaged format 1.3 file whose footer or index
    cannot be used by scanning its framed blocks (spec §18); `f.salvage` then
    says what was found, and reads fill damaged or missing regions from the
    nearest coarser level (`f.read_salvaged(key)` also lists them)."""
    return File(path, cache_bytes, salvage)


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
