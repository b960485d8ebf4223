// The stored levels' exact sums of binary16 runs with AVX2
// (stored_levels_avx2.cpp).
#pragma once

#include <cstdint>

namespace ivol::detail {

// For the first runs of a row of binary16 codes, each of 2^k codes (k ≥ 3),
// four at a time: run c's sum of values in units of 2^-24 into sums[c],
// where `magnitudes` is given its sum of magnitudes, and into special[c]
// whether it holds an infinity or a NaN (1) or not (0). Returns how many
// runs it did: a multiple of 4 at most `runs`, 0 where k < 3 or
// use_avx2() is false; the caller does the others.
std::uint64_t binary16_runs_avx2(const std::uint16_t* row, std::uint64_t runs, unsigned k, std::int64_t* sums,
                                 std::uint64_t* magnitudes, std::uint8_t* special);

}  // namespace ivol::detail
