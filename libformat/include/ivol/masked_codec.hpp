// Codec 4, "masked 16-bit" (spec §7.3, format 1.3): the payload of a values
// block of a bricked grid where one value (the background an object-fidelity
// file puts around the part) fills much of the brick. A mask says which
// voxels hold that value; only the others are stored, as two byte planes in
// one zstd frame. A brick of nothing but the background is 4 bytes. Bits are
// kept exactly (the background and the other values are bit patterns).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace ivol {

// The codec header in front of the zstd frame (spec §7.3).
constexpr std::size_t kMaskedHeaderSize = 4;

// The most common of `count` (at least one) values and how many times it
// occurs (the smallest such value when several tie), found in one pass.
struct CommonValue {
  std::uint16_t value = 0;
  std::size_t count = 0;
};
CommonValue most_common_value(const std::uint16_t* values, std::size_t count);

// A value that may fill an eighth of the `count` values or more (a
// background for codec 4), with its exact count, found from a sample of
// every 127th value first; {values[0], 0} where the sample shows none.
// Below 8128 values it is most_common_value. It can miss a value that fills
// an eighth of a brick but a sixteenth of no such lattice (a background
// with a smooth border is sampled evenly).
CommonValue likely_background(const std::uint16_t* values, std::size_t count);

// Encodes `count` (at least one) values as a codec 4 payload with
// `background` as the masked value, at zstd level `zstd_level`.
std::vector<std::uint8_t> encode_masked(const std::uint16_t* values, std::size_t count, std::uint16_t background,
                                        int zstd_level);

// Decodes a codec 4 payload of `count` values into `out`. Throws
// Error(Malformed) for a payload that breaks spec §7.3 (the message says what;
// the caller names the file and block); allocates nothing beyond the decoded
// frame, whose size the frame header states and is checked against the
// largest a block of `count` values can hold before it is allocated.
void decode_masked(const std::uint8_t* payload, std::size_t size, std::size_t count, std::uint16_t* out);

// The largest payload of `count` values (spec §7): the codec header and the
// largest zstd frame of the mask and every value.
std::uint64_t masked_payload_bound(std::uint64_t count);

}  // namespace ivol
