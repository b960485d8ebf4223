// Entropy coder 3 of codec 3 (spec §7.2.2): coder 2's tokens, contexts and
// bits below (token_contexts.hpp), under frequencies stored per context in
// the payload, with 32 rANS states taking the voxels in turn.
//
// Why beside coder 2: coder 2's decoding is bound by the chain from one of
// its two states to the next (a table lookup, a multiply, a
// renormalisation, about ten cycles a voxel), whatever else the loop does.
// Fixed tables and 32 states let a decoder run 32 such chains at once, 8
// a vector: the whole codec 3 decode runs 1.75–1.9 times as fast in 32³
// bricks, for 0.3–0.5 % more bytes (the tables and states), and twice as
// fast in 64³ for none (bench/RESULTS.md, "Entropy coder 3").
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "ivol/predicted_codec.hpp"
#include "token_contexts.hpp"

namespace ivol::detail {

inline constexpr unsigned kLaneCount = 32;
inline constexpr std::uint32_t kLaneStateLow = 1u << 16;  // a state lies in [2^16, 2^32) between voxels

// Appends the coded residuals (the part of a codec 3 payload after its
// header, spec §7.2.2) of the brick's n = dims[0]·dims[1]·dims[2] residuals
// to `out`. Returns false, leaving `out` as it was, when the result would be
// larger than `limit` bytes.
bool encode_residual_lanes(const std::uint16_t* residuals, const BrickDims& dims, std::size_t limit,
                           std::vector<std::uint8_t>& out);

// Decodes the coded residuals [data, data + size) of a brick of `dims` into
// residuals[0 .. n). Throws Error(Malformed), the message saying what is
// wrong, for any byte string that breaks §7.2.2.
void decode_residual_lanes(const std::uint8_t* data, std::size_t size, const BrickDims& dims, std::uint16_t* residuals);

// For the vector decoder (residual_lanes_avx2.cpp): every context's table
// as one word a slot, token | f << 5 | (slot − s) << 18, so that a step is
// one gathered load.
struct LaneSlotWords {
  std::vector<std::uint32_t> words;  // [context · 4096 + slot]
};

// Where the decoder stands: the 32 states, the words not yet read.
struct LaneDecoderState {
  std::array<std::uint32_t, kLaneCount> x;
  const std::uint8_t* words;  // the next word's two bytes
  const std::uint8_t* words_end;
};

// Decodes the tokens of whole rows from `row` on with AVX2, rows of a
// multiple of 32 voxels, while the words left surely hold a row's: writes
// tokens and bit lengths of those rows, advances `state`, and returns the
// first row not decoded (the scalar decoder goes on from there). Returns
// `row` itself where the processor has no AVX2.
std::size_t decode_lane_rows_avx2(const LaneSlotWords& slots, const BrickDims& dims, std::size_t row,
                                  LaneDecoderState& state, std::uint8_t* tokens, std::uint8_t* lengths);
bool lane_rows_avx2_available();

// For the vector encoder: f | s << 16 of token t in context k, at k · 32 + t.
using LaneSymbols = std::array<std::uint32_t, kTokenContexts * kTokenCount>;

// Codes voxels [0, 32 · chunks) with AVX2, from the last, as the scalar
// encoder does (voxel i on state i mod 32, a renormalisation's word stored
// below the ones before it): x holds the states after the voxels above
// them, `w` points after the room for the words, at least one a voxel
// still to code (a vector stores 8 words below `w`, those below its own
// written over later, so it writes nothing below the room of the voxels
// before it). Returns where the words now begin. Needs AVX2 (lane_rows_avx2_available).
std::uint16_t* encode_lane_chunks_avx2(const LaneSymbols& symbols, const std::uint8_t* contexts,
                                       const std::uint8_t* tokens, std::size_t chunks,
                                       std::array<std::uint32_t, kLaneCount>& x, std::uint16_t* w);

}  // namespace ivol::detail
