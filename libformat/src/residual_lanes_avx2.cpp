// Entropy coder 3's tokens decoded and coded with AVX2 (spec §7.2.2), the
// 32 states as four vectors of 8 lanes. The decoder: a gather of their slot
// words a vector, and the renormalisation of the lanes below 2^16 from the
// next words, moved into their lanes by a permutation chosen by the lanes'
// mask. Four gathers are in flight at once: on the cores measured a
// gather's result is otherwise waited for. The encoder: the same steps
// backwards, its words moved out of their lanes by such a permutation.
#include <array>
#include <cstring>

#include "cpu_features.hpp"
#include "residual_lanes.hpp"

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#include <immintrin.h>
#define IVOL_HAVE_AVX2_LANES 1
#endif

namespace ivol::detail {

#ifdef IVOL_HAVE_AVX2_LANES
namespace {

// For each mask of lanes that take a word: lane l takes word
// (the number of such lanes before it).
struct Permutations {
  std::array<std::array<std::uint32_t, 8>, 256> index{};
  Permutations() {
    for (unsigned m = 0; m < 256; ++m)
      for (unsigned l = 0, k = 0; l < 8; ++l)
        if (m >> l & 1) index[m][l] = k++;
  }
};

constexpr unsigned kVectors = kLaneCount / 8;

}  // namespace

__attribute__((target("avx2"))) std::size_t decode_lane_rows_avx2(const LaneSlotWords& slots, const BrickDims& d,
                                                                  std::size_t row, LaneDecoderState& state,
                                                                  std::uint8_t* tokens, std::uint8_t* lengths) {
  static const Permutations permutations;
  const int* const slot_words = reinterpret_cast<const int*>(slots.words.data());
  const std::uint32_t nx = d[0];
  const std::size_t rows = std::size_t{d[1]} * d[2], sy = nx, sz = std::size_t{nx} * d[1];
  __m256i xs[kVectors];
  for (unsigned v = 0; v < kVectors; ++v)
    xs[v] = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(state.x.data() + 8 * v));
  const std::uint8_t* words = state.words;
  const __m256i low12 = _mm256_set1_epi32(kTableTotal - 1), low5 = _mm256_set1_epi32(31),
                freq_mask = _mm256_set1_epi32(0x1FFF), zero = _mm256_setzero_si256();
  std::vector<std::uint8_t> zeros(nx), contexts(nx), padded(std::size_t{nx} + 2);
  // A row takes at most one word a voxel, and the last vector's load reads
  // 8 words from where it starts: a row whose voxels' words surely lie in
  // the stream reads nothing past it.
  for (; row < rows && static_cast<std::size_t>(state.words_end - words) >= 2 * std::size_t{nx}; ++row) {
    const std::size_t i = row * nx;
    row_contexts(row % d[1] ? lengths + i - sy : zeros.data(), row >= d[1] ? lengths + i - sz : zeros.data(), nx,
                 padded.data(), contexts.data());
    for (std::uint32_t x0 = 0; x0 < nx; x0 += kLaneCount) {
      __m256i w[kVectors];
      for (unsigned v = 0; v < kVectors; ++v) {  // the gathers, all in flight
        std::uint64_t eight;
        std::memcpy(&eight, contexts.data() + x0 + 8 * v, 8);
        const __m256i k = _mm256_cvtepu8_epi32(_mm_cvtsi64_si128(static_cast<long long>(eight)));
        const __m256i slot = _mm256_and_si256(xs[v], low12);
        w[v] = _mm256_i32gather_epi32(slot_words, _mm256_add_epi32(_mm256_slli_epi32(k, kTableBits), slot), 4);
      }
      for (unsigned v = 0; v < kVectors; ++v) {
        __m256i& x = xs[v];
        const __m256i t = _mm256_and_si256(w[v], low5);
        // Tokens to bytes: packus within the 128-bit halves, their low
        // quadwords together, then to bytes.
        const __m128i t16 = _mm256_castsi256_si128(_mm256_permute4x64_epi64(_mm256_packus_epi32(t, t), 0x08));
        const __m128i t8 = _mm_packus_epi16(t16, t16);
        _mm_storel_epi64(reinterpret_cast<__m128i*>(tokens + i + x0 + 8 * v), t8);
        // Bit lengths: (t >> 1) + (t > 0), as token_bit_length.
        const __m128i half = _mm_and_si128(_mm_srli_epi16(t8, 1), _mm_set1_epi8(0x7F));
        const __m128i nonzero = _mm_min_epu8(t8, _mm_set1_epi8(1));
        _mm_storel_epi64(reinterpret_cast<__m128i*>(lengths + i + x0 + 8 * v), _mm_add_epi8(half, nonzero));
        x = _mm256_add_epi32(_mm256_mullo_epi32(_mm256_and_si256(_mm256_srli_epi32(w[v], 5), freq_mask),
                                                _mm256_srli_epi32(x, kTableBits)),
                             _mm256_srli_epi32(w[v], 18));
        const __m256i need = _mm256_cmpeq_epi32(_mm256_srli_epi32(x, 16), zero);
        const unsigned m = static_cast<unsigned>(_mm256_movemask_ps(_mm256_castsi256_ps(need)));
        const __m256i next = _mm256_cvtepu16_epi32(_mm_loadu_si128(reinterpret_cast<const __m128i*>(words)));
        const __m256i placed = _mm256_permutevar8x32_epi32(
            next, _mm256_loadu_si256(reinterpret_cast<const __m256i*>(permutations.index[m].data())));
        x = _mm256_blendv_epi8(x, _mm256_or_si256(_mm256_slli_epi32(x, 16), placed), need);
        words += 2 * static_cast<unsigned>(__builtin_popcount(m));
      }
    }
  }
  for (unsigned v = 0; v < kVectors; ++v)
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(state.x.data() + 8 * v), xs[v]);
  state.words = words;
  return row;
}

namespace {

// For each mask of lanes that give a word: where each of the words ends up
// when they are moved to the top of 8 in lane order (the lanes whose word
// is not kept fill the bottom).
struct TopPermutations {
  std::array<std::array<std::uint32_t, 8>, 256> index{};
  TopPermutations() {
    for (unsigned m = 0; m < 256; ++m) {
      const unsigned count = static_cast<unsigned>(__builtin_popcount(m));
      for (unsigned l = 0, k = 8 - count; l < 8; ++l)
        if (m >> l & 1) index[m][k++] = l;
    }
  }
};

}  // namespace

// One vector's step, as the scalar encoder's: a state at or above f · 2^20
// gives its low word; then x ← ⌊x / f⌋ · 2^12 + x mod f + s. The quotient
// is below 2^20 and is the division's in binary64 truncated: x and f are
// exact there, and a quotient's fraction, when not 0, is at least 1/f
// below the next integer, far more than the division's rounding.
__attribute__((target("avx2"))) std::uint16_t* encode_lane_chunks_avx2(const LaneSymbols& symbols,
                                                                       const std::uint8_t* contexts,
                                                                       const std::uint8_t* tokens, std::size_t chunks,
                                                                       std::array<std::uint32_t, kLaneCount>& x_lanes,
                                                                       std::uint16_t* w) {
  static const TopPermutations permutations;
  const int* const table = reinterpret_cast<const int*>(symbols.data());
  __m256i xs[kVectors];
  for (unsigned v = 0; v < kVectors; ++v)
    xs[v] = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(x_lanes.data() + 8 * v));
  const __m256i low16 = _mm256_set1_epi32(0xFFFF), sign = _mm256_set1_epi32(INT32_MIN), one = _mm256_set1_epi32(1),
                total = _mm256_set1_epi32(kTableTotal);
  const __m256d two31 = _mm256_set1_pd(2147483648.0);
  for (std::size_t c = chunks; c-- > 0;) {
    const std::size_t base = 32 * c;
    for (unsigned v = kVectors; v-- > 0;) {
      std::uint64_t k8, t8;
      std::memcpy(&k8, contexts + base + 8 * v, 8);
      std::memcpy(&t8, tokens + base + 8 * v, 8);
      const __m256i k = _mm256_cvtepu8_epi32(_mm_cvtsi64_si128(static_cast<long long>(k8)));
      const __m256i t = _mm256_cvtepu8_epi32(_mm_cvtsi64_si128(static_cast<long long>(t8)));
      const __m256i fs = _mm256_i32gather_epi32(table, _mm256_add_epi32(_mm256_slli_epi32(k, 5), t), 4);
      const __m256i f = _mm256_and_si256(fs, low16), s = _mm256_srli_epi32(fs, 16);
      __m256i x = xs[v];
      // x ≥ f · 2^20, unsigned: x > f · 2^20 − 1, which for f = 4096
      // wraps to 2^32 − 1, above every state (such a token never gives one).
      const __m256i limit = _mm256_sub_epi32(_mm256_slli_epi32(f, 20), one);
      const __m256i out = _mm256_cmpgt_epi32(_mm256_xor_si256(x, sign), _mm256_xor_si256(limit, sign));
      const unsigned m = static_cast<unsigned>(_mm256_movemask_ps(_mm256_castsi256_ps(out)));
      {  // stored whatever m, a branch the data would decide costing more
        const __m256i moved = _mm256_permutevar8x32_epi32(
            _mm256_and_si256(x, low16),
            _mm256_loadu_si256(reinterpret_cast<const __m256i*>(permutations.index[m].data())));
        const __m256i packed = _mm256_permute4x64_epi64(_mm256_packus_epi32(moved, moved), 0x08);
        _mm_storeu_si128(reinterpret_cast<__m128i*>(w - 8), _mm256_castsi256_si128(packed));
        w -= __builtin_popcount(m);
        x = _mm256_blendv_epi8(x, _mm256_srli_epi32(x, 16), out);
      }
      // x as binary64: its bits less 2^31 as a signed integer, plus 2^31.
      const __m256i xb = _mm256_xor_si256(x, sign);
      const __m256d x_low = _mm256_add_pd(_mm256_cvtepi32_pd(_mm256_castsi256_si128(xb)), two31);
      const __m256d x_high = _mm256_add_pd(_mm256_cvtepi32_pd(_mm256_extracti128_si256(xb, 1)), two31);
      const __m256d f_low = _mm256_cvtepi32_pd(_mm256_castsi256_si128(f));
      const __m256d f_high = _mm256_cvtepi32_pd(_mm256_extracti128_si256(f, 1));
      const __m256i q = _mm256_set_m128i(_mm256_cvttpd_epi32(_mm256_div_pd(x_high, f_high)),
                                         _mm256_cvttpd_epi32(_mm256_div_pd(x_low, f_low)));
      // q · 2^12 + (x − q · f) + s = x + q · (2^12 − f) + s.
      xs[v] = _mm256_add_epi32(_mm256_add_epi32(x, s), _mm256_mullo_epi32(q, _mm256_sub_epi32(total, f)));
    }
  }
  for (unsigned v = 0; v < kVectors; ++v)
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(x_lanes.data() + 8 * v), xs[v]);
  _mm256_zeroupper();
  return w;
}

bool lane_rows_avx2_available() { return use_avx2(); }
#else
std::size_t decode_lane_rows_avx2(const LaneSlotWords&, const BrickDims&, std::size_t row, LaneDecoderState&,
                                  std::uint8_t*, std::uint8_t*) {
  return row;
}
bool lane_rows_avx2_available() { return false; }
std::uint16_t* encode_lane_chunks_avx2(const LaneSymbols&, const std::uint8_t*, const std::uint8_t*, std::size_t,
                                       std::array<std::uint32_t, kLaneCount>&, std::uint16_t* w) {
  return w;
}
#endif

}  // namespace ivol::detail
