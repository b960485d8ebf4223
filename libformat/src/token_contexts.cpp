// Tokens, contexts and the bits below for codec 3's entropy coders 2 and 3
// (spec §7.2.1, §7.2.2).
#include "token_contexts.hpp"

#include <array>
#include <cstring>

#include "cpu_features.hpp"

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#include <immintrin.h>
#define IVOL_HAVE_AVX2_TOKENS 1
#endif

namespace ivol::detail {

namespace {

// A residual's token: 0 and 1 themselves, else 2b − 2 plus the bit after the
// leading one (b its bit length), 2 .. 31; with its bit length. For z ≥ 2,
// z as a binary32 (exact) has the exponent b − 1 and the bit after the
// leading one as its first mantissa bit, so the token is the float's bits
// >> 22, less 2·127.
void tokens_scalar(const std::uint16_t* z, std::size_t from, std::size_t n, std::uint8_t* tokens,
                   std::uint8_t* lengths) {
  for (std::size_t i = from; i < n; ++i) {
    const std::uint32_t v = z[i];
    const float f = static_cast<float>(static_cast<std::int32_t>(v));
    std::uint32_t bits;
    std::memcpy(&bits, &f, sizeof bits);
    const std::uint32_t t = v < 2 ? v : (bits >> 22) - 254;
    tokens[i] = static_cast<std::uint8_t>(t);
    lengths[i] = static_cast<std::uint8_t>(t < 2 ? t : (t >> 1) + 1);
  }
}

#ifdef IVOL_HAVE_AVX2_TOKENS
// The same, 16 residuals a step (GCC 12 does not vectorise the scalar
// loop: it was 6-8 % of a binary16 conversion's time).
__attribute__((target("avx2"))) inline __m256i tokens_of8(__m128i z16) {
  const __m256i v = _mm256_cvtepu16_epi32(z16);
  const __m256i from_float =
      _mm256_sub_epi32(_mm256_srli_epi32(_mm256_castps_si256(_mm256_cvtepi32_ps(v)), 22), _mm256_set1_epi32(254));
  return _mm256_blendv_epi8(from_float, v, _mm256_cmpgt_epi32(_mm256_set1_epi32(2), v));  // v itself where v < 2
}

__attribute__((target("avx2"))) void tokens_avx2(const std::uint16_t* z, std::size_t n, std::uint8_t* tokens,
                                                 std::uint8_t* lengths) {
  std::size_t i = 0;
  for (; i + 16 <= n; i += 16) {
    const __m256i v16 = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(z + i));
    const __m256i low = tokens_of8(_mm256_castsi256_si128(v16)), high = tokens_of8(_mm256_extracti128_si256(v16, 1));
    // 32 → 16 → 8 bits: packus within 128-bit halves, then the quadwords in order.
    const __m256i t16 = _mm256_permute4x64_epi64(_mm256_packus_epi32(low, high), 0xD8);
    const __m128i t8 = _mm_packus_epi16(_mm256_castsi256_si128(t16), _mm256_extracti128_si256(t16, 1));
    _mm_storeu_si128(reinterpret_cast<__m128i*>(tokens + i), t8);
    // Bit lengths: (t >> 1) + (t > 0), as token_bit_length.
    const __m128i half = _mm_and_si128(_mm_srli_epi16(t8, 1), _mm_set1_epi8(0x7F));
    _mm_storeu_si128(reinterpret_cast<__m128i*>(lengths + i), _mm_add_epi8(half, _mm_min_epu8(t8, _mm_set1_epi8(1))));
  }
  _mm256_zeroupper();  // as in take_avx2
  tokens_scalar(z, i, n, tokens, lengths);
}
#endif

}  // namespace

// The contexts of a row of voxels from the bit lengths of the tokens in the
// row before it along y (`up`) and along z (`back`), 0 outside the brick:
// s = 2·up(x) + back(x) + up(x − 1) + up(x + 1), context min(11, (s + 2) / 5).
// Only earlier rows count, not the voxel before along x: the contexts of a
// whole row are known before its first token is decoded, so the decoder's
// loop carries only the rANS states from voxel to voxel (and these contexts
// compressed better than ones with the x neighbour, bench/RESULTS.md).
//
// `padded` holds nx + 2 bytes, 0 at both ends: the up row is copied between
// them, so that the loop has no edge cases and vectorises (its edge cases
// took a tenth of either coder's time).
// Not inlined: GCC 12 vectorises it alone, not inside the walk's loops.
#if defined(__GNUC__)
__attribute__((noinline))
#endif
void row_contexts(const std::uint8_t* up, const std::uint8_t* __restrict back, std::uint32_t nx,
                  std::uint8_t* __restrict padded, std::uint8_t* __restrict contexts) {
  std::memcpy(padded + 1, up, nx);
  for (std::size_t x = 0; x < nx; ++x) {
    const auto s = static_cast<std::uint16_t>(2 * padded[x + 1] + back[x] + padded[x] + padded[x + 2] + 2);
    const auto c = static_cast<std::uint16_t>(s / 5);
    contexts[x] = static_cast<std::uint8_t>(c < kTokenContexts - 1 ? c : kTokenContexts - 1);
  }
}

namespace {

// A residual's bits above the ones below its token: the token itself for
// lengths 0 .. 2, else its two leading bits (1 and the token's low bit)
// shifted over the e bits below.
constexpr std::uint32_t lead_of(unsigned t, unsigned e) { return t < 2 ? t : (2u | (t & 1u)) << e; }

// Voxels [from, to), their bits starting at bit `position` of the stream.
// A voxel reads the 8 bytes from its first bit's byte (fewer at the
// stream's end): at most 7 + 14 bits of them count.
std::uint64_t take_scalar(const std::uint8_t* tokens, std::size_t from, std::size_t to, const std::uint8_t* bits,
                          std::size_t size, std::uint64_t position, std::uint16_t* residuals) {
  for (std::size_t i = from; i < to; ++i) {
    const unsigned t = tokens[i], e = bits_below_token(t);
    const std::size_t byte = static_cast<std::size_t>(position >> 3);
    std::uint64_t word = 0;
    if (byte + 8 <= size) {
      unsigned char b[8];
      std::memcpy(b, bits + byte, 8);
      for (int k = 0; k < 8; ++k) word |= std::uint64_t{b[k]} << (8 * k);
    } else {
      for (std::size_t k = 0; byte + k < size && k < 8; ++k) word |= std::uint64_t{bits[byte + k]} << (8 * k);
    }
    const auto below = static_cast<std::uint32_t>(word >> (position & 7)) & ((1u << e) - 1);
    residuals[i] = static_cast<std::uint16_t>(lead_of(t, e) | below);
    position += e;
  }
  return position;
}

// The bits waiting to be written, fewer than 8 between voxels; each step
// stores 8 bytes and moves on by the whole ones among them.
struct BitSink {
  std::uint8_t* to;
  std::uint64_t pending = 0;
  unsigned count = 0;
  void put(std::uint64_t bits, unsigned n) {  // n ≤ 56
    pending |= bits << count;
    count += n;
    for (int k = 0; k < 8; ++k) to[k] = static_cast<std::uint8_t>(pending >> (8 * k));
    to += count >> 3;
    pending >>= count & ~7u;  // count ≤ 63
    count &= 7;
  }
  std::uint8_t* end() const { return to + (count != 0); }
};

std::uint8_t* put_scalar(const std::uint8_t* tokens, const std::uint16_t* residuals, std::size_t from, std::size_t to,
                         BitSink sink) {
  for (std::size_t i = from; i < to; ++i) {
    const unsigned e = bits_below_token(tokens[i]);
    sink.put(residuals[i] & ((1u << e) - 1), e);
  }
  return sink.end();
}

#ifdef IVOL_HAVE_AVX2_TOKENS
// Eight voxels a step: their bits joined in pairs, then fours, in the
// vector (each four at most 56 bits), the two fours then written.
__attribute__((target("avx2"))) std::uint8_t* put_avx2(const std::uint8_t* tokens, const std::uint16_t* residuals,
                                                       std::size_t n, std::uint8_t* to) {
  const __m256i one = _mm256_set1_epi32(1), zero = _mm256_setzero_si256(), low32 = _mm256_set1_epi64x(0xFFFFFFFF);
  BitSink sink{to};
  std::size_t i = 0;
  for (; i + 8 <= n; i += 8) {
    std::uint64_t eight;
    std::memcpy(&eight, tokens + i, 8);
    const __m256i t = _mm256_cvtepu8_epi32(_mm_cvtsi64_si128(static_cast<long long>(eight)));
    const __m256i e = _mm256_max_epi32(_mm256_sub_epi32(_mm256_srli_epi32(t, 1), one), zero);
    const __m256i r = _mm256_cvtepu16_epi32(_mm_loadu_si128(reinterpret_cast<const __m128i*>(residuals + i)));
    const __m256i v = _mm256_and_si256(r, _mm256_sub_epi32(_mm256_sllv_epi32(one, e), one));
    // Pairs in 64-bit lanes: the low voxel's bits, the high one's above them.
    const __m256i e_low = _mm256_and_si256(e, low32);
    const __m256i pair =
        _mm256_or_si256(_mm256_and_si256(v, low32), _mm256_sllv_epi64(_mm256_srli_epi64(v, 32), e_low));
    const __m256i pair_bits = _mm256_add_epi64(e_low, _mm256_srli_epi64(e, 32));
    // Fours in the low 64 bits of each 128-bit half.
    const __m256i four = _mm256_or_si256(pair, _mm256_sllv_epi64(_mm256_srli_si256(pair, 8), pair_bits));
    const __m256i four_bits = _mm256_add_epi64(pair_bits, _mm256_srli_si256(pair_bits, 8));
    sink.put(static_cast<std::uint64_t>(_mm256_extract_epi64(four, 0)),
             static_cast<unsigned>(_mm256_extract_epi64(four_bits, 0)));
    sink.put(static_cast<std::uint64_t>(_mm256_extract_epi64(four, 2)),
             static_cast<unsigned>(_mm256_extract_epi64(four_bits, 2)));
  }
  _mm256_zeroupper();  // as in take_avx2
  return put_scalar(tokens, residuals, i, n, sink);
}

// The exclusive prefix sum of eight 32-bit lanes, and their total.
__attribute__((target("avx2"))) inline __m256i exclusive_sum(__m256i e, std::uint32_t& total) {
  __m256i s = _mm256_add_epi32(e, _mm256_slli_si256(e, 4));
  s = _mm256_add_epi32(s, _mm256_slli_si256(s, 8));
  // The low half's total into every lane of the high half.
  s = _mm256_add_epi32(s, _mm256_shuffle_epi32(_mm256_permute2x128_si256(s, s, 0x08), 0xFF));
  total = static_cast<std::uint32_t>(_mm256_extract_epi32(s, 7));
  return _mm256_sub_epi32(s, e);
}

// Eight voxels a step while their bytes surely lie in the stream (8 × 14
// bits and a 4-byte load from the last one's byte: 17 bytes from the
// first), then the scalar loop.
__attribute__((target("avx2"))) void take_avx2(const std::uint8_t* tokens, std::size_t n, const std::uint8_t* bits,
                                               std::size_t size, std::uint16_t* residuals) {
  const __m256i one = _mm256_set1_epi32(1), two = _mm256_set1_epi32(2), seven = _mm256_set1_epi32(7),
                zero = _mm256_setzero_si256();
  std::uint64_t position = 0;
  std::size_t i = 0;
  for (; i + 8 <= n && (position >> 3) + 17 <= size; i += 8) {
    std::uint64_t eight;
    std::memcpy(&eight, tokens + i, 8);
    const __m256i t = _mm256_cvtepu8_epi32(_mm_cvtsi64_si128(static_cast<long long>(eight)));
    const __m256i e = _mm256_max_epi32(_mm256_sub_epi32(_mm256_srli_epi32(t, 1), one), zero);
    // (t & 1) | (2 if t ≥ 2), shifted over e: lead_of without a branch.
    const __m256i lead = _mm256_sllv_epi32(
        _mm256_or_si256(_mm256_and_si256(t, one), _mm256_and_si256(_mm256_min_epu32(t, two), two)), e);
    std::uint32_t total = 0;
    const __m256i at = _mm256_add_epi32(_mm256_set1_epi32(static_cast<int>(position & 7)), exclusive_sum(e, total));
    const __m256i words =
        _mm256_i32gather_epi32(reinterpret_cast<const int*>(bits + (position >> 3)), _mm256_srli_epi32(at, 3), 1);
    const __m256i mask = _mm256_sub_epi32(_mm256_sllv_epi32(one, e), one);
    const __m256i below = _mm256_and_si256(_mm256_srlv_epi32(words, _mm256_and_si256(at, seven)), mask);
    const __m256i values = _mm256_or_si256(lead, below);  // each below 2^16
    // 32 → 16 bits: packus works within the 128-bit halves; their low
    // quadwords then go together.
    const __m256i packed = _mm256_permute4x64_epi64(_mm256_packus_epi32(values, values), 0x08);
    _mm_storeu_si128(reinterpret_cast<__m128i*>(residuals + i), _mm256_castsi256_si128(packed));
    position += total;
  }
  // GCC 12 leaves the upper halves of the vector registers dirty here (no
  // vzeroupper before the scalar loop or the return): the SSE code that
  // runs next, the predictor's, then ran at two thirds of its speed.
  _mm256_zeroupper();
  take_scalar(tokens, i, n, bits, size, position, residuals);
}

#endif

}  // namespace

void tokens_of(const std::uint16_t* z, std::size_t n, std::uint8_t* tokens, std::uint8_t* lengths) {
#ifdef IVOL_HAVE_AVX2_TOKENS
  if (use_avx2()) return tokens_avx2(z, n, tokens, lengths);
#endif
  tokens_scalar(z, 0, n, tokens, lengths);
}

namespace {

// ceil(2^64 / f) for f from 2 to 2^12, made by the compiler.
constexpr std::array<std::uint64_t, kTableTotal + 1> kReciprocals = [] {
  std::array<std::uint64_t, kTableTotal + 1> of{};
  for (std::uint64_t f = 2; f <= kTableTotal; ++f) of[f] = ~std::uint64_t{0} / f + 1;
  return of;
}();

}  // namespace

std::uint32_t divide_by_frequency(std::uint32_t x, std::uint32_t f) {
  __extension__ using Wide = unsigned __int128;
  return f > 1 ? static_cast<std::uint32_t>((static_cast<Wide>(x) * kReciprocals[f]) >> 64) : x;
}

std::uint64_t count_bits_below(const std::uint8_t* tokens, std::size_t n) {
  // In 32-bit sums of at most 2^16 tokens (14 bits each): a loop that
  // vectorises.
  std::uint64_t total = 0;
  for (std::size_t from = 0; from < n; from += 1u << 16) {
    const std::size_t to = n - from < (1u << 16) ? n : from + (1u << 16);
    std::uint32_t sum = 0;
    for (std::size_t i = from; i < to; ++i) sum += bits_below_token(tokens[i]);
    total += sum;
  }
  return total;
}

std::uint8_t* put_bits_below(const std::uint8_t* tokens, const std::uint16_t* residuals, std::size_t n,
                             std::uint8_t* to) {
#ifdef IVOL_HAVE_AVX2_TOKENS
  if (use_avx2()) return put_avx2(tokens, residuals, n, to);
#endif
  return put_scalar(tokens, residuals, 0, n, BitSink{to});
}

void take_bits_below(const std::uint8_t* tokens, std::size_t n, const std::uint8_t* bits, std::size_t size,
                     std::uint16_t* residuals) {
#ifdef IVOL_HAVE_AVX2_TOKENS
  if (use_avx2()) return take_avx2(tokens, n, bits, size, residuals);
#endif
  take_scalar(tokens, 0, n, bits, size, 0, residuals);
}

}  // namespace ivol::detail
