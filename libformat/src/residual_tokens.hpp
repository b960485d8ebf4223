// Entropy coder 2 of codec 3 (spec §7.2.1): a brick's zigzag residuals as
// tokens (a residual's bit length and the bit after its leading one) coded by
// rANS under twelve adaptive contexts taken from the tokens of the voxel's
// causal neighbours, and the bits below each token packed as they are.
//
// Why this and not zstd's Huffman tables over byte planes (entropy coder 1):
// the residuals' sizes depend on their neighbours' (the part's edges, noise
// that varies across the brick), which byte planes cannot see, and the
// tokens are too skewed for whole-bit codes. The model learns within the
// brick and stores no table, so small bricks pay nothing for it; decoding
// is a table lookup and a multiply per voxel. Measured in bench/RESULTS.md
// ("Entropy coder 2 of codec 3").
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "ivol/predicted_codec.hpp"

namespace ivol::detail {

// Appends the coded residuals (the part of a codec 3 payload after its
// header, spec §7.2.1) of the brick's n = dims[0]·dims[1]·dims[2] residuals
// to `out`. Returns false, leaving `out` as it was, when the result would be
// larger than `limit` bytes: the caller then keeps the other coder.
bool encode_residual_tokens(const std::uint16_t* residuals, const BrickDims& dims, std::size_t limit,
                            std::vector<std::uint8_t>& out);

// Decodes the coded residuals [data, data + size) of a brick of `dims` into
// residuals[0 .. n). Throws Error(Malformed), the message saying what is
// wrong, for any byte string that breaks §7.2.1.
void decode_residual_tokens(const std::uint8_t* data, std::size_t size, const BrickDims& dims,
                            std::uint16_t* residuals);

}  // namespace ivol::detail
