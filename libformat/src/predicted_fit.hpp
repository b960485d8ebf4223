// The encoder's choice of taps for a codec 3 brick (spec §7.2): least
// squares fitted to the brick, with and without a level.
#pragma once

#include <cstdint>

#include "ivol/predicted_codec.hpp"
#include "predicted_rows.hpp"

namespace ivol::detail {

// The sums both fits need, over the brick's interior voxels (x, y, z > 0) of
// the mapped values u: count, Σf_i and Σf_i·f_j for f = (U, its seven causal
// neighbours in the order of the taps) less the first interior voxel. Exact
// integers (no rounding in any order of summation).
struct BrickMoments {
  std::int64_t count = 0;
  std::int64_t sum[8] = {};
  std::int64_t product[8][8] = {};
};

// Which interior rows (y, z > 0) the encoder's fits and its judging of
// candidate taps look at: every one (step 1), or (step 2) those of odd y and
// odd z, a quarter. A quarter of a brick's rows fits and judges taps about as
// well as all of them (files the same to 0.02 % without noise, 0.01-0.09 %
// larger with Poisson noise), and the fits and judging were more than a
// third of the encoder's time (bench/RESULTS.md, issue 22).
struct RowSample {
  std::uint32_t step = 1;  // along y and along z
  bool all() const { return step == 1; }
};

// A quarter of the rows where that still leaves enough voxels to judge by.
RowSample row_sample(const BrickDims& d);

// False when the sample has fewer than 64 interior voxels (no fit is tried).
bool brick_moments(const BrickDims& d, const std::uint16_t* u, BrickMoments& out, RowSample sample = {});

// Taps summing to exactly 2^12 (so that rounding them costs nothing on a
// constant level): U − U(x−1) fitted on the other six neighbours less
// U(x−1). False when the fit is degenerate or a tap does not fit.
bool fit_least_squares(const BrickMoments& m, PredictorTaps& out);

// Taps with a level (intercept), for bricks where noise dominates: the level
// is the mean of what the rounded taps leave over the sample's rows (one
// more pass over them).
bool fit_least_squares_with_level(const BrickDims& d, const std::uint16_t* u, const BrickMoments& m, PredictorTaps& out,
                                  RowSample sample = {});

}  // namespace ivol::detail
