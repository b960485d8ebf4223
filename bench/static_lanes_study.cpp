// Whether a static-table coder of codec 3's tokens decodes at issue 22's
// 300 MB/s a core (item 4), against coder 2, on the residuals of a real
// volume: a prototype, not a format.
//
//   static_lanes_study VOLUME.f32 N [BRICK_LOG2 [LANES]]
//
// VOLUME.f32: N^3 float32, x fastest (as codec_bench reads it). Each brick's
// codec 3 residuals (read from a coder 1 payload, as entropy_study does) are
// coded two ways, both with coder 2's tokens, bits below and contexts from
// the rows before (spec §7.2.1):
//   coder 2   the library's (adaptive counts, two rANS states);
//   static    each context's counts over the brick normalised to 2^12
//             (bench/RESULTS.md, "What a static-table coder would cost"),
//             LANES rANS states (default 8) taking the voxels in turn, so
//             that LANES independent chains run side by side; the tables
//             are counted as entropy_study's "static 12" counts them, not
//             written; decoded from three tables (a token a slot, and each
//             token's frequency and start) and from one word a slot
//             ("packed", made for each brick by the decoder);
//   vector    the same tables, 8 or 16 states renormalised by 16-bit words,
//             decoded with AVX2 where the CPU has it (one or two vectors of
//             states, a gather of slot words each; the bits below in scalar
//             code);
//   coder 3   what these prototypes led to: the library's entropy coder 3
//             (spec §7.2.2: stored tables, 32 states, the bits below taken
//             after the tokens), its bytes, decoding and encoding against
//             coder 2's encoder (printed to stderr).
// Both decoders are checked against the residuals; printed: bytes and
// decoding MB/s of 16-bit values per second of the thread's CPU time (best
// of five passes over every brick), for binary16 and uint16.
#include <zstd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <stdexcept>
#include <string>
#include <vector>

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#endif

#include "../libformat/src/residual_lanes.hpp"   // coder 3, internal to libformat
#include "../libformat/src/residual_tokens.hpp"  // coder 2, internal to libformat
#include "ivol/predicted_codec.hpp"
#include "sixteen_bit_volume.hpp"

namespace {

constexpr unsigned kContexts = 12, kTokens = 32, kPrecision = 12, kTotal = 1u << kPrecision;
constexpr std::uint32_t kStateLow = 1u << 23;

double cpu_now() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

unsigned bit_length(unsigned z) { return z == 0 ? 0 : 32 - static_cast<unsigned>(__builtin_clz(z)); }
unsigned token_of(unsigned z) {
  const unsigned b = bit_length(z);
  return z < 2 ? z : 2 * b - 2 + ((z >> (b - 2)) & 1);
}
unsigned token_length(unsigned t) { return t < 2 ? t : (t >> 1) + 1; }

// Coder 2's contexts of a row from the bit lengths of the rows before.
void row_contexts(const std::uint8_t* up, const std::uint8_t* back, std::uint32_t nx, std::uint8_t* padded,
                  std::uint8_t* contexts) {
  std::memcpy(padded + 1, up, nx);
  for (std::uint32_t x = 0; x < nx; ++x) {
    const unsigned s = 2u * padded[x + 1] + back[x] + padded[x] + padded[x + 2] + 2;
    contexts[x] = static_cast<std::uint8_t>(std::min(kContexts - 1, s / 5));
  }
}

template <class Visit>
void walk_rows(const ivol::BrickDims& d, std::uint8_t* lengths, Visit&& visit) {
  const std::size_t sy = d[0], sz = std::size_t{d[0]} * d[1];
  std::vector<std::uint8_t> zeros(d[0], 0), contexts(d[0]), padded(d[0] + 2, 0);
  std::size_t i = 0;
  for (std::uint32_t z = 0; z < d[2]; ++z)
    for (std::uint32_t y = 0; y < d[1]; ++y, i += d[0]) {
      row_contexts(y ? lengths + i - sy : zeros.data(), z ? lengths + i - sz : zeros.data(), d[0], padded.data(),
                   contexts.data());
      visit(i, contexts.data());
    }
}

struct Tables {
  std::array<std::array<std::uint16_t, kTokens>, kContexts> freq{}, start{};
  std::array<std::array<std::uint8_t, kTotal>, kContexts> token_at{};
  double table_bits = 0;
};

// The same tables as one word a slot, made by the decoder for each brick:
// token | freq << 5 | (slot − start) << 18, so that a voxel's step is one
// load (192 KiB for 12 contexts: out of the first-level cache).
struct PackedTables {
  std::vector<std::uint32_t> slots;  // [context][slot]
  void make(const Tables& tb) {
    slots.resize(std::size_t{kContexts} * kTotal);
    for (unsigned c = 0; c < kContexts; ++c)
      for (unsigned t = 0; t < kTokens; ++t)
        for (unsigned k = 0; k < tb.freq[c][t]; ++k)
          slots[c * kTotal + tb.start[c][t] + k] = t | std::uint32_t{tb.freq[c][t]} << 5 | k << 18;
  }
};

struct StaticCoded {
  std::vector<std::uint8_t> rans, below;
  // The same tokens for 8 states renormalised by 16-bit words (states in
  // [2^16, 2^32)), for a decoder whose states are the lanes of one vector.
  std::vector<std::uint16_t> words, words16;  // 8 states; 16 states (two vectors)
  std::array<std::uint32_t, 8> word_states{};
  std::array<std::uint32_t, 16> word_states16{};
  Tables tables;
  std::size_t bytes() const {
    return rans.size() + below.size() + static_cast<std::size_t>(std::ceil(tables.table_bits / 8)) +
           ivol::kPredictedHeaderSize;
  }
};

StaticCoded encode_static(const std::vector<std::uint16_t>& z, const ivol::BrickDims& d, unsigned lanes) {
  const std::size_t n = z.size();
  std::vector<std::uint8_t> lengths(n), ctx(n);
  for (std::size_t i = 0; i < n; ++i) lengths[i] = static_cast<std::uint8_t>(bit_length(z[i]));
  walk_rows(d, lengths.data(), [&](std::size_t row, const std::uint8_t* c) { std::memcpy(ctx.data() + row, c, d[0]); });
  StaticCoded out;
  Tables& tb = out.tables;
  std::array<std::array<std::uint32_t, kTokens>, kContexts> counts{};
  for (std::size_t i = 0; i < n; ++i) ++counts[ctx[i]][token_of(z[i])];
  for (unsigned c = 0; c < kContexts; ++c) {
    std::uint64_t total = 0;
    for (unsigned t = 0; t < kTokens; ++t) total += counts[c][t];
    tb.table_bits += 1;
    if (total == 0) {  // unused: any valid table
      for (unsigned t = 0; t < kTokens; ++t) tb.freq[c][t] = kTotal / kTokens;
    } else {
      tb.table_bits += kTokens;
      std::int64_t sum = 0;
      unsigned largest = 0;
      for (unsigned t = 0; t < kTokens; ++t) {
        if (!counts[c][t]) continue;
        const auto f = std::max<std::uint32_t>(
            1, static_cast<std::uint32_t>(double{kTotal} * counts[c][t] / static_cast<double>(total)));
        tb.freq[c][t] = static_cast<std::uint16_t>(f);
        sum += f;
        if (counts[c][t] > counts[c][largest]) largest = t;
      }
      tb.freq[c][largest] = static_cast<std::uint16_t>(tb.freq[c][largest] + static_cast<std::int64_t>(kTotal) - sum);
      for (unsigned t = 0; t < kTokens; ++t)
        if (tb.freq[c][t]) tb.table_bits += 2 * std::floor(std::log2(tb.freq[c][t])) + 1;
    }
    std::uint16_t s = 0;
    for (unsigned t = 0; t < kTokens; ++t) {
      tb.start[c][t] = s;
      std::memset(tb.token_at[c].data() + s, static_cast<int>(t), tb.freq[c][t]);
      s = static_cast<std::uint16_t>(s + tb.freq[c][t]);
    }
  }
  // The bits below, LSB first.
  std::uint64_t pending = 0;
  unsigned pending_bits = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const unsigned b = bit_length(z[i]), e = b > 2 ? b - 2 : 0;
    pending |= std::uint64_t{z[i] & ((1u << e) - 1)} << pending_bits;
    for (pending_bits += e; pending_bits >= 8; pending_bits -= 8, pending >>= 8)
      out.below.push_back(static_cast<std::uint8_t>(pending));
  }
  if (pending_bits) out.below.push_back(static_cast<std::uint8_t>(pending));
  for (int k = 0; k < 8; ++k) out.below.push_back(0);  // the decoder reads 8 bytes at a time
  // rANS from the back, voxel i on state i mod lanes.
  std::vector<std::uint8_t> back;
  std::vector<std::uint32_t> state(lanes, kStateLow);
  for (std::size_t i = n; i-- > 0;) {
    const unsigned c = ctx[i], t = token_of(z[i]);
    const std::uint32_t f = tb.freq[c][t], st = tb.start[c][t];
    std::uint32_t& x = state[i % lanes];
    const std::uint32_t x_max = ((kStateLow >> kPrecision) << 8) * f;
    while (x >= x_max) back.push_back(static_cast<std::uint8_t>(x)), x >>= 8;
    x = ((x / f) << kPrecision) + x % f + st;
  }
  for (unsigned l = lanes; l-- > 0;)
    for (int k = 3; k >= 0; --k) back.push_back(static_cast<std::uint8_t>(state[l] >> (8 * k)));
  out.rans.assign(back.rbegin(), back.rend());
  for (int k = 0; k < 4; ++k) out.rans.push_back(0);  // the decoder reads two bytes ahead
  // 8 or 16 states, 16-bit words.
  auto word_stream = [&](auto& states, std::vector<std::uint16_t>& words) {
    std::vector<std::uint16_t> words_back;
    const std::size_t count = states.size();
    states.fill(1u << 16);
    for (std::size_t i = n; i-- > 0;) {
      const unsigned c = ctx[i], t = token_of(z[i]);
      const std::uint32_t f = tb.freq[c][t], st = tb.start[c][t];
      std::uint32_t& x = states[i % count];
      if (std::uint64_t{x} >= (std::uint64_t{f} << 20)) words_back.push_back(static_cast<std::uint16_t>(x)), x >>= 16;
      x = ((x / f) << kPrecision) + x % f + st;
    }
    words.assign(words_back.rbegin(), words_back.rend());
    for (int k = 0; k < 16; ++k) words.push_back(0);  // the decoder loads 8 words at a time
  };
  word_stream(out.word_states, out.words);
  word_stream(out.word_states16, out.words16);
  return out;
}

// The bits below the tokens, LSB first: `bits` holds the next `count` of
// them, `q` the first byte not yet in it (refills without bounds checks:
// the encoder pads the stream by 8 bytes).
struct BitsBelow {
  const std::uint8_t* q;
  std::uint64_t bits = 0;
  unsigned count = 0;
  // Tops up to 56 bits or more; bits above `count` may come in too, and a
  // later refill ORs the same bits over them.
  void refill() {
    std::uint64_t word;
    std::memcpy(&word, q, 8);
    bits |= word << count;
    q += (63 - count) >> 3;
    count |= 56;
  }
  // The residuals and bit lengths of `lanes` voxels from their tokens.
  void take(const std::uint32_t* t, unsigned lanes, std::uint16_t* z, std::uint8_t* lengths) {
    refill();
    for (unsigned l = 0; l < lanes; ++l) {
      const unsigned b = token_length(t[l]), e = b > 2 ? b - 2 : 0;
      const unsigned lead = b > 2 ? (2 + (t[l] & 1)) << e : t[l];
      z[l] = static_cast<std::uint16_t>(lead | (bits & ((1u << e) - 1)));
      bits >>= e;
      count -= e;
      lengths[l] = static_cast<std::uint8_t>(b);
      if (count < 14 && l + 1 < lanes) refill();  // at most 14 bits a voxel
    }
  }
};

template <unsigned Lanes, bool Packed>
void decode_static(const StaticCoded& in, const ivol::BrickDims& d, std::uint16_t* z,
                   std::vector<std::uint8_t>& lengths, PackedTables& packed) {
  const Tables& tb = in.tables;
  if constexpr (Packed) packed.make(tb);
  const std::uint32_t* slots = packed.slots.data();
  const std::uint8_t* p = in.rans.data();
  std::uint32_t x[Lanes];
  for (unsigned l = 0; l < Lanes; ++l, p += 4)
    x[l] = std::uint32_t{p[0]} | std::uint32_t{p[1]} << 8 | std::uint32_t{p[2]} << 16 | std::uint32_t{p[3]} << 24;
  BitsBelow below{in.below.data()};
  const std::uint32_t nx = d[0];
  walk_rows(d, lengths.data(), [&](std::size_t row, const std::uint8_t* contexts) {
    for (std::uint32_t x0 = 0; x0 < nx; x0 += Lanes) {
      std::uint32_t t[Lanes];
      for (unsigned l = 0; l < Lanes; ++l) {  // the lanes' chains, side by side
        const unsigned c = contexts[x0 + l];
        const std::uint32_t slot = x[l] & (kTotal - 1);
        if constexpr (Packed) {
          const std::uint32_t w = slots[c * kTotal + slot];
          t[l] = w & 31;
          x[l] = ((w >> 5) & 0x1FFF) * (x[l] >> kPrecision) + (w >> 18);
        } else {
          t[l] = tb.token_at[c][slot];
          x[l] = tb.freq[c][t[l]] * (x[l] >> kPrecision) + slot - tb.start[c][t[l]];
        }
      }
      for (unsigned l = 0; l < Lanes; ++l) {  // renormalised in the encoder's order
        const unsigned k = static_cast<unsigned>(x[l] < kStateLow) + static_cast<unsigned>(x[l] < (kStateLow >> 8));
        const std::uint32_t next = std::uint32_t{p[0]} << 8 | p[1];
        x[l] = x[l] << (8 * k) | next >> (16 - 8 * k);
        p += k;
      }
      below.take(t, Lanes, z + row + x0, lengths.data() + row + x0);
    }
  });
}

#if defined(__x86_64__) && defined(__GNUC__)
// The 8 states as the lanes of one AVX2 vector: a gather of their slot
// words, a multiply, and the renormalisation of the lanes below 2^16 from
// the next words of the stream, moved into their lanes by a permutation
// chosen by the mask. The bits below a token are taken as the scalar
// decoders take them.
struct Permutations {
  std::array<std::array<std::uint32_t, 8>, 256> index{};
  Permutations() {
    for (unsigned m = 0; m < 256; ++m)
      for (unsigned l = 0, k = 0; l < 8; ++l)
        if (m >> l & 1) index[m][l] = k++;
  }
};

// Vectors: 1 (8 states) or 2 (16 states, two gathers in flight).
template <unsigned Vectors>
__attribute__((target("avx2"))) void decode_avx2(const StaticCoded& in, const ivol::BrickDims& d, std::uint16_t* z,
                                                 std::vector<std::uint8_t>& lengths, PackedTables& packed) {
  static const Permutations permutations;
  constexpr unsigned kLanes = 8 * Vectors;
  packed.make(in.tables);
  const int* slots = reinterpret_cast<const int*>(packed.slots.data());
  __m256i xs[Vectors];
  for (unsigned v = 0; v < Vectors; ++v)
    xs[v] = _mm256_loadu_si256(
        reinterpret_cast<const __m256i*>((Vectors == 1 ? in.word_states.data() : in.word_states16.data()) + 8 * v));
  const std::uint16_t* p = Vectors == 1 ? in.words.data() : in.words16.data();
  BitsBelow below{in.below.data()};
  const std::uint32_t nx = d[0];
  const __m256i low12 = _mm256_set1_epi32(kTotal - 1), low5 = _mm256_set1_epi32(31),
                freq_mask = _mm256_set1_epi32(0x1FFF), zero = _mm256_setzero_si256();
  alignas(32) std::uint32_t t[kLanes];
  // walk_rows written out: a lambda would not take this function's target.
  const std::size_t sy = d[0], sz = std::size_t{d[0]} * d[1];
  std::vector<std::uint8_t> zeros(d[0], 0), row_ctx(d[0]), padded(d[0] + 2, 0);
  std::size_t row = 0;
  for (std::uint32_t zz = 0; zz < d[2]; ++zz)
    for (std::uint32_t y = 0; y < d[1]; ++y, row += d[0]) {
      row_contexts(y ? lengths.data() + row - sy : zeros.data(), zz ? lengths.data() + row - sz : zeros.data(), d[0],
                   padded.data(), row_ctx.data());
      const std::uint8_t* contexts = row_ctx.data();
      for (std::uint32_t x0 = 0; x0 < nx; x0 += kLanes) {
        __m256i w[Vectors];
        for (unsigned v = 0; v < Vectors; ++v) {  // the gathers, both in flight
          std::uint64_t c8;
          std::memcpy(&c8, contexts + x0 + 8 * v, 8);
          const __m256i ctx = _mm256_cvtepu8_epi32(_mm_cvtsi64_si128(static_cast<long long>(c8)));
          const __m256i slot = _mm256_and_si256(xs[v], low12);
          w[v] = _mm256_i32gather_epi32(slots, _mm256_add_epi32(_mm256_slli_epi32(ctx, kPrecision), slot), 4);
        }
        for (unsigned v = 0; v < Vectors; ++v) {
          __m256i& x = xs[v];
          _mm256_store_si256(reinterpret_cast<__m256i*>(t + 8 * v), _mm256_and_si256(w[v], low5));
          x = _mm256_add_epi32(_mm256_mullo_epi32(_mm256_and_si256(_mm256_srli_epi32(w[v], 5), freq_mask),
                                                  _mm256_srli_epi32(x, kPrecision)),
                               _mm256_srli_epi32(w[v], 18));
          const __m256i need = _mm256_cmpeq_epi32(_mm256_srli_epi32(x, 16), zero);
          const unsigned m = static_cast<unsigned>(_mm256_movemask_ps(_mm256_castsi256_ps(need)));
          const __m256i next = _mm256_cvtepu16_epi32(_mm_loadu_si128(reinterpret_cast<const __m128i*>(p)));
          const __m256i placed = _mm256_permutevar8x32_epi32(
              next, _mm256_loadu_si256(reinterpret_cast<const __m256i*>(permutations.index[m].data())));
          x = _mm256_blendv_epi8(x, _mm256_or_si256(_mm256_slli_epi32(x, 16), placed), need);
          p += __builtin_popcount(m);
        }
        below.take(t, kLanes, z + row + x0, lengths.data() + row + x0);
      }
    }
}
#endif

struct Brick {
  ivol::BrickDims dims;
  std::vector<std::uint16_t> residuals;
  std::vector<std::uint8_t> coder2, coder3;
  StaticCoded coded;
};

void run(const char* label, const std::vector<std::uint16_t>& volume, std::uint32_t n, unsigned log2,
         ivol::ValueEncoding encoding, unsigned lanes) {
  const std::uint32_t edge = 1u << log2;
  std::vector<Brick> bricks;
  std::size_t coder2_bytes = 0, static_bytes = 0;
  for (std::uint32_t z0 = 0; z0 < n; z0 += edge)
    for (std::uint32_t y0 = 0; y0 < n; y0 += edge)
      for (std::uint32_t x0 = 0; x0 < n; x0 += edge) {
        Brick b;
        b.dims = {std::min(edge, n - x0), std::min(edge, n - y0), std::min(edge, n - z0)};
        if (b.dims[0] % lanes) throw std::runtime_error("static_lanes_study: a row is not a multiple of LANES");
        std::vector<std::uint16_t> values;
        for (std::uint32_t z = z0; z < z0 + b.dims[2]; ++z)
          for (std::uint32_t y = y0; y < y0 + b.dims[1]; ++y)
            for (std::uint32_t x = x0; x < x0 + b.dims[0]; ++x)
              values.push_back(volume[(std::size_t{z} * n + y) * n + x]);
        ivol::PredictedOptions planes_only;
        planes_only.entropy = ivol::PredictedOptions::Entropy::ZstdPlanes;
        const auto payload = ivol::encode_predicted(values.data(), b.dims, encoding, planes_only);
        std::vector<std::uint8_t> planes(2 * values.size());
        if (ZSTD_decompress(planes.data(), planes.size(), payload.data() + ivol::kPredictedHeaderSize,
                            payload.size() - ivol::kPredictedHeaderSize) != planes.size())
          throw std::runtime_error("static_lanes_study: a codec 3 frame did not decode");
        b.residuals.resize(values.size());
        for (std::size_t i = 0; i < values.size(); ++i)
          b.residuals[i] = static_cast<std::uint16_t>(planes[i] | planes[values.size() + i] << 8);
        if (!ivol::detail::encode_residual_tokens(b.residuals.data(), b.dims, ~std::size_t{0}, b.coder2))
          throw std::runtime_error("static_lanes_study: coder 2 refused a brick");
        b.coded = encode_static(b.residuals, b.dims, lanes);
        if (!ivol::detail::encode_residual_lanes(b.residuals.data(), b.dims, ~std::size_t{0}, b.coder3))
          throw std::runtime_error("static_lanes_study: coder 3 refused a brick");
        coder2_bytes += b.coder2.size() + ivol::kPredictedHeaderSize;
        static_bytes += b.coded.bytes();
        bricks.push_back(std::move(b));
      }
  const double mb = 2.0 * n * n * n / 1e6;
  std::vector<std::uint16_t> out(std::size_t{edge} * edge * edge);
  std::vector<std::uint8_t> lengths(out.size());
  PackedTables packed;
  double best2 = 1e30, best_static = 1e30, best_packed = 1e30, best_avx2 = 1e30, best_avx2_16 = 1e30;
  std::size_t word_bytes = 0, word_bytes16 = 0;
  for (const Brick& b : bricks) {
    const std::size_t rest = b.coded.below.size() - 8 +
                             static_cast<std::size_t>(std::ceil(b.coded.tables.table_bits / 8)) +
                             ivol::kPredictedHeaderSize;
    word_bytes += 2 * (b.coded.words.size() - 16) + 4 * 8 + rest;
    word_bytes16 += 2 * (b.coded.words16.size() - 16) + 4 * 16 + rest;
  }
#if defined(__x86_64__) && defined(__GNUC__)
  const bool avx2 = __builtin_cpu_supports("avx2");
#else
  const bool avx2 = false;
#endif
  auto decode = [&](const Brick& b, bool pack) {
    switch (lanes * 2 + pack) {
      case 8:
        return decode_static<4, false>(b.coded, b.dims, out.data(), lengths, packed);
      case 9:
        return decode_static<4, true>(b.coded, b.dims, out.data(), lengths, packed);
      case 16:
        return decode_static<8, false>(b.coded, b.dims, out.data(), lengths, packed);
      case 17:
        return decode_static<8, true>(b.coded, b.dims, out.data(), lengths, packed);
      case 32:
        return decode_static<16, false>(b.coded, b.dims, out.data(), lengths, packed);
      case 33:
        return decode_static<16, true>(b.coded, b.dims, out.data(), lengths, packed);
      default:
        throw std::runtime_error("static_lanes_study: LANES is 4, 8 or 16");
    }
  };
  for (int pass = 0; pass < 5; ++pass) {
    double t = cpu_now();
    for (const Brick& b : bricks) {
      ivol::detail::decode_residual_tokens(b.coder2.data(), b.coder2.size(), b.dims, out.data());
      if (pass == 0 && !std::equal(b.residuals.begin(), b.residuals.end(), out.begin()))
        throw std::runtime_error("static_lanes_study: coder 2 did not round-trip");
    }
    best2 = std::min(best2, cpu_now() - t);
    t = cpu_now();
    for (const bool pack : {false, true}) {
      t = cpu_now();
      for (const Brick& b : bricks) {
        decode(b, pack);
        if (pass == 0 && !std::equal(b.residuals.begin(), b.residuals.end(), out.begin()))
          throw std::runtime_error("static_lanes_study: the static coder did not round-trip");
      }
      double& best = pack ? best_packed : best_static;
      best = std::min(best, cpu_now() - t);
    }
#if defined(__x86_64__) && defined(__GNUC__)
    if (avx2)
      for (const unsigned vectors : {1u, 2u}) {
        if (vectors == 2 && bricks.front().dims[0] % 16) continue;
        t = cpu_now();
        for (const Brick& b : bricks) {
          if (vectors == 1)
            decode_avx2<1>(b.coded, b.dims, out.data(), lengths, packed);
          else
            decode_avx2<2>(b.coded, b.dims, out.data(), lengths, packed);
          if (pass == 0 && !std::equal(b.residuals.begin(), b.residuals.end(), out.begin()))
            throw std::runtime_error("static_lanes_study: the AVX2 decoder did not round-trip");
        }
        double& best = vectors == 1 ? best_avx2 : best_avx2_16;
        best = std::min(best, cpu_now() - t);
      }
#endif
  }
  // The library's coder 3 on the same residuals, and both coders' encoders.
  std::size_t coder3_bytes = 0;
  for (const Brick& b : bricks) coder3_bytes += b.coder3.size() + ivol::kPredictedHeaderSize;
  double best3 = 1e30, encode2 = 1e30, encode3 = 1e30;
  std::vector<std::uint8_t> sink;
  for (int pass = 0; pass < 5; ++pass) {
    double t = cpu_now();
    for (const Brick& b : bricks) {
      ivol::detail::decode_residual_lanes(b.coder3.data(), b.coder3.size(), b.dims, out.data());
      if (pass == 0 && !std::equal(b.residuals.begin(), b.residuals.end(), out.begin()))
        throw std::runtime_error("static_lanes_study: coder 3 did not round-trip");
    }
    best3 = std::min(best3, cpu_now() - t);
    for (const int coder : {2, 3}) {
      t = cpu_now();
      for (const Brick& b : bricks) {
        sink.clear();
        if (coder == 2)
          ivol::detail::encode_residual_tokens(b.residuals.data(), b.dims, ~std::size_t{0}, sink);
        else
          ivol::detail::encode_residual_lanes(b.residuals.data(), b.dims, ~std::size_t{0}, sink);
      }
      double& best = coder == 2 ? encode2 : encode3;
      best = std::min(best, cpu_now() - t);
    }
  }
  std::fprintf(stderr,
               "%s: the library's coder 3: %zu bytes (%+.2f %% of coder 2), decoding %.0f MB/s (coder 2 %.0f); "
               "encoding %.0f MB/s (coder 2 %.0f)\n",
               label, coder3_bytes,
               100.0 * (static_cast<double>(coder3_bytes) / static_cast<double>(coder2_bytes) - 1.0), mb / best3,
               mb / best2, mb / encode3, mb / encode2);
  // What making the slot words costs alone (every decoder above that
  // uses them makes them for each brick).
  double best_make = 1e30;
  for (int pass = 0; pass < 5; ++pass) {
    const double t = cpu_now();
    for (const Brick& b : bricks) packed.make(b.coded.tables);
    best_make = std::min(best_make, cpu_now() - t);
  }
  std::fprintf(stderr, "%s: making the slot words alone: %.0f MB/s of values\n", label, mb / best_make);
  auto against = [&](std::size_t bytes) {
    return 100.0 * (static_cast<double>(bytes) / static_cast<double>(coder2_bytes) - 1.0);
  };
  std::printf("| %s | %zu | %.0f | %zu (%+.2f %%) | %.0f | %.0f | %zu (%+.2f %%) | %.0f | %zu (%+.2f %%) | %.0f |\n",
              label, coder2_bytes, mb / best2, static_bytes, against(static_bytes), mb / best_static, mb / best_packed,
              word_bytes, against(word_bytes), avx2 ? mb / best_avx2 : 0.0, word_bytes16, against(word_bytes16),
              avx2 && best_avx2_16 < 1e30 ? mb / best_avx2_16 : 0.0);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: static_lanes_study VOLUME.f32 N [BRICK_LOG2 [LANES]]\n");
    return 2;
  }
  const auto n = static_cast<std::uint32_t>(std::stoul(argv[2]));
  const unsigned log2 = argc > 3 ? static_cast<unsigned>(std::stoul(argv[3])) : 5;
  const unsigned lanes = argc > 4 ? static_cast<unsigned>(std::stoul(argv[4])) : 8;
  try {
    const bench::SixteenBitVolume volume = bench::read_sixteen_bit(argv[1], n);
    std::printf(
        "| %s, %u lanes | coder 2 bytes | coder 2 decode MB/s | static bytes | static decode MB/s | packed decode "
        "MB/s | 8 vector lanes, bytes | AVX2 decode MB/s | 16 vector lanes, bytes | AVX2 x 2 decode MB/s |\n"
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
        argv[1], lanes);
    run("binary16", volume.binary16, n, log2, ivol::ValueEncoding::Binary16, lanes);
    run("uint16", volume.codes, n, log2, ivol::ValueEncoding::UInt16, lanes);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s: %s\n", argv[0], e.what());
    return 1;
  }
  return 0;
}
