#!/usr/bin/python3
"""Tests of ivolref.py's codec 3 entropy coder 2 (§7.2.1) against an encoder
written here from the encoder paragraph of §7.2.1 (not imported by ivolref.py).

    python3 test_entropy2.py              round trips, corruptions, fuzzing, whole files
    python3 test_entropy2.py --files DIR  also every DIR/*.ivol against its .raw

Whole files are built with format-spec/vectors/make_vectors.py's file writer
(header, index, framed blocks), the codec 3 payloads with the encoder below."""

import glob
import re
import os
import struct
import subprocess
import sys
import tempfile

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import ivolref  # noqa: E402

LOW = 1 << 23
LORENZO = (1, 1, 1, -1, -1, -1, 1)


# ------------------------------------------------------------ encoder (§7.2.1)

def bit_length(z):
    return z.bit_length()            # b(z): 0 for 0, else highest set bit + 1


def token_of(z):
    """(token, number of bits below e, the bits w)"""
    if z < 2:
        return z, 0, 0
    b = bit_length(z)
    e = b - 2
    return 2 * b - 2 + ((z >> e) & 1), e, z & ((1 << e) - 1)


def B(t):
    return t if t < 2 else (t >> 1) + 1


def make_table(c):
    T = sum(c)
    R4 = (1 << 44) // T
    f = [max(1, c_t * R4 // (1 << 32)) for c_t in c]
    D = 4096 - sum(f)
    big = max(f)
    f[f.index(big)] += D
    assert min(f) >= 1 and sum(f) == 4096
    s = [sum(f[:t]) for t in range(32)]
    return f, s


def contexts_and_tokens(zz, ext):
    """Run the model forward: per voxel (token, e, w, f, s)."""
    ex, ey, ez = ext
    n = ex * ey * ez
    assert len(zz) == n
    bl = {}
    counts = [[1] * 32 for _ in range(12)]
    m = [0] * 12
    tables = [make_table(counts[k]) for k in range(12)]
    out = []
    i = 0
    for z in range(ez):
        for y in range(ey):
            for x in range(ex):
                def at(a, b_, c):
                    if 0 <= a < ex and 0 <= b_ < ey and 0 <= c < ez:
                        return bl[(a, b_, c)]
                    return 0
                U, K = at(x, y - 1, z), at(x, y, z - 1)
                L, P = at(x - 1, y - 1, z), at(x + 1, y - 1, z)
                k = min(11, (2 * U + K + L + P + 2) // 5)
                t, e, w = token_of(int(zz[i]))
                f, s = tables[k]
                out.append((t, e, w, f[t], s[t]))
                bl[(x, y, z)] = B(t)
                counts[k][t] += 16
                m[k] += 1
                mk = m[k]
                if (mk >= 4 and (mk & (mk - 1)) == 0) or mk % 128 == 0:
                    tables[k] = make_table(counts[k])
                i += 1
    return out


def encode_residuals(zz, ext, raw_parts=False, lazy_last=False):
    """The bytes after the codec header: R, the rANS stream, the bits below.
    lazy_last: not the spec's encoder; for the last step of each state (voxels
    1 and 0) skip the output of bytes where the state stays below 2^32, which
    gives an initial state of 2^31 or more that the spec's decoder accepts."""
    sym = contexts_and_tokens(zz, ext)
    n = len(sym)
    X = [LOW, LOW]
    emitted = []
    for i in range(n - 1, -1, -1):
        _, _, _, f, s = sym[i]
        x = X[i % 2]
        if lazy_last and i < 2 and x < (1 << 20) * f:
            pass
        else:
            while x >= (1 << 19) * f:
                emitted.append(x % 256)
                x //= 256
        x = 4096 * (x // f) + (x % f) + s
        X[i % 2] = x
    stream = struct.pack("<II", X[0], X[1]) + bytes(reversed(emitted))
    acc, nbits = 0, 0
    for t, e, w, _, _ in sym:
        acc |= w << nbits
        nbits += e
    bits = acc.to_bytes((nbits + 7) // 8, "little")
    if raw_parts:
        return stream, bits, nbits
    return struct.pack("<I", len(stream)) + stream + bits


# ------------------------------------------------------------ §7.2 predictor (encoder side)

def b16_order(v):
    return v ^ 0xFFFF if v & 0x8000 else v | 0x8000


def residuals_of(vals, ext, value_map, shift, taps, level):
    ex, ey, ez = ext
    U = [b16_order(int(v)) if value_map == 1 else int(v) for v in vals]
    out = []
    i = 0
    sy, sz = ex, ex * ey

    def clamp(p):
        return max(0, min(65535, p))
    for z in range(ez):
        for y in range(ey):
            for x in range(ex):
                if x and y and z:
                    nb = (U[i - 1], U[i - sy], U[i - sz], U[i - 1 - sy], U[i - 1 - sz],
                          U[i - sy - sz], U[i - 1 - sy - sz])
                    S = sum(a * b for a, b in zip(taps, nb))
                    r = 1 << (shift - 1) if shift else 0
                    p = clamp((S + r) // (1 << shift) + level)
                else:
                    back = [st for c, st in ((x, 1), (y, sy), (z, sz)) if c]
                    if not back:
                        p = 0
                    elif len(back) == 1:
                        p = U[i - back[0]]
                    else:
                        p = clamp(U[i - back[0]] + U[i - back[1]] - U[i - back[0] - back[1]])
                d = (U[i] - p) % 65536
                if d >= 32768:
                    d -= 65536
                out.append(2 * d if d >= 0 else -2 * d - 1)
                i += 1
    return out


def header(value_map=0, shift=0, taps=(0,) * 7, level=0, entropy=2):
    return struct.pack("<BBBB7hi", 1, value_map, shift, entropy, *taps, level) + b"\0\0"


def payload_of(vals, ext, value_map=1, shift=0, taps=LORENZO, level=0):
    zz = residuals_of(vals, ext, value_map, shift, taps, level)
    return header(value_map, shift, taps, level) + encode_residuals(zz, ext)


# ------------------------------------------------------------ tests

FAILS = []


def check(cond, what):
    if not cond:
        FAILS.append(what)
        print("FAIL:", what)


def decode(body, ext, hdr=None):
    return ivolref.decode_rans_residuals((hdr or header()) + body, ext, "test")


def expect_malformed(body, ext, words, what):
    try:
        decode(body, ext)
    except ivolref.IvolError as err:
        ok = err.cls == "malformed" and all(w in err.message for w in words)
        check(ok, "%s: got %s: %s" % (what, err.cls, err.message))
        return err.message
    check(False, "%s: accepted" % what)


def residual_sets(n, rng):
    yield "all zero", [0] * n
    yield "all 65535", [65535] * n
    yield "all one", [1] * n
    b = rng.integers(0, 17, n)
    yield "random bit lengths", [0 if bb == 0 else int(rng.integers(1 << (bb - 1), 1 << bb)) for bb in b]
    yield "uniform 16-bit", [int(v) for v in rng.integers(0, 65536, n)]
    yield "small", [int(v) for v in rng.geometric(0.3, n) - 1]
    yield "every token", [[0, 1, 2, 3, 4, 6, 8, 12, 16, 24, 32, 48, 64, 96, 128, 192, 256, 384, 512,
                           768, 1024, 1536, 2048, 3072, 4096, 6144, 8192, 12288, 16384, 24576,
                           32768, 49152][i % 32] for i in range(n)]


SHAPES = [(1, 1, 1), (2, 3, 1), (5, 4, 3), (16, 16, 16), (31, 7, 9), (1, 1, 40), (40, 1, 1), (3, 1, 5)]


def test_round_trips(rng):
    import time
    worst = 0.0
    for ext in SHAPES:
        n = ext[0] * ext[1] * ext[2]
        for name, zz in residual_sets(n, rng):
            body = encode_residuals(zz, ext)
            t0 = time.time()
            got = decode(body, ext)
            worst = max(worst, time.time() - t0)
            check(got == list(zz), "round trip %s %s" % (ext, name))
            size = 24 + len(body)
            bound = 24 + ivolref.zstd_compress_bound(2 * n)
            if size > bound:
                print("  note: %s %s: payload %d > codec 3 bound %d" % (ext, name, size, bound))
    print("round trips: %d shapes x 7 residual sets; slowest decode %.3f s" % (len(SHAPES), worst))


def test_values(rng):
    """Whole codec 3 payloads through decode_predicted: every map, shifts, taps, levels."""
    for ext in SHAPES:
        n = ext[0] * ext[1] * ext[2]
        vals_sets = [[int(v) for v in rng.integers(0, 65536, n)],
                     [int(v) for v in (1000 + np.arange(n) * 7 + rng.integers(0, 9, n)) % 65536],
                     [0x8000] * n, [0xFFFF] * n]
        for vals in vals_sets:
            for vm, shift, taps, level in ((1, 0, LORENZO, 0), (0, 3, (5, 4, 3, -2, -1, -1, 0), -7),
                                           (1, 15, (32767, -32768, 100, 0, 0, 0, -1), 123456)):
                pl = payload_of(vals, ext, vm, shift, taps, level)
                got = np.frombuffer(ivolref.decode_predicted(pl, ext, "test"), "<u2").tolist()
                check(got == vals, "values %s map %d shift %d" % (ext, vm, shift))
    print("codec 3 payloads: decode_predicted gives the values back")


def test_corruptions(rng):
    ext = (5, 4, 3)
    n = 60
    zz = [0 if bb == 0 else int(rng.integers(1 << (bb - 1), 1 << bb)) for bb in rng.integers(0, 17, n)]
    stream, bits, E = encode_residuals(zz, ext, raw_parts=True)
    assert E % 8, "want padding bits for the padding test"

    def body(st=stream, bt=bits, R=None):
        return struct.pack("<I", len(st) if R is None else R) + st + bt
    check(decode(body(), ext) == zz, "corruption base decodes")
    # states below 2^23 at the start
    for j in (0, 1):
        st = bytearray(stream)
        struct.pack_into("<I", st, 4 * j, LOW - 1)
        expect_malformed(body(bytes(st)), ext, ["X_%d" % j, "not in 2^23 .. 2^31 - 1"], "X_%d = 2^23 - 1" % j)
        struct.pack_into("<I", st, 4 * j, 0)
        expect_malformed(body(bytes(st)), ext, ["X_%d" % j], "X_%d = 0" % j)
    # a byte left over at the end of the rANS stream
    expect_malformed(body(stream + b"\x00"), ext, ["left over"], "extra stream byte")
    expect_malformed(body(stream + b"\x5a"), ext, ["left over"], "extra stream byte 0x5a")
    # the stream cut short by a byte (R one less): bits part then too long, or stream ends
    msg = expect_malformed(body(stream[:-1]), ext, [], "stream one byte short")
    print("  stream one byte short ->", msg)
    # R out of range
    expect_malformed(body(R=7), ext, ["R = 7"], "R = 7")
    expect_malformed(body(R=len(stream) + len(bits) + 1), ext, ["R ="], "R past the payload")
    expect_malformed(body(R=0xFFFFFFFF), ext, ["R ="], "R = 2^32 - 1")
    # R too large by one but within the payload: the stream then holds a bits byte
    msg = expect_malformed(body(R=len(stream) + 1), ext, [], "R one too large")
    print("  R one too large ->", msg)
    # a missing or extra byte in the bits part
    expect_malformed(body(bt=bits[:-1]), ext, ["bits below"], "bits part one byte short")
    expect_malformed(body(bt=bits + b"\x00"), ext, ["bits below"], "bits part one byte long")
    expect_malformed(body(bt=b""), ext, ["bits below"], "bits part empty")
    # a set padding bit: every padding bit of the last byte, and bit E itself
    for bit in range(E % 8, 8):
        bt = bits[:-1] + bytes([bits[-1] | (1 << bit)])
        expect_malformed(body(bt=bt), ext, ["padding"], "padding bit %d set" % bit)
    # every used bit of the bits part may flip: that only changes residuals
    bt = bytes(b ^ 0xFF for b in bits[:-1]) + bytes([bits[-1] ^ ((1 << (E % 8)) - 1)])
    got = decode(body(bt=bt), ext)
    check(got != zz and len(got) == n, "flipped value bits decode to other residuals")
    # a changed stream byte: refused (final states or stream length) or other tokens
    refused = changed = 0
    for p in range(8, len(stream)):
        for flip in (1, 0x80):
            st = bytearray(stream)
            st[p] ^= flip
            try:
                got = decode(body(bytes(st)), ext)
                changed += got != zz
            except ivolref.IvolError as err:
                check(err.cls == "malformed", "stream flip class %s" % err.cls)
                refused += 1
    print("  %d stream-byte flips refused, %d accepted with other residuals" % (refused, changed))
    # payload too short for R
    for cut in range(0, 4):
        try:
            ivolref.decode_rans_residuals(header() + b"\x08\x00\x00"[:cut], ext, "test")
            check(False, "payload of %d bytes accepted" % (24 + cut))
        except ivolref.IvolError as err:
            check(err.cls == "malformed" and "R" in err.message, "short payload: %s" % err.message)
    # a minimal valid stream: n = 1, R = 8
    b1 = encode_residuals([0], (1, 1, 1))
    check(len(b1) == 12 and decode(b1, (1, 1, 1)) == [0], "n = 1, residual 0: R = 8, no bits")
    # the final states: a stream whose X_1 ends one above 2^23 (n = 1: X_1 is never used)
    st = bytearray(b1[4:])
    struct.pack_into("<I", st, 4, LOW + 1)
    expect_malformed(struct.pack("<I", 8) + bytes(st), (1, 1, 1), ["final rANS states"], "final X_1")
    # through decode_predicted: the class and the check of the codec header first
    pl = header(entropy=4) + body()
    try:
        ivolref.decode_predicted(pl, ext, "test")
        check(False, "entropy 4 accepted")
    except ivolref.IvolError as err:
        check(err.cls == "unsupported-feature", "entropy 4 class %s" % err.cls)
    print("corruptions: checked")


def test_high_initial_state(rng):
    """§7.2.1 asks for initial states in 2^23 .. 2^31 - 1, the range the
    spec's encoder ends in. Where a last step (voxel 0 or 1) would output
    one byte, leaving it out gives a state of 2^31 .. 2^32 - 1 that would
    decode to the same residuals: such a second coding is refused
    (SPEC-NOTES 74, taken into the spec)."""
    seen = 0
    for trial in range(200):
        ext = SHAPES[trial % len(SHAPES)]
        n = ext[0] * ext[1] * ext[2]
        zz = [int(v) for v in rng.integers(0, 1 << int(rng.integers(1, 17)), n)]
        normal = encode_residuals(zz, ext)
        lazy = encode_residuals(zz, ext, lazy_last=True)
        if lazy == normal:
            continue
        x0, x1 = struct.unpack_from("<II", lazy, 4)
        check(max(x0, x1) >= 1 << 31 and len(lazy) < len(normal), "lazy stream %s" % (ext,))
        msg = expect_malformed(lazy, ext, ["2^31"], "initial state >= 2^31")
        check("2^31" in msg, "initial state >= 2^31 refused for its range (%s): %s" % (ext, msg))
        seen += 1
    check(seen > 0, "no stream with an initial state >= 2^31 was made")
    print("initial states >= 2^31: %d streams, each a byte or two shorter than the encoder's, "
          "refused" % seen)


def test_adversary():
    """Residuals chosen voxel by voxel to be the costliest token of the table in
    use: entropy coder 2 then exceeds codec 3's limit on stored bytes (§7), so
    a writer must fall back to coder 1 (SPEC-NOTES 76).  Only reported."""
    import math
    E = [0, 0] + [(q >> 1) - 1 for q in range(2, 32)]
    for ext in ((4, 4, 4), (8, 8, 8), (16, 16, 16)):
        ex, ey, ez = ext
        n = ex * ey * ez
        counts = [[1] * 32 for _ in range(12)]
        m = [0] * 12
        tables = [make_table(counts[k]) for k in range(12)]
        bl, zz = {}, []
        for z in range(ez):
            for y in range(ey):
                for x in range(ex):
                    def at(a, b_, c):
                        return bl.get((a, b_, c), 0)
                    k = min(11, (2 * at(x, y - 1, z) + at(x, y, z - 1) + at(x - 1, y - 1, z)
                                 + at(x + 1, y - 1, z) + 2) // 5)
                    f = tables[k][0]
                    tok = max(range(32), key=lambda q: (E[q] - math.log2(f[q] / 4096), q))
                    zz.append(tok if tok < 2 else (2 + (tok & 1)) << E[tok])
                    bl[(x, y, z)] = B(tok)
                    counts[k][tok] += 16
                    m[k] += 1
                    if (m[k] >= 4 and m[k] & (m[k] - 1) == 0) or m[k] % 128 == 0:
                        tables[k] = make_table(counts[k])
        body = encode_residuals(zz, ext)
        check(decode(body, ext) == zz, "adversarial residuals round trip %s" % (ext,))
        size, bound = 24 + len(body), 24 + ivolref.zstd_compress_bound(2 * n)
        print("  adversarial residuals %s: payload %d bytes, codec 3 limit %d%s" % (
            ext, size, bound, " (over)" if size > bound else ""))


def test_fuzz(rng):
    """Random bytes after a valid header: malformed or residuals, never a crash."""
    outcomes = {}
    for trial in range(3000):
        ext = SHAPES[trial % 5]
        n = ext[0] * ext[1] * ext[2]
        if trial % 3 == 0:   # a valid body, then a random change
            zz = [int(v) for v in rng.integers(0, 1 << int(rng.integers(1, 17)), n)]
            body = bytearray(encode_residuals(zz, ext))
            p = int(rng.integers(0, len(body)))
            body[p] = int(rng.integers(0, 256))
            body = bytes(body)
        else:
            junk = rng.integers(0, 256, int(rng.integers(0, 60)), np.uint8).tobytes()
            body = struct.pack("<I", int(rng.integers(8, 40))) + junk
        try:
            got = decode(body, ext)
            assert len(got) == n and all(0 <= v < 65536 for v in got)
            outcomes["ok"] = outcomes.get("ok", 0) + 1
        except ivolref.IvolError as err:
            check(err.cls == "malformed", "fuzz class %s" % err.cls)
            key = re.sub(r"[0-9]+", "#", err.message.split(": ", 2)[-1])[:40]
            outcomes[key] = outcomes.get(key, 0) + 1
    print("fuzz:", dict(sorted(outcomes.items())))


def test_files(rng, tmp):
    """Whole .ivol 1.3 framed bricked files through `ivolref.py dense`."""
    sys.path.insert(0, os.path.join(HERE, "..", "vectors"))
    import make_vectors as mv

    def pred_payload(vals, ext, value_map=1, shift=0, taps=LORENZO, level=0, **_):
        return payload_of(vals, ext, value_map, shift, taps, level)
    mv.predicted_payload = pred_payload   # entropy coder 2 for every codec 3 block
    cases = [((37, 21, 18), mv.UINT16, 4), ((9, 7, 5), mv.BINARY16, 2), ((16, 16, 16), mv.UINT16, 4),
             ((1, 1, 1), mv.UINT16, 3)]
    for (X, Y, Z), enc, b in cases:
        zz_, yy, xx = np.mgrid[0:Z, 0:Y, 0:X]
        if enc == mv.UINT16:
            src = (20000 + 300 * np.sin(xx / 5.0) * yy + 17 * zz_
                   + rng.integers(0, 64, (Z, Y, X))).astype(np.uint16)
            src[0, 0, 0] = 65535
        else:
            src = rng.integers(0, 65536, (Z, Y, X)).astype(np.uint16)
        g = mv.write_bricked(src, enc, b)
        blocks = mv.bricked_blocks(g, mv.CODEC_PREDICTED, per_brick=lambda q: dict(
            value_map=1 if enc == mv.BINARY16 else q % 2, shift=q % 4,
            taps=LORENZO if q % 3 else (3, 2, 1, -1, -1, 0, 0), level=q - 3))
        blocks.insert(0, mv.meta_block(mv.DEFAULT_META))
        data, _ = mv.assemble(g, blocks, framed=True, minor=3, structure_kind=mv.KIND_BRICKED, ireserved=b)
        path = os.path.join(tmp, "e2_%dx%dx%d.ivol" % (X, Y, Z))
        with open(path, "wb") as f:
            f.write(data)
        out = path + ".out"
        rc = subprocess.run([sys.executable, os.path.join(HERE, "ivolref.py"), "dense", path, "-o", out],
                            capture_output=True, text=True)
        ok = rc.returncode == 0 and open(out, "rb").read() == src.astype("<u2").tobytes()
        check(ok, "file %s: %s %s" % (path, rc.returncode, rc.stdout.strip()))
    print("whole files: %d framed bricked files decode through `ivolref.py dense`" % len(cases))


def block_kinds(path):
    """How many values blocks of each codec (and codec 3 entropy coder) the
    file has; every coder 2 payload is also coded again by the encoder here
    from its decoded residuals, which must give the same bytes."""
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
            if payload[3] == 2:
                ext = ix.brick_of[(e.level, e.first_element)]
                zz = ivolref.decode_rans_residuals(payload, ext, "C++ block")
                again = encode_residuals(zz, ext)
                check(again == payload[24:], "C++ coder 2 block at %d: coded again, other bytes"
                      % e.file_offset)
                key += " (same bytes again)" if again == payload[24:] else " (OTHER BYTES again)"
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
        dims = open(base + ".txt").read().strip() if os.path.exists(base + ".txt") else "?"
        print("  %s (%s): exit %d %s%s; blocks %s" % (os.path.basename(path), dims, rc.returncode,
              "bit-exact" if same else "DIFFERENT", "" if rc.returncode == 0 else " " + rc.stdout.strip(),
              block_kinds(path)))
        check(same, "C++ file %s" % path)
    print("C++ files: %d checked" % len(files))


def main():
    rng = np.random.default_rng(7201)
    test_round_trips(rng)
    test_values(rng)
    test_corruptions(rng)
    test_high_initial_state(rng)
    test_adversary()
    test_fuzz(rng)
    with tempfile.TemporaryDirectory() as tmp:
        test_files(rng, tmp)
    if len(sys.argv) == 3 and sys.argv[1] == "--files":
        test_c_files(sys.argv[2])
    print("FAILED: %d" % len(FAILS) if FAILS else "all passed")
    return 1 if FAILS else 0


if __name__ == "__main__":
    sys.exit(main())
