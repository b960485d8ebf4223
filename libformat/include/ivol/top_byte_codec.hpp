// Codec 6, "top byte in context" (spec §7.4, format 1.3): the payload of a
// values block that is one brick of 2- or 4-byte values. Each value's most
// significant byte (sign, exponent and the top of the fraction, for binary16
// and float32) is coded by rANS under adaptive models chosen by the top bytes
// of its causal neighbours; in mode 1 (the library's for 4-byte values) also
// the next byte's high nibble, in the context of the top byte; the other
// bits are stored as they are.
//
// Why: in a CT reconstruction with Poisson noise the air and much of the
// part are noise around small values, whose sign flips from voxel to voxel.
// A predictor (codec 3) then sees residuals thousands of codes wide, and zstd
// over byte planes (codecs 2 and 5) codes the top plane with one table for the
// whole brick. The low bytes of such values are noise no model compresses;
// the top byte depends on its neighbours' signs and magnitudes, and is where
// the bytes can be saved (bench/RESULTS.md, issue 22, "Codec 6").
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "ivol/predicted_codec.hpp"

namespace ivol {

// Size of the codec header in front of the rANS stream (spec §7.4).
constexpr std::size_t kTopByteHeaderSize = 8;

// Encodes the brick's values, `width` (2 or 4) little-endian bytes each, in
// raster order (x fastest), as a codec 6 payload. Returns an empty vector
// when the payload would not be smaller than `limit` bytes, or would pass
// the spec's limit (top_byte_payload_bound): the caller then keeps another
// codec. `step` sets the width of the contexts' magnitude classes (the
// header's S, at least 1); 0 leaves it to the encoder, which takes two
// thirds of the top bytes' spread and at least 4 (best for noisy bricks;
// noise-free float32 bricks of 64³ do better with 1 or 2).
std::vector<std::uint8_t> encode_top_byte(const std::uint8_t* values, const BrickDims& dims, unsigned width,
                                          std::size_t limit, unsigned step = 0);

// Decodes a codec 6 payload of a brick of `dims` and `width` into `out`
// (dims' product times width bytes, little-endian values). Throws
// Error(Malformed), the message saying what is wrong (the caller names the
// file and block), for any byte string that breaks §7.4. Keeps per thread a
// byte a value and the models (about 3 KiB for each of 128 contexts, in
// mode 1 also 200 bytes for each of 256), made as their contexts are met;
// nothing the payload's bytes size.
void decode_top_byte(const std::uint8_t* payload, std::size_t size, const BrickDims& dims, unsigned width,
                     std::uint8_t* out);

// The largest payload spec §7 allows for `count` values of `width` bytes:
// 12 + width·count, no larger than the values stored and a header (an
// encoding that would be larger is not codec 6).
std::uint64_t top_byte_payload_bound(std::uint64_t count, unsigned width);

}  // namespace ivol
