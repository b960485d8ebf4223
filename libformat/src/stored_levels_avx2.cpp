// The stored levels' exact sums of binary16 runs with AVX2: the same
// arithmetic as the SSE2 path in stored_levels.cpp (normal numbers as
// binary64 in units of 2^-136, subnormals as 32-bit integers, every sum
// exact), eight codes a step, and four runs' lanes added across at once
// (a run of 8 codes, the 1/8 level's, had more horizontal sums than work).
#include "stored_levels_avx2.hpp"

#include <cstring>

#include "cpu_features.hpp"

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#include <immintrin.h>
#define IVOL_HAVE_AVX2_RUNS 1
#endif

namespace ivol::detail {

#ifdef IVOL_HAVE_AVX2_RUNS
namespace {

struct RunLanes {
  __m256d sum, magnitude;
  __m256i subnormal_sum, subnormal_magnitude, special;
};

__attribute__((target("avx2"))) inline void add_eight(const std::uint16_t* p, RunLanes& s) {
  const __m256i v = _mm256_cvtepu16_epi32(_mm_loadu_si128(reinterpret_cast<const __m128i*>(p)));
  const __m256i abs_mask = _mm256_set1_epi32(0x7FFF);
  const __m256i bits = _mm256_and_si256(v, abs_mask);
  const __m256i infinite_or_nan = _mm256_cmpgt_epi32(bits, _mm256_set1_epi32(0x7BFF));
  const __m256i subnormal = _mm256_cmpgt_epi32(_mm256_set1_epi32(0x0400), bits);  // and zeros
  s.special = _mm256_or_si256(s.special, infinite_or_nan);
  const __m256i sign = _mm256_slli_epi32(_mm256_andnot_si256(abs_mask, v), 16);
  const __m256i normal_bits = _mm256_andnot_si256(_mm256_or_si256(infinite_or_nan, subnormal), bits);
  const __m256 value = _mm256_castsi256_ps(_mm256_or_si256(_mm256_slli_epi32(normal_bits, 13), sign));
  const __m256d low = _mm256_cvtps_pd(_mm256_castps256_ps128(value));
  const __m256d high = _mm256_cvtps_pd(_mm256_extractf128_ps(value, 1));
  const __m256d abs_pd = _mm256_castsi256_pd(_mm256_set1_epi64x(0x7FFFFFFFFFFFFFFF));
  s.sum = _mm256_add_pd(s.sum, _mm256_add_pd(low, high));
  s.magnitude = _mm256_add_pd(s.magnitude, _mm256_add_pd(_mm256_and_pd(low, abs_pd), _mm256_and_pd(high, abs_pd)));
  const __m256i units = _mm256_and_si256(subnormal, bits);  // a subnormal's units: its significand
  const __m256i negative = _mm256_srai_epi32(sign, 31);
  s.subnormal_sum = _mm256_add_epi32(s.subnormal_sum, _mm256_sub_epi32(_mm256_xor_si256(units, negative), negative));
  s.subnormal_magnitude = _mm256_add_epi32(s.subnormal_magnitude, units);
}

// The four runs' totals, run r in lane r.
__attribute__((target("avx2"))) inline __m256d across(const __m256d (&v)[4]) {
  const __m256d ab = _mm256_hadd_pd(v[0], v[1]), cd = _mm256_hadd_pd(v[2], v[3]);
  // ab = [a01, b01, a23, b23], cd = [c01, d01, c23, d23]
  return _mm256_add_pd(_mm256_permute2f128_pd(ab, cd, 0x20), _mm256_permute2f128_pd(ab, cd, 0x31));
}
__attribute__((target("avx2"))) inline __m128i across(const __m256i (&v)[4]) {
  const __m256i ab = _mm256_hadd_epi32(v[0], v[1]), cd = _mm256_hadd_epi32(v[2], v[3]);
  const __m256i abcd = _mm256_hadd_epi32(ab, cd);  // [a, b, c, d] in each half
  return _mm_add_epi32(_mm256_castsi256_si128(abcd), _mm256_extracti128_si256(abcd, 1));
}

__attribute__((target("avx2"))) std::uint64_t runs_avx2(const std::uint16_t* row, std::uint64_t runs, unsigned k,
                                                        std::int64_t* sums, std::uint64_t* magnitudes,
                                                        std::uint8_t* special) {
  const std::uint64_t run = std::uint64_t{1} << k;
  constexpr double kUnitsPerLaneUnit = 0x1p136;  // 2^136 lane units are one of 2^-24
  std::uint64_t c = 0;
  for (; c + 4 <= runs; c += 4) {
    __m256d sum[4], magnitude[4];
    __m256i subnormal_sum[4], subnormal_magnitude[4];
    for (int r = 0; r < 4; ++r) {
      RunLanes s{_mm256_setzero_pd(), _mm256_setzero_pd(), _mm256_setzero_si256(), _mm256_setzero_si256(),
                 _mm256_setzero_si256()};
      const std::uint16_t* p = row + (c + r) * run;
      for (std::uint64_t x = 0; x < run; x += 8) add_eight(p + x, s);
      sum[r] = s.sum, magnitude[r] = s.magnitude;
      subnormal_sum[r] = s.subnormal_sum, subnormal_magnitude[r] = s.subnormal_magnitude;
      special[c + r] = !_mm256_testz_si256(s.special, s.special);
    }
    double totals[4], magnitude_totals[4];
    std::int32_t subnormal_totals[4], subnormal_magnitude_totals[4];
    _mm256_storeu_pd(totals, _mm256_mul_pd(across(sum), _mm256_set1_pd(kUnitsPerLaneUnit)));
    _mm256_storeu_pd(magnitude_totals, _mm256_mul_pd(across(magnitude), _mm256_set1_pd(kUnitsPerLaneUnit)));
    _mm_storeu_si128(reinterpret_cast<__m128i*>(subnormal_totals), across(subnormal_sum));
    _mm_storeu_si128(reinterpret_cast<__m128i*>(subnormal_magnitude_totals), across(subnormal_magnitude));
    for (int r = 0; r < 4; ++r) {
      sums[c + r] = static_cast<std::int64_t>(totals[r]) + subnormal_totals[r];
      if (magnitudes)
        magnitudes[c + r] = static_cast<std::uint64_t>(magnitude_totals[r]) +
                            static_cast<std::uint64_t>(static_cast<std::uint32_t>(subnormal_magnitude_totals[r]));
    }
  }
  _mm256_zeroupper();  // the caller's SSE code next (as in token_contexts.cpp)
  return c;
}

}  // namespace

std::uint64_t binary16_runs_avx2(const std::uint16_t* row, std::uint64_t runs, unsigned k, std::int64_t* sums,
                                 std::uint64_t* magnitudes, std::uint8_t* special) {
  if (k < 3 || !use_avx2()) return 0;
  return runs_avx2(row, runs, k, sums, magnitudes, special);
}
#else
std::uint64_t binary16_runs_avx2(const std::uint16_t*, std::uint64_t, unsigned, std::int64_t*, std::uint64_t*,
                                 std::uint8_t*) {
  return 0;
}
#endif

}  // namespace ivol::detail
