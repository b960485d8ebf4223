#!/usr/bin/env python3
"""Conformance test vectors for the .ivol format, version 1.3 (draft).

Written from format-spec/ivol.md alone (no code of the ivol project is used).
Needs only the Python standard library, numpy and zstandard; run it with

    /usr/bin/python3 format-spec/vectors/make_vectors.py

It (re)writes, next to this file: valid/, invalid/, manifest.json and
README.md.  The output is deterministic (fixed seeds, fixed metadata).

The script contains
  * CRC-32C (table driven, checked against the bit-wise definition of §2.1),
  * exact encoders to binary16 / uint16 / float32 (round to nearest, ties to
    even, done with exact rational arithmetic, §9),
  * an octree writer (§6-§10): lossless merging of regions whose non-padding
    voxels all have the same stored bits, padding held at the coarsest level,
    breadth-first arrays, inner averages by the recursion of §10, blocks per
    level and split by a size limit, stored, zstd or (since 1.2) zstd over
    byte planes (codec 2) blocks, index, footer,
  * an independent level-of-detail computation by weighted 2x2x2 box
    filtering of the dense source (§12.3 / §10),
  * writers of the structures of §8A (version 1.1): regular grid, rectilinear
    grid (stream 4, borders) and nested grid (stream 5, cells), and their
    levels of detail from the dense source by the flat binary64 sum of
    §12.3 (sequential, z then y then x, from +0.0; not numpy's pairwise sum),
  * (1.3 draft) bricked grids (§8A.4) with codecs 3 and 4 (§7.2, §7.3), and
    stored levels of detail in stream 7 (§8A.5), each level computed from
    the dense source by the same flat sum and bricked with its own sizes,
  * (1.3 draft) codec 3's entropy coder 2 (§7.2.1): tokens, contexts, the
    adaptive model, an rANS encoder with two interleaved states (model run
    forward, voxels coded last to first) and the self-test's decoder with
    every check of §7.2.1,
  * (1.3 draft) codec 3's entropy coder 3 (§7.2.2): the same tokens, contexts
    and bits below under tables stored per context (counted over the brick,
    frequencies proportional, or chosen otherwise for some vectors), the
    tables' bit string, an rANS encoder with 32 interleaved states and 16-bit
    words (voxels coded last to first, every state from 2^16) and the
    self-test's decoder with every check of §7.2.2,
  * a small reader that follows the check order of §13; it is used only as a
    self-test: every valid vector must read back to its expected dense export
    and levels of detail, and every invalid vector must fail with its
    expected error class at the intended check.  The expected outputs are
    NOT produced by this reader.
"""

import bisect
import copy
import json
import math
import os
import shutil
import struct
import sys
from fractions import Fraction

import numpy as np
import zstandard

HERE = os.path.dirname(os.path.abspath(__file__))

SIG = b"\x89IVOL\r\n\n"
END_SIG = b"IVOL_END"
IDX_SIG = b"IVIX"
MIB64 = 64 << 20
MIB16 = 16 << 20

BINARY16, UINT16, FLOAT32 = 1, 2, 3
ENC_NAME = {BINARY16: "binary16", UINT16: "uint16", FLOAT32: "float32"}
VWIDTH = {BINARY16: 2, UINT16: 2, FLOAT32: 4}
NPBITS = {BINARY16: np.uint16, UINT16: np.uint16, FLOAT32: np.uint32}

STREAM_META, STREAM_NODES, STREAM_VALUES = 1, 2, 3
STREAM_BORDERS, STREAM_CELLS = 4, 5                     # since 1.1 (§6.4, §8A)
STREAM_LOD = 7                                          # stored levels of detail, since 1.3 (§8A.5)
KIND_OCTREE, KIND_REGULAR, KIND_RECTILINEAR, KIND_NESTED = 1, 2, 3, 4
KIND_BRICKED = 5                                        # since 1.3 (§8A.4)
KIND_NAME = {KIND_OCTREE: "octree", KIND_REGULAR: "regular",           # as metadata structure.kind
             KIND_RECTILINEAR: "rectilinear", KIND_NESTED: "nested", KIND_BRICKED: "bricked"}
CODEC_STORED, CODEC_ZSTD = 0, 1
CODEC_PLANES = 2                 # zstd over byte planes, since 1.2 (§7)
CODEC_PREDICTED = 3              # predicted 16-bit, since 1.3 (§7.2)
CODEC_MASKED = 4                 # masked 16-bit, since 1.3 (§7.3)
CODEC_TOP_BYTE = 6               # top byte in context, since 1.3 (§7.4)
CODEC_FRAMES = 5                 # byte planes, a zstd frame each, since 1.3 (§7)
LORENZO = (1, 1, 1, -1, -1, -1, 1)


# ------------------------------------------------------- codec 3 (§7.2)

def b16_order(v):
    """§7.2 value map 1: binary16 bit patterns in numeric order."""
    return v ^ 0xFFFF if v & 0x8000 else v | 0x8000


def b16_order_inverse(u):
    return u ^ 0x8000 if u & 0x8000 else u ^ 0xFFFF


def predict(U, ext, x, y, z, shift, taps, level):
    """§7.2 step 2: the prediction of voxel (x, y, z) of a brick from the
    mapped values U (a dict or list indexed in raster order) before it."""
    ex, ey, _ = ext

    def at(a, b, c):
        return U[(c * ey + b) * ex + a]

    def clamp(p):
        return max(0, min(65535, p))
    if x > 0 and y > 0 and z > 0:
        n = (at(x - 1, y, z), at(x, y - 1, z), at(x, y, z - 1), at(x - 1, y - 1, z),
             at(x - 1, y, z - 1), at(x, y - 1, z - 1), at(x - 1, y - 1, z - 1))
        S = sum(t * v for t, v in zip(taps, n))
        r = 1 << (shift - 1) if shift else 0
        return clamp((S + r) // (1 << shift) + level)
    axes = [a for a, c in enumerate((x, y, z)) if c > 0]
    if not axes:
        return 0
    if len(axes) == 1:
        c = [x, y, z]
        c[axes[0]] -= 1
        return at(*c)
    c1, c2, c12 = [x, y, z], [x, y, z], [x, y, z]
    c1[axes[0]] -= 1
    c2[axes[1]] -= 1
    c12[axes[0]] -= 1
    c12[axes[1]] -= 1
    return clamp(at(*c1) + at(*c2) - at(*c12))


def predicted_residuals(vals, ext, value_map=1, shift=0, taps=LORENZO, level=0):
    """§7.2 steps 1-3 backwards: the zigzag residuals z_0 .. z_{n-1} of a brick's values."""
    ex, ey, ez = ext
    U = [b16_order(v) if value_map == 1 else v for v in vals]
    zs = []
    i = 0
    for z in range(ez):
        for y in range(ey):
            for x in range(ex):
                d = (U[i] - predict(U, ext, x, y, z, shift, taps, level)) % 65536
                if d >= 32768:
                    d -= 65536
                zs.append(2 * d if d >= 0 else -2 * d - 1)
                i += 1
    return zs


def values_from_residuals(zs, ext, value_map=1, shift=0, taps=LORENZO, level=0):
    """§7.2 steps 1-4 forwards: the values whose residuals are zs (any list of
    0 .. 65535 is the residuals of exactly one brick of values)."""
    ex, ey, ez = ext
    U = [0] * len(zs)
    i = 0
    for z in range(ez):
        for y in range(ey):
            for x in range(ex):
                zz = zs[i]
                d = zz // 2 if zz % 2 == 0 else -(zz + 1) // 2
                U[i] = (predict(U, ext, x, y, z, shift, taps, level) + d) % 65536
                i += 1
    return [b16_order_inverse(u) if value_map == 1 else u for u in U]


def predicted_payload(vals, ext, value_map=1, shift=0, taps=LORENZO, level=0, predictor=1,
                      entropy=1, reserved=b"\0\0", zcheck=False, e2=None, e3=None):
    """§7.2: the codec header, then (entropy 1) the zstd frame of the zigzag
    residuals' byte planes, (entropy 2) the rANS coding of §7.2.1, e2 the
    options of e2_encode (for invalid vectors and statistics), or (entropy 3)
    the coding of §7.2.2, e3 the options of e3_encode."""
    n = ext[0] * ext[1] * ext[2]
    zs = predicted_residuals(vals, ext, value_map, shift, taps, level)
    head = struct.pack("<BBBB7hi", predictor, value_map, shift, entropy, *taps, level) + reserved
    if entropy == 2:
        return head + e2_encode(zs, ext, **(e2 or {}))
    if entropy == 3:
        return head + e3_encode(zs, ext, **(e3 or {}))
    low, high = bytes(zz & 0xFF for zz in zs), bytes(zz >> 8 for zz in zs)
    assert len(low) == n
    return head + zframe(low + high, zcheck)


def predicted_decode(st, ext):
    """§7.2, for the self-test: the values of a codec 3 payload."""
    ex, ey, ez = ext
    n = ex * ey * ez
    if len(st) < 24:
        _fail("malformed", "codec3.short")
    predictor, value_map, shift, entropy = st[0], st[1], st[2], st[3]
    if predictor != 1:
        _fail("unsupported-feature", "codec3.predictor")
    if value_map not in (0, 1):
        _fail("malformed", "codec3.map")
    if shift > 15:
        _fail("malformed", "codec3.shift")
    if entropy not in (1, 2, 3):
        _fail("unsupported-feature", "codec3.entropy")
    if st[22:24] != b"\0\0":
        _fail("malformed", "codec3.reserved")
    taps = struct.unpack_from("<7h", st, 4)
    (level,) = struct.unpack_from("<i", st, 18)
    if entropy == 1:
        planes = zstd_content(st[24:], 2 * n)
        zs = [planes[i] | planes[n + i] << 8 for i in range(n)]
    elif entropy == 2:
        zs = e2_decode(st[24:], ext)
    else:
        zs = e3_decode(st[24:], ext)
    vals = values_from_residuals(zs, ext, value_map, shift, taps, level)
    return struct.pack("<%dH" % n, *vals)


# ------------------------------------------- codec 3, entropy coder 2 (§7.2.1)

E2_LOW = 1 << 23        # the states' lower bound, and what both start (encoder) and end (decoder) at


def e2_token(zz):
    """§7.2.1 Tokens: (token t, number e of bits below, their value w) of residual zz."""
    if zz < 2:
        return zz, 0, 0
    b = zz.bit_length()
    e = b - 2
    return 2 * b - 2 + ((zz >> e) & 1), e, zz & ((1 << e) - 1)


def e2_bitlen(t):
    """§7.2.1: B(t), the bit length of the residuals of token t."""
    return t if t < 2 else (t >> 1) + 1


def e2_residual(t, w):
    """§7.2.1: the residual of token t and its bits below w."""
    if t < 2:
        return t
    return ((2 + (t & 1)) << (e2_bitlen(t) - 2)) + w


def _check_e2_tokens():
    for zz in range(65536):
        t, e, w = e2_token(zz)
        assert 0 <= t < 32 and e == max(0, e2_bitlen(t) - 2) and e2_residual(t, w) == zz
    assert [e2_token(zz)[0] for zz in (0, 1, 2, 3, 4, 6, 32767, 32768, 49151, 49152, 65535)] == \
        [0, 1, 2, 3, 4, 5, 29, 30, 30, 31, 31]


class E2Model:
    """§7.2.1 Model: 12 contexts of 32 counts (each 1 at the start of the
    brick), their sum T, the number m of tokens coded in the context, and a
    frequency table made from the counts.  `stats` (a dict or None) collects
    what the vectors claim to cover: the number of tables made (the 12
    starting ones included), the largest m, and the most negative D."""

    def __init__(self, stats=None):
        self.c = [[1] * 32 for _ in range(12)]
        self.T = [32] * 12
        self.m = [0] * 12
        self.f = [None] * 12
        self.s = [None] * 12
        self.stats = stats
        for k in range(12):
            self._table(k)

    def _table(self, k):
        T = self.T[k]
        R4 = (1 << 44) // T
        f = [max(1, (c * R4) >> 32) for c in self.c[k]]
        D = 4096 - sum(f)                       # may be negative (max(1, ..) above), see SPEC-NOTES
        j = f.index(max(f))                     # the lowest t among equal largest
        f[j] += D
        assert f[j] >= 1 and sum(f) == 4096
        s, acc = [], 0
        for ft in f:
            s.append(acc)
            acc += ft
        self.f[k], self.s[k] = f, s
        if self.stats is not None:
            st = self.stats
            st["tables"] = st.get("tables", 0) + 1
            st["min_D"] = min(st.get("min_D", 0), D)

    def update(self, k, t):
        self.c[k][t] += 16
        self.T[k] += 16
        self.m[k] += 1
        m = self.m[k]
        if (m >= 4 and m & (m - 1) == 0) or m % 128 == 0:
            self._table(k)
        if self.stats is not None:
            ms = self.stats.setdefault("m", [0] * 12)
            ms[k] = max(ms[k], m)


def e2_context(B, ext, x, y, z):
    """§7.2.1 Contexts: k of voxel (x, y, z) from the bit lengths B (raster
    order) of the tokens at (x, y-1, z), (x, y, z-1), (x-1, y-1, z),
    (x+1, y-1, z), 0 outside the brick."""
    ex, ey, ez = ext

    def at(a, b, c):
        if 0 <= a < ex and 0 <= b < ey and 0 <= c < ez:
            return B[(c * ey + b) * ex + a]
        return 0
    u, k, l, p = at(x, y - 1, z), at(x, y, z - 1), at(x - 1, y - 1, z), at(x + 1, y - 1, z)
    return min(11, (2 * u + k + l + p + 2) // 5)


def _raster(ext):
    ex, ey, ez = ext
    return [(x, y, z) for z in range(ez) for y in range(ey) for x in range(ex)]


def e2_encode(zs, ext, start=(E2_LOW, E2_LOW), extra=None, stats=None):
    """§7.2.1, the encoder paragraph: R, the rANS stream and the bits below of
    the residuals zs (raster order) of a brick of extent ext.  The model is run
    forward (raster order) to give each voxel's frequency f and cumulative s;
    the voxels are then coded from the last to the first, voxel i with state
    X_{i mod 2}, both states starting at `start` (2^23 in a valid payload).
    extra = j (invalid vectors only): before the last coding step of state j
    emit one byte more than the encoder rule asks, so that X_j ends below 2^23
    while the stream otherwise decodes exactly."""
    n = len(zs)
    toks = [e2_token(zz) for zz in zs]
    B = [e2_bitlen(t) for t, _, _ in toks]
    model = E2Model(stats)
    fs = []
    for i, (x, y, z) in enumerate(_raster(ext)):
        k = e2_context(B, ext, x, y, z)
        t = toks[i][0]
        fs.append((model.f[k][t], model.s[k][t]))
        model.update(k, t)
    X = list(start)
    out = bytearray()
    for i in range(n - 1, -1, -1):
        j = i % 2
        x = X[j]
        f, s = fs[i]
        while x >= f << 19:
            out.append(x & 0xFF)
            x >>= 8
        if extra == j and i == j:
            out.append(x & 0xFF)
            x >>= 8
        X[j] = 4096 * (x // f) + x % f + s
    if extra is not None:
        assert X[extra] < E2_LOW
    stream = struct.pack("<II", X[0], X[1]) + bytes(reversed(out))
    acc = nbits = 0
    for _, e, w in toks:                         # least significant bit first
        acc |= w << nbits
        nbits += e
    bits = acc.to_bytes((nbits + 7) // 8, "little")
    return struct.pack("<I", len(stream)) + stream + bits


def e2_split(body):
    """(R, rANS stream, bits below) of the bytes after a codec 3 header, for
    building invalid vectors."""
    (R,) = struct.unpack_from("<I", body, 0)
    return R, body[4:4 + R], body[4 + R:]


def e2_decode(body, ext, skip=()):
    """§7.2.1, for the self-test: the residuals of the bytes after a codec 3
    header of entropy 2, with every check of §7.2.1 in the order a decoder
    meets them.  skip: names of checks left out (only to show that an
    invalid vector breaks nothing else)."""
    n = ext[0] * ext[1] * ext[2]
    if len(body) < 4:                               # payload shorter than 28 bytes: no R
        _fail("malformed", "codec3.entropy2.short")
    (R,) = struct.unpack_from("<I", body, 0)
    if R < 8:
        _fail("malformed", "codec3.entropy2.stream_size_below_8", str(R))
    if R > len(body) - 4:                           # R <= payload size - 28
        _fail("malformed", "codec3.entropy2.stream_size_over_payload", str(R))
    stream = body[4:4 + R]
    X = list(struct.unpack_from("<II", stream, 0))
    if any(not E2_LOW <= x < 1 << 31 for x in X) and "initial_state" not in skip:
        _fail("malformed", "codec3.entropy2.initial_state", "%d %d" % tuple(X))
    pos = 8
    model = E2Model()
    toks, B = [0] * n, [0] * n
    for i, (x, y, z) in enumerate(_raster(ext)):
        k = e2_context(B, ext, x, y, z)
        j = i % 2
        st = X[j]
        slot = st % 4096
        f, s = model.f[k], model.s[k]
        t = 0
        while not s[t] <= slot < s[t] + f[t]:
            t += 1
        st = f[t] * (st // 4096) + slot - s[t]
        while st < E2_LOW:
            if pos >= R:
                _fail("malformed", "codec3.entropy2.stream_end", "voxel %d" % i)
            st = 256 * st + stream[pos]
            pos += 1
        X[j] = st
        model.update(k, t)
        toks[i], B[i] = t, e2_bitlen(t)
    if X != [E2_LOW, E2_LOW] and "states_end" not in skip:
        _fail("malformed", "codec3.entropy2.states_end", "%d %d" % tuple(X))
    if pos != R and "stream_left" not in skip:
        _fail("malformed", "codec3.entropy2.stream_left", "%d of %d bytes read" % (pos, R))
    bits = body[4 + R:]
    E = sum(max(0, b - 2) for b in B)
    if len(bits) != (E + 7) // 8:
        _fail("malformed", "codec3.entropy2.bits_size", "%d bytes for %d bits" % (len(bits), E))
    acc = int.from_bytes(bits, "little")
    if acc >> E:
        _fail("malformed", "codec3.entropy2.padding")
    bitstr = bin(acc)[2:].zfill(E)[::-1] if E else ""     # bit j of the part is bitstr[j]
    zs, j = [], 0
    for t, b in zip(toks, B):
        e = max(0, b - 2)
        w = int(bitstr[j:j + e][::-1], 2) if e else 0
        j += e
        zs.append(e2_residual(t, w))
    return zs


# ------------------------------------------- codec 3, entropy coder 3 (§7.2.2)

E3_LOW = 1 << 16        # the states' lower bound: where the encoder starts them, where the decoder ends them
E3_STATES = 32          # the number of rANS states; voxel i is coded with X_{i mod 32}


class BitString:
    """A bit string packed into bytes from bit 0 of its first byte up (bit j
    is bit j mod 8 of byte j // 8), as §7.2.2's tables and §7.2.1's bits
    below are.  Every number is put least significant bit first (see
    SPEC-NOTES, §7.2.2).  `marks` records (name, bit position, width) of the
    fields put with a name, so that invalid vectors can change one."""

    def __init__(self):
        self.acc = 0
        self.n = 0
        self.marks = []

    def put(self, v, nbits, mark=None):
        assert 0 <= v < 1 << nbits or (nbits == 0 and v == 0), (v, nbits)
        if mark is not None:
            self.marks.append((mark, self.n, nbits))
        self.acc |= v << self.n
        self.n += nbits

    def tobytes(self):
        return self.acc.to_bytes((self.n + 7) // 8, "little")


def set_bits(data, pos, nbits, v):
    """data (bytes) with bits pos .. pos + nbits - 1 of its bit string set to
    the number v, least significant bit first."""
    acc = int.from_bytes(data, "little")
    acc = acc & ~(((1 << nbits) - 1) << pos) | v << pos
    return acc.to_bytes(len(data), "little")


def e3_tables_bits(tables):
    """§7.2.2 Tables: the bit string of the 12 contexts' tables (unpadded, as
    a BitString).  tables[k] is None (used = 0: every f_t = 128) or the list of
    (t, f_t) of the present tokens in increasing t; the last f is not written
    (a reader takes 4096 minus the others), the others as a = floor(log2 f)
    in 4 bits and w = f - 2^a in a bits."""
    bs = BitString()
    for k in range(12):
        pairs = tables[k]
        if pairs is None:
            bs.put(0, 1, ("used", k))
            continue
        bs.put(1, 1, ("used", k))
        present = 0
        for t, _ in pairs:
            present |= 1 << t
        bs.put(present, 32, ("present", k))
        for t, f in pairs[:-1]:
            a = f.bit_length() - 1
            assert 0 <= a <= 11, f
            bs.put(a, 4, ("a", k, t))
            bs.put(f - (1 << a), a, ("w", k, t))
    return bs


def e3_frequencies(counts):
    """One choice the encoder paragraph of §7.2.2 allows: f_t = max(1,
    floor(4096 c_t / N)) for every token that occurs (c_t > 0), 0 for the
    others, and the remainder 4096 - sum added to the most frequent token
    (the lowest t among equal counts)."""
    N = sum(counts)
    f = [max(1, 4096 * c // N) if c else 0 for c in counts]
    j = max(range(32), key=lambda t: (counts[t], -t))
    f[j] += 4096 - sum(f)
    assert f[j] >= 1 and sum(f) == 4096
    return f


def e3_analyse(zs, ext):
    """(tokens as (t, e, w), bit lengths B, contexts k) of the residuals zs of
    a brick, raster order (§7.2.1 Tokens and Contexts)."""
    toks = [e2_token(zz) for zz in zs]
    B = [e2_bitlen(t) for t, _, _ in toks]
    ks = [e2_context(B, ext, x, y, z) for x, y, z in _raster(ext)]     # earlier rows only
    return toks, B, ks


def e3_encode(zs, ext, freqs=None, uniform=(), start=None, extra=None, tables_out=None):
    """§7.2.2, the encoder paragraph: the tables, the 32 states, W, the word
    stream and the bits below of the residuals zs (raster order) of a brick
    of extent ext.  Each context's tokens are counted over the brick and its
    frequencies chosen by e3_frequencies, unless
      freqs = {k: [f_0 .. f_31]}: the frequencies of context k as given
              (f_t >= 1 for every token that occurs in k, sum 4096; tokens
              with f_t >= 1 that do not occur are allowed),
      uniform = contexts written with used = 0 although they code voxels
              (§7.2.2: "or may be read so"), coded under f_t = 128;
    a context that codes no voxel is written with used = 0 (unless freqs
    gives it a table).  The voxels are
    coded from the last to the first, voxel i with state X_{i mod 32}, every
    state starting at `start[j]` (2^16 in a valid payload).  extra = j
    (invalid vectors only): before the last coding step of state j emit one
    word more than the encoder rule asks, so that X_j ends below 2^16 while
    the stream otherwise decodes exactly.  tables_out (a dict or None)
    receives the tables' BitString and the frequencies used."""
    n = len(zs)
    toks, B, ks = e3_analyse(zs, ext)
    counts = [[0] * 32 for _ in range(12)]
    for (t, _, _), k in zip(toks, ks):
        counts[k][t] += 1
    F, tables = [], []
    for k in range(12):
        if k in uniform or not (any(counts[k]) or (freqs and k in freqs)):
            F.append([128] * 32)
            tables.append(None)
            continue
        f = list(freqs[k]) if freqs and k in freqs else e3_frequencies(counts[k])
        assert sum(f) == 4096 and all(ft >= 1 for ft, c in zip(f, counts[k]) if c), (k, f)
        F.append(f)
        tables.append([(t, ft) for t, ft in enumerate(f) if ft])
    S = []
    for f in F:
        s, acc = [], 0
        for ft in f:
            s.append(acc)
            acc += ft
        S.append(s)
    X = list(start) if start is not None else [E3_LOW] * E3_STATES
    emitted = []
    for i in range(n - 1, -1, -1):
        j = i % E3_STATES
        x = X[j]
        t = toks[i][0]
        f, s = F[ks[i]][t], S[ks[i]][t]
        if x >= f << 20:
            emitted.append(x & 0xFFFF)
            x >>= 16
        elif extra == j and i == j:          # (only where the rule emitted nothing: see e3 invalid vectors)
            emitted.append(x & 0xFFFF)
            x >>= 16
        X[j] = 4096 * (x // f) + x % f + s
        assert X[j] < 1 << 32
    if extra is not None:
        assert X[extra] < E3_LOW, "state %d emitted at its last step: choose another" % extra
    bs = e3_tables_bits(tables)
    if tables_out is not None:
        tables_out.update(bits=bs, F=F, counts=counts, W=len(emitted))
    words = list(reversed(emitted))
    acc = nbits = 0
    for _, e, w in toks:                         # least significant bit first
        acc |= w << nbits
        nbits += e
    bits = acc.to_bytes((nbits + 7) // 8, "little")
    return (bs.tobytes() + struct.pack("<32I", *X) + struct.pack("<I", len(words))
            + struct.pack("<%dH" % len(words), *words) + bits)


def e3_split(body):
    """(tables, states, W, words, bits below) of the bytes after a codec 3
    header of entropy 3, as bytes (W an int), for building invalid vectors;
    the tables end is found by parsing them."""
    tb = e3_tables_size(body)
    st = body[tb:tb + 128]
    (W,) = struct.unpack_from("<I", body, tb + 128)
    words = body[tb + 132:tb + 132 + 2 * W]
    return body[:tb], st, W, words, body[tb + 132 + 2 * W:]


def e3_join(tables, states, W, words, bits):
    return tables + states + struct.pack("<I", W) + words + bits


def e3_parse_tables(body):
    """§7.2.2 Tables, for the self-test: (frequencies of the 12 contexts, the
    number of bits the tables take), with every check of the tables."""
    nb = 8 * len(body)
    pos = 0

    def get(width):
        nonlocal pos
        if pos + width > nb:
            _fail("malformed", "codec3.entropy3.tables_short", "bit %d of %d" % (pos + width, nb))
        v = 0
        for q in range(width):                   # least significant bit first
            v |= (body[(pos + q) >> 3] >> ((pos + q) & 7) & 1) << q
        pos += width
        return v
    F = []
    for k in range(12):
        if not get(1):                           # used = 0
            F.append([128] * 32)
            continue
        present = get(32)
        if present == 0:
            _fail("malformed", "codec3.entropy3.present_zero", "context %d" % k)
        ts = [t for t in range(32) if present >> t & 1]
        f = [0] * 32
        for t in ts[:-1]:
            a = get(4)
            if a > 11:
                _fail("malformed", "codec3.entropy3.a_over_11", "context %d token %d: a = %d" % (k, t, a))
            f[t] = (1 << a) + get(a)
        last = 4096 - sum(f)
        if last < 1:
            _fail("malformed", "codec3.entropy3.last_frequency", "context %d token %d: %d" % (k, ts[-1], last))
        f[ts[-1]] = last
        F.append(f)
    return F, pos


def e3_tables_size(body):
    return (e3_parse_tables(body)[1] + 7) // 8


def e3_decode(body, ext, skip=()):
    """§7.2.2, for the self-test: the residuals of the bytes after a codec 3
    header of entropy 3, with every check of §7.2.2 in the order a decoder
    meets them (the tables as they parse, their padding, 132 bytes, the
    initial states, 2·W bytes, the word stream per renormalisation, the end
    states, no word left, the bits below and their padding).  skip: names of
    checks left out (only to show that an invalid vector breaks nothing
    else)."""
    n = ext[0] * ext[1] * ext[2]
    F, pos = e3_parse_tables(body)
    tb = (pos + 7) // 8
    if pos % 8 and body[pos // 8] >> (pos % 8):
        _fail("malformed", "codec3.entropy3.tables_padding")
    if len(body) < tb + 132:
        _fail("malformed", "codec3.entropy3.states_short", "%d bytes after the tables" % (len(body) - tb))
    X = list(struct.unpack_from("<32I", body, tb))
    if any(x < E3_LOW for x in X) and "initial_state" not in skip:
        _fail("malformed", "codec3.entropy3.initial_state", " ".join(str(x) for x in X))
    (W,) = struct.unpack_from("<I", body, tb + 128)
    wo = tb + 132
    if 2 * W > len(body) - wo:                   # exact arithmetic: no wrap of 2·W
        _fail("malformed", "codec3.entropy3.words_short", "W = %d, %d bytes left" % (W, len(body) - wo))
    words = struct.unpack_from("<%dH" % W, body, wo)
    S = []
    for f in F:
        s, acc = [], 0
        for ft in f:
            s.append(acc)
            acc += ft
        S.append(s)
    rd = 0
    toks, B = [0] * n, [0] * n
    for i, (x, y, z) in enumerate(_raster(ext)):
        k = e2_context(B, ext, x, y, z)
        j = i % E3_STATES
        st = X[j]
        slot = st % 4096
        f, s = F[k], S[k]
        t = 0
        while not s[t] <= slot < s[t] + f[t]:    # a token of frequency 0 is never chosen
            t += 1
        st = f[t] * (st // 4096) + slot - s[t]
        if st < E3_LOW:                          # one word always suffices
            if rd >= W:
                _fail("malformed", "codec3.entropy3.stream_end", "voxel %d" % i)
            st = 65536 * st + words[rd]
            rd += 1
        X[j] = st
        toks[i], B[i] = t, e2_bitlen(t)
    if any(x != E3_LOW for x in X) and "states_end" not in skip:
        _fail("malformed", "codec3.entropy3.states_end", " ".join(str(x) for x in X))
    if rd != W and "words_left" not in skip:
        _fail("malformed", "codec3.entropy3.words_left", "%d of %d words read" % (rd, W))
    bits = body[wo + 2 * W:]
    E = sum(max(0, b - 2) for b in B)
    if len(bits) != (E + 7) // 8:
        _fail("malformed", "codec3.entropy3.bits_size", "%d bytes for %d bits" % (len(bits), E))
    acc = int.from_bytes(bits, "little")
    if acc >> E:
        _fail("malformed", "codec3.entropy3.padding")
    zs, j = [], 0
    for t, b in zip(toks, B):
        e = max(0, b - 2)
        zs.append(e2_residual(t, acc >> j & ((1 << e) - 1)))
        j += e
    return zs


def masked_payload(vals, background, form=None, reserved=0, zcheck=False):
    """§7.3: the background, the form, and (form 1) the zstd frame of the
    mask and the other values' low bytes then high bytes.  form None: 0 when
    every value is the background, else 1."""
    n = len(vals)
    others = [v for v in vals if v != background]
    if form is None:
        form = 1 if others else 0
    head = struct.pack("<HBB", background, form, reserved)
    if form == 0:
        return head
    mask = bytearray((n + 7) // 8)
    for i, v in enumerate(vals):
        if v == background:
            mask[i // 8] |= 1 << (i % 8)
    content = bytes(mask) + bytes(v & 0xFF for v in others) + bytes(v >> 8 for v in others)
    return head + zframe(content, zcheck)


def masked_decode(st, n):
    """§7.3, for the self-test: the values of a codec 4 payload."""
    if len(st) < 4:
        _fail("malformed", "codec4.short")
    background, form, reserved = struct.unpack_from("<HBB", st, 0)
    if reserved != 0:
        _fail("malformed", "codec4.reserved")
    if form == 0:
        if len(st) != 4:
            _fail("malformed", "codec4.constant_size")
        return struct.pack("<%dH" % n, *([background] * n))
    if form != 1:
        _fail("malformed", "codec4.form")
    m = (n + 7) // 8
    try:
        size = zstandard.get_frame_parameters(st[4:]).content_size
    except zstandard.ZstdError:
        _fail("malformed", "zstd.frame")
    if size < m or size > m + 2 * n or (size - m) % 2:
        _fail("malformed", "codec4.content_size")
    content = zstd_content(st[4:], size)
    bits = [content[i // 8] >> (i % 8) & 1 for i in range(8 * m)]
    if any(bits[n:]):
        _fail("malformed", "codec4.padding")
    k = n - sum(bits[:n])
    if size != m + 2 * k:
        _fail("malformed", "codec4.count")
    vals, j = [], 0
    for i in range(n):
        if bits[i]:
            vals.append(background)
        else:
            vals.append(content[m + j] | content[m + k + j] << 8)
            j += 1
    return struct.pack("<%dH" % n, *vals)


# ---------------------------------------------------------------- CRC-32C (§2.1)

def crc32c_bitwise(data):
    crc = 0xFFFFFFFF
    for b in data:
        crc ^= b
        for _ in range(8):
            crc = (crc >> 1) ^ (0x82F63B78 if crc & 1 else 0)
    return crc ^ 0xFFFFFFFF


def _make_table():
    t = []
    for i in range(256):
        c = i
        for _ in range(8):
            c = (c >> 1) ^ (0x82F63B78 if c & 1 else 0)
        t.append(c)
    return t


_CRC_T = _make_table()


def crc32c(data):
    crc = 0xFFFFFFFF
    t = _CRC_T
    for b in bytes(data):
        crc = (crc >> 8) ^ t[(crc ^ b) & 0xFF]
    return crc ^ 0xFFFFFFFF


def _check_crc():
    assert crc32c(b"123456789") == 0xE3069283
    assert crc32c(bytes(32)) == 0x8A9136AA
    assert crc32c(b"\xff" * 32) == 0x62A8AB43
    for s in (b"", b"a", b"ivol", bytes(range(256))):
        assert crc32c(s) == crc32c_bitwise(s)


# ---------------------------------------------------------- value encodings (§9)

def _enc_ieee(m, mant, expb):
    """Round binary64 m to the nearest IEEE number with `mant` fraction bits
    and `expb` exponent bits, ties to even, overflow to infinity.  Returns
    the bit pattern, or None for NaN."""
    if math.isnan(m):
        return None
    bias = (1 << (expb - 1)) - 1
    emin = 1 - bias
    inf_bits = ((1 << expb) - 1) << mant
    sign = (1 << (mant + expb)) if math.copysign(1.0, m) < 0 else 0
    a = abs(m)
    if math.isinf(a):
        return sign | inf_bits
    if a == 0.0:
        return sign
    e = max(math.frexp(a)[1] - 1, emin)          # 2^e <= a < 2^(e+1) (or subnormal)
    q = Fraction(2) ** (e - mant)                # spacing of the target numbers there
    r = round(Fraction(a) / q)                   # Fraction rounds half to even
    if r >= (1 << mant):
        bits = ((e + bias) << mant) + (r - (1 << mant))   # carries into exponent
    else:
        bits = r                                 # subnormal (e == emin)
    if bits >= inf_bits:
        bits = inf_bits
    return sign | bits


def encode(enc, m):
    if enc == BINARY16:
        b = _enc_ieee(m, 10, 5)
        return 0x7E00 if b is None else b
    if enc == FLOAT32:
        b = _enc_ieee(m, 23, 8)
        return 0x7FC00000 if b is None else b
    if enc == UINT16:
        if math.isnan(m):
            raise ValueError("NaN cannot occur with uint16")
        if math.isinf(m):
            return 0 if m < 0 else 65535
        r = round(Fraction(m))
        return min(max(r, 0), 65535)
    raise ValueError(enc)


def _dec_ieee(bits, mant, expb):
    bias = (1 << (expb - 1)) - 1
    s = -1.0 if bits >> (mant + expb) else 1.0
    e = (bits >> mant) & ((1 << expb) - 1)
    f = bits & ((1 << mant) - 1)
    if e == (1 << expb) - 1:
        return s * math.inf if f == 0 else math.nan
    if e == 0:
        return s * math.ldexp(f, 1 - bias - mant)
    return s * math.ldexp(f + (1 << mant), e - bias - mant)


def decode(enc, bits):
    bits = int(bits)
    if enc == BINARY16:
        return _dec_ieee(bits, 10, 5)
    if enc == FLOAT32:
        return _dec_ieee(bits, 23, 8)
    if enc == UINT16:
        return float(bits)
    raise ValueError(enc)


def _check_encoders():
    rng = np.random.default_rng(12345)
    xs = list(rng.standard_normal(3000) * 10.0 ** rng.integers(-9, 6, 3000))
    xs += [65504.0, 65519.99, 65520.0, 1e300, -1e300, 2.0 ** -25, 2.0 ** -24 * 1.5,
           2.0 ** -26, 3.0 * 2 ** -25, 5e-324, -0.0, 0.0, math.inf, -math.inf]
    xs += [1.0 + 2.0 ** -11, 1.0 + 3 * 2.0 ** -11, 1.0 + 2.0 ** -24, 1.0 + 3 * 2.0 ** -24,
           2.0 ** -150, 3 * 2.0 ** -150, 3.4028235677973366e38, 3.4028235e38 * 1.0000001]
    with np.errstate(over="ignore"):
        for x in xs:
            x = float(x)
            h = int(np.array([x], dtype=np.float64).astype(np.float16).view(np.uint16)[0])
            f = int(np.array([x], dtype=np.float64).astype(np.float32).view(np.uint32)[0])
            assert encode(BINARY16, x) == h, (x, hex(encode(BINARY16, x)), hex(h))
            assert encode(FLOAT32, x) == f, (x, hex(encode(FLOAT32, x)), hex(f))
    for b in range(0x10000):
        v = decode(BINARY16, b)
        ref = float(np.array([b], dtype=np.uint16).view(np.float16)[0])
        assert (math.isnan(v) and math.isnan(ref)) or (v == ref and math.copysign(1, v) == math.copysign(1, ref))
        if not math.isnan(v):
            assert encode(BINARY16, v) == b
    assert encode(UINT16, 2.5) == 2 and encode(UINT16, 3.5) == 4 and encode(UINT16, -3.0) == 0
    assert encode(UINT16, 70000.4) == 65535 and encode(UINT16, 65534.5) == 65534


def f16(x):
    return encode(BINARY16, float(x))


def f32(x):
    return encode(FLOAT32, float(x))


def min_depth(X, Y, Z):
    return (max(X, Y, Z) - 1).bit_length()


def ceil_div(a, b):
    return -(-a // b)


# ------------------------------------------------------------------ octree (§8, §10)

class Node:
    __slots__ = ("l", "i", "j", "k", "w", "inner", "bits", "m", "children")

    def __init__(self, l, i, j, k):
        self.l, self.i, self.j, self.k = l, i, j, k
        self.inner = False
        self.bits = 0
        self.m = None
        self.children = None


class Tree:
    pass


def build_tree(src, enc, depth=None, force_inner=(), avg="spec"):
    """src: numpy array [z][y][x] of element bits (uint16 / uint32).
    A node is a leaf when it is entirely padding or when all its non-padding
    voxels have the same bits (lossless merge); otherwise it is inner.
    force_inner: set of (level, i, j, k) that are subdivided regardless
    (used only for invalid vectors).  avg: 'spec' (§10), 'rounded' (parents
    averaged from the children's stored values: a writer bug) or
    'unweighted' (children weight 1: a writer bug)."""
    Z, Y, X = src.shape
    D = min_depth(X, Y, Z) if depth is None else depth
    force_inner = set(force_inner)
    levels = [[Node(0, 0, 0, 0)]]
    for l in range(D + 1):
        s = 1 << (D - l)
        nxt = []
        for nd in levels[l]:
            x0, y0, z0 = nd.i * s, nd.j * s, nd.k * s
            reg = src[z0:min(z0 + s, Z), y0:min(y0 + s, Y), x0:min(x0 + s, X)]
            nd.w = int(reg.size)
            uniform = nd.w == 0 or bool((reg == reg.flat[0]).all())
            forced = (l, nd.i, nd.j, nd.k) in force_inner
            if l < D and (forced or not uniform):
                nd.inner = True
                nd.children = []
                for c in range(8):
                    ch = Node(l + 1, 2 * nd.i + (c & 1), 2 * nd.j + ((c >> 1) & 1), 2 * nd.k + ((c >> 2) & 1))
                    nd.children.append(ch)
                    nxt.append(ch)
            else:
                nd.bits = int(reg.flat[0]) if nd.w else 0
        if l < D:
            levels.append(nxt)
    # inner averages, bottom up (§10)
    for l in range(D, -1, -1):
        for nd in levels[l]:
            if not nd.inner:
                nd.m = decode(enc, nd.bits) if nd.w else None
                continue
            acc = 0.0
            W = 0
            for ch in nd.children:
                if ch.w > 0:
                    if avg == "spec":
                        acc = acc + float(ch.w) * ch.m
                        W = W + ch.w
                    elif avg == "rounded":
                        acc = acc + float(ch.w) * decode(enc, ch.bits)
                        W = W + ch.w
                    elif avg == "unweighted":
                        acc = acc + ch.m
                        W = W + 1
                    else:
                        raise ValueError(avg)
            if W == 0:
                nd.m = None
                nd.bits = 0
            else:
                nd.m = acc / float(W)
                nd.bits = encode(enc, nd.m)
    t = Tree()
    t.enc, t.D, t.size = enc, D, (X, Y, Z)
    t.levels = levels
    t.inner_count = [sum(1 for nd in levels[l] if nd.inner) for l in range(D + 1)]
    t.values = [nd.bits for lv in levels for nd in lv]
    words = []
    running = 1
    for lv in levels:
        for nd in lv:
            if nd.inner:
                mask = 0
                for c, ch in enumerate(nd.children):
                    if ch.inner:
                        mask |= 1 << c
                words.append((mask << 56) | running)
                running += bin(mask).count("1")
    t.nodes = words
    t.first_inner = [sum(t.inner_count[:l]) for l in range(D + 1)]
    t.level_values = [1] + [8 * t.inner_count[l - 1] for l in range(1, D + 1)]
    t.first_value = [0] + [1 + 8 * t.first_inner[l - 1] for l in range(1, D + 1)]
    assert len(t.values) == 1 + 8 * len(t.nodes)
    return t


# ------------------------------------------------- levels of detail from the source

def pyramid_lods(src, enc, D):
    """Levels of detail 1..D computed from the dense source alone: weighted
    2x2x2 box filter in octant order with the arithmetic of §10.  A cell whose
    non-padding voxels all have the same bits keeps those bits (that is what
    a file written with lossless leaf merging stores, §12.3)."""
    out = {}
    m = np.array([decode(enc, b) for b in src.ravel()], dtype=np.float64).reshape(src.shape)
    w = np.ones(src.shape, dtype=np.int64)
    ub = src.astype(np.int64)                      # uniform bits, -1: not uniform
    for k in range(1, D + 1):
        z2, y2, x2 = (ceil_div(n, 2) for n in m.shape)
        padw = ((0, 2 * z2 - m.shape[0]), (0, 2 * y2 - m.shape[1]), (0, 2 * x2 - m.shape[2]))
        mp = np.pad(m, padw, constant_values=0.0)
        wp = np.pad(w, padw, constant_values=0)
        bp = np.pad(ub, padw, constant_values=-2)
        acc = np.zeros((z2, y2, x2), dtype=np.float64)
        W = np.zeros((z2, y2, x2), dtype=np.int64)
        nub = np.full((z2, y2, x2), -2, dtype=np.int64)    # -2: no non-padding child yet
        with np.errstate(all="ignore"):
            for c in range(8):
                xb, yb, zb = c & 1, (c >> 1) & 1, (c >> 2) & 1
                mc = mp[zb::2, yb::2, xb::2]
                wc = wp[zb::2, yb::2, xb::2]
                bc = bp[zb::2, yb::2, xb::2]
                has = wc > 0
                prod = wc.astype(np.float64) * mc
                acc = np.where(has, acc + prod, acc)
                W = W + wc
                nub = np.where(~has, nub, np.where(nub == -2, bc, np.where(nub == bc, nub, -1)))
            mnew = acc / W.astype(np.float64)
        uni = nub >= 0
        res = np.zeros((z2, y2, x2), dtype=NPBITS[enc])
        for idx in np.ndindex(z2, y2, x2):
            if uni[idx]:
                res[idx] = nub[idx]
                mnew[idx] = decode(enc, nub[idx])
            else:
                res[idx] = encode(enc, float(mnew[idx]))
        out[k] = res
        m, w, ub = mnew, W, nub
    return out


def flat_lods(src, enc, D):
    """Levels of detail 1..D of the structures of §8A (§12.3), from the dense
    source alone: for each cell of 2^k voxels per side (clipped at the
    volume's border) the decoded values are summed in binary64 starting from
    +0.0, strictly one after the other in the order z, then y, then x (x
    fastest), the sum is divided by the number of voxels and the mean is
    encoded once.  No leaf exception: a cell of uniform -0 gives +0, a NaN
    gives the canonical NaN.  The loops run over the offsets inside a cell,
    each step adds one voxel to every cell at once (vectorised over cells,
    sequential within a cell; numpy's sum is pairwise and is not used)."""
    Z, Y, X = src.shape
    dec = np.array([decode(enc, b) for b in src.ravel()], dtype=np.float64).reshape(src.shape)
    out = {}
    for k in range(1, D + 1):
        s = 1 << k
        nz, ny, nx = ceil_div(Z, s), ceil_div(Y, s), ceil_div(X, s)
        P = np.zeros((nz * s, ny * s, nx * s), dtype=np.float64)
        M = np.zeros((nz * s, ny * s, nx * s), dtype=bool)
        P[:Z, :Y, :X] = dec
        M[:Z, :Y, :X] = True
        acc = np.zeros((nz, ny, nx), dtype=np.float64)          # +0.0
        with np.errstate(all="ignore"):
            for dz in range(min(s, Z)):
                for dy in range(min(s, Y)):
                    for dx in range(min(s, X)):
                        v = P[dz::s, dy::s, dx::s]
                        msk = M[dz::s, dy::s, dx::s]
                        acc = np.where(msk, acc + v, acc)
            cz = np.minimum(s, Z - s * np.arange(nz))
            cy = np.minimum(s, Y - s * np.arange(ny))
            cx = np.minimum(s, X - s * np.arange(nx))
            cnt = cz[:, None, None] * cy[None, :, None] * cx[None, None, :]
            mean = acc / cnt.astype(np.float64)
        res = np.zeros((nz, ny, nx), dtype=NPBITS[enc])
        for idx in np.ndindex(nz, ny, nx):
            res[idx] = encode(enc, float(mean[idx]))
        out[k] = res
    return out


# ------------------------------------------------------------------- file writer

class Blk:
    """One block: stream, level, element range, decoded bytes, codec, and
    optional overrides of entry fields / stored bytes (for invalid files)."""

    def __init__(self, stream, level, first, count, data, codec=CODEC_ZSTD, flags=0,
                 zcheck=True, zsize=True):
        self.stream, self.level, self.first, self.count = stream, level, first, count
        self.data, self.codec, self.flags = data, codec, flags
        self.zcheck, self.zsize = zcheck, zsize
        self.stored = None          # override of the stored bytes
        self.ov = {}                # override of entry fields
        self.extra = b""            # bytes 32 .. block_entry_size of the entry
        self.hov = {}               # override of block header fields (framed files, §7.1)

    def stored_bytes(self):
        if self.stored is not None:
            return self.stored
        if self.codec == CODEC_STORED:
            return self.data
        if self.codec == CODEC_ZSTD:
            return zframe(self.data, self.zcheck, self.zsize)
        if self.codec == CODEC_PLANES:
            return zframe(byte_planes(self.data, len(self.data) // self.count), self.zcheck, self.zsize)
        if self.codec == CODEC_FRAMES:
            return plane_frames(self.data, len(self.data) // self.count, self.zcheck, self.zsize)
        return self.data            # unknown codec: raw bytes


def byte_planes(data, w):
    """§7 codec 2: with n = element_count and w = width, content byte p*n + i
    is decoded byte i*w + p (the lowest byte of every element first)."""
    n = len(data) // w
    assert n * w == len(data)
    out = bytearray(len(data))
    for p in range(w):
        out[p * n:(p + 1) * n] = data[p::w]          # bytes i*w + p, i = 0 .. n-1
    return bytes(out)


def from_byte_planes(content, w):
    """The inverse of byte_planes: decoded byte i*w + p = content byte p*n + i."""
    n = len(content) // w
    out = bytearray(len(content))
    for p in range(w):
        out[p::w] = content[p * n:(p + 1) * n]
    return bytes(out)


def planes_of(data, w):
    """The w byte planes of `data` (elements of width w): plane p is decoded
    byte i*w + p for i = 0 .. n-1."""
    assert len(data) % w == 0
    return [data[p::w] for p in range(w)]


def plane_frames(data, w, checksum=True, content_size=True, frame=None):
    """§7 codec 5: w zstd frames back to back, frame p holding byte plane p of
    the decoded bytes `data`.  frame(p, plane) may return a frame of its own
    for plane p (None: a compressor's frame, with or without the content
    checksum)."""
    out = b""
    for p, plane in enumerate(planes_of(data, w)):
        f = frame(p, plane) if frame is not None else None
        out += f if f is not None else zframe(plane, checksum, content_size)
    return out


def zstd_checksum(content):
    """The content checksum of a zstd frame of `content` (the low 32 bits of
    XXH64, RFC 8878 §3.1.1), taken from the reference library's own frame."""
    return zstandard.ZstdCompressor(level=1, write_checksum=True).compress(content)[-4:]


def hand_zframe(content, blocks=None, fcs_bytes=4, single_segment=True, checksum=False, empties=0):
    """A zstd frame (RFC 8878 §3.1.1) built by hand, without a compressor.
    Frame header: Single_Segment_flag (else a Window_Descriptor of a window of
    at least the content), Frame_Content_Size in a field of fcs_bytes (1 only
    with the single segment flag; 2 holds the size - 256), no Dictionary_ID.
    Then `empties` empty raw blocks, then `blocks`: a list of ("raw", length)
    or ("rle", length) covering the content in order (default: one raw
    block), the last one with Last_Block set; then the content checksum if
    asked."""
    n = len(content)
    flag = {1: 0, 2: 1, 4: 2, 8: 3}[fcs_bytes]
    assert fcs_bytes != 1 or single_segment
    fhd = flag << 6 | (1 << 5 if single_segment else 0) | (1 << 2 if checksum else 0)
    out = bytearray(b"\x28\xb5\x2f\xfd") + bytes([fhd])
    if not single_segment:
        exponent = max(0, (max(n, 1) - 1).bit_length() - 10)     # window 2^(10 + exponent) >= n
        out.append(exponent << 3)
    fcs = n - 256 if fcs_bytes == 2 else n
    assert 0 <= fcs < 1 << (8 * fcs_bytes)
    out += fcs.to_bytes(fcs_bytes, "little")
    for _ in range(empties):
        out += (0 << 3 | 0 << 1 | 0).to_bytes(3, "little")          # raw, size 0, not last
    blocks = blocks or [("raw", n)]
    assert sum(k for _, k in blocks) == n
    at = 0
    for q, (kind, k) in enumerate(blocks):
        last = 1 if q == len(blocks) - 1 else 0
        part = content[at:at + k]
        if kind == "raw":
            out += (k << 3 | 0 << 1 | last).to_bytes(3, "little") + part
        else:
            assert k >= 1 and part == part[:1] * k
            out += (k << 3 | 1 << 1 | last).to_bytes(3, "little") + part[:1]
        at += k
    if checksum:
        out += zstd_checksum(content)
    fr = bytes(out)
    assert zstandard.ZstdDecompressor().decompress(fr) == content
    return fr


def runs_as_blocks(content, shortest=3):
    """("rle", k) for every run of at least `shortest` equal bytes, ("raw", k)
    for what lies between: the blocks of a hand-built frame of `content`."""
    blocks, at, raw = [], 0, 0
    while at < len(content):
        k = 1
        while at + k < len(content) and content[at + k] == content[at]:
            k += 1
        if k >= shortest:
            if raw:
                blocks.append(("raw", raw))
                raw = 0
            blocks.append(("rle", k))
        else:
            raw += k
        at += k
    if raw:
        blocks.append(("raw", raw))
    return blocks


def multiblock_zframe(content, chunk, checksum=True):
    """A compressor's frame of `content` made of several zstd blocks: a block
    ends after every `chunk` bytes (a flush; the frame stays one frame)."""
    c = zstandard.ZstdCompressor(level=19, write_checksum=checksum, write_content_size=True)
    o = c.compressobj(size=len(content))
    out = b""
    for a in range(0, len(content), chunk):
        out += o.compress(content[a:a + chunk]) + o.flush(zstandard.COMPRESSOBJ_FLUSH_BLOCK)
    out += o.flush(zstandard.COMPRESSOBJ_FLUSH_FINISH)
    assert len(zstd_block_types(out)) >= 3
    return out


def zstd_block_types(fr):
    """The types of the zstd blocks of the one frame fr (RFC 8878 §3.1.1.2):
    "raw", "rle" or "compressed", in order."""
    fhd = fr[4]
    single = (fhd >> 5) & 1
    p = 5 + (0 if single else 1) + (0, 1, 2, 4)[fhd & 3] + (1 if single else 0, 2, 4, 8)[fhd >> 6]
    types = []
    while True:
        h = int.from_bytes(fr[p:p + 3], "little")
        p += 3 + (1 if (h >> 1) & 3 == 1 else h >> 3)
        types.append(("raw", "rle", "compressed")[(h >> 1) & 3])
        if h & 1:
            return types


def _check_byte_planes():
    # the definition of §7, element by element, on a small case
    data = bytes(range(1, 13))                   # 3 elements of width 4
    want = bytes([1, 5, 9, 2, 6, 10, 3, 7, 11, 4, 8, 12])
    assert byte_planes(data, 4) == want and from_byte_planes(want, 4) == data
    assert byte_planes(data, 1) == data


def zstd_bound(n):
    """§7: the largest zstd frame of n content bytes (ZSTD_compressBound)."""
    return n + (n >> 8) + (((128 << 10) - n) >> 11 if n < (128 << 10) else 0)


def padded_zframe(data, size):
    """A valid zstd frame of `data` (single raw block, content size, no
    checksum) padded with empty raw blocks to at least `size` bytes: legal
    RFC 8878, but longer than any compressor writes."""
    header = bytes([0x28, 0xB5, 0x2F, 0xFD, 0xA0]) + struct.pack("<I", len(data))  # FCS 4 bytes, single segment
    body = b""
    empty = struct.pack("<I", 0 << 3 | 0 << 1 | 0)[:3]       # raw, not last, size 0
    while len(header) + len(body) + 3 + len(data) < size:
        body += empty
    last = struct.pack("<I", len(data) << 3 | 0 << 1 | 1)[:3]  # raw, last
    return header + body + last + data


def zframe(data, checksum=True, content_size=True):
    level = 19 if len(data) <= (1 << 20) else 3
    c = zstandard.ZstdCompressor(level=level, write_checksum=checksum,
                                 write_content_size=content_size, write_dict_id=False)
    return c.compress(data)


def pack_values(enc, vals):
    return struct.pack("<%d%s" % (len(vals), "I" if enc == FLOAT32 else "H"), *vals)


def pack_nodes(words):
    return struct.pack("<%dQ" % len(words), *words)


def split_range(a, b, per):
    out = []
    while a < b:
        e = min(b, a + per) if per else b
        out.append((a, e))
        a = e
    return out


def level_blocks(t, codec=CODEC_ZSTD, limit=None, zcheck=True):
    """Blocks in the order of §15: values of level l, then nodes of level l.
    limit: the largest decoded size of a block in bytes.  codec may be
    'auto' (zstd when smaller), 'alt' (alternate stored/zstd), 'cycle'
    (stored/zstd/byte planes in turn), 'planes' (values blocks codec 2,
    the others codec 1)."""
    vw = VWIDTH[t.enc]
    blocks = []
    for l in range(t.D + 1):
        a = t.first_value[l]
        for s, e in split_range(a, a + t.level_values[l], (limit // vw) if limit else None):
            blocks.append(Blk(STREAM_VALUES, l, s, e - s, pack_values(t.enc, t.values[s:e]), zcheck=zcheck))
        a = t.first_inner[l]
        for s, e in split_range(a, a + t.inner_count[l], (limit // 8) if limit else None):
            blocks.append(Blk(STREAM_NODES, l, s, e - s, pack_nodes(t.nodes[s:e]), zcheck=zcheck))
    for n, b in enumerate(blocks):
        if codec == "auto":
            b.codec = CODEC_ZSTD if len(zframe(b.data, zcheck)) < len(b.data) else CODEC_STORED
        elif codec == "alt":
            b.codec = (CODEC_STORED, CODEC_ZSTD)[n % 2]
        elif codec == "cycle":             # 0, 1, 2, 0, 1, 2, ... in file order
            b.codec = (CODEC_STORED, CODEC_ZSTD, CODEC_PLANES)[n % 3]
        elif codec == "planes":            # §15: values over byte planes, the rest zstd
            b.codec = CODEC_PLANES if b.stream == STREAM_VALUES else CODEC_ZSTD
        else:
            b.codec = codec
    return blocks


# ------------------------------------------------ §8A structures (version 1.1)

class Grid:
    """A structure of §8A, standing in for Tree in assemble(): enc, D, size,
    an all-zero level table, the value list, and the border list (kind 3)
    or the cell words (kind 4)."""

    def __init__(self, kind, enc, size, values, borders=None, cells=None, cell_log2=0):
        X, Y, Z = size
        self.kind, self.enc, self.size = kind, enc, size
        self.D = min_depth(X, Y, Z)
        self.inner_count = [0] * (self.D + 1)
        self.values = list(values)
        self.borders = list(borders) if borders is not None else None
        self.cells = list(cells) if cells is not None else None
        self.cell_log2 = cell_log2

    def copy(self):
        g = Grid(self.kind, self.enc, self.size, self.values, self.borders, self.cells, self.cell_log2)
        g.D, g.inner_count = self.D, list(self.inner_count)
        return g


def _uniform(reg):
    assert reg.size > 0 and bool((reg == reg.flat[0]).all())
    return int(reg.flat[0])


def write_regular(src, enc):
    """§8A.1: value index (z * size_y + y) * size_x + x."""
    Z, Y, X = src.shape
    vals = [_uniform(src[z:z + 1, y:y + 1, x:x + 1]) for z in range(Z) for y in range(Y) for x in range(X)]
    return Grid(KIND_REGULAR, enc, (X, Y, Z), vals)


def write_rectilinear(src, enc, bx, by, bz):
    """§8A.2: the writer takes one voxel per cell (asserting that the cell is
    uniform in the source); cell (i, j, k) has value (k * n_y + j) * n_x + i;
    stream 4 is B_x, B_y, B_z one after the other."""
    Z, Y, X = src.shape
    assert bx[0] == by[0] == bz[0] == 0 and (bx[-1], by[-1], bz[-1]) == (X, Y, Z)
    vals = []
    for k in range(len(bz) - 1):
        for j in range(len(by) - 1):
            for i in range(len(bx) - 1):
                vals.append(_uniform(src[bz[k]:bz[k + 1], by[j]:by[j + 1], bx[i]:bx[i + 1]]))
    return Grid(KIND_RECTILINEAR, enc, (X, Y, Z), vals, borders=list(bx) + list(by) + list(bz))


def write_nested(src, enc, cell_log2, expo):
    """§8A.3: expo[k][j][i] is the exponent of coarse cell (i, j, k).  Cell
    words in order (k * n_y + j) * n_x + i, values of each cell's sub-grid
    (r * m_y + q) * m_x + p, cells one after the other."""
    Z, Y, X = src.shape
    C = 1 << cell_log2
    nx, ny, nz = ceil_div(X, C), ceil_div(Y, C), ceil_div(Z, C)
    cells, vals = [], []
    for k in range(nz):
        for j in range(ny):
            for i in range(nx):
                e = expo[k][j][i]
                assert 0 <= e <= cell_log2
                h = C >> e
                o = (i * C, j * C, k * C)
                ext = (min(C, X - o[0]), min(C, Y - o[1]), min(C, Z - o[2]))
                m = [ceil_div(a, h) for a in ext]
                cells.append((e << 56) | len(vals))
                for r in range(m[2]):
                    for q in range(m[1]):
                        for p in range(m[0]):
                            lo = (o[0] + p * h, o[1] + q * h, o[2] + r * h)
                            hi = [min(lo[a] + h, o[a] + ext[a]) for a in range(3)]
                            vals.append(_uniform(src[lo[2]:hi[2], lo[1]:hi[1], lo[0]:hi[0]]))
    return Grid(KIND_NESTED, enc, (X, Y, Z), vals, cells=cells, cell_log2=cell_log2)



# ---- §7.4 codec 6, top byte in context ---------------------------------

def top_byte_context(a, b, c, centre, step):
    """§7.4: the context of a voxel from its neighbours' top bytes a, b, c."""
    g = (a >> 7) + (b >> 7) + (c >> 7)
    m = (a & 127) + (b & 127) + (c & 127)
    q = min(31, max(0, (m - 3 * centre) // step + 16))   # Python's // is a floor
    return 32 * g + q


def top_byte_table(c, T):
    """§7.4: frequencies summing to 2^16 and their cumulative sums from counts c (sum T)."""
    R6 = (1 << 48) // T
    f = [max(1, (ct * R6) >> 32) for ct in c]
    j = f.index(max(f))
    f[j] += 65536 - sum(f)
    s, acc = [], 0
    for ft in f:
        s.append(acc)
        acc += ft
    return f, s


class TopByteModel:
    """§7.4: one model's counts, sum, symbols coded and table."""

    def __init__(self, A):
        self.c, self.T, self.m = [1] * A, A, 0
        self.f, self.s = top_byte_table(self.c, self.T)

    def note(self, t):
        self.c[t] += 16
        self.T += 16
        self.m += 1
        if (self.m & (self.m - 1) == 0 and self.m >= 4) or self.m % 128 == 0:
            self.f, self.s = top_byte_table(self.c, self.T)


def top_byte_symbols(ext, tops, centre, step, mode, nibbles=None, decode=None):
    """§7.4: walks the voxels in raster order with their models; decode(model)
    returns the next symbol (decoder), else the symbols come from tops and
    nibbles (encoder).  Returns (tops, nibbles, [(f, s) of every symbol])."""
    ex, ey, ez = ext
    n = ex * ey * ez
    models = [TopByteModel(256) for _ in range(128)]
    nmodels = [TopByteModel(16) for _ in range(256)] if mode else None
    tops = list(tops) if tops is not None else [0] * n
    nibbles = list(nibbles) if nibbles is not None else [0] * n
    coded = []
    i = 0
    for z in range(ez):
        for y in range(ey):
            for x in range(ex):
                a = tops[i - 1] if x else 0
                b = tops[i - ex] if y else 0
                c = tops[i - ex * ey] if z else 0
                md = models[top_byte_context(a, b, c, centre, step)]
                t = decode(md, i) if decode else tops[i]
                tops[i] = t
                coded.append((md.f[t], md.s[t]))
                md.note(t)
                if mode:
                    nm = nmodels[t]
                    h = decode(nm, i) if decode else nibbles[i]
                    nibbles[i] = h
                    coded.append((nm.f[h], nm.s[h]))
                    nm.note(h)
                i += 1
    return tops, nibbles, coded


def top_byte_payload(data, ext, w, centre, step, mode=0, reserved=0):
    """§7.4 encoder: data holds n values of w bytes (little-endian), raster order."""
    n = ext[0] * ext[1] * ext[2]
    tops = [data[i * w + w - 1] for i in range(n)]
    highs = [data[i * w + w - 2] >> 4 for i in range(n)]
    _, _, coded = top_byte_symbols(ext, tops, centre, step, mode, highs)
    X = 1 << 23
    out = bytearray()
    for f, st in reversed(coded):
        while X >= (1 << 15) * f:
            out.append(X & 255)
            X >>= 8
        X = ((X // f) << 16) + X % f + st
    stream = struct.pack("<I", X) + bytes(reversed(out))
    whole = w - 2 if mode else w - 1
    stored = b"".join(bytes(data[i * w + p] for i in range(n)) for p in range(whole))
    if mode:
        lows = bytearray((n + 1) // 2)
        for i in range(n):
            lows[i // 2] |= (data[i * w + w - 2] & 15) << (4 * (i % 2))
        stored += bytes(lows)
    return bytes([centre, step, mode, reserved]) + struct.pack("<I", len(stream)) + stream + stored


def top_byte_decode(st, ext, w):
    """§7.4 decoder, for the self-test reader."""
    n = ext[0] * ext[1] * ext[2]
    if len(st) < 8:
        _fail("malformed", "codec6.short")
    centre, step, mode = st[0], st[1], st[2]
    if centre > 127:
        _fail("malformed", "codec6.centre")
    if step == 0:
        _fail("malformed", "codec6.step")
    if mode > 1:
        _fail("malformed", "codec6.mode")
    if st[3]:
        _fail("malformed", "codec6.reserved")
    N = 2 * n if mode else n
    (R,) = struct.unpack_from("<I", st, 4)
    if not 4 <= R <= 2 * N + 4:
        _fail("malformed", "codec6.stream_size", str(R))
    whole = w - 2 if mode else w - 1
    L = whole * n + ((n + 1) // 2 if mode else 0)
    if len(st) != 8 + R + L:
        _fail("malformed", "codec6.size", "%d bytes" % len(st))
    end = 8 + R
    if mode and n % 2 and st[end + whole * n + n // 2] >> 4:
        _fail("malformed", "codec6.padding")
    (X,) = struct.unpack_from("<I", st, 8)
    if not (1 << 23) <= X < (1 << 31):
        _fail("malformed", "codec6.initial_state", str(X))
    state = {"X": X, "pos": 12}

    def decode(model, i):
        X = state["X"]
        slot = X & 65535
        t = bisect.bisect_right(model.s, slot) - 1
        X = model.f[t] * (X >> 16) + slot - model.s[t]
        while X < (1 << 23):
            if state["pos"] >= end:
                _fail("malformed", "codec6.stream_end", "voxel %d" % i)
            X = (X << 8) | st[state["pos"]]
            state["pos"] += 1
        state["X"] = X
        return t

    tops, highs, _ = top_byte_symbols(ext, None, centre, step, mode, decode=decode)
    if state["X"] != (1 << 23):
        _fail("malformed", "codec6.state_end", str(state["X"]))
    if state["pos"] != end:
        _fail("malformed", "codec6.stream_left", "%d of %d bytes read" % (state["pos"] - 8, R))
    out = bytearray(n * w)
    for i in range(n):
        for p in range(whole):
            out[i * w + p] = st[end + p * n + i]
        if mode:
            out[i * w + w - 2] = (highs[i] << 4) | ((st[end + whole * n + i // 2] >> (4 * (i % 2))) & 15)
        out[i * w + w - 1] = tops[i]
    return bytes(out)


def bricked_order(size, b):
    """§8A.4: (first value, extent, origin) of every brick, in raster order of
    the bricks; the first values counted brick after brick."""
    X, Y, Z = size
    B = 1 << b
    out, first = [], 0
    for oz in range(0, Z, B):
        for oy in range(0, Y, B):
            for ox in range(0, X, B):
                ext = (min(B, X - ox), min(B, Y - oy), min(B, Z - oz))
                out.append((first, ext, (ox, oy, oz)))
                first += ext[0] * ext[1] * ext[2]
    return out


def write_bricked(src, enc, b):
    """§8A.4: the voxels brick by brick, raster order inside each brick."""
    Z, Y, X = src.shape
    vals = []
    for _, (ex, ey, ez), (ox, oy, oz) in bricked_order((X, Y, Z), b):
        vals += [int(v) for v in src[oz:oz + ez, oy:oy + ey, ox:ox + ex].reshape(-1)]
    return Grid(KIND_BRICKED, enc, (X, Y, Z), vals, cell_log2=b)


def bricked_blocks(g, codec=CODEC_PREDICTED, **pred):
    """One values block per brick; codec 3 blocks with the predictor settings
    `pred` (or a function of the brick number giving them)."""
    blocks = []
    for q, (first, ext, _) in enumerate(bricked_order(g.size, g.cell_log2)):
        n = ext[0] * ext[1] * ext[2]
        vals = g.values[first:first + n]
        c = codec(q) if callable(codec) else codec
        blk = Blk(STREAM_VALUES, 0, first, n, pack_values(g.enc, vals), codec=c)
        if c == CODEC_PREDICTED:
            kw = pred["per_brick"](q) if "per_brick" in pred else pred
            blk.stored = predicted_payload(vals, ext, **kw)
        if c == CODEC_TOP_BYTE:     # §7.4, with the centre and step given (or 60 and 4)
            kw = pred["per_brick"](q) if "per_brick" in pred else pred
            blk.stored = top_byte_payload(blk.data, ext, VWIDTH[g.enc], kw.get("centre", 60), kw.get("step", 4),
                                          kw.get("mode", 0))
        if c == CODEC_MASKED:       # the brick's most common value as background, unless given
            kw = pred["per_brick"](q) if "per_brick" in pred else dict(pred)
            background = kw.pop("background", None)
            if background is None:
                background = max(sorted(set(vals)), key=vals.count)
            blk.stored = masked_payload(vals, background, **kw)
        blocks.append(blk)
    return blocks


def pack_u32(v):
    return struct.pack("<%dI" % len(v), *v)


def grid_blocks(g, codec=CODEC_ZSTD, limit=None, slimit=None, zcheck=True, struct_first=True):
    """Blocks of a §8A file, all of level 0: the structure stream (borders or
    cells) split at slimit decoded bytes and the values split at limit
    decoded bytes; codec as in level_blocks."""
    vw = VWIDTH[g.enc]
    sb, vb = [], []
    if g.borders is not None:
        for s, e in split_range(0, len(g.borders), (slimit // 4) if slimit else None):
            sb.append(Blk(STREAM_BORDERS, 0, s, e - s, pack_u32(g.borders[s:e]), zcheck=zcheck))
    if g.cells is not None:
        for s, e in split_range(0, len(g.cells), (slimit // 8) if slimit else None):
            sb.append(Blk(STREAM_CELLS, 0, s, e - s, pack_nodes(g.cells[s:e]), zcheck=zcheck))
    for s, e in split_range(0, len(g.values), (limit // vw) if limit else None):
        vb.append(Blk(STREAM_VALUES, 0, s, e - s, pack_values(g.enc, g.values[s:e]), zcheck=zcheck))
    blocks = sb + vb if struct_first else vb + sb
    for n, b in enumerate(blocks):
        if codec == "auto":
            b.codec = CODEC_ZSTD if len(zframe(b.data, zcheck)) < len(b.data) else CODEC_STORED
        elif codec == "alt":
            b.codec = (CODEC_STORED, CODEC_ZSTD)[n % 2]
        elif codec == "cycle":             # 0, 1, 2, 0, 1, 2, ... in file order
            b.codec = (CODEC_STORED, CODEC_ZSTD, CODEC_PLANES)[n % 3]
        elif codec == "planes":            # §15: values over byte planes, the rest zstd
            b.codec = CODEC_PLANES if b.stream == STREAM_VALUES else CODEC_ZSTD
        else:
            b.codec = codec
    return blocks


def grid_file(g, meta=None, codec=CODEC_ZSTD, limit=None, slimit=None, meta_first=False,
              struct_first=True, zcheck=True, mutate_blocks=None, **kw):
    """A complete §8A file: version_minor 1, structure_kind and byte 11
    (cell_log2) from the grid, level table all zero."""
    blocks = grid_blocks(g, codec, limit, slimit, zcheck, struct_first)
    mb = meta_block(meta if meta is not None else DEFAULT_META,
                    codec if codec in (0, 1) else CODEC_ZSTD, zcheck=zcheck)
    if meta_first:
        blocks.insert(0, mb)
    else:
        blocks.append(mb)
    if mutate_blocks:
        mutate_blocks(blocks)
    kw.setdefault("minor", 1)
    kw.setdefault("structure_kind", g.kind)
    kw.setdefault("ireserved", g.cell_log2)
    data, lay = assemble(g, blocks, **kw)
    return data, lay, blocks


DEFAULT_META = {
    "voxel_size": [0.05, 0.05, 0.05],
    "unit": "mm",
    "origin": [0.0, 0.0, 0.0],
    "value": {"quantity": "grey_value", "unit": ""},
}


def meta_bytes(obj):
    return json.dumps(obj, ensure_ascii=False, separators=(",", ":")).encode("utf-8")


def meta_block(text, codec=CODEC_ZSTD, zcheck=True):
    if isinstance(text, dict):
        text = meta_bytes(text)
    return Blk(STREAM_META, 0, 0, len(text), text, codec=codec, zcheck=zcheck)


class Layout:
    pass


def assemble(t, blocks, scale=1.0, offset=0.0, major=1, minor=0, header_extra=b"",
             required=0, optional=0, hreserved=0, fixed_extra=b"", structure_kind=1,
             value_encoding=None, depth=None, ireserved=0, size=None, level_table=None,
             entry_extra=b"", gap_before_index=b"", index_tail=b"", block_count=None,
             framed=False, descriptor=None):
    """Header | blocks | index | footer, all CRCs computed.  Returns
    (bytes, Layout).  Every keyword overrides one field of a valid file.
    framed (1.3, §4.1, §7.1): required feature bit 0, the volume descriptor
    (index bytes 8 .. 40, or `descriptor`) and 8 reserved bytes in the
    header, and a 32-byte block header before every block's payload."""
    X, Y, Z = t.size if size is None else size
    D = t.D if depth is None else depth
    ve = t.enc if value_encoding is None else value_encoding
    fixed_fields = struct.pack("<BBBBIIIdd", structure_kind, ve, D, ireserved, X, Y, Z, scale, offset)
    if framed:
        required |= 1
        header_extra = (fixed_fields if descriptor is None else descriptor) + bytes(8) + header_extra
    header_size = 40 + len(header_extra)
    fixed_size = 48 + len(fixed_extra)
    entry_size = 32 + len(entry_extra)
    hdr = struct.pack("<8sHHIQQI", SIG, major, minor, header_size, required, optional, hreserved)
    hdr += header_extra
    hdr += struct.pack("<I", crc32c(hdr))
    assert len(hdr) == header_size
    out = bytearray(hdr)
    lay = Layout()
    lay.header_size, lay.fixed_size, lay.entry_size = header_size, fixed_size, entry_size
    lay.block_offsets = []
    entries = []
    for b in blocks:
        st = b.stored_bytes()
        if framed:
            st = block_header(b, st) + st
        f = dict(file_offset=len(out), first=b.first, count=b.count, stored_size=len(st),
                 crc=crc32c(st), stream=b.stream, codec=b.codec, flags=b.flags, level=b.level)
        f.update(b.ov)
        lay.block_offsets.append(len(out))
        out += st
        entries.append(struct.pack("<QQIIIBBBB", f["file_offset"], f["first"], f["count"],
                                   f["stored_size"], f["crc"], f["stream"], f["codec"],
                                   f["flags"], f["level"]) + (b.extra or entry_extra))
    out += gap_before_index
    index_offset = len(out)
    lt = t.inner_count if level_table is None else level_table
    bc = len(blocks) if block_count is None else block_count
    idx = struct.pack("<4sIBBBBIIIddII", IDX_SIG, fixed_size, structure_kind, ve, D, ireserved,
                      X, Y, Z, scale, offset, bc, entry_size) + fixed_extra
    lay.level_table_offset = len(idx)
    idx += struct.pack("<%dQ" % len(lt), *lt)
    lay.entries_offset = len(idx)
    idx += b"".join(entries) + index_tail
    out += idx
    footer = struct.pack("<QQI", index_offset, len(idx), crc32c(idx))
    footer += struct.pack("<I", crc32c(footer)) + END_SIG
    out += footer
    lay.index_offset, lay.index_size = index_offset, len(idx)
    return bytes(out), lay


def block_header(b, payload):
    """§7.1: signature, stream, codec, flags, level, first_element,
    element_count, payload_size, payload_crc, header_crc; `b.hov` overrides
    fields (and `header_crc`) for invalid files."""
    f = dict(sig=b"IVBK", stream=b.stream, codec=b.codec, flags=b.flags, level=b.level,
             first=b.first, count=b.count, payload_size=len(payload), payload_crc=crc32c(payload))
    f.update({k: v for k, v in b.hov.items() if k != "header_crc"})
    h = struct.pack("<4sBBBBQIII", f["sig"], f["stream"], f["codec"], f["flags"], f["level"],
                    f["first"], f["count"], f["payload_size"], f["payload_crc"])
    return h + struct.pack("<I", b.hov.get("header_crc", crc32c(h)))


def u16(d, o):
    return struct.unpack_from("<H", d, o)[0]


def u32(d, o):
    return struct.unpack_from("<I", d, o)[0]


def u64(d, o):
    return struct.unpack_from("<Q", d, o)[0]


def reseal(data, header=True, index=True):
    """Recompute header_crc, index_crc and footer_crc after a patch."""
    d = bytearray(data)
    if header:
        hs = u32(d, 12)
        struct.pack_into("<I", d, hs - 4, crc32c(d[:hs - 4]))
    f = len(d) - 32
    if index:
        io, isz = u64(d, f), u64(d, f + 8)
        struct.pack_into("<I", d, f + 16, crc32c(d[io:io + isz]))
    struct.pack_into("<I", d, f + 20, crc32c(d[f:f + 20]))
    return bytes(d)


def patch(data, off, fmt, *vals):
    d = bytearray(data)
    struct.pack_into(fmt, d, off, *vals)
    return bytes(d)


def patch_index(data, lay, rel, fmt, *vals):
    """Patch the index at offset rel (relative to the index) and reseal."""
    return reseal(patch(data, lay.index_offset + rel, fmt, *vals))


def entry_off(lay, n, field):
    fo = {"file_offset": 0, "first": 8, "count": 16, "stored_size": 20, "crc": 24,
          "stream": 28, "codec": 29, "flags": 30, "level": 31}[field]
    return lay.entries_offset + n * lay.entry_size + fo


# ------------------------------------------------------------------ self-test reader

class IvolError(Exception):
    def __init__(self, cls, tag, msg=""):
        super().__init__("%s [%s] %s" % (cls, tag, msg))
        self.cls, self.tag = cls, tag


def _fail(cls, tag, msg=""):
    raise IvolError(cls, tag, msg)


def _no_dups(pairs):
    d = {}
    for k, v in pairs:
        if k in d:
            _fail("malformed", "metadata.duplicate_key", k)
        d[k] = v
    return d


def _reject_constant(s):
    _fail("malformed", "metadata.json", "non-JSON constant " + s)


def _is_num(v):
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def check_metadata(txt):
    if len(txt) > MIB16:
        _fail("malformed", "metadata.size")
    if txt.startswith(b"\xef\xbb\xbf"):
        _fail("malformed", "metadata.bom")
    try:
        s = txt.decode("utf-8")
    except UnicodeDecodeError:
        _fail("malformed", "metadata.utf8")
    depth = deepest = 0
    in_str = esc = False
    for ch in s:                    # §11: nesting at most 128, found before parsing
        if in_str:
            if esc:
                esc = False
            elif ch == "\\":
                esc = True
            elif ch == '"':
                in_str = False
        elif ch == '"':
            in_str = True
        elif ch in "[{":
            depth += 1
            deepest = max(deepest, depth)
        elif ch in "]}":
            depth -= 1
    if deepest > 128:
        _fail("malformed", "metadata.depth")
    try:
        obj = json.loads(s, object_pairs_hook=_no_dups, parse_constant=_reject_constant)
    except json.JSONDecodeError:
        _fail("malformed", "metadata.json")
    if not isinstance(obj, dict):
        _fail("malformed", "metadata.top_level")
    vs = obj.get("voxel_size")
    if not (isinstance(vs, list) and len(vs) == 3 and all(_is_num(v) and v > 0 for v in vs)):
        _fail("malformed", "metadata.voxel_size")
    if not isinstance(obj.get("unit"), str):
        _fail("malformed", "metadata.unit")
    og = obj.get("origin")
    if not (isinstance(og, list) and len(og) == 3 and all(_is_num(v) for v in og)):
        _fail("malformed", "metadata.origin")
    val = obj.get("value")
    if not (isinstance(val, dict) and isinstance(val.get("quantity"), str)):
        _fail("malformed", "metadata.value")
    if "unit" in val and not isinstance(val["unit"], str):
        _fail("malformed", "metadata.value")
    for k in ("structure", "provenance", "user"):
        if k in obj and not isinstance(obj[k], dict):
            _fail("malformed", "metadata." + k)
    return obj


def check_block_header(st, e):
    """§7.1: the block header repeats the index entry; returns the payload."""
    if st[:4] != b"IVBK":
        _fail("malformed", "block_header.signature", "block %d" % e["n"])
    if crc32c(st[:28]) != u32(st, 28):
        _fail("checksum", "block_header.crc", "block %d" % e["n"])
    stream, codec, flags, level, first, count, psize, pcrc = struct.unpack_from("<BBBBQIII", st, 4)
    if (stream, codec, flags, level, first, count) != (e["stream"], e["codec"], e["flags"], e["level"],
                                                       e["first"], e["count"]):
        _fail("malformed", "block_header.fields", "block %d" % e["n"])
    if psize != len(st) - 32:
        _fail("malformed", "block_header.payload_size", "block %d" % e["n"])
    if crc32c(st[32:]) != pcrc:
        _fail("checksum", "block_header.payload_crc", "block %d" % e["n"])
    return st[32:]


def decode_block(data, e, width):
    st = data[e["file_offset"]:e["file_offset"] + e["stored_size"]]
    if crc32c(st) != e["crc"]:
        _fail("checksum", "block.crc", "block %d" % e["n"])
    if e["framed"]:
        st = check_block_header(st, e)
    need = e["count"] * width
    if e["codec"] == CODEC_STORED:
        return st
    if e["codec"] == CODEC_PREDICTED:
        if e.get("brick") is None or width != 2:
            _fail("malformed", "codec3.where")
        return predicted_decode(st, e["brick"])
    if e["codec"] == CODEC_TOP_BYTE:
        if e.get("brick") is None or width not in (2, 4):
            _fail("malformed", "codec6.where")
        return top_byte_decode(st, e["brick"], width)
    if e["codec"] == CODEC_MASKED:
        if e.get("brick") is None or width != 2:
            _fail("malformed", "codec4.where")
        return masked_decode(st, e["count"])
    if e["codec"] == CODEC_FRAMES:
        return from_byte_planes(zstd_plane_frames(st, e["count"], width), width)
    out = zstd_content(st, need)
    if e["codec"] == CODEC_PLANES:
        return from_byte_planes(out, width)
    return out


def zstd_plane_frames(st, n, w):
    """§7 codec 5: exactly w zstd frames and nothing else, each under the
    rules of codec 1 for n content bytes; returns their contents, the byte
    planes, one after the other.  (The frames' ends are found by the
    library's decoder, one frame at a time.)"""
    planes, rest = b"", st
    for p in range(w):
        if not rest:
            _fail("malformed", "codec5.frames", "%d frames, expected %d" % (p, w))
        if rest[:4] != b"\x28\xb5\x2f\xfd":
            _fail("malformed", "codec5.skippable" if rest[1:4] == b"\x2a\x4d\x18" and rest[0] >> 4 == 5
                  else "zstd.frame", "frame %d" % p)
        try:
            prm = zstandard.get_frame_parameters(rest)
        except zstandard.ZstdError:
            _fail("malformed", "zstd.frame", "frame %d" % p)
        if prm.content_size != n:
            _fail("malformed", "zstd.content_size", "frame %d: %d" % (p, prm.content_size))
        if prm.dict_id != 0:
            _fail("malformed", "zstd.dict", "frame %d" % p)
        dobj = zstandard.ZstdDecompressor().decompressobj()
        try:
            out = dobj.decompress(rest)
        except zstandard.ZstdError as ex:
            if "checksum" in str(ex).lower():
                _fail("checksum", "zstd.checksum", "frame %d" % p)
            _fail("malformed", "zstd.data", "frame %d: %s" % (p, ex))
        if not dobj.eof:
            _fail("malformed", "codec5.cut", "frame %d does not end within the payload" % p)
        if len(out) != n:
            _fail("malformed", "zstd.extra", "frame %d" % p)
        planes += out
        rest = dobj.unused_data
    if rest:
        _fail("malformed", "codec5.extra", "%d bytes after the %d frames" % (len(rest), w))
    return planes


def zstd_content(st, need):
    """§7 codec 1: exactly one zstd frame of `need` content bytes."""
    try:
        p = zstandard.get_frame_parameters(st)
    except zstandard.ZstdError:
        _fail("malformed", "zstd.frame")
    if p.content_size != need:
        _fail("malformed", "zstd.content_size", str(p.content_size))
    if p.dict_id != 0:
        _fail("malformed", "zstd.dict")
    dobj = zstandard.ZstdDecompressor().decompressobj()
    try:
        out = dobj.decompress(st)
    except zstandard.ZstdError as ex:
        if "checksum" in str(ex).lower():
            _fail("checksum", "zstd.checksum")
        _fail("malformed", "zstd.data", str(ex))
    if not dobj.eof or dobj.unused_data or len(out) != need:
        _fail("malformed", "zstd.extra")
    return out


def read_ivol(data, verify=True):
    """Returns (dense, {k: lod}, metadata).  Raises IvolError."""
    n = len(data)
    # 1. signature
    if n < 8:
        if data == SIG[:n]:
            _fail("truncated", "short.signature")
        _fail("not-ivol", "signature")
    if data[:8] != SIG:
        _fail("not-ivol", "signature")
    # 2. version
    if n < 10:
        _fail("truncated", "short.version")
    if u16(data, 8) != 1:
        _fail("unsupported-version", "version_major", str(u16(data, 8)))
    if n < 12:
        _fail("truncated", "short.version")
    # 3. header
    if n < 16:
        _fail("truncated", "short.header")
    hs = u32(data, 12)
    if not 40 <= hs <= 4096:
        _fail("malformed", "header_size")
    if n < hs + 32:
        _fail("truncated", "short.file")
    if crc32c(data[:hs - 4]) != u32(data, hs - 4):
        _fail("checksum", "header_crc")
    if u32(data, 32) != 0:
        _fail("malformed", "header.reserved")
    if u64(data, 16) & ~1:
        _fail("unsupported-feature", "required_features")
    framed = bool(u64(data, 16) & 1)         # §4.1 (1.3): framed blocks, volume descriptor
    if framed and hs < 80:
        _fail("malformed", "framed.header_size")
    if framed and data[68:76] != bytes(8):
        _fail("malformed", "framed.reserved")
    # 4. footer
    if data[-8:] != END_SIG:
        _fail("truncated", "end_signature")
    f = n - 32
    if crc32c(data[f:f + 20]) != u32(data, f + 20):
        _fail("checksum", "footer_crc")
    io, isz = u64(data, f), u64(data, f + 8)
    if io < hs or io + isz + 32 != n:
        _fail("malformed", "index_range")
    if isz > 4096 + 8 * 32 + 4096 * (io - hs):
        _fail("malformed", "index_size_bound")
    idx = data[io:io + isz]
    if crc32c(idx) != u32(data, f + 16):
        _fail("checksum", "index_crc")
    # 5. index: fixed part
    if isz < 48:
        _fail("malformed", "index_size")
    if idx[:4] != IDX_SIG:
        _fail("malformed", "index_signature")
    fs = u32(idx, 4)
    if not 48 <= fs <= 4096 or fs > isz:
        _fail("malformed", "fixed_size")
    sk, ve, D, ires = idx[8], idx[9], idx[10], idx[11]
    if sk not in (1, 2, 3, 4, 5):
        _fail("unsupported-feature", "structure_kind", str(sk))
    if ve not in (1, 2, 3):
        _fail("unsupported-feature", "value_encoding", str(ve))
    if sk == 4:
        if not 1 <= ires <= 31:
            _fail("malformed", "cell_log2", str(ires))
    elif sk == 5:
        if not 1 <= ires <= 8:
            _fail("malformed", "brick_log2", str(ires))
        if not framed:
            _fail("malformed", "bricked.unframed")
    elif ires != 0:
        _fail("malformed", "index.reserved")
    X, Y, Z = u32(idx, 12), u32(idx, 16), u32(idx, 20)
    if min(X, Y, Z) < 1:
        _fail("malformed", "size")
    if D > 31 or D != min_depth(X, Y, Z):
        _fail("malformed", "depth")
    scale, offset = struct.unpack_from("<dd", idx, 24)
    if not math.isfinite(scale) or scale == 0.0:
        _fail("malformed", "value_scale")
    if not math.isfinite(offset):
        _fail("malformed", "value_offset")
    if framed and data[36:68] != idx[8:40]:
        _fail("malformed", "framed.descriptor")
    bc, es = u32(idx, 40), u32(idx, 44)
    if bc < 2:
        _fail("malformed", "block_count")
    if not 32 <= es <= 4096:
        _fail("malformed", "block_entry_size")
    if isz != fs + 8 * (D + 1) + bc * es:
        _fail("malformed", "index_size")
    # level table
    ic = list(struct.unpack_from("<%dQ" % (D + 1), idx, fs))
    if sk != 1 and any(ic):
        _fail("malformed", "level_table.nonzero")
    if ic[0] > 1 or ic[D] != 0:
        _fail("malformed", "level_table")
    for l in range(D):
        if ic[l + 1] > 8 * ic[l]:
            _fail("malformed", "level_table")
    total_inner = sum(ic)
    total_values = 1 + 8 * total_inner
    first_inner = [sum(ic[:l]) for l in range(D + 1)]
    level_values = [1] + [8 * ic[l - 1] for l in range(1, D + 1)]
    first_value = [0] + [1 + 8 * first_inner[l - 1] for l in range(1, D + 1)]
    vw = VWIDTH[ve]
    width = {1: 1, 2: 8, 3: vw, 4: 4, 5: 8, 7: vw}
    # block table
    entries = []
    pos = hs
    for b in range(bc):
        o = fs + 8 * (D + 1) + b * es
        fo, fe, cnt, ss, crc, stream, codec, flags, level = struct.unpack_from("<QQIIIBBBB", idx, o)
        e = dict(n=b, file_offset=fo, first=fe, count=cnt, stored_size=ss, crc=crc,
                 stream=stream, codec=codec, flags=flags, level=level, framed=framed)
        if flags & 0xFE:
            _fail("malformed", "block.flags", "block %d" % b)
        if fo != pos:
            _fail("malformed", "block.placement", "block %d" % b)
        if cnt < 1 or ss < 1 or (framed and ss <= 32):
            _fail("malformed", "block.sizes", "block %d" % b)
        pos += ss
        # streams 4 and 5 are known only in files of kinds 3 and 4, stream 7
        # only in files of kind 5; elsewhere they are unknown streams (§6.4)
        if (stream in (1, 2, 3) or (stream == 4 and sk == 3) or (stream == 5 and sk == 4)
                or (stream == STREAM_LOD and sk == 5)):
            if stream == STREAM_LOD:         # §6.4, §8A.5: ignorable, a level 1 .. D
                if flags != 1:
                    _fail("malformed", "lod.flags", "block %d" % b)
                if not 1 <= level <= D:
                    _fail("malformed", "lod.level", "block %d level %d" % (b, level))
            elif flags != 0:
                _fail("malformed", "block.flags", "block %d" % b)
            if codec not in (0, 1, 2, 3, 4, 5, 6):
                _fail("unsupported-feature", "codec", "block %d codec %d" % (b, codec))
            if codec in (3, 4) and not (stream in (3, STREAM_LOD) and sk == 5 and ve in (1, 2)):
                _fail("malformed", "codec%d.where" % codec, "block %d" % b)
            if codec == 6 and not (stream in (3, STREAM_LOD) and sk == 5 and width[stream] in (2, 4)):
                _fail("malformed", "codec6.where", "block %d" % b)
            if codec == 6 and ss > 12 + width[stream] * cnt + (32 if framed else 0):
                _fail("malformed", "block.stored_bound", "block %d" % b)
            if codec == 5 and width[stream] < 2:       # §7: codec 5 needs w >= 2
                _fail("malformed", "codec5.where", "block %d" % b)
            if codec == 5 and ss > width[stream] * zstd_bound(cnt) + (32 if framed else 0):
                _fail("malformed", "block.stored_bound", "block %d" % b)
            if codec == 3 and ss > 24 + zstd_bound(2 * cnt) + (32 if framed else 0):
                _fail("malformed", "block.stored_bound", "block %d" % b)
            if codec == 4 and ss > 4 + zstd_bound((cnt + 7) // 8 + 2 * cnt) + (32 if framed else 0):
                _fail("malformed", "block.stored_bound", "block %d" % b)
            if cnt * width[stream] > MIB64:
                _fail("malformed", "block.too_large", "block %d" % b)
            if codec == 0 and ss != cnt * width[stream] + (32 if framed else 0):
                _fail("malformed", "block.stored_size", "block %d" % b)
            if codec in (1, 2) and ss > zstd_bound(cnt * width[stream]) + (32 if framed else 0):
                _fail("malformed", "block.stored_bound", "block %d" % b)
        elif not flags & 1:
            _fail("unsupported-feature", "stream", "block %d stream %d" % (b, stream))
        entries.append(e)
    if pos != io:
        _fail("malformed", "block.placement", "last block does not end at index_offset")
    metas = [e for e in entries if e["stream"] == 1]
    if len(metas) != 1:
        _fail("malformed", "metadata.count")
    if metas[0]["level"] != 0:
        _fail("malformed", "metadata.level")
    if sk != 1:
        return _read_grid(data, entries, metas[0], sk, ve, D, ires, (X, Y, Z), verify)
    for stream, total in ((2, total_inner), (3, total_values)):
        pos = 0
        for e in sorted((e for e in entries if e["stream"] == stream), key=lambda e: e["first"]):
            if e["first"] != pos:
                _fail("malformed", "stream.coverage", "stream %d" % stream)
            pos += e["count"]
            l = e["level"]
            if l > D:
                _fail("malformed", "block.level")
            lo, hi = ((first_inner[l], first_inner[l] + ic[l]) if stream == 2 else
                      (first_value[l], first_value[l] + level_values[l]))
            if e["first"] < lo or e["first"] + e["count"] > hi:
                _fail("malformed", "block.level", "block %d" % e["n"])
        if pos != total:
            _fail("malformed", "stream.coverage", "stream %d" % stream)
    meta = check_metadata(decode_block(data, metas[0], 1))
    # 6. the other blocks
    nodes = [None] * total_inner
    values = [None] * total_values
    for e in entries:
        if e["stream"] == 2:
            raw = decode_block(data, e, 8)
            nodes[e["first"]:e["first"] + e["count"]] = struct.unpack("<%dQ" % e["count"], raw)
        elif e["stream"] == 3:
            raw = decode_block(data, e, vw)
            values[e["first"]:e["first"] + e["count"]] = struct.unpack(
                "<%d%s" % (e["count"], "I" if vw == 4 else "H"), raw)
    # nodes (§8)
    dt = NPBITS[ve]
    dense = np.zeros((Z, Y, X), dtype=dt)

    def weight(l, i, j, k):
        s = 1 << (D - l)
        ov = lambda a, nn: max(0, min(nn, (a + 1) * s) - a * s)
        return ov(i, X) * ov(j, Y) * ov(k, Z)

    # per level: list of (value index, coords, inner node index or None)
    lvl = [[(0, (0, 0, 0), 0 if ic[0] == 1 else None)]]
    running = 1
    tree = []
    for l in range(D + 1):
        cur = lvl[l]
        nxt = []
        ninner = 0
        for vi, (i, j, k), nn in cur:
            w = weight(l, i, j, k)
            if w == 0 and nn is not None:
                _fail("malformed", "padding_subdivided", "level %d node %s" % (l, (i, j, k)))
            if w == 0 and values[vi] != 0:
                _fail("malformed", "padding_value", "level %d node %s" % (l, (i, j, k)))
            tree.append((l, vi, (i, j, k), nn, w))
            if nn is None:
                continue
            ninner += 1
            word = nodes[nn]
            fic, mask = word & ((1 << 56) - 1), word >> 56
            if l == D - 1 and mask:
                _fail("malformed", "mask_at_last_level", "node %d" % nn)
            if fic != running:
                _fail("malformed", "first_inner_child", "node %d: %d, expected %d" % (nn, fic, running))
            pc = 0
            for c in range(8):
                child_inner = (mask >> c) & 1
                ci = (2 * i + (c & 1), 2 * j + ((c >> 1) & 1), 2 * k + ((c >> 2) & 1))
                nxt.append((1 + 8 * nn + c, ci, (fic + pc) if child_inner else None))
                pc += child_inner
            running += pc
        if ninner != ic[l]:
            _fail("malformed", "popcount_sum", "level %d" % l)
        if l < D:
            lvl.append(nxt)
    # dense export (§12.2)
    node_m = {}
    by_vi = {}
    for l, vi, (i, j, k), nn, w in tree:
        by_vi[vi] = (l, (i, j, k), nn, w)
        if nn is None and w > 0:
            s = 1 << (D - l)
            dense[k * s:(k + 1) * s, j * s:(j + 1) * s, i * s:(i + 1) * s] = values[vi]
    # verify averages (§10)
    if verify:
        for l, vi, (i, j, k), nn, w in reversed(tree):
            if w == 0:
                continue
            if nn is None:
                node_m[vi] = decode(ve, values[vi])
                continue
            acc, W = 0.0, 0
            for c in range(8):
                cvi = 1 + 8 * nn + c
                cw = by_vi[cvi][3]
                if cw > 0:
                    acc = acc + float(cw) * node_m[cvi]
                    W += cw
            node_m[vi] = acc / float(W)
            if encode(ve, node_m[vi]) != values[vi]:
                _fail("malformed", "average", "value %d" % vi)
    # levels of detail (§12.3)
    lods = {}
    for kk in range(1, D + 1):
        L = D - kk
        arr = np.zeros((ceil_div(Z, 1 << kk), ceil_div(Y, 1 << kk), ceil_div(X, 1 << kk)), dtype=dt)
        for l, vi, (i, j, k), nn, w in tree:
            if l > L or w == 0 or (nn is not None and l < L):
                continue
            s = 1 << (L - l)
            arr[k * s:(k + 1) * s, j * s:(j + 1) * s, i * s:(i + 1) * s] = values[vi]
        lods[kk] = arr
    return dense, lods, meta


def _tile(entries, stream):
    """Blocks of a stream in order of first_element must tile 0 .. n; returns n."""
    pos = 0
    for e in sorted((e for e in entries if e["stream"] == stream), key=lambda e: e["first"]):
        if e["first"] != pos:
            _fail("malformed", "stream.coverage", "stream %d" % stream)
        pos += e["count"]
    return pos


def _read_grid(data, entries, meta_entry, sk, ve, D, cell_log2, size, verify=True):
    """The rest of read_ivol for the structures of §8A (§6.4, §8A, §12)."""
    X, Y, Z = size
    known = {2: (), 3: (4,), 4: (5,), 5: (STREAM_LOD,)}[sk]
    entries = [e for e in entries if e["stream"] in (1, 2, 3) + known]   # drop ignorable unknown
    present = {e["stream"] for e in entries}
    if 2 in present:
        _fail("malformed", "stream.kind", "nodes stream with structure_kind %d" % sk)
    if sk == 3 and 4 not in present:
        _fail("malformed", "stream.kind", "no borders stream")
    if sk == 4 and 5 not in present:
        _fail("malformed", "stream.kind", "no cells stream")
    for e in entries:
        if e["stream"] in (3, 4, 5) and e["level"] != 0:
            _fail("malformed", "block.level", "block %d" % e["n"])
    if sk == 3 and sum(e["count"] for e in entries if e["stream"] == 4) > X + Y + Z + 3:
        _fail("malformed", "borders.count")
    n_values_cov = _tile(entries, 3)
    if sk in (2, 5) and n_values_cov != X * Y * Z:
        _fail("malformed", "stream.coverage", "stream 3")
    def check_bricks(blocks, bsize, what):
        """§8A.4: one brick per block, or (codec 4) a run of whole bricks, the
        blocks already known to tile the grid of size bsize in order."""
        bricks = bricked_order(bsize, cell_log2)
        blocks = sorted(blocks, key=lambda e: e["first"])
        if len(blocks) > len(bricks):
            _fail("malformed", what + ".blocks", "%d blocks, %d bricks" % (len(blocks), len(bricks)))
        q = 0
        for e in blocks:
            if q >= len(bricks) or e["first"] != bricks[q][0]:
                _fail("malformed", what + ".block", "block %d" % e["n"])
            e["brick"] = bricks[q][1]
            left, held = e["count"], 0
            while left > 0 and q < len(bricks):
                ext = bricks[q][1]
                left -= ext[0] * ext[1] * ext[2]
                q, held = q + 1, held + 1
            if left != 0:
                _fail("malformed", "codec4.run" if e["codec"] == CODEC_MASKED else what + ".block",
                      "block %d" % e["n"])
            if held > 1 and e["codec"] != CODEC_MASKED:
                _fail("malformed", what + ".block", "block %d" % e["n"])

    stored_levels = {}
    if sk == 5:   # §8A.4: one brick per values block (codec 4: a run of whole bricks, §7.3)
        check_bricks([e for e in entries if e["stream"] == 3], size, "bricked")
        # §8A.5: each stored level k is a bricked grid of ceil(size / 2^k), whole or absent
        for e in entries:
            if e["stream"] == STREAM_LOD:
                stored_levels.setdefault(e["level"], []).append(e)
        for k, blocks in sorted(stored_levels.items()):
            m = tuple(ceil_div(a, 1 << k) for a in size)
            pos = 0
            for e in sorted(blocks, key=lambda e: e["first"]):
                if e["first"] != pos:
                    _fail("malformed", "lod.coverage", "level %d" % k)
                pos += e["count"]
            if pos != m[0] * m[1] * m[2]:
                _fail("malformed", "lod.coverage", "level %d" % k)
            check_bricks(blocks, m, "lod")
    if sk == 3:
        _tile(entries, 4)
    if sk == 4:
        C = 1 << cell_log2
        ncell = (ceil_div(X, C), ceil_div(Y, C), ceil_div(Z, C))
        if _tile(entries, 5) != ncell[0] * ncell[1] * ncell[2]:
            _fail("malformed", "stream.coverage", "stream 5")
    meta = check_metadata(decode_block(data, meta_entry, 1))
    vw = VWIDTH[ve]

    def gather(stream, width, fmt):
        out = []
        for e in sorted((e for e in entries if e["stream"] == stream), key=lambda e: e["first"]):
            raw = decode_block(data, e, width)
            out += struct.unpack("<%d%s" % (e["count"], fmt), raw)
        return out

    # structure -> list of boxes (x0, x1, y0, y1, z0, z1) in value order
    boxes = []
    if sk == 2:
        total = X * Y * Z
    elif sk == 5:
        total = X * Y * Z
        for _, (ex, ey, ez), (ox, oy, oz) in bricked_order(size, cell_log2):
            for z in range(oz, oz + ez):
                for y in range(oy, oy + ey):
                    for x in range(ox, ox + ex):
                        boxes.append((x, x + 1, y, y + 1, z, z + 1))
    elif sk == 3:
        b = gather(4, 4, "I")
        pos = [0]

        def take(n):
            if pos[0] >= len(b) or b[pos[0]] != 0:
                _fail("malformed", "borders.start")
            lst = [0]
            pos[0] += 1
            while lst[-1] != n:
                if pos[0] >= len(b):
                    _fail("malformed", "borders.end")
                v = b[pos[0]]
                if v <= lst[-1]:
                    _fail("malformed", "borders.increasing")
                if v > n:
                    _fail("malformed", "borders.end", "border %d beyond size %d" % (v, n))
                lst.append(v)
                pos[0] += 1
            return lst

        bx, by, bz = take(X), take(Y), take(Z)
        if pos[0] != len(b):
            _fail("malformed", "borders.extra")
        for k in range(len(bz) - 1):
            for j in range(len(by) - 1):
                for i in range(len(bx) - 1):
                    boxes.append((bx[i], bx[i + 1], by[j], by[j + 1], bz[k], bz[k + 1]))
        total = len(boxes)
    else:
        words = gather(5, 8, "Q")
        C = 1 << cell_log2
        nx, ny, nz = ncell
        running = 0
        geo = []
        for n, w in enumerate(words):
            e, fv = w >> 56, w & ((1 << 56) - 1)
            if e > cell_log2:
                _fail("malformed", "cells.exponent", "cell %d" % n)
            if fv != running:
                _fail("malformed", "cells.chain", "cell %d: %d, expected %d" % (n, fv, running))
            i, j, k = n % nx, (n // nx) % ny, n // (nx * ny)
            h = C >> e
            o = (i * C, j * C, k * C)
            ext = (min(C, X - o[0]), min(C, Y - o[1]), min(C, Z - o[2]))
            mm = [-(-a // h) for a in ext]
            geo.append((h, o, ext, mm))
            running += mm[0] * mm[1] * mm[2]
            if running > 1 << 56:
                _fail("malformed", "cells.total", "more than 2^56 values")
        total = running
        if n_values_cov != total:
            _fail("malformed", "stream.coverage", "stream 3: %d values, cells need %d" % (n_values_cov, total))
        for h, o, ext, mm in geo:
            for r in range(mm[2]):
                for q in range(mm[1]):
                    for p in range(mm[0]):
                        lo = (o[0] + p * h, o[1] + q * h, o[2] + r * h)
                        boxes.append((lo[0], min(lo[0] + h, o[0] + ext[0]), lo[1], min(lo[1] + h, o[1] + ext[1]),
                                      lo[2], min(lo[2] + h, o[2] + ext[2])))
    if n_values_cov != total:
        _fail("malformed", "stream.coverage", "stream 3: %d values, structure needs %d" % (n_values_cov, total))
    values = gather(3, vw, "I" if vw == 4 else "H")
    dt = NPBITS[ve]
    if sk == 2:
        dense = np.array(values, dtype=dt).reshape((Z, Y, X))
    else:
        dense = np.zeros((Z, Y, X), dtype=dt)
        cover = np.zeros((Z, Y, X), dtype=np.int64)
        for v, (x0, x1, y0, y1, z0, z1) in zip(values, boxes):
            dense[z0:z1, y0:y1, x0:x1] = v
            cover[z0:z1, y0:y1, x0:x1] += 1
        assert (cover == 1).all()
    # levels of detail (§12.3, §8A): plain Python floats, one voxel at a time
    dec = [[[decode(ve, dense[z, y, x]) for x in range(X)] for y in range(Y)] for z in range(Z)]
    lods = {}
    for kk in range(1, D + 1):
        s = 1 << kk
        shape = (ceil_div(Z, s), ceil_div(Y, s), ceil_div(X, s))
        arr = np.zeros(shape, dtype=dt)
        for zc in range(shape[0]):
            for yc in range(shape[1]):
                for xc in range(shape[2]):
                    acc = 0.0
                    n = 0
                    for z in range(zc * s, min(zc * s + s, Z)):
                        for y in range(yc * s, min(yc * s + s, Y)):
                            row = dec[z][y]
                            for x in range(xc * s, min(xc * s + s, X)):
                                acc = acc + row[x]
                                n += 1
                    arr[zc, yc, xc] = encode(ve, acc / n)
        lods[kk] = arr
    # stored levels of detail (§8A.5): decoded; a verifying reader compares
    # them with the levels just computed from full resolution
    for k, blocks in sorted(stored_levels.items()):
        m = tuple(ceil_div(a, 1 << k) for a in size)
        flat = [None] * (m[0] * m[1] * m[2])
        for e in blocks:
            raw = decode_block(data, e, vw)
            flat[e["first"]:e["first"] + e["count"]] = struct.unpack("<%d%s" % (e["count"], "I" if vw == 4 else "H"), raw)
        arr = np.zeros((m[2], m[1], m[0]), dtype=dt)
        for first, (ex, ey, ez), (ox, oy, oz) in bricked_order(m, cell_log2):
            arr[oz:oz + ez, oy:oy + ey, ox:ox + ex] = np.array(flat[first:first + ex * ey * ez],
                                                               dtype=dt).reshape(ez, ey, ex)
        if verify and not np.array_equal(arr, lods[k]):
            _fail("malformed", "lod.value", "level %d" % k)
    return dense, lods, meta


# ------------------------------------------------------------------- the vectors

MANIFEST = []
RAW_TOTAL = [0]


def _write(rel, data):
    p = os.path.join(HERE, rel)
    with open(p, "wb") as fh:
        fh.write(data)
    RAW_TOTAL[0] += len(data)


def raw_bits(arr):
    return arr.astype(arr.dtype.newbyteorder("<")).tobytes()


def add_valid(name, data, src, enc, desc, lods=True, kind=KIND_OCTREE, extra=None):
    D = min_depth(src.shape[2], src.shape[1], src.shape[0])
    rel = "valid/%s.ivol" % name
    _write(rel, data)
    ent = {"file": rel, "expect": "ok", "dense": "valid/%s.dense.raw" % name}
    _write(ent["dense"], raw_bits(src))
    if not lods:
        exp_lods = {}
    elif kind == KIND_OCTREE:
        exp_lods = pyramid_lods(src, enc, D)
    else:
        exp_lods = flat_lods(src, enc, D)
    if exp_lods:
        ent["lod"] = {}
        for k in sorted(exp_lods):
            ent["lod"][str(k)] = "valid/%s.lod%d.raw" % (name, k)
            _write(ent["lod"][str(k)], raw_bits(exp_lods[k]))
    ent["value_encoding"] = ENC_NAME[enc]
    ent["size"] = [src.shape[2], src.shape[1], src.shape[0]]
    ent["structure"] = KIND_NAME[kind]
    ent.update(extra or {})
    ent["description"] = desc
    MANIFEST.append(ent)
    # self-test
    dense, got_lods, _ = read_ivol(data)
    assert dense.dtype == src.dtype and np.array_equal(dense, src), name
    for k, a in exp_lods.items():
        assert np.array_equal(got_lods[k], a), (name, k)


def add_invalid(name, data, expect, tag, desc, verify_only=False, dense_src=None):
    rel = "invalid/%s.ivol" % name
    _write(rel, data)
    ent = {"file": rel, "expect": expect}
    if verify_only:
        ent["expect_without_verify"] = "ok"
        ent["dense"] = "invalid/%s.dense.raw" % name
        _write(ent["dense"], raw_bits(dense_src))
    ent["description"] = desc
    MANIFEST.append(ent)
    try:
        read_ivol(data)
    except IvolError as ex:
        assert ex.cls == expect, (name, ex.cls, ex.tag, str(ex))
        assert tag is None or ex.tag == tag, (name, ex.tag, tag, str(ex))
    else:
        raise AssertionError("%s was accepted" % name)
    if verify_only:
        dense, _, _ = read_ivol(data, verify=False)
        assert np.array_equal(dense, dense_src)


def simple_file(src, enc, meta=None, codec=CODEC_ZSTD, limit=None, meta_codec=None,
                meta_first=False, zcheck=True, tree=None, **kw):
    t = tree or build_tree(src, enc)
    blocks = level_blocks(t, codec, limit, zcheck=zcheck)
    mb = meta_block(meta if meta is not None else DEFAULT_META,
                    codec if meta_codec is None and codec in (0, 1) else (meta_codec or CODEC_ZSTD),
                    zcheck=zcheck)
    if meta_first:
        blocks.insert(0, mb)
    else:
        blocks.append(mb)
    data, lay = assemble(t, blocks, **kw)
    return data, lay, t, blocks


# ---- source volumes

def vol_object_in_air(X, Y, Z, enc, seed, air, centre, radius, lo, hi):
    rng = np.random.default_rng(seed)
    z, y, x = np.mgrid[0:Z, 0:Y, 0:X]
    d2 = (x - centre[0]) ** 2 + (y - centre[1]) ** 2 + (z - centre[2]) ** 2
    inside = d2 <= radius * radius
    if enc == UINT16:
        v = rng.integers(lo, hi, size=(Z, Y, X)).astype(np.uint16)
        a = np.uint16(air)
    else:
        noise = rng.uniform(lo, hi, size=(Z, Y, X))
        v = np.array([[[(f16 if enc == BINARY16 else f32)(q) for q in row] for row in pl] for pl in noise],
                     dtype=NPBITS[enc])
        a = NPBITS[enc]((f16 if enc == BINARY16 else f32)(air))
    return np.where(inside, v, a).astype(NPBITS[enc])


def arr_f16(vals, shape):
    return np.array([f16(v) for v in np.ravel(vals)], dtype=np.uint16).reshape(shape)


def arr_f32(vals, shape):
    return np.array([f32(v) for v in np.ravel(vals)], dtype=np.uint32).reshape(shape)


def sample_source():
    # 3 x 2 x 2 uint16; octant 0 (x < 2) holds 100..106 and 99, the column
    # x = 2 (octant 1) is uniform 301.
    src = np.zeros((2, 2, 3), dtype=np.uint16)
    oct0 = [100, 101, 102, 103, 104, 105, 106, 99]
    for c, v in enumerate(oct0):
        src[(c >> 2) & 1, (c >> 1) & 1, c & 1] = v
    src[:, :, 2] = 301
    return src


def specials_f32():
    """8 x 4 x 4 float32: each 2x2x2 cell of level of detail 1 tests one rule."""
    nan_s = 0x7F800001      # signalling NaN
    nan_neg = 0xFFC00000
    inf, ninf = 0x7F800000, 0xFF800000
    one = f32(1.0)
    ulp = lambda b, n=1: b + n
    maxf = 0x7F7FFFFF
    rng = np.random.default_rng(7)
    cells = [
        [0x80000000] * 8,                              # uniform -0 -> leaf keeps -0
        [0x80000000, 0] * 4,                           # -0 and +0 -> +0
        [inf] + [f32(3.5)] * 7,                        # +inf with finite -> +inf
        [inf, ninf] * 4,                               # inf - inf -> NaN -> 0x7FC00000
        [nan_s] * 8,                                   # uniform signalling NaN -> leaf keeps bits
        [nan_neg] + [one] * 7,                         # NaN with finite -> 0x7FC00000
        [nan_neg] * 8,                                 # uniform negative quiet NaN
        [1, 0] * 4,                                    # mean 2^-150: tie -> even (0)
        [one] * 4 + [ulp(one)] * 4,                    # 1 + 2^-24: tie -> 1.0 (even)
        [ulp(one)] * 4 + [ulp(one, 2)] * 4,            # 1 + 3*2^-24: tie -> 1 + 2^-22 (even)
        [maxf] * 4 + [maxf - 1] * 4,                   # tie at the top -> maxf - 1 (even)
        [f32(v) for v in rng.normal(5, 2, 8)],
        [f32(v) for v in rng.normal(-1e-3, 1e-3, 8)],
        [int(v) for v in rng.integers(1, 0x00800000, 8)],   # subnormals
        [f32(v) for v in rng.uniform(1e30, 3e38, 8)],
        [f32(2.0)] * 8,
    ]
    src = np.zeros((4, 4, 8), dtype=np.uint32)
    # cells 0..7 (NaN, inf, zeros) in x < 4, cells 8..15 (finite) in x >= 4, so
    # that the level-of-detail-2 cell of x >= 4 holds a finite average
    a = b = 0
    for k in range(2):
        for j in range(2):
            for i in range(4):
                if i < 2:
                    cell = cells[a]
                    a += 1
                else:
                    cell = cells[8 + b]
                    b += 1
                for c in range(8):
                    src[2 * k + ((c >> 2) & 1), 2 * j + ((c >> 1) & 1), 2 * i + (c & 1)] = cell[c]
    return src


def specials_f16():
    inf, ninf = 0x7C00, 0xFC00
    one = 0x3C00
    cells = [
        [0x8000] * 8,                                  # uniform -0
        [0x8000, 0] * 4,                               # -0 and +0 -> +0
        [inf] + [f16(3.5)] * 7,                        # +inf -> +inf
        [inf, ninf] * 4,                               # NaN -> 0x7E00
        [0x7C01] * 8,                                  # uniform signalling NaN
        [0xFE00] + [one] * 7,                          # NaN -> 0x7E00
        [0x7FFF] * 8,                                  # uniform NaN, all payload bits
        [1, 0] * 4,                                    # mean 2^-25: tie -> 0
        [one] * 4 + [one + 1] * 4,                     # tie -> 1.0
        [one + 1] * 4 + [one + 2] * 4,                 # tie -> one + 2
        [0x7BFF] * 4 + [0x7BFE] * 4,                   # 65504/65472: tie -> 65472
        [1, 3, 1, 3, 2, 2, 2, 3],                      # subnormal mean 17/8 * 2^-24 -> 2 (2^-23)
        [0x0001] * 7 + [0x03FF],                       # subnormal, not a tie
        [f16(v) for v in (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8)],
        [0x03FF, 0x0400] * 4,                          # largest subnormal / smallest normal: tie -> 0x0400
        [f16(-2.0)] * 8,
    ]
    src = np.zeros((4, 4, 8), dtype=np.uint16)
    a = b = 0
    for k in range(2):
        for j in range(2):
            for i in range(4):
                if i < 2:
                    cell = cells[a]
                    a += 1
                else:
                    cell = cells[8 + b]
                    b += 1
                for c in range(8):
                    src[2 * k + ((c >> 2) & 1), 2 * j + ((c >> 1) & 1), 2 * i + (c & 1)] = cell[c]
    return src


def ties_uint16():
    """3 x 3 x 3 uint16 whose level-of-detail-1 cells of weight 8, 4 and 2
    have means exactly halfway between two integers."""
    src = np.zeros((3, 3, 3), dtype=np.uint16)
    base = [1000, 2001, 3002, 4003, 5004, 6005, 7006, 8007]
    for c in range(8):
        i, j, k = c & 1, (c >> 1) & 1, (c >> 2) & 1
        cells = [(x, y, z) for z in range(2 * k, min(2 * k + 2, 3))
                 for y in range(2 * j, min(2 * j + 2, 3)) for x in range(2 * i, min(2 * i + 2, 3))]
        for n, (x, y, z) in enumerate(cells):
            # half of the voxels base, half base + 1 -> mean base + 0.5
            src[z, y, x] = base[c] + (n % 2) if len(cells) > 1 else base[c]
    return src


METADATA_FULL = r'''{
  "voxel_size": [0.0125, 0.0125, 2.5e-2],
  "unit": "mm",
  "origin": [-12.5, 0.325, 0],
  "value": {"quantity": "linear_attenuation", "unit": "1/mm"},
  "structure": {
    "kind": "octree",
    "lossless": true,
    "keep": {"rule": "threshold", "threshold": 0.01, "margin": 4},
    "source_encoding": "float32",
    "max_abs_error": 0.0
  },
  "provenance": {
    "software": {"name": "ivol-conformance-vectors", "version": "1.0.0"},
    "created": "2026-11-22T15:00:00Z",
    "sources": [
      {"path": "/data/scans/Prüfkörper_α/projections_0001.tif", "bytes": 8388608,
       "sha256": "9f86d081884c7d659a2feaa0c55ad015a3bf4f1b2b0b822cd15d6c15b0f00a08"}
    ],
    "geometry": {"source_isocentre": 250.0, "source_detector": 1000.0,
                 "detector": {"pixels": [2048, 2048], "pitch": 0.2},
                 "angles": {"start": 0, "step": 0.25, "count": 1440}},
    "reconstruction": {"algorithm": "FDK", "filter": "Shepp-Logan", "window": [0.0, 0.05]},
    "command": "ivol convert --keep threshold=0.01 \"Prüfkörper α.raw\" out.ivol"
  },
  "user": {
    "operator": "Zoë Łukasiewicz",
    "site": "東京ラボ",
    "note": "µ-CT, Ω ≈ 3 \u2013 escaped dash; emoji 🧪 raw and \ud83e\uddea escaped; tab\tquote\" backslash\\",
    "tags": ["α", "β", null, true, false, -1e-3, 12345678901234567890],
    "nested": {"empty_object": {}, "empty_array": [], "deep": {"deeper": {"deepest": "✓"}}},
    "unknown_keys_are_ignored": {"x": 1}
  },
  "future_top_level_key": {"readers": "must ignore unknown keys"}
}
'''


def gen():
    # ------------------------------------------------------------------ valid
    # 1x1x1
    src = arr_f32([0.1], (1, 1, 1))
    d, *_ = simple_file(src, FLOAT32, codec=CODEC_STORED)
    add_valid("tiny_1x1x1_float32", d, src, FLOAT32,
              "1x1x1 float32 (value 0.1f): depth 0, level table [0], empty node array, one value, "
              "two blocks (values, metadata), stored codec.")

    # 3x5x7 uint16 with scale and offset
    rng = np.random.default_rng(101)
    src = rng.integers(0, 4096, size=(7, 5, 3)).astype(np.uint16)
    src[0:2, 0:2, 0:2] = 777          # a uniform 2x2x2 cell -> leaf at level 2
    src[4:7, 4:5, 0:3] = 1234         # a uniform region partly padding -> leaf at level 1
    src[2:4, 2:4, 2:3] = 55           # uniform non-padding part of a cell -> leaf
    src3 = src
    d, *_ = simple_file(src, UINT16, scale=0.0007, offset=-1.25)
    add_valid("odd_3x5x7_uint16", d, src, UINT16,
              "3x5x7 uint16 (x=3, y=5, z=7), depth 3, value_scale 0.0007 and value_offset -1.25, zstd; "
              "random values with uniform regions (leaves at levels 1 and 2, some partly padding).")

    # 257 x 1 x 2 binary16
    x = np.arange(257)
    vals = np.zeros((2, 1, 257))
    rng = np.random.default_rng(102)
    vals[0, 0, :] = x / 16.0 + rng.uniform(0, 0.01, 257)
    vals[1, 0, :] = 100.0 - x / 8.0
    vals[:, :, 128:256] = 2.5         # a uniform run
    src = arr_f16(vals, (2, 1, 257))
    d, *_ = simple_file(src, BINARY16)
    add_valid("line_257x1x2_binary16", d, src, BINARY16,
              "257x1x2 binary16, depth 9 (2^9 = 512 >= 257): mostly padding, held at the coarsest "
              "level; a uniform run x = 128..255 becomes one leaf of side 128 covering padding too.")

    # 2x2x2
    src = arr_f16([0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8], (2, 2, 2))
    d, *_ = simple_file(src, BINARY16, codec=CODEC_STORED)
    add_valid("cube_2x2x2_binary16", d, src, BINARY16,
              "2x2x2 binary16 0.1 .. 0.8 (x fastest), depth 1, level table [1, 0], stored codec.")

    # 16^3 noise
    rng = np.random.default_rng(103)
    src = arr_f16(rng.uniform(-4.0, 4.0, 16 ** 3), (16, 16, 16))
    d, _, t, _ = simple_file(src, BINARY16, codec="auto")
    assert t.inner_count == [1, 8, 64, 512, 0]
    add_valid("noise_16_binary16", d, src, BINARY16,
              "16^3 binary16 uniform random noise: fully refined octree, level table [1, 8, 64, 512, 0]; "
              "codec chosen per block (zstd when smaller, else stored).")

    # uniform
    src = np.full((20, 20, 20), f32(0.5), dtype=np.uint32)
    d, _, t, _ = simple_file(src, FLOAT32)
    assert t.inner_count == [0] * 6 and len(t.values) == 1
    add_valid("uniform_20_float32", d, src, FLOAT32,
              "20^3 float32 all 0.5: depth 5, the root is one leaf, level table all zero, "
              "no node blocks, value array of one element (zstd).")

    # sphere in air
    src = vol_object_in_air(40, 33, 29, BINARY16, 104, 0.0015, (19.5, 15.0, 13.0), 11.0, 0.9, 1.1)
    d, _, t, _ = simple_file(src, BINARY16, limit=4096)
    add_valid("sphere_40x33x29_binary16", d, src, BINARY16,
              "40x33x29 binary16: sphere (radius 11) of noise 0.9..1.1 in uniform air 0.0015; depth 6; "
              "air and padding as large leaves; zstd; blocks limited to 4096 decoded bytes.")

    # float32 mixed
    rng = np.random.default_rng(105)
    z, y, x = np.mgrid[0:9, 0:10, 0:12]
    vals = 0.01 * x + 0.1 * y - 0.05 * z + rng.normal(0, 1e-4, (9, 10, 12))
    vals[0:4, 0:8, 0:8] = -7.25
    vals[4:9, 8:10, 8:12] = 3.0e-41    # subnormal float32, uniform, partly padding
    src = arr_f32(vals, (9, 10, 12))
    d, *_ = simple_file(src, FLOAT32, codec=CODEC_ZSTD)
    add_valid("gradient_12x10x9_float32", d, src, FLOAT32,
              "12x10x9 float32: gradient with noise, a uniform region -7.25 (one leaf of side 8 with "
              "padding) and a uniform subnormal region; zstd; depth 4.")

    # multiblock
    src = vol_object_in_air(24, 20, 18, UINT16, 106, 300, (11.0, 10.0, 9.0), 7.5, 20000, 40000)
    d, _, t, blocks = simple_file(src, UINT16, codec="alt", limit=48, meta_first=True,
                                  scale=2.0 ** -12, offset=-1.0)
    per_level = {}
    for b in blocks:
        per_level[(b.stream, b.level)] = per_level.get((b.stream, b.level), 0) + 1
    assert max(per_level.values()) >= 3
    add_valid("multiblock_24x20x18_uint16", d, src, UINT16,
              "24x20x18 uint16 ball in air, blocks limited to 48 decoded bytes (24 values or 6 node "
              "words), so most levels have several blocks of each stream; codecs alternate "
              "stored/zstd; the metadata block comes first in the file.")

    # shuffled block order
    t = build_tree(src3, UINT16)
    bl = level_blocks(t, CODEC_ZSTD, limit=8)
    bl.append(meta_block(DEFAULT_META))
    bl = bl[::-1]
    bl = bl[1:4] + bl[:1] + bl[4:]          # metadata somewhere in the middle
    d, _ = assemble(t, bl, scale=0.0007, offset=-1.25)
    add_valid("shuffled_blocks_3x5x7_uint16", d, src3, UINT16,
              "Same volume as odd_3x5x7_uint16, blocks of at most 8 decoded bytes written in reverse "
              "order with the metadata block among them: the spec fixes no file order of blocks, "
              "only that each stream's blocks, taken in order of first_element, tile it.")

    # base volume for extension tests and invalid files
    BASE = vol_object_in_air(6, 5, 4, UINT16, 107, 100, (2.0, 2.0, 1.5), 2.2, 1000, 2000)

    # unknown ignorable stream
    t = build_tree(BASE, UINT16)
    bl = level_blocks(t, CODEC_ZSTD)
    ext = Blk(200, 0, 0, 24, b"future stream, skip me\x00\x01", codec=CODEC_STORED, flags=1)
    bl.insert(2, ext)
    bl.append(meta_block(DEFAULT_META))
    d, _ = assemble(t, bl)
    add_valid("ignorable_stream_200", d, BASE, UINT16,
              "6x5x4 uint16 with an extra block of unknown stream 200, ignorable flag set (flags = 1), "
              "stored codec, 24 one-byte elements, between the level blocks: a reader must skip it.")

    # optional features
    d, *_ = simple_file(BASE, UINT16, optional=(1 << 0) | (1 << 17) | (1 << 63))
    add_valid("optional_features_unknown", d, BASE, UINT16,
              "optional_features = bits 0, 17 and 63 set (unknown to 1.0 - 1.2): a reader must ignore them.")

    # minor version 1.7 with bigger header, fixed part and entries
    t = build_tree(BASE, UINT16)
    bl = level_blocks(t, CODEC_ZSTD, limit=16)
    bl.append(meta_block(DEFAULT_META))
    d, _ = assemble(t, bl, minor=7, header_extra=bytes(range(0xA0, 0xB0)),
                    fixed_extra=b"FUTURE-FIXED-FIELDS-1.7" + bytes(9),
                    entry_extra=b"\xEE\xDD\xCC\xBB\xAA\x99\x88\x77")
    assert u32(d, 12) == 56
    add_valid("minor_1_7_extended", d, BASE, UINT16,
              "version 1.7: header_size 56 (16 unknown non-zero bytes at 36..52, header_crc at 52), "
              "fixed_size 80 (32 unknown bytes at 48..80, level table at 80), block_entry_size 40 "
              "(8 unknown bytes per entry). A 1.0, 1.1 or 1.2 reader must skip the extra bytes.")

    MINOR17 = d
    # the largest header, fixed part and block entries a reader must accept
    src = arr_f32([-3.75], (1, 1, 1))
    t = build_tree(src, FLOAT32)
    bl = level_blocks(t, CODEC_STORED)
    bl.append(meta_block(DEFAULT_META, CODEC_STORED))
    pat = lambda nb, s0: bytes((s0 + q) % 251 for q in range(nb))
    d, _ = assemble(t, bl, minor=3, header_extra=pat(4056, 1), fixed_extra=pat(4048, 2),
                    entry_extra=pat(4064, 3))
    assert u32(d, 12) == 4096
    add_valid("limits_4096", d, src, FLOAT32,
              "1x1x1 float32, version 1.3, with header_size, fixed_size and block_entry_size all 4096 "
              "(the largest a reader must accept), the unknown bytes filled with a non-zero pattern. "
              "(version_minor was 1 in the 1.0 vectors and 2 in the 1.1 vectors; 1.1 and 1.2 define "
              "minor 1 and 2 without any extension bytes, so the file now claims a later minor version, 3.)")

    # metadata with all keys
    text = METADATA_FULL.encode("utf-8")
    json.loads(text.decode("utf-8"))
    d, *_ = simple_file(BASE, UINT16, meta=text)
    add_valid("metadata_full_utf8", d, BASE, UINT16,
              "Metadata with every key of §11 (structure, provenance with all keys, user), non-ASCII "
              "UTF-8 (2-, 3- and 4-byte sequences), \\u escapes incl. a surrogate pair, a big integer, "
              "and unknown keys that must be ignored; pretty-printed with a trailing newline.")

    # metadata nested exactly 128 deep (§11): the top-level object, "user" and 126 arrays
    m = dict(DEFAULT_META)
    m["user"] = {"deep": json.loads("[" * 126 + "]" * 126)}
    text = meta_bytes(m)
    d, *_ = simple_file(BASE, UINT16, meta=text)
    add_valid("metadata_depth_128", d, BASE, UINT16,
              "Metadata whose arrays and objects nest 128 deep, the limit of §11: the top-level object, "
              "the object \"user\" and 126 nested arrays.")

    # sample
    src = sample_source()
    d, lay, t, bl = simple_file(src, UINT16, codec=CODEC_STORED, scale=0.5, offset=-1024.0,
                                meta={"voxel_size": [0.1, 0.1, 0.1], "unit": "mm",
                                      "origin": [0, 0, 0], "value": {"quantity": "grey_value"}})
    assert t.inner_count == [1, 1, 0] and t.values[0] == 169
    add_valid("sample", d, src, UINT16,
              "The annotated sample of §16: 3x2x2 uint16, scale 0.5, offset -1024, stored codec, "
              "6 blocks. Root average 169 = encode((8 * 102.5 + 4 * 301) / 12 = 168.67); averaging the "
              "stored child value 102 instead would give 168.")
    SAMPLE = (src, d, lay, t, bl)

    # specials
    src = specials_f32()
    d, *_ = simple_file(src, FLOAT32)
    add_valid("specials_8x4x4_float32", d, src, FLOAT32,
              "float32 special values, one 2x2x2 cell per case: uniform -0 (a leaf keeps -0), -0/+0 mix "
              "(average +0), +inf, inf-inf (NaN stored 0x7FC00000), uniform signalling NaN 0x7F800001 and "
              "negative NaN 0xFFC00000 (leaves keep their bits), NaN mixed, subnormal tie 2^-150 -> 0, "
              "ties to even at 1+2^-24, 1+3*2^-24 and FLT_MAX-ulp/2, subnormals, huge values.")
    src = specials_f16()
    d, *_ = simple_file(src, BINARY16)
    add_valid("specials_8x4x4_binary16", d, src, BINARY16,
              "binary16 special values, one 2x2x2 cell per case: uniform -0, -0/+0, +inf, inf-inf -> 0x7E00, "
              "uniform NaN 0x7C01 and 0x7FFF (kept), NaN mixed -> 0x7E00, ties to even (2^-25 -> 0, "
              "1+2^-11 -> 1, 65488 -> 65472, subnormal/normal boundary), subnormal means.")

    src = ties_uint16()
    d, *_ = simple_file(src, UINT16, codec=CODEC_STORED, scale=0.001, offset=0.0)
    add_valid("ties_3x3x3_uint16", d, src, UINT16,
              "3x3x3 uint16: every level-of-detail-1 cell of weight 8, 4 or 2 has a mean exactly "
              "halfway between two integers (base + 0.5, bases even and odd): round half to even.")

    # zstd without content checksum
    d, *_ = simple_file(BASE, UINT16, zcheck=False)
    add_valid("zstd_no_checksum", d, BASE, UINT16,
              "All blocks zstd frames without the (optional) content checksum.")

    # metadata of exactly 16 MiB
    small = arr_f16([1, 2, 3, 4, 5, 6, 7, 8], (2, 2, 2))
    text = meta_bytes(DEFAULT_META)
    text = text + b" " * (MIB16 - len(text))
    d, *_ = simple_file(small, BINARY16, meta=text)
    add_valid("metadata_16mib", d, small, BINARY16,
              "2x2x2 binary16 whose metadata is exactly 16 MiB (16 777 216 bytes: JSON followed by "
              "spaces), zstd-compressed: the largest allowed metadata.")

    # ---------------------------------------------------------------- invalid
    base, blay, bt, bblocks = simple_file(BASE, UINT16)
    n = len(base)
    # values block of level 2 index / nodes
    vblk = [i for i, b in enumerate(bblocks) if b.stream == 3 and b.level == 2][0]
    nblk1 = [i for i, b in enumerate(bblocks) if b.stream == 2 and b.level == 1][0]
    mblk = len(bblocks) - 1
    assert bt.inner_count[1] >= 2 and bt.inner_count[2] >= 1, bt.inner_count

    def inv(name, data, expect, tag, desc, **kw):
        add_invalid(name, data, expect, tag, desc, **kw)

    # not-ivol / truncated signatures
    inv("sig_png", b"\x89PNG\r\n\x1a\n" + base[8:], "not-ivol", "signature",
        "Signature replaced by the PNG signature.")
    inv("sig_crlf_to_lf", base.replace(b"\r\n", b"\n"), "not-ivol", "signature",
        "The whole file after CRLF->LF conversion (signature becomes 89 49 56 4F 4C 0A 0A ..).")
    inv("sig_lf_to_crlf", base[:7] + b"\r\n" + base[8:], "not-ivol", "signature",
        "The lone LF of the signature converted to CRLF.")
    inv("sig_high_bit_stripped", bytes([base[0] & 0x7F]) + base[1:], "not-ivol", "signature",
        "First byte 0x09 instead of 0x89 (7-bit channel).")
    inv("sig_short_other", b"GIF89", "not-ivol", "signature",
        "5-byte file that is not a prefix of the signature.")
    inv("trunc_empty", b"", "truncated", "short.signature",
        "Empty file (its 0 bytes equal the start of the signature, §13 step 1).")
    inv("trunc_5", base[:5], "truncated", "short.signature", "First 5 bytes of a valid file.")
    inv("trunc_11", base[:11], "truncated", "short.version",
        "First 11 bytes (version_major = 1 readable, but shorter than 12 bytes).")
    inv("trunc_30", base[:30], "truncated", "short.file",
        "First 30 bytes (shorter than header_size + 32).")
    inv("trunc_header_only", base[:40], "truncated", "short.file", "Only the 40-byte header.")
    inv("trunc_71", base[:71], "truncated", "short.file",
        "71 bytes: one byte short of header_size + 32.")
    mid = blay.block_offsets[vblk] + 3
    inv("trunc_mid_block", base[:mid], "truncated", "end_signature",
        "Cut in the middle of a values block.")
    inv("trunc_mid_index", base[:blay.index_offset + 20], "truncated", "end_signature",
        "Cut inside the index.")
    inv("trunc_no_footer", base[:n - 32], "truncated", "end_signature", "Footer missing entirely.")
    inv("trunc_in_footer_20", base[:n - 20], "truncated", "end_signature",
        "Last 20 bytes missing (cut inside the footer).")
    inv("trunc_last_byte", base[:n - 1], "truncated", "end_signature", "Last byte missing.")
    inv("appended_zeros", base + bytes(16), "truncated", "end_signature",
        "16 zero bytes appended after the footer.")
    inv("appended_text", base + b"\r\n", "truncated", "end_signature",
        "CRLF appended after the footer (e.g. by a text tool).")
    inv("concatenated_twice", base + base, "malformed", "index_range",
        "The file twice in a row: it ends with a valid footer (end_signature and footer_crc good), "
        "but index_offset + index_size + 32 != file size (§13 step 4) -> malformed, not truncated.")

    # versions
    inv("version_major_2", reseal(patch(base, 8, "<H", 2), index=False), "unsupported-version",
        "version_major", "version_major = 2 (header CRC recomputed).")
    inv("version_major_0", reseal(patch(base, 8, "<H", 0), index=False), "unsupported-version",
        "version_major", "version_major = 0 (header CRC recomputed).")
    v2 = SIG + struct.pack("<HHI", 2, 0, 100000) + b"a future format, nothing of 1.0 holds" * 2
    inv("version_major_2_other_layout", v2, "unsupported-version", "version_major",
        "version_major = 2 followed by data laid out differently (header_size 100000, no footer): "
        "the version is checked before anything else of the header.")
    inv("version_major_2_bad_crc", patch(base, 8, "<H", 2), "unsupported-version", "version_major",
        "version_major = 2 with the old (now wrong) header CRC: the version is checked first.")

    # header
    inv("header_size_39", reseal(patch(base, 12, "<I", 39), header=False, index=False), "malformed",
        "header_size", "header_size = 39 (< 40).")
    inv("header_size_4097", patch(base, 12, "<I", 4097), "malformed", "header_size",
        "header_size = 4097 (> 4096).")
    inv("header_size_beyond_file", reseal(patch(base, 12, "<I", n), header=False, index=False),
        "truncated", "short.file",
        "header_size = file size (in 40..4096, but file size < header_size + 32).")
    d = bytearray(MINOR17)
    d[45] ^= 0x01
    inv("minor_1_7_header_extra_flipped", bytes(d), "checksum", "header_crc",
        "The 1.7 file of valid/minor_1_7_extended.ivol with one of the unknown header bytes (offset 45) "
        "changed: they are covered by header_crc.")
    inv("header_crc_bad", patch(base, 36, "<I", u32(base, 36) ^ 0x00010000), "checksum", "header_crc",
        "header_crc with one bit flipped.")
    inv("header_byte_flipped", patch(base, 26, "<B", base[26] ^ 0x20), "checksum", "header_crc",
        "One byte of optional_features changed without updating header_crc.")
    inv("header_reserved_nonzero", reseal(patch(base, 32, "<I", 1), index=False), "malformed",
        "header.reserved", "Header reserved field (offset 32) = 1, header CRC recomputed.")
    inv("required_feature_bit1", reseal(patch(base, 16, "<Q", 2), index=False), "unsupported-feature",
        "required_features", "required_features bit 1 set (unknown in 1.0 - 1.3), header CRC recomputed.")
    inv("framed_header_size_40", reseal(patch(base, 16, "<Q", 1), index=False), "malformed",
        "framed.header_size", "required_features bit 0 (framed_blocks, 1.3) set in a 40-byte header: "
        "no room for the volume descriptor (§4.1); header CRC recomputed.")
    inv("required_feature_bit63", reseal(patch(base, 16, "<Q", 1 << 63), index=False),
        "unsupported-feature", "required_features", "required_features bit 63 set.")
    inv("order_reserved_before_required", reseal(patch(patch(base, 16, "<Q", 2), 32, "<I", 7), index=False),
        "malformed", "header.reserved",
        "Check order (§13 step 3): reserved header field non-zero AND unknown required feature: "
        "reserved fields are checked first -> malformed.")

    # footer
    f = n - 32
    inv("footer_crc_bad", patch(base, f + 20, "<I", u32(base, f + 20) ^ 1), "checksum", "footer_crc",
        "footer_crc with one bit flipped.")
    inv("footer_index_offset_flipped", patch(base, f, "<Q", u64(base, f) ^ 0x100), "checksum",
        "footer_crc", "A byte of index_offset changed, footer_crc not updated: footer_crc is checked "
        "before the range of index_offset.")
    inv("end_signature_bad", patch(base, n - 1, "<B", ord("d")), "truncated", "end_signature",
        "end_signature 'IVOL_ENd': a file that does not end with end_signature is 'truncated'.")
    inv("index_offset_below_header", reseal(patch(base, f, "<QQ", 8, n - 32 - 8), header=False,
                                            index=False), "malformed", "index_range",
        "index_offset = 8 (< header_size) with index_size = file size - 40 so that the sum rule holds; "
        "footer_crc recomputed.")
    inv("index_offset_plus_1", reseal(patch(base, f, "<Q", blay.index_offset + 1), header=False,
                                      index=False), "malformed", "index_range",
        "index_offset one too large (index_offset + index_size + 32 != file size); footer_crc recomputed.")
    io_big = (1 << 64) - 16
    isz_wrap = (n - 32 - io_big) % (1 << 64)
    inv("index_offset_wraps", reseal(patch(base, f, "<QQ", io_big, isz_wrap), header=False,
                                     index=False), "malformed", "index_range",
        "index_offset = 2^64 - 16 and index_size chosen so that index_offset + index_size + 32 equals "
        "the file size modulo 2^64: the sum must be computed without overflow.")
    inv("index_size_plus_8", reseal(patch(base, f + 8, "<Q", blay.index_size + 8), header=False,
                                    index=False), "malformed", "index_range",
        "index_size 8 too large; footer_crc recomputed.")
    d = patch(base, f + 16, "<I", u32(base, f + 16) ^ 0x80000000)
    d = reseal(d, header=False, index=False)
    inv("index_crc_bad", d, "checksum", "index_crc",
        "index_crc with one bit flipped, footer_crc recomputed over it: the index CRC is the first failure.")
    inv("index_byte_flipped", patch(base, blay.index_offset + blay.entries_offset + 20,
                                    "<B", base[blay.index_offset + blay.entries_offset + 20] ^ 4),
        "checksum", "index_crc", "A byte of the block table changed without updating index_crc.")

    # index fixed part
    def pix(rel, fmt, *v):
        return patch_index(base, blay, rel, fmt, *v)

    inv("index_signature_bad", pix(0, "<4s", b"IVIY"), "malformed", "index_signature",
        "index_signature 'IVIY' (CRCs recomputed).")
    inv("fixed_size_47", pix(4, "<I", 47), "malformed", "fixed_size", "fixed_size = 47 (< 48).")
    inv("structure_kind_9", pix(8, "<B", 9), "unsupported-feature", "structure_kind",
        "structure_kind = 9 (unknown; was structure_kind_2 in the 1.0 vectors, but 1.1 made 2 the "
        "regular grid).")
    inv("structure_kind_0", pix(8, "<B", 0), "unsupported-feature", "structure_kind",
        "structure_kind = 0 (not defined: 'other values').")
    inv("value_encoding_4", pix(9, "<B", 4), "unsupported-feature", "value_encoding",
        "value_encoding = 4 (unknown).")
    inv("value_encoding_0", pix(9, "<B", 0), "unsupported-feature", "value_encoding",
        "value_encoding = 0 (not defined).")
    inv("index_reserved_nonzero", pix(11, "<B", 1), "malformed", "index.reserved",
        "Octree file (structure_kind 1) with index byte 11 = 1: since 1.1 the byte is cell_log2 "
        "for structure_kind 4 only and stays reserved (0) for the other kinds.")
    inv("size_x_zero", pix(12, "<I", 0), "malformed", "size", "size_x = 0 (depth still matches max(size)).")
    inv("value_scale_zero", pix(24, "<d", 0.0), "malformed", "value_scale", "value_scale = 0.")
    inv("value_scale_nan", pix(24, "<Q", 0x7FF8000000000000), "malformed", "value_scale",
        "value_scale = NaN.")
    inv("value_offset_inf", pix(32, "<d", math.inf), "malformed", "value_offset", "value_offset = +inf.")
    inv("block_entry_size_31", pix(44, "<I", 31), "malformed", "block_entry_size",
        "block_entry_size = 31 (< 32).")
    inv("fixed_size_4097", pix(4, "<I", 4097), "malformed", "fixed_size", "fixed_size = 4097 (> 4096).")
    inv("block_entry_size_4097", pix(44, "<I", 4097), "malformed", "block_entry_size",
        "block_entry_size = 4097 (> 4096).")
    inv("block_count_huge", pix(40, "<I", 0xFFFFFFFF), "malformed", "index_size",
        "block_count = 2^32 - 1: the index_size rule fails; a reader must not allocate 2^32 entries "
        "before checking it.")
    inv("block_count_wrong", pix(40, "<I", len(bblocks) + 1), "malformed", "index_size",
        "block_count one larger than the entries present (index_size rule broken).")
    d, _ = assemble(bt, bblocks, index_tail=bytes(8))
    inv("index_trailing_bytes", d, "malformed", "index_size",
        "8 extra bytes at the end of the index (index_size = fixed_size + 8(D+1) + "
        "block_count*block_entry_size + 8).")
    # depth
    t4 = build_tree(BASE, UINT16, depth=4)
    bl = level_blocks(t4, CODEC_ZSTD)
    bl.append(meta_block(DEFAULT_META))
    d, _ = assemble(t4, bl)
    inv("depth_not_minimal", d, "malformed", "depth",
        "6x5x4 volume stored with depth 4 instead of 3; the octree, level table, blocks and averages "
        "are otherwise consistent for depth 4.")
    # level table
    ic = bt.inner_count
    D = bt.D
    assert D == 3
    lt_off = blay.level_table_offset
    inv("level_table_root_2", pix(lt_off, "<Q", 2), "malformed", "level_table",
        "inner_count[0] = 2.")
    inv("level_table_last_nonzero", pix(lt_off + 8 * D, "<Q", 1), "malformed", "level_table",
        "inner_count[D] = 1.")
    inv("level_table_growth", pix(lt_off + 8, "<QQ", 9, ic[2] + ic[1] - 9), "malformed", "level_table",
        "inner_count[1] = 9 > 8 * inner_count[0] (total_inner unchanged).")
    inv("level_table_zero_then_nonzero", pix(lt_off, "<QQ", 0, ic[1] + ic[0]), "malformed", "level_table",
        "inner_count[0] = 0 but inner_count[1] > 0.")
    huge = [min(8 ** l, 1 << 63) for l in range(31)] + [0]
    assert sum(huge) >= 1 << 64
    d, _ = assemble(bt, bblocks, size=(1 << 31, 5, 4), depth=31, level_table=huge)
    inv("level_table_overflow", d, "malformed", None,
        "size_x = 2^31, depth 31 and a level table that obeys its rules, inner_count[l] = min(8^l, "
        "2^63), whose sum exceeds 2^64: total_inner and total_values must not wrap around; the blocks "
        "present cannot cover the streams (block level / coverage rules) -> malformed.")

    # block table
    def pen(nb, field, fmt, v):
        return pix(entry_off(blay, nb, field) - 0, fmt, v)

    inv("block_flags_reserved_bit", pen(vblk, "flags", "<B", 2), "malformed", "block.flags",
        "A values block with flags bit 1 (reserved) set.")
    inv("block_ignorable_on_values", pen(vblk, "flags", "<B", 1), "malformed", "block.flags",
        "A values block (stream 3) with the ignorable flag: streams 1-5 (1-3 in 1.0) must have flags = 0.")
    inv("block_first_offset_wrong", pen(0, "file_offset", "<Q", 0), "malformed", "block.placement",
        "First block entry file_offset = 0 instead of header_size.")
    inv("block_offset_plus_1", pen(vblk, "file_offset", "<Q", blay.block_offsets[vblk] + 1), "malformed",
        "block.placement", "One block's file_offset one too large (blocks do not tile the file).")
    d, _ = assemble(bt, bblocks, gap_before_index=b"\x00GAP")
    inv("block_gap_before_index", d, "malformed", "block.placement",
        "4 bytes between the last block and the index (index_offset includes them): the last block "
        "does not end at index_offset.")
    inv("block_stored_size_plus_1", pen(vblk, "stored_size", "<I", len(bblocks[vblk].stored_bytes()) + 1),
        "malformed", "block.placement",
        "A block's stored_size one too large: the next block does not start where it ends.")
    for unknown in (7, 255):
        bl = level_blocks(bt, CODEC_ZSTD)
        bl.append(meta_block(DEFAULT_META))
        bl[vblk].codec = unknown
        bl[vblk].stored = bl[vblk].data
        d, _ = assemble(bt, bl)
        inv("codec_%d" % unknown, d, "unsupported-feature", "codec",
            "A values block with codec %d (unknown: 1.3 defines 0 to 6); its stored bytes are the "
            "raw values, CRC correct.%s" % (unknown, " (Was codec_6 in the earlier 1.3 drafts, codec_5 "
                                           "before codec 6, codec_4 before codec 5, codec_3 up to 1.2, "
                                           "codec_2 in the 1.0 and 1.1 vectors: 1.2 made codec 2 zstd over "
                                           "byte planes, 1.3 codec 3 predicted 16-bit, codec 4 masked "
                                           "16-bit, codec 5 byte planes a zstd frame each and codec 6 the "
                                           "top byte in context.)" if unknown == 7 else ""))
    bl = level_blocks(bt, CODEC_ZSTD)
    bl.append(meta_block(DEFAULT_META))
    bl[vblk].codec = CODEC_TOP_BYTE
    bl[vblk].stored = bl[vblk].data
    d, _ = assemble(bt, bl)
    inv("codec6_raw_values", d, "malformed", "codec6.where",
        "The file that was codec_6 before 1.3 defined codec 6: an octree values block with codec 6 whose "
        "stored bytes are the raw values, CRC correct. Codec 6 is now the top byte in context (§7.4), valid "
        "only on a bricked grid's bricks: malformed.")
    bl = level_blocks(bt, CODEC_ZSTD)
    bl.append(meta_block(DEFAULT_META))
    bl[vblk].codec = CODEC_FRAMES
    bl[vblk].stored = bl[vblk].data
    d, _ = assemble(bt, bl)
    inv("codec5_raw_values", d, "malformed", "zstd.frame",
        "The file that was codec_5 before 1.3 defined codec 5: a values block with codec 5 whose stored "
        "bytes are the raw values, CRC correct. Codec 5 is now byte planes, a zstd frame each (§7), and "
        "these bytes are no zstd frame: malformed.")
    bl = level_blocks(bt, CODEC_ZSTD)
    bl.append(meta_block(DEFAULT_META))
    bl[vblk].codec = CODEC_PREDICTED
    bl[vblk].stored = bl[vblk].data
    d, _ = assemble(bt, bl)
    inv("octree_with_codec3", d, "malformed", "codec3.where",
        "An octree values block with codec 3 (predicted 16-bit), which 1.3 allows only on the bricks of "
        "a bricked grid (§7); its stored bytes are the raw values, CRC correct.")
    bl = level_blocks(bt, CODEC_ZSTD)
    bl.append(meta_block(DEFAULT_META))
    zb = Blk(STREAM_VALUES, 2, bt.first_value[2], 0, b"", codec=CODEC_ZSTD)
    bl.insert(vblk, zb)
    d, _ = assemble(bt, bl)
    inv("block_element_count_zero", d, "malformed", "block.sizes",
        "An extra values block with element_count = 0 (a zstd frame of empty content) at the start of "
        "level 2; coverage of the stream is otherwise exact.")
    bl = level_blocks(bt, CODEC_ZSTD)
    bl.append(meta_block(DEFAULT_META))
    bl.insert(2, Blk(200, 0, 0, 16, b"must understand!", codec=CODEC_STORED, flags=0))
    d, _ = assemble(bt, bl)
    inv("stream_200_not_ignorable", d, "unsupported-feature", "stream",
        "An extra block of unknown stream 200 without the ignorable flag.")
    bl = level_blocks(bt, CODEC_ZSTD)
    d, _ = assemble(bt, bl)
    inv("metadata_missing", d, "malformed", "metadata.count", "No block of stream 1.")
    bl = level_blocks(bt, CODEC_ZSTD)
    bl.insert(0, meta_block(DEFAULT_META))
    bl.append(meta_block(DEFAULT_META))
    d, _ = assemble(bt, bl)
    inv("metadata_twice", d, "malformed", "metadata.count", "Two blocks of stream 1.")
    inv("metadata_level_1", pen(mblk, "level", "<B", 1), "malformed", "metadata.level",
        "The metadata block has level 1.")
    inv("block_level_wrong", pen(vblk, "level", "<B", 1), "malformed", "block.level",
        "A values block of level 2 whose level field says 1.")
    inv("block_level_beyond_depth", pen(vblk, "level", "<B", 9), "malformed", "block.level",
        "A values block with level 9 > depth 3.")
    inv("nodes_block_level_wrong", pen(nblk1, "level", "<B", 0), "malformed", "block.level",
        "A nodes block of level 1 whose level field says 0.")
    # stored size mismatch for codec 0
    bl = level_blocks(bt, CODEC_STORED)
    bl.append(meta_block(DEFAULT_META, CODEC_STORED))
    bl[vblk].stored = bl[vblk].data + b"\x00\x00"
    d, _ = assemble(bt, bl)
    inv("stored_size_mismatch", d, "malformed", "block.stored_size",
        "A stored (codec 0) values block whose stored_size is element_count*2 + 2 (two extra bytes, "
        "file layout and CRCs consistent).")
    # element ranges: use the multiblock file
    # a small file with several blocks per level (BASE, blocks of at most 16 decoded bytes)
    mdata, _, mt, mblocks = simple_file(BASE, UINT16, codec="alt", limit=16, meta_first=True,
                                        scale=2.0 ** -12, offset=-1.0)

    def rebuild_multi(mut):
        bl = []
        for b in mblocks:
            nb = Blk(b.stream, b.level, b.first, b.count, b.data, b.codec, b.flags)
            bl.append(nb)
        mut(bl)
        d, _ = assemble(mt, bl, scale=2.0 ** -12, offset=-1.0)
        return d

    vw = 2
    # find a level with >= 2 values blocks
    nvb = lambda l: sum(1 for b in mblocks if b.stream == 3 and b.level == l)
    lv = max((l for l in range(mt.D) if nvb(l + 1) >= 2), key=nvb)
    assert nvb(lv) >= 2
    vbs = [i for i, b in enumerate(mblocks) if b.stream == 3 and b.level == lv]
    i1, i2 = vbs[0], vbs[1]

    def values_of(a, e):
        return pack_values(UINT16, mt.values[a:e])

    def overlap(bl):
        b = bl[i2]
        b.first -= 1
        b.count += 1
        b.data = values_of(b.first, b.first + b.count)

    def gap(bl):
        b = bl[i1]
        b.count -= 1
        b.data = values_of(b.first, b.first + b.count)

    def straddle(bl):
        # move the first value of level lv+1 into the last block of level lv
        last = [i for i, b in enumerate(bl) if b.stream == 3 and b.level == lv][-1]
        nxt = [i for i, b in enumerate(bl) if b.stream == 3 and b.level == lv + 1][0]
        bl[last].count += 1
        bl[last].data = values_of(bl[last].first, bl[last].first + bl[last].count)
        bl[nxt].first += 1
        bl[nxt].count -= 1
        bl[nxt].data = values_of(bl[nxt].first, bl[nxt].first + bl[nxt].count)
        assert bl[nxt].count >= 1

    def dup(bl):
        b = bl[i1]
        bl.insert(i1 + 1, Blk(b.stream, b.level, b.first, b.count, b.data, b.codec, 0))

    inv("values_overlap", rebuild_multi(overlap), "malformed", "stream.coverage",
        "Small multiblock file (6x5x4, blocks <= 16 bytes): a values block starts one element early, so two blocks of the same level "
        "both hold one element (the same value; all CRCs good).")
    inv("values_gap", rebuild_multi(gap), "malformed", "stream.coverage",
        "Small multiblock file (6x5x4, blocks <= 16 bytes): a values block holds one element less, leaving one element of the stream "
        "in no block.")
    inv("values_block_duplicated", rebuild_multi(dup), "malformed", "stream.coverage",
        "Small multiblock file (6x5x4, blocks <= 16 bytes): one values block appears twice in the file (identical entry and bytes).")
    inv("values_block_straddles_levels", rebuild_multi(straddle), "malformed", "block.level",
        "Small multiblock file (6x5x4, blocks <= 16 bytes): the last values block of level %d also holds the first value of level %d "
        "(coverage of the stream still exact)." % (lv, lv + 1))
    nbs = [i for i, b in enumerate(mblocks) if b.stream == 2]

    def nodes_gap(bl):
        b = bl[nbs[-1]]
        if b.count == 1:
            bl.pop(nbs[-1])
        else:
            b.count -= 1
            b.data = pack_nodes(mt.nodes[b.first:b.first + b.count])

    inv("nodes_gap", rebuild_multi(nodes_gap), "malformed", "stream.coverage",
        "Small multiblock file (6x5x4, blocks <= 16 bytes): the last node word of the node stream is in no block.")
    # block too large
    bomb = meta_bytes(DEFAULT_META)
    bomb = bomb + b" " * (MIB64 + 1 - len(bomb))
    bl = level_blocks(bt, CODEC_ZSTD)
    bl.append(meta_block(bomb))
    d, _ = assemble(bt, bl)
    del bomb
    inv("block_decoded_64mib_plus_1", d, "malformed", "block.too_large",
        "The metadata block declares element_count = 64 MiB + 1 (a zstd frame of JSON plus spaces "
        "with that content size, %d bytes stored): must be refused from the index, before "
        "allocating or decoding (the metadata 16 MiB limit is also exceeded)." % len(bl[-1].stored_bytes()))
    bl = level_blocks(bt, CODEC_ZSTD)
    bl.append(meta_block(DEFAULT_META))
    bl[vblk].ov["count"] = 0x80000000
    d, _ = assemble(bt, bl)
    inv("block_count_2g_values", d, "malformed", "block.too_large",
        "A values block whose entry declares element_count = 2^31 (4 GiB decoded); the frame is small. "
        "Must be refused without allocating (stream coverage is also broken).")
    bl = level_blocks(bt, CODEC_ZSTD)
    bl.append(meta_block(DEFAULT_META))
    need = len(bl[vblk].data)
    bl[vblk].stored = padded_zframe(bl[vblk].data, zstd_bound(need) + 1)
    assert len(bl[vblk].stored) > zstd_bound(need)
    d, _ = assemble(bt, bl)
    inv("block_stored_over_zstd_bound", d, "malformed", "block.stored_bound",
        "A values block (codec 1) of %d decoded bytes stored as a valid zstd frame of %d bytes, more "
        "than ZSTD_compressBound (%d): the frame's one raw block is preceded by empty raw blocks. "
        "Must be refused from the index (§7), before the block is read: otherwise a stored_size of "
        "4 GiB would be read whole." % (need, len(bl[vblk].stored), zstd_bound(need)))
    text = meta_bytes(DEFAULT_META)
    text = text + b" " * (MIB16 + 1 - len(text))
    d, *_ = simple_file(small, BINARY16, meta=text)
    inv("metadata_16mib_plus_1", d, "malformed", "metadata.size",
        "Metadata of 16 MiB + 1 bytes (valid JSON followed by spaces), zstd-compressed.")

    # block CRCs and zstd
    d = bytearray(base)
    d[blay.block_offsets[vblk] + 5] ^= 0x40
    inv("block_crc_bad", bytes(d), "checksum", "block.crc", "One byte of a values block's stored bytes changed.")
    d = bytearray(base)
    d[blay.block_offsets[mblk] + 5] ^= 0x01
    inv("metadata_block_crc_bad", bytes(d), "checksum", "block.crc",
        "One byte of the metadata block's stored bytes changed.")
    d = bytearray(base)
    d[blay.block_offsets[nblk1] + 3] ^= 0x10
    inv("nodes_block_crc_bad", bytes(d), "checksum", "block.crc",
        "One byte of a nodes block's stored bytes changed.")
    bl = level_blocks(bt, CODEC_ZSTD)
    bl.append(meta_block(DEFAULT_META))
    fr = bytearray(zframe(bl[vblk].data))
    assert zstandard.get_frame_parameters(bytes(fr)).has_checksum
    fr[-1] ^= 0xFF
    bl[vblk].stored = bytes(fr)
    d, _ = assemble(bt, bl)
    inv("zstd_content_checksum_bad", d, "checksum", "zstd.checksum",
        "A values block whose zstd content checksum (last 4 bytes of the frame) is wrong; the block "
        "CRC is computed over the damaged frame, so only the zstd checksum fails.")
    bl = level_blocks(bt, CODEC_ZSTD)
    bl.append(meta_block(DEFAULT_META))
    bl[vblk].stored = zframe(bl[vblk].data, content_size=False)
    assert zstandard.get_frame_parameters(bl[vblk].stored).content_size == zstandard.CONTENTSIZE_UNKNOWN
    d, _ = assemble(bt, bl)
    inv("zstd_no_content_size", d, "malformed", "zstd.content_size",
        "A values block whose zstd frame has no Frame_Content_Size.")
    bl = level_blocks(bt, CODEC_ZSTD)
    bl.append(meta_block(DEFAULT_META))
    bl[vblk].stored = zframe(bl[vblk].data + b"\x01\x00")
    d, _ = assemble(bt, bl)
    inv("zstd_content_size_mismatch", d, "malformed", "zstd.content_size",
        "A values block whose zstd frame holds one element more than element_count.")
    bl = level_blocks(bt, CODEC_ZSTD)
    bl.append(meta_block(DEFAULT_META))
    half = len(bl[vblk].data) // 2
    bl[vblk].stored = zframe(bl[vblk].data[:half]) + zframe(bl[vblk].data[half:])
    d, _ = assemble(bt, bl)
    inv("zstd_two_frames", d, "malformed", "zstd.content_size",
        "A values block stored as two zstd frames (the first frame's content size is half the block).")
    bl = level_blocks(bt, CODEC_ZSTD)
    bl.append(meta_block(DEFAULT_META))
    bl[vblk].stored = zframe(bl[vblk].data) + struct.pack("<II", 0x184D2A50, 4) + b"skip"
    d, _ = assemble(bt, bl)
    inv("zstd_trailing_skippable_frame", d, "malformed", "zstd.extra",
        "A values block: a correct zstd frame followed by a skippable frame.")

    # nodes and values (§8, §10)
    def tree_file(t, mutate_words=None, mutate_values=None, enc=UINT16, limit=None):
        nodes = list(t.nodes)
        values = list(t.values)
        if mutate_words:
            mutate_words(nodes)
        if mutate_values:
            mutate_values(values)
        t2 = Tree()
        t2.__dict__.update(t.__dict__)
        t2.nodes, t2.values = nodes, values
        bl = level_blocks(t2, CODEC_ZSTD, limit)
        bl.append(meta_block(DEFAULT_META))
        return assemble(t2, bl)[0]

    # a level-1 inner node with children, not the first of its level
    l1 = list(range(bt.first_inner[1], bt.first_inner[1] + bt.inner_count[1]))
    cand = [nn for nn in l1 if (bt.nodes[nn] >> 56) and nn != l1[0]] or [nn for nn in l1 if bt.nodes[nn] >> 56]
    nn = cand[0]

    def fic_plus1(w):
        w[nn] += 1
        fic = w[nn] & ((1 << 56) - 1)
        assert fic + bin(w[nn] >> 56).count("1") <= bt.first_inner[2] + bt.inner_count[2]

    inv("first_inner_child_off_by_one", tree_file(bt, fic_plus1), "malformed", "first_inner_child",
        "Node word %d (level 1): first_inner_child one too large (still inside the level-2 range)." % nn)

    def fic_big(w):
        w[nn] = (w[nn] & ~((1 << 56) - 1)) | ((1 << 56) - 1)

    inv("first_inner_child_out_of_range", tree_file(bt, fic_big), "malformed", "first_inner_child",
        "Node word %d: first_inner_child = 2^56 - 1." % nn)
    l2 = list(range(bt.first_inner[2], bt.first_inner[2] + bt.inner_count[2]))

    def mask_last(w):
        w[l2[0]] |= 1 << 56

    inv("child_mask_at_level_D_minus_1", tree_file(bt, mask_last), "malformed", "mask_at_last_level",
        "An inner node of level D-1 = 2 with child_mask bit 0 set.")
    # a mask bit cleared: popcount sum of level 1 != inner_count[2]
    inner1 = [nn for nn in l1 if bt.nodes[nn] >> 56]
    victim = inner1[-1]

    def mask_clear(w):
        mask = w[victim] >> 56
        low = mask & -mask
        w[victim] &= ~(low << 56)
        running = 1                      # keep every first_inner_child consistent with the masks
        for q in range(len(w)):
            w[q] = (w[q] & ~((1 << 56) - 1)) | running
            running += bin(w[q] >> 56).count("1")

    inv("child_mask_bit_missing", tree_file(bt, mask_clear), "malformed", "popcount_sum",
        "The last inner node of level 1 with children lost one child_mask bit (first_inner_child of all "
        "nodes recomputed from the masks): the masks of level 1 announce one inner node fewer than "
        "inner_count[2] (§8.4 popcount rule).")
    # padding leaf value nonzero
    pad_vi = None
    for lv_ in bt.levels:
        for nd in lv_:
            if nd.w == 0:
                pad_vi = next(i for i, x in enumerate(v for l_ in bt.levels for v in l_) if x is nd)
                break
        if pad_vi is not None:
            break

    def pad_val(v):
        v[pad_vi] = 1

    inv("padding_leaf_nonzero", tree_file(bt, mutate_values=pad_val), "malformed", "padding_value",
        "The first padding leaf (value index %d, weight 0) holds 1 instead of 0." % pad_vi)
    # padding node subdivided: root child with x_bit=1 of a 3x5x7 volume (x >= 4 is padding)
    t357 = build_tree(src3, UINT16, force_inner={(1, 1, 0, 0)})
    bl = level_blocks(t357, CODEC_ZSTD)
    bl.append(meta_block(DEFAULT_META))
    d, _ = assemble(t357, bl, scale=0.0007, offset=-1.25)
    inv("padding_node_subdivided", d, "malformed", "padding_subdivided",
        "3x5x7 uint16: the level-1 node (1,0,0) (x = 4..7, all padding) is subdivided into 8 padding "
        "leaves of value 0; level table, node words and averages are otherwise consistent.")
    # averages
    root_wrong = lambda v: v.__setitem__(0, v[0] + 1)
    inv("inner_average_wrong", tree_file(bt, mutate_values=root_wrong), "malformed", "average",
        "The root value is one more than encode(m(root)). Only a reader that verifies averages "
        "(§10) refuses it; the dense export is unaffected.", verify_only=True, dense_src=BASE)
    ssrc = SAMPLE[0]
    tr = build_tree(ssrc, UINT16, avg="rounded")
    assert tr.values != SAMPLE[3].values
    inv("inner_average_from_rounded_children", tree_file(tr), "malformed", "average",
        "The sample volume (3x2x2 uint16) with the root value computed from the children's stored "
        "(rounded) values, 168, instead of their unrounded means, 169 (a plausible writer bug, §10).",
        verify_only=True, dense_src=ssrc)
    tu = build_tree(BASE, UINT16, avg="unweighted")
    assert tu.values != bt.values
    inv("inner_average_unweighted", tree_file(tu), "malformed", "average",
        "Inner values computed with every non-padding child weighted 1 instead of its voxel count "
        "(a plausible writer bug, §10).", verify_only=True, dense_src=BASE)

    # metadata
    def meta_file(text):
        bl = level_blocks(bt, CODEC_ZSTD)
        bl.append(meta_block(text))
        return assemble(bt, bl)[0]

    m = dict(DEFAULT_META)
    m["user"] = {"deep": json.loads("[" * 127 + "]" * 127)}
    inv("metadata_depth_129", meta_file(m), "malformed", "metadata.depth",
        "Metadata nested 129 deep (the top-level object, \"user\" and 127 arrays), one more than §11 "
        "allows; a reader refuses it before it parses (a few hundred bytes of brackets nested 100 000 "
        "deep would exhaust a recursive parser's stack).")
    inv("metadata_not_json", meta_file(b"{'voxel_size': [0.05, 0.05, 0.05], 'unit': 'mm'}"), "malformed",
        "metadata.json", "Metadata text is a Python dict literal with single quotes, not JSON.")
    inv("metadata_truncated_json", meta_file(meta_bytes(DEFAULT_META)[:-1]), "malformed", "metadata.json",
        "Metadata JSON missing its closing brace.")
    m2 = dict(DEFAULT_META)
    del m2["origin"]
    inv("metadata_missing_origin", meta_file(m2), "malformed", "metadata.origin",
        "Metadata without the required key 'origin'.")
    m2 = dict(DEFAULT_META)
    m2["value"] = {"unit": "1/mm"}
    inv("metadata_missing_quantity", meta_file(m2), "malformed", "metadata.value",
        "Metadata 'value' object without the required key 'quantity'.")
    inv("metadata_duplicate_key", meta_file(b'{"voxel_size":[1,1,1],"unit":"mm","unit":"um",'
                                            b'"origin":[0,0,0],"value":{"quantity":"density"}}'),
        "malformed", "metadata.duplicate_key", "Metadata object with the key 'unit' twice.")
    inv("metadata_top_level_array", meta_file(b'[{"voxel_size":[1,1,1],"unit":"mm","origin":[0,0,0],'
                                              b'"value":{"quantity":"density"}}]'),
        "malformed", "metadata.top_level", "Metadata whose top level is an array.")
    inv("metadata_bom", meta_file(b"\xef\xbb\xbf" + meta_bytes(DEFAULT_META)), "malformed", "metadata.bom",
        "Metadata starting with a UTF-8 byte-order mark.")
    inv("metadata_bad_utf8", meta_file(meta_bytes(DEFAULT_META).replace(b'"mm"', b'"\xb5m"')), "malformed",
        "metadata.utf8", "Metadata with a Latin-1 byte 0xB5 ('µ') inside a string: not UTF-8.")
    m2 = dict(DEFAULT_META)
    m2["voxel_size"] = [0.05, -0.05, 0.05]
    inv("metadata_voxel_size_negative", meta_file(m2), "malformed", "metadata.voxel_size",
        "voxel_size with a negative component (must be 3 positive numbers).")
    inv("metadata_nan", meta_file(b'{"voxel_size":[NaN,1,1],"unit":"mm","origin":[0,0,0],'
                                  b'"value":{"quantity":"density"}}'),
        "malformed", "metadata.json", "Metadata with the token NaN, which is not JSON (RFC 8259).")
    gen_grids_valid()
    gen_grids_invalid(base, bblocks, bt)
    gen_codec2_valid(BASE)
    gen_codec2_invalid(bt, vblk, nblk1)
    gen_framed()
    gen_bricked()
    gen_masked()
    gen_stored_lods()
    gen_entropy2()
    gen_bricked_float32()
    gen_codec5()
    gen_codec6()
    gen_entropy3()
    return SAMPLE


# ------------------------------------------------- vectors of §8A (version 1.1)

def _f32_from_bits(b):
    return decode(FLOAT32, b)


def rect_source(enc, bx, by, bz, cellvals):
    """Dense source of a rectilinear grid, voxel by voxel: the cell of a
    voxel is found by searching the border lists."""
    X, Y, Z = bx[-1], by[-1], bz[-1]
    nx, ny = len(bx) - 1, len(by) - 1
    src = np.zeros((Z, Y, X), dtype=NPBITS[enc])
    for z in range(Z):
        k = int(np.searchsorted(bz, z, side="right")) - 1
        for y in range(Y):
            j = int(np.searchsorted(by, y, side="right")) - 1
            for x in range(X):
                i = int(np.searchsorted(bx, x, side="right")) - 1
                src[z, y, x] = cellvals[(k * ny + j) * nx + i]
    return src


def nested_source(enc, size, cell_log2, expo, gen_value):
    """Dense source of a nested grid, voxel by voxel: coarse cell c = x // C,
    sub-voxel p = (x - c*C) // h; each sub-voxel gets gen_value() once."""
    X, Y, Z = size
    C = 1 << cell_log2
    table = {}
    src = np.zeros((Z, Y, X), dtype=NPBITS[enc])
    for z in range(Z):
        for y in range(Y):
            for x in range(X):
                c = (x // C, y // C, z // C)
                h = C >> expo[c[2]][c[1]][c[0]]
                key = (c, (x - c[0] * C) // h, (y - c[1] * C) // h, (z - c[2] * C) // h)
                if key not in table:
                    table[key] = None
                src[z, y, x] = 0
    for key in sorted(table):             # fixed order, independent of the file's value order
        table[key] = gen_value()
    for z in range(Z):
        for y in range(Y):
            for x in range(X):
                c = (x // C, y // C, z // C)
                h = C >> expo[c[2]][c[1]][c[0]]
                src[z, y, x] = table[(c, (x - c[0] * C) // h, (y - c[1] * C) // h, (z - c[2] * C) // h)]
    return src



def rectilinear_20x11x7_uint16():
    """The rectilinear grid of rectilinear_20x11x7_uint16 (and of the codec 2
    and codec 5 vectors that store it again): its borders, source and grid."""
    bx, by, bz = [0, 1, 4, 5, 11, 19, 20], [0, 11], [0, 2, 3, 7]
    rng = np.random.default_rng(203)
    cv = [int(v) for v in rng.integers(0, 65536, 18)]
    src = rect_source(UINT16, bx, by, bz, cv)
    g = write_rectilinear(src, UINT16, bx, by, bz)
    assert g.values == cv
    return src, g


def nested_37x21x10_uint16_c8():
    """The nested grid of nested_37x21x10_uint16_c8 (and of the codec 2 and
    codec 5 vectors that store it again): source, grid and metadata."""
    expo = [[[(i + j + 2 * k) % 4 for i in range(5)] for j in range(3)] for k in range(2)]
    rng = np.random.default_rng(206)
    src = nested_source(UINT16, (37, 21, 10), 3, expo, lambda: int(rng.integers(0, 65536)))
    g = write_nested(src, UINT16, 3, expo)
    meta = dict(DEFAULT_META)
    meta["structure"] = {"kind": "nested", "lossless": True, "source_encoding": "uint16"}
    return src, g, meta


def _order_sensitive_cells_f32(src):
    """Put LoD-1 cells whose flat sum depends on the order (§12.3): in z, y, x
    order (x fastest) the voxels are v[n], n = (dz*2 + dy)*2 + dx."""
    big = f32(2.0 ** 60)
    nbig = f32(-(2.0 ** 60))
    one = f32(1.0)
    cells = {
        (0, 0, 0): [big, one, nbig, one, one, one, one, one],   # sequential 5/8, exact 6/8, pairwise 4/8
        (1, 0, 0): [big, nbig, one, one, one, one, one, one],   # z,y,x: 6/8; x,y,z (z fastest): 3/8
        (2, 0, 0): [one, big, nbig, one, one, one, one, one],   # sequential 5/8
        (3, 1, 0): [nbig, one, one, one, one, one, one, big],   # sequential +0, exact 6/8
    }
    for (cx, cy, cz), v in cells.items():
        for n in range(8):
            dx, dy, dz = n & 1, (n >> 1) & 1, (n >> 2) & 1
            src[2 * cz + dz, 2 * cy + dy, 2 * cx + dx] = v[n]
    return cells


# ------------------------------------------------ framed blocks (version 1.3 draft)

def gen_framed():
    """§4.1, §7.1: files with required feature bit 0, the volume descriptor in
    an 80-byte header and a block header before every block, metadata first
    (§15); one file per structure kind, every encoding and codec; then files
    that break one framing rule each."""
    framed = dict(framed=True, minor=3)
    # octree, binary16, zstd over byte planes, several blocks per level
    rng = np.random.default_rng(1301)
    vals = np.round(rng.normal(1.0, 0.25, 9 * 7 * 5), 2)
    vals[: 9 * 7 * 2] = 0.5                       # a uniform slab: leaves above voxel level
    src = arr_f16(vals, (5, 7, 9))
    d, lay, t, bl = simple_file(src, BINARY16, codec="planes", limit=48, meta_first=True, **framed)
    add_valid("framed_octree_9x7x5_binary16", d, src, BINARY16,
              "Framed (1.3 draft, required feature bit 0): 80-byte header with the volume descriptor, "
              "a 32-byte block header (IVBK) before every block, the index entry's stored_size and crc "
              "covering header and payload; metadata block first, then values and nodes level by level "
              "(§15); octree 9x7x5 binary16, values over byte planes (codec 2), blocks of at most 48 bytes.")
    base, base_tree, base_blocks = d, t, bl
    # octree, uint16 with scale and offset, stored blocks (codec 0: stored_size = 32 + decoded)
    src = rng.integers(0, 4096, size=(4, 6, 5)).astype(np.uint16)
    src[:2, :2, :2] = 99
    d, *_ = simple_file(src, UINT16, codec=CODEC_STORED, limit=40, meta_first=True, scale=0.25,
                        offset=-3.0, **framed)
    add_valid("framed_octree_5x6x4_uint16_stored", d, src, UINT16,
              "Framed octree 5x6x4 uint16 (value_scale 0.25, value_offset -3), every block stored "
              "(codec 0): stored_size is 32 + element_count x width.")
    # octree, float32, zstd; early metadata (stream 6, ignorable) first, metadata last
    vals = rng.normal(0.0, 1.0, 6 * 6 * 6)
    src = arr_f32(vals, (6, 6, 6))
    t = build_tree(src, FLOAT32)
    blocks = level_blocks(t, CODEC_ZSTD, 256)
    early = meta_block({"voxel_size": [0.1, 0.1, 0.1], "unit": "mm", "origin": [0, 0, 0],
                        "value": {"quantity": "grey_value"}})
    early.stream, early.flags = 6, 1
    d, _ = assemble(t, [early] + blocks + [meta_block(DEFAULT_META)], **framed)
    add_valid("framed_octree_6x6x6_float32_early_metadata", d, src, FLOAT32,
              "Framed octree 6x6x6 float32 (zstd) written as a writer that learns its final metadata "
              "late (§15): an early metadata block (stream 6, ignorable flag set) first, the metadata "
              "block (stream 1) last. A reader skips stream 6; a salvaging reader uses it when stream 1 "
              "did not survive.")
    # the three grids of §8A
    rs = np.random.default_rng(1302)
    src = rs.integers(0, 60000, size=(3, 4, 5)).astype(np.uint16)
    g = write_regular(src, UINT16)
    d, *_ = grid_file(g, limit=32, meta_first=True, **framed)
    add_valid("framed_regular_5x4x3_uint16", d, src, UINT16,
              "Framed regular grid 5x4x3 uint16, metadata first, values in blocks of at most 16.",
              kind=KIND_REGULAR)
    bx, by, bz = [0, 2, 3, 7], [0, 1, 5], [0, 4]
    cv = [f16(v) for v in rs.normal(0.0, 4.0, 3 * 2 * 1)]
    src = rect_source(BINARY16, bx, by, bz, cv)
    g = write_rectilinear(src, BINARY16, bx, by, bz)
    d, *_ = grid_file(g, codec="planes", limit=8, slimit=8, meta_first=True, **framed)
    add_valid("framed_rectilinear_7x5x4_binary16", d, src, BINARY16,
              "Framed rectilinear grid 7x5x4 binary16 (B_x = [0,2,3,7], B_y = [0,1,5], B_z = [0,4]), "
              "borders and values in small blocks, values over byte planes.",
              kind=KIND_RECTILINEAR)
    expo = [[[(i + j + k) % 2 for i in range(3)] for j in range(2)] for k in range(2)]
    src = nested_source(FLOAT32, (6, 4, 3), 1, expo, lambda: f32(rs.normal(5.0, 2.0)))
    g = write_nested(src, FLOAT32, 1, expo)
    d, *_ = grid_file(g, limit=32, slimit=32, meta_first=True, **framed)
    add_valid("framed_nested_6x4x3_float32", d, src, FLOAT32,
              "Framed nested grid 6x4x3 float32, cell_log2 1: the descriptor repeats byte 11 "
              "(cell_log2) as well.", kind=KIND_NESTED, extra={"cell_log2": 1})

    # ---- invalid: one framing rule broken each (all other checksums hold)
    vb = next(n for n, b in enumerate(base_blocks) if b.stream == STREAM_VALUES and b.level > 0)

    def with_header(field, value):
        bl = [copy.copy(b) for b in base_blocks]
        bl[vb].hov = {field: value}
        data, _ = assemble(base_tree, bl, **framed)
        return data

    b = base_blocks[vb]
    add_invalid("framed_block_header_level", with_header("level", b.level + 1), "malformed",
                "block_header.fields", "Framed file whose values block header says level %d, its index "
                "entry %d (§7.1: the header repeats the entry)." % (b.level + 1, b.level))
    add_invalid("framed_block_header_first_element", with_header("first", b.first + 1), "malformed",
                "block_header.fields", "A block header's first_element differs from its index entry's.")
    add_invalid("framed_block_header_crc", with_header("header_crc", 0x12345678), "checksum",
                "block_header.crc", "A block header whose header_crc is wrong (the entry's crc, over "
                "header and payload, holds).")
    add_invalid("framed_block_signature", with_header("sig", b"IVBX"), "malformed",
                "block_header.signature", "A block header whose block_signature is 'IVBX' (header_crc and "
                "the entry's crc recomputed).")
    add_invalid("framed_payload_crc", with_header("payload_crc", 0), "checksum",
                "block_header.payload_crc", "A block header whose payload_crc is wrong.")
    add_invalid("framed_payload_size", with_header("payload_size", len(b.stored_bytes()) + 1),
                "malformed", "block_header.payload_size",
                "A block header whose payload_size is stored_size - 31 instead of stored_size - 32.")
    desc = bytearray(struct.pack("<BBBBIIIdd", 1, BINARY16, 4, 0, 9, 7, 5, 1.0, 0.0))
    struct.pack_into("<I", desc, 4, 10)          # size_x 10 in the header, 9 in the index
    data, _ = assemble(base_tree, base_blocks, descriptor=bytes(desc), **framed)
    add_invalid("framed_descriptor_mismatch", data, "malformed", "framed.descriptor",
                "The volume descriptor (header bytes 36..68) says size_x 10, the index 9 (§4.1).")
    add_invalid("framed_descriptor_reserved", reseal(patch(base, 70, "<B", 1), index=False), "malformed",
                "framed.reserved", "Reserved header byte 70 (of 68..76, kept for the brick layout) is 1; "
                "header CRC recomputed.")


def gen_bricked():
    """§8A.4, §7.2 (1.3 draft): bricked regular grids with codec 3 under every
    predictor setting the header allows, then files that break one rule each."""
    framed = dict(framed=True, minor=3)
    rng = np.random.default_rng(2201)

    def bricked_file(src, enc, b, codec=CODEC_PREDICTED, mutate=None, **pred):
        g = write_bricked(src, enc, b)
        blocks = bricked_blocks(g, codec, **pred)
        if mutate:
            mutate(blocks)
        blocks.insert(0, meta_block(DEFAULT_META))
        kw = dict(framed)
        kw.update(structure_kind=KIND_BRICKED, ireserved=b)
        data, _ = assemble(g, blocks, **kw)
        return data

    def valid(name, src, enc, b, desc, lods=True, **kw):
        add_valid(name, bricked_file(src, enc, b, **kw), src, enc, desc, lods=lods, kind=KIND_BRICKED,
                  extra={"brick_log2": b})

    smooth = lambda X, Y, Z, lo, step: (lo + step * (np.arange(X)[None, None, :] + 2 * np.arange(Y)[None, :, None]
                                                     + 3 * np.arange(Z)[:, None, None]))
    # ---- valid
    src = (smooth(5, 4, 3, 1000, 7) + rng.integers(0, 3, (3, 4, 5))).astype(np.uint16)
    valid("bricked_5x4x3_uint16_lorenzo", src, UINT16, 1,
          "Bricked regular grid (structure_kind 5, §8A.4) 5x4x3 uint16, bricks of 2 (byte 11 = 1), so "
          "edge bricks of 1 voxel along x and z; codec 3 (§7.2) with the Lorenzo taps, identity map.",
          value_map=0)
    vals = np.round(rng.normal(0.5, 0.3, 9 * 7 * 6), 3)
    src = arr_f16(vals, (6, 7, 9))
    flat = src.reshape(-1)
    flat[[0, 5, 17, 40, 77, 111, 200, 301]] = [0x8000, 0x7E01, 0xFE77, 0x7C00, 0xFC00, 0x0001, 0x8001, 0x8000]
    valid("bricked_9x7x6_binary16_specials", src, BINARY16, 2,
          "Bricked grid 9x7x6 binary16, bricks of 4, codec 3 with the binary16 order map (value_map 1): "
          "-0, NaNs with payloads, infinities and subnormals come back bit for bit.")
    src = (smooth(8, 8, 8, 20000, 11) + rng.integers(0, 40, (8, 8, 8))).astype(np.uint16)
    valid("bricked_8x8x8_uint16_fitted_taps", src, UINT16, 3,
          "Bricked grid 8x8x8 uint16, one brick: taps in units of 2^-12 (shift 12) summing to 4096, "
          "rounding by adding 2^11 before the floor division.",
          value_map=0, shift=12, taps=(2900, 1800, 1500, -1300, -1100, -900, 1196))
    src = (rng.integers(3000, 3100, (6, 6, 6))).astype(np.uint16)
    valid("bricked_6x6x6_uint16_level", src, UINT16, 2,
          "Bricked grid 6x6x6 uint16 of noise around a level: taps 0.25 each on x, y, z (shift 4) and a "
          "level L = 1541 added after the shift.",
          value_map=0, shift=4, taps=(4, 4, 4, 0, 0, 0, 0), level=1541)
    src = rng.integers(0, 65536, (4, 5, 6)).astype(np.uint16)
    valid("bricked_6x5x4_uint16_extreme_taps", src, UINT16, 2,
          "Bricked grid 6x5x4 uint16 of random bits, taps +-32767 and -32768 with shift 0 and a level of "
          "-2^31: predictions far outside 0..65535 are clamped before the residual is added.",
          value_map=0, shift=0, taps=(32767, -32768, 32767, -32768, 32767, -32768, 32767), level=-2 ** 31)
    src = (smooth(7, 6, 5, 40000, -13) + rng.integers(0, 9, (5, 6, 7))).astype(np.uint16)
    valid("bricked_7x6x5_uint16_negative_floor", src, UINT16, 2,
          "Bricked grid 7x6x5 uint16, taps summing to a negative S in places, shift 15: the division by "
          "2^15 floors toward minus infinity.",
          value_map=0, shift=15, taps=(-20000, 30000, 20000, 1000, -3000, 2000, 2768), level=-7)
    vals = np.round(rng.normal(1.0, 0.4, 10 * 5 * 4), 2)
    src = arr_f16(vals, (4, 5, 10))
    valid("bricked_10x5x4_binary16_mixed_codecs", src, BINARY16, 1,
          "Bricked grid 10x5x4 binary16, bricks of 2: the values blocks cycle through codecs 3, 0, 1, 2 "
          "(every codec is valid on a brick).",
          codec=lambda q: (CODEC_PREDICTED, CODEC_STORED, CODEC_ZSTD, CODEC_PLANES)[q % 4])
    src = arr_f16(np.round(rng.normal(-0.2, 0.3, 5 * 5 * 5), 3), (5, 5, 5))
    valid("bricked_5x5x5_binary16_identity_map", src, BINARY16, 2,
          "Bricked grid 5x5x5 binary16 around zero with value_map 0: the raw bit patterns are predicted "
          "(worse across zero, still exact).", value_map=0)
    src = np.array([[[0x8000]]], np.uint16)
    valid("bricked_1x1x1_binary16", src, BINARY16, 1,
          "Bricked grid of one voxel (-0), brick of 2: the brick's extent is 1x1x1, its one voxel "
          "predicted as 0.", lods=False)
    src = (smooth(17, 1, 1, 500, 3)).astype(np.uint16)
    valid("bricked_17x1x1_uint16_line", src, UINT16, 2,
          "Bricked grid 17x1x1 uint16, bricks of 4 (the last of 1 voxel): one-axis prediction only.",
          value_map=0)
    src = (smooth(5, 3, 2, 100, 1)).astype(np.uint16)
    valid("bricked_5x3x2_uint16_brick_larger_than_volume", src, UINT16, 4,
          "Bricked grid 5x3x2 uint16, bricks of 16 (byte 11 = 4): one brick smaller than B on every axis.",
          value_map=0)
    per = lambda q: dict(value_map=q % 2, shift=q % 16, taps=tuple(int(t) for t in rng.integers(-999, 999, 7)),
                         level=int(rng.integers(-5000, 5000)), zcheck=q % 2 == 0)
    src = rng.integers(0, 65536, (6, 6, 6)).astype(np.uint16)
    valid("bricked_6x6x6_uint16_taps_per_brick", src, UINT16, 1,
          "Bricked grid 6x6x6 uint16 of random bits, 27 bricks of 2, each with its own value map, shift, "
          "taps and level; every other residual frame carries a content checksum.", per_brick=per)

    # ---- invalid: one rule broken each
    src = (smooth(6, 5, 4, 1000, 5) + rng.integers(0, 5, (4, 5, 6))).astype(np.uint16)
    good = dict(value_map=0)

    def first_brick(field_bytes):
        def mutate(blocks):
            b = blocks[0]
            b.stored = field_bytes(b.stored)
        return mutate

    def with_byte(off, value):
        return first_brick(lambda st: st[:off] + bytes([value]) + st[off + 1:])

    def inv(name, expect, tag, desc, **kw):
        args = dict(good)
        args.update(kw)
        add_invalid(name, bricked_file(src, UINT16, 2, **args), expect, tag, desc)

    inv("bricked_codec3_predictor_2", "unsupported-feature", "codec3.predictor",
        "A codec 3 block whose predictor (payload byte 0) is 2, not defined (§7.2).", mutate=with_byte(0, 2))
    inv("bricked_codec3_entropy_0", "unsupported-feature", "codec3.entropy",
        "A codec 3 block whose entropy coder (payload byte 3) is 0.", mutate=with_byte(3, 0))
    inv("bricked_codec3_value_map_2", "malformed", "codec3.map",
        "A codec 3 block whose value_map (payload byte 1) is 2.", mutate=with_byte(1, 2))
    inv("bricked_codec3_shift_16", "malformed", "codec3.shift",
        "A codec 3 block whose shift (payload byte 2) is 16.", mutate=with_byte(2, 16))
    inv("bricked_codec3_reserved", "malformed", "codec3.reserved",
        "A codec 3 block whose reserved payload byte 23 is 1.", mutate=with_byte(23, 1))
    inv("bricked_codec3_short", "malformed", None,
        "A codec 3 block of 20 bytes, shorter than its 24-byte codec header.",
        mutate=first_brick(lambda st: st[:20]))
    inv("bricked_codec3_trailing_byte", "malformed", "zstd.extra",
        "A codec 3 block with one byte after its zstd frame.", mutate=first_brick(lambda st: st + b"\0"))
    first_ext = bricked_order((6, 5, 4), 2)[0][1]
    n0 = first_ext[0] * first_ext[1] * first_ext[2]
    inv("bricked_codec3_content_size", "malformed", "zstd.content_size",
        "A codec 3 block whose residual frame holds 2n - 2 bytes instead of 2n.",
        mutate=first_brick(lambda st: st[:24] + zframe(bytes(2 * n0 - 2), False)))

    def merge_first_two(blocks):
        a, b = blocks[0], blocks[1]
        merged = Blk(STREAM_VALUES, 0, a.first, a.count + b.count, a.data + b.data, codec=CODEC_ZSTD)
        blocks[0:2] = [merged]
    inv("bricked_two_bricks_in_a_block", "malformed", None,
        "A bricked grid whose first values block holds the first two bricks (zstd): one brick per "
        "block (§6.4, §8A.4).", codec=CODEC_ZSTD, mutate=merge_first_two)

    def split_first(blocks):
        a = blocks[0]
        h = a.count // 2
        blocks[0:1] = [Blk(STREAM_VALUES, 0, a.first, h, a.data[:2 * h], codec=CODEC_ZSTD),
                       Blk(STREAM_VALUES, 0, a.first + h, a.count - h, a.data[2 * h:], codec=CODEC_ZSTD)]
    inv("bricked_brick_split_in_two", "malformed", None,
        "A bricked grid whose first brick is split over two values blocks (the coverage holds).",
        codec=CODEC_ZSTD, mutate=split_first)
    g = write_bricked(src, UINT16, 2)
    blocks = [meta_block(DEFAULT_META)] + bricked_blocks(g, value_map=0)
    for b_log2, name, desc in ((0, "bricked_brick_log2_0", "byte 11 (brick log2) is 0, outside 1 .. 8"),
                               (9, "bricked_brick_log2_9", "byte 11 (brick log2) is 9, outside 1 .. 8")):
        data, _ = assemble(g, blocks, structure_kind=KIND_BRICKED, ireserved=b_log2, **framed)
        add_invalid(name, data, "malformed", "brick_log2", "A bricked grid whose " + desc + " (§6.1).")
    data, _ = assemble(g, blocks, structure_kind=KIND_BRICKED, ireserved=2, minor=3)
    add_invalid("bricked_unframed", data, "malformed", "bricked.unframed",
                "A bricked grid without framed blocks (required feature bit 0 clear): §8A.4 requires them.")
    reg = write_regular(src, UINT16)
    rblocks = grid_blocks(reg, CODEC_ZSTD)
    rblocks[0].stored = predicted_payload([int(v) for v in src.reshape(-1)], (6, 5, 4), value_map=0)
    rblocks[0].codec = CODEC_PREDICTED
    data, _ = assemble(reg, [meta_block(DEFAULT_META)] + rblocks, structure_kind=KIND_REGULAR, **framed)
    add_invalid("regular_with_codec3", data, "malformed", "codec3.where",
                "A regular grid (structure_kind 2) whose one values block has codec 3, valid only in a "
                "bricked grid (§7).")
    f32src = arr_f32(rng.normal(0, 1, 4 * 4 * 4), (4, 4, 4))
    g32 = write_bricked(f32src, FLOAT32, 2)
    b32 = bricked_blocks(g32, CODEC_ZSTD)
    b32[0].codec = CODEC_PREDICTED
    b32[0].stored = zframe(bytes(8))
    data, _ = assemble(g32, [meta_block(DEFAULT_META)] + b32, structure_kind=KIND_BRICKED, ireserved=2, **framed)
    add_invalid("bricked_float32_codec3", data, "malformed", "codec3.where",
                "A bricked grid of float32 values whose brick has codec 3, which holds 16-bit values only.")


def framed_bricked_file(src, enc, b, codec, mutate=None, **kw):
    """A framed 1.3 bricked grid of `src` in bricks of 2^b whose values blocks
    bricked_blocks() makes with `codec` and **kw; mutate(blocks) may change
    them before they are assembled (invalid vectors)."""
    g = write_bricked(src, enc, b)
    blocks = bricked_blocks(g, codec, **kw)
    if mutate:
        mutate(blocks)
    blocks.insert(0, meta_block(DEFAULT_META))
    data, _ = assemble(g, blocks, structure_kind=KIND_BRICKED, ireserved=b, framed=True, minor=3)
    return data


def add_valid_bricked(name, data, src, enc, b, desc, lods=True):
    add_valid(name, data, src, enc, desc, lods=lods, kind=KIND_BRICKED, extra={"brick_log2": b})


def smooth_f32(X, Y, Z, rng, lo=20.0, noise=0.05):
    """A float32 gradient with a little noise, [z][y][x], each voxel rounded
    once to binary32 (§9)."""
    z, y, x = np.mgrid[0:Z, 0:Y, 0:X]
    return arr_f32(lo + 0.37 * x - 0.21 * y + 0.13 * z + rng.normal(0.0, noise, (Z, Y, X)), (Z, Y, X))


def put_bits(src, cells):
    """Sets voxel (x, y, z) of src to the bit pattern of each (x, y, z): bits."""
    for (x, y, z), bits in cells.items():
        src[z, y, x] = bits


def gen_bricked_float32():
    """§8A.4 (1.3 draft): bricked regular grids of float32 values (value_encoding
    3), whose bricks may use codecs 0, 1 and 2 only (codecs 3 and 4 hold 16-bit
    values, §7).  Own generator (seed), so the vectors before keep their bytes."""
    rng = np.random.default_rng(2501)

    src = smooth_f32(9, 7, 5, rng)
    put_bits(src, {(0, 0, 0): 0x80000000,          # -0, brick (0, 0, 0)
                   (8, 0, 0): 0x7F800000,          # +inf, the edge brick of 1 voxel along x
                   (3, 6, 4): 0xFF800000,          # -inf, an edge brick 4x3x1
                   (5, 2, 1): 0x7FC01234,          # quiet NaN with a payload
                   (6, 5, 2): 0xFFC00001,          # negative quiet NaN with a payload
                   (1, 4, 3): 0x7FA00001,          # signalling NaN
                   (2, 1, 0): 0x00000001,          # smallest subnormal
                   (7, 3, 3): 0x807FFFFF,          # largest negative subnormal
                   (8, 6, 4): 0x00400000,          # subnormal, the last voxel (1x3x1 corner brick)
                   (4, 4, 0): 0x7F7FFFFF,          # largest finite
                   (0, 6, 1): 0x80800000})         # -(smallest normal)
    add_valid_bricked(
        "bricked_9x7x5_float32_specials_codec2", framed_bricked_file(src, FLOAT32, 2, CODEC_PLANES),
        src, FLOAT32, 2,
        "Bricked grid (structure_kind 5, §8A.4) 9x7x5 float32, bricks of 4 (edge bricks of extent 1 along "
        "x, 3 along y and 1 along z, down to the 1x3x1 corner brick), every brick one codec 2 block "
        "(zstd over the 4 byte planes of its values, §7). A gradient with noise and -0, +inf, -inf, the "
        "NaNs 0x7FC01234, 0xFFC00001 and 0x7FA00001 (signalling), the subnormals 0x00000001, "
        "0x807FFFFF and 0x00400000, the largest finite value and -(smallest normal): every bit pattern "
        "comes back unchanged (§9). Levels of detail by §12.3 (binary64 sum, canonical NaN 0x7FC00000).")

    src = smooth_f32(11, 9, 6, rng, lo=-1.5, noise=0.3)
    put_bits(src, {(0, 0, 0): 0x80000000,          # -0 in a stored brick (0)
                   (5, 1, 0): 0x7FC01234,          # NaN payload in a zstd brick (1)
                   (9, 8, 5): 0xFF800000,          # -inf in the last brick (17, 3x1x2, zstd)
                   (10, 2, 1): 0x00000003,         # subnormal in brick 2 (3x4x4, stored)
                   (1, 8, 4): 0x7F800000})         # +inf in brick 15 (4x1x2, zstd)
    add_valid_bricked(
        "bricked_11x9x6_float32_codecs_0_and_1", framed_bricked_file(
            src, FLOAT32, 2, lambda q: (CODEC_STORED, CODEC_ZSTD)[q % 2]),
        src, FLOAT32, 2,
        "Bricked grid 11x9x6 float32, bricks of 4 (edge extents 3 along x, 1 along y, 2 along z), 18 "
        "bricks whose blocks alternate codec 0 (stored: payload 4 bytes a value) and codec 1 (one zstd "
        "frame of 4n bytes), brick 0 stored; -0, the NaN 0x7FC01234, +inf, -inf and a subnormal in "
        "bricks of either codec.")


def gen_masked():
    """§7.3 (1.3 draft): bricked grids with codec 4 blocks (constant and
    masked forms, any background pattern), then files that break one rule
    each."""
    framed = dict(framed=True, minor=3)
    rng = np.random.default_rng(2202)

    def masked_file(src, enc, b, codec=CODEC_MASKED, mutate=None, **kw):
        return framed_bricked_file(src, enc, b, codec, mutate, **kw)

    def valid(name, src, enc, b, desc, lods=True, **kw):
        add_valid_bricked(name, masked_file(src, enc, b, **kw), src, enc, b, desc, lods)

    def object_volume(X, Y, Z, background, inside):
        """A ball of `inside` values in a volume of `background`."""
        z, y, x = np.meshgrid(np.arange(Z), np.arange(Y), np.arange(X), indexing="ij")
        ball = (x - X / 3) ** 2 + (y - Y / 3) ** 2 + (z - Z / 3) ** 2 < (min(X, Y, Z) / 3) ** 2
        return np.where(ball, inside, background).astype(np.uint16)

    # ---- valid
    inside = arr_f16(np.round(rng.normal(0.8, 0.2, 12 * 10 * 9), 3), (9, 10, 12))
    src = object_volume(12, 10, 9, 0x8000, inside)
    valid("bricked_12x10x9_binary16_masked_object", src, BINARY16, 2,
          "Bricked grid 12x10x9 binary16, bricks of 4: a ball of values in a background of -0 (0x8000); "
          "every brick codec 4 (§7.3) with its most common value as background: bricks of -0 alone are "
          "form 0 (a 4-byte payload), the others form 1 (mask and byte planes).")
    inside = rng.integers(0, 65536, (5, 6, 7)).astype(np.uint16)
    src = object_volume(7, 6, 5, 0x7E01, inside)
    src.reshape(-1)[[3, 50, 100]] = 0x7E01
    valid("bricked_7x6x5_binary16_masked_nan_background", src, BINARY16, 2,
          "Bricked grid 7x6x5 binary16, bricks of 4, edge bricks of 3 and 1 voxels (mask bytes not "
          "full): the background is the NaN 0x7E01; its payload comes back bit for bit.")
    src = rng.integers(1000, 1010, (4, 4, 6)).astype(np.uint16)
    valid("bricked_6x4x4_uint16_masked_not_most_common", src, UINT16, 2,
          "Bricked grid 6x4x4 uint16 of ten values, bricks of 4: every brick codec 4 with background "
          "1009, whatever its share (a reader decodes what the mask says, §7.3); every other frame "
          "carries a content checksum.",
          per_brick=lambda q: dict(background=1009, zcheck=q % 2 == 0))
    src = np.full((3, 5, 4), 4242, np.uint16)
    valid("bricked_4x5x3_uint16_masked_all_background_form_1", src, UINT16, 2,
          "Bricked grid 4x5x3 uint16 of one value, bricks of 4: form 1 with a mask of all ones, so the "
          "frame holds the mask alone (k = 0 other values).", form=1)
    inside = arr_f16(np.round(rng.normal(0.3, 0.1, 8 * 8 * 8), 3), (8, 8, 8))
    src = object_volume(8, 8, 8, 0x0000, inside)
    valid("bricked_8x8x8_binary16_codecs_3_and_4", src, BINARY16, 2,
          "Bricked grid 8x8x8 binary16, bricks of 4: codec 4 and codec 3 bricks in turn.",
          codec=lambda q: (CODEC_MASKED, CODEC_PREDICTED)[q % 2])

    def runs(*spans, background=None):
        """Merges the bricks q0 .. q1 - 1 of each span into one codec 4 block."""
        def mutate(blocks):
            for q0, q1 in sorted(spans, reverse=True):
                part = blocks[q0:q1]
                vals = [v for b in part for v in struct.unpack("<%dH" % b.count, b.data)]
                merged = Blk(STREAM_VALUES, 0, part[0].first, len(vals), b"".join(b.data for b in part),
                             codec=CODEC_MASKED)
                bg = background if background is not None else max(sorted(set(vals)), key=vals.count)
                merged.stored = masked_payload(vals, bg)
                blocks[q0:q1] = [merged]
        return mutate
    inside = arr_f16(np.round(rng.normal(0.6, 0.1, 12 * 10 * 9), 3), (9, 10, 12))
    src = object_volume(12, 10, 9, 0x3C00, inside)
    # Bricks of 4: 3 x 3 x 3 of them; the ball (centre 4, 3.3, 3; radius 3) leaves bricks 2, 5, 6, 7,
    # 8 and most of the last layer background alone.
    valid("bricked_12x10x9_binary16_masked_runs", src, BINARY16, 2,
          "Bricked grid 12x10x9 binary16, bricks of 4: codec 4 blocks holding runs of whole bricks "
          "(§7.3, §8A.4): bricks 5 .. 8 (across a row of bricks; background 1.0 alone, form 0), bricks "
          "18 .. 26 (the last layer), and bricks 0 .. 1 (form 1, the ball's values behind one mask); "
          "the others one brick each.",
          mutate=runs((0, 2), (5, 9), (18, 27)))

    # ---- invalid: one rule broken each (a 7x6x5 uint16 object, bricks of 4)
    src = object_volume(7, 6, 5, 500, rng.integers(600, 700, (5, 6, 7)).astype(np.uint16))
    first_n = 4 * 4 * 4

    def first_brick(change):
        def mutate(blocks):
            blocks[0].stored = change(blocks[0].stored)
        return mutate

    def inv(name, expect, tag, desc, **kw):
        add_invalid(name, masked_file(src, UINT16, 2, **kw), expect, tag, desc)

    inv("bricked_codec4_form_2", "malformed", "codec4.form",
        "A codec 4 block whose form (payload byte 2) is 2.",
        mutate=first_brick(lambda st: st[:2] + b"\x02" + st[3:]))
    inv("bricked_codec4_reserved", "malformed", "codec4.reserved",
        "A codec 4 block whose reserved payload byte 3 is 1.",
        mutate=first_brick(lambda st: st[:3] + b"\x01" + st[4:]))
    inv("bricked_codec4_short", "malformed", "codec4.short",
        "A codec 4 block of 3 bytes, shorter than its 4-byte codec header.",
        mutate=first_brick(lambda st: st[:3]))
    inv("bricked_codec4_constant_with_frame", "malformed", "codec4.constant_size",
        "A codec 4 block of form 0 (constant) followed by a zstd frame: form 0 is exactly 4 bytes.",
        mutate=first_brick(lambda st: st[:2] + b"\x00" + st[3:]))
    mask_all_but_one = bytes([0xFE] + [0xFF] * 7)
    inv("bricked_codec4_count_mismatch", "malformed", "codec4.count",
        "A codec 4 block whose mask leaves 1 value that is not the background but whose frame holds 2.",
        mutate=first_brick(lambda st: st[:4] + zframe(mask_all_but_one + bytes([1, 2, 0, 0]), False)))
    inv("bricked_codec4_odd_content", "malformed", "codec4.content_size",
        "A codec 4 block whose frame holds the 8-byte mask and 3 bytes: not two bytes per value.",
        mutate=first_brick(lambda st: st[:4] + zframe(mask_all_but_one + bytes(3), False)))
    inv("bricked_codec4_content_too_large", "malformed", "codec4.content_size",
        "A codec 4 block whose frame holds the mask and 2n + 2 bytes, more than n values.",
        mutate=first_brick(lambda st: st[:4] + zframe(bytes(8 + 2 * first_n + 2), False)))
    inv("bricked_codec4_content_too_small", "malformed", "codec4.content_size",
        "A codec 4 block whose frame holds 6 bytes, less than the 8-byte mask.",
        mutate=first_brick(lambda st: st[:4] + zframe(bytes(6), False)))
    inv("bricked_codec4_trailing_byte", "malformed", "zstd.extra",
        "A codec 4 block (form 1) with one byte after its zstd frame.",
        mutate=first_brick(lambda st: st + b"\0"))

    def padding_mutate(blocks):   # the last brick is 3x2x1 = 6 values: mask bits 6 and 7 are padding
        b = blocks[-1]
        vals = list(struct.unpack("<%dH" % b.count, b.data))
        mask = sum(1 << i for i, v in enumerate(vals) if v == 500) | 0x80
        k = sum(1 for v in vals if v != 500)
        b.stored = struct.pack("<HBB", 500, 1, 0) + zframe(bytes([mask]) + bytes(2 * k), False)
    inv("bricked_codec4_padding_bit", "malformed", "codec4.padding",
        "A codec 4 block of 6 values whose mask byte has bit 7 (past the last value) set.",
        per_brick=lambda q: dict(background=500, form=1), mutate=padding_mutate)
    def run_inside_brick(blocks):   # bricks 0 and 1 and the first 8 values of brick 2 in one block
        runs((0, 3))(blocks)
        b = blocks[0]
        vals = list(struct.unpack("<%dH" % b.count, b.data))
        cut = bricked_order((7, 6, 5), 2)[2][0] + 8   # bricks 0 and 1, and 8 values of brick 2
        first_part = Blk(STREAM_VALUES, 0, b.first, cut, b.data[:2 * cut], codec=CODEC_MASKED)
        first_part.stored = masked_payload(vals[:cut], 500)
        second = Blk(STREAM_VALUES, 0, b.first + cut, b.count - cut, b.data[2 * cut:], codec=CODEC_MASKED)
        second.stored = masked_payload(vals[cut:], 500)
        blocks[0:1] = [first_part, second]
    inv("bricked_codec4_run_ends_inside_a_brick", "malformed", None,
        "A codec 4 block holding bricks 0 and 1 and the first 8 values of brick 2 (a run must end at a "
        "brick, §7.3); the next codec 4 block holds the rest of brick 2, starting inside it.",
        mutate=run_inside_brick)
    inv("bricked_codec2_two_bricks", "malformed", "bricked.block",
        "A codec 2 block holding bricks 0 and 1: only codec 4 may hold a run of bricks (§8A.4).",
        codec=CODEC_PLANES, mutate=lambda blocks: blocks.__setitem__(
            slice(0, 2), [Blk(STREAM_VALUES, 0, 0, blocks[0].count + blocks[1].count,
                              blocks[0].data + blocks[1].data, codec=CODEC_PLANES)]))
    reg = write_regular(src, UINT16)
    rblocks = grid_blocks(reg, CODEC_ZSTD)
    rblocks[0].stored = masked_payload([int(v) for v in src.reshape(-1)], 500)
    rblocks[0].codec = CODEC_MASKED
    data, _ = assemble(reg, [meta_block(DEFAULT_META)] + rblocks, structure_kind=KIND_REGULAR, **framed)
    add_invalid("regular_with_codec4", data, "malformed", "codec4.where",
                "A regular grid (structure_kind 2) whose one values block has codec 4, valid only in a "
                "bricked grid (§7).")
    f32src = arr_f32(rng.normal(0, 1, 4 * 4 * 4), (4, 4, 4))
    g32 = write_bricked(f32src, FLOAT32, 2)
    b32 = bricked_blocks(g32, CODEC_ZSTD)
    b32[0].codec = CODEC_MASKED
    b32[0].stored = struct.pack("<HBB", 0, 0, 0)
    data, _ = assemble(g32, [meta_block(DEFAULT_META)] + b32, structure_kind=KIND_BRICKED, ireserved=2, **framed)
    add_invalid("bricked_float32_codec4", data, "malformed", "codec4.where",
                "A bricked grid of float32 values whose brick has codec 4, which holds 16-bit values only.")


# ------------------------------------- stored levels of detail (stream 7, 1.3 draft)

def lod_level_blocks(arr, enc, b, k, codec=CODEC_PLANES, **pred):
    """§8A.5: the blocks of stream 7 that store level of detail k, the array
    `arr` ([z][y][x], m_z x m_y x m_x): the level as a bricked grid of its own
    sizes m_a with the file's brick edge 2^b (§8A.4 with m_a for size_a), one
    brick per block, ignorable flag set, `level` k.  codec and pred as in
    bricked_blocks (codec 3 and 4 payloads of the level's bricks)."""
    blocks = bricked_blocks(write_bricked(arr, enc, b), codec, **pred)
    for blk in blocks:
        blk.stream, blk.level, blk.flags = STREAM_LOD, k, 1
    return blocks


def merge_masked_run(blocks, q0, q1, background=None):
    """Blocks q0 .. q1 - 1 (whole bricks that follow one another) as one codec
    4 block (§7.3), with the run's most common value as background unless
    given; stream, level and flags of the first."""
    part = blocks[q0:q1]
    vals = [v for b in part for v in struct.unpack("<%dH" % b.count, b.data)]
    merged = Blk(part[0].stream, part[0].level, part[0].first, len(vals), b"".join(b.data for b in part),
                 codec=CODEC_MASKED, flags=part[0].flags)
    bg = background if background is not None else max(sorted(set(vals)), key=vals.count)
    merged.stored = masked_payload(vals, bg)
    blocks[q0:q1] = [merged]


def merge_background_runs(blocks, background):
    """Every run of two or more blocks that follow one another and hold the
    background alone becomes one codec 4 block (form 0), as §15 recommends.
    Returns the runs merged, as (first block, end) of the original numbering."""
    alone = [all(v == background for v in struct.unpack("<%dH" % b.count, b.data)) for b in blocks]
    runs, q = [], 0
    while q < len(blocks):
        e = q
        while e < len(blocks) and alone[e]:
            e += 1
        if e - q >= 2:
            runs.append((q, e))
        q = max(e, q + 1)
    for q0, q1 in reversed(runs):
        merge_masked_run(blocks, q0, q1, background)
    return runs


def gen_stored_lods():
    """§8A.5 (1.3 draft): bricked grids that store levels of detail in stream 7,
    then files that break one rule of §6.4 / §8A.5 each, and files of other
    kinds where stream 7 is an unknown stream.  The stored levels are computed
    from the dense source by flat_lods (§12.3); the expected outputs of the
    valid files too (add_valid), never from the stored blocks."""
    framed = dict(framed=True, minor=3)
    rng = np.random.default_rng(2301)

    def lods_file(src, enc, b, levels, values=None, mutate=None, lods_first=False, lods=None, **kw):
        """A framed bricked grid: the metadata, the values bricks (codec and
        predictor settings `values`, default codec 3), then for each k of
        `levels` ({k: dict(codec=..., runs=background or None, predictor
        settings)}) the blocks of stream 7 of level k.  mutate(lod) may change
        the dict k -> blocks of stream 7 before the file is assembled."""
        g = write_bricked(src, enc, b)
        v = dict(values or {})
        background = v.pop("runs", None)
        blocks = bricked_blocks(g, v.pop("codec", CODEC_PREDICTED), **v)
        if background is not None:
            merge_background_runs(blocks, background)
        lods = lods if lods is not None else flat_lods(src, enc, g.D)
        lod = {}
        for k, how in sorted(levels.items()):
            how = dict(how)
            background = how.pop("runs", None)
            lod[k] = lod_level_blocks(lods[k], enc, b, k, how.pop("codec", CODEC_PLANES), **how)
            if background is not None:
                merge_background_runs(lod[k], background)
        if mutate:
            mutate(lod)
        stream7 = [blk for k in sorted(lod) for blk in lod[k]]
        if lods_first:
            blocks = list(reversed(stream7)) + blocks + [meta_block(DEFAULT_META)]
        else:
            blocks = [meta_block(DEFAULT_META)] + blocks + stream7
        data, _ = assemble(g, blocks, structure_kind=KIND_BRICKED, ireserved=b, **dict(framed, **kw))
        return data

    def valid(name, src, enc, b, levels, desc, **kw):
        add_valid(name, lods_file(src, enc, b, levels, **kw), src, enc, desc, kind=KIND_BRICKED,
                  extra={"brick_log2": b, "stored_levels": sorted(levels)})

    def ball(X, Y, Z, centre, radius, background, inside):
        z, y, x = np.mgrid[0:Z, 0:Y, 0:X]
        d2 = (x - centre[0]) ** 2 + (y - centre[1]) ** 2 + (z - centre[2]) ** 2
        return np.where(d2 <= radius * radius, inside, background).astype(np.uint16)

    # ---- valid
    src = rng.integers(0, 65536, (5, 7, 9)).astype(np.uint16)
    valid("bricked_lods_9x7x5_uint16_all_levels", src, UINT16, 1,
          {k: dict(codec=CODEC_PREDICTED, value_map=0) for k in range(1, 5)},
          "Bricked grid 9x7x5 uint16 (value_scale 0.5, value_offset -1000), bricks of 2, storing every level "
          "of detail k = 1 .. D = 4 in stream 7 (§8A.5; ignorable flag, level k): level k is a bricked grid "
          "of its own, ceil(size / 2^k) = 5x4x3, 3x2x2, 2x1x1, 1x1x1, with bricks of 2 (edge bricks of 1), "
          "each brick one codec 3 block. Random values: the means (of the decoded integers, not the "
          "physical values) have many ties, rounded to even.",
          values=dict(value_map=0), scale=0.5, offset=-1000.0)

    vals = np.round(rng.normal(0.4, 0.2, 13 * 6 * 11), 3)
    src = arr_f16(vals, (11, 6, 13))
    src[4:8, 0:4, 4:8] = 0x8000                      # a level-2 cell of -0: +0 in levels 2 ..
    src[0:4, 0:4, 8:12] = 0x0001                     # a cell of the smallest subnormal
    src[9, 5, 12] = 0x7C01                           # a NaN payload: the canonical NaN above it
    valid("bricked_lods_13x6x11_binary16_levels_2_up", src, BINARY16, 2,
          {2: dict(codec=CODEC_PREDICTED), 3: dict(codec=CODEC_PLANES), 4: dict(codec=CODEC_STORED)},
          "Bricked grid 13x6x11 binary16, bricks of 4, storing levels 2, 3 and 4 (= D) only, not level 1: "
          "level 2 (4x2x3, one brick) codec 3 with the binary16 order map, level 3 (2x1x2) codec 2, level 4 "
          "(1x1x1) codec 0. A 4x4x4 cell of -0 is +0 at level 2 and a NaN 0x7C01 gives the canonical NaN "
          "0x7E00 in every level above it (§12.3, no leaf exception); the stored levels hold exactly those "
          "bits. Level 1 is computed from full resolution.")

    inside = arr_f16(np.round(rng.normal(0.7, 0.15, 24 * 20 * 18), 3), (18, 20, 24))
    src = ball(24, 20, 18, (5.0, 5.5, 4.5), 4.6, 0x8000, inside)
    valid("bricked_lods_24x20x18_binary16_masked", src, BINARY16, 2,
          {1: dict(codec=CODEC_MASKED, runs=0x0000), 2: dict(codec=CODEC_MASKED),
           3: dict(codec=CODEC_PREDICTED), 4: dict(codec=CODEC_PREDICTED, value_map=0),
           5: dict(codec=CODEC_STORED)},
          "Bricked grid 24x20x18 binary16, bricks of 4, a ball of values in a background of -0 (0x8000), "
          "the values bricks codec 4 with runs of background bricks in one block each; storing every level: "
          "level 1 (12x10x9, 27 bricks) codec 4 with background +0 (the mean of -0 voxels, §12.3), its runs "
          "of bricks of +0 alone as single codec 4 blocks of form 0 (§7.3), level 2 (6x5x5) codec 4 one brick "
          "per block, levels 3 (3x3x3) and 4 (2x2x2) codec 3, level 5 (1x1x1) codec 0.",
          values=dict(codec=CODEC_MASKED, runs=0x8000))

    src = (rng.integers(0, 4000, (2, 3, 17)) + 20000).astype(np.uint16)
    valid("bricked_lods_17x3x2_uint16_blocks_first", src, UINT16, 2,
          {k: dict(codec=CODEC_ZSTD) for k in range(1, 6)},
          "Bricked grid 17x3x2 uint16, bricks of 4, depth 5, storing every level (9x2x1, 5x1x1, 3x1x1, "
          "2x1x1, 1x1x1; zstd), its stream 7 blocks at the start of the file in reverse order and the "
          "metadata last: blocks of stream 7 may lie anywhere (§8A.5, §6.3).",
          values=dict(codec=CODEC_PLANES), lods_first=True)

    src = arr_f32(rng.normal(3.0, 2.0, 10 * 9 * 7), (7, 9, 10))
    _order_sensitive_cells_f32(src)
    valid("bricked_lods_10x9x7_float32_levels_1_and_3", src, FLOAT32, 1,
          {1: dict(codec=CODEC_PLANES), 3: dict(codec=CODEC_STORED)},
          "Bricked grid 10x9x7 float32, bricks of 2, storing levels 1 (codec 2) and 3 (codec 0), not 2 "
          "and 4: a level may be absent. Level 1 holds cells of 2^60, -2^60 and 1s whose mean depends on "
          "the order of the sum (§12.3: binary64 from +0.0, z, then y, then x): (0,0,0) = 0.625, "
          "(1,0,0) = 0.75, (3,1,0) = +0, as in regular_16_float32.",
          values=dict(codec=CODEC_ZSTD))

    src = rng.integers(100, 200, (3, 5, 6)).astype(np.uint16)
    valid("bricked_lods_6x5x3_uint16_brick_8", src, UINT16, 3,
          {k: dict(codec=CODEC_STORED) for k in range(1, 4)},
          "Bricked grid 6x5x3 uint16, bricks of 8 (byte 11 = 3), larger than the volume and every level: "
          "each level (3x3x2, 2x2x1, 1x1x1) is one brick, one codec 0 block.",
          values=dict(codec=CODEC_STORED))

    # ---- stream 7 outside a bricked grid: an unknown stream (§6.4)
    base = vol_object_in_air(6, 5, 4, UINT16, 107, 100, (2.0, 2.0, 1.5), 2.2, 1000, 2000)
    t = build_tree(base, UINT16)

    def octree_with_stream_7(flags):
        bl = level_blocks(t, CODEC_ZSTD)
        bl.insert(2, Blk(STREAM_LOD, 9, 0, 3, b"not a stored level", codec=CODEC_PREDICTED, flags=flags))
        bl.append(meta_block(DEFAULT_META))
        return assemble(t, bl)[0]
    add_valid("octree_ignorable_stream_7", octree_with_stream_7(1), base, UINT16,
              "The 6x5x4 uint16 octree of ignorable_stream_200 (version_minor 0) with an ignorable block of "
              "stream 7 (level 9 > D, codec 3, 3 elements, 18 stored bytes that are no codec 3 payload): "
              "stream 7 is known only in files of structure_kind 5 (§6.4), so here it is an unknown stream, "
              "skipped, whose level, codec and element_count mean nothing.")
    src = rng.integers(0, 60000, (3, 4, 5)).astype(np.uint16)
    g = write_regular(src, UINT16)
    wrong = Blk(STREAM_LOD, 1, 0, 12, pack_values(UINT16, [0xFFFF] * 12), codec=CODEC_STORED, flags=1)
    d, *_ = grid_file(g, limit=32, meta_first=True, mutate_blocks=lambda bl: bl.append(wrong), **framed)
    add_valid("regular_ignorable_stream_7", d, src, UINT16,
              "Framed regular grid 5x4x3 uint16 (structure_kind 2) with an ignorable block of stream 7, level "
              "1, 12 elements (3x2x2, the size of level 1) of 0xFFFF: not the level of detail, but stream 7 "
              "is an unknown stream outside structure_kind 5 (§6.4): skipped, never compared.",
              kind=KIND_REGULAR)

    # ---- invalid: one rule broken each.  Base: 7x6x5 uint16, bricks of 2,
    # levels 1 (4x3x3: 8 bricks), 2 (2x2x2: one brick) and 3 stored, codec 2.
    src = rng.integers(900, 1100, (5, 6, 7)).astype(np.uint16)
    src[0:2, 0:2, 0:2] = [[[1000, 1000], [1000, 1000]], [[1000, 1000], [1000, 1004]]]   # mean 1000.5
    every = {k: dict(codec=CODEC_PLANES) for k in (1, 2, 3)}
    lods = flat_lods(src, UINT16, 3)
    assert lods[1][0, 0, 0] == 1000                  # the tie rounds to even
    read_ivol(lods_file(src, UINT16, 1, every))      # the base itself is valid

    def inv(name, expect, tag, desc, mutate, verify_only=False, **kw):
        add_invalid(name, lods_file(src, UINT16, 1, every, mutate=mutate, **kw), expect, tag, desc,
                    verify_only=verify_only, dense_src=src if verify_only else None)

    def add_level(k, arr):
        return lambda lod: lod.__setitem__(k, lod_level_blocks(arr, UINT16, 1, k))
    inv("bricked_lods_level_0", "malformed", "lod.level",
        "Base (7x6x5 uint16, bricks of 2, levels 1 .. 3 stored in stream 7, codec 2) with a level 0 in "
        "stream 7 as well: the full-resolution bricks again, ignorable, level 0. Stored levels are "
        "1 <= k <= D (§8A.5).", add_level(0, src))
    inv("bricked_lods_level_above_depth", "malformed", "lod.level",
        "Base with a stored level 4 > D = 3: one brick of one element (ceil(size / 16) = 1x1x1) holding "
        "the mean of the volume (§8A.5: 1 <= k <= D).", add_level(4, lods[3]))

    def set_flags(lod):
        lod[2][0].flags = 0
    inv("bricked_lods_not_ignorable", "malformed", "lod.flags",
        "Base whose block of stored level 2 has flags 0: stream 7 blocks MUST have the ignorable flag "
        "set (§6.4, §8A.5); a reader that knows stream 7 reports malformed (one that does not, an older "
        "1.3 draft reader, unsupported-feature).", set_flags)
    inv("bricked_lods_level_gap", "malformed", "lod.coverage",
        "Base without the fourth brick of level 1 (a gap: a level is stored whole or not at all).",
        lambda lod: lod[1].pop(3))
    inv("bricked_lods_level_overlap", "malformed", "lod.coverage",
        "Base with the third brick of level 1 stored twice (two identical blocks: an overlap).",
        lambda lod: lod[1].insert(3, copy.copy(lod[1][2])))

    def two_bricks(lod):
        a, b = lod[1][0], lod[1][1]
        lod[1][0:2] = [Blk(STREAM_LOD, 1, a.first, a.count + b.count, a.data + b.data, codec=CODEC_PLANES,
                           flags=1)]
    inv("bricked_lods_two_bricks_in_a_block", "malformed", "lod.block",
        "Base whose first block of level 1 holds its first two bricks (codec 2; the coverage holds): one "
        "brick of the level per block (§8A.5).", two_bricks)

    def split(lod):
        a = lod[1][0]
        h = a.count // 2
        lod[1][0:1] = [Blk(STREAM_LOD, 1, a.first, h, a.data[:2 * h], codec=CODEC_STORED, flags=1),
                       Blk(STREAM_LOD, 1, a.first + h, a.count - h, a.data[2 * h:], codec=CODEC_STORED, flags=1)]
    inv("bricked_lods_brick_split_in_two", "malformed", None,
        "Base whose first brick of level 1 is split over two blocks (codec 0; the coverage holds).", split)

    def run_inside(lod):
        bl = lod[1]
        merge_masked_run(bl, 0, 3)
        r = bl[0]
        vals = list(struct.unpack("<%dH" % r.count, r.data))
        cut = bricked_order((4, 3, 3), 1)[2][0] + 2          # bricks 0 and 1, 2 values of brick 2
        first = Blk(STREAM_LOD, 1, r.first, cut, r.data[:2 * cut], codec=CODEC_MASKED, flags=1)
        first.stored = masked_payload(vals[:cut], vals[0])
        rest = Blk(STREAM_LOD, 1, r.first + cut, r.count - cut, r.data[2 * cut:], codec=CODEC_MASKED, flags=1)
        rest.stored = masked_payload(vals[cut:], vals[cut])
        bl[0:1] = [first, rest]
    inv("bricked_lods_codec4_run_ends_inside_a_brick", "malformed", "codec4.run",
        "Base whose level 1 starts with a codec 4 block holding bricks 0 and 1 and the first 2 elements of "
        "brick 2 of the level, and a codec 4 block of the rest of brick 2 (the coverage holds): a run ends "
        "at a brick of its level (§7.3, §8A.5).", run_inside)

    def stored_size_over_bound(lod):
        blk = lod[2][0]
        blk.codec = CODEC_ZSTD
        blk.stored = padded_zframe(blk.data, zstd_bound(len(blk.data)) + 1)
    inv("bricked_lods_stored_size_over_bound", "malformed", "block.stored_bound",
        "Base whose level 2 block (8 elements, 16 bytes) is a valid zstd frame (codec 1) padded with empty "
        "raw blocks to more than ZSTD_compressBound(16) = 79 bytes (stored_size 114 > 79 + 32): the limits "
        "of §7 apply to stream 7 as to a values block of that many elements (§8A.5), unlike an unknown "
        "stream.", stored_size_over_bound)

    def bad_crc(lod):
        lod[1][1].ov = {"crc": crc32c(lod[1][1].stored_bytes()) ^ 1}
    inv("bricked_lods_crc", "checksum", "block.crc",
        "Base whose second block of level 1 has a wrong crc in its index entry (block header and payload "
        "CRCs hold): a verifying reader checks every block it reads, stream 7 included.", bad_crc)

    half_up = {k: a.copy() for k, a in lods.items()}
    half_up[1][0, 0, 0] = 1001
    inv("bricked_lods_value_rounded_half_up", "malformed", "lod.value",
        "Base whose stored level 1 holds 1001 at (0, 0, 0), where the mean of the cell's voxels "
        "(7 x 1000 and 1004) is 1000.5, rounded to even: 1000 (§9, §12.3). Only a reader that verifies "
        "stored levels (§8A.5, §13) refuses it; a reader that does not trusts it, and its dense export is "
        "the given one.", None, verify_only=True, lods=half_up)

    # binary16: -0 and a NaN payload are averaged at every level >= 1
    vals = np.round(rng.normal(0.25, 0.1, 6 * 6 * 5), 3)
    src16 = arr_f16(vals, (5, 6, 6))
    src16[0:2, 0:2, 0:2] = 0x8000
    src16[0:2, 0:2, 2:4] = 0x7C01
    lods16 = flat_lods(src16, BINARY16, 3)
    assert lods16[1][0, 0, 0] == 0x0000 and lods16[1][0, 0, 1] == 0x7E00
    for name, x, bits, what in (("negative_zero", 0, 0x8000, "-0 (0x8000) where the mean of the cell's "
                                 "eight -0 voxels is +0.0 + -0 + ... = +0 (0x0000)"),
                                ("nan_payload", 1, 0x7C01, "the NaN 0x7C01 of the cell's eight voxels, "
                                 "where the mean encodes to the canonical NaN 0x7E00")):
        changed = {k: a.copy() for k, a in lods16.items()}
        changed[1][0, 0, x] = bits
        data = lods_file(src16, BINARY16, 1, {k: dict(codec=CODEC_PREDICTED) for k in (1, 2, 3)},
                         lods=changed)
        add_invalid("bricked_lods_value_" + name, data, "malformed", "lod.value",
                    "Bricked grid 6x6x5 binary16, bricks of 2, levels 1 .. 3 stored (codec 3), whose stored "
                    "level 1 keeps at (%d, 0, 0) %s (§12.3: no leaf exception in a grid), as a writer that "
                    "copies uniform cells would. Only a verifying reader refuses it." % (x, what),
                    verify_only=True, dense_src=src16)

    f32src = arr_f32(rng.normal(0, 1, 5 * 4 * 3), (3, 4, 5))
    f32lods = flat_lods(f32src, FLOAT32, 3)

    def f32_codec3(lod):
        blk = lod[2][0]
        blk.codec = CODEC_PREDICTED
        blk.stored = predicted_payload([v & 0xFFFF for v in struct.unpack("<%dI" % blk.count, blk.data)],
                                       (blk.count, 1, 1), value_map=0)
    data = lods_file(f32src, FLOAT32, 1, {k: dict(codec=CODEC_PLANES) for k in (1, 2, 3)},
                     values=dict(codec=CODEC_PLANES), mutate=f32_codec3, lods=f32lods)
    add_invalid("bricked_lods_float32_codec3", data, "malformed", "codec3.where",
                "Bricked grid 5x4x3 float32 storing levels 1 .. 3, whose level 2 block has codec 3: codecs "
                "3 and 4 are valid on stream 7 blocks only in a grid of 16-bit values (§7).")

    def f32_codec4(lod):
        blk = lod[1][0]
        vals = [v & 0xFFFF for v in struct.unpack("<%dI" % blk.count, blk.data)]
        blk.codec = CODEC_MASKED
        blk.stored = masked_payload(vals, vals[0])
    data = lods_file(f32src, FLOAT32, 1, {k: dict(codec=CODEC_PLANES) for k in (1, 2, 3)},
                     values=dict(codec=CODEC_PLANES), mutate=f32_codec4, lods=f32lods)
    add_invalid("bricked_lods_float32_codec4", data, "malformed", "codec4.where",
                "Bricked grid 5x4x3 float32 storing levels 1 .. 3 (codec 2), whose first block of level 1 "
                "(one brick of 8 elements) has codec 4 (a valid form 1 payload of the elements' low 16 "
                "bits): codec 4 is valid only where codec 3 is, on stream 3 and 7 blocks of a grid of "
                "16-bit values (§7, §8A.5: \"codecs 3 and 4 only with value_encoding 1 or 2\"), checked "
                "with the block table.")
    add_invalid("octree_not_ignorable_stream_7", octree_with_stream_7(0), "unsupported-feature", "stream",
                "octree_ignorable_stream_7 with the block of stream 7 not ignorable (flags 0): outside "
                "structure_kind 5 stream 7 is an unknown stream, and a non-ignorable block of an unknown "
                "stream makes the reader refuse the file (§6.4).")

    # codec 3 with entropy coder 2 (§7.2.1) in stream 7; own generator, so the vectors above keep their bytes
    rng2 = np.random.default_rng(2402)
    src = (2000 + 37 * np.arange(13)[None, None, :] - 21 * np.arange(10)[None, :, None]
           + 15 * np.arange(9)[:, None, None] + rng2.integers(0, 60, (9, 10, 13))).astype(np.uint16)
    levels = {1: dict(codec=CODEC_PREDICTED, entropy=2, value_map=0),
              2: dict(codec=CODEC_PREDICTED, entropy=2, value_map=0, shift=2, taps=(3, 3, 2, -2, -2, -1, 1),
                      level=5),
              3: dict(codec=CODEC_PREDICTED, entropy=1, value_map=0),
              4: dict(codec=CODEC_PREDICTED, entropy=2, value_map=0)}
    valid("bricked_lods_13x10x9_uint16_entropy2", src, UINT16, 2, levels,
          "Bricked grid 13x10x9 uint16, bricks of 4, values codec 3 with entropy coder 2 (§7.2.1), storing "
          "every level of detail in stream 7 as codec 3 bricks: levels 1 (7x5x5: bricks 4x4x4 .. 3x1x1), "
          "2 (4x3x3, one brick; shift 2, taps 3, 3, 2, -2, -2, -1, 1, level 5) and 4 (1x1x1) with entropy "
          "coder 2, level 3 (2x2x2) with entropy coder 1. The contexts of a level's brick use the "
          "level's brick extents, which differ from the volume's bricks at the same brick coordinates.",
          values=dict(value_map=0, entropy=2))

    # float32 (value_encoding 3) with NaN and infinities in stored levels; own generator as well
    rng3 = np.random.default_rng(2502)
    src = smooth_f32(16, 12, 10, rng3)
    put_bits(src, {(13, 9, 7): 0x7FC01234,           # NaN payload: level-1 cell (6, 4, 3)
                   (2, 1, 1): 0x7F800000,            # +inf: level-1 cell (1, 0, 0), level-2 cell (0, 0, 0)
                   (5, 2, 2): 0xFF800000})           # -inf: level-1 cell (2, 1, 1), level-2 cell (1, 0, 0)
    src[0:2, 0:2, 8:10] = 0x80000000                 # level-1 cell (4, 0, 0): eight -0
    src[0:2, 0:2, 10:12] = [0x7F7FFFFF, 0x7F7FFFFE]  # (5, 0, 0): largest finite and the one below
    src[0:2, 0:2, 12:14] = [0x00000001, 0x00000002]  # (6, 0, 0): subnormals, mean 1.5 * 2^-149
    src[0:2, 0:2, 14:16] = [0x00000001, 0x00000000]  # (7, 0, 0): mean 2^-150
    lods = flat_lods(src, FLOAT32, 4)
    nan, inf, ninf = 0x7FC00000, 0x7F800000, 0xFF800000
    assert [int(v) for v in lods[1][0, 0, 4:8]] == [0, 0x7F7FFFFE, 2, 0]
    assert lods[1][0, 0, 1] == inf and lods[1][1, 1, 2] == ninf and lods[1][3, 4, 6] == nan
    assert lods[2][0, 0, 0] == inf and lods[2][0, 0, 1] == ninf and lods[2][1, 2, 3] == nan
    assert lods[3][0, 0, 0] == nan and lods[3][0, 1, 1] == nan and lods[4][0, 0, 0] == nan
    assert all(decode(FLOAT32, v) == decode(FLOAT32, v) for v in (lods[3][0, 0, 1], lods[3][1].reshape(-1)[0]))
    valid("bricked_lods_16x12x10_float32_nan_inf", src, FLOAT32, 2,
          {2: dict(codec=CODEC_PLANES), 3: dict(codec=CODEC_ZSTD), 4: dict(codec=CODEC_STORED)},
          "Bricked grid 16x12x10 float32, bricks of 4, values codec 2, storing levels 2 (4x3x3, one brick; "
          "codec 2), 3 (2x2x2; codec 1) and 4 (= D, 1x1x1; codec 0), not level 1 (§8A.5). Values per "
          "§12.3 (binary64 sum from +0.0, z, y, x; divided by the count; encoded once, §9): a NaN "
          "0x7FC01234 gives the canonical NaN 0x7FC00000 in its cells of every level; +inf and -inf in "
          "different level-2 cells give +inf and -inf at levels 1 and 2 and, meeting in level-3 cell "
          "(0, 0, 0), inf + -inf = NaN (0x7FC00000); level 4 is NaN. Level-1 cells of eight -0 (mean "
          "+0), of four 0x7F7FFFFF and four 0x7F7FFFFE (mean a tie, rounded to even 0x7F7FFFFE; a "
          "binary32 sum would overflow), of four 0x00000001 and four 0x00000002 (1.5 * 2^-149, to even: "
          "0x00000002) and of four 0x00000001 and four +0 (2^-150, to even: +0). Level 1 is computed from "
          "full resolution, the others may be read from stream 7: same bits.",
          values=dict(codec=CODEC_PLANES), lods=lods)


# --------------------------------- codec 3 with entropy coder 2 (§7.2.1, 1.3 draft)

def gen_entropy2():
    """§7.2.1 (1.3 draft): bricked grids whose codec 3 blocks code their
    residuals with entropy coder 2 (rANS over tokens with contexts), then
    files whose first codec 3 block breaks one rule of §7.2.1 each.  Own
    random generator, so that the vectors before it keep their bytes."""
    rng = np.random.default_rng(2401)

    def bricked_file(src, enc, b, codec=CODEC_PREDICTED, mutate=None, **pred):
        return framed_bricked_file(src, enc, b, codec, mutate, **pred)

    def valid(name, src, enc, b, desc, lods=True, **kw):
        add_valid_bricked(name, bricked_file(src, enc, b, **kw), src, enc, b, desc, lods)

    smooth = lambda X, Y, Z, lo, step: (lo + step * (np.arange(X)[None, None, :] + 2 * np.arange(Y)[None, :, None]
                                                     + 3 * np.arange(Z)[:, None, None]))
    # ---- valid
    src = (smooth(9, 5, 5, 2000, 9) + rng.integers(0, 6, (5, 5, 9))).astype(np.uint16)
    shapes = sorted({e for _, e, _ in bricked_order((9, 5, 5), 2)})
    assert (1, 1, 1) in shapes and (4, 1, 1) in shapes and (1, 4, 4) in shapes and len(shapes) == 8
    valid("bricked_entropy2_9x5x5_uint16_edge_bricks", src, UINT16, 2,
          "Bricked grid 9x5x5 uint16, bricks of 4, codec 3 (Lorenzo taps, identity map) with entropy "
          "coder 2 (§7.2.1: rANS over tokens with contexts) in every brick. The 12 bricks have the 8 "
          "extents %s: edge bricks of 1 voxel along one, two and all three axes (a 1x1x1 corner brick), "
          "where the context neighbours (x, y-1, z), (x, y, z-1), (x-1, y-1, z) and (x+1, y-1, z) fall "
          "outside the brick (bit length 0)." % ", ".join("%dx%dx%d" % e for e in shapes),
          value_map=0, entropy=2)

    vals = np.round(rng.normal(0.5, 0.3, 9 * 7 * 6), 3)
    src = arr_f16(vals, (6, 7, 9))
    flat = src.reshape(-1)
    flat[[0, 5, 17, 40, 77, 111, 200, 301, 302]] = [0x8000, 0x7E01, 0xFE77, 0x7C00, 0xFC00, 0x0001, 0x8001,
                                                    0x8000, 0x03FF]
    valid("bricked_entropy2_9x7x6_binary16_specials", src, BINARY16, 2,
          "Bricked grid 9x7x6 binary16, bricks of 4, codec 3 with the binary16 order map and entropy "
          "coder 2: -0, NaNs with payloads (0x7E01, 0xFE77), both infinities and subnormals (0x0001, "
          "0x8001, 0x03FF) come back bit for bit; their residuals are large tokens among small ones.",
          entropy=2)

    src = np.array([[[0x8000]]], np.uint16)
    one = predicted_payload([0x8000], (1, 1, 1), entropy=2)
    assert one[24 + 8:24 + 12] == b"\x00\x00\x80\x00" and e2_token(65534) == (31, 14, 16382)
    valid("bricked_entropy2_1x1x1_binary16", src, BINARY16, 1,
          "Bricked grid of one voxel (-0, mapped to 0x7FFF, predicted 0: residual 65534, token 31 with 14 "
          "bits below), codec 3 with entropy coder 2. With n = 1 only state X_0 codes a voxel: X_1 is "
          "never used and is 2^23 from the start (stream bytes 4 .. 7 = 00 00 80 00).", lods=False,
          entropy=2)

    # every token 0 .. 31 at both ends of its range, among random tokens
    ext = (8, 8, 4)
    n = 8 * 8 * 4
    ends = []
    for t in range(32):
        e = max(0, e2_bitlen(t) - 2)
        ends += [e2_residual(t, 0), e2_residual(t, (1 << e) - 1)]
    rest = []
    for t in rng.integers(0, 32, n - len(ends)):
        e = max(0, e2_bitlen(int(t)) - 2)
        rest.append(e2_residual(int(t), int(rng.integers(0, 1 << e)) if e else 0))
    zs = [int(z) for z in rng.permutation(np.array(ends + rest))]
    assert {e2_token(z)[0] for z in zs} == set(range(32)) and max(zs) == 65535
    src = np.array(values_from_residuals(zs, ext, value_map=0), np.uint16).reshape(4, 8, 8)
    assert predicted_residuals([int(v) for v in src.reshape(-1)], ext, value_map=0) == zs
    valid("bricked_entropy2_8x8x4_uint16_all_tokens", src, UINT16, 3,
          "Bricked grid 8x8x4 uint16, one brick of bricks of 8, codec 3 (Lorenzo, identity map) with "
          "entropy coder 2, whose values are made from chosen residuals: every token 0 .. 31 occurs, each "
          "at the lowest and the highest residual of its range (0, 1, 2, 3, 4 .. 5, 6 .. 7, ..., 32768 "
          "(token 30) .. 49151, 49152 .. 65535 (token 31), e = 0 .. 14 bits below), among random tokens "
          "with random bits: every bit length of the contexts and every width of the bits below.",
          value_map=0, entropy=2)

    # one brick of 32x16x16: contexts past m = 128, 256, 384 (tables made again)
    X, Y, Z = 32, 16, 16
    z, y, x = np.mgrid[0:Z, 0:Y, 0:X]
    inside = (x - 13.0) ** 2 + (y - 8.0) ** 2 + (z - 7.5) ** 2 <= 10.5 ** 2
    noise = rng.normal(0, 1, (Z, Y, X)) * (1 + 6 * x)          # noise grows along x: every context used
    part = 30000 + 40 * x + 25 * y - 30 * z + noise
    src = np.where(inside, np.clip(np.round(part), 0, 65535), 1000).astype(np.uint16)
    stats = {}
    predicted_payload([int(v) for v in src.reshape(-1)], (X, Y, Z), value_map=0, entropy=2, e2=dict(stats=stats))
    ms = stats["m"]
    assert min(ms) > 0 and max(ms) > 384 and sum(1 for m in ms if m > 128) >= 6 and stats["min_D"] < 0, stats
    valid("bricked_entropy2_32x16x16_uint16_one_brick", src, UINT16, 5,
          "Bricked grid 32x16x16 uint16, one brick (bricks of 32), codec 3 (Lorenzo, identity map) with "
          "entropy coder 2: a ball of a ramp with noise growing along x in a background of 1000. Its "
          "8192 voxels use all 12 contexts; %d of them code more than 128 tokens, the largest %d (so its "
          "table is made again at m = 4 .. 64, 128, 256, 384, ...; %d tables made in all, the 12 starting "
          "ones included), and the tables of "
          "the most used contexts have D < 0 (down to %d: counts of 1 give f = max(1, 0) = 1, so the "
          "largest frequency is lowered)."
          % (sum(1 for m in ms if m > 128), max(ms), stats["tables"], stats["min_D"]),
          value_map=0, entropy=2)

    vals = np.round(rng.normal(1.0, 0.5, 12 * 8 * 6), 2)
    src = arr_f16(vals, (6, 8, 12))
    src.reshape(-1)[[3, 50, 100, 333]] = [0x8000, 0x7C00, 0x7E00, 0x0000]
    per = lambda q: dict(entropy=1 + q % 2, value_map=q // 2 % 2, shift=q % 16,
                         taps=tuple(int(t) for t in rng.integers(-999, 999, 7)) if q % 3 else LORENZO,
                         level=int(rng.integers(-5000, 5000)) if q % 3 else 0)
    valid("bricked_entropy2_12x8x6_binary16_mixed_entropy", src, BINARY16, 2,
          "Bricked grid 12x8x6 binary16, 12 bricks of 4 (4x4x2 at the top), codec 3 in every brick, "
          "alternating entropy coder 1 (zstd over byte planes) and 2 (rANS) from brick to brick, each brick "
          "with its own value map, shift, taps and level (a writer keeps per brick the coder that is "
          "smaller, §7.2).", per_brick=per)

    # adversarial residuals: a correct entropy 2 coding larger than codec 3's limit (§7)
    ext = (8, 8, 8)
    n = 512
    model, B, zs = E2Model(), [0] * n, []
    for i, (x, y, z) in enumerate(_raster(ext)):
        k = e2_context(B, ext, x, y, z)
        f = model.f[k]
        t = max(range(32), key=lambda t: (max(0, e2_bitlen(t) - 2) * 4096 + 4096 * math.log2(4096 / f[t]), -t))
        e = max(0, e2_bitlen(t) - 2)
        zs.append(e2_residual(t, int(rng.integers(0, 1 << e)) if e else 0))
        B[i] = e2_bitlen(t)
        model.update(k, t)
    adv = np.array(values_from_residuals(zs, ext, value_map=0), np.uint16).reshape(8, 8, 8)
    over = predicted_payload([int(v) for v in adv.reshape(-1)], ext, value_map=0, entropy=2)
    limit = 24 + zstd_bound(2 * n)
    assert len(over) > limit
    assert len(predicted_payload([int(v) for v in adv.reshape(-1)], ext, value_map=0)) <= limit

    # ---- invalid: the first brick of a bricked grid breaks one rule of §7.2.1 each
    src = (smooth(6, 5, 4, 1000, 5) + rng.integers(0, 25, (4, 5, 6))).astype(np.uint16)
    good = dict(value_map=0, entropy=2)
    ext0 = bricked_order((6, 5, 4), 2)[0][1]
    base = predicted_payload([int(v) for v in write_bricked(src, UINT16, 2).values[:64]], ext0, **good)
    R0, stream0, bits0 = e2_split(base[24:])
    vals0 = [int(v) for v in write_bricked(src, UINT16, 2).values[:64]]
    zs0 = predicted_residuals(vals0, ext0, value_map=0)
    E0 = sum(e2_token(z)[1] for z in zs0)
    assert ext0 == (4, 4, 4) and R0 > 12 and 1 <= E0 % 8 <= 6, (R0, E0)
    # the three codings that break one check only: each decodes to the brick without that check
    for check, e2 in (("initial_state", dict(extra=1)), ("states_end", dict(start=(E2_LOW, E2_LOW + 1)))):
        bad = predicted_payload(vals0, ext0, e2=e2, **good)[24:]
        assert e2_decode(bad, ext0, skip=(check,)) == zs0
    R, s, b = e2_split(base[24:])
    assert e2_decode(struct.pack("<I", R + 1) + s + b"\x5a" + b, ext0, skip=("stream_left",)) == zs0

    def body(fn):                       # mutate the bytes after the codec header of the first brick
        def mutate(blocks):
            st = blocks[0].stored
            blocks[0].stored = st[:24] + fn(*e2_split(st[24:]))
        return mutate

    def join(R, stream, bits):
        return struct.pack("<I", R) + stream + bits

    def inv(name, expect, tag, desc, first=None, **kw):
        args = dict(good)
        if first is not None:           # settings of the first brick only
            args = dict(per_brick=lambda q: dict(good, **(first if q == 0 else {})))
        args.update(kw)
        add_invalid(name, bricked_file(src, UINT16, 2, **args), expect, tag, desc)

    head = ("Bricked grid 6x5x4 uint16, bricks of 4, codec 3 with entropy coder 2 in every brick, whose "
            "first brick (4x4x4, R = %d, %d bytes of bits below for E = %d bits) " % (R0, len(bits0), E0))
    inv("bricked_codec3_entropy2_stream_size_7", "malformed", "codec3.entropy2.stream_size_below_8",
        head + "says R = 7: the rANS stream holds at least the two 4-byte states (§7.2.1: 8 <= R).",
        mutate=body(lambda R, s, b: join(7, s, b)))
    inv("bricked_codec3_entropy2_stream_size_over_payload", "malformed",
        "codec3.entropy2.stream_size_over_payload",
        head + "says R = payload size - 27, one more than the payload holds (§7.2.1: R <= payload size - 28).",
        mutate=body(lambda R, s, b: join(R + len(b) + 1, s, b)))
    inv("bricked_codec3_entropy2_initial_state_below_2_23", "malformed", "codec3.entropy2.initial_state",
        head + "was coded with one byte more emitted before the last coding step of state X_1, so that "
               "X_1 (stream bytes 4 .. 7) starts below 2^23 (§7.2.1: each MUST be >= 2^23); a decoder "
               "that did not check it would read that byte back in its first renormalisation and decode "
               "the brick exactly, with both states ending at 2^23 and every byte read.",
        first=dict(e2=dict(extra=1)))
    inv("bricked_codec3_entropy2_initial_state_2_31", "malformed", "codec3.entropy2.initial_state",
        head + "has bit 31 of state X_1 (stream bytes 4 .. 7) set: X_1 starts at 2^31 or more (§7.2.1: each "
               "MUST lie in 2^23 .. 2^31 - 1, the range an encoder's states end in, so that each list of "
               "residuals has one coding). The first check that fails; what the brick would decode to "
               "without it is not meant to be anything.",
        mutate=body(lambda R, s, b: join(R, s[:7] + bytes([s[7] | 0x80]) + s[8:], b)))
    inv("bricked_codec3_entropy2_states_end", "malformed", "codec3.entropy2.states_end",
        head + "was coded with state X_1 starting at 2^23 + 1 instead of 2^23: the decoder reads every "
               "byte of the stream and ends with X_0 = 2^23 but X_1 = 2^23 + 1 (§7.2.1: both MUST equal "
               "2^23).", first=dict(e2=dict(start=(E2_LOW, E2_LOW + 1))))
    inv("bricked_codec3_entropy2_stream_byte_left", "malformed", "codec3.entropy2.stream_left",
        head + "has one byte more at the end of its rANS stream (R + 1, bits below unchanged): the "
               "states end at 2^23 with that byte unread (§7.2.1: all R bytes MUST have been read).",
        mutate=body(lambda R, s, b: join(R + 1, s + b"\x5a", b)))
    inv("bricked_codec3_entropy2_stream_ends_early", "malformed", "codec3.entropy2.stream_end",
        head + "lacks the last byte of its rANS stream (R - 1, bits below unchanged): the decoder's "
               "last renormalisation finds the stream ended (§7.2.1 step 3).",
        mutate=body(lambda R, s, b: join(R - 1, s[:-1], b)))
    inv("bricked_codec3_entropy2_bits_short", "malformed", "codec3.entropy2.bits_size",
        head + "lacks the last byte of its bits below: ceil(E / 8) - 1 bytes (§7.2.1: exactly the bytes "
               "the tokens need).", mutate=body(lambda R, s, b: join(R, s, b[:-1])))
    inv("bricked_codec3_entropy2_bits_long", "malformed", "codec3.entropy2.bits_size",
        head + "has a zero byte after its bits below: ceil(E / 8) + 1 bytes (§7.2.1: exactly the bytes "
               "the tokens need).", mutate=body(lambda R, s, b: join(R, s, b + b"\0")))
    inv("bricked_codec3_entropy2_padding_bit", "malformed", "codec3.entropy2.padding",
        head + "has bit 7 of the last byte of its bits below set, a padding bit (E mod 8 = %d, so bits "
               "%d .. 7 of that byte are padding; §7.2.1: they are 0)." % (E0 % 8, E0 % 8),
        mutate=body(lambda R, s, b: join(R, s, b[:-1] + bytes([b[-1] | 0x80]))))
    inv("bricked_codec3_entropy2_short", "malformed", "codec3.entropy2.short",
        head + "is cut to 27 bytes, the codec header and 3 bytes: too short for R (§7.2.1: 28 + R <= "
               "payload size).", mutate=lambda blocks: setattr(blocks[0], "stored", blocks[0].stored[:27]))
    inv("bricked_codec3_entropy_4", "unsupported-feature", "codec3.entropy",
        head + "has entropy (payload byte 3) 4, not defined (§7.2 defines 1, 2 and 3: unsupported-feature); "
               "the bytes after the header are its valid entropy 2 coding. (Before §7.2.2 this file had "
               "entropy 3 and was named bricked_codec3_entropy_3.)",
        mutate=lambda blocks: setattr(blocks[0], "stored",
                                      blocks[0].stored[:3] + b"\x04" + blocks[0].stored[4:]))
    add_invalid("bricked_codec3_entropy2_over_bound",
                bricked_file(adv, UINT16, 3, value_map=0, entropy=2), "malformed", "block.stored_bound",
                "Bricked grid 8x8x8 uint16, one brick, codec 3 with entropy coder 2, whose residuals were "
                "chosen against the adaptive model (each voxel's token the one that costs most, "
                "bits below included, under its context's current table): a correct §7.2.1 coding of %d "
                "bytes, more than codec 3's limit 24 + bound(2n) = %d (§7; its entropy 1 payload fits). The stored_size rule is checked from "
                "the block table, whatever the coder." % (len(over), limit))


# --------------------------------- codec 3 with entropy coder 3 (§7.2.2, 1.3 draft)

def gen_entropy3():
    """§7.2.2 (1.3 draft): bricked grids whose codec 3 blocks code their
    residuals with entropy coder 3 (§7.2.1's tokens, contexts and bits below
    under frequencies stored per context, 32 rANS states renormalised by
    16-bit words), then files whose first codec 3 block breaks one rule of
    §7.2.2 each, and codings that exceed codec 3's limit of §7.  Own random
    generator, so that the vectors before it keep their bytes."""
    rng = np.random.default_rng(2603)

    def bricked_file(src, enc, b, codec=CODEC_PREDICTED, mutate=None, **pred):
        return framed_bricked_file(src, enc, b, codec, mutate, **pred)

    def valid(name, src, enc, b, desc, lods=True, **kw):
        add_valid_bricked(name, bricked_file(src, enc, b, **kw), src, enc, b, desc, lods)

    def limit(n):
        return 24 + zstd_bound(2 * n)        # §7: codec 3's limit on the payload (+ 32 for the block header)

    def brick_vals(src, enc, b, q):
        first, ext, _ = bricked_order((src.shape[2], src.shape[1], src.shape[0]), b)[q]
        n = ext[0] * ext[1] * ext[2]
        return [int(v) for v in write_bricked(src, enc, b).values[first:first + n]], ext

    def info(vals, ext, **kw):
        """(payload, tables_out) of the entropy 3 coding of one brick."""
        out = {}
        pl = predicted_payload(vals, ext, entropy=3, e3=dict(kw.pop("e3", {}), tables_out=out), **kw)
        return pl, out

    def from_rule(ext, rule):
        """Residuals chosen voxel by voxel (raster order): rule(k, x, y, z)
        gives the token of a voxel in context k; its bits below are random."""
        n = ext[0] * ext[1] * ext[2]
        B, zs = [0] * n, []
        for i, (x, y, z) in enumerate(_raster(ext)):
            t = rule(e2_context(B, ext, x, y, z), x, y, z)
            e = max(0, e2_bitlen(t) - 2)
            zs.append(e2_residual(t, int(rng.integers(0, 1 << e)) if e else 0))
            B[i] = e2_bitlen(t)
        return zs

    smooth = lambda X, Y, Z, lo, step: (lo + step * (np.arange(X)[None, None, :] + 2 * np.arange(Y)[None, :, None]
                                                     + 3 * np.arange(Z)[:, None, None]))
    e3u = dict(value_map=0, entropy=3)

    # ---- valid
    # edge bricks: extents of 1 along one axis in entropy 3, along two and three axes in entropy 2 (the limit of §7)
    size = (9, 9, 9)
    src = (smooth(9, 9, 9, 3000, 7) + (rng.random((9, 9, 9)) < 0.15)).astype(np.uint16)    # sparse noise
    order = bricked_order(size, 3)
    exts = [e for _, e, _ in order]
    big = [q for q, e in enumerate(exts) if e[0] * e[1] * e[2] >= 64]
    assert sorted(exts[q] for q in big) == [(1, 8, 8), (8, 1, 8), (8, 8, 1), (8, 8, 8)]
    small = {}
    for q, e in enumerate(exts):
        if q not in big:
            vals, _ = brick_vals(src, UINT16, 3, q)
            small[e] = (len(predicted_payload(vals, e, **e3u)), limit(len(vals)))
            assert small[e][0] > small[e][1]
    for q in big:
        vals, e = brick_vals(src, UINT16, 3, q)
        pl, out = info(vals, e, value_map=0)
        assert len(pl) <= limit(len(vals)) and any(f != [128] * 32 for f in out["F"]), (e, len(pl))
    valid("bricked_entropy3_9x9x9_uint16_edge_bricks", src, UINT16, 3,
          "Bricked grid 9x9x9 uint16, bricks of 8, codec 3 (Lorenzo taps, identity map). The bricks of 64 "
          "voxels and more use entropy coder 3 (§7.2.2): 8x8x8 and the edge bricks of extent 1 along one "
          "axis, 1x8x8 (context neighbours (x-1, y-1, z) and (x+1, y-1, z) outside the brick), 8x1x8 "
          "((x, y-1, z), (x-1, y-1, z), (x+1, y-1, z) outside: the context is from (x, y, z-1) alone) and "
          "8x8x1 ((x, y, z-1) outside). The edge bricks of extent 1 along two and three axes, 1x1x8, "
          "1x8x1, 8x1x1 and 1x1x1, use entropy coder 2, because their entropy 3 payloads exceed codec 3's "
          "limit 24 + bound(2n) (§7; %s): the tables, the 32 states and W alone take at least 134 bytes, so "
          "no brick of fewer than 36 voxels can use coder 3 (see bricked_codec3_entropy3_1x1x1_over_bound "
          "and bricked_entropy3_6x6x1_uint16_smallest_brick)."
          % "; ".join("%dx%dx%d: %d > %d bytes" % (e + small[e]) for e in sorted(small)),
          value_map=0, per_brick=lambda q: dict(value_map=0, entropy=3 if q in big else 2))
    edge_src, edge_exts, edge_big = src, exts, big

    # a column: bricks of extent 1 along two axes (x and y)
    walk = 20000 + np.cumsum(rng.integers(-3, 4, 128))
    src = walk.astype(np.uint16).reshape(128, 1, 1)
    pl, out = info(*brick_vals(src, UINT16, 6, 0), value_map=0)
    used = [k for k in range(12) if any(out["counts"][k])]
    valid("bricked_entropy3_1x1x128_uint16_column", src, UINT16, 6,
          "Bricked grid 1x1x128 uint16 (a column along z), bricks of 64: two bricks of extent 1x1x64 (extent "
          "1 along x and y), codec 3 (identity map; every prediction is the voxel one step back along z) "
          "with entropy coder 3. Each row is one voxel, so of the context neighbours only (x, y, z-1) lies "
          "in the brick: k = min(11, floor((B + 2) / 5)) from the bit length B of the voxel below (first "
          "brick: contexts %s used); each of the 32 states codes 2 voxels of a brick (z and z + 32)."
          % ", ".join(map(str, used)), **e3u)

    # rows of exactly 64 and 32 voxels
    src = (smooth(64, 2, 2, 9000, 3) + rng.integers(0, 30, (2, 2, 64))).astype(np.uint16)
    pl, out = info(*brick_vals(src, UINT16, 6, 0), value_map=0)
    valid("bricked_entropy3_64x2x2_uint16_rows_of_64", src, UINT16, 6,
          "Bricked grid 64x2x2 uint16, one brick of bricks of 64 (256 voxels), codec 3 (Lorenzo, identity "
          "map) with entropy coder 3: rows of exactly 64 voxels, so state X_j codes the voxels x = j and "
          "x = j + 32 of every row, 8 voxels each; the context neighbour (x+1, y-1, z) falls outside at "
          "x = 63 only. W = %d words, %d bytes of payload." % (out["W"], len(pl)), **e3u)

    vals = 0.25 + 0.002 * (np.arange(32)[None, None, :] - 3 * np.arange(4)[None, :, None]
                           + 5 * np.arange(2)[:, None, None]) + rng.normal(0, 0.003, (2, 4, 32))
    src = arr_f16(np.round(vals, 4).reshape(-1), (2, 4, 32))
    kw32 = dict(value_map=1, shift=2, taps=(3, 3, 2, -2, -2, -1, 1), level=-3, entropy=3)
    pl, out = info(*brick_vals(src, BINARY16, 5, 0), **{k: v for k, v in kw32.items() if k != "entropy"})
    valid("bricked_entropy3_32x4x2_binary16_rows_of_32", src, BINARY16, 5,
          "Bricked grid 32x4x2 binary16, one brick of bricks of 32 (256 voxels), codec 3 with the binary16 "
          "order map, shift 2, taps 3, 3, 2, -2, -2, -1, 1 and level -3, with entropy coder 3: rows of "
          "exactly 32 voxels, so state X_j codes column x = j of every row (8 voxels each). W = %d words."
          % out["W"], **kw32)

    # binary16 specials through the binary16 order map
    X, Y, Z = 12, 8, 8
    vals = 0.5 + 0.01 * (np.arange(X)[None, None, :] + np.arange(Y)[None, :, None] - np.arange(Z)[:, None, None]) \
        + rng.normal(0, 0.002, (Z, Y, X))
    src = arr_f16(np.round(vals, 4).reshape(-1), (Z, Y, X))
    specials = {(0, 0, 0): 0x8000, (3, 2, 1): 0x0000, (5, 5, 5): 0x7E01, (6, 1, 7): 0xFE77, (2, 7, 3): 0x7C00,
                (7, 3, 2): 0xFC00, (1, 1, 1): 0x0001, (4, 6, 6): 0x8001, (7, 7, 7): 0x03FF, (9, 4, 2): 0x8000,
                (10, 6, 5): 0x7C00, (11, 0, 7): 0x7D55, (8, 2, 4): 0x8000, (8, 3, 4): 0x0000, (8, 4, 4): 0x83FF}
    for (x, y, z), v in specials.items():
        src[z, y, x] = v
    for q in (0, 1):
        vv, e = brick_vals(src, BINARY16, 3, q)
        assert len(predicted_payload(vv, e, entropy=3)) <= limit(len(vv))
    valid("bricked_entropy3_12x8x8_binary16_specials", src, BINARY16, 3,
          "Bricked grid 12x8x8 binary16, bricks of 8 (8x8x8 and 4x8x8), codec 3 with the binary16 order map "
          "(value_map 1) and entropy coder 3: -0 (0x8000) and +0 next to each other, NaNs with payloads "
          "(0x7E01, 0xFE77, 0x7D55), both infinities and subnormals (0x0001, 0x8001, 0x03FF, 0x83FF) in a "
          "smooth field come back bit for bit; their residuals are large tokens among small ones.",
          entropy=3)

    # contexts with a single present token: f = 4096, the state does not change
    ext = (8, 8, 8)
    zs = from_rule(ext, lambda k, x, y, z: 20 if k == 0 else 31 if k == 11 else
                   int(rng.integers(max(2, 2 * k), 31)) if z >= 6 else int(rng.integers(max(2, 2 * k - 5), 2 * k + 2)))
    src = np.array(values_from_residuals(zs, ext, value_map=0), np.uint16).reshape(8, 8, 8)
    pl, out = info([int(v) for v in src.reshape(-1)], ext, value_map=0)
    cnt = out["counts"]
    assert [t for t in range(32) if cnt[0][t]] == [20] and [t for t in range(32) if cnt[11][t]] == [31]
    assert all(any(c) for c in cnt) and len(pl) <= limit(512)
    assert out["F"][0][20] == 4096 and out["F"][11][31] == 4096
    valid("bricked_entropy3_8x8x8_uint16_single_token_contexts", src, UINT16, 3,
          "Bricked grid 8x8x8 uint16, one brick, codec 3 (Lorenzo, identity map) with entropy coder 3, whose "
          "values are made from chosen residuals: all 12 contexts code voxels; context 0 (%d voxels) only "
          "token 20 (9 bits below) and context 11 (%d voxels) only token 31 (14 bits below), so each of their tables "
          "has a single present token, written as `present` alone (no a, no w: the last present token takes "
          "4096 - 0), f = 4096 and s = 0 (also s_31 of context 11: no token before it is present): coding "
          "such a voxel leaves its state "
          "unchanged (the encoder never emits, X >= 2^20 * 4096 = 2^32 being impossible; the decoder's "
          "X = 4096 * floor(X / 4096) + slot is X)." % (sum(cnt[0]), sum(cnt[11])), **e3u)

    # every residual 0 (a constant brick of 0), next to a constant brick of 1000
    src = np.zeros((8, 8, 16), np.uint16)
    src[:, :, 8:] = 1000
    pl0, out0 = info(*brick_vals(src, UINT16, 3, 0), value_map=0)
    pl1, out1 = info(*brick_vals(src, UINT16, 3, 1), value_map=0)
    assert e2_token(2000)[:2] == (21, 9) and predicted_residuals(brick_vals(src, UINT16, 3, 1)[0], (8, 8, 8),
                                                                  value_map=0) == [2000] + [0] * 511
    assert len(pl0) == 24 + 6 + 132 and out0["W"] == 0 and pl0[24 + 6:24 + 6 + 128] == struct.pack("<I", E3_LOW) * 32
    valid("bricked_entropy3_16x8x8_uint16_constant", src, UINT16, 3,
          "Bricked grid 16x8x8 uint16, two bricks of 8x8x8, codec 3 (Lorenzo, identity map) with entropy coder "
          "3. The first brick is all 0: every residual is 0, token 0 in context 0 only, so the tables are 44 "
          "bits in 6 bytes (used = 1 and present = bit 0 for context 0, used = 0 for the 11 others), every "
          "state stays 2^16, W = 0 and there are no bits below: a %d-byte payload (24 + 6 + 128 + 4). The "
          "second brick is all 1000: only voxel 0 has a residual (2000, token 21 with 9 bits below), the "
          "others 0 (%d bytes, W = %d)." % (len(pl0), len(pl1), out1["W"]), **e3u)

    # every token 0 .. 31, values over the whole 16-bit range
    ext = (8, 8, 8)
    n = 512
    ends = []
    for t in range(32):
        e = max(0, e2_bitlen(t) - 2)
        ends += [e2_residual(t, 0), e2_residual(t, (1 << e) - 1)]
    rest = []
    for t in rng.integers(0, 10, n - len(ends)):
        e = max(0, e2_bitlen(int(t)) - 2)
        rest.append(e2_residual(int(t), int(rng.integers(0, 1 << e)) if e else 0))
    zs = [int(z) for z in rng.permutation(np.array(ends + rest))]
    assert {e2_token(z)[0] for z in zs} == set(range(32)) and max(zs) == 65535
    src = np.array(values_from_residuals(zs, ext, value_map=0), np.uint16).reshape(8, 8, 8)
    assert predicted_residuals([int(v) for v in src.reshape(-1)], ext, value_map=0) == zs
    assert int(src.min()) < 2000 and int(src.max()) > 63000
    pl, out = info([int(v) for v in src.reshape(-1)], ext, value_map=0)
    assert len(pl) <= limit(n)
    valid("bricked_entropy3_8x8x8_uint16_all_tokens", src, UINT16, 3,
          "Bricked grid 8x8x8 uint16, one brick, codec 3 (Lorenzo, identity map) with entropy coder 3, whose "
          "values (%d .. %d) are made from chosen residuals: every token 0 .. 31 occurs, each at the lowest "
          "and the highest residual of its range (0, 1, 2, 3, 4 .. 5, ..., 32768 .. 49151 (token 30), "
          "49152 .. 65535 (token 31), 0 .. 14 bits below), among random tokens 0 .. 9: the stored tables "
          "hold up to %d present tokens a context, with frequencies from 1 (a = 0, no bits of w) up; "
          "%d bytes, within the limit %d." % (int(src.min()), int(src.max()),
                                              max(sum(1 for c in cc if c) for cc in out["counts"]), len(pl), limit(n)),
          **e3u)

    # entropy coders 1, 2 and 3 in one file, each brick with its own predictor settings
    X, Y, Z = 16, 16, 8
    vals = 1.5 + 0.02 * (np.arange(X)[None, None, :] - np.arange(Y)[None, :, None]) \
        + 0.03 * np.arange(Z)[:, None, None] + rng.normal(0, 0.004, (Z, Y, X))
    src = arr_f16(np.round(vals, 4).reshape(-1), (Z, Y, X))
    src.reshape(-1)[[3, 500, 1100, 1801]] = [0x8000, 0x7C00, 0x7E00, 0x0000]
    per = [dict(entropy=3, value_map=1),
           dict(entropy=1, value_map=0, shift=3, taps=(8, 8, 8, -8, -8, -8, 8), level=-2),
           dict(entropy=2, value_map=1, shift=1, taps=(2, 2, 2, -2, -2, -2, 2), level=0),
           dict(entropy=3, value_map=1, shift=2, taps=(3, 3, 2, -2, -2, -1, 1), level=7)]
    for q in (0, 3):
        vv, e = brick_vals(src, BINARY16, 3, q)
        assert len(predicted_payload(vv, e, **per[q])) <= limit(len(vv))
    valid("bricked_entropy3_16x16x8_binary16_mixed_entropy", src, BINARY16, 3,
          "Bricked grid 16x16x8 binary16, 4 bricks of 8x8x8, codec 3 in every brick with entropy coders 3, "
          "1, 2, 3 in brick order, each brick with its own value map, shift, taps and level (brick 3: shift "
          "2, taps 3, 3, 2, -2, -2, -1, 1, level 7); -0, +inf, a NaN and +0 among the values.",
          per_brick=lambda q: per[q])

    # the encoder's freedom in choosing tables (§7.2.2: "any with f_t >= 1 for every token that occurs")
    ext = (8, 8, 8)
    zs = from_rule(ext, lambda k, x, y, z: 12 if k == 0 else int(rng.integers(max(2, 2 * k - 4), 2 * k + 2)))
    src = np.array(values_from_residuals(zs, ext, value_map=0), np.uint16).reshape(8, 8, 8)
    toks, B, ks = e3_analyse(zs, ext)
    counts = [[0] * 32 for _ in range(12)]
    for (t, _, _), k in zip(toks, ks):
        counts[k][t] += 1
    assert [t for t in range(32) if counts[0][t]] == [12]
    by_use = sorted((k for k in range(1, 12) if any(counts[k])), key=lambda k: (-sum(counts[k]), k))
    k_all, k_uni = by_use[0], by_use[1]
    absent = [t for t in range(32) if not counts[k_all][t]]
    N = sum(counts[k_all])
    f_all = [max(1, (4096 - len(absent)) * c // N) if c else 1 for c in counts[k_all]]
    j = max(range(32), key=lambda t: (counts[k_all][t], -t))
    f_all[j] += 4096 - sum(f_all)
    f0 = [0] * 32
    f0[12], f0[31] = 4095, 1
    k_none = max(k for k in range(12) if not any(counts[k]))
    f_none = [0] * 32
    f_none[0], f_none[2], f_none[9] = 1, 2048, 2047
    e3kw = dict(freqs={0: f0, k_all: f_all, k_none: f_none}, uniform=(k_uni,))
    pl, out = info([int(v) for v in src.reshape(-1)], ext, value_map=0, e3=e3kw)
    assert len(pl) <= limit(512) and absent and ("a", 0, 12) in [m[0] for m in out["bits"].marks]
    valid("bricked_entropy3_8x8x8_uint16_table_choices", src, UINT16, 3,
          "Bricked grid 8x8x8 uint16, one brick, codec 3 (Lorenzo, identity map) with entropy coder 3 whose "
          "tables are not the proportional ones most other files use (§7.2.2 lets the encoder choose any "
          "frequencies with f_t >= 1 for every token that occurs in the context, summing to 4096): context 0 "
          "codes only token 12 (%d voxels) but its table has tokens 12 and 31 present, f_12 = 4095 (a = 11, "
          "w = 2047: the largest a written frequency can be) and f_31 = 1 (the last present token, not "
          "written: 4096 - 4095); context %d (the most used, %d voxels) has all 32 tokens present "
          "(present = 0xFFFFFFFF), the %d that do not occur with f = 1 (a = 0, no bits of w); context %d "
          "(%d voxels) is written with used = 0 although it codes voxels, so they are coded under f_t = 128 "
          "for every t (§7.2.2: \"or may be read so\"); context %d codes no voxel but is written with "
          "used = 1 and a table (tokens 0, 2 and 9 present, f_0 = 1, f_2 = 2048 = 2^11 + 0, f_9 = 2047)."
          % (sum(counts[0]), k_all, N, len(absent), k_uni, sum(counts[k_uni]), k_none),
          value_map=0, entropy=3, e3=e3kw)

    # stored levels of detail (stream 7) in entropy 3
    X, Y, Z = 16, 16, 8
    src = (4000 + 23 * np.arange(X)[None, None, :] - 17 * np.arange(Y)[None, :, None]
           + 31 * np.arange(Z)[:, None, None] + rng.integers(0, 50, (Z, Y, X))).astype(np.uint16)
    g = write_bricked(src, UINT16, 3)
    lods = flat_lods(src, UINT16, g.D)
    levels = {1: dict(entropy=3, value_map=0), 2: dict(entropy=2, value_map=0),
              3: dict(entropy=1, value_map=0), 4: dict(entropy=2, value_map=0)}
    blocks = [meta_block(DEFAULT_META)] + bricked_blocks(g, CODEC_PREDICTED, **e3u)
    for k, how in sorted(levels.items()):
        blocks += lod_level_blocks(lods[k], UINT16, 3, k, CODEC_PREDICTED, **how)
    assert [lods[k].shape for k in (1, 2, 3, 4)] == [(4, 8, 8), (2, 4, 4), (1, 2, 2), (1, 1, 1)]
    l1 = [int(v) for v in lods[1].reshape(-1)]
    assert len(predicted_payload(l1, (8, 8, 4), **e3u)) <= limit(256)
    l2 = [int(v) for v in lods[2].reshape(-1)]
    assert len(predicted_payload(l2, (4, 4, 2), **e3u)) > limit(32)
    data, _ = assemble(g, blocks, structure_kind=KIND_BRICKED, ireserved=3, framed=True, minor=3)
    add_valid("bricked_lods_16x16x8_uint16_entropy3", data, src, UINT16,
              "Bricked grid 16x16x8 uint16, bricks of 8, values codec 3 with entropy coder 3 (§7.2.2), storing "
              "every level of detail in stream 7 as codec 3 bricks: level 1 (8x8x4, one brick of 256 "
              "elements) with entropy coder 3; level 2 (4x4x2, 32 elements, too few for coder 3 within the "
              "limit of §7) and level 4 (1x1x1) with entropy coder 2, level 3 (2x2x1) with entropy coder 1. "
              "The contexts of a level's brick use the level's brick extents.",
              kind=KIND_BRICKED, extra={"brick_log2": 3, "stored_levels": sorted(levels)})

    # ---- invalid: the first brick of a bricked grid breaks one rule of §7.2.2 each
    X, Y, Z = 8, 8, 10
    src = (smooth(X, Y, Z, 1500, 4) + rng.integers(0, 37, (Z, Y, X))).astype(np.uint16)
    vals0, ext0 = brick_vals(src, UINT16, 3, 0)
    assert ext0 == (8, 8, 8)
    base, out0 = info(vals0, ext0, value_map=0)
    zs0 = predicted_residuals(vals0, ext0, value_map=0)
    tab0, st0, W0, words0, bits0 = e3_split(base[24:])
    nbits0 = out0["bits"].n
    E0 = sum(e2_token(z)[1] for z in zs0)
    marks = out0["bits"].marks
    k3 = next(k for k in range(12) if sum(1 for f in out0["F"][k] if f) >= 3 and any(out0["counts"][k]))
    assert 1 <= nbits0 % 8 <= 7 and 1 <= E0 % 8 <= 7 and W0 >= 2 and len(tab0) > 3, (nbits0, E0, W0)
    assert base == predicted_payload(vals0, ext0, **e3u)

    # the codings that break one check only: each decodes to the brick without that check
    def emits_at_last_step(j):         # whether the encoder rule emits a word at state j's last step
        try:
            predicted_payload(vals0, ext0, e3=dict(extra=j), **e3u)
        except AssertionError:
            return True
        return False
    j_init = next(j for j in range(31, -1, -1) if not emits_at_last_step(j))
    bad_init = predicted_payload(vals0, ext0, e3=dict(extra=j_init), **e3u)[24:]
    assert e3_decode(bad_init, ext0, skip=("initial_state",)) == zs0
    j_end = 17
    bad_end = predicted_payload(vals0, ext0, e3=dict(start=[E3_LOW + (j == j_end) for j in range(32)]), **e3u)[24:]
    assert e3_decode(bad_end, ext0, skip=("states_end",)) == zs0
    assert e3_decode(e3_join(tab0, st0, W0 + 1, words0 + b"\x5a\xa5", bits0), ext0, skip=("words_left",)) == zs0

    def body(fn):                       # mutate the bytes after the codec header of the first brick
        def mutate(blocks):
            st = blocks[0].stored
            blocks[0].stored = st[:24] + fn(*e3_split(st[24:]))
        return mutate

    def inv(name, tag, desc, first=None, expect="malformed", **kw):
        args = dict(e3u)
        if first is not None:           # settings of the first brick only
            args = dict(per_brick=lambda q: dict(e3u, **(first if q == 0 else {})))
        args.update(kw)
        add_invalid(name, bricked_file(src, UINT16, 3, **args), expect, "codec3.entropy3." + tag, desc)

    def mark(name):
        return next((pos, width) for m, pos, width in marks if m[0] == name)    # the first field of that name

    head = ("Bricked grid 8x8x10 uint16, bricks of 8, codec 3 (Lorenzo, identity map) with entropy coder 3 in "
            "both bricks, whose first brick (8x8x8; %d bytes of tables for %d bits, W = %d words, %d bytes of "
            "bits below for E = %d bits) " % (len(tab0), nbits0, W0, len(bits0), E0))
    inv("bricked_codec3_entropy3_tables_short", "tables_short",
        head + "is cut to 27 bytes, the codec header and 3 bytes of its tables: the tables do not parse "
               "within the payload (§7.2.2: a payload too short for the tables as they parse is malformed).",
        mutate=lambda blocks: setattr(blocks[0], "stored", blocks[0].stored[:27]))
    p, w = mark("present")
    kp = next(m[0][1] for m in marks if m[0][0] == "present")
    inv("bricked_codec3_entropy3_present_zero", "present_zero",
        head + "has the 32 bits `present` of context %d (its first context with used = 1, table bits %d .. "
               "%d) all 0 (§7.2.2: present = 0 is malformed); the bits after them are unchanged."
               % (kp, p, p + 31),
        mutate=body(lambda t, s, W, wd, b: e3_join(set_bits(t, p, 32, 0), s, W, wd, b)))
    pa, _ = mark("a")
    ma = next(m for m in marks if m[0][0] == "a")[0]
    inv("bricked_codec3_entropy3_a_12", "a_over_11",
        head + "has the 4-bit number a of its first written frequency (context %d, token %d, table bits %d .. "
               "%d) set to 12 (§7.2.2: a <= 11); the bits after it are unchanged." % (ma[1], ma[2], pa, pa + 3),
        mutate=body(lambda t, s, W, wd, b: e3_join(set_bits(t, pa, 4, 12), s, W, wd, b)))
    pairs = [[(t, f) for t, f in enumerate(out0["F"][k]) if f] if any(out0["counts"][k]) else None
             for k in range(12)]
    bigj = max(range(len(pairs[k3]) - 1), key=lambda q: (pairs[k3][q][1], -q))
    fl = pairs[k3][-1][1]
    assert pairs[k3][bigj][1] + fl <= 4095
    pairs[k3][bigj] = (pairs[k3][bigj][0], pairs[k3][bigj][1] + fl)
    tab_last = e3_tables_bits(pairs).tobytes()
    inv("bricked_codec3_entropy3_last_frequency_0", "last_frequency",
        head + "has in the table of context %d the frequency of token %d raised by %d, the frequency of the "
               "last present token %d, so that the written frequencies sum to 4096 and the last one would be "
               "4096 - 4096 = 0 (§7.2.2: it MUST be >= 1); the tables are otherwise those of the valid coding."
               % (k3, pairs[k3][bigj][0], fl, pairs[k3][-1][0]),
        mutate=body(lambda t, s, W, wd, b: e3_join(tab_last, s, W, wd, b)))
    inv("bricked_codec3_entropy3_tables_padding", "tables_padding",
        head + "has bit 7 of the last byte of its tables set, a padding bit (the tables take %d bits, so "
               "bits %d .. 7 of that byte are padding; §7.2.2: they MUST be 0)." % (nbits0, nbits0 % 8),
        mutate=body(lambda t, s, W, wd, b: e3_join(t[:-1] + bytes([t[-1] | 0x80]), s, W, wd, b)))
    inv("bricked_codec3_entropy3_states_short", "states_short",
        head + "is cut to 24 + %d + 131 bytes: its tables parse, then 131 bytes where the 32 states and W "
               "need 132 (§7.2.2)." % len(tab0),
        mutate=lambda blocks: setattr(blocks[0], "stored", blocks[0].stored[:24 + len(tab0) + 131]))
    inv("bricked_codec3_entropy3_initial_state_below_2_16", "initial_state",
        head + "was coded with one word more emitted before the last coding step of state X_%d (voxel %d), "
               "so that X_%d starts below 2^16 (§7.2.2: each state MUST lie in 2^16 .. 2^32 - 1); a decoder "
               "that did not check it would read that word back at voxel %d and decode the brick exactly, "
               "every state ending at 2^16 and every word read (W = %d)."
               % (j_init, j_init, j_init, j_init, W0 + 1), first=dict(e3=dict(extra=j_init)))
    rest0 = 2 * W0 + len(bits0)
    inv("bricked_codec3_entropy3_words_over_payload", "words_short",
        head + "says W = %d: 2W = %d bytes, one or two more than the %d bytes after W (the words and the "
               "bits below) (§7.2.2: a payload too short for 2W is malformed)."
               % (rest0 // 2 + 1, 2 * (rest0 // 2 + 1), rest0),
        mutate=body(lambda t, s, W, wd, b: e3_join(t, s, rest0 // 2 + 1, wd, b)))
    inv("bricked_codec3_entropy3_words_count_wraps", "words_short",
        head + "says W = %d + 2^31: 2W = 2^32 + %d, which a reader that computes 2W in 32 bits takes for "
               "%d, the true size of the words (§7.2.2: the payload is too short for 2W; sizes are exact "
               "integers)." % (W0, 2 * W0, 2 * W0),
        mutate=body(lambda t, s, W, wd, b: e3_join(t, s, W + (1 << 31), wd, b)))
    inv("bricked_codec3_entropy3_stream_ends_early", "stream_end",
        head + "lacks the last word of its word stream (W - 1, bits below unchanged): the decoder's last "
               "renormalisation finds no word left (§7.2.2 step 3).",
        mutate=body(lambda t, s, W, wd, b: e3_join(t, s, W - 1, wd[:-2], b)))
    inv("bricked_codec3_entropy3_word_left", "words_left",
        head + "has one word more at the end of its word stream (W + 1, bits below unchanged): every state "
               "ends at 2^16 with that word unread (§7.2.2: all W words MUST have been read).",
        mutate=body(lambda t, s, W, wd, b: e3_join(t, s, W + 1, wd + b"\x5a\xa5", b)))
    inv("bricked_codec3_entropy3_states_end", "states_end",
        head + "was coded with state X_%d starting at 2^16 + 1 instead of 2^16: the decoder reads every word "
               "and ends with X_%d = 2^16 + 1, the 31 other states at 2^16 (§7.2.2: every state MUST equal "
               "2^16)." % (j_end, j_end),
        first=dict(e3=dict(start=[E3_LOW + (j == j_end) for j in range(32)])))
    inv("bricked_codec3_entropy3_bits_short", "bits_size",
        head + "lacks the last byte of its bits below: ceil(E / 8) - 1 bytes (§7.2.2, as §7.2.1: exactly the "
               "bytes the tokens need).", mutate=body(lambda t, s, W, wd, b: e3_join(t, s, W, wd, b[:-1])))
    inv("bricked_codec3_entropy3_bits_long", "bits_size",
        head + "has a zero byte after its bits below: ceil(E / 8) + 1 bytes (§7.2.2: exactly the bytes the "
               "tokens need).", mutate=body(lambda t, s, W, wd, b: e3_join(t, s, W, wd, b + b"\0")))
    inv("bricked_codec3_entropy3_padding_bit", "padding",
        head + "has bit 7 of the last byte of its bits below set, a padding bit (E mod 8 = %d, so bits %d .. "
               "7 of that byte are padding; §7.2.2: padding bits 0)." % (E0 % 8, E0 % 8),
        mutate=body(lambda t, s, W, wd, b: e3_join(t, s, W, wd, b[:-1] + bytes([b[-1] | 0x80]))))

    # correct codings over codec 3's limit of §7: no brick of fewer than 36 voxels fits coder 3
    q1, q8 = edge_exts.index((1, 1, 1)), edge_exts.index((8, 1, 1))
    v1, _ = brick_vals(edge_src, UINT16, 3, q1)
    p1 = predicted_payload(v1, (1, 1, 1), **e3u)
    assert e3_tables_size(p1[24:]) == 6 and p1[30:158] == struct.pack("<I", E3_LOW) * 32
    v8, _ = brick_vals(edge_src, UINT16, 3, q8)
    p8 = predicted_payload(v8, (8, 1, 1), **e3u)
    for q, name, what in ((q1, "1x1x1", "its one voxel (token %d alone in context 0: f = 4096, so X_0 stays "
                                      "2^16 like the 31 unused states; all 32 states are 2^16)"
                           % e2_token(predicted_residuals(v1, (1, 1, 1), value_map=0)[0])[0]),
                          (q8, "8x1x1", "its 8 voxels (states X_8 .. X_31 unused, 2^16)")):
        pl = p1 if q == q1 else p8
        add_invalid("bricked_codec3_entropy3_%s_over_bound" % name,
                    bricked_file(edge_src, UINT16, 3, per_brick=lambda r, q=q: dict(
                        value_map=0, entropy=3 if r in edge_big or r == q else 2)),
                    "malformed", "block.stored_bound",
                    "bricked_entropy3_9x9x9_uint16_edge_bricks with its %s edge brick (n = %d) coded with "
                    "entropy coder 3 instead of 2: a correct §7.2.2 coding of %s, %d bytes (the tables, the "
                    "32 states and W alone take %d), more than codec 3's limit 24 + bound(2n) = %d (§7). The "
                    "stored_size rule is checked from the block table, whatever the coder: a brick of fewer "
                    "than 36 voxels cannot use coder 3, so §7.2.2's \"a brick of fewer than 32 voxels leaves "
                    "the states it does not use at 2^16\" never applies to a valid file."
                    % (name, len(v1) if q == q1 else len(v8), what, len(pl), e3_tables_size(pl[24:]) + 132,
                       limit(1 if q == q1 else 8)))
    # the smallest coder 3 payload: every context written with used = 0, tokens 0 .. 3 (no bits below), W = 0
    def smallest(ext):
        n = ext[0] * ext[1] * ext[2]
        zs = [int(z) for z in rng.choice([0, 2, 2, 3], n)]
        vals = values_from_residuals(zs, ext, value_map=0)
        pl = predicted_payload(vals, ext, e3=dict(uniform=range(12)), **e3u)
        assert len(pl) == 24 + 2 + 132 and pl[24:26] == b"\0\0"
        return np.array(vals, np.uint16).reshape(ext[2], ext[1], ext[0]), len(pl), limit(n)
    src, size36, lim36 = smallest((6, 6, 1))
    assert size36 <= lim36 == 159
    valid("bricked_entropy3_6x6x1_uint16_smallest_brick", src, UINT16, 3,
          "Bricked grid 6x6x1 uint16, one brick of 36 voxels, codec 3 (Lorenzo, identity map) with entropy "
          "coder 3 in the smallest payload coder 3 has: all 12 contexts written with used = 0 (12 zero bits, "
          "2 bytes of tables; every voxel coded under f_t = 128), residuals 0, 2 and 3 only (tokens 0, 2, 3: "
          "no bits below), so no state reaches 2^27 = 2^20 * 128 and W = 0: %d bytes, within codec 3's limit "
          "24 + bound(72) = %d (§7). 36 voxels is the fewest for which coder 3 fits the limit at all "
          "(bricked_codec3_entropy3_7x5x1_over_bound)." % (size36, lim36), **dict(e3u, e3=dict(uniform=range(12))))
    src, size35, lim35 = smallest((7, 5, 1))
    assert size35 > lim35 == 157
    add_invalid("bricked_codec3_entropy3_7x5x1_over_bound",
                bricked_file(src, UINT16, 3, e3=dict(uniform=range(12)), **e3u), "malformed", "block.stored_bound",
                "Bricked grid 7x5x1 uint16, one brick of 35 voxels, codec 3 with entropy coder 3 coded as "
                "bricked_entropy3_6x6x1_uint16_smallest_brick is (every context used = 0, tokens 0, 2 and 3, "
                "W = 0): %d bytes, the smallest coder 3 payload, one byte over codec 3's limit 24 + bound(70) "
                "= %d (§7), checked from the block table." % (size35, lim35))

def gen_grids_valid():
    # ---- regular grid (§8A.1)
    rng = np.random.default_rng(101)          # the voxels of odd_3x5x7_uint16
    src = rng.integers(0, 4096, size=(7, 5, 3)).astype(np.uint16)
    src[0:2, 0:2, 0:2] = 777
    src[4:7, 4:5, 0:3] = 1234
    src[2:4, 2:4, 2:3] = 55
    g = write_regular(src, UINT16)
    d, lay, bl = grid_file(g, limit=64, meta_first=True, scale=0.0007, offset=-1.25)
    assert sum(1 for b in bl if b.stream == STREAM_VALUES) == 4
    add_valid("regular_3x5x7_uint16", d, src, UINT16,
              "Regular grid (structure_kind 2, version 1.1) of the voxels of odd_3x5x7_uint16: 105 values "
              "in 4 value blocks of at most 32 values (zstd), metadata block first, value_scale 0.0007, "
              "value_offset -1.25, depth 3, level table [0, 0, 0, 0]. Levels of detail by the flat sum of "
              "§12.3 over the decoded (unscaled) integers, clipped cells at the border, ties to even.",
              kind=KIND_REGULAR)

    rng = np.random.default_rng(201)
    vals = rng.standard_normal(16 ** 3) * 10.0 ** rng.integers(-3, 12, 16 ** 3)
    src = arr_f32(vals, (16, 16, 16))
    cells = _order_sensitive_cells_f32(src)
    exp = flat_lods(src, FLOAT32, 4)
    # the sequential z, y, x sum is what is tested: show that other orders differ
    for (cx, cy, cz), v in cells.items():
        got = exp[1][cz, cy, cx]
        exact = f32(float(sum(Fraction(_f32_from_bits(b)) for b in v) / 8))
        seq = 0.0
        for b in v:
            seq = seq + _f32_from_bits(b)
        assert got == f32(seq / 8)
        assert (got == exact) == ((cx, cy, cz) == (1, 0, 0))     # the exact mean differs elsewhere
    assert exp[1][0, 0, 0] == f32(0.625) and exp[1][0, 0, 1] == f32(0.75) and exp[1][0, 1, 3] == 0
    g = write_regular(src, FLOAT32)
    d, lay, bl = grid_file(g, codec="alt", limit=4096)
    add_valid("regular_16_float32", d, src, FLOAT32,
              "Regular grid 16^3 float32, random values of magnitudes 1e-3 .. 1e12, 4 value blocks of 1024 "
              "values, codecs alternate stored/zstd. Some level-of-detail-1 cells hold 2^60, -2^60 and 1s "
              "so that only the exact order of §12.3 (binary64 from +0.0, z then y then x, one value after "
              "the other) gives the expected bits: cell (0,0,0) = 0.625 (exact mean 0.75, pairwise sum "
              "0.5), cell (1,0,0) = 0.75 (z-fastest order: 0.375), cell (3,1,0) = +0 (exact mean 0.75).",
              kind=KIND_REGULAR)

    rng = np.random.default_rng(202)
    vals = rng.uniform(-100.0, 100.0, (5, 6, 9))
    src = arr_f16(vals, (5, 6, 9))
    src[0:2, 0:2, 0:2] = 0x8000            # uniform -0: level of detail +0 (no leaf exception)
    src[0:2, 0:2, 2:4] = 0x7C01            # uniform signalling NaN: level of detail 0x7E00
    src[0:2, 2:4, 0:2] = 0x7C00            # +inf
    src[0:2, 2:4, 2] = 0xFC00              # -inf beside +inf: NaN
    src[2:4, 0:2, 0:2] = [[[1, 0], [1, 0]], [[1, 0], [1, 0]]]   # mean 2^-25: tie -> +0
    src[4, 4:6, 8] = 0x8000                # a clipped cell (x = 8, z = 4) of two -0
    src[2:4, 2:4, 2:4] = f16(0.1)          # uniform finite: keeps its bits
    g = write_regular(src, BINARY16)
    d, lay, bl = grid_file(g, codec=CODEC_STORED, limit=64)
    add_valid("regular_9x6x5_binary16", d, src, BINARY16,
              "Regular grid 9x6x5 binary16, stored codec, 9 value blocks. Special values: a uniform -0 "
              "2x2x2 cell and a clipped cell of two -0 give +0 in the levels of detail (+0.0 + -0 = +0; "
              "unlike an octree leaf), a uniform signalling NaN 0x7C01 gives 0x7E00, +inf with -inf gives "
              "0x7E00, a mean of 2^-25 rounds to +0 (tie to even), a uniform 0.1 keeps its bits.",
              kind=KIND_REGULAR)

    # ---- rectilinear grid (§8A.2)
    src, g = rectilinear_20x11x7_uint16()
    d, lay, bl = grid_file(g, codec="alt", limit=16, slimit=8, meta_first=True, scale=0.5, offset=-1000.0)
    assert [len(b.data) // 4 for b in bl if b.stream == STREAM_BORDERS] == [2] * 6 + [1]
    add_valid("rectilinear_20x11x7_uint16", d, src, UINT16,
              "Rectilinear grid (structure_kind 3) 20x11x7 uint16, B_x = [0,1,4,5,11,19,20] (uneven), "
              "B_y = [0,11] (one cell along y), B_z = [0,2,3,7]; 13 borders in 7 blocks (blocks straddle "
              "the lists: [0,1] [4,5] [11,19] [20,0] [11,0] [2,3] [7]), 18 values in 3 blocks; "
              "codecs alternate stored/zstd; metadata first; scale 0.5, offset -1000; depth 5.",
              kind=KIND_RECTILINEAR)

    bx, by, bz = [0, 1, 2, 3, 64, 100, 128, 255, 256, 257], [0, 1], [0, 1, 2]
    rng = np.random.default_rng(204)
    cv = [f16(v) for v in rng.uniform(-8.0, 8.0, 18)]
    src = rect_source(BINARY16, bx, by, bz, cv)
    g = write_rectilinear(src, BINARY16, bx, by, bz)
    d, lay, bl = grid_file(g, limit=8, slimit=12, struct_first=False)
    add_valid("rectilinear_257x1x2_binary16", d, src, BINARY16,
              "Rectilinear grid 257x1x2 binary16, depth 9, B_x = [0,1,2,3,64,100,128,255,256,257], B_y = "
              "[0,1], B_z = [0,1,2]: 15 borders in 5 blocks of 3, 18 values in 5 blocks, all zstd, values "
              "before borders in the file; 9 levels of detail, cells clipped at x = 257.",
              kind=KIND_RECTILINEAR)

    bx, by, bz = [0, 1, 2, 3, 4, 5], [0, 1, 2, 3], [0, 1, 2]
    rng = np.random.default_rng(205)
    cv = [f32(v) for v in rng.normal(0.0, 1.0, 30)]
    src = rect_source(FLOAT32, bx, by, bz, cv)
    g = write_rectilinear(src, FLOAT32, bx, by, bz)
    assert len(g.borders) == 5 + 3 + 2 + 3
    d, lay, bl = grid_file(g, codec=CODEC_STORED)
    add_valid("rectilinear_full_5x3x2_float32", d, src, FLOAT32,
              "Rectilinear grid 5x3x2 float32 with a border at every voxel: the borders stream holds "
              "size_x + size_y + size_z + 3 = 13 elements, the most allowed; stored codec.",
              kind=KIND_RECTILINEAR)

    bx, by, bz = [0, 6], [0, 4], [0, 3]
    src = rect_source(FLOAT32, bx, by, bz, [f32(-2.75)])
    g = write_rectilinear(src, FLOAT32, bx, by, bz)
    d, lay, bl = grid_file(g)
    add_valid("rectilinear_one_cell_6x4x3_float32", d, src, FLOAT32,
              "Rectilinear grid 6x4x3 float32 of one cell (borders [0,6] [0,4] [0,3], 6 elements, the "
              "fewest), one value -2.75; zstd.",
              kind=KIND_RECTILINEAR)

    # ---- streams 4 and 5 outside their kinds are unknown streams (§6.4)
    BASE = vol_object_in_air(6, 5, 4, UINT16, 107, 100, (2.0, 2.0, 1.5), 2.2, 1000, 2000)
    t = build_tree(BASE, UINT16)
    bl = level_blocks(t, CODEC_ZSTD)
    bl.insert(2, Blk(STREAM_BORDERS, 0, 0, 24, b"future stream, skip me\x00\x01", codec=CODEC_STORED, flags=1))
    bl.append(meta_block(DEFAULT_META))
    d, _ = assemble(t, bl)
    add_valid("ignorable_stream_4_octree", d, BASE, UINT16,
              "The file of ignorable_stream_200 (6x5x4 uint16 octree, version_minor 0) with stream 4 "
              "instead of 200, ignorable flag set: stream 4 is known only in files of structure_kind 3, so "
              "here it is an unknown ignorable stream that a 1.0 and a 1.1 reader skip.")

    # ---- nested grid (§8A.3)
    src, g, meta = nested_37x21x10_uint16_c8()
    assert len(g.cells) == 30
    d, lay, bl = grid_file(g, meta=meta, limit=512, slimit=64, scale=0.25, offset=-512.0)
    assert sum(1 for b in bl if b.stream == STREAM_CELLS) == 4 and sum(1 for b in bl if b.stream == 3) >= 3
    add_valid("nested_37x21x10_uint16_c8", d, src, UINT16,
              "Nested grid (structure_kind 4) 37x21x10 uint16, cell_log2 3 (C = 8): 5x3x2 = 30 cells, "
              "exponent of cell (i,j,k) = (i + j + 2k) mod 4, so 0, 1, 2 and 3 all occur, also on the "
              "cells clipped at x = 32..36, y = 16..20 and z = 8..9 (e.g. e = 2, h = 2 on 5 voxels: "
              "sub-voxels of 2, 2 and 1); %d values in %d blocks, cells in 4 blocks, zstd; scale 0.25, "
              "offset -512; depth 6; metadata structure.kind \"nested\"." % (len(g.values), sum(1 for b in bl if b.stream == 3)),
              kind=KIND_NESTED, extra={"cell_log2": 3})

    rng = np.random.default_rng(207)
    expo = [[[int(rng.integers(0, 2)) for i in range(4)] for j in range(3)] for k in range(2)]
    assert {e for pl in expo for row in pl for e in row} == {0, 1}
    src = nested_source(FLOAT32, (7, 5, 3), 1, expo, lambda: f32(rng.normal(10.0, 3.0)))
    g = write_nested(src, FLOAT32, 1, expo)
    d, lay, bl = grid_file(g, codec=CODEC_STORED, limit=64, slimit=32)
    add_valid("nested_7x5x3_float32_c2", d, src, FLOAT32,
              "Nested grid 7x5x3 float32, cell_log2 1 (C = 2): 4x3x2 = 24 cells with exponents 0 and 1, "
              "cells clipped to 1 voxel at x = 6, y = 4 and z = 2; stored codec, cells in 6 blocks, "
              "values in several blocks.",
              kind=KIND_NESTED, extra={"cell_log2": 1})

    vals = iter([f16(v) for v in (1.5, -2.25, 0.375, 1000.0)])
    src = nested_source(BINARY16, (5, 3, 6), 4, [[[2]]], lambda: next(vals))
    g = write_nested(src, BINARY16, 4, [[[2]]])
    assert len(g.values) == 4
    d, lay, bl = grid_file(g, mutate_blocks=lambda bl: bl.insert(1, Blk(
        STREAM_BORDERS, 0, 0, 12, pack_u32([0, 5, 0, 3, 0, 6]), codec=CODEC_ZSTD, flags=1)))
    add_valid("nested_5x3x6_binary16_c16", d, src, BINARY16,
              "Nested grid 5x3x6 binary16, cell_log2 4 (C = 16, larger than the volume, depth 3): one cell "
              "clipped to 5x3x6, exponent 2 (h = 4): a 2x1x2 sub-grid whose voxels cover x 0..3 and 4, "
              "y 0..2, z 0..3 and 4..5; zstd. Between the cells and values blocks an ignorable block of "
              "stream 4 (flags 1, 12 bytes of border-like data): in a nested grid stream 4 is an unknown "
              "stream and is skipped.",
              kind=KIND_NESTED, extra={"cell_log2": 4})

    rng = np.random.default_rng(208)
    src = nested_source(UINT16, (6, 5, 3), 31, [[[30]]], lambda: int(rng.integers(0, 65536)))
    g = write_nested(src, UINT16, 31, [[[30]]])
    assert len(g.values) == 18
    d, lay, bl = grid_file(g, struct_first=False)
    add_valid("nested_6x5x3_uint16_c2p31", d, src, UINT16,
              "Nested grid 6x5x3 uint16, cell_log2 31 (C = 2^31, the largest): one cell, exponent 30 "
              "(h = 2): 3x3x2 sub-voxels; the cells block after the values block; zstd.",
              kind=KIND_NESTED, extra={"cell_log2": 31})


def gen_grids_invalid(octree_base, octree_blocks, octree_tree):
    def inv(name, data, expect, tag, desc):
        add_invalid(name, data, expect, tag, desc)

    # base files
    rng = np.random.default_rng(301)
    RB_src = rng.integers(0, 65536, size=(2, 3, 4)).astype(np.uint16)
    RB = write_regular(RB_src, UINT16)
    RB_kw = dict(limit=16)
    rb, rblay, rbbl = grid_file(RB, **RB_kw)
    bx, by, bz = [0, 2, 3, 6], [0, 2, 4], [0, 3]
    RC_src = rect_source(UINT16, bx, by, bz, [int(v) for v in rng.integers(0, 65536, 6)])
    RC = write_rectilinear(RC_src, UINT16, bx, by, bz)
    RC_kw = dict(slimit=20)
    rc, rclay, rcbl = grid_file(RC, **RC_kw)
    expo = [[[(i + j + k) % 3 for i in range(3)] for j in range(2)] for k in range(2)]
    NB_src = nested_source(UINT16, (10, 6, 5), 2, expo, lambda: int(rng.integers(0, 65536)))
    NB = write_nested(NB_src, UINT16, 2, expo)
    NB_kw = dict(limit=32, slimit=32)
    nb, nblay, nbbl = grid_file(NB, **NB_kw)
    assert len(NB.cells) == 12
    # the bases are valid
    for d_, s_ in ((rb, RB_src), (rc, RC_src), (nb, NB_src)):
        assert np.array_equal(read_ivol(d_)[0], s_)
    gdesc = {"RB": "regular grid 4x3x2 uint16 (24 values in 3 blocks)",
             "RC": "rectilinear grid 6x4x3 uint16 (B_x = [0,2,3,6], B_y = [0,2,4], B_z = [0,3]; 6 values)",
             "NB": "nested grid 10x6x5 uint16, cell_log2 2 (C = 4, 3x2x2 = 12 cells, exponents 0..2)"}

    def pg(data, lay, rel, fmt, *v):
        return patch_index(data, lay, rel, fmt, *v)

    def gf(g, kw, **more):
        k2 = dict(kw)
        k2.update(more)
        return grid_file(g, **k2)[0]

    # level table (§6.2)
    inv("regular_level_table_nonzero", pg(rb, rblay, rblay.level_table_offset, "<Q", 1), "malformed",
        "level_table.nonzero", "%s with inner_count[0] = 1 (a table that would be valid for an octree): "
        "every level table entry must be 0 for kinds 2-4." % gdesc["RB"])
    inv("rectilinear_level_table_nonzero", pg(rc, rclay, rclay.level_table_offset, "<QQ", 1, 1), "malformed",
        "level_table.nonzero", "%s with level table [1, 1, 0, 0]." % gdesc["RC"])
    inv("nested_level_table_nonzero", pg(nb, nblay, nblay.level_table_offset, "<QQ", 1, 8), "malformed",
        "level_table.nonzero", "%s with level table [1, 8, 0, 0, 0]." % gdesc["NB"])

    # streams that do not belong to the kind (§6.4)
    def add_block(blk, pos=0):
        return lambda bl: bl.insert(pos, blk)

    inv("regular_with_nodes_stream", gf(RB, RB_kw, mutate_blocks=add_block(
        Blk(STREAM_NODES, 0, 0, 1, pack_nodes([1]), codec=CODEC_STORED))), "malformed", "stream.kind",
        "%s with an extra nodes block (stream 2, one node word, level 0): stream 2 appears only with "
        "structure_kind 1 (its coverage rule, total_inner = 0, is broken with it)." % gdesc["RB"])
    inv("regular_with_borders_stream", gf(RB, RB_kw, mutate_blocks=add_block(
        Blk(STREAM_BORDERS, 0, 0, 6, pack_u32([0, 4, 0, 3, 0, 2]), codec=CODEC_STORED))), "unsupported-feature",
        "stream", "%s with an extra borders block [0,4, 0,3, 0,2] (valid lists for its size), flags 0: "
        "stream 4 is known only in files of structure_kind 3, elsewhere it is an unknown stream, and "
        "without the ignorable flag the file is refused." % gdesc["RB"])
    inv("rectilinear_borders_missing", gf(RC, RC_kw, mutate_blocks=lambda bl: bl.__setitem__(
        slice(None), [b for b in bl if b.stream != STREAM_BORDERS])), "malformed", "stream.kind",
        "%s without its borders blocks: stream 4 must appear with structure_kind 3." % gdesc["RC"])
    inv("rectilinear_with_cells_stream", gf(RC, RC_kw, mutate_blocks=add_block(
        Blk(STREAM_CELLS, 0, 0, 1, pack_nodes([0]), codec=CODEC_STORED), 3)), "unsupported-feature", "stream",
        "%s with an extra cells block (stream 5, one word 0, flags 0): an unknown stream outside "
        "structure_kind 4, not ignorable." % gdesc["RC"])
    inv("nested_with_borders_stream", gf(NB, NB_kw, mutate_blocks=add_block(
        Blk(STREAM_BORDERS, 0, 0, 6, pack_u32([0, 10, 0, 6, 0, 5]), codec=CODEC_ZSTD), 2)),
        "unsupported-feature", "stream", "%s with an extra borders block [0,10, 0,6, 0,5], flags 0: an "
        "unknown stream outside structure_kind 3, not ignorable." % gdesc["NB"])
    inv("nested_cells_missing", gf(NB, NB_kw, mutate_blocks=lambda bl: bl.__setitem__(
        slice(None), [b for b in bl if b.stream != STREAM_CELLS])), "malformed", "stream.kind",
        "%s without its cells blocks: stream 5 must appear with structure_kind 4." % gdesc["NB"])
    bl = [Blk(b.stream, b.level, b.first, b.count, b.data, b.codec, b.flags) for b in octree_blocks]
    bl.insert(2, Blk(STREAM_CELLS, 0, 0, 1, pack_nodes([0]), codec=CODEC_STORED))
    d, _ = assemble(octree_tree, bl)
    inv("octree_with_cells_stream", d, "unsupported-feature", "stream",
        "Octree file (6x5x4 uint16, structure_kind 1, version_minor 0) with an extra block of stream 5, "
        "flags 0: as in 1.0, an unknown non-ignorable stream (stream 5 is known only in files of "
        "structure_kind 4).")

    # block level (§6.4)
    vb = [i for i, b in enumerate(rbbl) if b.stream == STREAM_VALUES][1]
    inv("regular_values_block_level_1", pg(rb, rblay, entry_off(rblay, vb, "level"), "<B", 1), "malformed",
        "block.level", "%s: the second values block has level 1 (depth 2): blocks of kinds 2-4 have "
        "level 0." % gdesc["RB"])
    sb = [i for i, b in enumerate(rcbl) if b.stream == STREAM_BORDERS][0]
    inv("rectilinear_borders_block_level_1", pg(rc, rclay, entry_off(rclay, sb, "level"), "<B", 1),
        "malformed", "block.level", "%s: the first borders block has level 1." % gdesc["RC"])
    cb = [i for i, b in enumerate(nbbl) if b.stream == STREAM_CELLS][-1]
    inv("nested_cells_block_level_2", pg(nb, nblay, entry_off(nblay, cb, "level"), "<B", 2),
        "malformed", "block.level", "%s: the last cells block has level 2." % gdesc["NB"])

    # borders (§8A.2)
    def rect_with(borders, values=None):
        g = RC.copy()
        g.borders = list(borders)
        if values is not None:
            g.values = list(values)
        return gf(g, RC_kw)

    inv("borders_y_not_starting_at_0", rect_with([0, 2, 3, 6, 1, 2, 4, 0, 3]), "malformed", "borders.start",
        "%s with B_y = [1,2,4] (does not start with 0; the number of cells is unchanged)." % gdesc["RC"])
    inv("borders_x_decreasing", rect_with([0, 3, 2, 6, 0, 2, 4, 0, 3]), "malformed", "borders.increasing",
        "%s with B_x = [0,3,2,6] (not increasing)." % gdesc["RC"])
    inv("borders_x_repeated", rect_with([0, 2, 2, 6, 0, 2, 4, 0, 3]), "malformed", "borders.increasing",
        "%s with B_x = [0,2,2,6] (not strictly increasing: an empty interval)." % gdesc["RC"])
    inv("borders_z_not_ending_at_size", rect_with([0, 2, 3, 6, 0, 2, 4, 0, 2]), "malformed", "borders.end",
        "%s with B_z = [0,2] although size_z = 3: the stream ends before B_z reaches size_z." % gdesc["RC"])
    inv("borders_x_past_size", rect_with([0, 2, 3, 7, 0, 2, 4, 0, 3]), "malformed", "borders.end",
        "%s with B_x = [0,2,3,7]: it never equals size_x = 6 (7 > size_x)." % gdesc["RC"])
    inv("borders_y_list_missing", rect_with([0, 2, 3, 6, 0, 3]), "malformed", "borders.end",
        "%s whose borders stream holds B_x and B_z only ([0,2,3,6, 0,3]): read as B_y = [0,3] it never "
        "reaches size_y = 4; B_z is missing." % gdesc["RC"])
    inv("borders_extra_list", rect_with([0, 2, 3, 6, 0, 2, 4, 0, 3, 0, 3]), "malformed", "borders.extra",
        "%s with a fourth list [0,3] after B_z (11 elements, within the limit of size_x + size_y + "
        "size_z + 3 = 16): B_z must end at the last element of the stream." % gdesc["RC"])
    full = list(range(7)) + list(range(5)) + list(range(4))
    assert len(full) == 6 + 4 + 3 + 3
    inv("borders_too_many", rect_with(full + [3], [int(v) for v in rng.integers(0, 65536, 72)]),
        "malformed", "borders.count",
        "%s variant with a border at every voxel (16 elements, the most allowed, 72 values) plus one "
        "element 3 more: 17 > size_x + size_y + size_z + 3, to be refused from the block table before "
        "the stream is read." % gdesc["RC"])

    def huge_borders(bl):
        i = [n for n, b in enumerate(bl) if b.stream == STREAM_BORDERS]
        data = pack_u32(RC.borders) + bytes(4 * ((1 << 24) - len(RC.borders)))
        big = Blk(STREAM_BORDERS, 0, 0, 1 << 24, data, codec=CODEC_ZSTD)
        bl[i[0]:i[-1] + 1] = [big]

    d, _, hbl = grid_file(RC, mutate_blocks=huge_borders, **RC_kw)
    hsz = [len(b.stored_bytes()) for b in hbl if b.stream == STREAM_BORDERS][0]
    inv("borders_count_huge", d, "malformed", "borders.count",
        "%s whose borders are one zstd block of element_count 2^24 (decoded 64 MiB, exactly the block "
        "limit; the lists followed by zeros, %d bytes stored): far more than size_x + size_y + size_z + 3 "
        "= 16; a reader must refuse it before allocating or decoding." % (gdesc["RC"], hsz))

    # values totals (§8A)
    g = RB.copy()
    g.values = g.values[:-1]
    inv("regular_values_one_short", gf(g, RB_kw), "malformed", "stream.coverage",
        "%s whose values stream holds 23 values instead of size_x * size_y * size_z = 24." % gdesc["RB"])
    g = RC.copy()
    g.values = g.values + [7]
    inv("rectilinear_values_one_extra", gf(g, RC_kw), "malformed", "stream.coverage",
        "%s whose values stream holds 7 values instead of n_x * n_y * n_z = 6." % gdesc["RC"])
    g = NB.copy()
    g.values = g.values + [7]
    inv("nested_values_one_extra", gf(g, NB_kw), "malformed", "stream.coverage",
        "%s whose values stream holds one value more than the last cell's first_value plus its voxel "
        "count (%d)." % (gdesc["NB"], len(NB.values)))

    # cell_log2 (§6.1)
    inv("nested_cell_log2_0", pg(nb, nblay, 11, "<B", 0), "malformed", "cell_log2",
        "%s with index byte 11 (cell_log2) = 0: must be 1 .. 31 for structure_kind 4." % gdesc["NB"])
    inv("nested_cell_log2_32", pg(nb, nblay, 11, "<B", 32), "malformed", "cell_log2",
        "%s with cell_log2 = 32." % gdesc["NB"])
    inv("regular_cell_log2_set", pg(rb, rblay, 11, "<B", 3), "malformed", "index.reserved",
        "%s with index byte 11 = 3: reserved (0) for kinds other than 4." % gdesc["RB"])
    inv("rectilinear_cell_log2_set", pg(rc, rclay, 11, "<B", 1), "malformed", "index.reserved",
        "%s with index byte 11 = 1: reserved (0) for kinds other than 4." % gdesc["RC"])

    # cell words (§8A.3)
    def nest_with(cells, values=None):
        g = NB.copy()
        g.cells = list(cells)
        if values is not None:
            g.values = list(values)
        return gf(g, NB_kw)

    FV = (1 << 56) - 1
    cw = NB.cells
    last_e = cw[-1] >> 56
    inv("nested_exponent_too_big", nest_with(cw[:-1] + [(3 << 56) | (cw[-1] & FV)]), "malformed",
        "cells.exponent", "%s: the last cell (exponent %d) has exponent 3 > cell_log2 = 2 (h = C >> 3 "
        "would be 0); values unchanged." % (gdesc["NB"], last_e))
    inv("nested_exponent_255", nest_with([(255 << 56) | (cw[0] & FV)] + cw[1:]), "malformed",
        "cells.exponent", "%s: the first cell has exponent 255 (a shift a C reader must not "
        "perform)." % gdesc["NB"])
    counts = [(cw[n + 1] & FV) - (cw[n] & FV) for n in range(len(cw) - 1)] + [len(NB.values) - (cw[-1] & FV)]
    inv("nested_first_value_not_zero", nest_with([w + 1 for w in cw], [0] + NB.values), "malformed",
        "cells.chain", "%s with every first_value one larger and one extra value in front: the chain "
        "is intact but the first cell's first_value is 1, not 0." % gdesc["NB"])
    inv("nested_chain_gap", nest_with(cw[:5] + [w + 1 for w in cw[5:]],
                                      NB.values[:cw[5] & FV] + [0] + NB.values[cw[5] & FV:]),
        "malformed", "cells.chain", "%s: cells 5 .. 11 have first_value one larger (one unused value "
        "between cells 4 and 5, values stream one longer): cell 5 breaks the chain." % gdesc["NB"])
    assert counts[4] >= 2
    inv("nested_chain_overlap", nest_with(cw[:5] + [w - 1 for w in cw[5:]],
                                          NB.values[:(cw[5] & FV) - 1] + NB.values[cw[5] & FV:]),
        "malformed", "cells.chain", "%s: cells 5 .. 11 have first_value one smaller (cells 4 and 5 "
        "share a value, values stream one shorter)." % gdesc["NB"])
    inv("nested_cells_one_extra", nest_with(cw + [len(NB.values)], NB.values + [9]), "malformed",
        "stream.coverage", "%s with a 13th cell word (exponent 0, first_value continuing the chain) "
        "and its value: the cells stream must hold n_x * n_y * n_z = 12 words." % gdesc["NB"])
    inv("nested_cells_one_short", nest_with(cw[:-1], NB.values[:cw[-1] & FV]), "malformed",
        "stream.coverage", "%s without its last cell word and the last cell's %d values: 11 cell words "
        "instead of 12." % (gdesc["NB"], counts[-1]))

    # totals beyond 64 bits (§8A): 2^31 voxels per axis
    S = 1 << 31
    g = Grid(KIND_NESTED, UINT16, (S, S, S), [], cells=[31 << 56], cell_log2=31)
    d, _ = assemble(g, [Blk(STREAM_CELLS, 0, 0, 1, pack_nodes(g.cells)), meta_block(DEFAULT_META)],
                    minor=1, structure_kind=KIND_NESTED, ireserved=31)
    inv("nested_total_values_wraps", d, "malformed", "cells.total",
        "Nested grid of 2^31 x 2^31 x 2^31 voxels, cell_log2 31, depth 31: one cell at full resolution "
        "(exponent 31, first_value 0), so total_values = 2^93 > 2^56 (§8A.3 bound), and 2^93 is 0 "
        "modulo 2^64; the file has no values block at all (two blocks: cells, metadata) -> malformed; a reader that computes the total in 64 bits sees 0 values and must still not "
        "accept it or read values that are not there.")
    g = Grid(KIND_REGULAR, UINT16, (S, S, S), [])
    d, _ = assemble(g, [Blk(200, 0, 0, 9, b"ignore me", codec=CODEC_STORED, flags=1),
                        meta_block(DEFAULT_META)], minor=1, structure_kind=KIND_REGULAR)
    inv("regular_total_values_wraps", d, "malformed", "stream.coverage",
        "Regular grid of 2^31 x 2^31 x 2^31 voxels (total_values = 2^93, 0 modulo 2^64), depth 31, "
        "with no values block: an ignorable block of stream 200 and the metadata block only. The "
        "values stream does not cover its 2^93 elements -> malformed.")

    # structure kinds (§6.1)
    inv("structure_kind_6", pg(rb, rblay, 8, "<B", 6), "unsupported-feature", "structure_kind",
        "%s with structure_kind = 6 (not defined in 1.3; was structure_kind_5 up to 1.2, before the "
        "bricked grid)." % gdesc["RB"])
    return rb


# --------------------------------------- codec 2, zstd over byte planes (version 1.2)

def gen_codec2_valid(base_src):
    """Valid files with blocks of codec 2 (§7); all carry version_minor 2 (§4)
    except codec2_minor_0, which tests that a reader does not check it."""
    V2 = " (version 1.2: version_minor 2.)"
    src = vol_object_in_air(40, 33, 29, BINARY16, 104, 0.0015, (19.5, 15.0, 13.0), 11.0, 0.9, 1.1)
    d, _, t, bl = simple_file(src, BINARY16, codec="planes", limit=4096, minor=2)
    assert {(b.stream, b.codec) for b in bl} == {(1, 1), (2, 1), (3, 2)}
    add_valid("codec2_sphere_40x33x29_binary16", d, src, BINARY16,
              "The volume of sphere_40x33x29_binary16 written as §15 recommends for 1.2: every values block "
              "codec 2 (zstd over byte planes, width 2: the low bytes of the block's values, then their high "
              "bytes), the nodes blocks and the metadata block codec 1; blocks of at most 4096 decoded "
              "bytes, %d values blocks.%s" % (sum(1 for b in bl if b.stream == 3), V2))

    rng = np.random.default_rng(105)                       # the volume of gradient_12x10x9_float32
    z, y, x = np.mgrid[0:9, 0:10, 0:12]
    vals = 0.01 * x + 0.1 * y - 0.05 * z + rng.normal(0, 1e-4, (9, 10, 12))
    vals[0:4, 0:8, 0:8] = -7.25
    vals[4:9, 8:10, 8:12] = 3.0e-41
    src = arr_f32(vals, (9, 10, 12))
    d, _, t, bl = simple_file(src, FLOAT32, codec=CODEC_PLANES, meta_codec=CODEC_PLANES, minor=2)
    assert all(b.codec == CODEC_PLANES for b in bl) and any(b.stream == 2 and b.count > 1 for b in bl)
    add_valid("codec2_gradient_12x10x9_float32", d, src, FLOAT32,
              "The volume of gradient_12x10x9_float32 with EVERY block codec 2: values of width 4 "
              "(four byte planes), node words of width 8 (eight planes; §7 does not restrict codec 2 to "
              "the values stream) and the metadata of width 1 (where codec 2 is codec 1).%s" % V2)

    src = vol_object_in_air(24, 20, 18, UINT16, 106, 300, (11.0, 10.0, 9.0), 7.5, 20000, 40000)
    d, _, t, bl = simple_file(src, UINT16, codec="cycle", limit=48, meta_first=True,
                              scale=2.0 ** -12, offset=-1.0, minor=2)
    per = {}
    for b in bl:
        per.setdefault((b.stream, b.level), set()).add(b.codec)
    assert any(c == {0, 1, 2} for c in per.values())
    add_valid("codec2_multiblock_24x20x18_uint16", d, src, UINT16,
              "The volume of multiblock_24x20x18_uint16 (uint16, scale 2^-12, offset -1), blocks of at most "
              "48 decoded bytes; the metadata block first (codec 1), then the level blocks with codecs 0, 1, "
              "2, 0, 1, 2, ... in file order, so one stream and level mixes stored, zstd and byte-plane "
              "blocks, for values (width 2) and nodes (width 8).%s" % V2)

    src = arr_f32([0.1], (1, 1, 1))
    d, *_ = simple_file(src, FLOAT32, codec=CODEC_PLANES, meta_codec=CODEC_PLANES, minor=2)
    add_valid("codec2_tiny_1x1x1_float32", d, src, FLOAT32,
              "1x1x1 float32 (0.1f): the one values block (one element, n = 1: the planes are the "
              "element's bytes in order) and the metadata block are codec 2.%s" % V2)

    rng = np.random.default_rng(101)                       # the volume of odd_3x5x7_uint16
    src = rng.integers(0, 4096, size=(7, 5, 3)).astype(np.uint16)
    src[0:2, 0:2, 0:2] = 777
    src[4:7, 4:5, 0:3] = 1234
    src[2:4, 2:4, 2:3] = 55
    d, _, t, bl = simple_file(src, UINT16, codec="planes", zcheck=False, scale=0.0007, offset=-1.25,
                              minor=2)
    for b in bl:
        assert not zstandard.get_frame_parameters(b.stored_bytes()).has_checksum
    add_valid("codec2_no_checksum_3x5x7_uint16", d, src, UINT16,
              "The volume of odd_3x5x7_uint16 with its values blocks codec 2 and every zstd frame (codec 1 "
              "and 2) without the optional content checksum.%s" % V2)

    src, g = rectilinear_20x11x7_uint16()
    d, lay, bl = grid_file(g, codec=CODEC_PLANES, limit=16, slimit=8, meta_first=True, scale=0.5,
                           offset=-1000.0, minor=2)
    assert {(b.stream, b.codec) for b in bl} == {(1, 1), (3, 2), (4, 2)}
    add_valid("codec2_rectilinear_20x11x7_uint16", d, src, UINT16,
              "The rectilinear grid of rectilinear_20x11x7_uint16 (structure_kind 3) with every borders "
              "block (u32, width 4) and values block (width 2) codec 2, metadata codec 1; 13 borders in 7 "
              "blocks, 18 values in 3 blocks.%s" % V2, kind=KIND_RECTILINEAR)

    src, g, meta = nested_37x21x10_uint16_c8()
    d, lay, bl = grid_file(g, meta=meta, codec=CODEC_PLANES, limit=512, slimit=64, scale=0.25,
                           offset=-512.0, minor=2)
    assert {(b.stream, b.codec) for b in bl} == {(1, 1), (3, 2), (5, 2)}
    add_valid("codec2_nested_37x21x10_uint16_c8", d, src, UINT16,
              "The nested grid of nested_37x21x10_uint16_c8 (structure_kind 4, cell_log2 3) with every cells "
              "block (u64 cell words, width 8) and values block codec 2, metadata codec 1.%s" % V2,
              kind=KIND_NESTED, extra={"cell_log2": 3})

    d, _, t, bl = simple_file(base_src, UINT16, codec="planes", minor=0)
    add_valid("codec2_minor_0", d, base_src, UINT16,
              "6x5x4 uint16 octree with its values blocks codec 2 but version_minor 0: §4 asks writers "
              "for at least 2, but readers MUST NOT refuse a file for its minor version (§4, §14.1); a "
              "reader that knows codec 2 reads it.")

    t = build_tree(base_src, UINT16)
    bl = level_blocks(t, CODEC_ZSTD)
    bl.insert(2, Blk(200, 0, 0, 24, b"codec 255: skip me all\x00\x01", codec=255, flags=1))
    bl.append(meta_block(DEFAULT_META))
    d, _ = assemble(t, bl)
    add_valid("ignorable_stream_200_codec_255", d, base_src, UINT16,
              "ignorable_stream_200 with codec 255 (unknown) in the entry of its ignorable stream-200 "
              "block: a reader that does not know the stream gives its codec no meaning (§6.4) and skips "
              "the block.")


def gen_codec2_invalid(bt, vblk, nblk1):
    """Invalid codec-2 blocks: the frame rules of codec 1 apply to codec 2
    (§7). The 6x5x4 uint16 octree of the other invalid files, values blocks
    codec 2, version_minor 2; one defect in the values block of level 2."""
    what = "6x5x4 uint16 octree (values blocks codec 2, version 1.2): the values block of level 2"

    def c2(stored_of, minor=2, blk=None, codec=CODEC_PLANES):
        bl = level_blocks(bt, "planes")
        bl.append(meta_block(DEFAULT_META))
        b = bl[vblk if blk is None else blk]
        b.codec = codec
        b.stored = stored_of(b.data, byte_planes(b.data, len(b.data) // b.count))
        d, _ = assemble(bt, bl, minor=minor)
        return d

    def inv(name, data, expect, tag, desc):
        add_invalid(name, data, expect, tag, desc)

    def bad_checksum(data, content):
        fr = bytearray(zframe(content))
        assert zstandard.get_frame_parameters(bytes(fr)).has_checksum
        fr[-1] ^= 0xFF
        return bytes(fr)

    inv("codec2_content_checksum_bad", c2(bad_checksum), "checksum", "zstd.checksum",
        "%s has a wrong zstd content checksum (last byte of the frame changed, block CRC recomputed): "
        "class checksum as for codec 1 (§7, §13). The checksum is XXH64 of the frame's content, the byte "
        "planes, not of the regrouped elements." % what)
    inv("codec2_no_content_size", c2(lambda data, content: zframe(content, content_size=False)),
        "malformed", "zstd.content_size",
        "%s is a zstd frame without Frame_Content_Size (codec 2 follows every rule of codec 1)." % what)
    inv("codec2_content_size_one_element_more",
        c2(lambda data, content: zframe(byte_planes(data + b"\x01\x00", 2))),
        "malformed", "zstd.content_size",
        "%s is a frame of the byte planes of element_count + 1 elements: Frame_Content_Size is "
        "element_count x 2 + 2, not element_count x width." % what)
    inv("codec2_content_size_one_byte_short", c2(lambda data, content: zframe(content[:-1])),
        "malformed", "zstd.content_size",
        "%s is a frame of its byte planes without their last byte: Frame_Content_Size is "
        "element_count x 2 - 1 (not even a whole number of elements)." % what)
    inv("codec2_one_frame_per_plane",
        c2(lambda data, content: zframe(content[:len(content) // 2]) + zframe(content[len(content) // 2:])),
        "malformed", "zstd.content_size",
        "%s is two zstd frames, one per byte plane (low bytes, then high bytes): a codec-2 block is "
        "exactly one frame holding all planes." % what)
    inv("codec2_trailing_skippable_frame",
        c2(lambda data, content: zframe(content) + struct.pack("<II", 0x184D2A50, 4) + b"skip"),
        "malformed", "zstd.extra",
        "%s is a correct frame of its byte planes followed by a skippable frame." % what)
    inv("codec2_trailing_bytes", c2(lambda data, content: zframe(content) + b"\x00\x00\x00"),
        "malformed", "zstd.extra",
        "%s is a correct frame of its byte planes followed by 3 zero bytes (stored_size and CRC "
        "include them)." % what)

    def with_dict_id(data, content):
        fr = bytearray(zframe(content))
        fhd = fr[4]
        assert fhd & 3 == 0
        at = 5 + (0 if (fhd >> 5) & 1 else 1)           # after the Window_Descriptor, if any
        fr[4] = fhd | 1                                  # Dictionary_ID_Flag 1: one byte
        fr[at:at] = b"\x2a"
        assert zstandard.get_frame_parameters(bytes(fr)).dict_id == 42
        return bytes(fr)

    inv("codec2_dictionary_id", c2(with_dict_id), "malformed", "zstd.dict",
        "%s is a frame whose header names Dictionary_ID 42 (one byte inserted into the frame header): "
        "the frame must not need a dictionary." % what)
    inv("codec2_raw_planes", c2(lambda data, content: content), "malformed", "zstd.frame",
        "%s holds its byte planes uncompressed (stored_size = element_count x 2, as for codec 0, but no "
        "zstd frame): codec 2 stored bytes are one zstd frame." % what)

    def rows_not_planes(data, content):
        assert content != data
        return zframe(data)

    inv("codec2_nodes_not_regrouped", c2(rows_not_planes, blk=nblk1), "malformed", None,
        "6x5x4 uint16 octree, version 1.2: the nodes block of level 1 (%d node words) is marked codec 2 "
        "but its frame holds the words in element order (a codec-1 frame): regrouped as byte planes of "
        "width 8 they are not the node words of §8, and the tree's rules fail." % bt.inner_count[1])

    S = (1 << 25) + 1                                    # 2 x S = 64 MiB + 2 decoded bytes
    g = Grid(KIND_REGULAR, UINT16, (S, 1, 1), [])
    big = Blk(STREAM_VALUES, 0, 0, S, bytes(2 * S), codec=CODEC_PLANES)
    d, _ = assemble(g, [big, meta_block(DEFAULT_META)], minor=2, structure_kind=KIND_REGULAR)
    inv("codec2_block_decoded_64mib_plus_2", d, "malformed", "block.too_large",
        "Regular grid %d x 1 x 1 uint16 (depth 26), all zero, in ONE values block of codec 2 with "
        "element_count %d: decoded size element_count x width = 64 MiB + 2 > 64 MiB (§7); the frame "
        "(%d bytes) holds exactly that many bytes. Stream coverage is exact; a reader must refuse it "
        "from the index (element_count x width, not element_count alone) before allocating."
        % (S, S, len(big.stored_bytes())))



def gen_codec6():
    """§7.4 codec 6 (1.3 draft): the top byte in context, on bricks of binary16,
    uint16 and float32, then files that break one rule each.  Own generator
    (seed), after all others, so the vectors before keep their bytes."""
    rng = np.random.default_rng(2606)

    # binary16 noise around zero: signs flip, the top byte spans many contexts
    src = arr_f16(rng.normal(0.0, 0.02, 12 * 10 * 9), (9, 10, 12))
    flat = src.reshape(-1)
    flat[[0, 7, 100, 333, 600, 1079]] = [0x8000, 0x7E01, 0xFC00, 0x0001, 0x7BFF, 0x8000]
    add_valid_bricked(
        "bricked_12x10x9_binary16_codec6_noise", framed_bricked_file(
            src, BINARY16, 3, CODEC_TOP_BYTE, centre=40, step=6),
        src, BINARY16, 3,
        "Bricked grid 12x10x9 binary16 of noise around zero (signs flip), bricks of 8 (edge extents 4, 2 "
        "and 1), every brick codec 6 (§7.4) with centre 40 and step 6: the top bytes coded in 128 contexts "
        "from the x, y and z neighbours' top bytes (0 outside the brick), the low bytes stored. -0, a NaN "
        "with a payload, -inf, the smallest subnormal and the largest finite value come back bit for bit.")

    # float32: several centres and steps, including the extremes, one brick each
    src = smooth_f32(9, 8, 7, rng, lo=-0.05, noise=0.08)
    put_bits(src, {(0, 0, 0): 0x80000000, (8, 7, 6): 0x7FC01234, (4, 4, 4): 0xFF800000})
    per = lambda q: [dict(centre=0, step=1, mode=1), dict(centre=127, step=255), dict(centre=61, step=4, mode=1),
                     dict(centre=63, step=2)][q % 4]
    add_valid_bricked(
        "bricked_9x8x7_float32_codec6_steps", framed_bricked_file(
            src, FLOAT32, 2, CODEC_TOP_BYTE, per_brick=per),
        src, FLOAT32, 2,
        "Bricked grid 9x8x7 float32 around zero, bricks of 4, every brick codec 6 with its own centre, "
        "step and mode, cycling (0, 1, mode 1), (127, 255, mode 0), (61, 4, mode 1), (63, 2, mode 0): "
        "classes below 0 and above 31 are clamped, m - 3C < 0 is floored; mode 1 codes the second byte's "
        "high nibble in the context of the top byte and stores two planes and the low nibbles, mode 0 "
        "stores three planes. -0, a NaN payload and -inf kept.")

    src = smooth_f32(5, 3, 3, rng, lo=0.01, noise=0.02)
    add_valid_bricked(
        "bricked_5x3x3_float32_codec6_odd_nibbles", framed_bricked_file(
            src, FLOAT32, 3, CODEC_TOP_BYTE, centre=60, step=3, mode=1),
        src, FLOAT32, 3,
        "Bricked grid 5x3x3 float32, one brick of 45 voxels as codec 6 mode 1: the low nibbles take "
        "ceil(45 / 2) = 23 bytes, the last one's high nibble the 0 padding.")
    src = arr_f16(rng.normal(0.5, 0.2, 7 * 6 * 5), (5, 6, 7))
    add_valid_bricked(
        "bricked_7x6x5_binary16_codec6_mode1", framed_bricked_file(
            src, BINARY16, 3, CODEC_TOP_BYTE, centre=56, step=4, mode=1),
        src, BINARY16, 3,
        "Bricked grid 7x6x5 binary16, one brick of 210 voxels as codec 6 mode 1 (either mode is valid "
        "for either width): the low byte's high nibble coded, its low nibbles stored, no whole plane.")

    # uint16: codec 6 among codecs 3, 0 and 2
    src = rng.integers(0, 65536, (6, 6, 6)).astype(np.uint16)
    src[:, :3, :] = 30000 + rng.integers(0, 50, (6, 3, 6))
    add_valid_bricked(
        "bricked_6x6x6_uint16_codec6_mixed", framed_bricked_file(
            src, UINT16, 2, lambda q: (CODEC_TOP_BYTE, CODEC_PREDICTED, CODEC_STORED, CODEC_PLANES)[q % 4],
            value_map=0),
        src, UINT16, 2,
        "Bricked grid 6x6x6 uint16, bricks of 4, the blocks cycling codecs 6, 3, 0 and 2; half random bits, "
        "half a level with little noise.")

    # a brick of one voxel
    src = np.array([[[0xBC00]]], np.uint16)
    add_valid_bricked(
        "bricked_1x1x1_binary16_codec6", framed_bricked_file(src, BINARY16, 1, CODEC_TOP_BYTE,
                                                             centre=0, step=1),
        src, BINARY16, 1, "Bricked grid of one voxel (-1.0) as codec 6: one top byte, one low byte.", lods=False)

    # ---- invalid: one rule broken each
    src = arr_f16(rng.normal(0.0, 0.05, 6 * 5 * 4), (4, 5, 6))
    n0 = 4 * 4 * 4

    def inv(name, tag, desc, mutate, expect="malformed"):
        add_invalid(name, framed_bricked_file(src, BINARY16, 2, CODEC_TOP_BYTE, mutate=mutate, centre=30,
                                              step=5), expect, tag, desc)

    def first(fn):
        def mutate(blocks):
            blocks[0].stored = fn(top_byte_payload(blocks[0].data, (4, 4, 4), 2, 30, 5))
        return mutate

    def byte(off, value):
        return first(lambda st: st[:off] + bytes([value]) + st[off + 1:])

    inv("bricked_codec6_centre_128", "codec6.centre", "A codec 6 block whose centre (payload byte 0) is 128.",
        byte(0, 128))
    inv("bricked_codec6_step_0", "codec6.step", "A codec 6 block whose step (payload byte 1) is 0.", byte(1, 0))
    inv("bricked_codec6_reserved", "codec6.reserved", "A codec 6 block whose reserved payload byte 3 is 1.",
        byte(3, 1))
    inv("bricked_codec6_mode_2", "codec6.mode", "A codec 6 block whose mode (payload byte 2) is 2.", byte(2, 2))
    odd = smooth_f32(5, 3, 3, rng, lo=0.01, noise=0.02)

    def padding(blocks):
        st = bytearray(top_byte_payload(blocks[0].data, (5, 3, 3), 4, 60, 3, mode=1))
        st[-1] |= 0x10
        blocks[0].stored = bytes(st)

    add_invalid("bricked_codec6_padding_nibble", framed_bricked_file(odd, FLOAT32, 3, CODEC_TOP_BYTE, mutate=padding,
                                                                    centre=60, step=3, mode=1),
                "malformed", "codec6.padding",
                "A codec 6 mode 1 block of 45 float32 values whose last low-nibble byte has a padding nibble "
                "of 1 (it must be 0).")
    inv("bricked_codec6_short", "codec6.short", "A codec 6 block of 6 bytes, shorter than its header.",
        first(lambda st: st[:6]))
    inv("bricked_codec6_stream_size_3", "codec6.stream_size",
        "A codec 6 block whose rANS stream length R is 3 (below 4).",
        first(lambda st: st[:4] + struct.pack("<I", 3) + st[8:]))
    inv("bricked_codec6_stream_size_over_2n_plus_4", "codec6.stream_size",
        "A codec 6 block whose R is 2n + 5 = %d for the n = %d voxels of its brick." % (2 * n0 + 5, n0),
        first(lambda st: st[:4] + struct.pack("<I", 2 * n0 + 5) + st[8:]))
    inv("bricked_codec6_trailing_byte", "codec6.size",
        "A codec 6 block with one byte after its lower plane (8 + R + (w - 1)n + 1 bytes).",
        first(lambda st: st + b"\0"))
    inv("bricked_codec6_initial_state", "codec6.initial_state",
        "A codec 6 block whose initial rANS state is 2^31 (above 2^31 - 1).",
        first(lambda st: st[:8] + struct.pack("<I", 1 << 31) + st[12:]))

    def wrong_state(st):
        (R,) = struct.unpack_from("<I", st, 4)
        b = bytearray(st)
        b[8 + R - 1] ^= 0x5A     # the last stream byte: every voxel decodes, the state ends elsewhere
        return bytes(b)

    inv("bricked_codec6_final_state", None,
        "A codec 6 block with the last byte of its rANS stream changed: the voxels decode, but the final "
        "state is not 2^23, or the stream runs out or is left over (§7.4: malformed either way).",
        first(wrong_state))

    g = write_bricked(src, BINARY16, 2)
    blocks = bricked_blocks(g, CODEC_TOP_BYTE, centre=30, step=5)
    blocks[0].stored = top_byte_payload(blocks[0].data, (4, 4, 4), 2, 30, 5) + bytes(4 * n0 + 12)
    blocks.insert(0, meta_block(DEFAULT_META))
    data, _ = assemble(g, blocks, structure_kind=KIND_BRICKED, ireserved=2, framed=True, minor=3)
    add_invalid("bricked_codec6_stored_size_over_bound", data, "malformed", "block.stored_bound",
                "A codec 6 block whose stored_size exceeds 12 + wn + 32 (§7), refused with the "
                "block table before the block is read.")

    # codec 6 on a regular grid (structure_kind 2) is not allowed
    reg = write_regular(src, BINARY16)
    rblocks = grid_blocks(reg, CODEC_ZSTD)
    rblocks[0].stored = top_byte_payload(rblocks[0].data, (6, 5, 4), 2, 30, 5)
    rblocks[0].codec = CODEC_TOP_BYTE
    data, _ = assemble(reg, [meta_block(DEFAULT_META)] + rblocks, structure_kind=KIND_REGULAR, framed=True,
                       minor=3)
    add_invalid("regular_with_codec6", data, "malformed", "codec6.where",
                "A regular grid (structure_kind 2) whose values block is codec 6: valid only on a bricked grid.")


def gen_codec5():
    """§7 codec 5 (1.3 draft): byte planes, a zstd frame each, on every stream
    of width >= 2 (node words, values, borders, cell words, stored levels of
    detail), then files that break one rule of codec 5 each.  Own generator
    (seed), after all others, so the vectors before keep their bytes."""
    framed = dict(framed=True, minor=3)
    rng = np.random.default_rng(2505)
    V3 = " Version 1.3 (version_minor 3)."

    def bricked_file(src, enc, b, codec, frames=None, levels=None, lod_frames=None):
        """A framed bricked grid of `src` (bricks of 2^b): the metadata first,
        then one values block per brick (codec(q) for brick q); frames(q, blk)
        may replace a codec 5 brick's stored bytes.  levels {k: codec} store
        levels of detail k in stream 7 (computed from the source, §12.3), and
        lod_frames(k, q, blk) may replace their stored bytes."""
        g = write_bricked(src, enc, b)
        blocks = bricked_blocks(g, codec)
        for q, blk in enumerate(blocks):
            st = frames(q, blk) if frames else None
            if st is not None:
                blk.stored = st
        lods = flat_lods(src, enc, g.D) if levels else {}
        for k in sorted(levels or {}):
            lb = lod_level_blocks(lods[k], enc, b, k, levels[k])
            for q, blk in enumerate(lb):
                st = lod_frames(k, q, blk) if lod_frames else None
                if st is not None:
                    blk.stored = st
            blocks += lb
        blocks.insert(0, meta_block(DEFAULT_META))
        data, _ = assemble(g, blocks, structure_kind=KIND_BRICKED, ireserved=b, **framed)
        return data, blocks

    def codecs_of(blocks, stream):
        return [b.codec for b in blocks if b.stream == stream]

    # ---- float32 bricked grid: codec 5 among codecs 0, 1, 2; every kind of frame; stored levels
    src = smooth_f32(9, 5, 5, rng)
    put_bits(src, {(0, 0, 0): 0x80000000,          # -0, brick 0 (codec 5, frames of every kind)
                   (2, 2, 2): 0x7FC01234,          # quiet NaN with a payload, brick 0
                   (5, 1, 3): 0x00400000,          # subnormal, brick 1 (codec 0)
                   (8, 1, 1): 0x7F800000,          # +inf, brick 2 (1x4x4, codec 5)
                   (1, 4, 1): 0x7F812345,          # signalling NaN with a payload, brick 3 (codec 1)
                   (5, 4, 2): 0xFF800000,          # -inf, brick 4 (4x1x4, codec 5 without checksums)
                   (1, 1, 4): 0xFFC00001,          # negative quiet NaN, brick 6 (4x4x1, raw frames)
                   (6, 2, 4): 0x7FA00001,          # signalling NaN, brick 7 (codec 5)
                   (8, 3, 4): 0x00000001,          # smallest subnormal, brick 8 (1x4x1)
                   (6, 4, 4): 0x80000000,          # -0, brick 10 (4x1x1)
                   (8, 4, 4): 0x807FFFFF})         # largest negative subnormal: brick 11, 1x1x1 (n = 1)
    per_brick = [CODEC_FRAMES, CODEC_STORED, CODEC_FRAMES, CODEC_ZSTD, CODEC_FRAMES, CODEC_PLANES,
                 CODEC_FRAMES, CODEC_FRAMES, CODEC_FRAMES, CODEC_PLANES, CODEC_FRAMES, CODEC_FRAMES]

    def frames32(q, blk):
        if q == 0:      # each plane a frame of another kind
            def one(p, plane):
                if p == 0:      # a compressor's frame of several zstd blocks (a block every 16 bytes)
                    return multiblock_zframe(plane, 16, checksum=True)
                if p == 1:      # a compressor's frame without checksum
                    return zframe(plane, checksum=False)
                if p == 2:      # one raw block, a Window_Descriptor, no checksum
                    return hand_zframe(plane, single_segment=False)
                blocks = runs_as_blocks(plane)      # raw and RLE blocks, with checksum
                assert any(k == "rle" for k, _ in blocks) and any(k == "raw" for k, _ in blocks)
                return hand_zframe(plane, blocks, checksum=True)
            return plane_frames(blk.data, 4, frame=one)
        if q == 4:      # no content checksum in any frame
            return plane_frames(blk.data, 4, checksum=False)
        if q == 6:      # each plane one raw block, Frame_Content_Size in 1 byte, with checksum
            return plane_frames(blk.data, 4, frame=lambda p, plane: hand_zframe(plane, fcs_bytes=1,
                                                                               checksum=True))
        if q == 8:      # frames with and without checksum alternate
            return plane_frames(blk.data, 4, frame=lambda p, plane: zframe(plane, checksum=p % 2 == 0))
        return None

    def lod_frames32(k, q, blk):
        if k == 3:      # n = 2: frames without checksum
            return plane_frames(blk.data, 4, checksum=False)
        return None

    d, bl = bricked_file(src, FLOAT32, 2, lambda q: per_brick[q], frames32,
                         levels={1: CODEC_FRAMES, 2: CODEC_FRAMES, 3: CODEC_FRAMES, 4: CODEC_FRAMES},
                         lod_frames=lod_frames32)
    assert codecs_of(bl, STREAM_VALUES) == per_brick and set(codecs_of(bl, STREAM_LOD)) == {CODEC_FRAMES}
    assert sorted(b.count for b in bl if b.stream == STREAM_LOD) == [1, 2, 9, 12, 36]
    add_valid("codec5_bricked_9x5x5_float32_mixed", d, src, FLOAT32,
              "Bricked grid (structure_kind 5) 9x5x5 float32, bricks of 4: 12 bricks of 64, 16, 4 and 1 "
              "values (the corner brick 1x1x1, n = 1), one block each, of codecs 5, 0, 5, 1, 5, 2, 5, 5, "
              "5, 2, 5, 5 (§8A.4: a float32 grid's bricks are of codecs 0, 1, 2 or 5). A codec 5 block is "
              "4 zstd frames back to back, frame p the byte plane p of the brick's values (§7). Brick 0's "
              "four frames are each of another kind: a compressor's frame of several zstd blocks (a block "
              "every 16 bytes, then an empty last block) with checksum, a compressor's frame without "
              "checksum, one raw block under a Window_Descriptor (no single segment), and a hand-made frame "
              "of raw and RLE blocks with checksum; brick 4's frames have no checksum, brick 6's are each "
              "one raw block with a 1-byte Frame_Content_Size and a checksum, brick 8's alternate with and "
              "without checksum, the others are compressor frames with checksum. Values: a gradient with "
              "-0, +inf, -inf, NaNs with payloads (quiet, signalling, negative) and subnormals, every bit "
              "pattern passed through (§9). Stored levels of detail 1 .. 4 (stream 7, §8A.5), every block "
              "codec 5: level 1 (5x3x3, bricks of 36 and 9), 2 (3x2x2), 3 (2x1x1: n = 2, frames without "
              "checksum) and 4 (1x1x1: n = 1, four frames of one byte).%s" % V3,
              kind=KIND_BRICKED, extra={"brick_log2": 2, "stored_levels": [1, 2, 3, 4]})

    # ---- binary16 bricked grid: codec 5 among codecs 2, 3, 4; stored levels all codec 5
    src = arr_f16(np.round(rng.normal(0.5, 0.2, 10 * 5 * 5), 3), (5, 5, 10))
    src[0:2, 0:2, 0:2] = 0x8000                      # a level-1 cell of -0: +0 in the levels
    put_bits(src, {(5, 1, 1): 0x7C01,                # a NaN with a payload: the canonical NaN above it
                   (9, 2, 0): 0x7C00,                # +inf
                   (2, 4, 3): 0xFC00,                # -inf, brick 3 (4x1x4)
                   (6, 3, 4): 0x0001,                # smallest subnormal
                   (1, 2, 4): 0x83FF,                # largest negative subnormal
                   (8, 4, 4): 0xFE00})               # negative NaN: brick 11 (2x1x1, n = 2)
    per_brick = [CODEC_FRAMES, CODEC_PREDICTED, CODEC_FRAMES, CODEC_MASKED, CODEC_FRAMES, CODEC_FRAMES,
                 CODEC_PLANES, CODEC_FRAMES, CODEC_FRAMES, CODEC_PREDICTED, CODEC_FRAMES, CODEC_FRAMES]

    def frames16(q, blk):
        if q == 2:      # 1x4x4: no checksum
            return plane_frames(blk.data, 2, checksum=False)
        if q == 11:     # n = 2: each plane one raw block, 1-byte Frame_Content_Size
            return plane_frames(blk.data, 2, frame=lambda p, plane: hand_zframe(plane, fcs_bytes=1,
                                                                               checksum=p == 1))
        return None

    def lod_frames16(k, q, blk):
        if k == 1 and q == 1:
            return plane_frames(blk.data, 2, checksum=False)
        if k == 2:
            return plane_frames(blk.data, 2, frame=lambda p, plane: multiblock_zframe(plane, 4)
                                if p == 0 else None)
        return None

    d, bl = bricked_file(src, BINARY16, 2, lambda q: per_brick[q], frames16,
                         levels={k: CODEC_FRAMES for k in range(1, 5)}, lod_frames=lod_frames16)
    assert codecs_of(bl, STREAM_VALUES) == per_brick
    add_valid("codec5_bricked_lods_10x5x5_binary16", d, src, BINARY16,
              "Bricked grid 10x5x5 binary16, bricks of 4: 12 bricks (the last 2x1x1, n = 2) of codecs 5, 3, "
              "5, 4, 5, 5, 2, 5, 5, 3, 5, 5: a codec 5 block is 2 zstd frames, the low bytes of the brick's "
              "values, then their high bytes (§7); brick 2's frames have no checksum, brick 11's are each "
              "one raw block (Frame_Content_Size in 1 byte), the first without, the second with checksum. "
              "Stored levels of detail 1 .. 4 (stream 7, §8A.5), every block codec 5: level 1 (5x3x3, "
              "bricks of 36 and 9 elements, the second without checksums), level 2 (3x2x2, its low plane "
              "a frame of several zstd blocks), level 3 (2x1x1, n = 2), level 4 (1x1x1, n = 1). -0 (a "
              "2x2x2 cell of it: +0 in the levels), NaN 0x7C01 and 0xFE00, +inf, -inf, subnormals; the "
              "levels hold +0 and the canonical NaN 0x7E00 where §12.3 gives them.%s" % V3,
              kind=KIND_BRICKED, extra={"brick_log2": 2, "stored_levels": [1, 2, 3, 4]})

    # ---- octree (unframed): node words (w = 8) and values (w = 2) codec 5
    src = vol_object_in_air(24, 20, 18, UINT16, 106, 300, (11.0, 10.0, 9.0), 7.5, 20000, 40000)
    t = build_tree(src, UINT16)
    bl = level_blocks(t, CODEC_FRAMES, limit=48)
    for n, b in enumerate(bl):
        b.zcheck = n % 3 != 2                    # every third block's frames without checksum
    bl.insert(0, meta_block(DEFAULT_META))
    d, _ = assemble(t, bl, scale=2.0 ** -12, offset=-1.0, minor=3)
    nodes = [b for b in bl if b.stream == STREAM_NODES]
    assert nodes[0].count == 1 and all(b.codec == CODEC_FRAMES for b in bl[1:])
    add_valid("codec5_octree_24x20x18_uint16", d, src, UINT16,
              "The volume of multiblock_24x20x18_uint16 (octree, uint16, scale 2^-12, offset -1) WITHOUT "
              "framed blocks (§7: codec 5 does not need them; its stored bytes are then the w frames "
              "alone): every nodes block (node words, w = 8: eight frames, one per byte of the u64) and "
              "every values block (w = 2) codec 5, the metadata first, codec 1; blocks of at most 48 "
              "decoded bytes (%d nodes blocks, %d values blocks; the root's node word and value are blocks "
              "of one element, n = 1), every third block's frames without checksum.%s"
              % (len(nodes), sum(1 for b in bl if b.stream == STREAM_VALUES), V3))

    rng2 = np.random.default_rng(105)                       # the volume of gradient_12x10x9_float32
    z, y, x = np.mgrid[0:9, 0:10, 0:12]
    vals = 0.01 * x + 0.1 * y - 0.05 * z + rng2.normal(0, 1e-4, (9, 10, 12))
    vals[0:4, 0:8, 0:8] = -7.25
    vals[4:9, 8:10, 8:12] = 3.0e-41
    src = arr_f32(vals, (9, 10, 12))
    t = build_tree(src, FLOAT32)
    bl = level_blocks(t, CODEC_FRAMES)
    big = max((b for b in bl if b.stream == STREAM_VALUES), key=lambda b: b.count)
    multi = []

    def thirds(p, plane):                    # a block ends after every third of the plane
        fr = multiblock_zframe(plane, -(-len(plane) // 3))
        multi.append(zstd_block_types(fr).count("compressed"))
        return fr
    big.stored = plane_frames(big.data, 4, frame=thirds)
    assert max(multi) >= 2
    bl.insert(0, meta_block(DEFAULT_META))
    d, _ = assemble(t, bl, **framed)
    assert all(b.codec == CODEC_FRAMES for b in bl[1:]) and any(b.stream == 2 and b.count > 1 for b in bl)
    add_valid("codec5_octree_framed_12x10x9_float32", d, src, FLOAT32,
              "The volume of gradient_12x10x9_float32 (octree) with framed blocks, every nodes block (w = 8) "
              "and values block (w = 4) codec 5, the metadata first (codec 1); one block per stream and "
              "level. The largest values block (level %d, n = %d) has frames of several zstd blocks (a "
              "block ends after every third of its plane; %s compressed blocks in its four frames), so "
              "a decoder carries the frame's history from block to block. The limit of §7 is w·bound(n) "
              "plus 32 for the block header.%s" % (big.level, big.count, ", ".join(map(str, multi)), V3))

    # ---- grids: borders (w = 4) and cell words (w = 8) codec 5
    src, g = rectilinear_20x11x7_uint16()
    d, lay, bl = grid_file(g, codec=CODEC_FRAMES, limit=16, slimit=8, meta_first=True, scale=0.5,
                           offset=-1000.0, **framed)
    assert {(b.stream, b.codec) for b in bl} == {(1, 1), (3, 5), (4, 5)}
    assert any(b.stream == STREAM_BORDERS and b.count == 1 for b in bl)
    add_valid("codec5_rectilinear_20x11x7_uint16", d, src, UINT16,
              "The rectilinear grid of rectilinear_20x11x7_uint16 (structure_kind 3) with framed blocks, "
              "every borders block (u32, w = 4: four frames) and values block (w = 2) codec 5, metadata "
              "first, codec 1; 13 borders in 7 blocks (the last of one border, n = 1), 18 values in 3 "
              "blocks.%s" % V3, kind=KIND_RECTILINEAR)

    src, g, meta = nested_37x21x10_uint16_c8()
    d, lay, bl = grid_file(g, meta=meta, codec=CODEC_FRAMES, limit=512, slimit=56, scale=0.25,
                           offset=-512.0, minor=3)
    assert {(b.stream, b.codec) for b in bl} == {(1, 1), (3, 5), (5, 5)}
    add_valid("codec5_nested_37x21x10_uint16_c8", d, src, UINT16,
              "The nested grid of nested_37x21x10_uint16_c8 (structure_kind 4, cell_log2 3), without "
              "framing, every cells block (u64 cell words, w = 8: eight frames; blocks of 7, 7, 7, 7 and 2 "
              "cell words) and values block codec 5, metadata codec 1.%s" % V3,
              kind=KIND_NESTED, extra={"cell_log2": 3})

    # ---- the limit of §7: w·bound(n), reached exactly (valid) and by one byte more (invalid)
    assert zstd_bound(1) == 64 and zstd_bound(4) == 67
    src_b = smooth_f32(5, 5, 5, rng)

    def at_bound(extra):
        """The 1x1x1 brick (n = 1, w = 4) as 4 legal frames of one byte each,
        padded with empty raw blocks to 4·bound(1) = 256 bytes (+ extra)."""
        def f(q, blk):
            if q != 7:
                return None
            planes = planes_of(blk.data, 4)
            fr = [hand_zframe(planes[0], fcs_bytes=1, empties=16),                      # 10 + 48
                  hand_zframe(planes[1], fcs_bytes=4, empties=16, single_segment=not extra),  # 13 (14) + 48
                  hand_zframe(planes[2], fcs_bytes=4, checksum=True, empties=17),      # 17 + 51
                  hand_zframe(planes[3], fcs_bytes=4, checksum=True, single_segment=False, empties=17)]
            st = b"".join(fr)
            assert len(st) == 4 * zstd_bound(1) + extra
            return st
        return f

    d, bl = bricked_file(src_b, FLOAT32, 2, CODEC_FRAMES, at_bound(0))
    assert bl[8].count == 1 and len(bl[8].stored_bytes()) == 256
    add_valid("codec5_stored_size_at_bound_5x5x5_float32", d, src_b, FLOAT32,
              "Bricked grid 5x5x5 float32, bricks of 4, every brick codec 5; the last brick (1x1x1: n = 1, "
              "w = 4) is 4 legal frames of one byte each, padded with empty raw zstd blocks to exactly "
              "w·bound(n) = 4 x 64 = 256 bytes of payload (stored_size 288 with the block header), the "
              "largest §7 allows for codec 5. A reader that applied codec 2's limit, bound(w·n) = "
              "bound(4) = 67 (+ 32), would refuse it.%s" % V3,
              kind=KIND_BRICKED, extra={"brick_log2": 2})
    d, bl = bricked_file(src_b, FLOAT32, 2, CODEC_FRAMES, at_bound(1))
    add_invalid("codec5_stored_size_over_bound", d, "malformed", "block.stored_bound",
                "codec5_stored_size_at_bound_5x5x5_float32 with one byte more in the codec 5 block of its "
                "1x1x1 brick (its second frame has a Window_Descriptor): 257 bytes of payload, stored_size "
                "289 > w·bound(n) + 32 = 288 (§7). Every frame is legal and the block's CRCs hold; a reader "
                "refuses it with the block table, before it reads any block.")

    # ---- invalid: one defect in the codec 5 block of brick 1 of a float32 grid
    src_i = smooth_f32(6, 5, 4, rng)
    what = ("Bricked grid 6x5x4 float32, bricks of 4, every brick codec 5 (4 frames with checksum, "
            "framed, version 1.3): the block of brick 1 (2x4x4, n = 32)")

    def inv(name, expect, tag, desc, stored_of):
        def f(q, blk):
            return stored_of(blk.data, planes_of(blk.data, 4)) if q == 1 else None
        d, bl = bricked_file(src_i, FLOAT32, 2, CODEC_FRAMES, f)
        assert bl[2].count == 32
        add_invalid(name, d, expect, tag, "%s %s" % (what, desc))

    def zf(planes, p):
        return zframe(planes[p])

    def frames(planes, order=range(4)):
        return b"".join(zframe(planes[p]) for p in order)

    inv("codec5_three_frames", "malformed", "codec5.frames",
        "is 3 frames (planes 0, 1 and 2) instead of w = 4: fewer than w frames (§7).",
        lambda data, planes: frames(planes, range(3)))
    inv("codec5_five_frames", "malformed", "codec5.extra",
        "is 5 frames, the frame of plane 3 twice: more than w = 4 frames (§7).",
        lambda data, planes: frames(planes, (0, 1, 2, 3, 3)))
    inv("codec5_trailing_byte", "malformed", "codec5.extra",
        "is its 4 frames and one byte 0x00 after them (stored_size and CRCs include it): nothing may "
        "follow the last frame (§7).",
        lambda data, planes: frames(planes) + b"\x00")
    inv("codec5_skippable_frame_between", "malformed", "codec5.skippable",
        "has a skippable frame (magic 0x184D2A50, 4 bytes of content) between the frames of planes 1 and "
        "2: codec 5 allows no skippable frames (§7).",
        lambda data, planes: frames(planes, (0, 1)) + struct.pack("<II", 0x184D2A50, 4) + b"skip"
        + frames(planes, (2, 3)))
    inv("codec5_frame_content_size_n_plus_1", "malformed", "zstd.content_size",
        "has as its last frame a frame of plane 3 and one byte more: its Frame_Content_Size is n + 1 = "
        "33, not n (§7: each frame holds n bytes).",
        lambda data, planes: frames(planes, range(3)) + zframe(planes[3] + b"\x00"))
    inv("codec5_planes_split_one_byte_off", "malformed", "zstd.content_size",
        "has a first frame of plane 0 and the first byte of plane 1 (33 bytes) and a second of the rest "
        "of plane 1 (31 bytes): the frames' contents add up to w·n, but each frame must hold n bytes (§7).",
        lambda data, planes: zframe(planes[0] + planes[1][:1]) + zframe(planes[1][1:])
        + frames(planes, (2, 3)))
    inv("codec5_frame_without_content_size", "malformed", "zstd.content_size",
        "has as its frame of plane 1 a frame without Frame_Content_Size (§7: present and equal to n, as "
        "for codec 1).",
        lambda data, planes: frames(planes, (0,)) + zframe(planes[1], content_size=False)
        + frames(planes, (2, 3)))

    def with_dict_id(fr):
        fr = bytearray(fr)
        fhd = fr[4]
        assert fhd & 3 == 0
        at = 5 + (0 if (fhd >> 5) & 1 else 1)           # after the Window_Descriptor, if any
        fr[4] = fhd | 1                                  # Dictionary_ID_Flag 1: one byte
        fr[at:at] = b"\x2a"
        assert zstandard.get_frame_parameters(bytes(fr)).dict_id == 42
        return bytes(fr)

    inv("codec5_frame_dictionary_id", "malformed", "zstd.dict",
        "has as its frame of plane 2 a frame whose header names Dictionary_ID 42 (one byte inserted into "
        "its header): no frame may need a dictionary (§7).",
        lambda data, planes: frames(planes, (0, 1)) + with_dict_id(zframe(planes[2])) + zframe(planes[3]))

    def bad_checksum(fr):
        fr = bytearray(fr)
        assert zstandard.get_frame_parameters(bytes(fr)).has_checksum
        fr[-1] ^= 0xFF
        return bytes(fr)

    inv("codec5_content_checksum_bad", "checksum", "zstd.checksum",
        "has a wrong content checksum in its frame of plane 2 (the frame's last byte changed, the block's "
        "CRCs recomputed): class checksum, as for codec 1 (§7, §13). Each frame's checksum is XXH64 of its "
        "own plane.",
        lambda data, planes: frames(planes, (0, 1)) + bad_checksum(zframe(planes[2])) + zframe(planes[3]))

    def cut(data, planes):
        last = zframe(planes[3])
        return frames(planes, range(3)) + last[:-5]
    inv("codec5_last_frame_cut_short", "malformed", "codec5.cut",
        "ends 5 bytes before the end of its last frame (the frame of plane 3 without its checksum and the "
        "last byte of its block): a frame that does not end within the stored bytes is malformed (§7).",
        cut)

    g = write_bricked(src_i, FLOAT32, 2)
    blocks = bricked_blocks(g, CODEC_FRAMES)
    mb = meta_block(DEFAULT_META)
    mb.codec = CODEC_FRAMES                               # w = 1: one frame of the one plane
    blocks.insert(0, mb)
    d, _ = assemble(g, blocks, structure_kind=KIND_BRICKED, ireserved=2, **framed)
    assert zstandard.ZstdDecompressor().decompress(mb.stored_bytes()) == mb.data
    add_invalid("codec5_metadata", d, "malformed", "codec5.where",
                "Bricked grid 6x5x4 float32, every brick codec 5, whose metadata block is codec 5 too: its "
                "payload is the one frame of its one byte plane (w = 1), which would decode, but codec 5 on "
                "the metadata stream is malformed, checked with the block table (§7).")


README_HEAD = """# .ivol 1.3 (draft) conformance vectors

Generated by `make_vectors.py` from the specification `format-spec/ivol.md`
alone. Regenerate with

    /usr/bin/python3 format-spec/vectors/make_vectors.py

(the Debian interpreter, which sees python3-numpy and python3-zstandard).
The script deletes and rewrites `valid/`, `invalid/`, `manifest.json` and
this README; running it twice gives identical bytes (fixed seeds, fixed
metadata, no time stamps; zstd frames depend on the zstd library version,
the one used here is reported in `manifest.json` as `zstd_version`).
Before writing the manifest the script runs a small self-test reader of its
own over every file; the expected outputs are not produced by that reader
but from the source arrays.

## Manifest

`manifest.json`: `{"vectors": [ ... ]}`, one object per file, paths relative
to the folder of the manifest:

| key | meaning |
|---|---|
| `file` | the `.ivol` file |
| `expect` | `"ok"`, or the error class of §13 a reader must report: `not-ivol`, `unsupported-version`, `unsupported-feature`, `truncated`, `checksum`, `malformed` |
| `dense` | (valid files) the expected dense export (§12.2): raw little-endian element bits, `u16` per voxel for binary16 and uint16, `u32` for float32, in order `[z][y][x]`, x fastest |
| `lod` | (valid files) `{"k": file}`: expected level of detail k (§12.3) for every k = 1 .. D, same layout as `dense`, array shape `ceil(size/2^k)` per axis |
| `value_encoding`, `size` | (valid files) for convenience: the encoding name and `[size_x, size_y, size_z]` |
| `structure` | (valid files) for convenience: `octree` (structure_kind 1), `regular` (2), `rectilinear` (3), `nested` (4, since 1.1) or `bricked` (5, since 1.3), the names of §11 `structure.kind` (`bricked` is this manifest's name; §11 lists none for kind 5) |
| `cell_log2` | (valid nested grids) for convenience: index byte 11 |
| `brick_log2` | (valid bricked grids) for convenience: index byte 11, b (bricks of 2^b) |
| `stored_levels` | (valid bricked grids with stream 7) for convenience: the levels of detail k the file stores (§8A.5); `lod` still lists every k = 1 .. D, computed from the dense source |
| `expect_without_verify` | (some invalid files) the result for a reader that does not verify, i.e. checks neither inner averages (§10) nor stored levels of detail against full resolution (§8A.5, §13): `"ok"`; `dense` then gives the dense export it must produce. `expect` is the verifying reader's result: these files need a full check (every block read, every average and stored level recomputed) to be refused. Such a reader's levels of detail are not given (one that reads a stored level trusts it, §8A.5) |
| `description` | what the file tests |

Level of detail 0 is the dense export. All comparisons are bit-exact: no
tolerance at all, NaN payloads and the sign of zero included. For an invalid
file the reader must refuse the file with exactly the listed class (which is
the class of the first failing check in the order of §13: each invalid file
has one defect, with checksums around it recomputed where needed, unless its
description says it tests the check order).

The expected levels of detail are computed from the dense source by weighted
2x2x2 box filtering in octant order with the binary64 arithmetic of §10 and
rounded once per cell to the encoding, except that a cell whose non-padding
voxels all have the same bits keeps those bits (such a cell is one leaf in a
file written with lossless merging, and §12.3 then takes the leaf's value;
this matters only for -0 and NaN payloads).

For the structures of §8A (regular, rectilinear and nested grids, version
1.1) the expected levels of detail follow §12.3's own rule for them: for each
cell of 2^k voxels per side, clipped at the volume's border, the decoded
values (§9: the integer for uint16, without scale and offset) are added in
binary64 starting from +0.0, one after the other in the order z, then y, then
x (x fastest), the sum is divided by the number of voxels and the mean is
encoded once. There is no leaf exception: a cell of uniform -0 gives +0, a
uniform NaN with a payload gives the canonical NaN. The order matters for
float32 (`regular_16_float32` has cells where an exact, pairwise or
z-fastest sum gives other bits). These files carry version_minor 1. The
octree files of 1.0 are unchanged, except where the list of changes below
says otherwise.

Version 1.2 adds codec 2, zstd over byte planes (§7): the stored bytes are
one zstd frame under every rule of codec 1, whose content is the block's
decoded bytes regrouped by byte position (with n = element_count and w the
stream's width, content byte p*n + i is decoded byte i*w + p). The
`codec2_*` files cover it: values of width 2 (binary16, uint16) and 4
(float32), node words and cell words (width 8), borders (width 4), the
metadata (width 1, where codec 2 is codec 1), one-element blocks, frames
without content checksum, and files that mix codecs 0, 1 and 2 (also within
one stream and level). They carry version_minor 2 (§4), except
`codec2_minor_0`, which a reader must read all the same (readers MUST NOT
refuse a file for its minor version). The invalid `codec2_*` files break
the frame rules of §7 in a codec-2 block, each with the class §7 and §13
give. Every valid codec-2 file has the same dense export and levels of
detail as the file it is derived from (named in its description).

Stored levels of detail (1.3 draft, §8A.5): a bricked grid may store levels
of detail k (1 <= k <= D) in stream 7, each level a bricked grid of its own
(ceil(size / 2^k) elements per axis, the file's brick edge), one brick per
block (or a codec 4 run of whole bricks), ignorable flag set, `level` k, and
equal bit for bit to the level computed from full resolution. The
`bricked_lods_*` files cover it. Their stored levels, and their expected
levels of detail (`lod`, for every k, stored or not), are both computed from
the dense source by the flat sum above, never read back from the file; a
reader may read a stored level or compute it, the bytes must be the same.
The invalid `bricked_lods_*` files break one rule of §6.4 / §8A.5 each; the
three `bricked_lods_value_*` files hold a stored level that differs from the
computed one in one element (a tie rounded up, -0 kept, a NaN payload kept):
only a verifying reader refuses them (`expect_without_verify`). Outside
structure_kind 5 stream 7 is an unknown stream: `octree_ignorable_stream_7`
and `regular_ignorable_stream_7` are valid (the block is skipped, whatever it
holds), `octree_not_ignorable_stream_7` is `unsupported-feature`.

Codec 5, byte planes a zstd frame each (1.3 draft, §7): the stored bytes
(the payload, in a framed file) are exactly w zstd frames back to back and
nothing else, frame p holding byte plane p of the block (decoded byte
i*w + p for i = 0 .. n-1), each under every rule of codec 1 for n bytes
(Frame_Content_Size present and equal to n, no dictionary, its content
checksum verified when present); codec 5 is valid on every stream of width
w >= 2 and `malformed` on the metadata, and its `stored_size` is at most
w * bound(n) (+ 32 framed), checked with the block table. The `codec5_*`
files cover it. Valid: a float32 bricked grid whose bricks mix codec 5 with
codecs 0, 1 and 2 and whose stored levels of detail are codec 5 (NaN
payloads, infinities, -0, subnormals; bricks and levels of n = 1 and
n = 2), a binary16 bricked grid mixing codec 5 with codecs 2, 3 and 4 with
every stored level in codec 5, octrees with node words (w = 8) and values
(w = 2 and 4) in codec 5, framed and not, a rectilinear grid's borders
(w = 4) and a nested grid's cell words (w = 8) in codec 5, and a block
exactly at its limit w * bound(n), far above codec 2's bound(w * n). The
frames vary: with and without content checksum (also within one block), a
compressor's frame of several zstd blocks, hand-made frames of one raw
block, of raw and RLE blocks, with a 1-, 2- or 4-byte Frame_Content_Size,
with a Window_Descriptor instead of the single-segment flag. Every valid
codec 5 file of an earlier volume has that volume's dense export and levels
of detail (named in its description). The invalid `codec5_*` files break
one rule of codec 5 each (w - 1 or w + 1 frames, a byte after the last
frame, a skippable frame between two, a frame of n + 1 bytes, planes split
one byte off, a frame without Frame_Content_Size, one that needs a
dictionary, a wrong content checksum (`checksum`), the last frame cut
short, `stored_size` one byte over w * bound(n), codec 5 on the metadata,
stored bytes that are no frame); every other is `malformed`.

Codec 3's entropy coder 3 (1.3 draft, §7.2.2): the codec header's `entropy`
byte 3; the residuals are sent as §7.2.1's tokens and bits below, in §7.2.1's
12 contexts, but each context's frequencies are stored in the payload (a bit
string: `used`, then `present` and each present token's frequency but the
last as 4 bits a and a bits w, f = 2^a + w; the last takes what is left of
4096), and 32 rANS states X_{i mod 32} take the voxels in turn, renormalised
by 16-bit words (payload: tables, 32 states, W, W words, bits below). The
vectors read every multi-bit field of the tables least significant bit
first (bit t of `present` is token t). The `bricked_entropy3_*` files and
`bricked_lods_16x16x8_uint16_entropy3` cover it: uint16 and binary16 (the
binary16 order map with -0, +0, NaN payloads, infinities, subnormals), edge
bricks of extent 1 along one axis, rows of exactly 32 and 64 voxels, a
column of 1x1x64 bricks, contexts with a single present token (f = 4096: the
state does not change), a brick of residuals 0 only (W = 0), every token
0 .. 31, entropy coders 1, 2 and 3 in one file, tables an encoder may choose
besides the proportional ones (a context that codes voxels written with
used = 0, one that codes none written with a table, tokens present that do
not occur, f = 4095 and f = 1), stored
levels of detail in coder 3, and the smallest payload coder 3 has. Codec 3's
limit of §7, 24 + bound(2n), holds whatever the coder: the tables, states
and W take at least 134 bytes, so a brick of fewer than 36 voxels cannot be
coded with coder 3 at all (edge bricks of extent 1 along two or three axes
use coder 2 in `bricked_entropy3_9x9x9_uint16_edge_bricks`; the
`bricked_codec3_entropy3_*_over_bound` files are correct codings that a
reader refuses from the block table). The invalid `bricked_codec3_entropy3_*`
files break one rule of §7.2.2 each in their first brick, all `malformed`:
the tables cut short, `present` = 0, a = 12, a last frequency of 0, table
padding, fewer than 132 bytes for the states and W, an initial state below
2^16, W beyond the payload (also by 2^31, where 2W wraps in 32 bits), the
word stream ending early or a word left over, a state not ending at 2^16,
the bits below one byte short or long, and their padding.

### Changes to the 1.0 vectors for 1.1

* `invalid/structure_kind_2.ivol` is now `invalid/structure_kind_9.ivol`:
  1.1 made structure_kind 2 the regular grid, so the unknown kind is 9 (same
  class, `unsupported-feature`).
* `valid/limits_4096.ivol` now has version_minor 2 instead of 1: its
  extension bytes belong to a later minor version, and 1.1 (minor 1) defines
  none. A reader must accept it either way.
* `invalid/index_reserved_nonzero.ivol` (index byte 11 = 1 in an octree file)
  is unchanged; byte 11 is now cell_log2 for structure_kind 4 and stays
  reserved for kinds 1-3. Descriptions of a few other vectors now say
  "1.0 and 1.1" where they said "1.0".
* The manifest's valid entries have a new key `structure`.
* Streams 4 and 5 are known only in files of structure_kind 3 and 4; in other
  files they are unknown streams as in 1.0 (§6.4), so the old vectors with
  stream 200 keep their meaning, and `valid/ignorable_stream_4_octree.ivol`
  shows the same for stream 4.

### Changes to the 1.2 vectors for 1.3 (draft)

* Required feature bit 0 is now `framed_blocks` (§4.1, §7.1).
  `invalid/required_feature_bit0.ivol` is gone: the same file (bit 0 set in
  a 40-byte header) is now `invalid/framed_header_size_40.ivol`, refused as
  `malformed` (a framed file needs header_size >= 80 for its volume
  descriptor); an unknown required feature is tested by
  `invalid/required_feature_bit1.ivol` (same construction, bit 1,
  `unsupported-feature`). `invalid/order_reserved_before_required.ivol` sets
  bit 1 instead of bit 0, so that it still combines a reserved field with an
  unknown feature.
* New: 6 valid `framed_*` files (an octree of each encoding and codec, one
  with an early metadata block of stream 6, and one file of each grid kind;
  all with the metadata first) and 9 invalid ones, each breaking one framing
  rule (block header fields, header_crc, signature, payload_crc,
  payload_size, the descriptor against the index, its reserved bytes).
* The manifest's `format` is `ivol 1.3 (draft)`.
* New (codec 3's entropy coder 2, §7.2.1): 6 valid `bricked_entropy2_*`
  files and `bricked_lods_13x10x9_uint16_entropy2` (edge bricks down to
  1x1x1, binary16 specials, every token 0 .. 31, one 32x16x16 brick whose
  context tables are made again past m = 128, 256, 384, entropy coders 1
  and 2 mixed per brick, stored levels of detail), and 12 invalid
  `bricked_codec3_entropy2_*` / `bricked_codec3_entropy_4` (named
  `bricked_codec3_entropy_3` until §7.2.2, see below) files, each
  breaking one rule of §7.2.1 (R, the initial and final states, the rANS
  stream's length, the bits below and their padding, the entropy byte, the
  limit of §7 on an over-long but correct coding). The older vectors are
  unchanged byte for byte.
* New (bricked grids of float32 values, §8A.4, §8A.5): 3 valid files,
  `bricked_9x7x5_float32_specials_codec2` (codec 2 over 4 byte planes, odd
  sizes, -0, infinities, NaN payloads, subnormals),
  `bricked_11x9x6_float32_codecs_0_and_1` (codecs 0 and 1 alternating per
  brick) and `bricked_lods_16x12x10_float32_nan_inf` (stored levels 2 .. 4
  whose cells hold NaN, +inf, -inf, inf + -inf = NaN, ties rounded to even
  at the top of the range and among subnormals), and the invalid
  `bricked_lods_float32_codec4` (codec 4 on a stream-7 block of a float32
  grid, `malformed`; with `bricked_float32_codec3`, `bricked_float32_codec4`
  and `bricked_lods_float32_codec3` every place of §7's "value_encoding 1 or
  2" rule is covered). The older vectors are unchanged byte for byte.
* Codec 5 (§7: byte planes, a zstd frame each): `invalid/codec_5.ivol` is
  now `invalid/codec_6.ivol` (same construction, a values block whose
  stored bytes are the raw values; same class, `unsupported-feature`: 1.3
  defines codecs 0 to 5), and the same block labelled codec 5 is
  `invalid/codec5_raw_values.ivol` (its bytes are no zstd frame:
  `malformed`). New: 7 valid and 13 invalid `codec5_*` files (above). The
  other vectors are unchanged byte for byte.
* Codec 3's entropy coder 3 (§7.2.2): `invalid/bricked_codec3_entropy_3.ivol`
  is now `invalid/bricked_codec3_entropy_4.ivol` (the same file with
  entropy byte 4 instead of 3, CRCs recomputed; same class,
  `unsupported-feature`: §7.2 now defines entropy 1, 2 and 3). New (above):
  12 valid files, `bricked_entropy3_*` and
  `bricked_lods_16x16x8_uint16_entropy3`, and 18 invalid
  `bricked_codec3_entropy3_*` files (15 that break one rule of §7.2.2, 3
  correct codings over codec 3's limit of §7). The other vectors are
  unchanged byte for byte.

### Changes to the 1.1 vectors for 1.2

* `invalid/codec_2.ivol` is gone: 1.2 made codec 2 zstd over byte planes.
  The unknown codec is now tested by `invalid/codec_3.ivol` and
  `invalid/codec_255.ivol` (same construction: a values block whose stored
  bytes are the raw values; same class, `unsupported-feature`).
  `invalid/codec2_raw_planes.ivol` shows what such a block is under 1.2
  when labelled codec 2 (its stored bytes are not a zstd frame:
  `malformed`).
* `valid/limits_4096.ivol` now has version_minor 3 instead of 2: its
  extension bytes belong to a later minor version, and 1.2 (minor 2) defines
  none. A reader must accept it either way.
* New: 8 valid and 11 invalid `codec2_*` files (above), and
  `valid/ignorable_stream_200_codec_255.ivol` (an unknown codec in the entry
  of an ignorable unknown-stream block has no meaning, §6.4).
* The manifest's `format` is `ivol 1.2`. Descriptions that said "unknown to
  1.0 and 1.1" now say "1.0 - 1.2".

## Vectors
"""


def write_readme(zver):
    lines = [README_HEAD]
    lines.append("### Valid files (`expect: ok`)\n")
    lines.append("| file | tests |")
    lines.append("|---|---|")
    for e in MANIFEST:
        if e["expect"] == "ok":
            lines.append("| `%s` | %s |" % (e["file"], e["description"].replace("|", "\\|")))
    lines.append("\n### Invalid files\n")
    lines.append("| file | expect | tests |")
    lines.append("|---|---|---|")
    for e in MANIFEST:
        if e["expect"] != "ok":
            ex = e["expect"] + (" (ok without verify)" if "expect_without_verify" in e else "")
            lines.append("| `%s` | `%s` | %s |" % (e["file"], ex, e["description"].replace("|", "\\|")))
    lines.append("""
## Notes

* `valid/sample.ivol` is the file of the annotated example (§16).
* `valid/metadata_16mib.ivol` and `invalid/block_decoded_64mib_plus_1.ivol`
  are small files whose zstd frames decode to 16 MiB and 64 MiB + 1 bytes. A
  reader must refuse the latter from the index alone (§7), without
  allocating. A reader that imposes lower limits of its own (§13) may report
  its limit for `metadata_16mib` instead of reading it; that is not an error
  of the file.
* `invalid/codec2_block_decoded_64mib_plus_2.ivol` is a 2.5 KB file whose
  one codec-2 values block decodes to 64 MiB + 2 bytes (element_count
  2^25 + 1 of width 2); a reader must refuse it from the index, by
  element_count x width, before it allocates or decodes.
* `valid/codec5_stored_size_at_bound_5x5x5_float32.ivol` has a codec 5
  block of one float32 value whose 4 frames are padded with empty raw zstd
  blocks (legal in RFC 8878) to exactly w x bound(1) = 256 bytes, the limit
  of §7 for codec 5; `invalid/codec5_stored_size_over_bound.ivol` is one
  byte longer. A reader that uses codec 2's limit bound(w x n) for codec 5
  refuses valid files (also the octrees and the nested grid of `codec5_*`,
  whose blocks of few elements have frames that together exceed it).
* `invalid/borders_count_huge.ivol` declares a borders block of 2^24
  elements (64 MiB decoded, within the block limit of §7); a reader must
  refuse it by the limit of §8A.2 (at most size_x + size_y + size_z + 3
  borders) from the block table, before it allocates or decodes.
* No valid file has a codec 3 block of entropy coder 3 with fewer than 36
  voxels: §7.2.2's bricks "of fewer than 32 voxels", whose unused states
  stay 2^16, are always over codec 3's limit of §7
  (`invalid/bricked_codec3_entropy3_1x1x1_over_bound.ivol`,
  `..._8x1x1_over_bound`, `..._7x5x1_over_bound`; see `SPEC-NOTES.md`).
* Invalid files marked "ok without verify" break the inner-average rule of
  §10, or the rule of §8A.5 that a stored level of detail equals the level
  computed from full resolution, which only a verifying reader checks.
* Questions about the specification that came up while writing these vectors
  are listed in `SPEC-NOTES.md`.
""")
    with open(os.path.join(HERE, "README.md"), "w", encoding="utf-8") as fh:
        fh.write("\n".join(lines))


def main():
    _check_crc()
    _check_encoders()
    _check_byte_planes()
    _check_e2_tokens()
    for sub in ("valid", "invalid"):
        p = os.path.join(HERE, sub)
        if os.path.isdir(p):
            shutil.rmtree(p)
        os.makedirs(p)
    gen()
    zver = ".".join(str(v) for v in zstandard.ZSTD_VERSION)
    man = {"format": "ivol 1.3 (draft)", "generator": "make_vectors.py", "zstd_version": zver,
           "vectors": MANIFEST}
    with open(os.path.join(HERE, "manifest.json"), "w", encoding="utf-8") as fh:
        json.dump(man, fh, indent=1, ensure_ascii=False)
        fh.write("\n")
    write_readme(zver)
    nv = sum(1 for e in MANIFEST if e["expect"] == "ok")
    print("%d valid and %d invalid vectors, %d bytes of files" % (nv, len(MANIFEST) - nv, RAW_TOTAL[0]))


if __name__ == "__main__":
    main()
