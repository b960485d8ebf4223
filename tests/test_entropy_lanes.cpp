// Codec 3's entropy coder 3 (spec §7.2.2): the library's coder against a
// decoder written here as plainly as the section reads (every voxel's
// context from its neighbours' coordinates, the token found by walking the
// cumulative frequencies, one state a voxel), round trips in the brick
// shapes that take the vector path, the scalar path and both, every rule
// of the section broken once in a payload built here bit by bit, and
// damage anywhere refused as malformed.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <optional>
#include <random>
#include <string>

#include "ivol/error.hpp"
#include "ivol/predicted_codec.hpp"
#include "residual_lanes.hpp"
#include "spec_coder3.hpp"

namespace {

using ivol::BrickDims;
using ivol::test::bit_length;
using ivol::test::Bits;
using ivol::test::le32;

std::size_t count(const BrickDims& d) { return std::size_t{d[0]} * d[1] * d[2]; }

// §7.2.2 read literally (tests/support/spec_coder3.cpp).
std::vector<std::uint16_t> spec_decode(const std::uint8_t* b, std::size_t size, const BrickDims& d) {
  return ivol::test::spec_coder3_decode(b, size, d);
}

std::vector<std::uint8_t> encode(const std::vector<std::uint16_t>& z, const BrickDims& d) {
  std::vector<std::uint8_t> coded;
  EXPECT_TRUE(ivol::detail::encode_residual_lanes(z.data(), d, ~std::size_t{0}, coded));
  return coded;
}

std::vector<std::uint16_t> decode(const std::vector<std::uint8_t>& coded, const BrickDims& d) {
  std::vector<std::uint16_t> z(count(d));
  ivol::detail::decode_residual_lanes(coded.data(), coded.size(), d, z.data());
  return z;
}

// Residuals as a predictor leaves them: mostly small, their sizes varying
// across the brick, now and then one of any size.
std::vector<std::uint16_t> residuals_like(const BrickDims& d, unsigned seed) {
  std::mt19937 rng(seed);
  std::vector<std::uint16_t> z(count(d));
  for (std::size_t i = 0; i < z.size(); ++i) {
    const unsigned bits = 1 + (i / d[0]) % 9;
    z[i] = static_cast<std::uint16_t>(rng() % 97 == 0 ? rng() : rng() & ((1u << bits) - 1));
  }
  return z;
}

// Bricks of 4096 voxels or more with rows of 32 or 64 take the vector path
// (on processors with AVX2) and finish in scalar code where the words left
// run short; the others are scalar throughout.
TEST(EntropyLanes, RoundTripsInEveryPathAgainstThePlainDecoder) {
  unsigned seed = 1;
  for (const BrickDims& d :
       {BrickDims{32, 32, 32}, BrickDims{64, 16, 8}, BrickDims{32, 4, 4}, BrickDims{96, 8, 8}, BrickDims{31, 7, 9},
        BrickDims{5, 3, 2}, BrickDims{1, 1, 1}, BrickDims{33, 2, 1}, BrickDims{1, 40, 3}}) {
    const auto z = residuals_like(d, seed++);
    const auto coded = encode(z, d);
    EXPECT_EQ(decode(coded, d), z) << d[0] << "x" << d[1] << "x" << d[2];
    EXPECT_EQ(spec_decode(coded.data(), coded.size(), d), z) << d[0] << "x" << d[1] << "x" << d[2];
  }
}

TEST(EntropyLanes, EverySixteenBitResidualInOrderAndShuffled) {
  const BrickDims d{64, 32, 32};
  std::vector<std::uint16_t> z(count(d));
  for (std::size_t i = 0; i < z.size(); ++i) z[i] = static_cast<std::uint16_t>(i);
  auto shuffled = z;
  std::shuffle(shuffled.begin(), shuffled.end(), std::mt19937(7));
  for (const auto* r : {&z, &shuffled}) {
    const auto coded = encode(*r, d);
    EXPECT_EQ(decode(coded, d), *r);
    EXPECT_EQ(spec_decode(coded.data(), coded.size(), d), *r);
  }
}

// One token in a context: its frequency is 4096, a step leaves the state
// as it was, and no word is ever read.
TEST(EntropyLanes, ConstantBricksUseOneTokenOfFrequency4096) {
  for (const BrickDims& d : {BrickDims{32, 32, 32}, BrickDims{7, 1, 1}}) {
    const std::vector<std::uint16_t> z(count(d), 0);
    const auto coded = encode(z, d);
    // Tables: context 0 used, token 0 alone (33 bits), 11 unused (11 bits):
    // 6 bytes; the states, W = 0, no bits below.
    ASSERT_EQ(coded.size(), 6u + 128 + 4);
    EXPECT_EQ(le32(coded.data() + 6 + 128), 0u);
    EXPECT_EQ(decode(coded, d), z);
  }
}

// A payload built here: context 0 with the tokens and frequencies given
// (the last one's implied), every other context unused; the states, the
// words and the bits below as given.
struct Built {
  std::vector<std::pair<unsigned, unsigned>> tokens;  // (t, f) in increasing t
  std::optional<std::uint32_t> present_override;
  std::vector<std::uint32_t> states = std::vector<std::uint32_t>(32, 65536);
  std::vector<std::uint16_t> words;
  std::uint32_t word_count_override = ~0u;
  std::vector<std::uint8_t> bits;
  unsigned table_padding = 0;
  std::vector<std::uint8_t> bytes() const {
    std::vector<std::uint8_t> out;
    std::uint64_t acc = 0;
    unsigned n = 0;
    auto put = [&](std::uint32_t v, unsigned c) {
      acc |= std::uint64_t{v} << n;
      for (n += c; n >= 8; n -= 8, acc >>= 8) out.push_back(static_cast<std::uint8_t>(acc));
    };
    put(1, 1);
    std::uint32_t present = 0;
    for (auto [t, f] : tokens) present |= 1u << t;
    put(present_override.value_or(present), 32);
    for (std::size_t j = 0; j + 1 < tokens.size(); ++j) {
      const unsigned f = tokens[j].second, a = bit_length(f) - 1;
      put(a, 4);
      put(f - (1u << a), a);
    }
    for (int k = 1; k < 12; ++k) put(0, 1);
    if (n) out.push_back(static_cast<std::uint8_t>(acc | table_padding << n));
    auto u32 = [&](std::uint32_t v) {
      for (int k = 0; k < 4; ++k) out.push_back(static_cast<std::uint8_t>(v >> (8 * k)));
    };
    for (std::uint32_t s : states) u32(s);
    u32(word_count_override != ~0u ? word_count_override : static_cast<std::uint32_t>(words.size()));
    for (std::uint16_t w : words)
      out.push_back(static_cast<std::uint8_t>(w)), out.push_back(static_cast<std::uint8_t>(w >> 8));
    out.insert(out.end(), bits.begin(), bits.end());
    return out;
  }
};

void expect_refused(const std::vector<std::uint8_t>& p, const BrickDims& d, const std::string& words) {
  std::vector<std::uint16_t> z(count(d));
  try {
    ivol::detail::decode_residual_lanes(p.data(), p.size(), d, z.data());
    ADD_FAILURE() << "accepted; expected: " << words;
  } catch (const ivol::Error& e) {
    EXPECT_EQ(e.error_class(), ivol::ErrorClass::Malformed) << e.what();
    EXPECT_NE(std::string(e.what()).find(words), std::string::npos) << e.what();
  }
}

TEST(EntropyLanes, EveryRuleOfTheSectionBrokenOnce) {
  const BrickDims one{1, 1, 1};  // one voxel, context 0 (no neighbours)
  Built good;
  good.tokens = {{0, 4096}};
  ASSERT_EQ(decode(good.bytes(), one), std::vector<std::uint16_t>{0});
  Built p = good;
  p.tokens = {{0, 4096}};
  p.present_override = 0;
  expect_refused(p.bytes(), one, "no token present");
  p = good, p.tokens = {{0, 4095}, {3, 1}};
  auto bad_a = p.bytes();
  bad_a[4] = static_cast<std::uint8_t>((bad_a[4] & 0xE1) | (12 << 1));  // a of token 0 (bits 33..36) = 12
  expect_refused(bad_a, one, "exceeds 11");
  p = good, p.tokens = {{0, 4095}, {1, 1}, {2, 1}};
  expect_refused(p.bytes(), one, "leaving none");
  p = good, p.table_padding = 1;
  expect_refused(p.bytes(), one, "padding bits after the tables");
  const auto whole = good.bytes();
  expect_refused(std::vector<std::uint8_t>(whole.begin(), whole.begin() + 3), one, "ends within the tables");
  expect_refused(std::vector<std::uint8_t>(whole.begin(), whole.end() - 1), one, "ends within the states");
  p = good, p.states[7] = 65535;
  expect_refused(p.bytes(), one, "below 2^16");
  p = good, p.word_count_override = 1;
  expect_refused(p.bytes(), one, "exceed");
  p = good, p.words = {0};
  expect_refused(p.bytes(), one, "words are left");
  p = good, p.states[31] = 65537;
  expect_refused(p.bytes(), one, "ends at 65537");
  p = good, p.bits = {0};
  expect_refused(p.bytes(), one, "left after the bits below");

  // The word stream ending early, the bits below short, their padding set:
  // cut from a real brick.
  const BrickDims d{9, 5, 4};
  const auto z = residuals_like(d, 9);
  const auto coded = encode(z, d);
  std::size_t tables = 0;
  {
    Bits t{coded.data(), coded.size()};
    for (int k = 0; k < 12; ++k)
      if (t.get(1)) {
        const std::uint32_t present = t.get(32);
        for (int b = 0; b < 31 - __builtin_clz(present); ++b)
          if (present >> b & 1) t.get(t.get(4));
      }
    tables = (t.at + 7) / 8;
  }
  const std::uint32_t W = le32(coded.data() + tables + 128);
  ASSERT_GT(W, 0u);
  auto fewer = coded;
  const std::uint32_t w1 = W - 1;
  std::memcpy(fewer.data() + tables + 128, &w1, 4);
  expect_refused(fewer, d, "word stream ends");
  expect_refused(std::vector<std::uint8_t>(coded.begin(), coded.end() - 1), d, "bits below the tokens end");
  std::size_t E = 0;
  for (std::uint16_t r : z) E += bit_length(r) > 2 ? bit_length(r) - 2 : 0;
  ASSERT_NE(E % 8, 0u) << "choose residuals whose bits do not fill their last byte";
  auto padded = coded;
  padded.back() = static_cast<std::uint8_t>(padded.back() | 0x80);
  expect_refused(padded, d, "padding bits after the last residual");
}

// Cut at every length, and damaged anywhere: only ivol::Error (malformed)
// or other residuals, never a read past the payload (the ASan suite runs
// this) or a crash.
TEST(EntropyLanes, CutsAndDamageAreRefused) {
  for (const BrickDims& d : {BrickDims{9, 5, 4}, BrickDims{32, 16, 8}}) {
    const auto z = residuals_like(d, 3);
    const auto coded = encode(z, d);
    std::vector<std::uint16_t> out(count(d));
    for (std::size_t cut = 0; cut < coded.size(); cut += d[0] == 9 ? 1 : 7)
      EXPECT_THROW(ivol::detail::decode_residual_lanes(coded.data(), cut, d, out.data()), ivol::Error) << cut;
    std::mt19937 rng(5);
    for (int trial = 0; trial < 2000; ++trial) {
      auto p = coded;
      for (int k = 0, flips = 1 + static_cast<int>(rng() % 4); k < flips; ++k)
        p[rng() % p.size()] ^= static_cast<std::uint8_t>(1 + rng() % 255);
      try {
        ivol::detail::decode_residual_lanes(p.data(), p.size(), d, out.data());
      } catch (const ivol::Error& e) {
        EXPECT_EQ(e.error_class(), ivol::ErrorClass::Malformed) << e.what();
      }
    }
  }
}

// Through codec 3 as a writer uses it: the header says coder 3, and every
// binary16 pattern (−0, NaN payloads, infinities) comes back.
TEST(EntropyLanes, CodecThreeWritesAndReadsCoderThree) {
  const BrickDims d{32, 16, 16};
  std::mt19937 rng(4);
  std::vector<std::uint16_t> v(count(d));
  for (std::size_t i = 0; i < v.size(); ++i) v[i] = static_cast<std::uint16_t>(0x3C00 + (i % 32) * 3 + rng() % 5);
  for (std::uint16_t special : {0x8000, 0x0000, 0x7C00, 0xFC00, 0x7E01, 0xFE77, 0x0001, 0x8001})
    v[rng() % v.size()] = special;
  ivol::PredictedOptions options;
  options.entropy = ivol::PredictedOptions::Entropy::Lanes;
  const auto payload = ivol::encode_predicted(v.data(), d, ivol::ValueEncoding::Binary16, options);
  ASSERT_EQ(payload[3], 3);
  std::vector<std::uint16_t> out(v.size());
  ivol::decode_predicted(payload.data(), payload.size(), d, out.data());
  EXPECT_EQ(out, v);
}

}  // namespace
