// Codec 3, "predicted 16-bit" (spec §7.2, format 1.3): the payload of a
// values block that is a brick of 16-bit values. A causal 3-D predictor on
// the u16 bit patterns (so -0 and NaN payloads come back exactly), zigzag
// residuals, entropy-coded by zstd over their two byte planes or by rANS over
// tokens with contexts (§7.2.1), whichever is smaller. Each brick carries
// its own integer predictor taps and level: least squares fitted to the brick
// (with or without a level), or the Lorenzo predictor, whichever leaves the
// smallest residuals.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "ivol/encoding.hpp"

namespace ivol {

// The brick's voxels along x, y, z; the values lie in raster order (x fastest).
using BrickDims = std::array<std::uint32_t, 3>;

struct PredictedOptions {
  int zstd_level = 3;
  // Which taps the encoder may store (the decoder reads any).
  // Best: the smallest residuals of Lorenzo and both fits; LeastSquares: of
  // the fits only.
  enum class Taps { Best, Lorenzo, LeastSquares } taps = Taps::Best;
  // Which entropy coder (§7.2, header byte 3) the encoder may use.
  // Auto (the default): Lanes where zstd_level is 3 or below, Smaller above
  // (the bricked writer's levels 1-3 code residuals at level 1): the
  // default files decode 1.8-1.9 times as fast and encode about twice as
  // fast as Smaller's, for 0.3-0.5 % more bytes in 32³ bricks; a higher
  // level asks for the smaller file (bench/RESULTS.md, "Coder 3 by
  // default"). Smaller: coder 2 (rANS over tokens with adaptive contexts, §7.2.1), or
  // in bricks of 2^18 voxels (64³) or more coder 3 (the same tokens under
  // stored tables with 32 states, §7.2.2: as small there, and decoding
  // twice as fast); and coder 1 (zstd over byte planes) where that coder
  // spends under a bit a voxel or the brick has fewer than 4096 voxels, and
  // coder 1 is smaller (elsewhere coder 1 did not win by more than a few
  // bytes a file and cost a fifth of the encoding time). ZstdPlanes, Tokens:
  // only that one (Tokens falls back to coder 1 where coder 2 passes the
  // spec's limit). Lanes: coder 3 in every brick, or coder 1 under the same
  // rule as Smaller (1.75–1.9 times coder 2's decoding speed in 32³ bricks,
  // for 0.3–0.5 % more bytes).
  enum class Entropy { Auto, Smaller, ZstdPlanes, Tokens, Lanes } entropy = Entropy::Auto;
};

// Size of the codec header in front of the zstd frame (spec §7.2).
constexpr std::size_t kPredictedHeaderSize = 24;

// Encodes `values` (dims[0] * dims[1] * dims[2] of them, at least one) as a
// codec 3 payload. `encoding` picks the value map (binary16 values are
// predicted in their numeric order, uint16 as they are); any bits round-trip.
std::vector<std::uint8_t> encode_predicted(const std::uint16_t* values, const BrickDims& dims, ValueEncoding encoding,
                                           const PredictedOptions& options = {});

// Decodes a codec 3 payload of a brick of `dims` into `out` (room for all of
// its values). Throws Error(Malformed) for a payload that breaks spec §7.2
// and Error(UnsupportedFeature) for a predictor or entropy coder it does not
// know; the message says what is wrong (the caller names the file and block).
// Allocates the residuals' planes (the brick's decoded size) and, for
// entropy coder 2, a byte a voxel and 52 KiB of context tables.
void decode_predicted(const std::uint8_t* payload, std::size_t size, const BrickDims& dims, std::uint16_t* out);

// The largest payload spec §7 allows for `voxels` values, whichever entropy
// coder: the codec header and the largest zstd frame of 2 * voxels bytes.
std::uint64_t predicted_payload_bound(std::uint64_t voxels);

}  // namespace ivol
