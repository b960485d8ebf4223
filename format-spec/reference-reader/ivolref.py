#!/usr/bin/python3
"""ivolref.py -- independent reference reader for the .ivol format, version 1.3 (draft).

Written from format-spec/ivol.md alone (no code of the ivol project was read).
Section numbers (§n) below refer to that document.  Where the specification
left a choice open, the choice made here is listed in SPEC-NOTES.md next to
this file, and the code cites it as "SPEC-NOTES n" at that place.

Needs Python 3 with numpy and zstandard (Debian: python3-numpy,
python3-zstandard).  Usage:

    ivolref.py check FILE               full verification; prints "ok"
    ivolref.py dense FILE -o OUT        full verification + dense export (§12.2)
    ivolref.py lod FILE K -o OUT        level of detail K (§12.3), partial read
    ivolref.py info FILE                JSON summary of header, index, metadata
    ivolref.py conformance MANIFEST     run a set of test vectors
    ivolref.py salvage FILE -o OUT      salvage a cut or damaged framed file (§18)

Exit status: 0 success; 1 the file was refused ("error: <class>: <message>");
2 usage or I/O error; 3 the file exceeds this reader's own limits (§13 allows
them; not an error of the file); 4 internal error of this reader (a bug).
"""

import argparse
import bisect
import collections
import json
import math
import os
import signal
import struct
import sys

import numpy as np
import zstandard


# ============================================================ errors (§13)

ERROR_CLASSES = ("not-ivol", "unsupported-version", "unsupported-feature",
                 "truncated", "checksum", "malformed")


class IvolError(Exception):
    """The file is refused; `cls` is one of the error classes of §13.
    `reason`, where given, names the check that failed (for example
    "codec3.entropy3.present_zero"); None elsewhere."""

    def __init__(self, cls, message, reason=None):
        assert cls in ERROR_CLASSES
        super().__init__("%s: %s" % (cls, message))
        self.cls = cls
        self.message = message
        self.reason = reason


class ReaderLimit(Exception):
    """The file exceeds a limit of this reader (§13, last paragraphs)."""


class UsageError(Exception):
    """The command line asks for something impossible (exit status 2)."""


def fail(cls, message, reason=None):
    raise IvolError(cls, message, reason)


# Limits of this reader (lower than the format allows, as §13 permits).
LIMIT_DECODED_BYTES = 1 << 30    # node array + value array held in memory
LIMIT_OUTPUT_BYTES = 1 << 30     # dense export / level of detail


# ============================================================ §2.1 CRC-32C

def _crc32c_table():
    table = []
    for n in range(256):
        crc = n
        for _ in range(8):
            crc = (crc >> 1) ^ (0x82F63B78 if crc & 1 else 0)
        table.append(crc)
    return table


_CRC32C_TABLE = _crc32c_table()


def crc32c_pure(data):
    """CRC-32C (Castagnoli), reflected, init and final XOR 0xFFFFFFFF (§2.1)."""
    table = _CRC32C_TABLE
    crc = 0xFFFFFFFF
    for b in data:
        crc = table[(crc ^ b) & 0xFF] ^ (crc >> 8)
    return crc ^ 0xFFFFFFFF


# Debian's python3-crc32c computes the same CRC in C, about 100 times faster.
# IVOLREF_PURE_PYTHON=1 keeps the pure-Python code above (the tests run both).
_PURE = os.environ.get("IVOLREF_PURE_PYTHON", "") not in ("", "0")
try:
    if _PURE:
        raise ImportError
    import crc32c as _crc32c_module

    def crc32c(data):
        return _crc32c_module.crc32c(data)
except ImportError:
    crc32c = crc32c_pure


def _selftest_crc32c():
    # The check values of the table in §2.1.
    assert crc32c(b"123456789") == 0xE3069283
    assert crc32c(bytes(32)) == 0x8A9136AA
    assert crc32c(b"\xff" * 32) == 0x62A8AB43


# ============================================================ XXH64
# The zstd content checksum (RFC 8878 §3.1.1) is the low 32 bits of XXH64 of
# the decompressed content with seed 0.  Implemented here so that a wrong
# content checksum is told apart from other damage (error class `checksum`).

_P1, _P2, _P3 = 0x9E3779B185EBCA87, 0xC2B2AE3D27D4EB4F, 0x165667B19E3779F9
_P4, _P5 = 0x85EBCA77C2B2AE63, 0x27D4EB2F165667C5
_M64 = (1 << 64) - 1


def _rotl64(x, r):
    return ((x << r) | (x >> (64 - r))) & _M64


def _xxh_round(acc, lane):
    acc = (acc + lane * _P2) & _M64
    return (_rotl64(acc, 31) * _P1) & _M64


def xxh64_pure(data, seed=0):
    n = len(data)
    p = 0
    if n >= 32:
        v1 = (seed + _P1 + _P2) & _M64
        v2 = (seed + _P2) & _M64
        v3 = seed
        v4 = (seed - _P1) & _M64
        stripes = n // 32
        for a, b, c, d in struct.iter_unpack("<4Q", data[:stripes * 32]):
            v1 = _xxh_round(v1, a)
            v2 = _xxh_round(v2, b)
            v3 = _xxh_round(v3, c)
            v4 = _xxh_round(v4, d)
        p = stripes * 32
        h = (_rotl64(v1, 1) + _rotl64(v2, 7) + _rotl64(v3, 12) + _rotl64(v4, 18)) & _M64
        for v in (v1, v2, v3, v4):
            h = ((h ^ _xxh_round(0, v)) * _P1 + _P4) & _M64
    else:
        h = (seed + _P5) & _M64
    h = (h + n) & _M64
    while p + 8 <= n:
        (lane,) = struct.unpack_from("<Q", data, p)
        h = (_rotl64(h ^ _xxh_round(0, lane), 27) * _P1 + _P4) & _M64
        p += 8
    if p + 4 <= n:
        (lane,) = struct.unpack_from("<I", data, p)
        h = (_rotl64(h ^ ((lane * _P1) & _M64), 23) * _P2 + _P3) & _M64
        p += 4
    while p < n:
        h = (_rotl64(h ^ ((data[p] * _P5) & _M64), 11) * _P1) & _M64
        p += 1
    h ^= h >> 33
    h = (h * _P2) & _M64
    h ^= h >> 29
    h = (h * _P3) & _M64
    h ^= h >> 32
    return h


# Debian's python3-xxhash: the same hash in C (unless IVOLREF_PURE_PYTHON=1).
try:
    if _PURE:
        raise ImportError
    import xxhash as _xxhash_module

    def xxh64(data, seed=0):
        return _xxhash_module.xxh64_intdigest(data, seed)
except ImportError:
    xxh64 = xxh64_pure


def checksum_backends():
    """Which code computes CRC-32C and XXH64: "c" (python3-crc32c,
    python3-xxhash) or "pure-python"."""
    return {"crc32c": "pure-python" if crc32c is crc32c_pure else "c",
            "xxh64": "pure-python" if xxh64 is xxh64_pure else "c"}


# ============================================================ file access

class FileReader:
    """Reads byte ranges of the file; never outside it (§13)."""

    def __init__(self, path):
        self.f = open(path, "rb")
        self.size = os.fstat(self.f.fileno()).st_size

    def read(self, offset, size):
        # Every caller has checked the range against self.size before.
        if offset < 0 or size < 0 or offset + size > self.size:
            raise AssertionError("read outside the file")
        self.f.seek(offset)
        data = self.f.read(size)
        if len(data) != size:   # the file shrank while we read it
            fail("truncated", "file ended at offset %d while reading %d bytes"
                 % (offset + len(data), size))
        return data

    def close(self):
        self.f.close()


# ============================================================ §4 Header

SIGNATURE = b"\x89IVOL\r\n\n"

Header = collections.namedtuple(
    "Header", "version_major version_minor header_size "
              "required_features optional_features framed descriptor")
FEATURE_FRAMED_BLOCKS = 1        # §14.3: required feature bit 0 (since 1.3)


def read_header(r):
    """§4, checked in the order of §13 steps 1 to 3."""
    head = r.read(0, min(r.size, 16))
    # Step 1: signature (an empty file is truncated, SPEC-NOTES 2).
    n = min(r.size, 8)
    if head[:n] != SIGNATURE[:n]:
        fail("not-ivol", "header: bytes 0..%d are %s, expected the signature %s"
             % (n, head[:n].hex(" "), SIGNATURE.hex(" ")))
    if r.size < 8:
        fail("truncated", "file is %d bytes long, shorter than the signature" % r.size)
    # Step 2: version_major (SPEC-NOTES 3: read when its 2 bytes are present).
    if r.size < 10:
        fail("truncated", "file is %d bytes long, ends inside version_major" % r.size)
    (major,) = struct.unpack_from("<H", head, 8)
    if major != 1:
        fail("unsupported-version",
             "header: version_major at offset 8 is %d, this reader knows 1" % major)
    if r.size < 12:
        fail("truncated", "file is %d bytes long, shorter than 12 bytes" % r.size)
    (minor,) = struct.unpack_from("<H", head, 10)
    # Step 3: header_size, file size, header_crc, reserved, required features.
    if r.size < 16:
        fail("truncated", "file is %d bytes long, ends inside header_size" % r.size)
    (header_size,) = struct.unpack_from("<I", head, 12)
    if not 40 <= header_size <= 4096:
        fail("malformed", "header: header_size at offset 12 is %d, expected 40..4096"
             % header_size)
    if r.size < header_size + 32:
        fail("truncated", "file is %d bytes long, shorter than header (%d) + footer (32)"
             % (r.size, header_size))
    hdr = r.read(0, header_size)
    (stored_crc,) = struct.unpack_from("<I", hdr, header_size - 4)
    actual = crc32c(hdr[:header_size - 4])
    if actual != stored_crc:
        fail("checksum", "header: header_crc at offset %d is 0x%08X, CRC-32C of bytes "
             "0..%d is 0x%08X" % (header_size - 4, stored_crc, header_size - 4, actual))
    required, optional, reserved = struct.unpack_from("<QQI", hdr, 16)
    if reserved != 0:
        fail("malformed", "header: reserved field at offset 32 is 0x%08X, expected 0"
             % reserved)
    # Bit 0 (framed_blocks, §4.1) is the only required feature known: name the others.
    unknown = required & ~FEATURE_FRAMED_BLOCKS
    if unknown != 0:
        bits = [b for b in range(64) if unknown >> b & 1]
        fail("unsupported-feature", "header: required_features has unknown bit(s) %s"
             % ", ".join(map(str, bits)))
    framed = bool(required & FEATURE_FRAMED_BLOCKS)
    descriptor = None
    if framed:   # §4.1: the volume descriptor, compared with the index in step 5
        if header_size < 80:
            fail("malformed", "header: header_size %d, expected >= 80 with required "
                 "feature bit 0 (framed_blocks)" % header_size)
        if hdr[68:76] != bytes(8):
            fail("malformed", "header: reserved bytes 68..76 are %s, expected 0"
                 % hdr[68:76].hex(" "))
        descriptor = hdr[36:68]
    # optional_features: ignored (§14.2).  Other bytes up to header_size - 4: skipped (§4).
    return Header(major, minor, header_size, required, optional, framed, descriptor)


# ============================================================ §5 Footer

END_SIGNATURE = b"IVOL_END"

Footer = collections.namedtuple("Footer", "index_offset index_size index_crc")


def read_footer(r, header):
    """§5, checked in the order of §13 step 4.  Returns the footer and the index bytes."""
    at = r.size - 32
    ft = r.read(at, 32)
    if ft[24:32] != END_SIGNATURE:
        fail("truncated", "footer: bytes at offset %d are %s, expected end_signature "
             "'IVOL_END'" % (at + 24, ft[24:32].hex(" ")))
    index_offset, index_size, index_crc, footer_crc = struct.unpack_from("<QQII", ft, 0)
    actual = crc32c(ft[:20])
    if actual != footer_crc:
        fail("checksum", "footer: footer_crc at offset %d is 0x%08X, CRC-32C of footer "
             "bytes 0..20 is 0x%08X" % (at + 20, footer_crc, actual))
    if index_offset < header.header_size:
        fail("malformed", "footer: index_offset %d is less than header_size %d"
             % (index_offset, header.header_size))
    if index_offset + index_size + 32 != r.size:
        fail("malformed", "footer: index_offset %d + index_size %d + 32 = %d, expected "
             "the file size %d" % (index_offset, index_size,
                                   index_offset + index_size + 32, r.size))
    blocks_bytes = index_offset - header.header_size   # §5: each block is >= 1 byte
    max_index = 4096 + 8 * 32 + 4096 * blocks_bytes
    if index_size > max_index:
        fail("malformed", "footer: index_size %d exceeds %d, what %d bytes of blocks allow"
             % (index_size, max_index, blocks_bytes))
    index = r.read(index_offset, index_size)
    actual = crc32c(index)
    if actual != index_crc:
        fail("checksum", "index: index_crc (footer offset %d) is 0x%08X, CRC-32C of the "
             "%d index bytes at offset %d is 0x%08X"
             % (at + 16, index_crc, index_size, index_offset, actual))
    return Footer(index_offset, index_size, index_crc), index


# ============================================================ §6 Index

INDEX_SIGNATURE = b"IVIX"
ENCODINGS = {1: ("binary16", 2), 2: ("uint16", 2), 3: ("float32", 4)}   # §9
STREAM_METADATA, STREAM_NODES, STREAM_VALUES = 1, 2, 3                  # §6.4
STREAM_BORDERS, STREAM_CELLS = 4, 5                                    # §6.4, since 1.1
STREAM_STORED_LOD = 7                                                  # §6.4, §8A.5, since 1.3
STREAM_NAMES = {1: "metadata", 2: "nodes", 3: "values", 4: "borders", 5: "cells",
                7: "stored level of detail"}
KNOWN_STREAMS = frozenset(STREAM_NAMES)


def known_stream(stream, kind):
    """§6.4 (1.1): streams 1-3 are known in every file; stream 4 only in a
    rectilinear grid (kind 3) and stream 5 only in a nested grid (kind 4). In
    files of other kinds they are unknown streams, as in version 1.0.  The
    same holds for stream 7 (1.3), known only in a bricked grid (kind 5).
    Stream 6 (early metadata) is never "known" here: it is ignorable and this
    reader does not use it except when salvaging."""
    if stream == STREAM_BORDERS:
        return kind == KIND_RECTILINEAR
    if stream == STREAM_CELLS:
        return kind == KIND_NESTED
    if stream == STREAM_STORED_LOD:
        return kind == KIND_BRICKED
    return stream in KNOWN_STREAMS
KIND_OCTREE, KIND_REGULAR, KIND_RECTILINEAR, KIND_NESTED = 1, 2, 3, 4   # §6.1, §8, §8A
KIND_BRICKED = 5                                                       # §8A.4 (1.3)
KIND_NAMES = {1: "octree", 2: "regular grid", 3: "rectilinear grid", 4: "nested grid",
              5: "bricked regular grid"}
MAX_BRICK_LOG2 = 8                                                     # §6.1 byte 11
PREDICTED_HEADER = 24                                                  # §7.2
MASKED_HEADER = 4                                                      # §7.3
TOP_BYTE_HEADER = 8                                                    # §7.4
TOP_BYTE_LIMIT_EXTRA = 12                                              # §7: 12 + w·n
MAX_BLOCK_DECODED = 64 * 1024 * 1024                                   # §7
MAX_METADATA = 16 * 1024 * 1024                                        # §11

BlockEntry = collections.namedtuple(
    "BlockEntry", "number file_offset first_element element_count stored_size "
                  "crc stream codec flags level")


class Index:
    """The decoded index (§6.1 fixed part, §6.2 level table, §6.3 block table)."""

    def where(self, e):
        """How error messages name a block (§13)."""
        return "block %d (stream %d%s, level %d, at offset %d)" % (
            e.number, e.stream,
            " " + STREAM_NAMES[e.stream] if known_stream(e.stream, self.structure_kind) else "",
            e.level, e.file_offset)


def read_index(header, footer, idx):
    """§6, checked in the order of §13 step 5 (without the metadata block)."""
    ix = Index()
    ix.header = header
    ix.footer = footer
    base = footer.index_offset
    # ---- §6.1 fixed part
    if len(idx) < 48:
        fail("malformed", "index: index_size %d is smaller than the fixed part (48)"
             % len(idx))
    (sig, fixed_size, structure_kind, value_encoding, depth, cell_log2,
     size_x, size_y, size_z, value_scale, value_offset,
     block_count, block_entry_size) = struct.unpack_from("<4sI4B3I2d2I", idx, 0)
    if sig != INDEX_SIGNATURE:   # SPEC-NOTES 6: class not stated; malformed
        fail("malformed", "index: index_signature at offset %d is %s, expected 'IVIX'"
             % (base, sig.hex(" ")))
    if not 48 <= fixed_size <= 4096:
        fail("malformed", "index: fixed_size %d, expected 48..4096" % fixed_size)
    if structure_kind not in KIND_NAMES:
        fail("unsupported-feature", "index: structure_kind %d, this reader knows 1 "
             "(octree), 2 (regular grid), 3 (rectilinear grid), 4 (nested grid), "
             "5 (bricked regular grid)" % structure_kind)
    if value_encoding not in ENCODINGS:
        fail("unsupported-feature", "index: value_encoding %d, this reader knows 1, 2, 3"
             % value_encoding)
    if depth > 31:
        fail("malformed", "index: depth %d, expected 0..31" % depth)
    if structure_kind == KIND_NESTED:   # §6.1 byte 11: cell_log2 (SPEC-NOTES 47, 48)
        if not 1 <= cell_log2 <= 31:
            fail("malformed", "index: cell_log2 (index offset 11) is %d, expected 1..31 "
                 "for structure_kind 4 (nested grid)" % cell_log2)
    elif structure_kind == KIND_BRICKED:   # §6.1 byte 11: b, log2 of the brick edge
        if not 1 <= cell_log2 <= MAX_BRICK_LOG2:
            fail("malformed", "index: brick log2 (index offset 11) is %d, expected 1..%d "
                 "for structure_kind 5 (bricked regular grid)" % (cell_log2, MAX_BRICK_LOG2))
        if not header.framed:   # §8A.4
            fail("malformed", "index: structure_kind 5 (bricked regular grid) needs framed "
                 "blocks (required feature bit 0)")
    elif cell_log2 != 0:
        fail("malformed", "index: reserved byte at index offset 11 is %d, expected 0 "
             "for structure_kind %d" % (cell_log2, structure_kind))
    for name, v in (("size_x", size_x), ("size_y", size_y), ("size_z", size_z)):
        if v < 1:
            fail("malformed", "index: %s is 0, expected >= 1" % name)
    expected_depth = (max(size_x, size_y, size_z) - 1).bit_length()
    if depth != expected_depth:
        fail("malformed", "index: depth %d, expected %d for %dx%dx%d voxels"
             % (depth, expected_depth, size_x, size_y, size_z))
    if not (math.isfinite(value_scale) and value_scale != 0):
        fail("malformed", "index: value_scale %r, expected finite and non-zero"
             % value_scale)
    if not math.isfinite(value_offset):
        fail("malformed", "index: value_offset %r, expected finite" % value_offset)
    if header.framed and header.descriptor != idx[8:40]:   # §4.1
        fail("malformed", "header: the volume descriptor (bytes 36..68) is %s, the "
             "index's fixed part bytes 8..40 are %s" % (header.descriptor.hex(" "),
                                                        idx[8:40].hex(" ")))
    if block_count < 2:
        fail("malformed", "index: block_count %d, expected >= 2" % block_count)
    if not 32 <= block_entry_size <= 4096:
        fail("malformed", "index: block_entry_size %d, expected 32..4096"
             % block_entry_size)
    D = depth
    expected_size = fixed_size + 8 * (D + 1) + block_count * block_entry_size
    if len(idx) != expected_size:   # §6.3; checked here, before the tables are read
        fail("malformed", "index: index_size %d, expected fixed_size %d + 8 x %d + "
             "block_count %d x block_entry_size %d = %d"
             % (len(idx), fixed_size, D + 1, block_count, block_entry_size,
                expected_size))
    ix.structure_kind = structure_kind
    ix.structure_name = KIND_NAMES[structure_kind]
    ix.cell_log2 = cell_log2
    ix.value_encoding = value_encoding
    ix.encoding_name, ix.width = ENCODINGS[value_encoding]
    ix.depth = D
    ix.size = (size_x, size_y, size_z)
    ix.value_scale, ix.value_offset = value_scale, value_offset
    ix.fixed_size, ix.block_entry_size = fixed_size, block_entry_size

    # ---- §6.2 level table
    counts = list(struct.unpack_from("<%dQ" % (D + 1), idx, fixed_size))
    if structure_kind != KIND_OCTREE:   # §6.2: all zero for the kinds of §8A
        for l in range(D + 1):
            if counts[l] != 0:
                fail("malformed", "level table: inner_count[%d] is %d, expected 0 for "
                     "structure_kind %d (%s)" % (l, counts[l], structure_kind,
                                                 ix.structure_name))
    if counts[0] > 1:
        fail("malformed", "level table: inner_count[0] is %d, expected 0 or 1" % counts[0])
    if counts[D] != 0:
        fail("malformed", "level table: inner_count[%d] (last level) is %d, expected 0"
             % (D, counts[D]))
    for l in range(D):
        if counts[l + 1] > 8 * counts[l]:
            fail("malformed", "level table: inner_count[%d] = %d exceeds 8 x "
                 "inner_count[%d] = %d" % (l + 1, counts[l + 1], l, 8 * counts[l]))
    for l in range(D + 1):   # implied by the rule above; checked as §6.2 lists it
        if counts[l] == 0 and any(counts[m] for m in range(l + 1, D + 1)):
            fail("malformed", "level table: inner_count[%d] is 0 but a deeper level "
                 "has inner nodes" % l)
    ix.inner_count = counts
    ix.total_inner = sum(counts)
    ix.total_values = 1 + 8 * ix.total_inner
    ix.first_inner = [sum(counts[:l]) for l in range(D + 1)]
    ix.level_values = [1] + [8 * counts[l - 1] for l in range(1, D + 1)]
    ix.first_value = [0] + [1 + 8 * ix.first_inner[l - 1] for l in range(1, D + 1)]
    if structure_kind != KIND_OCTREE:
        # §6.2: the numbering does not apply; §8A gives the number of values.
        ix.total_inner = None
        ix.first_inner = ix.first_value = ix.level_values = None
        ix.total_values = None          # kinds 3 and 4: known once stream 4/5 is read
        if structure_kind in (KIND_REGULAR, KIND_BRICKED):
            ix.total_values = size_x * size_y * size_z          # §8A.1, §8A.4
        if structure_kind == KIND_NESTED:
            C = 1 << cell_log2                                  # §8A.3
            ix.cells = tuple(-(-n // C) for n in ix.size)       # n_a = ceil(size_a / C)
            ix.cell_count = ix.cells[0] * ix.cells[1] * ix.cells[2]

    # ---- §6.3 block table (per entry, in table order; SPEC-NOTES 7)
    at = fixed_size + 8 * (D + 1)
    expected_offset = header.header_size
    entries = []
    for number in range(block_count):
        e = BlockEntry(number, *struct.unpack_from("<QQIIIBBBB", idx, at))
        at += block_entry_size           # bytes 32 .. block_entry_size: skipped
        if e.file_offset != expected_offset:
            fail("malformed", "block table: block %d has file_offset %d, expected %d "
                 "(blocks follow each other without gaps from header_size)"
                 % (number, e.file_offset, expected_offset))
        expected_offset = e.file_offset + e.stored_size
        if e.element_count < 1:
            fail("malformed", "block table: %s has element_count 0" % ix.where(e))
        if e.stored_size < 1:
            fail("malformed", "block table: %s has stored_size 0" % ix.where(e))
        if header.framed and e.stored_size <= BLOCK_HEADER_SIZE:   # §7.1
            fail("malformed", "block table: %s has stored_size %d, which leaves no "
                 "payload after the 32-byte block header" % (ix.where(e), e.stored_size))
        if e.flags & 0xFE:
            fail("malformed", "block table: %s has reserved flag bits set (flags 0x%02X)"
                 % (ix.where(e), e.flags))
        if not known_stream(e.stream, structure_kind):   # §6.4: reserved or unknown here
            if not e.flags & 1:
                fail("unsupported-feature", "block table: %s belongs to unknown stream %d "
                     "and is not ignorable" % (ix.where(e), e.stream))
            entries.append(e)    # ignorable: skipped (SPEC-NOTES 12 for its CRC)
            continue
        if e.stream == STREAM_STORED_LOD:     # §6.4, §8A.5 (SPEC-NOTES 61, 62)
            check_stored_lod_entry(ix, e)
        elif e.flags != 0:
            fail("malformed", "block table: %s has flags 0x%02X, expected 0 for stream %d"
                 % (ix.where(e), e.flags, e.stream))
        check_stream_kind(ix, e)
        check_block_level(ix, e)
        if e.codec in (3, 4) and not (e.stream in (STREAM_VALUES, STREAM_STORED_LOD)
                                      and structure_kind == KIND_BRICKED
                                      and value_encoding in (1, 2)):   # §7 codecs 3 and 4
            fail("malformed", "block table: %s: codec %d is valid only on values and stored "
                 "level of detail blocks of a bricked regular grid of 16-bit values"
                 % (ix.where(e), e.codec))
        if e.codec == CODEC_TOP_BYTE and not (e.stream in (STREAM_VALUES, STREAM_STORED_LOD)
                                              and structure_kind == KIND_BRICKED
                                              and value_encoding in (1, 2, 3)):
            # §7 codec 6: 2- or 4-byte values (SPEC-NOTES 91)
            fail("malformed", "block table: %s: codec 6 (top byte in context) is valid only on "
                 "values and stored level of detail blocks of a bricked regular grid of 2- or "
                 "4-byte values" % ix.where(e))
        if e.codec == CODEC_PLANE_FRAMES and stream_width(ix, e.stream) < 2:   # §7 codec 5
            fail("malformed", "block table: %s: codec 5 (byte planes, a zstd frame each) is "
                 "valid only on streams whose elements are wider than one byte, not on the "
                 "metadata (width 1)" % ix.where(e))
        if e.stream == STREAM_STORED_LOD or e.codec in (CODEC_PLANE_FRAMES, CODEC_TOP_BYTE):
            # §8A.5, §7: the limits of §7 with the block table (SPEC-NOTES 64, 81, 87)
            check_block_limits(ix, e)
        entries.append(e)
    if expected_offset != footer.index_offset:
        fail("malformed", "block table: the last block ends at %d, expected index_offset %d"
             % (expected_offset, footer.index_offset))
    ix.blocks = entries

    # ---- §6.4 streams
    meta = [e for e in entries if e.stream == STREAM_METADATA]
    if len(meta) != 1:
        fail("malformed", "block table: %d blocks of stream 1 (metadata), expected 1"
             % len(meta))
    ix.metadata_block = meta[0]
    if structure_kind == KIND_OCTREE:
        check_stream_coverage(ix, STREAM_NODES, ix.total_inner)
        check_stream_coverage(ix, STREAM_VALUES, ix.total_values)
        return ix
    # §6.4 for the kinds of §8A (SPEC-NOTES 44, 45): stream 4 always with
    # kind 3, stream 5 always with kind 4; coverage of streams 3, 4, 5.
    for stream, kind in ((STREAM_BORDERS, KIND_RECTILINEAR), (STREAM_CELLS, KIND_NESTED)):
        if structure_kind == kind and not any(e.stream == stream for e in entries):
            fail("malformed", "block table: no block of stream %d (%s), which structure_"
                 "kind %d (%s) always has" % (stream, STREAM_NAMES[stream], kind,
                                              KIND_NAMES[kind]))
    # Stream 3: without gap or overlap from element 0; its total is checked here
    # for the regular grid, and against §8A once stream 4 or 5 is read otherwise.
    ix.value_elements = check_stream_coverage(ix, STREAM_VALUES, ix.total_values)
    if structure_kind == KIND_RECTILINEAR:
        ix.border_elements = check_stream_coverage(ix, STREAM_BORDERS, None)
        limit = size_x + size_y + size_z + 3      # §8A.2, before allocating
        if ix.border_elements > limit:
            fail("malformed", "block table: stream 4 (borders) holds %d elements, at most "
                 "size_x + size_y + size_z + 3 = %d are possible"
                 % (ix.border_elements, limit))
    if structure_kind == KIND_NESTED:
        check_stream_coverage(ix, STREAM_CELLS, ix.cell_count)
    if structure_kind == KIND_BRICKED:
        ix.brick_of = {}
        check_bricks(ix, [e for e in entries if e.stream == STREAM_VALUES], 0)
        ix.stored_levels = check_stored_levels(ix, entries)
    return ix


def level_size(size, k):
    """§12.3, §8A.5: level of detail k has ceil(size_a / 2^k) elements along axis a."""
    return tuple(-(-s // (1 << k)) for s in size)


def check_stored_lod_entry(ix, e):
    """§6.4, §8A.5: a block of stream 7 has the ignorable flag set (the reserved
    flag bits were checked before) and a level k with 1 <= k <= D."""
    if not e.flags & 1:
        fail("malformed", "block table: %s: a stored level of detail block (stream 7) must "
             "have the ignorable flag set, its flags are 0x%02X" % (ix.where(e), e.flags))
    if not 1 <= e.level <= ix.depth:
        fail("malformed", "block table: %s: a stored level of detail must have a level 1..%d "
             "(depth), this block has level %d" % (ix.where(e), ix.depth, e.level))


def check_stored_levels(ix, entries):
    """§8A.5: the blocks of each stored level k cover the level's elements
    0 .. m_x·m_y·m_z exactly once, and each holds one brick of the level (or,
    codec 4, a run of whole bricks), the bricks of §8A.4 with the sizes m_a.
    Returns the stored levels, in increasing order."""
    by_level = collections.defaultdict(list)
    for e in entries:
        if e.stream == STREAM_STORED_LOD:
            by_level[e.level].append(e)
    for k in sorted(by_level):
        mx, my, mz = level_size(ix.size, k)
        check_coverage(ix, by_level[k], mx * my * mz, "stream 7 (stored level of detail %d)" % k)
        check_bricks(ix, by_level[k], k)
    return sorted(by_level)


def brick_layout(size, b):
    """§8A.4: bricks per axis, and per brick (i, j, k) its extent and the value
    index of its first voxel, as functions."""
    B = 1 << b
    sx, sy, sz = size
    n = tuple(-(-s // B) for s in size)

    def extent(i, j, k):
        return (min(B, sx - i * B), min(B, sy - j * B), min(B, sz - k * B))

    def first(i, j, k):
        ex, ey, ez = extent(i, j, k)
        return k * B * sy * sx + j * B * sx * ez + i * B * ey * ez
    return n, extent, first


def check_bricks(ix, values, k):
    """§6.4, §8A.4, §7.3: every values block holds exactly one brick, or (codec
    4) a run of whole bricks that follow one another.  Each block is checked
    on its own, by the brick its first element and its end fall on, so a
    claimed size costs nothing.  k = 0: the blocks of stream 3 and the
    volume's bricks; k >= 1: the blocks of stored level of detail k (stream
    7) and the bricks of that level, with the sizes m_a of §8A.5.  Records
    the extent of each block's first brick in ix.brick_of[(k, first_element)]."""
    size = level_size(ix.size, k)
    (nx, ny, nz), extent, first = brick_layout(size, ix.cell_log2)
    B = 1 << ix.cell_log2
    sx, sy, sz = size
    total = sx * sy * sz
    what = "values" if k == 0 else "level %d" % k
    if len(values) > nx * ny * nz:
        fail("malformed", "block table: %d %s blocks, the bricked grid%s has %d bricks "
             "(at least one brick per block)" % (len(values), what,
                                                 "'s level of detail %d" % k if k else "",
                                                 nx * ny * nz))

    def brick_starting_at(v):
        """The brick (i, j, k) whose first value is v, or None: the layers of
        bricks before it are whole, then the rows of its layer, then the
        bricks of its row (§8A.4's first(i, j, k) taken apart)."""
        if not 0 <= v < total:
            return None
        layer = min(B, sz) * sy * sx            # every layer but the last is B voxels deep
        k = v // layer
        ez = extent(0, 0, k)[2]
        v -= k * layer
        row = min(B, sy) * sx * ez
        j = v // row
        ey = extent(0, j, k)[1]
        v -= j * row
        one = min(B, sx) * ey * ez
        if v % one:
            return None
        return (v // one, j, k)

    for e in values:
        b = brick_starting_at(e.first_element)
        if b is None:
            fail("malformed", "block table: %s: first_element %d is not the first %s of a brick"
                 % (ix.where(e), e.first_element, "value" if k == 0 else
                    "element of level of detail %d" % k))
        ext = extent(*b)
        voxels = ext[0] * ext[1] * ext[2]
        end = e.first_element + e.element_count
        if e.codec == 4:      # §7.3: a run of whole bricks
            if end != total and brick_starting_at(end) is None:
                fail("malformed", "block table: %s: a codec 4 block ends at element %d, inside a "
                     "brick" % (ix.where(e), end))
        elif e.element_count != voxels:
            fail("malformed", "block table: %s: brick (%d, %d, %d) is elements %d..%d"
                 % (ix.where(e), b[0], b[1], b[2], e.first_element, e.first_element + voxels))
        ix.brick_of[(k, e.first_element)] = ext


def check_stream_kind(ix, e):
    """§6.4 (1.1): which streams appear with which structure kind, and the level of
    the blocks of streams 3, 4 and 5 of the kinds of §8A."""
    kind = ix.structure_kind
    # Streams 4 and 5 in files of other kinds never get here: they are
    # unknown streams there (known_stream).
    allowed = {STREAM_NODES: (KIND_OCTREE,)}.get(e.stream)
    if allowed is not None and kind not in allowed:
        fail("malformed", "block table: %s: stream %d (%s) appears only with "
             "structure_kind %d, this file has structure_kind %d (%s)"
             % (ix.where(e), e.stream, STREAM_NAMES[e.stream], allowed[0], kind,
                ix.structure_name))
    if kind != KIND_OCTREE and e.stream not in (STREAM_METADATA, STREAM_STORED_LOD) \
            and e.level != 0:
        fail("malformed", "block table: %s: level %d, expected 0 for structure_kind %d "
             "(%s)" % (ix.where(e), e.level, kind, ix.structure_name))


def check_block_level(ix, e):
    """§6.4: all elements of a block belong to the level in its `level` field."""
    if e.stream == STREAM_METADATA:
        if e.level != 0:
            fail("malformed", "block table: %s: the metadata block has level %d, expected 0"
                 % (ix.where(e), e.level))
        if e.first_element != 0:   # SPEC-NOTES 23: the only block of its stream
            fail("malformed", "block table: %s: the metadata block has first_element %d, "
                 "expected 0" % (ix.where(e), e.first_element))
        return
    if ix.structure_kind != KIND_OCTREE:
        return                          # level 0, checked by check_stream_kind
    if e.level > ix.depth:
        fail("malformed", "block table: %s: level %d is deeper than depth %d"
             % (ix.where(e), e.level, ix.depth))
    if e.stream == STREAM_NODES:
        lo, n = ix.first_inner[e.level], ix.inner_count[e.level]
    else:
        lo, n = ix.first_value[e.level], ix.level_values[e.level]
    if not (lo <= e.first_element and e.first_element + e.element_count <= lo + n):
        fail("malformed", "block table: %s: elements %d..%d lie outside level %d's range "
             "%d..%d" % (ix.where(e), e.first_element, e.first_element + e.element_count,
                         e.level, lo, lo + n))


def check_stream_coverage(ix, stream, total):
    """§6.4: the blocks of a stream cover 0 .. total exactly once.  With total
    None, only that they cover 0 .. n without gap or overlap; returns n."""
    return check_coverage(ix, [e for e in ix.blocks if e.stream == stream], total,
                          "stream %d (%s)" % (stream, STREAM_NAMES[stream]))


def check_coverage(ix, blocks, total, what):
    """The blocks, taken in order of first_element, cover 0 .. total exactly
    once (total None: 0 .. n for some n); returns n."""
    position = 0
    for e in sorted(blocks, key=lambda e: e.first_element):
        if e.first_element != position:
            fail("malformed", "block table: %s: %s starts at element %d, expected %d (%s)"
                 % (what, ix.where(e), e.first_element, position,
                    "gap" if e.first_element > position else "overlap"))
        position += e.element_count
    if total is not None and position != total:
        fail("malformed", "block table: %s covers elements 0..%d, expected 0..%d"
             % (what, position, total))
    return position


# ============================================================ §7 Blocks

def stream_width(ix, stream):
    return {STREAM_METADATA: 1, STREAM_NODES: 8, STREAM_VALUES: ix.width,
            STREAM_BORDERS: 4, STREAM_CELLS: 8, STREAM_STORED_LOD: ix.width}[stream]


BLOCK_SIGNATURE = b"IVBK"
BLOCK_HEADER_SIZE = 32
BlockHeader = collections.namedtuple(
    "BlockHeader", "stream codec flags level first_element element_count "
                   "payload_size payload_crc header_crc")


def parse_block_header(b):
    """§7.1: the 32 bytes of a block header."""
    return BlockHeader(*struct.unpack_from("<BBBBQIIII", b, 4))


def check_block_header(ix, e, stored):
    """§7.1: in a framed file the stored bytes start with a block header that
    repeats the index entry.  Returns the payload."""
    where = ix.where(e)
    if stored[:4] != BLOCK_SIGNATURE:
        fail("malformed", "%s: block_signature is %s, expected 'IVBK'"
             % (where, stored[:4].hex(" ")))
    h = parse_block_header(stored)
    actual = crc32c(stored[:28])
    if actual != h.header_crc:
        fail("checksum", "%s: header_crc is 0x%08X, CRC-32C of block header bytes 0..28 "
             "is 0x%08X" % (where, h.header_crc, actual))
    for field in ("stream", "codec", "flags", "level", "first_element", "element_count"):
        if getattr(h, field) != getattr(e, field):
            fail("malformed", "%s: the block header's %s is %d, the index entry's is %d"
                 % (where, field, getattr(h, field), getattr(e, field)))
    if h.payload_size != e.stored_size - BLOCK_HEADER_SIZE:
        fail("malformed", "%s: payload_size is %d, expected stored_size - 32 = %d"
             % (where, h.payload_size, e.stored_size - BLOCK_HEADER_SIZE))
    payload = stored[BLOCK_HEADER_SIZE:]
    actual = crc32c(payload)
    if actual != h.payload_crc:
        fail("checksum", "%s: payload_crc is 0x%08X, CRC-32C of the payload is 0x%08X"
             % (where, h.payload_crc, actual))
    return payload
def zstd_compress_bound(n):
    """§7: the largest zstd frame of n content bytes (ZSTD_compressBound)."""
    return n + (n >> 8) + (((128 << 10) - n) >> 11 if n < (128 << 10) else 0)


CODEC_PLANE_FRAMES = 5                   # §7 codec 5, byte planes a zstd frame each (1.3)
CODEC_TOP_BYTE = 6                       # §7.4 codec 6, top byte in context (1.3)
KNOWN_CODECS = (0, 1, 2, 3, 4, 5, 6)


def stored_size_bound(ix, e):
    """§7: the largest stored_size of a block of codec 1 to 6 (None for others)."""
    if e.codec not in (1, 2, 3, 4, 5, 6):
        return None
    if e.codec == CODEC_TOP_BYTE:   # §7: 12 + w·n, no zstd frame (SPEC-NOTES 88)
        n, w = e.element_count, stream_width(ix, e.stream)
        bound = TOP_BYTE_LIMIT_EXTRA + w * n
        return bound + (BLOCK_HEADER_SIZE if ix.header.framed else 0)
    bound = zstd_compress_bound(e.element_count * stream_width(ix, e.stream))
    if e.codec == 5:       # §7: w frames of n bytes each, w·bound(n)
        bound = stream_width(ix, e.stream) * zstd_compress_bound(e.element_count)
    if e.codec == 3:       # §7.2: the codec header and a frame of 2n bytes
        bound = PREDICTED_HEADER + zstd_compress_bound(2 * e.element_count)
    if e.codec == 4:       # §7.3: the codec header and a frame of the mask and every value
        bound = MASKED_HEADER + zstd_compress_bound((e.element_count + 7) // 8 + 2 * e.element_count)
    if ix.header.framed:   # §7.1: plus the block header
        bound += BLOCK_HEADER_SIZE
    return bound


def bound_meaning(ix, e):
    """What the bound of stored_size_bound() is, for messages."""
    if e.codec == 5:
        return ("w = %d times the largest zstd frame of n = %d bytes (codec 5: a frame per "
                "byte plane)" % (stream_width(ix, e.stream), e.element_count))
    if e.codec == CODEC_TOP_BYTE:
        return ("12 + w·n with n = %d and w = %d (codec 6: no larger than its values "
                "stored and a header)" % (e.element_count, stream_width(ix, e.stream)))
    return "the largest zstd frame of its decoded size"


def check_block_limits(ix, e):
    """§6.4, §7, checked with the block table: a known codec, the decoded-size
    limit, and the stored_size of codec 0 and the bound of codecs 1 to 6.
    This reader does it for stream 7 (§8A.5) and for every block of codecs 5 and 6;
    for the other blocks of streams 1 to 5 it checks the same when it reads
    the block (SPEC-NOTES 8, 54, 64, 81, 87)."""
    where = ix.where(e)
    if e.codec not in KNOWN_CODECS:   # §7 (SPEC-NOTES 63)
        fail("unsupported-feature", "block table: %s: codec %d, this reader knows 0 .. 6"
             % (where, e.codec))
    size = e.element_count * stream_width(ix, e.stream)
    if size > MAX_BLOCK_DECODED:
        fail("malformed", "block table: %s: decoded size %d exceeds 64 MiB" % (where, size))
    framing = BLOCK_HEADER_SIZE if ix.header.framed else 0
    if e.codec == 0 and e.stored_size != framing + size:
        fail("malformed", "block table: %s: stored block (codec 0) has stored_size %d, "
             "expected %d" % (where, e.stored_size, framing + size))
    bound = stored_size_bound(ix, e)
    if bound is not None and e.stored_size > bound:
        fail("malformed", "block table: %s: stored_size %d exceeds %d, %s"
             % (where, e.stored_size, bound, bound_meaning(ix, e)))


def read_block(r, ix, e, limit=MAX_BLOCK_DECODED):
    """§7: read one block, check its CRC, decode it.  Returns the decoded bytes."""
    where = ix.where(e)
    bound = stored_size_bound(ix, e)   # §7: bounded before the stored bytes are read
    if bound is not None and e.stored_size > bound:
        fail("malformed", "%s: stored_size %d exceeds %d, %s"
             % (where, e.stored_size, bound, bound_meaning(ix, e)))
    stored = r.read(e.file_offset, e.stored_size)
    actual = crc32c(stored)
    if actual != e.crc:   # §7: the CRC is checked before decoding
        fail("checksum", "%s: CRC-32C of the %d stored bytes is 0x%08X, the block table "
             "says 0x%08X" % (where, e.stored_size, actual, e.crc))
    if ix.header.framed:
        stored = check_block_header(ix, e, stored)
    return decode_payload(ix, e, stored, limit)


def decode_payload(ix, e, stored, limit=MAX_BLOCK_DECODED):
    """§7: decode a block's payload (its stored bytes without a block header)."""
    where = ix.where(e)
    if e.codec not in KNOWN_CODECS:   # checked when the block is read (SPEC-NOTES 8)
        fail("unsupported-feature", "%s: codec %d, this reader knows 0 (stored), 1 (zstd), "
             "2 (zstd over byte planes), 3 (predicted 16-bit), 4 (masked 16-bit), 5 (byte "
             "planes, a zstd frame each) and 6 (top byte in context)" % (where, e.codec))
    width = stream_width(ix, e.stream)
    size = e.element_count * width
    if size > MAX_BLOCK_DECODED:
        fail("malformed", "%s: decoded size %d exceeds 64 MiB" % (where, size))
    if size > limit:   # §11: the metadata is at most 16 MiB
        fail("malformed", "%s: decoded size %d exceeds %d" % (where, size, limit))
    if e.codec == 0:
        if len(stored) != size:
            fail("malformed", "%s: stored block (codec 0) has a payload of %d bytes, "
                 "expected element_count x width = %d" % (where, len(stored), size))
        return stored
    if e.codec in (3, 4):   # a brick of stream 3, or of a stored level (§8A.5, SPEC-NOTES 66)
        ext = getattr(ix, "brick_of", {}).get((e.level, e.first_element))
        if ext is None or e.stream not in (STREAM_VALUES, STREAM_STORED_LOD) or width != 2:
            fail("malformed", "%s: codec %d outside a brick of 16-bit values" % (where, e.codec))
        if e.codec == 3:
            return decode_predicted(stored, ext, where)
        return decode_masked(stored, e.element_count, where)
    if e.codec == CODEC_TOP_BYTE:   # §7.4: one brick of stream 3 or of a stored level
        ext = getattr(ix, "brick_of", {}).get((e.level, e.first_element))
        if (ext is None or e.stream not in (STREAM_VALUES, STREAM_STORED_LOD)
                or width not in (2, 4) or ext[0] * ext[1] * ext[2] != e.element_count):
            fail("malformed", "%s: codec 6 outside a brick of 2- or 4-byte values" % where)
        return decode_top_byte(stored, ext, width, where)
    if e.codec == CODEC_PLANE_FRAMES:   # §7 codec 5: w frames, one per byte plane
        if width < 2:   # refused with the block table already (metadata)
            fail("malformed", "%s: codec 5 on a stream of width 1" % where)
        return decode_plane_frames(stored, e.element_count, width, where)
    content = decode_zstd_frame(stored, size, where)
    if e.codec == 1:
        return content
    return unshuffle_byte_planes(content, e.element_count, width)


def decode_predicted(payload, ext, where):
    """§7.2 codec 3: the codec header, the residuals (entropy coder 1: a zstd
    frame of two byte planes; 2: §7.2.1; 3: §7.2.2), then every voxel in
    raster order from its prediction.  Returns the values as little-endian u16."""
    ex, ey, ez = ext
    n = ex * ey * ez
    if len(payload) < PREDICTED_HEADER:
        fail("malformed", "%s: codec 3 payload of %d bytes, shorter than its 24-byte header"
             % (where, len(payload)))
    predictor, value_map, s, entropy = payload[0], payload[1], payload[2], payload[3]
    if predictor != 1:
        fail("unsupported-feature", "%s: codec 3 predictor %d, this reader knows 1" % (where, predictor))
    if value_map not in (0, 1):
        fail("malformed", "%s: codec 3 value_map %d, expected 0 or 1" % (where, value_map))
    if s > 15:
        fail("malformed", "%s: codec 3 shift %d, expected 0..15" % (where, s))
    if entropy not in (1, 2, 3):
        fail("unsupported-feature", "%s: codec 3 entropy coder %d, this reader knows 1, 2 and 3"
             % (where, entropy))
    t = struct.unpack_from("<7h", payload, 4)
    (level,) = struct.unpack_from("<i", payload, 18)
    if payload[22] or payload[23]:
        fail("malformed", "%s: codec 3 reserved bytes 22..24 are not 0" % where)
    if entropy == 1:
        content = decode_zstd_frame(bytes(payload[PREDICTED_HEADER:]), 2 * n, where)
        planes = np.frombuffer(content, np.uint8).astype(np.int64)
        zz = planes[:n] + 256 * planes[n:]
    elif entropy == 2:
        # every check of §7.2.1 is made before any value is predicted (SPEC-NOTES 71)
        zz = np.array(decode_rans_residuals(bytes(payload), ext, where), np.int64)
    else:
        # every check of §7.2.2 likewise (SPEC-NOTES 71, 99)
        zz = np.array(decode_rans3_residuals(bytes(payload), ext, where), np.int64)
    diff = np.where(zz % 2 == 0, zz // 2, -(zz + 1) // 2).tolist()
    r = (1 << (s - 1)) if s > 0 else 0
    sy, sz = ex, ex * ey          # index steps along y and z
    u = [0] * n

    def clamp(p):
        return 0 if p < 0 else 65535 if p > 65535 else p
    i = 0
    for z in range(ez):
        for y in range(ey):
            for x in range(ex):
                if x and y and z:
                    S = (t[0] * u[i - 1] + t[1] * u[i - sy] + t[2] * u[i - sz]
                         + t[3] * u[i - 1 - sy] + t[4] * u[i - 1 - sz] + t[5] * u[i - sy - sz]
                         + t[6] * u[i - 1 - sy - sz])
                    p = clamp(((S + r) >> s) + level)      # >> is floor division by 2^s
                else:
                    back = [step for c, step in ((x, 1), (y, sy), (z, sz)) if c]
                    if not back:
                        p = 0
                    elif len(back) == 1:
                        p = u[i - back[0]]
                    else:
                        a, b = back
                        p = clamp(u[i - a] + u[i - b] - u[i - a - b])
                u[i] = (p + diff[i]) % 65536
                i += 1
    v = np.array(u, np.uint32)
    if value_map == 1:   # the inverse of the binary16 order map
        v = np.where(v & 0x8000, v ^ 0x8000, v ^ 0xFFFF)
    return v.astype("<u2").tobytes()


RANS_PROB_BITS = 12                 # §7.2.1: tables sum to 4096
RANS_LOW = 1 << 23                  # §7.2.1: the states' lower bound and final value
RANS_CONTEXTS = 12
RANS_TOKENS = 32


def rans_table(c, T):
    """§7.2.1: the frequencies f_0 .. f_31 (summing to 4096) and the cumulative
    frequencies s_0 .. s_31 made from the counts c (sum T) of one context."""
    R4 = (1 << 44) // T
    f = [max(1, (ct * R4) >> 32) for ct in c]
    j = f.index(max(f))              # the lowest t among equal largest
    f[j] += (1 << RANS_PROB_BITS) - sum(f)   # D, which may be negative (SPEC-NOTES 73)
    return f, cumulative(f)


def cumulative(f):
    """s_t = f_0 + ... + f_{t-1}."""
    s, acc = [], 0
    for ft in f:
        s.append(acc)
        acc += ft
    return s


def token_bit_length(t):
    """§7.2.1: B(t), the bit length of the residuals of token t."""
    return t if t < 2 else (t >> 1) + 1


def token_context(blen, i, x, y, z, ex, sy, sz):
    """§7.2.1 Contexts: the context k (0 .. 11) of voxel i at (x, y, z) of a
    brick of row length ex (index steps sy along y, sz along z), from blen,
    the bit lengths B(t) of the tokens of the voxels before it; each
    neighbour outside the brick counts 0.  Only earlier rows count."""
    ctx = 2
    if y:
        ctx += 2 * blen[i - sy]                   # U at (x, y - 1, z)
        if x:
            ctx += blen[i - sy - 1]               # L at (x - 1, y - 1, z)
        if x + 1 < ex:
            ctx += blen[i - sy + 1]               # P at (x + 1, y - 1, z)
    if z:
        ctx += blen[i - sz]                       # K at (x, y, z - 1)
    k = ctx // 5
    return k if k < RANS_CONTEXTS else RANS_CONTEXTS - 1


def residuals_from_bits_below(bits, tokens, what, reason=None):
    """§7.2.1 Bits below (also §7.2.2): the residuals of the tokens from the
    bytes `bits`, which must be exactly the ceil(E / 8) bytes of the E bits
    the tokens need, the padding bits 0.  reason: the prefix of the reasons
    of the two checks (None: none given).  Returns a list of ints."""
    tok = np.array(tokens, np.int64)
    e = np.where(tok < 2, 0, (tok >> 1) - 1)       # e = B(t) - 2 for t >= 2
    E = int(e.sum())
    if len(bits) != (E + 7) // 8:
        fail("malformed", "%s: the bits below the tokens take %d bytes, the tokens need %d "
             "bits (%d bytes)%s" % (what, len(bits), E, (E + 7) // 8, tag(reason, "bits_size")),
             reason and reason + ".bits_size")
    if E % 8 and bits[-1] >> (E % 8):   # (SPEC-NOTES 75)
        fail("malformed", "%s: padding bits %d..7 of the last byte of the bits below the "
             "tokens are not 0 (byte 0x%02X)%s" % (what, E % 8, bits[-1], tag(reason, "padding")),
             reason and reason + ".padding")
    b = np.frombuffer(bytes(bits) + b"\0\0\0", np.uint8).astype(np.int64)
    at = np.cumsum(e) - e                          # the first bit of every token's bits
    q = at >> 3
    window = b[q] | (b[q + 1] << 8) | (b[q + 2] << 16)   # e + (at mod 8) <= 21 bits
    w = (window >> (at & 7)) & ((np.int64(1) << e) - 1)
    zz = np.where(tok < 2, tok, ((2 + (tok & 1)) << e) + w)
    return zz.tolist()


def tag(prefix, name):
    """The reason of a check, to end its message: ' [prefix.name]'; '' where
    the check has none (prefix None)."""
    return " [%s.%s]" % (prefix, name) if prefix else ""


def decode_rans_residuals(payload, ext, where):
    """§7.2.1 codec 3 entropy coder 2: the residuals z_0 .. z_{n-1} of a brick
    of extent ext from the bytes after the 24-byte codec header of payload:
    the stream length R, the rANS stream of two interleaved states coding one
    token a voxel in one of 12 adaptive contexts, then the bits below the
    tokens.  Returns the residuals as a list of ints."""
    ex, ey, ez = ext
    n = ex * ey * ez
    what = "%s: codec 3 entropy coder 2" % where
    base = PREDICTED_HEADER
    if len(payload) < base + 4:      # (SPEC-NOTES 72)
        fail("malformed", "%s: payload of %d bytes has no room for the stream length R "
             "(at least 28 bytes)" % (what, len(payload)))
    (R,) = struct.unpack_from("<I", payload, base)
    if R < 8 or R > len(payload) - 28:
        fail("malformed", "%s: rANS stream length R = %d, expected 8 .. %d (payload size "
             "%d - 28)" % (what, R, len(payload) - 28, len(payload)))
    start = base + 4                  # stream byte 0
    end = start + R                   # one past the last stream byte
    X = list(struct.unpack_from("<2I", payload, start))
    for j in (0, 1):   # §7.2.1: 2^23 .. 2^31 - 1 (SPEC-NOTES 74 asked for the upper bound)
        if not RANS_LOW <= X[j] < 1 << 31:
            fail("malformed", "%s: initial rANS state X_%d = %d is not in 2^23 .. 2^31 - 1" % (what, j, X[j]))
    pos = start + 8                   # next stream byte to read
    # every context: counts, their sum, tokens coded in it, frequencies, cumulative frequencies
    counts = [[1] * RANS_TOKENS for _ in range(RANS_CONTEXTS)]
    totals = [RANS_TOKENS] * RANS_CONTEXTS
    coded = [0] * RANS_CONTEXTS
    f0, s0 = rans_table(counts[0], totals[0])
    freqs = [list(f0) for _ in range(RANS_CONTEXTS)]
    cums = [list(s0) for _ in range(RANS_CONTEXTS)]
    tokens = [0] * n
    blen = [0] * n                    # B(t) of every voxel's token
    sy, sz = ex, ex * ey
    mask = (1 << RANS_PROB_BITS) - 1
    find = bisect.bisect_right
    i = 0
    for z in range(ez):
        for y in range(ey):
            for x in range(ex):
                k = token_context(blen, i, x, y, z, ex, sy, sz)
                f, s = freqs[k], cums[k]
                j = i & 1
                st = X[j]
                slot = st & mask
                tok = find(s, slot) - 1
                st = f[tok] * (st >> RANS_PROB_BITS) + slot - s[tok]
                while st < RANS_LOW:
                    if pos >= end:
                        fail("malformed", "%s: the rANS stream of %d bytes ends at voxel %d of %d"
                             % (what, R, i, n))
                    st = (st << 8) | payload[pos]
                    pos += 1
                X[j] = st
                tokens[i] = tok
                blen[i] = token_bit_length(tok)
                c = counts[k]
                c[tok] += 16
                totals[k] += 16
                m = coded[k] + 1
                coded[k] = m
                if (m & (m - 1) == 0 and m >= 4) or m % 128 == 0:
                    freqs[k], cums[k] = rans_table(c, totals[k])
                i += 1
    if X[0] != RANS_LOW or X[1] != RANS_LOW:
        fail("malformed", "%s: final rANS states are %d and %d, expected 2^23 = %d for both"
             % (what, X[0], X[1], RANS_LOW))
    if pos != end:
        fail("malformed", "%s: %d of the %d bytes of the rANS stream are left over after the "
             "last voxel" % (what, end - pos, R))
    # the bits below the tokens, in voxel order, least significant first
    return residuals_from_bits_below(payload[end:], tokens, what)


RANS3_LOW = 1 << 16                 # §7.2.2: the states' lower bound and final value
RANS3_STATES = 32                   # §7.2.2: voxel i uses state i mod 32
RANS3_REASON = "codec3.entropy3"    # the prefix of the reasons of §7.2.2's checks
# §7.2.2 Tables: the longest bit string, 12 contexts of 1 + 32 + 31 x (4 + 11) bits
RANS3_TABLES_MAX_BYTES = (RANS_CONTEXTS * (1 + 32 + 31 * (4 + 11)) + 7) // 8


def read_rans3_tables(payload, start, what):
    """§7.2.2 Tables: from the bit string at byte `start` of payload, the
    frequencies and cumulative frequencies of the 12 contexts, and the byte
    offset after the tables (where the states begin).  Every field of the
    string, `present` included, is read least significant bit first
    (SPEC-NOTES 97)."""
    def bad(reason, message):
        fail("malformed", "%s: %s%s" % (what, message, tag(RANS3_REASON, reason)),
             "%s.%s" % (RANS3_REASON, reason))
    chunk = payload[start:start + RANS3_TABLES_MAX_BYTES]
    string = int.from_bytes(chunk, "little")   # bit j of the string is bit j of this number
    have = 8 * len(chunk)
    pos = 0                                    # the next bit of the string

    def take(nbits, field):
        nonlocal pos
        if pos + nbits > have:
            bad("short", "the payload of %d bytes ends inside the tables (%s of context %d)"
                % (len(payload), field, k))
        v = (string >> pos) & ((1 << nbits) - 1)
        pos += nbits
        return v
    freqs, cums = [], []
    for k in range(RANS_CONTEXTS):
        if not take(1, "used"):
            f = [128] * RANS_TOKENS            # (SPEC-NOTES 98)
        else:
            present = take(32, "present")
            if present == 0:
                bad("present_zero", "context %d is used but its `present` is 0" % k)
            listed = [t for t in range(RANS_TOKENS) if present >> t & 1]
            f = [0] * RANS_TOKENS
            for t in listed[:-1]:
                a = take(4, "a of token %d" % t)
                if a > 11:
                    bad("table_a", "context %d, token %d: a = %d, expected 0 .. 11" % (k, t, a))
                f[t] = (1 << a) + take(a, "w of token %d" % t)
            last = (1 << RANS_PROB_BITS) - sum(f)
            if last < 1:
                bad("last_freq", "context %d: the frequencies before its last token %d sum "
                    "to %d, leaving it %d (at least 1 needed)" % (k, listed[-1], sum(f), last))
            f[listed[-1]] = last
        freqs.append(f)
        cums.append(cumulative(f))
    if pos % 8 and string >> pos & ((1 << (8 - pos % 8)) - 1):
        bad("table_padding", "bits %d..7 of the last byte of the tables (byte %d) are not 0"
            % (pos % 8, start + pos // 8))
    return freqs, cums, start + (pos + 7) // 8


def decode_rans3_residuals(payload, ext, where):
    """§7.2.2 codec 3 entropy coder 3: the residuals z_0 .. z_{n-1} of a brick
    of extent ext from the bytes after the 24-byte codec header of payload:
    the 12 contexts' stored tables, 32 rANS states, the word count W and the
    W 16-bit words, then the bits below the tokens (§7.2.1's tokens, contexts
    and bits below).  Every check raises `malformed` with a reason
    "codec3.entropy3.<check>".  Returns the residuals as a list of ints."""
    ex, ey, ez = ext
    n = ex * ey * ez
    what = "%s: codec 3 entropy coder 3" % where

    def bad(reason, message):
        fail("malformed", "%s: %s%s" % (what, message, tag(RANS3_REASON, reason)),
             "%s.%s" % (RANS3_REASON, reason))
    freqs, cums, pos = read_rans3_tables(payload, PREDICTED_HEADER, what)
    if len(payload) - pos < 4 * RANS3_STATES + 4:
        bad("short", "%d bytes after the tables (payload of %d bytes), the 32 states and W "
            "need 132" % (len(payload) - pos, len(payload)))
    X = list(struct.unpack_from("<32I", payload, pos))
    for j in range(RANS3_STATES):   # 2^16 .. 2^32 - 1, the upper bound true of a u32 (SPEC-NOTES 102)
        if X[j] < RANS3_LOW:
            bad("initial_state", "initial rANS state X_%d = %d is not in 2^16 .. 2^32 - 1"
                % (j, X[j]))
    (W,) = struct.unpack_from("<I", payload, pos + 4 * RANS3_STATES)
    wpos = pos + 4 * RANS3_STATES + 4       # the next word to read
    wend = wpos + 2 * W                      # one past the last word (exact: SPEC-NOTES 100)
    if wend > len(payload):
        bad("words_size", "W = %d words (%d bytes), only %d bytes follow it"
            % (W, 2 * W, len(payload) - wpos))
    tokens = [0] * n
    blen = [0] * n                           # B(t) of every voxel's token
    sy, sz = ex, ex * ey
    mask = (1 << RANS_PROB_BITS) - 1
    find = bisect.bisect_right
    i = 0
    for z in range(ez):
        for y in range(ey):
            for x in range(ex):
                k = token_context(blen, i, x, y, z, ex, sy, sz)
                f, s = freqs[k], cums[k]
                j = i & (RANS3_STATES - 1)
                st = X[j]
                slot = st & mask
                tok = find(s, slot) - 1          # the last t with s_t <= slot: f_t >= 1
                st = f[tok] * (st >> RANS_PROB_BITS) + slot - s[tok]
                if st < RANS3_LOW:               # one word always suffices
                    if wpos >= wend:
                        bad("stream_end", "the word stream of %d words ends at voxel %d of %d"
                            % (W, i, n))
                    st = (st << 16) | payload[wpos] | (payload[wpos + 1] << 8)
                    wpos += 2
                X[j] = st
                tokens[i] = tok
                blen[i] = token_bit_length(tok)
                i += 1
    # every state, those a brick of fewer than 32 voxels does not use too (SPEC-NOTES 101)
    wrong = [j for j in range(RANS3_STATES) if X[j] != RANS3_LOW]
    if wrong:
        bad("states_end", "final rANS state X_%d = %d (and %d more not 2^16 = %d)"
            % (wrong[0], X[wrong[0]], len(wrong) - 1, RANS3_LOW))
    if wpos != wend:
        bad("words_left", "%d of the %d words of the word stream are left over after the "
            "last voxel" % ((wend - wpos) // 2, W))
    return residuals_from_bits_below(payload[wend:], tokens, what, RANS3_REASON)


TOP_PROB_BITS = 16                  # §7.4: tables sum to 65536, slots of 16 bits
TOP_CONTEXTS = 128                  # models of the top bytes (A = 256), one per context k
TOP_SYMBOLS = 256
NIBBLE_MODELS = 256                 # mode 1: models of the high nibbles, one per top byte
NIBBLE_SYMBOLS = 16                 # (A = 16)


def top_byte_table(c, T):
    """§7.4 (made as in §7.2.1): the frequencies f_0 .. f_{A-1} (summing to
    65536) and the cumulative frequencies s_0 .. s_{A-1} made from the counts
    c (sum T) of one model, A = len(c) (256 for a top byte, 16 for a high
    nibble)."""
    R6 = (1 << 48) // T
    f = [max(1, (ct * R6) >> 32) for ct in c]
    j = f.index(max(f))              # the lowest t among equal largest
    f[j] += (1 << TOP_PROB_BITS) - sum(f)    # D, which may be negative (as SPEC-NOTES 73)
    s, acc = [], 0
    for ft in f:
        s.append(acc)
        acc += ft
    return f, s


def decode_top_byte(payload, ext, w, where):
    """§7.4 codec 6: the header (centre C, step S, mode M, reserved, stream
    length R), the rANS stream of one state coding every voxel's top byte in
    one of 128 adaptive models chosen by its neighbours' top bytes (mode 1:
    then its second byte's high nibble in one of 256 models chosen by that
    top byte), then the stored bits: mode 0, the w - 1 lower byte planes;
    mode 1, the w - 2 lower planes and the second bytes' low nibbles, two a
    byte.  Every check of the block is made before any value is returned
    (SPEC-NOTES 89, 94).  Returns the values as little-endian w-byte integers
    in raster order."""
    ex, ey, ez = ext
    n = ex * ey * ez
    what = "%s: codec 6" % where
    if len(payload) < TOP_BYTE_HEADER:
        fail("malformed", "%s: payload of %d bytes, shorter than its 8-byte header"
             % (what, len(payload)))
    C, S, M = payload[0], payload[1], payload[2]
    if C > 127:
        fail("malformed", "%s: centre C = %d, expected 0..127" % (what, C))
    if S == 0:
        fail("malformed", "%s: step S = 0, expected 1..255" % what)
    if M > 1:
        fail("malformed", "%s: mode M = %d, expected 0 or 1" % (what, M))
    if payload[3]:
        fail("malformed", "%s: reserved byte 3 is not 0 (0x%02X)" % (what, payload[3]))
    (R,) = struct.unpack_from("<I", payload, 4)
    N = n if M == 0 else 2 * n       # symbols in the stream
    if R < 4 or R > 2 * N + 4:
        fail("malformed", "%s: rANS stream length R = %d, expected 4 .. 2N + 4 = %d (mode %d, "
             "N = %d symbols, n = %d)" % (what, R, 2 * N + 4, M, N, n))
    if M == 0:
        L = (w - 1) * n
        formula = "8 + R + (w - 1)n"
    else:
        L = (w - 2) * n + (n + 1) // 2
        formula = "8 + R + (w - 2)n + ceil(n/2)"
    expected = TOP_BYTE_HEADER + R + L
    if len(payload) != expected:
        fail("malformed", "%s: payload of %d bytes, expected %s = %d (mode %d, R = %d, "
             "n = %d, w = %d)" % (what, len(payload), formula, expected, M, R, n, w))
    start = TOP_BYTE_HEADER           # stream byte 0
    end = start + R                   # one past the last stream byte
    (X,) = struct.unpack_from("<I", payload, start)
    if not RANS_LOW <= X < 1 << 31:
        fail("malformed", "%s: initial rANS state X = %d is not in 2^23 .. 2^31 - 1" % (what, X))
    pos = start + 4                   # next stream byte to read
    # the class q of every magnitude sum m = 0 .. 381 (// is a floor, also for m < 3C)
    qof = [min(31, max(0, (m - 3 * C) // S + 16)) for m in range(3 * 127 + 1)]
    # every model: counts (made when first used), their sum, symbols coded in it,
    # frequencies and cumulative frequencies (shared until a model's table is made again)
    counts = [None] * TOP_CONTEXTS
    totals = [TOP_SYMBOLS] * TOP_CONTEXTS
    coded = [0] * TOP_CONTEXTS
    f0, s0 = top_byte_table([1] * TOP_SYMBOLS, TOP_SYMBOLS)   # every f_t = 256
    freqs = [f0] * TOP_CONTEXTS
    cums = [s0] * TOP_CONTEXTS
    if M == 1:
        ncounts = [None] * NIBBLE_MODELS
        ntotals = [NIBBLE_SYMBOLS] * NIBBLE_MODELS
        ncoded = [0] * NIBBLE_MODELS
        g0, h0 = top_byte_table([1] * NIBBLE_SYMBOLS, NIBBLE_SYMBOLS)   # every f_t = 4096
        nfreqs = [g0] * NIBBLE_MODELS
        ncums = [h0] * NIBBLE_MODELS
        highs = bytearray(n)          # 16·h of every voxel's second byte
    sign = [0] * n                    # a >> 7 of every voxel's top byte
    mag = [0] * n                     # a AND 127
    tops = bytearray(n)
    sy, sz = ex, ex * ey
    mask = (1 << TOP_PROB_BITS) - 1
    find = bisect.bisect_right
    data = payload
    i = 0
    for z in range(ez):
        for y in range(ey):
            for x in range(ex):
                # the neighbours' top bytes at x - 1, y - 1, z - 1, 0 outside the brick
                g = m = 0
                if x:
                    g = sign[i - 1]
                    m = mag[i - 1]
                if y:
                    g += sign[i - sy]
                    m += mag[i - sy]
                if z:
                    g += sign[i - sz]
                    m += mag[i - sz]
                k = 32 * g + qof[m]
                f, s = freqs[k], cums[k]
                slot = X & mask
                t = find(s, slot) - 1
                X = f[t] * (X >> TOP_PROB_BITS) + slot - s[t]
                while X < RANS_LOW:
                    if pos >= end:
                        fail("malformed", "%s: the rANS stream of %d bytes ends at the top "
                             "byte of voxel %d of %d" % (what, R, i, n))
                    X = (X << 8) | data[pos]
                    pos += 1
                tops[i] = t
                sign[i] = t >> 7
                mag[i] = t & 127
                c = counts[k]
                if c is None:
                    c = counts[k] = [1] * TOP_SYMBOLS
                c[t] += 16
                totals[k] += 16
                mc = coded[k] + 1
                coded[k] = mc
                if (mc & (mc - 1) == 0 and mc >= 4) or mc % 128 == 0:
                    freqs[k], cums[k] = top_byte_table(c, totals[k])
                if M == 1:            # the high nibble, with the model of top byte t
                    f, s = nfreqs[t], ncums[t]
                    slot = X & mask
                    h = find(s, slot) - 1
                    X = f[h] * (X >> TOP_PROB_BITS) + slot - s[h]
                    while X < RANS_LOW:
                        if pos >= end:
                            fail("malformed", "%s: the rANS stream of %d bytes ends at the "
                                 "high nibble of voxel %d of %d" % (what, R, i, n))
                        X = (X << 8) | data[pos]
                        pos += 1
                    highs[i] = h << 4
                    c = ncounts[t]
                    if c is None:
                        c = ncounts[t] = [1] * NIBBLE_SYMBOLS
                    c[h] += 16
                    ntotals[t] += 16
                    mc = ncoded[t] + 1
                    ncoded[t] = mc
                    if (mc & (mc - 1) == 0 and mc >= 4) or mc % 128 == 0:
                        nfreqs[t], ncums[t] = top_byte_table(c, ntotals[t])
                i += 1
    if X != RANS_LOW:
        fail("malformed", "%s: final rANS state is %d, expected 2^23 = %d" % (what, X, RANS_LOW))
    if pos != end:
        fail("malformed", "%s: %d of the %d bytes of the rANS stream are left over after the "
             "last symbol" % (what, end - pos, R))
    if M == 1 and n % 2 and payload[-1] >> 4:   # stored bits, after the stream (SPEC-NOTES 94)
        fail("malformed", "%s: n = %d is odd and bits 4..7 of the last byte of the low "
             "nibbles are not 0 (byte 0x%02X)" % (what, n, payload[-1]))
    # value i = top_i·256^(w-1) + second_i·256^(w-2) + Σ_p plane_p[i]·256^p, little-endian
    out = np.empty((n, w), np.uint8)
    out[:, w - 1] = np.frombuffer(bytes(tops), np.uint8)
    if M == 0:
        planes = np.frombuffer(bytes(payload[end:]), np.uint8).reshape(w - 1, n)
        out[:, :w - 1] = planes.T
    else:
        low = end + (w - 2) * n       # the low nibbles, two a byte
        if w > 2:
            planes = np.frombuffer(bytes(payload[end:low]), np.uint8).reshape(w - 2, n)
            out[:, :w - 2] = planes.T
        nib = np.frombuffer(bytes(payload[low:]), np.uint8)
        pairs = np.empty(2 * len(nib), np.uint8)
        pairs[0::2] = nib & 15        # value 2j: bits 0..3 of byte j
        pairs[1::2] = nib >> 4        # value 2j + 1: bits 4..7
        out[:, w - 2] = np.frombuffer(bytes(highs), np.uint8) | pairs[:n]
    return out.tobytes()


def decode_masked(payload, n, where):
    """§7.3 codec 4: the background value, then (form 1) one zstd frame of the
    mask and the other values' byte planes.  Returns little-endian u16."""
    if len(payload) < MASKED_HEADER:
        fail("malformed", "%s: codec 4 payload of %d bytes, shorter than its 4-byte header"
             % (where, len(payload)))
    (background,) = struct.unpack_from("<H", payload, 0)
    form = payload[2]
    if payload[3] != 0:
        fail("malformed", "%s: codec 4 reserved byte 3 is %d, not 0" % (where, payload[3]))
    if form == 0:
        if len(payload) != MASKED_HEADER:
            fail("malformed", "%s: codec 4 form 0 (constant) has a payload of %d bytes, not 4"
                 % (where, len(payload)))
        return np.full(n, background, "<u2").tobytes()
    if form != 1:
        fail("malformed", "%s: codec 4 form %d, expected 0 or 1" % (where, form))
    m = (n + 7) // 8

    def frame_size(content_size):   # the mask and two bytes per value that is not the background
        if content_size < m or content_size > m + 2 * n or (content_size - m) % 2:
            fail("malformed", "%s: codec 4 frame holds %d bytes, not a %d-byte mask and two "
                 "bytes per other value" % (where, content_size, m))
        return content_size
    content = decode_zstd_frame(bytes(payload[MASKED_HEADER:]), None, where, frame_size)
    mask = np.unpackbits(np.frombuffer(content[:m], np.uint8), bitorder="little")
    if mask[n:].any():
        fail("malformed", "%s: codec 4 mask bits past the last value are set" % where)
    background_at = mask[:n].astype(bool)
    others = n - int(background_at.sum())
    if len(content) != m + 2 * others:
        fail("malformed", "%s: codec 4 mask leaves %d values that are not the background, the "
             "frame holds %d" % (where, others, (len(content) - m) // 2))
    planes = np.frombuffer(content[m:], np.uint8).astype(np.uint16)
    v = np.full(n, background, np.uint16)
    v[~background_at] = planes[:others] | (planes[others:] << 8)
    return v.astype("<u2").tobytes()


def unshuffle_byte_planes(content, n, w):
    """§7 codec 2 (since 1.2): the frame's content holds the decoded bytes
    regrouped by byte position; decoded byte i·w + p = content byte p·n + i.
    The width w is the block's stream width (§6.4), whatever the stream
    (SPEC-NOTES 56); for w = 1 the content is the decoded bytes.  Codec 5
    gives the same planes, one frame each, joined in order of p."""
    if w == 1:
        return content
    planes = np.frombuffer(content, dtype=np.uint8).reshape(w, n)   # planes[p, i] = byte p·n + i
    return planes.T.tobytes()                                        # row i: bytes i·w .. i·w + w


ZSTD_MAGIC = b"\x28\xb5\x2f\xfd"
ZstdFrame = collections.namedtuple("ZstdFrame", "start end blocks_end fhd content_size checksum")


def is_skippable_magic(b):
    """RFC 8878 §3.1.2: a skippable frame starts with 0x184D2A50 .. 0x184D2A5F (LE)."""
    return len(b) >= 4 and b[0] & 0xF0 == 0x50 and b[1:4] == b"\x2a\x4d\x18"


def parse_zstd_frame(data, start, size, where, size_rule=None,
                     size_name="element_count x width"):
    """RFC 8878 §3.1.1: the zstd frame that starts at data[start], checked as
    §7 asks of codec 1's frame before it is decoded, in the order of
    SPEC-NOTES 9: magic, reserved bit, Frame_Content_Size present, no
    dictionary, Frame_Content_Size equal to `size` (size_rule: see
    decode_zstd_frame); then its blocks are walked to find where it ends.
    A frame that does not end within data is malformed.  Returns a
    ZstdFrame (end: one past its last byte, its checksum included)."""
    def need(n, what):
        if len(data) < start + n:
            fail("malformed", "%s: zstd frame ends inside the %s" % (where, what))

    need(5, "frame header")
    if data[start:start + 4] != ZSTD_MAGIC:
        fail("malformed", "%s: stored bytes%s do not start with a zstd frame (magic %s%s)"
             % (where, " from payload byte %d" % start if start else "",
                data[start:start + 4].hex(" "),
                ": a skippable frame" if is_skippable_magic(data[start:start + 4]) else ""))
    fhd = data[start + 4]
    fcs_flag, single_segment = fhd >> 6, (fhd >> 5) & 1
    reserved_bit, has_checksum, did_flag = (fhd >> 3) & 1, (fhd >> 2) & 1, fhd & 3
    if reserved_bit:
        fail("malformed", "%s: zstd frame header has its reserved bit set" % where)
    p = 5 + (0 if single_segment else 1)          # Window_Descriptor
    did_size = (0, 1, 2, 4)[did_flag]
    fcs_size = (1 if single_segment else 0, 2, 4, 8)[fcs_flag]
    need(p + did_size + fcs_size, "frame header")
    p += start
    dictionary_id = int.from_bytes(data[p:p + did_size], "little")
    p += did_size
    if fcs_size == 0:
        fail("malformed", "%s: zstd frame header carries no Frame_Content_Size" % where)
    content_size = int.from_bytes(data[p:p + fcs_size], "little")
    content_size += 256 if fcs_size == 2 else 0
    p += fcs_size
    if size_rule is not None:
        size = size_rule(content_size)
    if dictionary_id != 0:
        fail("malformed", "%s: zstd frame needs dictionary %d" % (where, dictionary_id))
    if content_size != size:
        fail("malformed", "%s: zstd Frame_Content_Size is %d, expected %s = %d"
             % (where, content_size, size_name, size))
    p -= start
    # Walk the zstd blocks to find the end of the frame (RFC 8878 §3.1.1.2).
    while True:
        need(p + 3, "block header")
        block_header = int.from_bytes(data[start + p:start + p + 3], "little")
        p += 3
        last, block_type, block_size = block_header & 1, (block_header >> 1) & 3, block_header >> 3
        if block_type == 3:
            fail("malformed", "%s: zstd block of reserved type 3" % where)
        p += 1 if block_type == 1 else block_size
        need(p, "last zstd block")
        if last:
            break
    blocks_end = start + p
    checksum = None
    if has_checksum:
        need(p + 4, "content checksum")
        (checksum,) = struct.unpack_from("<I", data, start + p)
        p += 4
    return ZstdFrame(start, start + p, blocks_end, fhd, content_size, checksum)


def decompress_zstd_frame(data, fr, where):
    """Decode a frame found by parse_zstd_frame: it must decode to exactly its
    Frame_Content_Size bytes (`malformed` otherwise), and its content checksum,
    when present, must match (`checksum`, §13)."""
    size = fr.content_size
    # Decode the frame without its checksum; the checksum is verified below, so
    # that a wrong checksum is reported as class `checksum`.
    frame = (data[fr.start:fr.start + 4] + bytes([fr.fhd & ~0x04])
             + data[fr.start + 5:fr.blocks_end])
    try:
        out = zstandard.ZstdDecompressor(max_window_size=1 << 31).decompress(
            frame, max_output_size=size)
    except zstandard.ZstdError as err:
        fail("malformed", "%s: zstd frame does not decode: %s" % (where, err))
    if len(out) != size:
        fail("malformed", "%s: zstd frame decodes to %d bytes, expected %d"
             % (where, len(out), size))
    if fr.checksum is not None:
        actual = xxh64(out) & 0xFFFFFFFF
        if actual != fr.checksum:
            fail("checksum", "%s: zstd content checksum is 0x%08X, XXH64 of the content "
                 "gives 0x%08X" % (where, fr.checksum, actual))
    return out


def decode_zstd_frame(data, size, where, size_rule=None):
    """§7 codecs 1 and 2: exactly one zstd frame (RFC 8878 §3.1.1) with
    Frame_Content_Size.  Codec 2 applies the same frame rules (SPEC-NOTES 57).
    size_rule (codec 4, whose content size the frame states): checks the
    stated size and returns it, in place of a known `size`."""
    fr = parse_zstd_frame(data, 0, size, where, size_rule)
    if fr.end != len(data):
        fail("malformed", "%s: %d bytes follow the zstd frame (only one frame is allowed)"
             % (where, len(data) - fr.end))
    return decompress_zstd_frame(data, fr, where)


def decode_plane_frames(payload, n, w, where):
    """§7 codec 5 (1.3): exactly w zstd frames back to back and nothing else,
    frame p holding byte plane p (decoded byte i·w + p for i = 0 .. n - 1), each
    under every rule of codec 1 for its own content of n bytes.  Every frame
    is found and its header checked first, then that nothing follows the w-th
    frame, then each frame is decoded and its checksum verified, in order
    (SPEC-NOTES 82).  Returns the decoded bytes (the planes put back as for
    codec 2)."""
    frames = []
    at = 0
    for p in range(w):
        what = "%s: codec 5 frame %d (byte plane %d of %d)" % (where, p, p, w)
        if at == len(payload):   # fewer than w frames
            fail("malformed", "%s: the payload ends after %d zstd frame%s, codec 5 holds "
                 "w = %d (one per byte plane)" % (where, p, "" if p == 1 else "s", w))
        frames.append(parse_zstd_frame(payload, at, n, what, size_name="element_count n"))
        at = frames[-1].end
    if at != len(payload):       # more than w frames, a skippable frame, other bytes
        rest = payload[at:at + 4]
        kind = ("a further zstd frame" if rest == ZSTD_MAGIC else
                "a skippable frame" if is_skippable_magic(rest) else "bytes that are no frame")
        fail("malformed", "%s: %d bytes (%s) follow the %d zstd frames of codec 5, which holds "
             "exactly w frames and nothing else" % (where, len(payload) - at, kind, w))
    planes = b"".join(decompress_zstd_frame(
        payload, fr, "%s: codec 5 frame %d (byte plane %d of %d)" % (where, p, p, w))
        for p, fr in enumerate(frames))
    return unshuffle_byte_planes(planes, n, w)


# ============================================================ §11 Metadata

class _DuplicateKey(Exception):
    pass


def _object_without_duplicates(pairs):
    obj = {}
    for key, value in pairs:
        if key in obj:
            raise _DuplicateKey(key)
        obj[key] = value
    return obj


def _reject_constant(name):     # NaN, Infinity, -Infinity are not JSON (RFC 8259)
    raise ValueError("%s is not JSON" % name)


def _parse_int(text):           # Python refuses int() of > 4300 digits
    return int(text) if len(text) <= 4000 else float(text)


def _is_finite(v):
    try:
        return math.isfinite(float(v))
    except OverflowError:
        return False


def _is_number(v):
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _has_lone_surrogate(v):
    """True if a key or string of the parsed JSON cannot be encoded as UTF-8."""
    if isinstance(v, str):
        try:
            v.encode("utf-8")
        except UnicodeEncodeError:
            return True
        return False
    if isinstance(v, dict):
        return any(_has_lone_surrogate(k) or _has_lone_surrogate(x) for k, x in v.items())
    if isinstance(v, list):
        return any(_has_lone_surrogate(x) for x in v)
    return False


MAX_METADATA_DEPTH = 128                                                # §11


def json_nesting_depth(text, limit=MAX_METADATA_DEPTH):
    """§11: how deep arrays and objects nest (the top level counts 1), by a
    scan that skips strings; stops counting once past `limit`."""
    depth = deepest = 0
    in_string = False
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if in_string:
            if c == "\\":
                i += 1
            elif c == '"':
                in_string = False
        elif c == '"':
            in_string = True
        elif c in "[{":
            depth += 1
            if depth > deepest:
                deepest = depth
                if deepest > limit:
                    return deepest
        elif c in "]}" and depth > 0:
            depth -= 1
        i += 1
    return deepest


def read_metadata(r, ix):
    """§11: the metadata block (stream 1) holds a JSON object."""
    e = ix.metadata_block
    data = read_block(r, ix, e, limit=MAX_METADATA)
    where = "metadata (%s)" % ix.where(e)
    if data.startswith(b"\xef\xbb\xbf"):
        fail("malformed", "%s: starts with a UTF-8 byte-order mark" % where)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as err:
        fail("malformed", "%s: not valid UTF-8 (byte %d)" % (where, err.start))
    depth = json_nesting_depth(text)
    if depth > MAX_METADATA_DEPTH:   # §11, before the (recursive) parser runs
        fail("malformed", "%s: arrays and objects nest deeper than %d"
             % (where, MAX_METADATA_DEPTH))
    try:
        meta = json.loads(text, object_pairs_hook=_object_without_duplicates,
                          parse_constant=_reject_constant, parse_int=_parse_int)
    except _DuplicateKey as err:
        fail("malformed", "%s: an object contains key %r twice" % (where, err.args[0]))
    except ValueError as err:
        fail("malformed", "%s: not valid JSON: %s" % (where, err))
    except RecursionError:   # RFC 8259 §9 lets a parser limit nesting (SPEC-NOTES 35c)
        raise ReaderLimit("%s: JSON nested too deeply for this reader" % where)
    if not isinstance(meta, dict):
        fail("malformed", "%s: the top level is not a JSON object" % where)
    if _has_lone_surrogate(meta):   # §11: "\ud800" alone is not valid text
        fail("malformed", "%s: a string holds a lone surrogate escape" % where)

    def bad(key, what):
        fail("malformed", "%s: key %r %s" % (where, key, what))

    def number_triple(key, positive):
        v = meta.get(key)
        if not (isinstance(v, list) and len(v) == 3 and all(_is_number(a) for a in v)):
            bad(key, "must be an array of 3 numbers")
        for a in v:   # SPEC-NOTES 35d: numbers too large for binary64 are refused
            if not _is_finite(a) or (positive and not a > 0):
                bad(key, "holds %r, expected a finite%s number"
                    % (a, " positive" if positive else ""))

    for key in ("voxel_size", "unit", "origin", "value"):
        if key not in meta:
            bad(key, "is required and missing")
    number_triple("voxel_size", positive=True)
    if not isinstance(meta["unit"], str):
        bad("unit", "must be a string")
    number_triple("origin", positive=False)
    value = meta["value"]
    if not isinstance(value, dict):
        bad("value", "must be an object")
    if not isinstance(value.get("quantity"), str):
        bad("value.quantity", "is required and must be a string")
    if "unit" in value and not isinstance(value["unit"], str):
        bad("value.unit", "must be a string")
    for key in ("structure", "provenance", "user"):   # SPEC-NOTES 36: only their type
        if key in meta and not isinstance(meta[key], dict):
            bad(key, "must be an object")
    return meta


# ============================================================ §13 steps 1-5

def open_ivol(path):
    """Open a file and check everything up to and including the metadata
    (§13 steps 1-5).  Returns (reader, index, metadata)."""
    r = FileReader(path)
    try:
        header = read_header(r)                     # steps 1-3
        footer, idx = read_footer(r, header)        # step 4
        ix = read_index(header, footer, idx)        # step 5: index
        meta = read_metadata(r, ix)                 # step 5: metadata block
    except BaseException:
        r.close()
        raise
    return r, ix, meta


# ============================================================ §13 step 6: other blocks

def check_ignorable_block(r, ix, e):
    """§6.4: an ignorable block of an unknown stream is skipped; a verifying
    reader still checks its CRC-32C."""
    stored = r.read(e.file_offset, e.stored_size)
    if crc32c(stored) != e.crc:
        fail("checksum", "%s: CRC-32C of the ignorable block does not match" % ix.where(e))
    if ix.header.framed:
        check_block_header(ix, e, stored)


def read_streams(r, ix, top_level, check_ignorable):
    """§13 step 6 (SPEC-NOTES 10, 27): read the node blocks of levels < top_level
    and the value blocks of levels <= top_level, in table (file) order; check the
    CRCs of ignorable blocks when check_ignorable (SPEC-NOTES 12).  Returns
    (nodes, values) as little-endian numpy arrays."""
    n_nodes = ix.first_inner[top_level]
    n_values = ix.first_value[top_level] + ix.level_values[top_level]
    need = n_nodes * 8 + n_values * ix.width
    if need > LIMIT_DECODED_BYTES:
        raise ReaderLimit("the node and value arrays need %d bytes, this reader's limit "
                          "is %d" % (need, LIMIT_DECODED_BYTES))
    nodes = np.zeros(n_nodes, "<u8")
    values = np.zeros(n_values, "<u%d" % ix.width)
    for e in ix.blocks:
        if not known_stream(e.stream, ix.structure_kind):   # ignorable, unknown (§6.4)
            if check_ignorable:
                check_ignorable_block(r, ix, e)
            continue
        if e.stream == STREAM_NODES and e.level < top_level:
            target = nodes
        elif e.stream == STREAM_VALUES and e.level <= top_level:
            target = values
        else:
            continue        # the metadata (already read) or a block not needed
        data = read_block(r, ix, e)
        target[e.first_element:e.first_element + e.element_count] = \
            np.frombuffer(data, target.dtype)
    return nodes, values


# ============================================================ §8 The octree

POPCOUNT = np.array([bin(i).count("1") for i in range(256)], np.int64)
OCTANT = np.arange(8, dtype=np.int64)                  # c = x_bit + 2 y_bit + 4 z_bit
X_BIT, Y_BIT, Z_BIT = OCTANT & 1, (OCTANT >> 1) & 1, (OCTANT >> 2) & 1
FIC_BITS = np.uint64((1 << 56) - 1)


def ov(a, n, s):
    """§8.1: ov(a, n) = max(0, min(n, (a+1)·s) − a·s), for arrays a."""
    return np.maximum(0, np.minimum(n, (a + 1) * s) - a * s)


def weights_f64(wx, wy, wz, side):
    """w = ov·ov·ov converted to binary64 (§8.1, §10).  Exact integer product,
    then one rounding to nearest (exact while w <= 2^53; SPEC-NOTES 30)."""
    if side ** 3 < 1 << 63:
        return (wx * wy * wz).astype(np.float64)
    return np.array([float(int(a) * int(b) * int(c))
                     for a, b, c in zip(wx.ravel(), wy.ravel(), wz.ravel())],
                    np.float64).reshape(wx.shape)


class Level:
    """The inner nodes of one level and their eight children, as the §8 walk
    found them (arrays in node order)."""


def walk_octree(ix, nodes, values, top_level):
    """§8.3/§8.4: visit the inner nodes of levels 0 .. top_level-1 breadth-first,
    check the structural rules, and return one Level per level with inner nodes."""
    D = ix.depth
    sx, sy, sz = ix.size
    levels = []
    if ix.inner_count[0] == 0:
        return levels                     # the root is a leaf (§8.3)
    ci = cj = ck = np.zeros(1, np.int64)  # node coordinates of the root
    vidx = np.zeros(1, np.int64)          # the root's value is value 0
    masks_before = 0                      # Σ popcount(child_mask) of all earlier nodes
    for l in range(top_level):
        count = ix.inner_count[l]
        if count == 0:
            break
        first = ix.first_inner[l]
        words = nodes[first:first + count]
        fic = (words & FIC_BITS).astype(np.int64)
        mask = (words >> np.uint64(56)).astype(np.int64)
        pop = POPCOUNT[mask]
        numbers = first + np.arange(count, dtype=np.int64)

        def refuse(bad, what):
            k = int(np.flatnonzero(bad)[0])
            fail("malformed", "nodes: inner node %d (level %d, node coordinates %d,%d,%d, "
                 "node word 0x%016X): %s" % (first + k, l, ci[k], cj[k], ck[k],
                                             int(words[k]), what(k)))

        # §8.3: first_inner_child(n) = 1 + Σ_{m<n} popcount(child_mask(m))
        expected = 1 + masks_before + np.cumsum(pop) - pop
        bad = fic != expected
        if bad.any():
            refuse(bad, lambda k: "first_inner_child is %d, expected %d (breadth-first "
                   "order)" % (fic[k], expected[k]))
        # §8.3: first_inner_child lies in the next level's range of inner nodes
        lo = ix.first_inner[l + 1]                       # l < top_level <= D
        hi = lo + ix.inner_count[l + 1]
        bad = ~((fic >= lo) & ((fic < hi) | ((fic == hi) & (mask == 0))))
        if bad.any():
            refuse(bad, lambda k: "first_inner_child %d outside %d..%d" % (fic[k], lo, hi))
        # §8.4: an inner node of level D-1 has child_mask 0
        if l == D - 1:
            bad = mask != 0
            if bad.any():
                refuse(bad, lambda k: "child_mask 0x%02X at level D-1, expected 0" % mask[k])
        # Geometry of the eight children (§8.1), side s = 2^(D-l-1)
        s = 1 << (D - l - 1)
        cx = 2 * ci[:, None] + X_BIT
        cy = 2 * cj[:, None] + Y_BIT
        cz = 2 * ck[:, None] + Z_BIT
        wx, wy, wz = ov(cx, sx, s), ov(cy, sy, s), ov(cz, sz, s)
        empty = (wx == 0) | (wy == 0) | (wz == 0)           # weight 0: all padding
        inner = ((mask[:, None] >> OCTANT) & 1).astype(bool)
        child_vidx = 1 + 8 * numbers[:, None] + OCTANT       # §8.3: values 1 + 8n + c
        child_values = values[child_vidx]
        # §8.4: a node of weight 0 is a leaf, and its value has all bits zero
        bad_child = empty & inner
        if bad_child.any():
            refuse(bad_child.any(axis=1), lambda k: "child %d has weight 0 (padding) but "
                   "is marked inner" % np.flatnonzero(bad_child[k])[0])
        bad_child = empty & (child_values != 0)
        if bad_child.any():
            refuse(bad_child.any(axis=1), lambda k: "child %d (value %d) has weight 0 "
                   "(padding) but its value 0x%X is not zero" % (
                       np.flatnonzero(bad_child[k])[0],
                       child_vidx[k][bad_child[k]][0], child_values[k][bad_child[k]][0]))
        # §8.4: Σ popcount(child_mask) over level l = inner_count[l + 1]
        total = int(pop.sum())
        expected_total = ix.inner_count[l + 1]
        if total != expected_total:
            fail("malformed", "nodes: level %d: the child masks mark %d inner children, "
                 "inner_count[%d] is %d" % (l, total, l + 1, expected_total))
        lv = Level()
        lv.level, lv.first, lv.count = l, first, count
        lv.ci, lv.cj, lv.ck, lv.vidx = ci, cj, ck, vidx
        lv.cx, lv.cy, lv.cz, lv.wx, lv.wy, lv.wz = cx, cy, cz, wx, wy, wz
        lv.empty, lv.inner, lv.child_vidx = empty, inner, child_vidx
        levels.append(lv)
        # The inner children, in (n, c) order, are the inner nodes of level l+1.
        ci, cj, ck, vidx = cx[inner], cy[inner], cz[inner], child_vidx[inner]
        masks_before += total
    return levels


# ============================================================ §9 Value encodings

def decode_values(values, encoding):
    """§9: the binary64 number `decoded` of each stored element."""
    with np.errstate(all="ignore"):
        if encoding == 1:
            return values.view("<f2").astype(np.float64)
        if encoding == 2:
            return values.astype(np.float64)
        return values.view("<f4").astype(np.float64)


def encode_binary16(m):
    """§9: round binary64 to the nearest binary16, ties to even, overflow to
    infinity; NaN -> 0x7E00.  Integer arithmetic on the bits, one rounding."""
    bits = m.view(np.uint64)
    sign = (bits >> np.uint64(63)).astype(np.int64) << 15
    exponent = ((bits >> np.uint64(52)) & np.uint64(0x7FF)).astype(np.int64)
    mantissa = (bits & np.uint64((1 << 52) - 1)).astype(np.int64) | (1 << 52)
    e = exponent - 1023                                  # m = mantissa · 2^(e-52)
    shift = np.minimum(42 + np.maximum(0, -14 - e), 60)  # to the binary16 quantum
    q = mantissa >> shift
    rest = mantissa & ((np.int64(1) << shift) - 1)
    half = np.int64(1) << (shift - 1)
    q += (rest > half) | ((rest == half) & ((q & 1) == 1))
    magnitude = np.where(e >= -14, ((e + 15) << 10) + (q - 1024), q)  # carry is natural
    magnitude = np.minimum(magnitude, 0x7C00)            # overflow -> infinity
    magnitude = np.where(exponent == 0, 0, magnitude)    # zero, binary64 subnormals
    magnitude = np.where(exponent == 0x7FF, 0x7C00, magnitude)  # infinity
    out = (sign | magnitude).astype(np.uint16)
    out[np.isnan(m)] = 0x7E00
    return out


def encode_values(m, encoding):
    """§9: encode(m) for an array of binary64 numbers; returns the stored bits."""
    with np.errstate(all="ignore"):
        if encoding == 1:
            return encode_binary16(m)
        if encoding == 2:
            return np.clip(np.rint(m), 0, 65535).astype(np.uint16)
        out = m.astype(np.float32).view(np.uint32).copy()
        out[np.isnan(m)] = 0x7FC00000
        return out


# ============================================================ §10 Inner-node averages

def check_averages(ix, values, levels):
    """§10: recompute m(node) bottom-up, in exactly the spec's order of
    operations, and compare encode(m) with every stored inner value bit for bit."""
    D = ix.depth
    decoded = decode_values(values, ix.value_encoding)
    m_of_level = [None] * len(levels)
    m_next = None          # m of the inner nodes of the level below, in node order
    with np.errstate(all="ignore"):
        for lv in reversed(levels):
            m_child = decoded[lv.child_vidx]                # leaves: decoded value
            if m_next is not None:
                m_child[lv.inner] = m_next                  # inner children: unrounded m
            side = 1 << (D - lv.level - 1)
            w = weights_f64(lv.wx, lv.wy, lv.wz, side)
            acc = np.zeros(lv.count)                        # acc = +0.0
            for c in range(8):                              # c = 0 … 7, in order
                take = w[:, c] > 0
                acc = np.where(take, acc + w[:, c] * m_child[:, c], acc)
            # W = Σ w(child) = w(node): the children partition the node's voxels
            W = weights_f64(ov(lv.ci, ix.size[0], 2 * side),
                            ov(lv.cj, ix.size[1], 2 * side),
                            ov(lv.ck, ix.size[2], 2 * side), 2 * side)
            m = acc / W
            m_of_level[lv.level] = m
            m_next = m
    for lv, m in zip(levels, m_of_level):                    # report top-down
        expected = encode_values(m, ix.value_encoding)
        stored = values[lv.vidx]
        bad = np.flatnonzero(expected != stored)
        if bad.size:
            k = int(bad[0])
            fail("malformed", "nodes: inner node %d (level %d, node coordinates %d,%d,%d) "
                 "stores value %d = 0x%X, the average of §10 encodes to 0x%X (m = %r)"
                 % (lv.first + k, lv.level, lv.ci[k], lv.cj[k], lv.ck[k], int(lv.vidx[k]),
                    int(stored[k]), int(expected[k]), float(m[k])))


# ============================================================ §12 Derived views

def build_level_of_detail(ix, values, levels, top_level):
    """§12.3 (and §12.2 for top_level = D): the array [z][y][x] of the values of
    the nodes of level top_level, a missing node taking the value of the leaf
    that covers it.  Built top-down on the non-padding extent of each level."""
    D = ix.depth
    sx, sy, sz = ix.size
    grid = values[0:1].reshape(1, 1, 1)                      # level 0: the root
    for l in range(top_level):
        s = 1 << (D - l - 1)
        extent = (-(-sz // s), -(-sy // s), -(-sx // s))     # ceil(size / s)
        grid = grid.repeat(2, 0).repeat(2, 1).repeat(2, 2)
        grid = grid[:extent[0], :extent[1], :extent[2]].copy()
        if l < len(levels):                                 # children of level l's inner nodes
            lv = levels[l]
            keep = ~lv.empty
            grid[lv.cz[keep], lv.cy[keep], lv.cx[keep]] = values[lv.child_vidx[keep]]
    return grid


def output_bytes(ix, top_level):
    k = ix.depth - top_level
    n = 1
    for size in ix.size:
        n *= -(-size // (1 << k))
    return n * ix.width


def check_output_limit(ix, top_level):
    need = output_bytes(ix, top_level)
    if need > LIMIT_OUTPUT_BYTES:
        raise ReaderLimit("the output needs %d bytes, this reader's limit is %d"
                          % (need, LIMIT_OUTPUT_BYTES))


# ============================================================ §8A Other structures

class Grid:
    """A structure of §8A as read and checked: the value array and what the
    cells of the structure need (borders of a rectilinear grid, cell words of a
    nested grid)."""


def read_grid_streams(r, ix, verify):
    """§13 step 6 for the kinds of §8A: read every block of streams 3, 4 and 5
    in table (file) order, then check the borders (§8A.2) or the cell words and
    their first_value chain (§8A.3), and that stream 3 holds total_values
    elements.  With verify (a whole-file check), also check the CRCs of
    ignorable blocks of unknown streams (SPEC-NOTES 12) and read the stored
    levels of detail of a bricked grid (stream 7, §8A.5) into g.stored, k ->
    the level's elements in its own brick order; without it, stream 7 is not
    read.  Every size was checked against the index or a limit before it is
    allocated."""
    kind = ix.structure_kind
    n_values = ix.value_elements
    n_borders = ix.border_elements if kind == KIND_RECTILINEAR else 0
    n_cells = ix.cell_count if kind == KIND_NESTED else 0
    stored_levels = getattr(ix, "stored_levels", []) if verify else []
    n_stored = sum(math.prod(level_size(ix.size, k)) for k in stored_levels)
    need = (n_values + n_stored) * ix.width + n_borders * 4 + n_cells * 8
    if need > LIMIT_DECODED_BYTES:
        raise ReaderLimit("the value, border and cell arrays need %d bytes, this "
                          "reader's limit is %d" % (need, LIMIT_DECODED_BYTES))
    arrays = {STREAM_VALUES: np.zeros(n_values, "<u%d" % ix.width),
              STREAM_BORDERS: np.zeros(n_borders, "<u4"),
              STREAM_CELLS: np.zeros(n_cells, "<u8")}
    stored = {k: np.zeros(math.prod(level_size(ix.size, k)), "<u%d" % ix.width)
              for k in stored_levels}
    for e in ix.blocks:
        if not known_stream(e.stream, ix.structure_kind):   # ignorable, unknown (§6.4)
            if verify:
                check_ignorable_block(r, ix, e)
            continue
        if e.stream == STREAM_METADATA:
            continue                        # already read
        if e.stream == STREAM_STORED_LOD:
            if not verify:
                continue                    # computed from full resolution instead (§12.3)
            target = stored[e.level]
        else:
            target = arrays[e.stream]       # streams 3, 4, 5 (check_stream_kind)
        data = read_block(r, ix, e)
        target[e.first_element:e.first_element + e.element_count] = \
            np.frombuffer(data, target.dtype)
    g = Grid()
    g.values = arrays[STREAM_VALUES]
    g.stored = stored
    if kind in (KIND_REGULAR, KIND_BRICKED):
        g.total_values = ix.total_values
    elif kind == KIND_RECTILINEAR:
        g.borders = check_borders(ix, arrays[STREAM_BORDERS])
        g.intervals = tuple(len(b) - 1 for b in g.borders)
        g.total_values = g.intervals[0] * g.intervals[1] * g.intervals[2]
    else:
        check_cells(ix, arrays[STREAM_CELLS], g)
    if g.total_values != n_values:
        fail("malformed", "block table: stream 3 (values) covers elements 0..%d, §8A "
             "gives total_values %d for this %s" % (n_values, g.total_values,
                                                   ix.structure_name))
    return g


def check_borders(ix, stream):
    """§8A.2: stream 4 holds B_x, B_y, B_z one after the other; each starts with
    0, increases strictly and ends with the size along its axis.  B_x and B_y
    end at their first element (after the first) equal to size_x, size_y; B_z
    ends at the last element of the stream.  Returns the three lists.  Order of
    the checks: SPEC-NOTES 51."""
    b = stream.astype(np.int64)
    n = len(b)
    lists = []
    at = 0
    for axis, name in enumerate("xyz"):
        size = ix.size[axis]
        where = "borders (stream 4): B_%s" % name
        if at >= n:
            fail("malformed", "%s would start at element %d, but the stream has only %d "
                 "elements" % (where, at, n))
        if b[at] != 0:
            fail("malformed", "%s starts at element %d with %d, expected 0"
                 % (where, at, b[at]))
        if axis < 2:
            hits = np.flatnonzero(b[at + 1:] == size)
            end = at + 1 + int(hits[0]) if hits.size else n - 1
        else:
            end = n - 1
        part = b[at:end + 1]
        steps = np.flatnonzero(np.diff(part) <= 0)
        if steps.size:
            k = at + 1 + int(steps[0])
            fail("malformed", "%s does not increase strictly: element %d is %d after %d"
                 % (where, k, b[k], b[k - 1]))
        if part[-1] != size or len(part) < 2:
            fail("malformed", "%s ends %s with %d, expected size_%s = %d"
                 % (where, "at the end of the stream" if axis == 2 or not hits.size
                    else "at element %d" % end, part[-1], name, size))
        lists.append(part)
        at = end + 1
    return lists


def check_cells(ix, words, g):
    """§8A.3: the exponent of every cell word is 0 .. cell_log2, and first_value
    follows the chain 0, then previous first_value + m_x·m_y·m_z, in cell order.
    Sets g.exponent, g.first_value, g.m (m_x, m_y, m_z per cell, shape
    (n_z, n_y, n_x)) and g.total_values."""
    L = ix.cell_log2
    C = 1 << L
    nx, ny, nz = ix.cells
    first_value = (words & FIC_BITS).astype(np.int64)
    exponent = (words >> np.uint64(56)).astype(np.int64)
    bad_e = np.flatnonzero(exponent > L)
    e = np.minimum(exponent, L)
    shift = L - e                                       # h = C >> e = 2^shift

    def extents(size, n):                               # ext_a = min(C, size_a − c_a·C)
        return np.minimum(C, size - np.arange(n, dtype=np.int64) * C)

    ext = [extents(ix.size[0], nx)[None, None, :], extents(ix.size[1], ny)[None, :, None],
           extents(ix.size[2], nz)[:, None, None]]
    sh = shift.reshape(nz, ny, nx)
    m = [((ea + (np.int64(1) << sh) - 1) >> sh).ravel() for ea in ext]  # ceil(ext / h)
    # m_x·m_y·m_z per cell; clipped at 2^56, where no later first_value can match
    # (SPEC-NOTES 50), so that the int64 running sum cannot wrap before the first
    # mismatch.
    xy = m[0] * m[1]                                    # <= 2^62
    cap = np.int64(1) << 56
    big = xy > cap // m[2]
    count = np.where(big, cap, xy * np.where(big, 1, m[2]))
    expected = np.concatenate(([0], np.cumsum(count)[:-1]))
    bad_c = np.flatnonzero(first_value != expected)
    first_bad = min([int(a[0]) for a in (bad_e, bad_c) if a.size], default=None)
    if first_bad is not None:
        k = first_bad
        i, j, kk = k % nx, (k // nx) % ny, k // (nx * ny)
        where = "cells (stream 5): cell %d (cell coordinates %d,%d,%d, cell word 0x%016X)" \
            % (k, i, j, kk, int(words[k]))
        if bad_e.size and bad_e[0] == k:
            fail("malformed", "%s: exponent %d, expected 0..cell_log2 = %d"
                 % (where, exponent[k], L))
        fail("malformed", "%s: first_value %d, expected %d (the previous cell's "
             "first_value + its voxel count)" % (where, first_value[k], expected[k]))
    last = len(words) - 1
    g.exponent, g.first_value = e, first_value
    g.m = [a.reshape(nz, ny, nx) for a in m]
    g.total_values = (int(first_value[last]) + int(m[0][last]) * int(m[1][last])
                      * int(m[2][last]))


def grid_dense(ix, g):
    """§12.2 for §8A: the stored bits of the cell covering each voxel, [z][y][x]."""
    sx, sy, sz = ix.size
    kind = ix.structure_kind
    if kind == KIND_REGULAR:                      # §8A.1: (z·size_y + y)·size_x + x
        return g.values.reshape(sz, sy, sx)
    if kind == KIND_BRICKED:                      # §8A.4: brick by brick
        return unbrick(g.values, ix.size, ix.cell_log2)
    if kind == KIND_RECTILINEAR:                  # §8A.2: (k·n_y + j)·n_x + i
        nx, ny, nz = g.intervals
        cell = [np.repeat(np.arange(len(b) - 1), np.diff(b)) for b in g.borders]
        return g.values.reshape(nz, ny, nx)[np.ix_(cell[2], cell[1], cell[0])]
    # §8A.3, one z plane at a time
    L = ix.cell_log2
    mask = (1 << L) - 1
    nx, ny, nz = ix.cells
    x, y = np.arange(sx, dtype=np.int64), np.arange(sy, dtype=np.int64)
    cx, lx = (x >> L)[None, :], (x & mask)[None, :]
    cy, ly = (y >> L)[:, None], (y & mask)[:, None]
    e = g.exponent.reshape(nz, ny, nx)
    fv = g.first_value.reshape(nz, ny, nx)
    mx, my = g.m[0], g.m[1]
    out = np.empty((sz, sy, sx), g.values.dtype)
    for z in range(sz):
        cz, lz = z >> L, z & mask
        sh = (L - e[cz])[cy, cx]                  # voxel edge h = 2^sh in each cell
        p, q, r = lx >> sh, ly >> sh, lz >> sh
        index = fv[cz][cy, cx] + (r * my[cz][cy, cx] + q) * mx[cz][cy, cx] + p
        out[z] = g.values[index]
    return out


def unbrick(values, size, b):
    """§8A.4 (and §8A.5 for a stored level of detail, with its sizes m_a): the
    array [z][y][x] of a bricked grid of the given size and brick edge 2^b,
    from its elements in brick order.  Element (x, y, z) is element
    first(x >> b, y >> b, z >> b) + ((z mod B)·e_y + (y mod B))·e_x + (x mod B)."""
    sx, sy, sz = size
    B, m = 1 << b, (1 << b) - 1
    z = np.arange(sz, dtype=np.int64)[:, None, None]
    y = np.arange(sy, dtype=np.int64)[None, :, None]
    x = np.arange(sx, dtype=np.int64)[None, None, :]
    i, j, k = x >> b, y >> b, z >> b
    ex, ey, ez = np.minimum(B, sx - i * B), np.minimum(B, sy - j * B), np.minimum(B, sz - k * B)
    first = k * B * sy * sx + j * B * sx * ez + i * B * ey * ez
    return values[first + ((z & m) * ey + (y & m)) * ex + (x & m)]


def check_stored_levels_equal(ix, g, dense):
    """§8A.5, §13: a verifying reader checks that every stored level of detail
    k holds exactly the bits of level of detail k computed from full
    resolution by §12.3 (`malformed` otherwise; SPEC-NOTES 68)."""
    for k in sorted(g.stored):
        stored = unbrick(g.stored[k], level_size(ix.size, k), ix.cell_log2)
        computed = lod_from_dense(ix, dense, k)
        bad = np.argwhere(stored != computed)
        if bad.size:
            z, y, x = (int(a) for a in bad[0])
            fail("malformed", "stored level of detail %d (stream 7): element (%d, %d, %d) is "
                 "0x%X, level of detail %d computed from full resolution (§12.3) is 0x%X"
                 % (k, x, y, z, int(stored[z, y, x]), k, int(computed[z, y, x])))


def read_stored_level(r, ix, k):
    """§8A.5, §12.3: level of detail k of a bricked grid that stores it, read
    from the blocks of stream 7 of level k alone (their CRCs, block headers
    and codecs checked as for any block read), not from full resolution.  A
    reader that does not verify trusts the stored values (§8A.5, SPEC-NOTES 67)."""
    values = np.zeros(math.prod(level_size(ix.size, k)), "<u%d" % ix.width)
    for e in ix.blocks:
        if e.stream == STREAM_STORED_LOD and e.level == k:
            data = read_block(r, ix, e)
            values[e.first_element:e.first_element + e.element_count] = \
                np.frombuffer(data, values.dtype)
    return unbrick(values, level_size(ix.size, k), ix.cell_log2)


def lod_from_dense(ix, dense, k):
    """§12.3 for §8A: each element of level of detail k >= 1 is the mean of the
    decoded values of its cell, summed in binary64 from +0.0 in the order z, then
    y, then x (x fastest), divided by their number, and encoded (§9).  The sum is
    sequential: np.cumsum (np.add.accumulate) adds one element after the other,
    unlike np.sum, which adds pairwise.  Level of detail 0 is the dense export
    itself (SPEC-NOTES 42)."""
    if k == 0:
        return dense
    B = 1 << k
    sz, sy, sx = dense.shape
    oz, oy, ox = -(-sz // B), -(-sy // B), -(-sx // B)
    # Cells of one output row along y (or x): full ones of edge B, and a last,
    # partial one of edge size % B.
    def groups(size):
        full = size // B
        out = [(0, full, B)] if full else []
        if size % B:
            out.append((full, full + 1, size % B))
        return out

    by = np.minimum(B, sy - np.arange(oy) * B)
    bx = np.minimum(B, sx - np.arange(ox) * B)
    out = np.empty((oz, oy, ox), dense.dtype)
    with np.errstate(all="ignore"):
        for zc in range(oz):
            acc = np.zeros((oy, ox))                         # +0.0
            z0, z1 = zc * B, min((zc + 1) * B, sz)
            for z in range(z0, z1):                          # z, then y, then x
                plane = decode_values(dense[z], ix.value_encoding)
                for gy0, gy1, ey in groups(sy):
                    for gx0, gx1, ex in groups(sx):
                        part = plane[gy0 * B:gy0 * B + (gy1 - gy0) * ey,
                                     gx0 * B:gx0 * B + (gx1 - gx0) * ex]
                        part = part.reshape(gy1 - gy0, ey, gx1 - gx0, ex)
                        part = part.transpose(0, 2, 1, 3).reshape(gy1 - gy0, gx1 - gx0,
                                                                  ey * ex)
                        seq = np.concatenate((acc[gy0:gy1, gx0:gx1, None], part), axis=2)
                        acc[gy0:gy1, gx0:gx1] = np.cumsum(seq, axis=2)[:, :, -1]
            number = ((z1 - z0) * by[:, None] * bx[None, :]).astype(np.float64)
            out[zc] = encode_values(acc / number, ix.value_encoding)
    return out


def check_dense_limit(ix):
    need = output_bytes(ix, ix.depth)
    if need > LIMIT_OUTPUT_BYTES:
        raise ReaderLimit("the dense export, from which the level of detail of a %s is "
                          "computed, needs %d bytes, this reader's limit is %d"
                          % (ix.structure_name, need, LIMIT_OUTPUT_BYTES))


# ============================================================ whole-file operations

def verify_file(path, want_dense=False):
    """Full verification (§13 steps 1-6, all blocks, all nodes, all averages).
    Returns (index, metadata, dense bytes or None)."""
    r, ix, meta = open_ivol(path)
    try:
        D = ix.depth
        if want_dense:
            check_output_limit(ix, D)
        if ix.structure_kind != KIND_OCTREE:          # §8A
            g = read_grid_streams(r, ix, verify=True)
            if not (want_dense or g.stored):
                return ix, meta, None
            if g.stored:                          # §8A.5: compared with the computed levels
                check_dense_limit(ix)
            dense = grid_dense(ix, g)
            check_stored_levels_equal(ix, g, dense)
            return ix, meta, dense.tobytes() if want_dense else None
        nodes, values = read_streams(r, ix, D, check_ignorable=True)
        levels = walk_octree(ix, nodes, values, D)
        check_averages(ix, values, levels)
        dense = None
        if want_dense:
            dense = build_level_of_detail(ix, values, levels, D).tobytes()
        return ix, meta, dense
    finally:
        r.close()


def level_of_detail(path, k):
    """§12.3: level of detail k, reading only the blocks of levels <= D - k.
    Returns (index, bytes).  With k = 0 all blocks are read and the averages
    (or a bricked grid's stored levels of detail) are checked as well.  A
    level k >= 1 that a bricked grid stores is read from stream 7 alone
    (§8A.5)."""
    r, ix, meta = open_ivol(path)
    try:
        D = ix.depth
        if not 0 <= k <= D:
            raise UsageError("level of detail %d out of range 0..%d for this file" % (k, D))
        top = D - k
        check_output_limit(ix, top)
        if ix.structure_kind == KIND_BRICKED and k in ix.stored_levels:   # §8A.5
            return ix, read_stored_level(r, ix, k).tobytes()
        if ix.structure_kind != KIND_OCTREE:          # §8A: from the dense export
            check_dense_limit(ix)
            g = read_grid_streams(r, ix, verify=(k == 0))
            dense = grid_dense(ix, g)
            if k == 0:
                check_stored_levels_equal(ix, g, dense)
            return ix, lod_from_dense(ix, dense, k).tobytes()
        nodes, values = read_streams(r, ix, top, check_ignorable=(k == 0))
        levels = walk_octree(ix, nodes, values, top)
        if k == 0:
            check_averages(ix, values, levels)
        return ix, build_level_of_detail(ix, values, levels, top).tobytes()
    finally:
        r.close()


def info(path):
    r, ix, meta = open_ivol(path)
    r.close()
    h = ix.header
    blocks = []
    for e in ix.blocks:
        blocks.append({"block": e.number, "stream": e.stream,
                       "stream_name": STREAM_NAMES[e.stream]
                       if known_stream(e.stream, ix.structure_kind) else "unknown (ignorable)",
                       "level": e.level, "codec": e.codec, "flags": e.flags,
                       "file_offset": e.file_offset, "stored_size": e.stored_size,
                       "first_element": e.first_element,
                       "element_count": e.element_count, "crc": "0x%08X" % e.crc})
    per_stream = {}
    for e in ix.blocks:
        s = per_stream.setdefault(STREAM_NAMES[e.stream] if known_stream(e.stream, ix.structure_kind)
                                  else "stream %d" % e.stream,
                                  {"blocks": 0, "elements": 0, "stored_bytes": 0})
        s["blocks"] += 1
        s["elements"] += e.element_count
        s["stored_bytes"] += e.stored_size
    out = {
        "version": "%d.%d" % (h.version_major, h.version_minor),
        "version_major": h.version_major, "version_minor": h.version_minor,
        "header_size": h.header_size, "optional_features": h.optional_features,
        "file_size": ix.footer.index_offset + ix.footer.index_size + 32,
        "index_offset": ix.footer.index_offset, "index_size": ix.footer.index_size,
        "sizes": list(ix.size), "size_x": ix.size[0], "size_y": ix.size[1],
        "size_z": ix.size[2], "depth": ix.depth,
        "encoding": ix.encoding_name, "value_encoding": ix.value_encoding,
        "scale": ix.value_scale, "offset": ix.value_offset,
        "structure_kind": ix.structure_kind, "structure": ix.structure_name,
        "inner_count": ix.inner_count, "total_inner": ix.total_inner,
        "total_values": ix.total_values,
        "block_count": len(ix.blocks), "blocks_per_stream": per_stream,
        "blocks": blocks, "metadata": meta,
    }
    if ix.structure_kind != KIND_OCTREE:
        # §8A: total_values of kinds 3 and 4 follows from streams 4 and 5, which
        # info does not read (null then); value_elements is what stream 3 covers.
        out["value_elements"] = ix.value_elements
    if ix.structure_kind == KIND_RECTILINEAR:
        out["border_elements"] = ix.border_elements
    if ix.structure_kind == KIND_BRICKED:
        out["brick_log2"] = ix.cell_log2
        out["stored_levels"] = ix.stored_levels        # §8A.5: levels of detail in stream 7
    if ix.structure_kind == KIND_NESTED:
        out["cell_log2"] = ix.cell_log2
        out["cell_edge"] = 1 << ix.cell_log2
        out["cells"] = list(ix.cells)
        out["cell_count"] = ix.cell_count
    return out


# ============================================================ conformance runner

def run_conformance(manifest_path):
    """Run every vector of a manifest; returns the number of failures."""
    with open(manifest_path, "rb") as f:
        manifest = json.loads(f.read().decode("utf-8"))
    base = os.path.dirname(os.path.abspath(manifest_path))
    vectors = manifest["vectors"]
    passed = failed = 0
    for number, v in enumerate(vectors):
        name = v.get("file", "#%d" % number) if isinstance(v, dict) else "#%d" % number
        try:
            problems = run_vector(base, v)
        except Exception as err:   # a broken manifest entry fails its vector only
            problems = ["cannot run vector: %s: %s" % (type(err).__name__, err)]
        if problems:
            failed += 1
            print("FAIL %s: %s" % (name, "; ".join(problems)))
        else:
            passed += 1
            print("PASS %s" % name)
    print("%d passed, %d failed" % (passed, failed))
    return failed


def run_vector(base, v):
    path = os.path.join(base, v["file"])
    expect = v["expect"]
    problems = []
    try:
        _, _, dense = verify_file(path, want_dense=expect == "ok" and "dense" in v)
        got, message = "ok", ""
    except IvolError as err:
        got, message = err.cls, err.message
    except ReaderLimit as err:
        got, message = "reader-limit", str(err)
    if got != expect:
        return ["expected %s, got %s%s" % (expect, got, ": " + message if message else "")]
    if expect != "ok":
        return []
    if "dense" in v:
        with open(os.path.join(base, v["dense"]), "rb") as f:
            want = f.read()
        if dense != want:
            problems.append("dense export differs (%d bytes, expected %d)%s"
                            % (len(dense), len(want), first_difference(dense, want)))
    for k, raw in sorted((v.get("lod") or {}).items(), key=lambda kv: int(kv[0])):
        with open(os.path.join(base, raw), "rb") as f:
            want = f.read()
        try:
            _, got_bytes = level_of_detail(path, int(k))
        except (IvolError, ReaderLimit, UsageError) as err:
            problems.append("lod %s: %s" % (k, err))
            continue
        if got_bytes != want:
            problems.append("lod %s differs (%d bytes, expected %d)%s"
                            % (k, len(got_bytes), len(want),
                               first_difference(got_bytes, want)))
    return problems


def first_difference(a, b):
    for i in range(min(len(a), len(b))):
        if a[i] != b[i]:
            return ", first difference at byte %d" % i
    return ""


# ============================================================ §18 Salvage (informative)

class SalvageIndex:
    """What §18 step 3 rebuilds: enough of an Index for where() and
    decode_payload(), the level table and the blocks placed."""

    def where(self, e):
        return "block at offset %d (stream %d, level %d)" % (e.file_offset, e.stream, e.level)


def salvage_header(data):
    """§18 step 1: the header, with its volume descriptor, must be intact."""
    if len(data) < 16 or data[:8] != SIGNATURE:
        fail("truncated", "salvage: the header is cut or not an .ivol header")
    major, minor, header_size = struct.unpack_from("<HHI", data, 8)
    if major != 1 or not 80 <= header_size <= 4096 or len(data) < header_size:
        fail("truncated", "salvage: version %d, header_size %d, or the header is cut"
             % (major, header_size))
    (stored_crc,) = struct.unpack_from("<I", data, header_size - 4)
    if crc32c(data[:header_size - 4]) != stored_crc:
        fail("checksum", "salvage: the header's CRC-32C does not match")
    (required,) = struct.unpack_from("<Q", data, 16)
    if required != FEATURE_FRAMED_BLOCKS:
        fail("unsupported-feature", "salvage: required_features is 0x%X; only framed "
             "files (bit 0 alone) can be salvaged" % required)
    ix = SalvageIndex()
    ix.header_size = header_size
    (kind, encoding, depth, cell_log2, sx, sy, sz, scale, offset) = \
        struct.unpack_from("<4B3I2d", data, 36)
    if kind not in KIND_NAMES or encoding not in ENCODINGS:
        fail("unsupported-feature", "salvage: structure_kind %d / value_encoding %d"
             % (kind, encoding))
    if kind == KIND_BRICKED:   # not built in this reader (the library salvages them)
        fail("unsupported-feature", "salvage: this reader does not salvage structure_kind 5 "
             "(bricked regular grid)")
    if min(sx, sy, sz) < 1 or depth != (max(sx, sy, sz) - 1).bit_length():
        fail("malformed", "salvage: the volume descriptor's sizes or depth are wrong")
    ix.structure_kind, ix.value_encoding, ix.depth = kind, encoding, depth
    ix.encoding_name, ix.width = ENCODINGS[encoding]
    ix.size = (sx, sy, sz)
    ix.cell_log2 = cell_log2
    return ix


_crc_memo = {}


def _crc_of(b):
    """crc32c, remembered: salvaging every cut of a file checks the same blocks again."""
    if b not in _crc_memo:
        _crc_memo[b] = crc32c(b)
    return _crc_memo[b]


def salvage_scan(data, start):
    """§18 step 2: walk the blocks from `start`; where a header does not hold,
    search forward for the next IVBK whose header_crc and payload_crc hold.
    Returns the blocks found, as (BlockEntry, payload)."""
    found = []
    pos = start
    while pos < len(data):
        if len(data) - pos > BLOCK_HEADER_SIZE and data[pos:pos + 4] == BLOCK_SIGNATURE:
            h = parse_block_header(data[pos:pos + BLOCK_HEADER_SIZE])
            end = pos + BLOCK_HEADER_SIZE + h.payload_size
            if (_crc_of(data[pos:pos + 28]) == h.header_crc and h.payload_size > 0
                    and end <= len(data)
                    and _crc_of(data[pos + BLOCK_HEADER_SIZE:end]) == h.payload_crc):
                e = BlockEntry(len(found), pos, h.first_element, h.element_count,
                               BLOCK_HEADER_SIZE + h.payload_size, None, h.stream, h.codec,
                               h.flags, h.level)
                found.append((e, data[pos + BLOCK_HEADER_SIZE:end]))
                pos = end
                continue
        nxt = data.find(BLOCK_SIGNATURE, pos + 1)
        pos = len(data) if nxt < 0 else nxt
    return found


def salvage_usable(ix, found, stream):
    """Blocks of `stream` whose fields an index entry could have had (§6.3,
    §6.4, §7), by first_element; one overlapping an earlier one is dropped."""
    out = []
    for e, payload in sorted((b for b in found if b[0].stream == stream),
                             key=lambda b: b[0].first_element):
        size = e.element_count * stream_width(ix, stream)
        if (e.flags != 0 or e.codec not in (0, 1, 2, 5) or e.element_count < 1
                or size > MAX_BLOCK_DECODED
                or (e.codec == 0 and len(payload) != size) or e.level > ix.depth
                or (ix.structure_kind != KIND_OCTREE and e.level != 0)):
            continue
        if out and e.first_element < out[-1][0].first_element + out[-1][0].element_count:
            continue
        out.append((e, payload))
    return out


def salvage_decode(ix, e, payload):
    try:
        return decode_payload(ix, e, payload)
    except IvolError:
        return None


def salvage(data):
    """§18: the volume of a cut or damaged framed file, from its blocks alone.
    Returns (summary dict, dense stored bits as a numpy array in [z][y][x])."""
    ix = salvage_header(data)
    found = salvage_scan(data, ix.header_size)
    summary = {"blocks_found": len(found), "metadata": "missing"}
    # §15: the metadata block when it survived, else the early metadata (stream 6).
    for stream, name in ((STREAM_METADATA, "complete"), (6, "early")):
        for e, payload in found:
            # codecs 0, 1 and 2 (which is codec 1 for w = 1) hold text; codec 5
            # is not valid on a stream of width 1 (§7, SPEC-NOTES 84)
            if e.stream != stream or summary["metadata"] != "missing" or e.codec not in (0, 1, 2):
                continue
            try:
                text = payload if e.codec == 0 else decode_zstd_frame(
                    payload, e.element_count, ix.where(e))
                if isinstance(json.loads(text.decode("utf-8")), dict):
                    summary["metadata"] = name
            except (IvolError, ValueError):
                pass
    sx, sy, sz = ix.size
    dtype = "<u%d" % ix.width
    dense = np.zeros((sz, sy, sx), dtype)
    filled = np.ones((sz, sy, sx), bool)    # voxels that did not get their own value
    if ix.structure_kind == KIND_REGULAR:   # §18 step 4: no coarser level; fill 0
        for e, payload in salvage_usable(ix, found, STREAM_VALUES):
            if e.first_element + e.element_count > sx * sy * sz:
                continue
            decoded = salvage_decode(ix, e, payload)
            if decoded is not None:
                flat = dense.reshape(-1)
                flat[e.first_element:e.first_element + e.element_count] = \
                    np.frombuffer(decoded, dtype)
                filled.reshape(-1)[e.first_element:e.first_element + e.element_count] = False
        summary["filled_voxels"] = int(filled.sum())
        return summary, dense
    if ix.structure_kind != KIND_OCTREE:
        raise UsageError("salvage of rectilinear and nested grids is not implemented here")
    D = ix.depth
    nodes_found = salvage_usable(ix, found, STREAM_NODES)
    values_found = salvage_usable(ix, found, STREAM_VALUES)
    # §18 step 3: inner_count[l + 1] from the masks of level l while every node
    # of level l was found; the root is taken as inner (a leaf root has no
    # node word to tell it).  Past that level the next level's count is at most
    # 8 x inner_count[l], its values are used, and deeper levels are absent.
    counts = [0] * (D + 1)
    counts[0] = 1 if D > 0 else 0
    first_inner = lambda l: sum(counts[:l])
    node_words = {}
    known = D
    for l in range(D):
        lo, n = first_inner(l), counts[l]
        level_blocks = [(e, p) for e, p in nodes_found if e.level == l
                        and lo <= e.first_element and e.first_element + e.element_count <= lo + n]
        held = 0
        for e, payload in level_blocks:
            words = salvage_decode(ix, e, payload)
            if words is None:
                continue
            held += e.element_count
            for k, w in enumerate(np.frombuffer(words, "<u8")):
                node_words[e.first_element + k] = int(w)
        if held != n:
            if l + 1 < D:
                counts[l + 1] = 8 * counts[l]
            known = l
            break
        counts[l + 1] = 0 if l + 1 == D else sum(
            bin(node_words[lo + k] >> 56).count("1") for k in range(n))
    value_of = {}
    for l in range(min(known + 1, D) + 1):
        lo = 0 if l == 0 else 1 + 8 * first_inner(l - 1)
        n = 1 if l == 0 else 8 * counts[l - 1]
        for e, payload in values_found:
            if e.level == l and lo <= e.first_element and e.first_element + e.element_count <= lo + n:
                decoded = salvage_decode(ix, e, payload)
                if decoded is not None:
                    for k, v in enumerate(np.frombuffer(decoded, dtype)):
                        value_of[e.first_element + k] = int(v)
    # §18 step 4: each voxel takes its leaf's value where it survived, else the
    # value of its nearest ancestor that survived (0 where none did).
    fic_mask = (1 << 56) - 1

    def visit(l, i, j, k, vidx, inner, fallback):
        have = vidx in value_of
        own = value_of[vidx] if have else fallback
        word = node_words.get(inner) if inner is not None else None
        if word is not None:   # §8.3 range and §8.4 rules, as any reader checks them
            mask, fic = word >> 56, word & fic_mask
            lo = first_inner(l + 1)
            if (l + 1 > D or (l + 1 == D and mask) or fic < lo
                    or fic + bin(mask).count("1") > lo + counts[l + 1]):
                word = None
        if word is None:
            s = 1 << (D - l)
            region = (slice(k * s, (k + 1) * s), slice(j * s, (j + 1) * s),
                      slice(i * s, (i + 1) * s))
            dense[region] = own
            filled[region] = not (have and inner is None)
            return
        nxt = fic
        for c in range(8):
            child = None
            if mask >> c & 1:
                child, nxt = nxt, nxt + 1
            ci, cj, ck = 2 * i + (c & 1), 2 * j + (c >> 1 & 1), 2 * k + (c >> 2 & 1)
            s = 1 << (D - l - 1)
            if ci * s < sx and cj * s < sy and ck * s < sz:
                visit(l + 1, ci, cj, ck, 1 + 8 * inner + c, child, own)

    visit(0, 0, 0, 0, 0, 0 if counts[0] else None, 0)
    summary["levels_known"] = known
    summary["filled_voxels"] = int(filled.sum())
    return summary, dense


def salvage_command(path, out, every_cut):
    with open(path, "rb") as f:
        data = f.read()
    if not every_cut:
        summary, dense = salvage(data)
        with open(out, "wb") as f:
            f.write(dense.tobytes())
        print(json.dumps(summary))
        return
    # Every prefix of the file: one record each, a byte 1 and the dense bits
    # when it salvaged, a byte 0 and zeros when not (tests cross-check this).
    size = None
    records = []
    for cut in range(len(data)):
        try:
            _, dense = salvage(data[:cut])
            records.append(b"\x01" + dense.tobytes())
            size = len(records[-1]) - 1
        except IvolError:
            records.append(None)
    if size is None:
        raise UsageError("no cut of %s can be salvaged" % path)
    with open(out, "wb") as f:
        for r in records:
            f.write(r if r is not None else bytes(size + 1))


# ============================================================ command line

def main(argv=None):
    parser = argparse.ArgumentParser(
        prog="ivolref.py", description="Reference reader for .ivol version 1.2 "
        "(written from format-spec/ivol.md alone).")
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("check", help="full verification; prints ok")
    p.add_argument("file")
    p = sub.add_parser("dense", help="full verification and dense export (§12.2)")
    p.add_argument("file")
    p.add_argument("-o", dest="out", required=True)
    p = sub.add_parser("lod", help="level of detail K (§12.3), partial read")
    p.add_argument("file")
    p.add_argument("k", type=int)
    p.add_argument("-o", dest="out", required=True)
    p = sub.add_parser("info", help="JSON summary of header, index and metadata")
    p.add_argument("file")
    p = sub.add_parser("conformance", help="run the vectors of a JSON manifest")
    p.add_argument("manifest")
    p = sub.add_parser("salvage", help="the volume of a cut or damaged framed file "
                       "(§18): dense stored bits, missing regions from coarser levels")
    p.add_argument("file")
    p.add_argument("-o", dest="out", required=True)
    p.add_argument("--every-cut", action="store_true",
                   help="salvage every prefix of the file; one record per cut")
    args = parser.parse_args(argv)

    try:
        _selftest_crc32c()
        if args.command == "check":
            verify_file(args.file)
            print("ok")
        elif args.command == "dense":
            _, _, dense = verify_file(args.file, want_dense=True)
            with open(args.out, "wb") as f:
                f.write(dense)
        elif args.command == "lod":
            _, data = level_of_detail(args.file, args.k)
            with open(args.out, "wb") as f:
                f.write(data)
        elif args.command == "info":
            print(json.dumps(info(args.file), indent=2))
        elif args.command == "salvage":
            salvage_command(args.file, args.out, args.every_cut)
        elif args.command == "conformance":
            try:
                failed = run_conformance(args.manifest)
            except (OSError, ValueError, KeyError, TypeError) as err:
                print("error: usage: cannot read manifest %s: %s" % (args.manifest, err))
                return 2
            return 0 if failed == 0 else 1
        return 0
    except IvolError as err:
        print("error: %s: %s" % (err.cls, err.message))
        return 1
    except UsageError as err:
        print("error: usage: %s" % err)
        return 2
    except OSError as err:
        print("error: io: %s" % err)
        return 2
    except (ReaderLimit, MemoryError) as err:
        print("error: reader-limit: %s" % (err or "out of memory"))
        return 3
    except Exception as err:   # a bug of this reader, never a verdict on the file
        print("error: internal: %s: %s" % (type(err).__name__, err))
        return 4


if __name__ == "__main__":
    if hasattr(signal, "SIGPIPE"):            # "ivolref.py info F | head" is not an error
        signal.signal(signal.SIGPIPE, signal.SIG_DFL)
    sys.exit(main())
