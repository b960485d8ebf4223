#!/usr/bin/env python3
"""Issue 22: what a float32 codec that predicts in the values' own (linear)
domain and codes sign, exponent and fraction apart would give, estimated per
brick of 32^3 against pcodec's and codec 2's bytes (bench/RESULTS.md).

    /usr/bin/python3 bench/float32_split_estimate.py VOLUME.f32 [--brick 32]

VOLUME.f32: 256^3 float32 (x fastest), as bench/run_peers_codecs.sh caches
them. Each voxel is predicted from the causal neighbours of its brick (x, y
or z one step back; the mean of those present, Lorenzo, or x alone), in
fixed point with 40 fractional bits (so a codec could do it in integers),
then coded as:
  - its sign relative to the prediction's, in the context of the
    prediction's exponent field;
  - its exponent field minus the prediction's (clipped to +-15, an escape
    sending 8 bits), in the context of (prediction's exponent, sign flip);
  - its fraction as a residual (the prediction's fraction when sign and
    exponent agree, else the fraction's end nearest the prediction), as
    coder 2's tokens (sign, bit length, two bits below the top) in the
    context of (exponent, case), the other bits sent as they are.
Each context's cost is what an adaptive model that starts afresh in every
brick pays (the Krichevsky-Trofimov sum with a prior count of 1/16, which
is coder 2's start of 1 and step of 16), so it counts the learning.
Needs numpy and scipy (Debian's python3-numpy, python3-scipy).
"""
import argparse

import numpy as np
from scipy.special import gammaln


def adaptive_bits(context, symbol, brick, alpha=1.0 / 16):
    """Bits of an adaptive count model per (brick, context), order-free."""
    key = (brick << 40) + (context << 20) + symbol
    _, with_symbol = np.unique(key, return_counts=True)
    _, per_context = np.unique((brick << 40) + (context << 20), return_counts=True)
    alphabet = len(np.unique(symbol))
    nats = (gammaln(per_context + alpha * alphabet) - gammaln(alpha * alphabet)).sum() - (
        gammaln(with_symbol + alpha) - gammaln(alpha)
    ).sum()
    return nats / np.log(2)


def tokens(residual):
    """Coder 2's tokens of a signed residual, and the bits sent below them."""
    magnitude = np.abs(residual)
    length = np.zeros_like(magnitude)
    nonzero = magnitude > 0
    length[nonzero] = np.floor(np.log2(magnitude[nonzero])).astype(np.int64) + 1
    top = np.where(length >= 3, (magnitude >> np.maximum(length - 3, 0)) & 3, magnitude)
    return (np.sign(residual) + 1) * 128 + length * 4 + top, np.maximum(length - 3, 0).sum()


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("volume")
    ap.add_argument("--brick", type=int, default=32)
    args = ap.parse_args()
    b = args.brick
    v = np.fromfile(args.volume, dtype=np.float32).reshape(256, 256, 256)
    nb = 256 // b
    bricks = v.reshape(nb, b, nb, b, nb, b).transpose(0, 2, 4, 1, 3, 5).reshape(-1, b, b, b)
    brick_id = np.broadcast_to(np.arange(bricks.shape[0])[:, None, None, None], bricks.shape).ravel().astype(np.int64)
    values = bricks.astype(np.float64)

    def back(a, axis):  # the neighbour one step back along an axis of the brick, NaN outside
        out = np.full_like(a, np.nan)
        dst = [slice(None)] * 4
        src = [slice(None)] * 4
        dst[axis], src[axis] = slice(1, None), slice(0, -1)
        out[tuple(dst)] = a[tuple(src)]
        return out

    x, y, z = back(values, 3), back(values, 2), back(values, 1)
    xy, xz, yz = back(x, 2), back(x, 1), back(y, 1)
    xyz = back(xy, 1)

    def first_of(*candidates):
        p = candidates[0]
        for c in candidates[1:]:
            p = np.where(np.isnan(p), c, p)
        return np.where(np.isnan(p), 0.0, p)

    with np.errstate(invalid="ignore"):
        mean = np.nanmean(np.stack([x, y, z]), axis=0)
    predictors = {
        "mean of x, y, z": first_of(mean),
        "Lorenzo": first_of(x + y + z - xy - xz - yz + xyz, x + y - xy, x + z - xz, y + z - yz, x, y, z),
        "x": first_of(x, y, z),
    }
    bits = bricks.view(np.uint32).ravel().astype(np.int64)
    sign, exponent, fraction = bits >> 31, (bits >> 23) & 255, bits & ((1 << 23) - 1)
    n = bits.size
    for name, p in predictors.items():
        fixed = np.trunc(p * 2.0**40) / 2.0**40
        pbits = fixed.astype(np.float32).view(np.uint32).ravel().astype(np.int64)
        psign, pexponent, pfraction = pbits >> 31, (pbits >> 23) & 255, pbits & ((1 << 23) - 1)
        flip = sign ^ psign
        step = exponent - pexponent
        escapes = np.abs(step) > 15
        sign_bits = adaptive_bits(pexponent, flip, brick_id)
        exponent_bits = adaptive_bits(pexponent * 2 + flip, np.clip(step, -16, 16) + 16, brick_id) + 8 * escapes.sum()
        case = np.where(flip == 1, 3, np.where(step == 0, 0, np.where(step > 0, 1, 2)))
        reference = np.where(case == 0, pfraction, np.where(case == 2, (1 << 23) - 1, 0))
        token, below = tokens(fraction - reference)
        fraction_bits = adaptive_bits(exponent * 4 + case, token, brick_id) + below
        total = (sign_bits + exponent_bits + fraction_bits) / 8
        print(
            f"{name:16s} {total:14,.0f} bytes ({8 * total / n:.2f} bits a voxel: sign {sign_bits / n:.2f}, "
            f"exponent {exponent_bits / n:.2f}, fraction {fraction_bits / n:.2f}; escapes {escapes.mean():.4%})",
            flush=True,
        )


if __name__ == "__main__":
    main()
