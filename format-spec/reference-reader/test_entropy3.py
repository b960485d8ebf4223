#!/usr/bin/python3
"""Tests of ivolref.py's codec 3 entropy coder 3 (§7.2.2) against an encoder
written here from the encoder paragraph of §7.2.2 (not imported by ivolref.py).

    python3 test_entropy3.py              round trips, corruptions, fuzzing, whole files
    python3 test_entropy3.py --files DIR  also every DIR/*.ivol against its .raw

Whole files are built with format-spec/vectors/make_vectors.py's file writer
(header, index, framed blocks), the codec 3 payloads with the encoder below
(coder 3; coder 1, a zstd frame, where coder 3 would exceed codec 3's limit)."""

import glob
import os
import struct
import subprocess
import sys
import tempfile
import traceback

import numpy as np
import zstandard

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import ivolref  # noqa: E402
# Coder 2's test has the tokens of §7.2.1 and §7.2's predictor on the
# encoder's side: coder 3 shares them.
from test_entropy2 import B, b16_order, residuals_of, token_of  # noqa: E402

LOW = 1 << 16                       # §7.2.2: the states start and end at 2^16
STATES = 32
LORENZO = (1, 1, 1, -1, -1, -1, 1)
REASONS = ("present_zero", "table_a", "last_freq", "table_padding", "short", "initial_state",
           "words_size", "stream_end", "states_end", "words_left", "bits_size", "padding")


# ------------------------------------------------------------ tokens and contexts (§7.2.1)

def tokens_and_contexts(zz, ext):
    """Per voxel, raster order: (token, e, w, context k)."""
    ex, ey, ez = ext
    assert len(zz) == ex * ey * ez
    bl = {}
    out = []
    i = 0
    for z in range(ez):
        for y in range(ey):
            for x in range(ex):
                def at(a, b_, c):
                    return bl.get((a, b_, c), 0)      # 0 outside the brick
                U, K = at(x, y - 1, z), at(x, y, z - 1)
                L, P = at(x - 1, y - 1, z), at(x + 1, y - 1, z)
                k = min(11, (2 * U + K + L + P + 2) // 5)
                t, e, w = token_of(int(zz[i]))
                out.append((t, e, w, k))
                bl[(x, y, z)] = B(t)
                i += 1
    return out


# ------------------------------------------------------------ frequencies (the encoder's choice)

def proportional(counts, rng=None):
    """f_t proportional to the count, each occurring token >= 1, the remainder
    (which may be negative) to the most frequent (lowest t among equals)."""
    T = sum(counts)
    f = [max(1, c * 4096 // T) if c else 0 for c in counts]
    j = f.index(max(f))
    f[j] += 4096 - sum(f)
    return f


def flat(counts, rng=None):
    """used = 0: every f_t = 128, whether or not the context codes voxels."""
    return None


def all_present(counts, rng=None):
    """Every token present, also those that do not occur."""
    return proportional([c * 64 + 1 for c in counts])


def random_table(counts, rng):
    """Random frequencies: every occurring token, and some others, >= 1."""
    listed = [t for t in range(32) if counts[t] or rng.random() < 0.3]
    if not listed:
        listed = [int(rng.integers(0, 32))]
    cuts = sorted(rng.choice(np.arange(1, 4096), len(listed) - 1, replace=False).tolist())
    parts = [b - a for a, b in zip([0] + cuts, cuts + [4096])]
    f = [0] * 32
    for t, p in zip(listed, parts):
        f[t] = p
    return f


def extreme(counts, rng=None):
    """The largest possible first frequency (4095, a = 11, w = 2047) and 1s."""
    listed = [t for t in range(32) if counts[t]]
    if len(listed) < 2:
        return proportional(counts)
    f = [0] * 32
    for t in listed[1:]:
        f[t] = 1
    f[listed[0]] = 4096 - (len(listed) - 1)
    return f


# ------------------------------------------------------------ encoder (§7.2.2)

class BitWriter:
    """Bits from bit 0 of the first byte up; every field least significant bit first."""

    def __init__(self):
        self.acc, self.n = 0, 0

    def put(self, value, nbits):
        assert 0 <= value < (1 << nbits) or nbits == 0 and value == 0
        self.acc |= value << self.n
        self.n += nbits

    def bytes(self):
        return self.acc.to_bytes((self.n + 7) // 8, "little")


def put_table(bw, f):
    """One context's table: f None for used = 0, else its 32 frequencies."""
    if f is None:
        bw.put(0, 1)
        return
    assert sum(f) == 4096 and min(f) >= 0
    listed = [t for t in range(32) if f[t]]
    bw.put(1, 1)
    bw.put(sum(1 << t for t in listed), 32)
    for t in listed[:-1]:
        a = f[t].bit_length() - 1        # f_t = 2^a + w, w < 2^a
        assert a <= 11
        bw.put(a, 4)
        bw.put(f[t] - (1 << a), a)


def encode_parts(zz, ext, choose=proportional, rng=None, tables=None):
    """The parts of §7.2.2: tables (bytes, their bit count), the 32 final
    states, the words, the bits below (bytes, E), and the tables chosen
    (None for used = 0): chosen by choose(counts, rng) for each context that
    codes a voxel, or given as `tables`."""
    sym = tokens_and_contexts(zz, ext)
    n = len(sym)
    counts = [[0] * 32 for _ in range(12)]
    for t, _, _, k in sym:
        counts[k][t] += 1
    if tables is None:
        tables = [choose(counts[k], rng) if any(counts[k]) else None for k in range(12)]
    bw = BitWriter()
    for f in tables:
        put_table(bw, f)
    freq = [f if f is not None else [128] * 32 for f in tables]
    cum = [[sum(f[:t]) for t in range(32)] for f in freq]
    for k in range(12):
        for t in range(32):
            assert counts[k][t] == 0 or freq[k][t] >= 1, "token %d of context %d has f = 0" % (t, k)
    X = [LOW] * STATES
    emitted = []
    for i in range(n - 1, -1, -1):   # last voxel first (rANS is last in, first out)
        t, _, _, k = sym[i]
        f, s = freq[k][t], cum[k][t]
        x = X[i % STATES]
        if x >= (1 << 20) * f:
            emitted.append(x % 65536)
            x //= 65536
        x = 4096 * (x // f) + (x % f) + s
        assert LOW <= x < 1 << 32
        X[i % STATES] = x
    words = list(reversed(emitted))
    acc, E = 0, 0
    for t, e, w, _ in sym:
        acc |= w << E
        E += e
    return dict(tables=bw.bytes(), table_bits=bw.n, states=X, words=words,
                bits=acc.to_bytes((E + 7) // 8, "little"), E=E, chosen=tables)


def body_of(p, tables=None, states=None, W=None, words=None, bits=None):
    """The bytes after the codec header from parts, any of them replaced."""
    tables = p["tables"] if tables is None else tables
    states = p["states"] if states is None else states
    words = p["words"] if words is None else words
    W = len(words) if W is None else W
    bits = p["bits"] if bits is None else bits
    return (tables + struct.pack("<32I", *states) + struct.pack("<I", W)
            + struct.pack("<%dH" % len(words), *words) + bits)


def encode_residuals(zz, ext, choose=proportional, rng=None):
    return body_of(encode_parts(zz, ext, choose, rng))


# ------------------------------------------------------------ payloads (§7.2)

def header(value_map=0, shift=0, taps=(0,) * 7, level=0, entropy=3, predictor=1):
    return struct.pack("<BBBB7hi", predictor, value_map, shift, entropy, *taps, level) + b"\0\0"


def payload_of(vals, ext, value_map=1, shift=0, taps=LORENZO, level=0, choose=proportional):
    zz = residuals_of(vals, ext, value_map, shift, taps, level)
    return header(value_map, shift, taps, level) + encode_residuals(zz, ext, choose)


def coder1_payload(vals, ext, value_map=1, shift=0, taps=LORENZO, level=0):
    """§7.2 entropy coder 1: one zstd frame of the residuals' two byte planes."""
    zz = residuals_of(vals, ext, value_map, shift, taps, level)
    planes = bytes(z & 255 for z in zz) + bytes(z >> 8 for z in zz)
    frame = zstandard.ZstdCompressor(level=3, write_content_size=True).compress(planes)
    return header(value_map, shift, taps, level, entropy=1) + frame


# ------------------------------------------------------------ tests

FAILS = []
COUNT = {"checks": 0}


def check(cond, what):
    COUNT["checks"] += 1
    if not cond:
        FAILS.append(what)
        print("FAIL:", what)


def decode(body, ext, hdr=None):
    return ivolref.decode_rans3_residuals((hdr or header()) + body, ext, "test")


def expect_malformed(body, ext, reason, what, hdr=None):
    """The body must be refused as `malformed` for the check `reason`."""
    try:
        decode(body, ext, hdr)
    except ivolref.IvolError as err:
        want = "codec3.entropy3." + reason
        ok = err.cls == "malformed" and err.reason == want and ("[%s]" % want) in err.message
        check(ok, "%s: got %s (%s): %s" % (what, err.cls, err.reason, err.message))
        return err.message
    except Exception as err:   # noqa: BLE001 -- anything else is a bug of the reader
        check(False, "%s: %s: %s" % (what, type(err).__name__, err))
        return None
    check(False, "%s: accepted" % what)
    return None


EVERY_TOKEN = [0, 1, 2, 3, 4, 6, 8, 12, 16, 24, 32, 48, 64, 96, 128, 192, 256, 384, 512, 768, 1024,
               1536, 2048, 3072, 4096, 6144, 8192, 12288, 16384, 24576, 32768, 49152]
# the largest residual of each token: all its bits below set
LARGEST = [t if t < 2 else ((2 + (t & 1)) << (B(t) - 2)) + (1 << (B(t) - 2)) - 1 for t in range(32)]


def residual_sets(n, rng):
    yield "all zero", [0] * n
    yield "all 65535", [65535] * n
    yield "all one", [1] * n
    b = rng.integers(0, 17, n)
    yield "random bit lengths", [0 if bb == 0 else int(rng.integers(1 << (bb - 1), 1 << bb)) for bb in b]
    yield "uniform 16-bit", [int(v) for v in rng.integers(0, 65536, n)]
    yield "small", [int(v) for v in rng.geometric(0.3, n) - 1]
    yield "every token", [EVERY_TOKEN[i % 32] for i in range(n)]
    yield "every token, largest of each", [LARGEST[(i * 7) % 32] for i in range(n)]


SHAPES = [(1, 1, 1), (2, 3, 1), (4, 4, 1), (31, 1, 1), (5, 3, 2), (32, 1, 1), (33, 2, 1),
          (64, 1, 1), (32, 2, 1), (64, 3, 2), (5, 4, 3), (31, 7, 9), (16, 16, 16), (1, 1, 40),
          (3, 1, 5), (1, 33, 1), (2, 1, 17)]
CHOOSERS = [("proportional", proportional), ("flat", flat), ("all present", all_present),
            ("random", random_table), ("extreme", extreme)]


def test_tokens():
    """The token map of §7.2.1 reproduced here is a bijection on 0 .. 65535."""
    seen, wrong = set(), []
    for z in range(65536):
        t, e, w = token_of(z)
        back = t if t < 2 else ((2 + (t & 1)) << e) + w
        if back != z or not 0 <= t < 32 or e != max(0, B(t) - 2):
            wrong.append(z)
        seen.add(t)
    check(not wrong, "token map: %d residuals do not come back" % len(wrong))
    check(seen == set(range(32)), "all 32 tokens occur")
    check([token_of(z)[0] for z in LARGEST] == list(range(32)), "LARGEST has each token once")
    check(sorted(token_of(z)[0] for z in EVERY_TOKEN) == list(range(32)), "EVERY_TOKEN has each token once")


def test_round_trips(rng):
    import time
    worst, n_cases = 0.0, 0
    for ext in SHAPES:
        n = ext[0] * ext[1] * ext[2]
        for name, zz in residual_sets(n, rng):
            for cname, choose in CHOOSERS:
                if n > 1000 and cname not in ("proportional", "random"):
                    continue
                p = encode_parts(zz, ext, choose, rng)
                body = body_of(p)
                t0 = time.time()
                try:
                    got = decode(body, ext)
                except ivolref.IvolError as err:
                    check(False, "round trip %s %s %s: %s" % (ext, name, cname, err))
                    continue
                worst = max(worst, time.time() - t0)
                check(got == list(zz), "round trip %s %s %s" % (ext, name, cname))
                n_cases += 1
                # the states a brick of fewer than 32 voxels does not use stay at 2^16
                check(all(x == LOW for x in p["states"][n:]), "unused states %s %s" % (ext, name))
    print("round trips: %d (%d shapes x 8 residual sets x up to 5 frequency choices); "
          "slowest decode %.3f s" % (n_cases, len(SHAPES), worst))


def test_single_token(rng):
    """A context with one token present: that token gets f = 4096, no a or w
    bits are stored, and its voxels neither move a state nor emit a word."""
    for ext in ((1, 1, 1), (5, 3, 2), (32, 1, 1), (33, 2, 1), (7, 5, 3)):
        n = ext[0] * ext[1] * ext[2]
        for name, zz in (("zero", [0] * n), ("one", [1] * n), ("65535", [65535] * n)):
            p = encode_parts(zz, ext)
            body = body_of(p)
            used = [f for f in p["chosen"] if f is not None]
            check(all(sorted(f)[-1] == 4096 for f in used), "single token: f = 4096 %s %s" % (ext, name))
            freqs, _, end = ivolref.read_rans3_tables(header() + body, 24, "test")
            check(end == 24 + len(p["tables"]), "tables end %s %s" % (ext, name))
            for k, f in enumerate(p["chosen"]):
                check(freqs[k] == (f if f is not None else [128] * 32), "tables read back %s %s" % (ext, name))
            check(p["table_bits"] == 12 + 32 * len(used), "one used bit a context, 32 present bits "
                  "and nothing more for a single token %s %s" % (ext, name))
            if name == "zero":
                check(p["words"] == [] and p["states"] == [LOW] * 32,
                      "all-zero residuals: no words, every state 2^16 %s" % (ext,))
            check(decode(body, ext) == zz, "single token round trip %s %s" % (ext, name))
    # context 0 alone, token 0 only: the whole body is 6 bytes of tables + 132
    p = encode_parts([0] * 8, (8, 1, 1))
    check(len(body_of(p)) == (12 + 32 + 7) // 8 + 132, "8 zeros in a row: %d bytes" % len(body_of(p)))
    print("single-token contexts: f = 4096, no words")


def test_tables(rng):
    """Random valid tables written here read back the same through the reader."""
    for trial in range(300):
        tables = []
        for k in range(12):
            r = rng.random()
            if r < 0.2:
                tables.append(None)
            elif r < 0.3:
                f = [0] * 32
                f[int(rng.integers(0, 32))] = 4096
                tables.append(f)
            else:
                tables.append(random_table([int(c) for c in rng.integers(0, 2, 32)], rng))
        bw = BitWriter()
        for f in tables:
            put_table(bw, f)
        data = header() + bw.bytes() + b"\xAA" * 5
        freqs, cums, end = ivolref.read_rans3_tables(data, 24, "test")
        check(end == 24 + (bw.n + 7) // 8, "tables end, trial %d" % trial)
        for k in range(12):
            want = tables[k] if tables[k] is not None else [128] * 32
            check(freqs[k] == want and cums[k] == [sum(want[:t]) for t in range(32)],
                  "tables trial %d context %d" % (trial, k))
    print("tables: 300 random sets of 12 read back")


def test_values(rng):
    """Whole codec 3 payloads through decode_predicted: every map, shifts, taps, levels."""
    for ext in ((1, 1, 1), (5, 3, 2), (33, 2, 1), (5, 4, 3), (31, 7, 9), (8, 8, 8)):
        n = ext[0] * ext[1] * ext[2]
        vals_sets = [[int(v) for v in rng.integers(0, 65536, n)],
                     [int(v) for v in (1000 + np.arange(n) * 7 + rng.integers(0, 9, n)) % 65536],
                     [0x8000] * n, [0xFFFF] * n, [0x7FFF, 0x8000, 0xFC00, 0x7E01] * (n // 4) + [0] * (n % 4)]
        for vals in vals_sets:
            for vm, shift, taps, level in ((1, 0, LORENZO, 0), (0, 3, (5, 4, 3, -2, -1, -1, 0), -7),
                                           (1, 15, (32767, -32768, 100, 0, 0, 0, -1), 123456)):
                pl = payload_of(vals, ext, vm, shift, taps, level)
                got = np.frombuffer(ivolref.decode_predicted(pl, ext, "test"), "<u2").tolist()
                check(got == vals, "values %s map %d shift %d" % (ext, vm, shift))
    print("codec 3 payloads: decode_predicted gives the values back")


def test_header_first(rng):
    """Through decode_predicted: the codec header's checks come first."""
    ext = (5, 3, 2)
    body = encode_residuals([int(v) for v in rng.integers(0, 300, 30)], ext)
    for hdr, cls, what in ((header(entropy=4), "unsupported-feature", "entropy 4"),
                           (header(entropy=255), "unsupported-feature", "entropy 255"),
                           (header(predictor=2), "unsupported-feature", "predictor 2"),
                           (header(value_map=2), "malformed", "value_map 2"),
                           (header(shift=16), "malformed", "shift 16"),
                           (header()[:22] + b"\0\1", "malformed", "reserved byte")):
        for b in (body, b"", b"\xFF" * 3):   # the header is refused whatever follows
            try:
                ivolref.decode_predicted(hdr + b, ext, "test")
                check(False, "%s accepted" % what)
            except ivolref.IvolError as err:
                check(err.cls == cls and err.reason is None, "%s: got %s: %s" % (what, err.cls, err.message))
    got = ivolref.decode_predicted(header() + body, ext, "test")
    check(len(got) == 60, "entropy 3 accepted by decode_predicted")
    print("codec header: checked before the tables (entropy 4 unsupported-feature)")


def test_corruptions(rng):
    """One crafted fault per check of §7.2.2, each `malformed` with its reason."""
    ext = (9, 8, 5)                  # 360 voxels: about 11 a state, so words are emitted
    n = 360
    for attempt in range(100):       # want padding bits in both bit strings
        zz = [0 if bb == 0 else int(rng.integers(1 << (bb - 1), 1 << bb)) for bb in rng.integers(0, 17, n)]
        p = encode_parts(zz, ext)
        if p["table_bits"] % 8 and p["E"] % 8 and len(p["words"]) >= 2:
            break
    check(p["table_bits"] % 8 and p["E"] % 8 and len(p["words"]) >= 2, "corruption base has padding and words")
    check(decode(body_of(p), ext) == zz, "corruption base decodes")

    def tables_with(*fields):
        """A tables part from raw (value, nbits) fields; the other contexts used = 0."""
        bw = BitWriter()
        for v, nb in fields:
            bw.put(v, nb)
        return bw

    def rest_tables(bw, contexts_done):
        for _ in range(12 - contexts_done):
            bw.put(0, 1)
        return bw.bytes()

    # present = 0
    bw = tables_with((1, 1), (0, 32))
    expect_malformed(body_of(p, tables=rest_tables(bw, 1)), ext, "present_zero", "present = 0 in context 0")
    bw = tables_with(*[(0, 1)] * 11 + [(1, 1), (0, 32)])
    expect_malformed(body_of(p, tables=bw.bytes()), ext, "present_zero", "present = 0 in context 11")
    # a > 11 (a = 12 .. 15); a = 11 with the largest w is valid
    for a in (12, 13, 15):
        bw = tables_with((1, 1), (0b11, 32), (a, 4))
        expect_malformed(body_of(p, tables=bw.bytes() + b"\0" * 8), ext, "table_a", "a = %d" % a)
    bw = tables_with((1, 1), (0b1001, 32), (11, 4), (2047, 11))   # f_0 = 4095, f_3 = 1
    freqs, _, _ = ivolref.read_rans3_tables(header() + rest_tables(bw, 1), 24, "test")
    check(freqs[0][0] == 4095 and freqs[0][3] == 1 and sum(freqs[0]) == 4096, "a = 11, w = 2047 valid")
    # the last frequency 0 or below
    bw = tables_with((1, 1), (0b111, 32), (11, 4), (2047, 11), (0, 4))   # 4095 + 1, last 0
    expect_malformed(body_of(p, tables=rest_tables(bw, 1)), ext, "last_freq", "last f = 0")
    bw = tables_with((1, 1), (0b111, 32), (11, 4), (2047, 11), (11, 4), (2047, 11))   # last -4094
    expect_malformed(body_of(p, tables=rest_tables(bw, 1)), ext, "last_freq", "last f < 0")
    bw = tables_with((1, 1), (0xFFFFFFFF, 32), *[(7, 4), (0, 7)] * 31)   # 31 x 128, last 128: valid
    freqs, _, _ = ivolref.read_rans3_tables(header() + rest_tables(bw, 1), 24, "test")
    check(freqs[0] == [128] * 32, "32 present tokens of 128")
    bw = tables_with((1, 1), (0xFFFFFFFF, 32), *[(7, 4), (1, 7)] * 31)   # 31 x 129: last 97, valid
    freqs, _, _ = ivolref.read_rans3_tables(header() + rest_tables(bw, 1), 24, "test")
    check(freqs[0][31] == 4096 - 31 * 129, "32 present tokens, last 97")
    bw = tables_with((1, 1), (0xFFFFFFFF, 32), *[(7, 4), (5, 7)] * 31)   # 31 x 133 = 4123: last -27
    expect_malformed(body_of(p, tables=rest_tables(bw, 1)), ext, "last_freq", "31 x 133")
    # a set padding bit after context 11: every padding bit
    tb = p["table_bits"]
    for bit in range(tb % 8, 8):
        t = bytearray(p["tables"])
        t[-1] |= 1 << bit
        expect_malformed(body_of(p, tables=bytes(t)), ext, "table_padding", "table padding bit %d" % bit)
    # too short: inside the tables, then for the 132 bytes after them
    full = body_of(p)
    for cut in (0, 1, len(p["tables"]) - 1):
        expect_malformed(full[:cut], ext, "short", "payload cut at %d (inside the tables)" % cut)
    bw = tables_with((1, 1), (0b11, 32), (11, 4))   # ends inside w
    expect_malformed(bw.bytes(), ext, "short", "payload ends inside w")
    for after in (0, 1, 127, 131):
        expect_malformed(full[:len(p["tables"]) + after], ext, "short", "%d bytes after the tables" % after)
    # the initial states
    for j in (0, 1, 7, 31):
        for bad in (LOW - 1, 0, 1):
            st = list(p["states"])
            st[j] = bad
            expect_malformed(body_of(p, states=st), ext, "initial_state", "X_%d = %d" % (j, bad))
    st = list(p["states"])
    st[5] = LOW
    st[6] = 0xFFFFFFFF                          # in range: accepted, other tokens or refused later
    try:
        decode(body_of(p, states=st), ext)
    except ivolref.IvolError as err:
        check(err.reason not in ("codec3.entropy3.initial_state", None), "X = 2^32 - 1: %s" % err.message)
    # W larger than the words there are
    after_w = 2 * len(p["words"]) + len(p["bits"])
    for W in (after_w // 2 + 1, 0xFFFFFFFF, 0x80000000):
        expect_malformed(body_of(p, W=W), ext, "words_size", "W = %d (%d bytes follow)" % (W, after_w))
    # the word stream running out: the last word taken away
    expect_malformed(body_of(p, words=p["words"][:-1]), ext, "stream_end", "last word missing")
    expect_malformed(body_of(p, words=[], bits=b""), ext, "stream_end", "no words")
    # a final state other than 2^16: an unused state of a brick of fewer than 32 voxels
    small = encode_parts([0, 5, 9, 100, 3, 0, 1], (7, 1, 1))
    for j in (7, 31):
        st = list(small["states"])
        st[j] = LOW + 1
        expect_malformed(body_of(small, states=st), (7, 1, 1), "states_end", "unused X_%d = 2^16 + 1" % j)
    st = list(small["states"])
    st[2] += 4096                            # same slot, same token, state one step too high
    expect_malformed(body_of(small, states=st), (7, 1, 1), "states_end", "used X_2 + 4096")
    # a word left over (one more word at the end of the stream)
    for extra in (0, 0xFFFF):
        expect_malformed(body_of(p, words=p["words"] + [extra]), ext, "words_left", "extra word %d" % extra)
    # the bits below: one byte short, one long, none
    expect_malformed(body_of(p, bits=p["bits"][:-1]), ext, "bits_size", "bits part one byte short")
    expect_malformed(body_of(p, bits=p["bits"] + b"\0"), ext, "bits_size", "bits part one byte long")
    expect_malformed(body_of(p, bits=b""), ext, "bits_size", "bits part empty")
    expect_malformed(body_of(p) + b"\0", ext, "bits_size", "a byte after the payload")
    # every padding bit of the bits below, bit E itself included
    E = p["E"]
    for bit in range(E % 8, 8):
        bt = p["bits"][:-1] + bytes([p["bits"][-1] | (1 << bit)])
        expect_malformed(body_of(p, bits=bt), ext, "padding", "padding bit %d set" % bit)
    # every used bit of the bits part may flip: that only changes residuals
    bt = bytes(b ^ 0xFF for b in p["bits"][:-1]) + bytes([p["bits"][-1] ^ ((1 << (E % 8)) - 1)])
    got = decode(body_of(p, bits=bt), ext)
    check(got != zz and len(got) == n, "flipped value bits decode to other residuals")
    # changed words: refused (final states, stream, bits) or other residuals
    refused, changed = {}, 0
    for q in range(len(p["words"])):
        for flip in (1, 0x8000):
            w = list(p["words"])
            w[q] ^= flip
            try:
                changed += decode(body_of(p, words=w), ext) != zz
            except ivolref.IvolError as err:
                check(err.cls == "malformed" and err.reason, "word flip: %s" % err.message)
                refused[err.reason] = refused.get(err.reason, 0) + 1
    print("  word flips: refused %s, %d accepted with other residuals" % (refused, changed))
    # a minimal payload: n = 1, residual 0, all tables unused
    b1 = body_of(encode_parts([0], (1, 1, 1), flat))
    check(len(b1) == 2 + 132 and decode(b1, (1, 1, 1)) == [0], "n = 1, flat tables: 134 bytes")
    print("corruptions: each check of §7.2.2 refused with its reason")


def test_limit():
    """Informative: codec 3's limit 24 + bound(2n) against the smallest coder 3
    payload (24 + 2 bytes of tables + 132, no words, no bits)."""
    smallest = 24 + 2 + 132
    first = next(n for n in range(1, 1000) if 24 + ivolref.zstd_compress_bound(2 * n) >= smallest)
    check(first > 31, "no brick of fewer than 32 voxels fits codec 3's limit with coder 3")
    zz = [0] * first
    body = encode_residuals(zz, (first, 1, 1), flat)
    check(24 + len(body) <= 24 + ivolref.zstd_compress_bound(2 * first),
          "a brick of %d voxels fits with coder 3" % first)
    print("limit: a coder 3 payload is at least %d bytes; bricks of fewer than %d voxels "
          "never fit codec 3's limit with coder 3" % (smallest, first))


def test_fuzz(rng):
    """Random or mutated bodies: residuals or the reader's own `malformed`,
    never another exception."""
    outcomes = {}
    shapes = [(1, 1, 1), (5, 3, 2), (33, 2, 1), (5, 4, 3), (8, 8, 2)]
    for trial in range(3000):
        ext = shapes[trial % len(shapes)]
        n = ext[0] * ext[1] * ext[2]
        kind = trial % 5
        if kind in (0, 1):   # a valid body, then random changes
            zz = [int(v) for v in rng.integers(0, 1 << int(rng.integers(1, 17)), n)]
            body = bytearray(encode_residuals(zz, ext, CHOOSERS[trial % 5][1], rng))
            for _ in range(int(rng.integers(1, 4))):
                q = int(rng.integers(0, len(body)))
                if kind == 0:
                    body[q] = int(rng.integers(0, 256))
                else:
                    body[q] ^= 1 << int(rng.integers(0, 8))
            body = bytes(body)
        elif kind == 2:      # a valid body cut or lengthened
            zz = [int(v) for v in rng.integers(0, 1 << int(rng.integers(1, 17)), n)]
            body = encode_residuals(zz, ext, CHOOSERS[trial % 5][1], rng)
            cut = int(rng.integers(0, len(body) + 3))
            body = body[:cut] + rng.integers(0, 256, max(0, cut - len(body)), np.uint8).tobytes()
        elif kind == 3:      # plausible tables, random states and words
            bw = BitWriter()
            for k in range(12):
                put_table(bw, random_table([int(c) for c in rng.integers(0, 2, 32)], rng)
                          if rng.random() < 0.5 else None)
            W = int(rng.integers(0, 20))
            states = [int(v) for v in rng.integers(1 << 16, 1 << 32, 32, dtype=np.uint64)]
            body = (bw.bytes() + struct.pack("<32I", *states) + struct.pack("<I", W)
                    + rng.integers(0, 256, int(rng.integers(0, 60)), np.uint8).tobytes())
        else:                # random bytes
            body = rng.integers(0, 256, int(rng.integers(0, 400)), np.uint8).tobytes()
        try:
            if trial % 7 == 0:
                got = ivolref.decode_predicted(header(1, 0, LORENZO, 0) + body, ext, "test")
                assert len(got) == 2 * n
            else:
                got = decode(body, ext)
                assert len(got) == n and all(0 <= v < 65536 for v in got)
            outcomes["ok"] = outcomes.get("ok", 0) + 1
        except ivolref.IvolError as err:
            ok = (err.cls == "malformed" and err.reason is not None
                  and err.reason.startswith("codec3.entropy3.") and err.reason.split(".")[-1] in REASONS)
            check(ok, "fuzz trial %d: %s %s: %s" % (trial, err.cls, err.reason, err.message))
            key = err.reason.split(".")[-1] if err.reason else "?"
            outcomes[key] = outcomes.get(key, 0) + 1
        except Exception:   # noqa: BLE001 -- a bug of the reader
            check(False, "fuzz trial %d: %s" % (trial, traceback.format_exc()))
    print("fuzz: 3000 bodies:", dict(sorted(outcomes.items())))
    missing = [r for r in REASONS if r not in outcomes]
    if missing:
        print("  (reasons the fuzzer did not reach: %s)" % ", ".join(missing))


def test_files(rng, tmp):
    """Whole .ivol 1.3 framed bricked files through `ivolref.py dense`."""
    sys.path.insert(0, os.path.join(HERE, "..", "vectors"))
    import make_vectors as mv
    used = {1: 0, 3: 0}

    def pred_payload(vals, ext, value_map=1, shift=0, taps=LORENZO, level=0, **_):
        n = ext[0] * ext[1] * ext[2]
        pl = payload_of(vals, ext, value_map, shift, taps, level)
        if len(pl) > 24 + ivolref.zstd_compress_bound(2 * n):   # §7.2: a writer then uses coder 1
            pl = coder1_payload(vals, ext, value_map, shift, taps, level)
        used[pl[3]] += 1
        return pl
    mv.predicted_payload = pred_payload   # entropy coder 3 (or 1) for every codec 3 block
    cases = [((37, 21, 18), mv.UINT16, 4), ((9, 7, 5), mv.BINARY16, 2), ((16, 16, 16), mv.UINT16, 4),
             ((33, 2, 5), mv.UINT16, 5), ((1, 1, 1), mv.UINT16, 3), ((40, 40, 3), mv.BINARY16, 5)]
    for (X, Y, Z), enc, b in cases:
        zz_, yy, xx = np.mgrid[0:Z, 0:Y, 0:X]
        if enc == mv.UINT16:
            src = (20000 + 300 * np.sin(xx / 5.0) * yy + 17 * zz_
                   + rng.integers(0, 64, (Z, Y, X))).astype(np.uint16)
            src[0, 0, 0] = 65535
        else:
            src = rng.integers(0, 65536, (Z, Y, X)).astype(np.uint16)
            src[:, :, : X // 2] = 0x3C00 + (xx[:, :, : X // 2] & 7)   # smooth half: coder 3 fits
        g = mv.write_bricked(src, enc, b)
        blocks = mv.bricked_blocks(g, mv.CODEC_PREDICTED, per_brick=lambda q: dict(
            value_map=1 if enc == mv.BINARY16 else q % 2, shift=q % 4,
            taps=LORENZO if q % 3 else (3, 2, 1, -1, -1, 0, 0), level=q - 3))
        blocks.insert(0, mv.meta_block(mv.DEFAULT_META))
        data, _ = mv.assemble(g, blocks, framed=True, minor=3, structure_kind=mv.KIND_BRICKED, ireserved=b)
        path = os.path.join(tmp, "e3_%dx%dx%d.ivol" % (X, Y, Z))
        with open(path, "wb") as f:
            f.write(data)
        out = path + ".out"
        rc = subprocess.run([sys.executable, os.path.join(HERE, "ivolref.py"), "dense", path, "-o", out],
                            capture_output=True, text=True)
        ok = rc.returncode == 0 and open(out, "rb").read() == src.astype("<u2").tobytes()
        check(ok, "file %s: %s %s" % (path, rc.returncode, rc.stdout.strip()))
        rc = subprocess.run([sys.executable, os.path.join(HERE, "ivolref.py"), "check", path],
                            capture_output=True, text=True)
        check(rc.returncode == 0, "check %s: %s" % (path, rc.stdout.strip()))
    check(used[3] > 0, "some codec 3 blocks of the files use coder 3")
    print("whole files: %d framed bricked files decode through `ivolref.py dense` and pass "
          "`check` (%d codec 3 blocks with coder 3, %d over the limit with it, coder 1)"
          % (len(cases), used[3], used[1]))


def block_kinds(path):
    """How many values blocks of each codec (and codec 3 entropy coder) the
    file has; every coder 3 payload is also coded again by the encoder here,
    from its decoded residuals under its own stored tables, which must give
    the same bytes after the tables (the coding is unique once the tables are)."""
    r, ix, _ = ivolref.open_ivol(path)
    kinds = {}
    with open(path, "rb") as f:
        data = f.read()
    skip = 32 if ix.header.framed else 0
    for e in ix.blocks:
        if e.stream not in (ivolref.STREAM_VALUES, ivolref.STREAM_STORED_LOD):
            continue
        key = "codec %d" % e.codec
        if e.codec == 3:
            payload = data[e.file_offset + skip:e.file_offset + e.stored_size]
            key += " entropy %d" % payload[3]
            if payload[3] == 3:
                ext = ix.brick_of[(e.level, e.first_element)]
                zz = ivolref.decode_rans3_residuals(payload, ext, "C++ block")
                freqs, _, end = ivolref.read_rans3_tables(payload, 24, "C++ block")
                mine = encode_parts(zz, ext, tables=freqs)
                again = body_of(mine)[len(mine["tables"]):]
                same = again == payload[end:]
                check(same, "C++ coder 3 block at %d: coded again, other bytes" % e.file_offset)
                key += " (same bytes again)" if same else " (OTHER BYTES again)"
        kinds[key] = kinds.get(key, 0) + 1
    r.close()
    return kinds


def test_c_files(d):
    files = sorted(glob.glob(os.path.join(d, "*.ivol")))
    for path in files:
        base = path[:-5]
        want = open(base + ".raw", "rb").read()
        out = tempfile.mktemp(suffix=".dense")
        rc = subprocess.run([sys.executable, os.path.join(HERE, "ivolref.py"), "dense", path, "-o", out],
                            capture_output=True, text=True)
        got = open(out, "rb").read() if rc.returncode == 0 else b""
        same = got == want
        if rc.returncode == 0:
            os.unlink(out)
        print("  %s: exit %d %s%s; blocks %s" % (os.path.basename(path), rc.returncode,
              "bit-exact" if same else "DIFFERENT", "" if rc.returncode == 0 else " " + rc.stdout.strip(),
              block_kinds(path)))
        check(same, "C++ file %s" % path)
    print("C++ files: %d checked" % len(files))


def main():
    rng = np.random.default_rng(7202)
    steps = [("tokens", lambda: test_tokens()), ("round trips", lambda: test_round_trips(rng)),
             ("single token", lambda: test_single_token(rng)), ("tables", lambda: test_tables(rng)),
             ("values", lambda: test_values(rng)), ("codec header", lambda: test_header_first(rng)),
             ("corruptions", lambda: test_corruptions(rng)), ("limit", test_limit),
             ("fuzz", lambda: test_fuzz(rng))]
    for name, step in steps:
        try:
            step()
        except Exception:   # noqa: BLE001 -- a test that crashes fails, the others still run
            check(False, "%s: %s" % (name, traceback.format_exc()))
    with tempfile.TemporaryDirectory() as tmp:
        try:
            test_files(rng, tmp)
        except Exception:   # noqa: BLE001
            check(False, "whole files: %s" % traceback.format_exc())
    if len(sys.argv) == 3 and sys.argv[1] == "--files":
        test_c_files(sys.argv[2])
    print("%d checks, %s" % (COUNT["checks"], "FAILED: %d" % len(FAILS) if FAILS else "all passed"))
    return 1 if FAILS else 0


if __name__ == "__main__":
    sys.exit(main())
