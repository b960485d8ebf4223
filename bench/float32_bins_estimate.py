#!/usr/bin/env python3
"""Issue 22: what a binned float32 codec would give, estimated, against
codec 2 (zstd 3 over byte planes, one frame flushed per plane) and pcodec,
per brick of 32^3 of a reconstruction.

    python bench/float32_bins_estimate.py VOLUME.f32 [--every K] [--groups G] [--table-bits T]

VOLUME.f32: 256^3 float32 (x fastest), as bench/run_peers_codecs.sh caches
them. --every K takes every K-th layer of bricks along z (default 4).
The estimate: the values in the binary32 order (negative ones reversed
below the positive ones); bins chosen per brick by a dynamic programme over
G quantile groups (default 128) minimising bits: each voxel's bin by its
entropy (order 0, or with the x and y neighbours' bins as context, plus
half a log2 of the context's count a bin for learning it) and its offset in
the fewest whole bits that cover its bin, plus T bits of table a bin
(default 40). Needs numpy, zstandard and pcodec (the peers' venv).
"""
import argparse

import numpy as np


def entropy_bits(counts):
    c = counts[counts > 0].astype(float)
    return -(c * np.log2(c / c.sum())).sum()


def offset_bits(span):
    return np.ceil(np.log2(np.maximum(span, 0) + 1)).astype(np.int64)


def binned_bits(a, groups, table_bits, b):
    """Order-0 and context estimates of one brick (a: the ordered values)."""
    n = a.size
    s = np.sort(a)
    cuts = np.unique(np.searchsorted(s, s[(np.arange(1, groups) * n) // groups], side="left"))
    cuts = cuts[(cuts > 0) & (cuts < n)]
    starts = np.concatenate([[0], cuts])
    ends = np.concatenate([cuts, [n]])
    g = len(starts)
    lo, hi = s[starts], s[ends - 1]
    cum = np.concatenate([[0], np.cumsum(ends - starts)])
    best = np.full(g + 1, np.inf)
    best[0] = 0
    arg = np.zeros(g + 1, np.int64)
    for j in range(1, g + 1):
        i = np.arange(j)
        c = cum[j] - cum[i]
        cost = best[i] + c * offset_bits(hi[j - 1] - lo[i]) - c * np.log2(c / n) + table_bits
        k = int(np.argmin(cost))
        best[j], arg[j] = cost[k], k
    bins = []
    j = g
    while j > 0:
        bins.append((lo[arg[j]], hi[j - 1]))
        j = arg[j]
    bins.reverse()
    bin_lo = np.array([x[0] for x in bins])
    idx = np.searchsorted(bin_lo, a, side="right") - 1
    raw = offset_bits(np.array([x[1] - x[0] for x in bins]))[idx].sum()
    table = len(bins) * table_bits
    order0 = entropy_bits(np.bincount(idx, minlength=len(bins))) + raw + table
    bi = idx.reshape(b, b, b)
    before_x = np.zeros_like(bi)
    before_x[:, :, 1:] = bi[:, :, :-1]
    before_y = np.zeros_like(bi)
    before_y[:, 1:, :] = bi[:, :-1, :]
    context = np.minimum(7, ((before_x + before_y) * 4) // max(len(bins), 1))
    with_context = raw + table
    for c in range(8):
        m = bi[context == c]
        if m.size:
            with_context += entropy_bits(np.bincount(m, minlength=len(bins))) + 0.5 * len(bins) * np.log2(max(m.size, 2))
    return order0, with_context


def main():
    import zstandard
    from pcodec import ChunkConfig, standalone
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("volume")
    parser.add_argument("--every", type=int, default=4)
    parser.add_argument("--groups", type=int, default=128)
    parser.add_argument("--table-bits", type=int, default=40)
    args = parser.parse_args()
    b = 32
    v = np.fromfile(args.volume, dtype="<f4")
    n = round(len(v) ** (1 / 3))
    v = v.reshape(n, n, n)
    u = v.view(np.uint32).astype(np.int64)
    ordered = np.where(u >> 31, 0x7FFFFFFF - (u & 0x7FFFFFFF), 0x80000000 + (u & 0x7FFFFFFF))
    totals = dict(codec2=0, pcodec=0, bins=0.0, bins_context=0.0)
    bricks = 0
    for z0 in range(0, n - b + 1, b * args.every):
        for y0 in range(0, n - b + 1, b):
            for x0 in range(0, n - b + 1, b):
                brick = np.ascontiguousarray(v[z0:z0 + b, y0:y0 + b, x0:x0 + b])
                planes = brick.view(np.uint8).reshape(-1, 4)
                z = zstandard.ZstdCompressor(level=3).compressobj(size=brick.nbytes)
                frame = b""
                for p in range(4):
                    frame += z.compress(planes[:, p].tobytes())
                    if p < 3:
                        frame += z.flush(zstandard.COMPRESSOBJ_FLUSH_BLOCK)
                frame += z.flush()
                totals["codec2"] += len(frame)
                totals["pcodec"] += len(standalone.simple_compress(brick.ravel(), ChunkConfig()))
                o0, oc = binned_bits(ordered[z0:z0 + b, y0:y0 + b, x0:x0 + b].ravel(), args.groups,
                                     args.table_bits, b)
                totals["bins"] += o0 / 8
                totals["bins_context"] += oc / 8
                bricks += 1
    base = totals["codec2"]
    print("%s: %d bricks of %d^3" % (args.volume, bricks, b))
    for k, t in totals.items():
        print("  %-13s %12d bytes  %+.2f %% against codec 2" % (k, t, 100.0 * t / base - 100))


if __name__ == "__main__":
    main()
